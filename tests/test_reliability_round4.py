"""Reliability, round 4: a hostile-input audit of the growing model discrepancy's model-file keys
([calibration] model_discrepancy_growth_um_per_mm, training_poses naming a points file beside the model file)
through the commands that read a model file (tip, view, ring, live) and the Python API. Each test is named after
what it checks; all are fast (a few points, no fit)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from arm_model import InputError
from arm_model.cli import main
from conftest import NOMINAL

GROWTH = "model_discrepancy_um = 5.0\nmodel_discrepancy_growth_um_per_mm = 20.0\n"
Q_DEG = np.array([[10.0, 20.0, -30.0, 40.0, 5.0, -15.0, 25.0], [-10.0, 35.0, 12.0, -40.0, 8.0, 30.0, -5.0]])


def points_text(q_deg) -> str:
    cols = ",".join(f"q{k + 1}_deg" for k in range(q_deg.shape[1]))
    return f"measurement,feature,{cols}\n" + "".join(
        "m,seat," + ",".join(f"{x:.12g}" for x in row) + "\n" for row in q_deg)


@pytest.fixture
def folder(tmp_path):
    """A model file with a growth, its training poses beside it and a points file: tip reads them."""
    (tmp_path / "tp.csv").write_text(points_text(Q_DEG))
    (tmp_path / "points.csv").write_text(points_text(Q_DEG + 3.0))
    return tmp_path


def model(folder, calibration: str, name: str = "m.toml"):
    path = folder / name
    path.write_text(NOMINAL.read_text() + "\n[calibration]\n" + calibration)
    return path


def tip(folder, arm, out, *more) -> int:
    return main(["tip", str(folder / "points.csv"), "--arm", str(arm), "-o", str(out), "--uncertainty", *more])


# ---------------------------------------------------------------------------------------------
# outputs never over the training poses

def test_tip_output_over_the_training_poses_file_is_refused(folder, capsys):
    arm = model(folder, GROWTH + 'training_poses = "tp.csv"\n')
    before = (folder / "tp.csv").read_bytes()
    assert tip(folder, arm, folder / "tp.csv") == 2
    assert "over an input" in capsys.readouterr().err
    assert (folder / "tp.csv").read_bytes() == before


def test_the_arm_inputs_name_the_training_poses_file(folder):
    """Every command guards its outputs against arm_inputs: the training poses file is one of them (an output
    folder holding it, e.g. calibrate's -o of the run that wrote it, is refused as for the covariance file)."""
    import argparse

    from arm_model.cli_options import arm_inputs
    sub = folder / "run1"
    sub.mkdir()
    (sub / "tp.csv").write_text(points_text(Q_DEG))
    arm = model(folder, GROWTH + 'training_poses = "run1/tp.csv"\n')
    args = argparse.Namespace(arm=arm, tip_frame=None, masses=None, base_frame=None)
    assert any(str(p).endswith("tp.csv") for p in arm_inputs(args))


def test_ring_output_folder_holding_the_training_poses_is_refused(folder, capsys):
    from conftest import ROOT
    sub = folder / "poses"
    sub.mkdir()
    (sub / "tp.csv").write_text(points_text(Q_DEG))
    arm = model(folder, GROWTH + 'training_poses = "poses/tp.csv"\n')
    ring = ROOT / "examples" / "data" / "paper-ring-xyz"
    rc = main(["ring", str(ring / "points.csv"), str(ring / "artefacts.toml"), "--arm", str(arm), "-o", str(sub)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "over an input" in err and "tp.csv" in err, err
    assert (sub / "tp.csv").read_text() == points_text(Q_DEG)


# ---------------------------------------------------------------------------------------------
# what training_poses may name

def _refused(folder, arm, capsys, *needles) -> str:
    out = folder / "out.csv"
    assert tip(folder, arm, out) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and not out.exists(), err
    for n in needles:
        assert n in err, err
    return err


def test_training_poses_naming_the_model_file_itself_is_refused(folder, capsys):
    arm = model(folder, GROWTH + 'training_poses = "m.toml"\n')
    _refused(folder, arm, capsys, "m.toml", "key 'calibration.training_poses'", "the model file itself")


def test_training_poses_naming_the_covariance_file_is_refused(folder, capsys):
    (folder / "c.csv").write_text("parameter,unit,value,u\n")
    arm = model(folder, GROWTH + 'covariance = "c.csv"\ntraining_poses = "c.csv"\n')
    _refused(folder, arm, capsys, "m.toml", "key 'calibration.training_poses'", "covariance file")


def test_training_poses_as_an_absolute_path_is_refused(folder, capsys):
    arm = model(folder, GROWTH + f'training_poses = "{folder / "tp.csv"}"\n')
    _refused(folder, arm, capsys, "m.toml", "key 'calibration.training_poses'", "relative to the model file")


@pytest.mark.parametrize("name", ["sub", "."])
def test_training_poses_naming_a_folder_says_it_is_a_folder(folder, capsys, name):
    (folder / "sub").mkdir()
    arm = model(folder, GROWTH + f'training_poses = "{name}"\n')
    err = _refused(folder, arm, capsys, "a folder")
    assert "no such file" not in err


def test_training_poses_naming_a_fifo_is_refused_without_waiting(folder, capsys):
    import os
    os.mkfifo(folder / "f")
    arm = model(folder, GROWTH + 'training_poses = "f"\n')
    err = _refused(folder, arm, capsys, "not a regular file")
    assert "no such file" not in err


def test_training_poses_above_the_model_folder_are_read(folder):
    """'..' is a relative path like any other: a model file in a sub-folder reads its poses above it."""
    from arm_model.model_file import read_model_file
    sub = folder / "models"
    sub.mkdir()
    arm = read_model_file(model(sub, GROWTH + 'training_poses = "../tp.csv"\n'))
    assert arm.discrepancy.training.q.shape == Q_DEG.shape


@pytest.mark.parametrize("rows, needle", [
    ("", "empty"),
    ("measurement,feature," + ",".join(f"q{k + 1}_deg" for k in range(7)) + "\n", "no points"),
])
def test_training_poses_without_a_pose_are_refused(folder, capsys, rows, needle):
    (folder / "tp.csv").write_text(rows)
    arm = model(folder, GROWTH + 'training_poses = "tp.csv"\n')
    _refused(folder, arm, capsys, "tp.csv", needle)


@pytest.mark.parametrize("cell, needle", [("nan", "finite"), ("inf", "finite"), ("1e300", "plausible"),
                                          ("-1e6", "plausible"), ("x", "")])
def test_training_poses_with_a_bad_angle_name_the_line_and_column(folder, capsys, cell, needle):
    text = points_text(Q_DEG).splitlines()
    cells = text[2].split(",")
    cells[4] = cell
    text[2] = ",".join(cells)
    (folder / "tp.csv").write_text("\n".join(text) + "\n")
    arm = model(folder, GROWTH + 'training_poses = "tp.csv"\n')
    _refused(folder, arm, capsys, "tp.csv, line 3", "q3_deg", needle)


@pytest.mark.parametrize("q", [Q_DEG[:, :6], np.hstack([Q_DEG, Q_DEG[:, :1]])])
def test_training_poses_of_another_joint_count_are_refused(folder, capsys, q):
    (folder / "tp.csv").write_text(points_text(q))
    arm = model(folder, GROWTH + 'training_poses = "tp.csv"\n')
    _refused(folder, arm, capsys, "tp.csv, line 1", "the arm has 7 joints")


def test_duplicate_training_poses_read_as_one(folder):
    """A pose given twice (a seat probed twice) is a training pose like any other: d is the same."""
    from arm_model.model_file import load_model
    one = load_model(model(folder, GROWTH + 'training_poses = "tp.csv"\n')).discrepancy
    (folder / "tp2.csv").write_text(points_text(np.vstack([Q_DEG, Q_DEG])))
    two = load_model(model(folder, GROWTH + 'training_poses = "tp2.csv"\n', "m2.toml")).discrepancy
    q = np.radians(Q_DEG + 7.0)
    np.testing.assert_array_equal(one.sd(load_model(folder / "m.toml").desc, q),
                                  two.sd(load_model(folder / "m.toml").desc, q))


# ---------------------------------------------------------------------------------------------
# the Python API

@pytest.mark.parametrize("kw, match", [
    ({"discrepancy_growth": 0.02, "training_poses": "tp.csv"}, "model_discrepancy"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": 0.02}, "training_poses"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": -0.02, "training_poses": "tp.csv"}, "growth"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": math.nan, "training_poses": "tp.csv"}, "growth"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": math.inf, "training_poses": "tp.csv"}, "growth"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": 1e3, "training_poses": "tp.csv"}, "growth"),
    ({"model_discrepancy": math.nan}, "model_discrepancy"),
    ({"model_discrepancy": 1.0}, "model_discrepancy"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": 0.02, "training_poses": "/abs/tp.csv"}, "training_poses"),
])
def test_format_model_never_writes_a_discrepancy_its_reader_refuses(kw, match):
    """format_model (the API every writer uses) refuses what parse_model would refuse, instead of writing a model
    file that no command reads."""
    from arm_model.model_file import format_model, parse_model
    desc = parse_model(NOMINAL.read_text(), str(NOMINAL)).desc
    with pytest.raises(ValueError, match=match):
        format_model(desc, **kw)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sigma=st.floats(0, 1e5), growth=st.floats(0, 1e5), name=st.from_regex(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,20}",
                                                                             fullmatch=True))
def test_a_written_discrepancy_reads_back(sigma, growth, name):
    """Any sigma0 [um] and growth [um/mm] in range and any plain file name: format_model's text reads back to the
    same values (4 significant digits) and the same file name."""
    from arm_model.model_file import format_model, parse_model
    desc = parse_model(NOMINAL.read_text(), str(NOMINAL)).desc
    text = format_model(desc, model_discrepancy=sigma * 1e-6, discrepancy_growth=growth * 1e-3, training_poses=name)
    arm = parse_model(text, "/nowhere/m.toml")
    assert arm.model_discrepancy == pytest.approx(sigma * 1e-6, rel=6e-4, abs=1e-300)
    assert arm.discrepancy_growth == pytest.approx(growth * 1e-3, rel=6e-4, abs=1e-300)
    assert arm.training_poses.name == name


_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**20, 10**20), st.booleans(),
                    st.text(max_size=12), st.just(""), st.just("m.toml"), st.just("/etc/passwd"), st.just(".."),
                    st.lists(st.integers(), max_size=2))


@settings(max_examples=80, deadline=None)       # 80: each of the six keys in about 30 tables
@given(cal=st.dictionaries(st.sampled_from(["model_discrepancy_um", "model_discrepancy_growth_um_per_mm",
                                            "training_poses", "covariance", "probing_scatter_um", "bogus_key"]),
                           _VALUES, max_size=4))
def test_any_calibration_table_reads_or_says_where(cal):
    """Any [calibration] table of the discrepancy keys (any TOML value): the model file reads, or an InputError
    names the file and the key; the discrepancy of what reads is either None, a finite constant or a growth with
    its training poses named."""
    import tomllib

    from arm_model.description import toml_text
    from arm_model.model_file import parse_model
    try:
        text = NOMINAL.read_text() + "\n" + toml_text({"calibration": cal}, None)
        tomllib.loads(text)
    except (ValueError, TypeError):
        return                          # not writable as TOML (e.g. a NUL in a string)
    try:
        arm = parse_model(text, "/nowhere/m.toml")
    except InputError as exc:
        assert exc.path == "/nowhere/m.toml" and "calibration" in (exc.column or ""), exc
        return
    for v in (arm.model_discrepancy, arm.discrepancy_growth):
        assert v is None or (math.isfinite(v) and v >= 0)
    if arm.discrepancy_growth:
        assert arm.model_discrepancy is not None and arm.training_poses is not None


# ---------------------------------------------------------------------------------------------
# --prior-scale at the boundary

@pytest.mark.parametrize("command", ["calibrate", "close-loop"])
@pytest.mark.parametrize("value", ["1e-300", "5e-324", "1e-7"])
def test_a_prior_scale_factor_too_small_to_weigh_is_refused(tmp_path, capsys, command, value):
    """A factor below 1e-6 (1 nm on a 1 mm plausible size) divides by zero in the prior's weights (1e-300) or
    stalls the fit on NaN (5e-324): refused at the option, exit 2, nothing written."""
    from conftest import ROOT
    ring = ROOT / "examples" / "data" / "paper-ring-xyz"
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main([command, str(ring / "points.csv"), str(ring / "artefacts.toml"), "--arm", str(NOMINAL),
              "-o", str(out), "--prior-scale", value])
    assert exc.value.code == 2 and not out.exists()
    assert "--prior-scale" in capsys.readouterr().err


def test_close_loop_prior_scale_error_lists_auto(capsys):
    """close-loop's --prior-scale takes auto (its default): a bad value's message lists it with the others."""
    with pytest.raises(SystemExit):
        main(["close-loop", "p.csv", "a.toml", "--arm", str(NOMINAL), "-o", "out", "--prior-scale", "often"])
    err = capsys.readouterr().err
    assert "expected auto, evidence, off or a number" in err, err


# ---------------------------------------------------------------------------------------------
# the discrepancy's Python API

def test_training_poses_beyond_plausible_joint_values_are_refused_by_the_api(nominal):
    """TrainingPoses range-checks as the points reader does (|angle| <= 10000 deg, |length| <= 1000 m): at 1e300
    rad the levers' central differences vanish (q + 1e-6 == q) and every pose would lie at d = 0."""
    from arm_model.discrepancy import TrainingPoses
    with pytest.raises(ValueError, match="plausible"):
        TrainingPoses.of(nominal, np.full((1, nominal.n_joints), 1e300))
    TrainingPoses.of(nominal, np.full((1, nominal.n_joints), math.radians(9999.0)))


@pytest.mark.filterwarnings("error::RuntimeWarning")
@pytest.mark.parametrize("bad", [math.nan, math.inf, 1e300])
def test_a_growing_discrepancy_refuses_poses_it_cannot_measure(nominal, bad):
    """sd and distance at a NaN, infinite or implausible pose: a ValueError, never a NaN or a silent d = 0; checked
    before the chain is evaluated there (sd evaluated the levers at an infinite angle first: NaN, 'invalid value
    encountered in sin')."""
    from arm_model.discrepancy import GrowingDiscrepancy, TrainingPoses
    g = GrowingDiscrepancy(5e-6, 0.02, TrainingPoses.of(nominal, np.zeros((2, nominal.n_joints))))
    q = np.zeros((3, nominal.n_joints))
    q[1, 2] = bad
    for f in (g.sd, g.distance):
        with pytest.raises(ValueError, match="pose"):
            f(nominal, q)


# ---------------------------------------------------------------------------------------------
# the files a calibration writes, named after the arm

@pytest.mark.parametrize("name", ["語" * 100, "𝒜" * 120, "é" * 119 + "x", "a" * 300],
                         ids=["cjk-100", "math-script-120", "accented-120", "ascii-300"])
def test_the_model_files_of_a_long_arm_name_in_any_script_fit_a_file_name(name):
    """An arm named by 100 CJK characters (300 bytes in UTF-8) made calibrate fit, then fail on writing
    '<name>-calibrated-covariance.csv' (File name too long): every file named after the arm (model, covariance,
    URDF, training poses) stays within the 255 bytes of a file name."""
    from arm_model.output import safe_name
    from calibration.model_output import model_paths
    for path in model_paths("/x", name + "-calibrated").values():
        assert len(path.name.encode("utf-8")) <= 255, path.name
    assert safe_name(name) == safe_name(name) and len(safe_name(name).encode("utf-8")) <= 120


# ---------------------------------------------------------------------------------------------
# the default joint compliance of a robot with masses

def test_a_robot_without_a_revolute_joint_gets_no_default_joint_compliance():
    """A gantry (every joint prismatic) whose links carry masses: the joint compliance (revolute joints only) would
    hold no parameter, yet be logged and listed in summary.json's base_effects, and turn close-loop's
    --prior-scale auto to evidence. The default adds none."""
    import re

    from arm_model.model import ArmModel
    from arm_model.model_file import parse_model
    from calibration.calibrate import gravity_compliance
    text = NOMINAL.read_text().replace("[[joint]]\n", '[[joint]]\ntype = "prismatic"\n')
    text = re.sub(r"(lower|upper)_deg = .*\n", "", text).replace("encoder_resolution_deg", "encoder_resolution_mm")
    desc = parse_model(text, "gantry.toml").desc
    assert all(j.prismatic for j in desc.encoders) and any(j.mass > 0 for j in desc.joints)
    assert gravity_compliance(ArmModel(desc)) == ()
    assert gravity_compliance(ArmModel(parse_model(NOMINAL.read_text(), str(NOMINAL)).desc)) != ()


@pytest.mark.parametrize("text", ["root:x:0:0:root:/root:/bin/bash\n",
                                  "measurement,feature,q1_deg\nm,s,1\n"], ids=["not-a-points-file", "one-joint"])
def test_a_bad_training_poses_file_says_whose_it_is(folder, capsys, text):
    """The training poses' points file is not on the command line: its error names it, the line and the column,
    and says it is the model file's training poses (a user looking for 'tp.csv' among their inputs finds why)."""
    (folder / "tp.csv").write_text(text)
    arm = model(folder, GROWTH + 'training_poses = "tp.csv"\n')
    _refused(folder, arm, capsys, "tp.csv, line 1", "[calibration] training_poses")


@pytest.mark.parametrize("command", ["view", "ring", "live"])
def test_other_commands_with_a_missing_training_poses_file_exit_2_and_write_nothing(folder, capsys, command):
    """view --ellipsoids, ring and live add the model discrepancy as tip does: a model file whose training poses
    are gone is one error naming the file, exit 2, nothing written."""
    from conftest import ROOT
    ring = ROOT / "examples" / "data" / "paper-ring-xyz"
    arm = model(folder, GROWTH + 'training_poses = "gone.csv"\n')
    out = folder / "out"
    argv = {"view": ["view", str(ring / "points.csv"), "--ellipsoids", "--html", str(out)],
            "ring": ["ring", str(ring / "points.csv"), str(ring / "artefacts.toml"), "-o", str(out)],
            "live": ["live", str(ROOT / "examples" / "live" / "samples.csv"), "-o", str(out)]}[command]
    assert main([*argv, "--arm", str(arm)]) == 2
    err = capsys.readouterr().err       # (pytest shows the viewer's libraries' deprecation warnings: not counted)
    errors = [line for line in err.splitlines() if not line.startswith("warning: DeprecationWarning")]
    assert len(errors) == 1 and "gone.csv" in errors[0] and "no such file" in errors[0] and "Traceback" not in err, err
    assert not out.exists()


def test_training_poses_linked_to_the_model_file_is_refused(folder, capsys):
    """A symbolic link to the model file is the model file: refused at the key, as its own name is."""
    import os
    os.symlink("m.toml", folder / "link.csv")
    arm = model(folder, GROWTH + 'training_poses = "link.csv"\n')
    _refused(folder, arm, capsys, "m.toml", "key 'calibration.training_poses'", "the model file itself")


def test_training_poses_linked_to_a_points_file_elsewhere_are_read(folder, tmp_path_factory):
    """A link to a real points file (a folder of shared poses) reads like the file itself."""
    import os

    from arm_model.model_file import read_model_file
    other = tmp_path_factory.mktemp("shared") / "poses.csv"
    other.write_text(points_text(Q_DEG))
    os.symlink(other, folder / "link.csv")
    arm = read_model_file(model(folder, GROWTH + 'training_poses = "link.csv"\n'))
    np.testing.assert_allclose(arm.discrepancy.training.q, np.radians(Q_DEG), rtol=0, atol=1e-12)


def test_effect_none_with_another_effect_is_refused(tmp_path, capsys):
    """'--effect none' is the geometry alone: with another --effect it contradicts itself (it was ignored and the
    other effect fitted)."""
    from conftest import ROOT
    ring = ROOT / "examples" / "data" / "paper-ring-xyz"
    for command in ("calibrate", "close-loop"):
        rc = main([command, str(ring / "points.csv"), str(ring / "artefacts.toml"), "--arm", str(NOMINAL), "-o",
                   str(tmp_path / command), "--effect", "none", "--effect", "joint_compliance"])
        assert rc == 2 and not (tmp_path / command).exists()
        assert "--effect none" in capsys.readouterr().err


def test_a_live_session_from_python_adds_the_model_files_discrepancy(folder):
    """Session(arm=<model file>) without inputs takes the arm's default input uncertainties: with the model file's
    probing scatter, also its model discrepancy (constant and growing), as `aacmm live` and `tip` do (it was left
    out: every point's uncertainty without the discrepancy)."""
    from arm_model.live.session import Session
    from arm_model.model_file import load_model
    path = model(folder, GROWTH + 'training_poses = "tp.csv"\n')
    session = Session(path)
    inputs = session.input_uncertainty(force=False)
    assert inputs.discrepancy == pytest.approx(5e-6)
    assert inputs.growing is not None and inputs.growing.growth == pytest.approx(0.02)
    q = np.radians(Q_DEG + 3.0)
    np.testing.assert_allclose(inputs.discrepancy_sd(session.desc, q),
                               load_model(path).discrepancy.sd(session.desc, q), rtol=1e-12)


def test_a_given_model_discrepancy_does_not_need_the_training_poses(folder, capsys):
    """--u-model-discrepancy-um replaces the model file's discrepancy, its growth too (docs/uncertainty.md): tip then
    has no use for the training poses and runs without them (it stopped at the missing file)."""
    arm = model(folder, GROWTH + 'training_poses = "gone.csv"\n')
    out = folder / "out.csv"
    assert tip(folder, arm, out, "--u-model-discrepancy-um", "7") == 0
    assert "model discrepancy    7.000    7.000    7.000   given" in capsys.readouterr().out
    out.unlink()
    assert _refused(folder, arm, capsys, "gone.csv")        # without it, the growth needs them
