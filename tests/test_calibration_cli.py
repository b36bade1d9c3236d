"""``aacmm calibrate`` and ``aacmm study poses`` end to end on files; bad input stops with one clear
message and writes nothing; outputs never overwrite inputs."""
from __future__ import annotations

import json

import pytest

from arm_model import load_description
from arm_model.cli import main
from arm_model.errors import InputError
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from conftest import NOMINAL


@pytest.fixture(scope="module")
def files(tmp_path_factory, nominal):
    model = ArmModel(nominal)
    c = make_campaign(model, SynthSpec(ballbars=8, ballbar_points=5, seats=3, articulations=8, spheres=2,
                                       sphere_points=10, reference_points=30, force=1.0, noise=2e-6,
                                       reference_noise=3e-6), seed=31)
    out = tmp_path_factory.mktemp("campaign")
    return c, c.write(out)


def test_calibrate_end_to_end(files, tmp_path, capsys):
    c, f = files
    out = tmp_path / "out"
    code = main(["calibrate", str(f["points"]), str(f["artefacts"]), "--arm", str(NOMINAL), "--reference-points",
                 str(f["reference"]), "--holdout", "0.25", "--sigma-probe-um", "2", "--sigma-ref-um", "3",
                 "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0
    assert "fixed j1.theta_offset" in text and "held-out" in text
    names = {p.name for p in out.iterdir()}
    assert {"aacmm7-calibrated.toml", "aacmm7-calibrated.urdf", "summary.json", "report.html", "parameters.csv",
            "residuals.csv", "residuals.png", "parameters.png", "correlation.png"} <= names
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"].startswith("converged")
    assert {"parameters", "fixed", "correlation", "identifiability_final", "validation_holdout"} <= set(summary)
    assert any(r["name"] == "j1.theta_offset" and r["state"] == "fixed" for r in summary["parameters"])
    assert summary["validation_holdout"]
    # each held-out figure with its bootstrap uncertainty (more than one held-out measurement here)
    held = {r["key"]: r for r in summary["validation_holdout"]}
    assert len(summary["holdout"]) >= 2
    assert all(r["u_after"] is not None and 0 < r["u_after"] for k, r in held.items()
               if k.startswith(("length", "reference")))
    assert " ± " in text
    # the calibrated description reads back and carries the estimated errors
    cal = load_description(out / "aacmm7-calibrated.toml")
    nom = load_description(NOMINAL)
    row = {r["name"]: r for r in summary["parameters"]}
    assert cal.name == "aacmm7-calibrated"
    assert abs(cal.joints[2].d - nom.joints[2].d - row["j3.d"]["value"]) < 1e-12
    assert abs(row["j3.d"]["value"] - c.truth["j3.d"]) < 4 * row["j3.d"]["u"]
    assert "<robot" in (out / "aacmm7-calibrated.urdf").read_text()
    assert (out / "residuals.png").read_bytes()[:4] == b"\x89PNG"


def test_refuses_to_write_over_an_input(files, tmp_path, capsys):
    _, f = files
    before = f["points"].read_bytes()
    code = main(["calibrate", str(f["points"]), str(f["artefacts"]), "--arm", str(NOMINAL), "-o", str(f["points"])])
    assert code == 2 and "refusing" in capsys.readouterr().err
    assert f["points"].read_bytes() == before


def test_bad_input_names_file_line_and_column(files, tmp_path, capsys):
    _, f = files
    lines = f["points"].read_text().splitlines()
    lines[5] = lines[5].replace("seat", "no-such-feature", 1) if "seat" in lines[5] else \
        ",".join(["m", "no-such-feature"] + lines[5].split(",")[2:])
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    code = main(["calibrate", str(bad), str(f["artefacts"]), "--arm", str(NOMINAL), "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert "bad.csv" in err and "line 6" in err and "'feature'" in err and "no-such-feature" in err
    assert not out.exists()


def test_stop_policy_exits_with_the_list(files, tmp_path, capsys):
    _, f = files
    code = main(["calibrate", str(f["points"]), str(f["artefacts"]), "--arm", str(NOMINAL),
                 "--on-unidentifiable", "stop", "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err
    # a rank deficiency is a numerical failure: its own exit status (docs/guarantees.md, section 4)
    assert code == 4 and "numerical failure:" in err and "j1.theta_offset" in err and "cannot identify" in err
    assert not (tmp_path / "o").exists()


def test_unknown_parameter_pattern(files, tmp_path, capsys):
    _, f = files
    code = main(["calibrate", str(f["points"]), str(f["artefacts"]), "--arm", str(NOMINAL), "--free", "j9.*",
                 "-o", str(tmp_path / "o")])
    assert code == 2 and "'j9.*' matches no parameter" in capsys.readouterr().err


def test_study_poses(files, tmp_path, capsys):
    _, f = files
    code = main(["study", "poses", str(f["points"]), str(f["artefacts"]), "--arm", str(NOMINAL), "--count", "6",
                 "-q", "-o", str(tmp_path)])
    assert code == 0
    sel = json.loads((tmp_path / "poses.json").read_text())
    assert len(sel["chosen"]) == 6 and len(set(sel["chosen"])) == 6
    # O1 is per pose (it may fall as poses are added); the greedy sets beat random ones of each size
    assert all(o > r for o, r in zip(sel["o1"], sel["o1_random"], strict=True))
    assert set(sel["u_chosen"]) == set(sel["parameters"])
    assert all(sel["u_chosen"][k] >= sel["u_pool"][k] * (1 - 1e-9) for k in sel["parameters"])
    import hashlib

    from arm_model.shipped import version
    assert sel["aacmm_version"] == version()
    assert sel["input_sha256"][str(f["points"])] == hashlib.sha256(f["points"].read_bytes()).hexdigest()


PANDA = __import__("conftest").ROOT / "examples" / "data" / "real-panda-seats"


@pytest.mark.parametrize("command, urdf, effect, words", [
    ("calibrate", "panda.urdf", "probe_compliance", "is driven by the measured contact force"),
    ("calibrate", "panda-with-inertials.urdf", "force_sensor", "is driven by the measured contact force"),
    ("calibrate", "panda.urdf", "joint_compliance", "while the arm has no masses"),
    ("close-loop", "panda.urdf", "probe_compliance_matrix", "is driven by the measured contact force"),
    ("close-loop", "panda.urdf", "lateral_compliance", "while the arm has no masses"),
])
def test_an_effect_nothing_in_the_data_drives_is_refused(tmp_path, capsys, command, urdf, effect, words):
    """Points without force columns: an effect the measured force alone drives, or a joint's compliance on an arm
    without masses, was held at zero as if estimated ("no effect on the data"); refused, naming the option and the
    file, exit 2, nothing written."""
    points = PANDA / "front" / "points.csv"
    out = tmp_path / "out"
    code = main([command, str(points), str(PANDA / "artefacts.toml"), "--arm", str(PANDA / urdf), "--tip-frame",
                 "ball_link", "--effect", effect, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert f"{points}, line 1: --effect {effect} " in err and words in err, err
    assert f"{points} holds no force columns (fx_N, fy_N, fz_N)" in err, err
    assert not out.exists()


def _refused(tmp_path, capsys, command, points, *options) -> str:
    """The standard error of ``command`` on ``points`` of the Panda's seats (its artefacts, its URDF without masses)
    with ``options``, asserted refused: exit 2, no traceback or internal error, nothing written."""
    out = tmp_path / "out"
    code = main([command, str(points), str(PANDA / "artefacts.toml"), "--arm", str(PANDA / "panda.urdf"),
                 "--tip-frame", "ball_link", *options, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and "internal error" not in err, err
    assert not out.exists()
    return err


@pytest.mark.parametrize("command", ["calibrate", "close-loop"])
def test_a_probe_compliance_freed_on_data_without_force_is_refused(tmp_path, capsys, command):
    """`--free 'probe.*'` on points without force columns held the probe's compliances ("fixed: no effect on the
    data", exit 0) and wrote the model as if they had been estimated; refused as `--effect probe_compliance` is,
    naming the option and the file, exit 2, nothing written."""
    points = PANDA / "front" / "points.csv"
    err = _refused(tmp_path, capsys, command, points, "--free", "probe.*")
    assert f"{points}, line 1: --free probe.* names probe.compliance_x" in err, err
    assert f"{points} holds no force columns (fx_N, fy_N, fz_N)" in err, err


def test_a_probe_compliance_freed_is_kept_when_held_or_pushed():
    """The check of `--free` refuses only a force-driven parameter left free on data without force: one held by
    `--hold`, or on points with a force, passes; a pattern of other parameters passes."""
    from arm_model import read_points
    from arm_model.errors import InputError
    from arm_model.io import parse_points
    from arm_model.urdf_import import description_from_urdf
    from calibration.cli import refuse_undriven_free
    model = ArmModel(description_from_urdf(PANDA / "panda.urdf", "ball_link"), ())
    points = read_points(PANDA / "front" / "points.csv", model.desc.joint_quantities)
    refuse_undriven_free(model, ["probe.*"], ["probe.compliance_*"], points)
    refuse_undriven_free(model, ["probe.x", "panda_joint*.origin_z"], None, points)
    pushed = parse_points("measurement,feature," + ",".join(f"q{i}_rad" for i in range(1, 8)) + ",fx_N,fy_N,fz_N\n"
                          "m,f,0,0,0,-1,0,1,0,0,0,2\n", "f.csv", model.desc.joint_quantities)
    refuse_undriven_free(model, ["probe.*"], None, points, pushed)
    with pytest.raises(InputError, match="--free probe.compliance_z names probe.compliance_z, driven by"):
        refuse_undriven_free(model, ["probe.x", "probe.compliance_z"], None, points)


@pytest.mark.parametrize("command", ["calibrate", "close-loop"])
def test_a_thermal_effect_on_a_constant_temperature_is_refused(tmp_path, capsys, command):
    """`--effect thermal` on points at one temperature was fitted and written 'fixed' at zero ("no effect on the
    data" at 20 degC, "not separable" from the lengths elsewhere), exit 0; refused as the force-driven effects are,
    naming the option, the file and its temperature column, exit 2, nothing written."""
    lines = (PANDA / "front" / "points.csv").read_text().splitlines()
    points = tmp_path / "points.csv"
    points.write_text("\n".join([lines[0] + ",temperature_C"] + [row + ",21.5" for row in lines[1:]]) + "\n")
    err = _refused(tmp_path, capsys, command, points, "--effect", "thermal")
    assert f"{points}, line 1, column 'temperature_C': --effect thermal grows the links" in err, err
    assert "varies by 0 K only (at least 0.2 K needed" in err, err


def test_a_thermal_effect_over_a_temperature_range_is_kept():
    """The temperature check refuses a span below 0.2 K only, over all the points files of the fit together."""
    from arm_model.io import parse_points
    from arm_model.urdf_import import description_from_urdf
    from calibration.cli import refuse_undriven_effects
    desc = description_from_urdf(PANDA / "panda.urdf", "ball_link")
    head = "measurement,feature," + ",".join(f"q{i}_rad" for i in range(1, 8)) + ",fx_N,fy_N,fz_N,temperature_C\n"
    cold, warm = (parse_points(head + f"m,f,0,0,0,-1,0,1,0,0,0,2,{t}\nm,f,0,0,0,-1,0,1,0.1,0,0,2,{t}\n", f"{t}.csv",
                               desc.joint_quantities) for t in (20.0, 20.3))
    refuse_undriven_effects(("thermal",), desc, cold, warm)
    with pytest.raises(InputError, match="varies by 0 K only"):
        refuse_undriven_effects(("thermal",), desc, cold, None)


def test_a_joint_compliance_under_gravity_alone_is_kept():
    """Without force, a robot's joints still bend under their links' weight: joint and lateral compliance are
    kept on an arm with masses; with a force column, every force-driven effect is."""
    from arm_model import read_points
    from arm_model.io import parse_points
    from arm_model.urdf_import import description_from_urdf
    from calibration.cli import FORCE_DRIVEN, LOAD_DRIVEN, refuse_undriven_effects
    desc = description_from_urdf(PANDA / "panda-with-inertials.urdf", "ball_link")
    points = read_points(PANDA / "front" / "points.csv", desc.joint_quantities)
    refuse_undriven_effects(LOAD_DRIVEN, desc, points, None)
    pushed = parse_points("measurement,feature," + ",".join(f"q{i}_rad" for i in range(1, 8)) + ",fx_N,fy_N,fz_N\n"
                          "m,f,0,0,0,-1,0,1,0,0,0,2\n", "f.csv", desc.joint_quantities)
    refuse_undriven_effects(FORCE_DRIVEN + LOAD_DRIVEN, description_from_urdf(PANDA / "panda.urdf", "ball_link"),
                            points, pushed)


@pytest.mark.parametrize("name, words", [("a\nb.csv", "without control characters"),
                                         ("a\u202eb.csv", "invisible or text-direction"),
                                         ("a.csv ", "begin or end with white space")])
def test_a_points_file_residuals_csv_cannot_name_is_refused_before_the_fit(tmp_path, capsys, name, words):
    """residuals.csv names each point by its file: a points file named with a line break, a text-direction
    character or a trailing space made calibrate fit, then stop at the read-back of residuals.csv, exit 3 ("internal
    error ... please report it"); refused by the command line's path type before any work, exit 2, nothing
    written."""
    from conftest import exit_status
    points = tmp_path / name
    points.write_text((PANDA / "front" / "points.csv").read_text())
    out = tmp_path / "out"
    code = exit_status(["calibrate", str(points), str(PANDA / "artefacts.toml"), "--arm", str(PANDA / "panda.urdf"),
                        "--tip-frame", "ball_link", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "argument points: the path must" in err and words in err, err
    assert not out.exists()


@pytest.mark.parametrize("option", [("--effect", "probe_compliance"), ("--free", "probe.*")])
def test_study_montecarlo_refuses_a_probe_compliance_without_a_force_sensor(tmp_path, capsys, option):
    """A campaign simulating no force sensor (sensor = "none": no force columns) with `--effect probe_compliance`
    or `--free 'probe.*'` ran every fit with the compliance held, exit 0 (and a biased probe.z, the contact still
    deflecting it); refused before any run, as calibrate refuses it on measured points, exit 2, nothing written."""
    root = __import__("conftest").ROOT
    text = (root / "examples" / "campaigns" / "calibration.toml").read_text()
    assert 'sensor = "xyz"' in text
    camp = tmp_path / "none.toml"
    camp.write_text(text.replace('sensor = "xyz"', 'sensor = "none"'))
    out = tmp_path / "out"
    code = main(["study", "montecarlo", str(camp), "--runs", "1", "--holdout", "0", *option, "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err, err
    assert f"{camp}, line 1: {' '.join(option)} " in err and "simulates no force sensor" in err, err
    assert not out.exists()


def test_prior_groups_is_an_option_of_the_fit():
    """``calibrate --prior-groups pooled`` is the fit's ``FitOptions.prior_groups`` (default separate)."""
    from arm_model.cli import build_parser
    from calibration.cli import fit_options
    argv = ["calibrate", "points.csv", "artefacts.toml", "--arm", str(NOMINAL), "-o", "out"]
    assert fit_options(build_parser(argv).parse_args(argv)).prior_groups == "separate"
    argv += ["--prior-groups", "pooled"]
    assert fit_options(build_parser(argv).parse_args(argv)).prior_groups == "pooled"
