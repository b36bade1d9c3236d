"""``aacmm close-loop``: files in, report out; bad input stops with one message and writes nothing."""
from __future__ import annotations

import json

import numpy as np
import pytest

from arm_model import InputError
from arm_model.cli import main
from arm_model.model_file import load_model
from arm_model.sim import campaign_from_dict, simulate
from conftest import NOMINAL

CAMPAIGN = {"seed": 11, "sensor": "xyz", "signals": {"enabled": False},
            "noise": {"probing_repeatability_um": 2.0},
            "truth": {"eccentricity": [{"joint": "j3", "amplitude_deg": 0.005, "phase_deg": -60.0}]},
            "task": [{"kind": "ballbar", "positions": 8, "length_mm": 600.0, "points_per_sphere": 4},
                     {"kind": "seat", "articulations": 8, "measurements": 4},
                     {"kind": "sphere", "points": 8, "measurements": 4}]}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    out = tmp_path_factory.mktemp("loop")
    simulate(campaign_from_dict(CAMPAIGN)).write(out)
    return out


def test_close_loop_writes_the_report(files, tmp_path, capsys):
    out = tmp_path / "loop"
    code = main(["close-loop", str(files / "points.csv"), str(files / "artefacts.toml"), "--arm", str(NOMINAL),
                 "--sigma-probe-um", "2", "--folds", "3", "--cv-top", "2", "--mpe-e-uni-um", "1000",
                 "--mpe-spat-um", "0.01", "-o", str(out)])
    assert code == 0
    printed = capsys.readouterr()
    assert "base model" in printed.out and "+ eccentricity j3" in printed.out
    assert "screening" in printed.err                       # progress on stderr
    s = json.loads((out / "summary.json").read_text())
    (eff,) = s["effects_added"]
    assert eff["name"] == "eccentricity j3" and eff["joint"] == "j3"
    names = {p["name"] for p in eff["parameters"]}
    assert {"j3.ecc1_cos", "j3.ecc1_sin", "j3.ecc1_amplitude"} <= names
    amp = next(p for p in eff["parameters"] if p["name"] == "j3.ecc1_amplitude")
    assert amp["display_value"] == pytest.approx(0.005, abs=3 * amp["display_u"] + 1e-5)
    assert eff["heldout_after"]["rms_um"] < eff["heldout_before"]["rms_um"]
    # the held-out RMS with its bootstrap uncertainty, also in the before/after table
    assert 0 < eff["heldout_after"]["u_rms_um"] < eff["heldout_after"]["rms_um"]
    assert all(r["u"]["rms_um"] > 0 for r in s["before_after"])
    assert s["structure_remains"] is False and "eccentricity j3" in s["verdict"]
    assert s["stages"][1]["cross_validation"][0]["passed"] is True
    # the stability rule stated and its figures: the one added far below its level (no fold required), yet every
    # fold better by --min-improvement
    cv = s["stages"][1]["cross_validation"][0]
    assert cv["wilcoxon_p_value"] < cv["threshold"] / 10 and cv["stability_required"] == 0.0
    assert cv["stability"] == 1.0 and min(cv["fold_relative_improvements"]) >= 0.02
    assert "every fold better" in s["decision_power"]["stability_rule"]
    html = (out / "report.html").read_text()
    assert "folds better" in html
    for png in ("before-after.png", "stage-1-screening.png", "stage-1-signature.png"):
        assert (out / png).stat().st_size > 1000 and png in html
    assert (out / "before-after.txt").read_text().startswith("held-out test set")
    # the model discrepancy of the model file written, reported as calibrate reports it (its section and plot)
    disc, written = s["model"]["model_discrepancy"], s["model"]["model_discrepancy"]["written"]
    arm = load_model(out / s["model"]["file"], None)
    if written["growth_um_per_mm"] is not None:     # per joint, with the estimates' uncertainty carried
        assert arm.model_discrepancy == pytest.approx(written["sigma0_um"] * 1e-6, rel=1e-3, abs=1e-10)
        np.testing.assert_allclose(arm.discrepancy_growth, np.array(written["growth_um_per_mm"]) * 1e-3,
                                   rtol=1e-3, atol=1e-10)
        assert s["model"]["training_poses"] == arm.training_poses.name
    else:                               # a growth floored at 0 resolves nothing: written as a constant
        assert arm.model_discrepancy == pytest.approx(disc["sigma_um"] * 1e-6, rel=1e-3, abs=1e-10)
        assert arm.discrepancy_growth is None and s["model"]["training_poses"] is None
    assert "<h2>Model discrepancy</h2>" in html and f"{disc['sigma_um']:.4g} um per axis" in html
    assert (out / "discrepancy.png").read_bytes()[:4] == b"\x89PNG" and "src='discrepancy.png'" in html
    # the standard tests as calibrate gives them (--mpe-*-um): the final model on every point, the design fit
    # on the outer test set; each verdict follows from the items written next to it
    conf = s["conformance"]
    assert conf["mpe_given"] and conf["mpe_um"] == {"e-uni": 1000.0, "spat": 0.01}
    for key in ("training", "holdout"):
        rows = {r["key"]: r for r in conf[key]}
        assert rows["e-uni"]["n"] > 0 and rows["spat"]["n"] > 0, key
        for r in rows.values():
            if r["mpe_um"] is not None and r["n"]:
                assert r["result"] == ("PASS" if max(abs(i["value_um"]) for i in r["items"]) <= r["mpe_um"]
                                       else "FAIL")
        assert rows["e-uni"]["result"] == "PASS" and rows["spat"]["result"] == "FAIL"
        assert rows["l-dia"]["result"] is None
        assert (out / f"conformance_{key}.png").read_bytes()[:4] == b"\x89PNG"
        assert f"conformance_{key}.png" in html
    # the training items are the whole campaign's (8 ball-bar positions), the held-out ones the outer test set's
    training = {r["key"]: r for r in conf["training"]}
    holdout = {r["key"]: r for r in conf["holdout"]}
    bars = [m for m in s["measurements"]["test"] if m.startswith("bar-pos")]
    assert training["e-uni"]["n"] == 8 and holdout["e-uni"]["n"] == len(bars) > 0, s["measurements"]
    assert "E_UNI on training data" in printed.out and "FAIL" in printed.out


class _BaseFit(Exception):
    """Raised in place of the loop's first fit (:func:`test_weights_stated_reach_the_base_fit`)."""


@pytest.mark.parametrize("weights, from_data", [("stated", False), ("data", True)])
def test_weights_stated_reach_the_base_fit(files, tmp_path, monkeypatch, weights, from_data):
    """The fast counterpart of :func:`test_weights_stated_keeps_the_stated_sigmas` (6.5 s of CPU, make test-slow):
    ``--weights stated`` reaches the loop's base fit, whose weights every later fit takes, as the stated 100 um with
    no noise from the data; ``--weights data`` as starting values. The base fit itself is not run (0.3 s)."""
    import calibration.loop.state as state
    seen = []

    def first_fit(model, data, options):
        seen.append(options)
        raise _BaseFit

    monkeypatch.setattr(state, "calibrate", first_fit)
    main(["close-loop", str(files / "points.csv"), str(files / "artefacts.toml"), "--arm", str(NOMINAL),
          "--sigma-probe-um", "100", "--max-effects", "0", "--candidates", "eccentricity", "--library-only",
          "--no-plots", "--weights", weights, "-o", str(tmp_path / "loop")])
    (options,) = seen
    assert options.weights.probe == pytest.approx(100e-6) and "probe" not in options.weights.defaulted
    assert options.weights.factors == () and options.weights_from_data is from_data
    assert not (tmp_path / "loop").exists()


@pytest.mark.slow
def test_weights_stated_keeps_the_stated_sigmas(files, tmp_path):
    """``--weights stated`` (once ignored by close-loop): every fit weights its rows by the stated 100 um, with no
    factor from the data (``--weights data``, the default, would scale each row group to its residuals: s0 about 1),
    so the base fit's s0 is the residual's scatter (the probing noise and the eccentricity left out, about 15 um)
    over 100 um; summary.json's stage fits say so, the reference's sigma nobody stated and no row used null."""
    out = tmp_path / "loop"
    assert main(["close-loop", str(files / "points.csv"), str(files / "artefacts.toml"), "--arm", str(NOMINAL),
                 "--sigma-probe-um", "100", "--max-effects", "0", "--candidates", "eccentricity", "--library-only",
                 "--no-plots", "--weights", "stated",
                 "-o", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["settings"]["weights_from_data"] is False
    (stage,) = s["stages"]
    noise = stage["fit"]["noise"]
    assert noise["probe_um"] == pytest.approx(100.0) and noise["factors"] == {} and not noise["from_data"], noise
    assert noise["reference_um"] is None and noise["defaulted"] == ["reference"], noise
    assert 0.03 < stage["fit"]["s0"] < 0.4, stage["fit"]["s0"]


def test_refuses_to_write_over_an_input(files, tmp_path, capsys):
    points = tmp_path / "summary.json"                  # an input where the report would go
    points.write_text((files / "points.csv").read_text())
    before = points.read_text()
    code = main(["close-loop", str(points), str(files / "artefacts.toml"), "--arm", str(NOMINAL), "-o", str(tmp_path)])
    assert code == 2
    assert "over an input" in capsys.readouterr().err
    assert points.read_text() == before
    assert not (tmp_path / "report.html").exists()


def test_bad_options_stop_with_one_message(files, tmp_path, capsys):
    out = tmp_path / "x"
    code = main(["close-loop", str(files / "points.csv"), str(files / "artefacts.toml"), "--arm", str(NOMINAL),
                 "--candidates", "eccentricity,gravity", "-o", str(out)])
    assert code == 2
    assert "unknown candidate family gravity" in capsys.readouterr().err
    assert not out.exists()
    bad = tmp_path / "points.csv"
    bad.write_text((files / "points.csv").read_text().replace("q2_deg", "q2", 1))
    code = main(["close-loop", str(bad), str(files / "artefacts.toml"), "--arm", str(NOMINAL), "-o", str(out)])
    assert code == 2
    err = capsys.readouterr().err
    assert "points.csv" in err and "q2" in err
    assert not out.exists()


@pytest.mark.slow   # make test-slow: the API side is held in make test by test_loop_cross_harmonics (built) and
#                     test_loop_honesty (the library alone)
def test_effect_built_from_the_residual_and_library_only(tmp_path, capsys):
    """A third harmonic of the wrist j6 hidden in the simulator's truth: by default the loop builds it from
    the residual (summary.json origin "residual"); with --library-only it adds nothing."""
    camp = {**CAMPAIGN, "seed": 3,
            "truth": {"harmonics": [{"joint": "j6", "harmonic": 3, "amplitude_deg": 0.004, "phase_deg": 30.0}]},
            "task": [{"kind": "ballbar", "positions": 10, "length_mm": 600.0, "points_per_sphere": 4},
                     {"kind": "seat", "articulations": 8, "measurements": 4},
                     {"kind": "sphere", "points": 8, "measurements": 5}]}
    simulate(campaign_from_dict(camp)).write(tmp_path / "sim")
    args = ["close-loop", str(tmp_path / "sim" / "points.csv"), str(tmp_path / "sim" / "artefacts.toml"),
            "--arm", str(NOMINAL), "--sigma-probe-um", "2", "--cv-top", "2", "--quiet"]
    assert main(args + ["-o", str(tmp_path / "built")]) == 0
    s = json.loads((tmp_path / "built" / "summary.json").read_text())
    (eff,) = s["effects_added"]
    assert eff["name"].startswith("harmonics j6 (h ") and eff["origin"] == "residual" and eff["found_from_the_residual"]
    assert "(found from the residual)" in s["verdict"]
    assert "found from the residual" in (tmp_path / "built" / "report.html").read_text()
    assert main(args + ["--library-only", "-o", str(tmp_path / "library")]) == 0
    s = json.loads((tmp_path / "library" / "summary.json").read_text())
    assert s["effects_added"] == [] and s["settings"]["synthesise"] is False
    capsys.readouterr()


def test_free_hold_and_effect_are_one_option_in_calibrate_and_close_loop():
    """One definition each (calibration.cli.model_options): the same flags, metavar, action and help."""
    from arm_model.cli import build_parser
    sub = next(a for a in build_parser()._actions if a.choices and "calibrate" in a.choices).choices

    def option(cmd, flag):
        a = next(a for a in sub[cmd]._actions if flag in a.option_strings)
        return a.option_strings, a.metavar, a.help, type(a).__name__, a.default
    for flag in ("--free", "--hold", "--effect"):
        assert option("calibrate", flag) == option("close-loop", flag), flag


def test_the_loop_frees_what_calibrate_would_and_every_effect_it_adds(nominal):
    """close-loop's --free and --hold mean calibrate's: an effect of the base model (thermal) is free only if
    named; the parameters of an effect the loop added (a joint compliance) are free whatever --free says; a
    held name is never free, and None keeps calibrate's default set."""
    from arm_model.effects import JointCompliance, ThermalGrowth
    from arm_model.model import ArmModel
    from calibration.loop.state import fitted_names
    base = ArmModel(nominal, (ThermalGrowth(),))
    grown = base.with_effects(JointCompliance(joints=(1,)))
    size = base.spec.size
    assert fitted_names(grown, None, (), size) is None
    assert fitted_names(grown, ("j*.d",), ("j2.d",), size) == (
        [f"j{i}.d" for i in range(1, 8) if i != 2] + ["j2.compliance"])
    assert "links.thermal_alpha" in fitted_names(grown, None, ("j1.*",), size)
    assert "links.thermal_alpha" not in fitted_names(grown, ("j*.d",), (), size)
    assert "j2.compliance" not in fitted_names(grown, None, (), size, held=("j2.compliance",))


def test_holdout_keeps_its_rows_out_of_the_model_which_is_calibrates_with_its_reference_frame(tmp_path, capsys):
    """``--holdout IDS``: the model written is fitted without the held-out measurements, as ``calibrate
    --holdout``'s is; with nothing added (``--max-effects 0``) it is calibrate's model: the same parameter
    values in the model files and the same fitted ``T_ref_base`` in both summaries (``reference_frame``)."""
    from arm_model.io import read_points
    from arm_model.model_file import load_model

    camp = {**CAMPAIGN, "task": CAMPAIGN["task"] + [{"kind": "tracker", "nests": 6, "articulations": 2,
                                                      "noise_um": 10.0}]}
    sim = tmp_path / "sim"
    simulate(campaign_from_dict(camp)).write(sim)
    held = ["bar-pos-02", "seat-03", "sphere-03"]
    common = [str(sim / "points.csv"), str(sim / "artefacts.toml"), "--arm", str(NOMINAL), "--reference-points",
              str(sim / "points-ref.csv"), "--sigma-probe-um", "2", "--holdout", ",".join(held), "--quiet"]
    assert main(["close-loop", *common, "--max-effects", "0", "--no-plots", "-o", str(tmp_path / "loop")]) == 0
    # --no-plots: no PNG drawn, the report with its tables alone
    assert not list((tmp_path / "loop").glob("*.png")) and "<img" not in (tmp_path / "loop" / "report.html").read_text()
    # calibrate at the loop's estimation (no prior, the practical-resolution rule: tests/conftest.py loop_fit_options)
    assert main(["calibrate", *common, "--prior-scale", "off", "--min-resolution", "0.1", "--no-plots",
                 "-o", str(tmp_path / "cal")]) == 0
    loop, cal = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("loop", "cal"))
    assert loop["measurements"]["test"] == held and loop["effects_added"] == []
    pts = read_points(sim / "points.csv", 7)
    n_ref = len(read_points(sim / "points-ref.csv", 7))     # the tracker rows, none in a held-out measurement
    assert loop["model"]["points"] == cal["n_points"] == int(sum(m not in held for m in pts.measurement)) + n_ref
    assert "held-out" in loop["model"]["fitted_on"]
    t_loop, t_cal = (np.array(s["reference_frame"]["frames"][0]["T_ref_base"]) for s in (loop, cal))
    assert t_loop.shape == (4, 4) and loop["reference_frame"]["fitted"]
    np.testing.assert_allclose(t_loop, t_cal, atol=1e-9)
    a, b = (load_model(tmp_path / d / "aacmm7-calibrated.toml") for d in ("loop", "cal"))
    np.testing.assert_allclose(a.desc.row_table(), b.desc.row_table(), atol=1e-12)
    np.testing.assert_allclose(a.desc.probe.p_last, b.desc.probe.p_last, atol=1e-12)
    capsys.readouterr()


@pytest.mark.parametrize("extra, escalate", [([], True), (["--candidates", "eccentricity"], False)])
def test_naming_the_candidates_turns_the_escalation_off(files, tmp_path, monkeypatch, extra, escalate):
    """The opt-in families are offered when the outer test set is worse than stated, unless the user named the
    candidates (``--candidates``): the settings the command hands to the loop say so."""
    import calibration.loop as loop

    seen = {}

    class Handed(Exception):
        pass

    def fake_close_loop(*args, settings, **kw):
        seen["escalate"] = settings.escalate
        raise Handed

    monkeypatch.setattr(loop, "close_loop", fake_close_loop)   # loop_cli imports it when it runs
    code = main(["close-loop", str(files / "points.csv"), str(files / "artefacts.toml"), "--arm", str(NOMINAL),
                 *extra, "-o", str(tmp_path / "loop")])
    assert code == 3 and seen == {"escalate": escalate}        # the stand-in's exception is an internal error
    assert not (tmp_path / "loop").exists()


def test_prior_groups_and_pose_folds_reach_the_loops_settings(files, tmp_path, monkeypatch, capsys):
    """``--prior-groups pooled --pose-folds blocked`` are the settings the loop is given (every fit's
    ``FitOptions.prior_groups`` is ``LoopSettings.prior_groups``); an unknown choice stops with exit 2."""
    import calibration.loop as loop
    got = {}

    def stop(*args, settings, **kw):
        got["settings"] = settings
        raise InputError("stopped by the test")
    monkeypatch.setattr(loop, "close_loop", stop)
    args = ["close-loop", str(files / "points.csv"), str(files / "artefacts.toml"), "--arm", str(NOMINAL), "-o"]
    assert main(args + [str(tmp_path / "a"), "--prior-groups", "pooled", "--pose-folds", "blocked"]) == 2
    assert (got["settings"].prior_groups, got["settings"].pose_folds) == ("pooled", "blocked")
    assert main(args + [str(tmp_path / "b")]) == 2 and got["settings"].prior_groups == "separate"
    with pytest.raises(SystemExit):
        main(args + [str(tmp_path / "c"), "--prior-groups", "one"])
    capsys.readouterr()
    with pytest.raises(ValueError, match="prior_groups"):
        loop.LoopSettings(prior_groups="one")
