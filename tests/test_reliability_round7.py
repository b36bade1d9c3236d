"""Reliability, round 7: a hostile-input audit of what rounds 1-6 did not look at, and the rules they left
inconsistent: a certified distance to a ring or cylinder (refused at its line by the reader, not at fit time),
joint values beyond the declared limits (warned alike whether measured or held), numerical failure (its own exit
status, 4), `study montecarlo` (--holdout 0, a run's input error, --scheduler). Each test is named after what it
checks; all are fast (no fit, or one of a few points)."""
from __future__ import annotations

import pytest

from arm_model.cli import main
from conftest import NOMINAL, exit_status

QCOLS = ",".join(f"q{k}_deg" for k in range(1, 8))


_exit = exit_status


def _points(tmp_path, rows=("m,f,10,20,30,40,50,60,70",), name="p.csv"):
    path = tmp_path / name
    path.write_text(f"measurement,feature,{QCOLS}\n" + "".join(r + "\n" for r in rows))
    return path


# ---------------------------------------------------------------------------------------------
# (b) a certified distance joins two centres: refused at its line for a ring, a cylinder or a free point

_ART = '''[[feature]]
id = "A"
kind = "seat"

[[feature]]
id = "R"
kind = "{kind}"
{size}
[[distance]]
between = ["A", "R"]
length_mm = 100.0
'''


@pytest.mark.parametrize("kind, size, words", [
    ("ring", "diameter_mm = 50.0\n", "a ring's axis is a line"),
    ("cylinder", "diameter_mm = 50.0\n", "a cylinder's axis is a line"),
    ("point", "# a point has no size\n", "a free point is no artefact's centre"),
])
def test_a_distance_to_a_feature_without_a_centre_is_refused_at_its_line(tmp_path, capsys, kind, size, words):
    """A distance to a ring was refused by the fit ("a distance needs feature centres", no line) only when a
    measurement held both features, and read without a word by `aacmm ring`, `view` and a live plan (which
    measured it between the ring's axis point and the seat). The artefacts reader refuses it at the table's line,
    so every command that reads the file says the same."""
    art = tmp_path / "a.toml"
    art.write_text(_ART.format(kind=kind, size=size))
    rc = _exit(["calibrate", str(_points(tmp_path, ("m,A,10,20,30,40,50,60,70",))), str(art), "--arm", "aacmm7",
                "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "a.toml, line 11, key 'distance[1].between'" in err and words in err, err
    assert not (tmp_path / "o").exists()
    from arm_model.errors import InputError
    from arm_model.live.plan import read_plan
    with pytest.raises(InputError, match="line 11"):
        read_plan(art)


# ---------------------------------------------------------------------------------------------
# (c) numerical failure: its own exit status, said by --help and docs/guarantees.md alike

def test_a_numerical_failure_exits_4_and_says_so(tmp_path, monkeypatch, capsys):
    """A fit that did not converge, a rank deficiency, inverse kinematics without a solution exited 2 like a
    typo in a file, while the guide treats numerical failure as distinct from bad input: exit 4, "numerical
    failure: ...", nothing written. Bad input keeps exit 2."""
    import arm_model.commands as commands
    from arm_model import NumericalError

    def fail(*args, **kwargs):
        raise NumericalError("Levenberg-Marquardt did not converge in 200 iterations")
    monkeypatch.setattr(commands, "tip_centres", fail)
    out = tmp_path / "t.csv"
    rc = _exit(["tip", str(_points(tmp_path)), "--arm", "aacmm7", "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 4 and "aacmm tip: error: numerical failure: Levenberg-Marquardt did not converge" in err, err
    assert "nothing written" in err and not out.exists()


def test_the_exit_statuses_of_help_and_guarantees_agree():
    """`aacmm --help` listed 0, 2, 3 and 130 (no 1 for study montecarlo's failed runs, no 143); the guarantees
    listed 1 but no numerical failure. One list, the same in both."""
    import re

    from arm_model.cli import EXIT_STATUS, build_parser
    from conftest import ROOT
    table = (ROOT / "docs" / "guarantees.md").read_text().split("## 4.")[1].split("## 5.")[0]
    documented = set(re.findall(r"^\| (\d+(?: / \d+)?) \|", table, re.M))
    assert documented == {"0", "1", "2", "3", "4", "130 / 143"}, documented
    for code in ("0 done", "1 study montecarlo", "2 bad input", "3 internal error", "4 numerical failure",
                 "130/143"):
        assert code in EXIT_STATUS
    assert " ".join(build_parser().format_help().split()).count(" ".join(EXIT_STATUS.split())) == 1


# ---------------------------------------------------------------------------------------------
# (d) study montecarlo: --holdout 0, a run's input error, every run failing, --scheduler

_CAMPAIGN = 'arm = "{arm}"\nsensor = "none"\n[[task]]\nkind = "seat"\nmeasurements = 2\narticulations = 4\n'


@pytest.fixture()
def campaign(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(_CAMPAIGN.format(arm=NOMINAL))
    return path


def test_montecarlo_holdout_0_holds_nothing_out():
    """`--holdout 0` was refused ("must be in (0, 1)"), so a campaign too small to split (two measurements: the
    default 0.25 holds out none) could not be studied at all. 0 now means no held-out data: the parameters
    against the truth, no predicted accuracy. 1 stays refused (nothing left to fit)."""
    from arm_model.cli import build_parser
    from calibration.study import RunSettings
    parser = build_parser(["study", "montecarlo"])
    assert parser.parse_args(["study", "montecarlo", "c.toml", "--holdout", "0", "-o", "o"]).holdout == 0.0
    with pytest.raises(SystemExit):
        parser.parse_args(["study", "montecarlo", "c.toml", "--holdout", "1", "-o", "o"])
    assert RunSettings(holdout=0.0).holdout == 0.0
    for bad in (1.0, -0.1, float("nan"), True, "0.2"):
        with pytest.raises(ValueError, match=r"holdout must be a fraction in \[0, 1\)"):
            RunSettings(holdout=bad)


def test_montecarlo_a_holdout_the_campaign_cannot_give_is_bad_input(campaign, tmp_path, capsys):
    """`--holdout 0.01` on a campaign of two measurements failed every run with the same input error ("the
    held-out set is empty ... name the measurements to hold out (--holdout ID,ID)", an option study montecarlo
    lacks), wrote study.json with no result and exited 1 ("done, but some runs failed"). An input error stops the
    study at the first run: exit 2, naming the option, nothing written."""
    rc = _exit(["study", "montecarlo", str(campaign), "--runs", "3", "--workers", "1", "--holdout", "0.01",
                "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "--holdout 0.01: the held-out set is empty" in err and "or 0 to hold nothing out" in err
    assert "ID,ID" not in err and not (tmp_path / "o").exists()


def test_montecarlo_without_a_successful_run_is_a_numerical_failure(campaign, tmp_path, capsys, monkeypatch):
    """Every run failing numerically wrote a study.json of empty tables and exited 1; it is a study without a
    result: exit 4, the runs' errors said, nothing written."""
    import calibration.study as study
    from arm_model import NumericalError

    def fail(source, settings, seed, t0):
        raise NumericalError(f"Levenberg-Marquardt did not converge (seed {seed})")
    monkeypatch.setattr(study, "_run", fail)
    rc = _exit(["study", "montecarlo", str(campaign), "--runs", "2", "--workers", "1", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 4 and "numerical failure: no run succeeded (2 runs): NumericalError" in err, err
    assert not (tmp_path / "o").exists()


def test_montecarlo_scheduler_and_workers_exclude_each_other(campaign, tmp_path, capsys):
    """`--scheduler ADDR --workers 1` silently ignored --workers."""
    rc = _exit(["study", "montecarlo", str(campaign), "--workers", "1", "--scheduler", "tcp://127.0.0.1:9",
                "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "give one of them" in err and not (tmp_path / "o").exists()


def test_montecarlo_runs_carry_the_campaign_read_not_its_path(campaign):
    """Each run read the campaign file again, by a path relative to where `aacmm` ran: a Dask worker on another
    machine (or in another folder) could not find it, and a file edited during the study gave runs of different
    campaigns. The campaign is read once and travels with the runs."""
    import pickle

    from calibration.study import SimSource
    source = pickle.loads(pickle.dumps(SimSource(str(campaign))))
    campaign.unlink()
    arm, points, *_ = source.make(0)
    assert len(points.measurement) == 8
    with pytest.raises(TypeError, match="SimSource: campaign must be a Campaign"):
        SimSource(42)


# ---------------------------------------------------------------------------------------------
# (a) joint limits: one rule for measured and held values, warned and used

_ARM_URDF = str(NOMINAL.with_suffix("").with_suffix(".urdf"))      # the toolkit's own URDF, limits j2 +-150 deg


@pytest.mark.parametrize("hold, words", [
    ("j7=400", "joint 'j7' held at 400 deg, beyond its limits [-360, 360] deg"),
    ("j2=-151", "joint 'j2' held at -151 deg, beyond its limits [-150, 150] deg"),
])
def test_a_joint_held_beyond_its_limits_is_warned_and_used_as_a_measured_one(tmp_path, capsys, hold, words):
    """A points file's angle beyond its joint's limits was warned and used while the same value given by
    `--hold-joint` was refused (exit 2). A limit is the description's claim; a value beyond it, measured or stated,
    contradicts it, and either may be the wrong one: both are warned (also with --quiet) and used."""
    from arm_model import load_arm
    out = tmp_path / "a.urdf"
    assert main(["urdf", _ARM_URDF, "--tip-frame", "ball", "--hold-joint", hold, "-o", str(out), "-q"]) == 0
    err = capsys.readouterr().err
    assert err.count("warning:") == 1 and words in err and "used as given" in err, err
    name, value = hold.split("=")
    desc = load_arm(_ARM_URDF, "ball", hold={name: float(value)})
    assert dict(desc.held_joints)[name] == pytest.approx(float(value))
    # a measured angle beyond the same limit: the same kind of line
    rows = ("m,f,10,-151,30,40,50,60,70",)
    assert main(["tip", str(_points(tmp_path, rows)), "--arm", _ARM_URDF, "--tip-frame", "ball", "-q",
                 "-o", str(tmp_path / "t.csv")]) == 0
    assert "warning:" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# model files: a joint named twice, a 'kind' that is no text, a suggestion with a unit

@pytest.fixture(scope="module")
def model_text(nominal):
    from arm_model.effects import EncoderEccentricity, JointCompliance
    from arm_model.model_file import format_model
    return format_model(nominal, (EncoderEccentricity(), JointCompliance()))


@pytest.mark.parametrize("old, new, key, words", [
    ('kind = "joint_compliance"', 'kind = "joint_compliance"\njoints = ["j1", "j1"]', "effect[2].joints",
     "joint 'j1' is named twice"),
    ('kind = "eccentricity"', "kind = 3", "effect[1].kind", "'kind' must be text, one of: eccentricity"),
    ('name = "j1.ecc1_cos", value_urad = 0.0', 'name = "j1.ecc1_cos", value_mm = 0.0',
     "effect[1].parameter[1].value_mm", "did you mean 'value_rad'?"),
])
def test_a_model_file_effect_that_cannot_be_right_names_its_key(model_text, tmp_path, capsys, old, new, key, words):
    """`joints = ["j1", "j1"]` was refused as "joints must be distinct whole
    numbers, got (0, 0)" at the table's first line; `kind = 3` said "missing 'kind'"; `value_mm` on an angle was
    answered "did you mean 'value_rad_mm'?" (a key that exists nowhere)."""
    assert old in model_text
    model = tmp_path / "m.toml"
    model.write_text(model_text.replace(old, new, 1))
    out = tmp_path / "t.csv"
    rc = _exit(["tip", str(_points(tmp_path)), "--arm", str(model), "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and f"key '{key}'" in err and words in err, err
    assert not out.exists()


def test_did_you_mean_offers_a_whole_key_as_it_is_and_a_base_with_the_users_unit():
    from arm_model.errors import did_you_mean
    assert did_you_mean("value_mm", ["value_urad", "value_rad", "u_rad"]) == "; did you mean 'value_rad'?"
    assert did_you_mean("u_diamter_mm", ["u_diameter", "diameter"]) == "; did you mean 'u_diameter_mm'?"


# ---------------------------------------------------------------------------------------------
# live: an empty source, an event before the first sample

def test_live_an_empty_source_is_named_as_such():
    """`aacmm live ""` read the current folder ("'.': it is a folder, not a file")."""
    from arm_model.errors import InputError
    from arm_model.live.sources import open_source
    for spec in ("", "  "):
        with pytest.raises(InputError, match="not a source: give a file"):
            open_source(spec)


def test_live_an_event_before_the_first_sample_shows_no_nan_time():
    """A bad line before any sample was logged as "warning: [       nan s] bad_line ..." (events.csv already left
    its time empty): no time is shown as a dash, never as nan."""
    from arm_model.live.session import Event
    assert str(Event(float("nan"), "bad_line", "x")) == f"[{'-':>10} s] bad_line: x"
    assert str(Event(1.5, "bad_line", "x")) == "[     1.500 s] bad_line: x"


# ---------------------------------------------------------------------------------------------
# view --points-per-s: a rate the page can play

@pytest.mark.parametrize("rate", ["1e-300", "5e-324", "0.0009", "1e5"])
def test_view_an_animation_rate_the_page_cannot_play_is_refused(tmp_path, capsys, rate):
    """`view --animate --points-per-s 1e-300 --html` wrote a page whose frames sat at 1e300 s (infinity in the
    page's 32-bit clip times): exit 0 and an animation that never moved."""
    out = tmp_path / "v.html"
    rc = _exit(["view", str(_points(tmp_path)), "--arm", "aacmm7", "--animate", "--points-per-s", rate,
                "--html", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "--points-per-s" in err and "must be in [0.001, 10000]" in err, err
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# ring --signals: a signal that is zero throughout

def test_a_force_signal_of_zeros_says_so_not_a_noise_of_1e_312(tmp_path):
    """A signal zero in every sample was refused as "0 peaks found (above 10 x the noise, 1e-312 N)": a noise
    nobody measured, shown as a figure."""
    from arm_model.errors import InputError
    from arm_model.io import read_force_signal
    from correction.signals import find_point_forces
    path = tmp_path / "m.csv"
    path.write_text("time_s,f_bend_N,f_axial_N\n" + "".join(f"{k / 1000:.3f},0,0\n" for k in range(200)))
    with pytest.raises(InputError, match=r"m.csv: force signal of measurement 'm': the force is zero in every "
                                         r"sample, but the points file has 3 points") as exc:
        find_point_forces(read_force_signal(path), 3, "m")
    assert "e-3" not in str(exc.value)


# ---------------------------------------------------------------------------------------------
# the public Python API called with what cannot be right

@pytest.mark.parametrize("call, match", [
    (lambda g: g.fit_cylinder([[float("nan")] * 3] * 10), "points must be finite: row 0"),
    (lambda g: g.fit_sphere([[float("inf"), 0, 0]] * 10), "points must be finite: row 0"),
    (lambda g: g.fit_plane([[0, 0, 0], [1, 0, 0], [0, 1, 0], [float("nan"), 1, 0]]), "points must be finite: row 3"),
    (lambda g: g.fit_circle_2d([[float("inf"), 0], [1, 0], [0, 1]]), "points must be finite"),
    (lambda g: g.fit_ring_axis([[float("nan")] * 3] * 6), "points must be finite"),
    (lambda g: g.smallest_enclosing_sphere([[0, 0, float("nan")]] * 4), "points must be finite"),
    (lambda g: g.kabsch([[float("nan")] * 3] * 3, [[0.0] * 3] * 3), "points must be finite"),
    (lambda g: g.kabsch([[0.0] * 3] * 3, [[0.0] * 3] * 4), "must have one shape"),
    (lambda g: g.fit_cylinder("abc"), r"an \(N, 3\) array of numbers"),
])
def test_a_geometry_fit_of_points_that_are_not_numbers_is_a_value_error(call, match, capfd):
    """NaN or infinite points reached LAPACK, which printed "** On entry to DLASCL parameter number 4 had an illegal
    value" on standard error and raised LinAlgError (neither a ValueError nor the toolkit's error). One check of the
    point arrays for every fit."""
    from arm_model import geometry
    with pytest.raises(ValueError, match=match):
        call(geometry)
    assert "DLASCL" not in capfd.readouterr().err


def test_simulate_and_monte_carlo_refuse_arguments_of_the_wrong_kind(nominal):
    """`simulate("c.toml")` ended in AttributeError ('str' object has no attribute 'seed'); `simulate(c, seed=1.5)`
    and `seed="3"` ran as seeds 1 and 3; `monte_carlo(source, 0)` and `runs=-1` returned an empty study."""
    from arm_model.sim import load_campaign, simulate
    from calibration.study import SynthSource, monte_carlo
    with pytest.raises(TypeError, match="campaign must be a Campaign"):
        simulate("c.toml")
    camp = load_campaign(NOMINAL.parents[1] / "examples" / "campaigns" / "calibration.toml")
    for bad in (1.5, "3", -1, True):
        with pytest.raises(ValueError, match="seed must be a whole number >= 0"):
            simulate(camp, seed=bad)
    for runs in (0, -1, 2.0):
        with pytest.raises(ValueError, match="runs must be a whole number >= 1"):
            monte_carlo(SynthSource(nominal, None), runs, progress=False)
    with pytest.raises(ValueError, match="seed must be a whole number >= 0"):
        monte_carlo(SynthSource(nominal, None), 1, seed=-1, progress=False)


# ---------------------------------------------------------------------------------------------
# campaign files: cone half-angles and spreads in range; an error at the key's own line

@pytest.mark.parametrize("task, line, key, words", [
    ('kind = "seat"\nstylus_cone_deg = 200.0\n', 5, "task[1].stylus_cone_deg", "from 0 to 180 deg, got 200 deg"),
    ('kind = "seat"\nstylus_cone_deg = -1.0\n', 5, "task[1].stylus_cone_deg", "from 0 to 180 deg, got -1 deg"),
    ('kind = "sphere"\npolar_max_rad = 4.0\n', 5, "task[1].polar_max_rad", "got 229.183 deg"),
    ('kind = "ring"\nangle_jitter_deg = -1\n', 5, "task[1].angle_jitter_deg", "must not be negative"),
])
def test_a_campaign_cone_beyond_a_half_turn_or_a_negative_spread_is_refused(tmp_path, capsys, task, line, key,
                                                                            words):
    """`stylus_cone_deg = 200` (or -1) drew the stylus from another cone than the one written (cos 200 deg is cos
    160 deg), `angle_jitter_deg = -1` a spread of 1 deg; and errors of a key given with its unit named the line of
    its table, not its own."""
    camp = tmp_path / "c.toml"
    camp.write_text(f'arm = "aacmm7"\nsensor = "none"\n[[task]]\n{task}')
    rc = _exit(["simulate", str(camp), "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and f"c.toml, line {line}, key '{key}'" in err and words in err, err
    assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------------------------------------
# ids the toolkit writes into its CSV files are one line of text

def test_a_session_measurement_id_with_a_line_break_is_refused_before_any_write(tmp_path, capsys):
    """A plan with `measurement = "a\\nb"` ran a session whose points.csv its own points reader refuses ("not valid
    CSV: unexpected end of data", so `aacmm tip` and `calibrate` could not read the session); the same from
    --measurement or a session folder named with a line break."""
    samples = NOMINAL.parents[1] / "examples" / "live" / "samples.csv"
    plan = tmp_path / "plan.toml"
    plan.write_text('measurement = "a\\nb"\n[[feature]]\nid = "s"\nkind = "seat"\n')
    for extra, out, words in ((["--plan", str(plan)], "s1", "plan.toml, line 1, key 'measurement'"),
                              (["--measurement", "a\tb"], "s2", "the measurement id (--measurement)"),
                              ([], "s\n3", "argument -o/--output: the path")):  # refused as a path
        rc = _exit(["live", str(samples), "--arm", "aacmm7", "--speed", "0", "-o", str(tmp_path / out), *extra])
        err = capsys.readouterr().err
        assert rc == 2 and words in err and "one line of text without control characters" in err, err
        assert not (tmp_path / out).exists()


def test_a_feature_id_with_a_line_break_is_refused_by_the_artefacts_reader_and_in_python():
    from arm_model.errors import InputError
    from arm_model.io import Feature, parse_artefacts
    with pytest.raises(InputError, match=r"a.toml, line 2, key 'feature\[1\].id': 'id' must be one line"):
        parse_artefacts('[[feature]]\nid = "x\\ny"\nkind = "seat"\n', "a.toml")
    with pytest.raises(ValueError, match="Feature: id must be one line of text"):
        Feature("x\ry", "seat")


def test_a_number_without_a_unit_out_of_range_is_said_without_a_stray_blank():
    """`<mimic multiplier="1e300">` said "1e+300  is not a plausible ratio (|value| at most 1000 ); check the number
    and its unit" (a ratio has no unit)."""
    from arm_model.units import implausible
    assert implausible(1e300, "ratio")[1] == "1e+300 is not a plausible ratio (|value| at most 1000); check the number"
    assert implausible(2e3, "length")[1].startswith("2e+06 mm is not a plausible length (|value| at most 1e+06 mm)")
