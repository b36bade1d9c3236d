"""Reliability, round 6: a hostile-input audit of what is new since round 5 (--hold-joint, --base-frame,
--holdout-points, the gross-error options, the option aliases) and of combinations: -o named with another
format's suffix, numbers in other scripts' digits, model files whose covariance contradicts them, artefacts
with a distance given twice. Each test is named after what it checks; all are fast (no fit, or one of a few
points)."""
from __future__ import annotations

import pytest

from arm_model.cli import main
from conftest import NOMINAL, exit_status

QCOLS = ",".join(f"q{k}_deg" for k in range(1, 8))


_exit = exit_status


def _points(tmp_path, rows=("m,f,10,20,30,40,50,60,70",)):
    path = tmp_path / "p.csv"
    path.write_text(f"measurement,feature,{QCOLS}\n" + "".join(r + "\n" for r in rows))
    return path


# ---------------------------------------------------------------------------------------------
# -o named with the suffix of a format the toolkit reads, but not the one the command writes

@pytest.mark.parametrize("command, name, writes", [
    ("tip", "out.json", ".csv"), ("tip", "out.toml", ".csv"), ("tip", "out.urdf", ".csv"),
    ("urdf", "arm.toml", ".urdf"), ("urdf", "arm.JSON", ".urdf"), ("urdf", "arm.csv", ".urdf"),
    ("view --html", "page.json", ".html"),
])
def test_an_output_file_named_as_another_format_is_refused_before_any_work(tmp_path, capsys, command, name, writes):
    """`aacmm urdf aacmm7 -o arm.toml` wrote a URDF, then its own read-back (by the suffix: a .toml file is read as
    TOML by every --arm) refused it: exit 3, "internal error, please report it". The name is the user's input: exit
    2 naming the option and the suffix the command writes, nothing written."""
    out = tmp_path / "o" / name
    argv = {"tip": ["tip", str(_points(tmp_path)), "--arm", "aacmm7", "-o"], "urdf": ["urdf", "aacmm7", "-o"],
            "view --html": ["view", str(_points(tmp_path)), "--arm", "aacmm7", "--html"]}[command]
    rc = main(argv + [str(out)])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert f"{out}:" in err and f"'{writes}'" in err and "internal error" not in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("name", ["arm.urdf", "arm.URDF", "arm.xml", "arm.txt", "arm"])
def test_an_output_file_with_its_own_suffix_or_one_no_reader_takes_is_written(tmp_path, capsys, name):
    assert main(["urdf", "aacmm7", "-o", str(tmp_path / name)]) == 0
    assert (tmp_path / name).read_text().startswith("<?xml")


# ---------------------------------------------------------------------------------------------
# numbers on the command line follow the files' number rule

@pytest.mark.parametrize("option, value", [
    ("--sigma-probe-um", "١٠"), ("--sigma-probe-um", "１０"), ("--prior-scale", "٣"),
    ("--hold-joint", "j7=1_0"), ("--hold-joint", "j7=٣"), ("--hold-joint", "j7="), ("--hold-joint", "j7=nan"),
])
def test_a_number_in_another_script_or_with_underscores_is_refused_on_the_command_line(tmp_path, capsys, option,
                                                                                       value):
    """`--prior-scale ٣` (Arabic-Indic three) and `--hold-joint j7=1_0` were read as 3 and 10 (Python's float takes
    both), `--hold-joint j7=` as 0; a points file refuses the same cells. One rule: ASCII digits, exit 2."""
    arm = ["--arm", "aacmm7"] if option != "--hold-joint" else ["--arm", str(NOMINAL.with_suffix("").with_suffix(
        ".urdf")), "--tip-frame", "ball"]
    rc = _exit(["calibrate", str(_points(tmp_path)), *arm, option, value, "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and option in err and value in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("value, expected", [("j7", ("j7", 0.0)), ("j7=-12.5", ("j7", -12.5)),
                                             (" j7 = 3 ", ("j7", 3.0)),
                                             ("j7=1e2", ("j7", 100.0))])
def test_a_hold_joint_value_in_ascii_digits_is_read(value, expected):
    from arm_model.cli_options import _hold_joint
    assert _hold_joint(value) == expected


def test_whole_number_options_keep_refusing_fractions_and_take_signs():
    import argparse

    from arm_model.cli_options import number_in
    assert number_in(kind=int)(" +7 ") == 7 and number_in(kind=int)("-3") == -3
    for bad in ("7.0", "1e3", "٧", "7_0"):
        with pytest.raises(argparse.ArgumentTypeError):
            number_in(kind=int)(bad)


def test_a_holdout_in_another_scripts_digits_is_an_id_not_a_fraction():
    from calibration.cli import parse_holdout
    assert parse_holdout("0.2") == 0.2 and parse_holdout("٠.٢") == ["٠.٢"] and parse_holdout("0_2") == ["0_2"]


# ---------------------------------------------------------------------------------------------
# artefacts: a distance given twice, a distance to a plane

_ART = '''[[feature]]
id = "A"
kind = "sphere"
diameter_mm = 25.0

[[feature]]
id = "B"
kind = "sphere"
diameter_mm = 25.0

[[feature]]
id = "table"
kind = "plane"

[[distance]]
between = ["A", "B"]
length_mm = 600.0
'''


@pytest.mark.parametrize("extra, line, words", [
    ('\n[[distance]]\nbetween = ["A", "B"]\nlength_mm = 600.0\n', 20, ("given twice", "line 16")),
    ('\n[[distance]]\nbetween = ["B", "A"]\nlength_mm = 500.0\n', 20, ("given twice", "line 16")),
    ('\n[[distance]]\nbetween = ["A", "table"]\nlength_mm = 500.0\n', 20, ("'table' is a plane", "has none")),
])
def test_a_distance_given_twice_or_to_a_plane_is_refused_with_its_line(tmp_path, capsys, extra, line, words):
    """The same pair twice made the fit's normal matrix singular ("unidentifiable", no file, no line) and with
    two lengths (600 and 500 mm) the fit went on with both; a distance to a plane (which has no centre) was
    silently unused when no measurement held both. Each is one error at the second table's line."""
    (tmp_path / "a.toml").write_text(_ART + extra)
    rc = main(["calibrate", str(_points(tmp_path, ("m,A,10,20,30,40,50,60,70",))), str(tmp_path / "a.toml"),
               "--arm", "aacmm7", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and f"a.toml, line {line}, key 'distance[2].between'" in err, err
    for w in words:
        assert w in err, err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------------------------
# a model file edited by hand so that its covariance file is of another fit

@pytest.fixture(scope="module")
def effect_model(tmp_path_factory):
    """A model file with an effect and its covariance, written by the writers calibrate uses (no fit)."""
    import numpy as np

    from arm_model.effects import JointGain
    from arm_model.model_file import format_model, load_model, write_covariance
    folder = tmp_path_factory.mktemp("model")
    desc = load_model(str(NOMINAL)).desc
    names = ["j1.gain", "j2.gain", "j3.gain"]
    values = {"j1.gain": 2e-6, "j2.gain": -1e-6, "j3.gain": 0.0}
    u = {"j1.gain": 3e-7, "j2.gain": 4e-7, "j3.gain": 0.0}
    states = {"j1.gain": "free", "j2.gain": "prior-dominated", "j3.gain": "fixed"}
    (folder / "m.toml").write_text(format_model(desc, (JointGain(joints=(0, 1, 2)),), values, u, states,
                                                covariance="m-cov.csv"))
    cov = np.diag([3e-7 ** 2, 4e-7 ** 2])
    write_covariance(folder / "m-cov.csv", names[:2], ["1", "1"], [2e-6, -1e-6], cov)
    return folder


@pytest.mark.parametrize("edit, column, words", [
    (("value_ppm = 2.0", "value_ppm = 20.0"), "value", "2 ppm here, but 20 ppm in the model file"),
    (("u_ppm = 0.3", "u_ppm = 3.0"), "u", "0.3 ppm here, but 3 ppm in the model file"),
    (('u_ppm = 0.3, state = "free"', 'u_ppm = 0.3, state = "fixed"'), "parameter", "'fixed' in the model file"),
    (('state = "prior-dominated"', 'state = "held"'), "parameter", "'held' in the model file"),
    (('u_ppm = 0.0, state = "fixed"', 'u_ppm = 0.0, state = "free"'), None,
     "'j3.gain' is 'free' (estimated) in the model file, but the covariance file has no row"),
])
def test_a_model_file_contradicting_its_covariance_file_is_refused(effect_model, tmp_path, capsys, edit, column,
                                                                   words):
    """A parameter's value, uncertainty or state edited in the model file (or its covariance file swapped for
    another fit's) was read as it stood: `tip` propagated the covariance of one fit around the values of another
    (a 'fixed' parameter with an uncertainty, an estimated one without). Now one error naming the covariance file's
    line and column."""
    import shutil
    for f in ("m.toml", "m-cov.csv"):
        shutil.copy(effect_model / f, tmp_path / f)
    text = (tmp_path / "m.toml").read_text()
    assert edit[0] in text
    (tmp_path / "m.toml").write_text(text.replace(edit[0], edit[1], 1))
    rc = main(["tip", str(_points(tmp_path)), "--arm", str(tmp_path / "m.toml"), "-o", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "m-cov.csv" in err and words in err, err
    if column is not None:
        assert f"line {2 if 'j1' in err else 3}, column '{column}'" in err, err
    assert not (tmp_path / "o.csv").exists()


def test_a_model_file_agreeing_with_its_covariance_file_is_read(effect_model, tmp_path, capsys):
    out = tmp_path / "o.csv"
    assert main(["tip", str(_points(tmp_path)), "--arm", str(effect_model / "m.toml"), "-o", str(out)]) == 0
    assert "u_x_mm" in out.read_text().splitlines()[0]


# ---------------------------------------------------------------------------------------------
# the Python API: effects refuse joints and harmonics they cannot act on, when built

@pytest.mark.parametrize("kind, kw, error, match", [
    ("joint_gain", {"joints": ("j1",)}, TypeError, "joints must be a tuple of whole numbers"),
    ("joint_gain", {"joints": (1.5,)}, TypeError, "joints must be a tuple of whole numbers"),
    ("joint_gain", {"joints": (True,)}, TypeError, "joints must be a tuple of whole numbers"),
    ("joint_gain", {"joints": 3}, TypeError, "joints must be a tuple of whole numbers"),
    ("joint_gain", {"joints": (-1,)}, ValueError, "joints must be distinct whole numbers >= 0"),
    ("joint_gain", {"joints": ()}, ValueError, "at least one"),
    ("joint_gain", {"joints": (2, 2)}, ValueError, "distinct"),
    ("eccentricity", {"harmonics": (0, 1)}, ValueError, "harmonics must be distinct whole numbers >= 1"),
    ("eccentricity", {"harmonics": (1.5,)}, TypeError, "harmonics must be a tuple of whole numbers"),
    ("eccentricity", {"harmonics": "12"}, TypeError, "harmonics must be a tuple of whole numbers"),
    ("joint_harmonics", {"harmonics": (10 ** 6,)}, ValueError, "<= 1000"),
    ("joint_harmonics", {"source": "j1"}, TypeError, "source must be a 0-based joint index"),
])
def test_an_effect_built_in_python_refuses_joints_and_harmonics_it_cannot_act_on(kind, kw, error, match):
    """JointGain(joints=("j1",)) failed deep in param_defs ("tuple indices must be integers"), joints=(-1,) acted on
    the last joint and (True,) on the second; Eccentricity(harmonics=(0,)) made a constant (an offset, a singular
    fit) and (1.5,) a parameter 'j1.ecc1.5_cos'. Each is refused where the effect is built."""
    from arm_model.effects import EFFECTS
    with pytest.raises(error, match=match):
        EFFECTS[kind](**kw)


@pytest.mark.parametrize("kind, kw", [("joint_gain", {"joints": (99,)}),
                                      ("joint_harmonics", {"joints": (1,), "source": 7})])
def test_an_effect_on_a_joint_the_arm_lacks_says_so(nominal, kind, kw):
    from arm_model.effects import EFFECTS
    with pytest.raises(ValueError, match="but the arm has 7 joints"):
        EFFECTS[kind](**kw).param_defs(nominal)


def test_a_model_file_with_a_harmonic_zero_names_its_key(effect_model, tmp_path, capsys):
    text = (effect_model / "m.toml").read_text().replace('kind = "joint_gain"',
                                                         'kind = "eccentricity"\nharmonics = [0]')
    (tmp_path / "m.toml").write_text(text)
    rc = main(["tip", str(_points(tmp_path)), "--arm", str(tmp_path / "m.toml"), "-o", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "m.toml, line" in err and "key 'effect[1]'" in err and "harmonics must be" in err, err


# ---------------------------------------------------------------------------------------------
# calibrate: the outlier options that contradict each other

@pytest.mark.parametrize("options, words", [
    (["--drop-outliers", "--keep-outliers"], "not allowed with argument"),
    (["--keep-outliers", "--gross-threshold", "8"], "--keep-outliers keeps every point"),
    (["--drop-outliers", "--gross-threshold", "8"], "--drop-outliers drops every outlier"),
])
def test_outlier_options_that_contradict_each_other_are_refused(tmp_path, capsys, options, words):
    """`--drop-outliers --keep-outliers` dropped every outlier (the keep silently lost), and `--gross-threshold 8`
    beside either was silently unused."""
    (tmp_path / "a.toml").write_text(_ART)
    rc = _exit(["calibrate", str(_points(tmp_path, ("m,A,10,20,30,40,50,60,70",))), str(tmp_path / "a.toml"),
                "--arm", "aacmm7", "-o", str(tmp_path / "o"), *options])
    err = capsys.readouterr().err
    assert rc == 2 and words in err, err
    assert not (tmp_path / "o").exists()


def test_the_default_gross_threshold_and_keep_outliers_are_what_the_fit_gets():
    import argparse

    from calibration.cli import gross_threshold
    from calibration.options import GROSS_THRESHOLD
    ns = argparse.Namespace
    assert gross_threshold(ns(gross_threshold=None, keep_outliers=False, drop_outliers=False)) == GROSS_THRESHOLD
    assert gross_threshold(ns(gross_threshold=8.0, keep_outliers=False, drop_outliers=False)) == 8.0
    assert gross_threshold(ns(gross_threshold=None, keep_outliers=True, drop_outliers=False)) is None
    assert gross_threshold(ns(gross_threshold=None, keep_outliers=False, drop_outliers=True)) == GROSS_THRESHOLD


# ---------------------------------------------------------------------------------------------
# the Python API: FitOptions refuses what would fail deep in the fit

@pytest.mark.parametrize("kw, match", [
    ({"prior_scale": 1e-300}, r"prior_scale must be in \[1e-12, 1e\+12\]"),
    ({"prior_scale": 5e-324}, r"prior_scale must be in"),
    ({"prior_scale": 1e300}, r"prior_scale must be in"),
    ({"prior_scale": {"lengths": 1e-300}}, r"prior_scale\['lengths'\] must be in"),
    ({"values": {"j1.a": float("nan")}}, r"values\['j1.a'\] must be a finite number"),
    ({"start": {"j1.a": float("inf")}}, r"start\['j1.a'\] must be a finite number"),
    ({"values": {"j1.a": "x"}}, r"values\['j1.a'\] must be a finite number"),
    ({"priors": {"j*.a": -1.0}}, r"priors\['j\*.a'\] must be a positive finite number"),
    ({"free": [1, 2]}, "free must be a sequence of parameter names"),
    ({"free": ("",)}, "free must be a sequence of parameter names"),
    ({"prior_length": 1e300}, r"prior_length must be in \[1e-09, 1000\]"),
    ({"prior_centre": [float("nan")]}, "prior_centre must be finite"),
    ({"drop_outliers": "no"}, "drop_outliers must be True or False"),
    ({"weights_from_data": "yes"}, "weights_from_data must be True or False"),
])
def test_fit_options_refuse_what_would_fail_deep_in_the_fit(kw, match):
    """FitOptions(prior_scale=1e-300) ended in a NumericalError blaming the data ("the normal matrix is exactly
    singular"), 5e-324 in a fit stalled on NaN, values={'j1.a': nan} and free=[1, 2] deep in the fit,
    drop_outliers="no" dropped them. Each is a ValueError naming the option."""
    from calibration.options import FitOptions
    with pytest.raises(ValueError, match=match):
        FitOptions(**kw)


def test_fit_options_keep_taking_what_the_fits_use():
    import numpy as np

    from calibration.options import FitOptions
    o = FitOptions(prior_scale=1e-9, values={"j1.a": np.float64(1e-4), "j2.d": np.array(2e-4)}, free=["j*.a"],
                   priors={"j*.a": 1e-3})
    assert o.values == {"j1.a": 1e-4, "j2.d": 2e-4} and o.free == ("j*.a",)
    assert FitOptions(prior_scale=1e4).prior_scale == 1e4 and FitOptions(prior_scale=None).prior_scale is None


@pytest.mark.parametrize("which", ["model", "data", "options"])
def test_calibrate_called_with_the_wrong_kind_of_argument_says_which(which):
    """calibrate("aacmm7", data) and calibrate(model, data, {"free": None}) ended in AttributeErrors deep in the fit
    ("'str' object has no attribute 'spec'"); a TypeError names the argument and how to make it."""
    from calibration import calibrate
    args = {"model": "aacmm7", "data": "points.csv", "options": {"free": None}}
    kw = {k: (args[k] if k == which else None) for k in args}
    if which != "model":
        from arm_model import load_description
        from arm_model.model import ArmModel
        kw["model"] = ArmModel(load_description(NOMINAL))
    if which == "options":
        from calibration.data import CalibrationData
        kw["data"] = object.__new__(CalibrationData)     # never reached: the options are refused first
    kw.pop("options") if which != "options" else None
    with pytest.raises(TypeError, match=f"calibrate: {which} must be a"):
        calibrate(**kw)


# ---------------------------------------------------------------------------------------------
# aacmm live: a clock reset back by a little, and a bad time stamp among the first samples

_Q = [0.17, 0.61, -0.09, 1.22, 0.05, 0.7, 0.14]


def _session(times, rate=None):
    from arm_model.live import Session
    s = Session("aacmm7", rate=rate)
    for t in times:
        s.push(t, _Q, (0.0, 0.0, 0.0))
    s.close()
    return s.counts


@pytest.mark.parametrize("back", [5, 50, 99])
def test_a_clock_reset_back_by_less_than_the_bound_is_one_clock_jump_not_late_samples(back):
    """A device clock that jumps back by 50 periods (less than the 100 that make a time stamp 'far off') made every
    sample late until the new clock passed the old one's last time: 50 samples skipped. The samples after it keep
    the new clock: one clock jump, none late, none lost."""
    counts = _session([k * 1e-3 for k in range(200)] + [(200 - back + k) * 1e-3 for k in range(200)], rate=1000.0)
    assert counts["clock_jumps"] == 1 and counts["late"] == 0 and counts["time_jumps"] == 0, counts
    assert counts["samples"] == 400 and counts["dropped"] == 0, counts


def test_samples_out_of_order_are_still_late_ones():
    """Three datagrams that came late (fewer than a clock jump needs), then the stream on its clock: three late."""
    from arm_model.live.session import JUMP_CONFIRM
    times = [k * 1e-3 for k in range(101)] + [97e-3, 98e-3, 99e-3] + [k * 1e-3 for k in range(101, 200)]
    assert JUMP_CONFIRM > 3
    counts = _session(times, rate=1000.0)
    assert counts["late"] == 3 and counts["clock_jumps"] == counts["time_jumps"] == 0, counts
    assert counts["samples"] == 200, counts


@pytest.mark.parametrize("bad_at", [0, 2])
def test_a_bad_time_stamp_among_the_first_samples_does_not_make_the_session_late(bad_at):
    """Without --rate-Hz, the first intervals are not judged (the period is learnt from them): a time stamp at 1e6 s
    as the first or third sample was taken, and every later sample was late (the whole session lost). The samples
    after it keep their own clock: one clock jump back, and every one of them taken."""
    times = [k * 1e-3 for k in range(300)]
    times.insert(bad_at, 1e6)
    counts = _session(times)
    assert counts["late"] == 0 and counts["clock_jumps"] == 1, counts
    assert counts["samples"] == 301, counts


# ---------------------------------------------------------------------------------------------
# --hold-joint: what it cannot hold

_ARM_URDF = str(NOMINAL.with_suffix("").with_suffix(".urdf"))      # the toolkit's own URDF, with the probe's joints


@pytest.mark.parametrize("hold, words", [
    (["probe_axial=0.5"], "joint 'probe_axial' is the probe's elastic joint"),
    ([f"j{k}" for k in range(1, 8)], "--hold-joint holds every moving joint between 'base_link' and 'ball'"),
])
def test_a_joint_held_beyond_its_limits_or_the_probes_elastic_joint_is_refused(tmp_path, capsys, hold, words):
    """(Round 7: a value beyond the limits is warned and used, as an encoder angle beyond them is:
    tests/test_reliability_round7.py.) `--hold-joint probe_axial=0.5` was silently unused (the probe's elastic
    joints are its compliance, taken from the force); holding every joint blamed --tip-frame."""
    argv = ["urdf", _ARM_URDF, "--tip-frame", "ball", "-o", str(tmp_path / "a.urdf")]
    for h in hold:
        argv += ["--hold-joint", h]
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and "key '--hold-joint'" in err and words in err, err
    assert not (tmp_path / "a.urdf").exists()


def test_a_joint_held_at_its_limit_is_taken(tmp_path):
    out = tmp_path / "a.urdf"
    assert main(["urdf", _ARM_URDF, "--tip-frame", "ball", "--hold-joint", "j2=150", "-o", str(out)]) == 0


# ---------------------------------------------------------------------------------------------
# the Python API of a live session: a sample pushed by hand is held to the stream reader's rule

@pytest.mark.parametrize("args, kw, error, match", [
    ((float("nan"), _Q, (0, 0, 0)), {}, ValueError, r"t must be a finite time"),
    ((float("inf"), _Q, (0, 0, 0)), {}, ValueError, r"t must be a finite time"),
    ((1e300, _Q, (0, 0, 0)), {}, ValueError, r"t must be a finite time in \[-1e\+10, 1e\+10\]"),
    (("1", _Q, (0, 0, 0)), {}, TypeError, "t must be a number"),
    ((0.0, [float("nan")] * 7, (0, 0, 0)), {}, ValueError, r"q\[0\] must be a finite angle"),
    ((0.0, [1e9] * 7, (0, 0, 0)), {}, ValueError, r"q\[0\] must be a finite angle"),
    ((0.0, _Q, (1e300, 0, 0)), {}, ValueError, r"wrench\[0\] must be a finite force"),
    ((0.0, _Q, (0, 0, 0, 0, 0, float("inf"))), {}, ValueError, r"wrench\[5\] must be a finite torque"),
    ((0.0, _Q, (0, 0, 0)), {"temperature": -500.0}, ValueError,
     r"temperature must be a finite temperature in \[-273.15"),
    ((0.0, _Q, (0, 0, 0)), {"temperature": float("nan")}, ValueError, "temperature must be a finite temperature"),
    ((0.0, _Q, (0, 0, 0)), {"trigger": "no"}, TypeError, "trigger must be True, False or None"),
])
def test_a_sample_pushed_in_python_is_held_to_the_stream_readers_rule(args, kw, error, match):
    """Session.push(nan, ...) was taken: every later sample was then off the clock (the session lost); q = nan, a
    force of 1e300 N, a temperature of -500 C were taken too, and trigger="no" was True. Each is refused where it
    is pushed, as the stream reader refuses the same cell."""
    from arm_model.live import Session
    s = Session("aacmm7")
    with pytest.raises(error, match=match):
        s.push(*args, **kw)
    assert s.counts["samples"] == 0


@pytest.mark.parametrize("kw, match", [
    ({"id": "", "kind": "plane"}, "id must be a non-empty text"),
    ({"id": "s", "kind": "sphere", "diameter": -0.025}, "diameter must be a finite length"),
    ({"id": "s", "kind": "sphere", "diameter": float("nan")}, "diameter must be a finite length"),
    ({"id": "s", "kind": "sphere", "diameter": 0.025, "u_diameter": -1e-6}, "u_diameter must be a finite length"),
    ({"id": "s", "kind": "ring", "diameter": 1e9}, "diameter must be a finite length"),
])
def test_a_feature_begun_in_python_is_held_to_the_artefacts_readers_rule(kw, match):
    """Session.begin_feature("s", "sphere", diameter=-0.025) (or NaN, or an empty id) was taken; the fits of that
    feature then compared the points with a negative certificate."""
    from arm_model.live import Session
    with pytest.raises(ValueError, match=match):
        Session("aacmm7").begin_feature(**kw)


def test_a_session_plan_given_as_a_path_says_how_to_read_it():
    from arm_model.live import Session
    with pytest.raises(TypeError, match=r"plan must be a SessionPlan \(arm_model.live.read_plan\(path\)\)"):
        Session("aacmm7", plan="plan.toml")


@pytest.mark.parametrize("kw, error, match", [
    ({"hold": {"j7": float("nan")}}, ValueError, r"hold\['j7'\] must be finite"),
    ({"hold": {"j7": "10"}}, TypeError, r"hold\['j7'\] must be a number"),
    ({"hold": {7: 1.0}}, TypeError, "hold must be a dict"),
    ({"hold": ["j7"]}, TypeError, "hold must be a dict"),
    ({"base_frame": 3}, TypeError, "base_frame must be a link name"),
    ({"tip_frame": ("ball",)}, TypeError, "tip_frame must be a link name"),
])
def test_load_model_refuses_a_hold_or_frame_of_the_wrong_kind(kw, error, match):
    """load_model(urdf, tip_frame="ball", hold={"j7": "10"}) failed in numpy ("ufunc 'radians' not supported"),
    hold={7: 1.0} and base_frame=3 with AttributeErrors; NaN passed wherever the joint has no limits."""
    from arm_model.model_file import load_model
    args = {"tip_frame": "ball", **kw}
    with pytest.raises(error, match=match):
        load_model(_ARM_URDF, **args)


@pytest.mark.parametrize("effects, match", [
    (("thermal",), r"every effect must be an arm_model.effects.Effect \(e.g."),
    ("thermal", "effects must be a tuple of effects"),
    ("class", r"\(an instance: call it"),
])
def test_an_arm_model_with_effects_of_the_wrong_kind_says_so(nominal, effects, match):
    """ArmModel(desc, ("thermal",)) failed with "'str' object has no attribute 'param_defs'"; an effect's class
    instead of an instance with a missing argument deep in param_defs."""
    from arm_model.effects import EFFECTS
    from arm_model.model import ArmModel
    with pytest.raises(TypeError, match=match):
        ArmModel(nominal, (EFFECTS["thermal"],) if effects == "class" else effects)


def test_an_arm_model_of_a_name_and_make_data_of_paths_say_what_they_need(nominal):
    from arm_model.model import ArmModel
    from calibration import make_data
    with pytest.raises(TypeError, match="desc must be an ArmDescription"):
        ArmModel("aacmm7")
    with pytest.raises(TypeError, match="make_data: points must be a PointSet"):
        make_data("points.csv", None, ArmModel(nominal))
    with pytest.raises(TypeError, match="make_data: model must be an ArmModel or None"):
        make_data(object.__new__(__import__("arm_model.io", fromlist=["PointSet"]).PointSet), None, nominal)


# ---------------------------------------------------------------------------------------------
# -o: a dangling link

def test_an_output_file_that_is_a_link_into_a_missing_folder_makes_no_folder_there(tmp_path, capsys):
    """`tip -o out.csv` where out.csv is a link to /somewhere/missing/x.csv made the folders /somewhere/missing
    (outside every folder the user named) and wrote there; a shell's > refuses. Now exit 2, nothing made."""
    target = tmp_path / "elsewhere" / "deep" / "x.csv"
    (tmp_path / "out.csv").symlink_to(target)
    rc = main(["tip", str(_points(tmp_path)), "--arm", "aacmm7", "-o", str(tmp_path / "out.csv")])
    err = capsys.readouterr().err
    assert rc == 2 and "whose folder does not exist" in err, err
    assert not (tmp_path / "elsewhere").exists()


def test_an_output_folder_that_is_a_link_into_a_missing_folder_makes_no_folder_there(tmp_path, capsys):
    (tmp_path / "o").symlink_to(tmp_path / "elsewhere" / "deep" / "o")
    (tmp_path / "a.toml").write_text(_ART)
    rc = main(["calibrate", str(_points(tmp_path, ("m,A,10,20,30,40,50,60,70",))), str(tmp_path / "a.toml"),
               "--arm", "aacmm7", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "whose folder does not exist" in err, err
    assert not (tmp_path / "elsewhere").exists()


def test_an_output_file_that_is_a_link_into_an_existing_folder_is_written_through(tmp_path):
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out.csv").symlink_to(tmp_path / "elsewhere" / "x.csv")
    assert main(["tip", str(_points(tmp_path)), "--arm", "aacmm7", "-o", str(tmp_path / "out.csv")]) == 0
    assert (tmp_path / "out.csv").is_symlink()
    assert (tmp_path / "elsewhere" / "x.csv").read_text().startswith("measurement")


# ---------------------------------------------------------------------------------------------
# study montecarlo --workers: not more processes than cores

def test_more_workers_than_cores_are_refused_before_any_run(tmp_path, capsys):
    """`aacmm study montecarlo --workers 100000` forked 100000 worker processes (a load average of 1300 on a
    2-core machine, 100 MB each): the option is range-checked against the cores this process may run on, and
    run_tasks never starts more processes than those cores."""
    from arm_model.parallel import cores
    from calibration.study import run_tasks
    campaign = NOMINAL.parents[1] / "examples" / "campaigns" / "calibration.toml"
    rc = _exit(["study", "montecarlo", str(campaign), "--workers", str(cores() + 1), "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and f"--workers: must be in [1, {cores()}]" in err, err
    assert not (tmp_path / "o").exists()
    with pytest.raises(ValueError, match="workers must be a whole number >= 1"):
        run_tasks(abs, [1], workers=0)
    assert run_tasks(abs, [-1, -2], workers=10 ** 6, progress=False) == [1, 2]


# ---------------------------------------------------------------------------------------------
# a points file written with another separator is said as such, not as a missing column

@pytest.mark.parametrize("sep, name", [("\t", "tab"), (";", "semicolon")])
def test_a_points_file_of_another_separator_is_named(tmp_path, capsys, sep, name):
    path = tmp_path / "p.csv"
    path.write_text(sep.join(["measurement", "feature", *QCOLS.split(",")]) + "\n"
                    + sep.join(["m", "f", "10", "20", "30", "40", "50", "60", "70"]) + "\n")
    out = tmp_path / "tips.csv"
    assert _exit(["tip", str(path), "--arm", str(NOMINAL), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"p.csv, line 1: the header is {name}-separated" in err and "commas" in err and not out.exists()
