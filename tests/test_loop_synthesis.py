"""Beyond the library: an effect hidden in the truth that the library does not hold leaves a significant
structure family; the loop builds the effect from it, cross-validates it like a library candidate, adds it
(reported as found from the residual), recovers its size within 3 sigma, and brings the held-out RMS within
1.3 times that of the same campaign without the effect.

The loop may reach the hidden effect through another parameterization (a library effect first, then the
rest from the residual: eccentricity j6 with harmonics j6 (h 3) for a third harmonic, the anisotropic probe
compliance with the matrix's other terms). So the truth is put in the fit's terms independently of the
loop: the hidden effect's ball displacement at the fit's own points (the true model, hidden parameters on
minus off), least squares on the columns of the added parameters (the fitted model's evaluator, central
differences; the effects are linear in their parameters at these sizes). The added effects must reproduce
it (5 % RMS left at most) and the fitted values must lie in the 3-sigma region of the fit's covariance
around it (chi-square of all added free parameters, 99.73 %)."""
from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest
from scipy import stats

from arm_model import load_description
from arm_model.cli import main
from arm_model.effects import (
    ApproachOffset,
    EncoderEccentricity,
    JointHarmonics,
    LateralCompliance,
    ProbeComplianceMatrix,
)
from arm_model.model import ArmModel
from arm_model.sim import campaign_from_dict, simulate
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration.candidates import Candidate
from calibration.data import Weights, make_data
from calibration.loop import close_loop
from calibration.loop_report import write_loop_model
from calibration.model_output import refine_torques
from calibration.synthesis import RESIDUAL, synthesise
from conftest import NOMINAL, assert_close

NOISE = 2e-6
#: 280 points, 26 measurements: enough approach directions and forces that the loop's choices do not hang on
#: one draw of the campaign (seeds 1-5 measured, docs/studies/close-loop.md)
SPEC = SynthSpec(ballbars=12, ballbar_points=5, seats=4, articulations=10, spheres=10, sphere_points=12,
                 noise=NOISE)

#: case -> (hidden effects, true values, force [N], kind of the effect built from the residual)
CASES = {
    "wrist third harmonic": ((JointHarmonics(joints=(5,), harmonics=(3,)),),
                             {"j6.harm3_cos": 3.5e-5, "j6.harm3_sin": 6.0e-5}, 0.0, "harmonics j6"),
    "elbow lateral compliance": ((LateralCompliance(joints=(3,)),),
                                 {"j4.lateral_compliance_x": 1e-5, "j4.lateral_compliance_y": 8e-6}, 0.0,
                                 "lateral compliance j4"),
    "anisotropic probe": ((ProbeComplianceMatrix(),),
                          {"probe.dcompliance_xx": 3e-6, "probe.dcompliance_yy": -3e-6, "probe.dcompliance_xy": 4e-6},
                          3.0, "probe compliance matrix"),
    "lobing": ((ApproachOffset(),), {"approach.dx_uy": 6e-6, "approach.dy_ux": -4e-6, "approach.dz_ux": 5e-6}, 0.0,
               "approach offset"),
    "library and residual": ((EncoderEccentricity(joints=(1,), harmonics=(1, 2)), ApproachOffset()),
                             {"j2.ecc1_cos": 3e-5, "j2.ecc1_sin": 5e-5, "approach.dx_uy": 6e-6,
                              "approach.dy_ux": -4e-6, "approach.dz_ux": 5e-6}, 0.0, "approach offset"),
}


def _truth(effects, values, seed=1):
    nominal = load_description(NOMINAL)
    truth = ArmModel(nominal, tuple(effects))
    p = random_truth(truth, np.random.default_rng(seed), length=30e-6, angle=5e-5, probe=30e-6)
    p[truth.base_size:] = 0.0
    for k, v in values.items():
        p[truth.spec.index(k)] = v
    return nominal, truth, p


@cache
def run(case: str | None, force: float = 0.0):
    """(truth model, true p, the loop, the campaign) on a synthetic campaign with ``case`` hidden (None: the
    same campaign, same base errors, without it)."""
    effects, values, force = CASES[case][:3] if case else ((), {}, force)
    nominal, truth, p = _truth(effects, values)
    camp = make_campaign(truth, SynthSpec(**{**SPEC.__dict__, "force": force}), seed=1, p_true=p)
    return truth, p, close_loop(camp.points, camp.artefacts, nominal, weights=Weights(probe=NOISE), cv_top=2), camp


def tip_gives_the_loops_points(loop, points_csv, tmp_path):
    """``aacmm tip`` with the model file the loop writes (its final fit on every point, refined with the
    torques on its calibrated geometry and written as ``aacmm close-loop`` does) gives the loop's own
    corrected points to 1 nm; each effect built from the residual is in the file and moves those points by
    more than 0.1 um somewhere (so a tip that left it out would fail)."""
    from arm_model.model_file import load_model

    final = refine_torques(loop.model_fit)
    files = write_loop_model(dataclasses.replace(loop, model_fit=final), tmp_path / "loop")
    built = [c for c in loop.added if c.origin == RESIDUAL]
    assert built
    in_file = load_model(files["model"]).effects
    tip = tmp_path / "tip.csv"
    assert main(["tip", str(points_csv), "--arm", str(files["model"]), "-o", str(tip)]) == 0
    got = np.genfromtxt(tip, delimiter=",", names=True, dtype=None, encoding="utf-8")
    got = np.column_stack([got["x_mm"], got["y_mm"], got["z_mm"]]) * 1e-3
    data = final.data
    own = final.model.ball_centres(data.points.q, data.wrench, final.p, data.aux)
    assert got.shape == own.shape
    assert_close(got, own, atol=1e-9)
    desc = final.model.desc
    for c in built:
        assert c.effect in in_file, (c.effect, in_file)
        off = np.array(final.p, dtype=float)
        off[[final.model.spec.index(n) for n in c.param_names(desc)]] = 0.0
        moved = np.linalg.norm(own - final.model.ball_centres(data.points.q, data.wrench, off, data.aux), axis=1)
        assert moved.max() > 1e-7, (c.name, moved.max())


def hidden_in_fit_terms(model: ArmModel, names, truth: ArmModel, p_true, hidden, q, w, aux=(None, None)):
    """The hidden parameters ``hidden`` of ``(truth, p_true)`` in the terms of the parameters ``names`` of
    ``model``: the values that reproduce the hidden effects' ball displacement at the points (q, w) (least
    squares over the points, columns by central differences of 1e-6 SI), and the RMS fraction of that
    displacement they leave unexplained. ``aux``: the truth's and the model's aux inputs."""
    p_off = np.array(p_true, dtype=float)
    p_off[[truth.spec.index(n) for n in hidden]] = 0.0
    d = (truth.ball_centres(q, w, p_true, aux[0]) - truth.ball_centres(q, w, p_off, aux[0])).ravel()
    cols = []
    for n in names:
        dp = np.zeros(model.spec.size)
        dp[model.spec.index(n)] = 1e-6
        cols.append((model.ball_centres(q, w, dp, aux[1]) - model.ball_centres(q, w, -dp, aux[1])).ravel() / 2e-6)
    a = np.column_stack(cols)
    theta = np.linalg.lstsq(a, d, rcond=None)[0]
    return theta, float(np.linalg.norm(a @ theta - d) / np.linalg.norm(d))


def _within_3_sigma(result, truth_values: dict):
    """The fitted values of the free names of ``truth_values`` (held ones: not identifiable, e.g. the thermal
    rate of a link of zero length) inside the 3-sigma region of the fit's covariance around the truth
    (chi-square, 99.73 %)."""
    names = [n for n in truth_values if n in result.free]
    assert names, (list(truth_values), result.free)
    idx = [result.free.index(n) for n in names]
    d = np.array([result.value(n) - truth_values[n] for n in names])
    chi2 = float(d @ np.linalg.solve(result.cov[np.ix_(idx, idx)], d))
    limit = stats.chi2.ppf(stats.chi2.cdf(9.0, 1), len(names))
    z = ", ".join(f"{n} {result.value(n):.4g} +- {result.uncertainty(n):.2g} (truth {truth_values[n]:.4g})"
                  for n in names)
    assert chi2 <= limit, f"chi2 {chi2:.1f} > {limit:.1f}: {z}"


#: in make test-slow: a harmonic built from the residual is held in make test by test_loop_honesty and
#: test_loop_cross_harmonics, a library effect by test_loop_effects (one seed each); the lateral compliance and the
#: probe compliance matrix (each a loop of 280 points and the same campaign's without it, 15 and 13 s of CPU) by
#: the lobing case: an effect built from the residual, recovered within 3 sigma against its clean campaign and
#: carried by the model file; their offering by test_synthesis_offers_only_what_the_model_lacks
SLOW_CASES = {"wrist third harmonic", "library and residual", "elbow lateral compliance", "anisotropic probe"}


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_CASES else c for c in CASES])
def test_loop_builds_adds_and_recovers_the_hidden_effect(case, tmp_path, capsys):
    effects, values, force, kind = CASES[case]
    truth, p, loop, camp = run(case)
    final = loop.final.result
    desc = final.model.desc
    built = [c for c in loop.added if c.origin == RESIDUAL]
    assert [c.name for c in built if c.name.startswith(kind)], loop.verdict
    for c in built:
        assert f"{c.name} (found from the residual)" in loop.verdict
    names = [n for c in loop.added for n in c.param_names(desc) if n in final.free]
    pts = final.data.points
    aux = (make_data(pts, final.data.artefacts, truth).aux, final.data.aux)
    theta, unexplained = hidden_in_fit_terms(final.model, names, truth, p, list(values), pts.q, final.data.wrench, aux)
    assert unexplained <= 0.05, ([c.name for c in loop.added], unexplained)
    _within_3_sigma(final, dict(zip(names, theta, strict=True)))
    clean = run(None, force)[2]
    assert loop.final.heldout["rms_um"] <= 1.3 * clean.final.heldout["rms_um"], (
        loop.final.heldout["rms_um"], clean.final.heldout["rms_um"])
    assert not loop.remaining, loop.verdict
    if case == "library and residual":
        # the library's effect first (effects are built from the residual only once the library is exhausted)
        assert [(c.name, c.origin) for c in loop.added] == [("eccentricity j2", "library"),
                                                             ("approach offset", RESIDUAL)], loop.verdict
    # the model file the loop writes, applied by aacmm tip, gives the loop's corrected points
    camp.write(tmp_path / "sim")
    tip_gives_the_loops_points(loop, tmp_path / "sim" / "points.csv", tmp_path)


def test_truth_in_fit_terms_maps_one_parameterization_onto_another(nominal):
    """The reference of the test above, against hand-derived values: a diagonal probe compliance matrix
    (xx 3, yy -3 um/N) seen by an anisotropic probe compliance (x, y) is the same numbers; a third harmonic
    seen by harmonics 1-3 is harm3 itself and zeros; a lateral compliance is not a joint compliance."""
    from arm_model.effects import JointCompliance, ProbeCompliance

    rng = np.random.default_rng(2)
    q = rng.uniform(-2, 2, (40, nominal.n_joints))
    w = np.column_stack([rng.normal(0, 3, (40, 3)), np.zeros((40, 3))])
    truth = ArmModel(nominal, (ProbeComplianceMatrix(terms=("xx", "yy")),))
    p = truth.spec.vector({"probe.dcompliance_xx": 3e-6, "probe.dcompliance_yy": -3e-6})
    theta, left = hidden_in_fit_terms(ArmModel(nominal, (ProbeCompliance(anisotropic=True),)),
                                      ["probe.dcompliance_x", "probe.dcompliance_y"], truth, p,
                                      ["probe.dcompliance_xx", "probe.dcompliance_yy"], q, w)
    np.testing.assert_allclose(theta, [3e-6, -3e-6], rtol=1e-6)
    assert left < 1e-3          # not 0: the elastic joints rotate the ball (second order in the compliance)
    truth = ArmModel(nominal, (JointHarmonics(joints=(5,), harmonics=(3,)),))
    p = truth.spec.vector({"j6.harm3_cos": 3.5e-5, "j6.harm3_sin": 6e-5})
    fitted = ArmModel(nominal, (JointHarmonics(joints=(5,), harmonics=(1, 2, 3)),))
    theta, left = hidden_in_fit_terms(fitted, list(fitted.spec.names[fitted.base_size:]), truth, p,
                                      ["j6.harm3_cos", "j6.harm3_sin"], q, w)
    np.testing.assert_allclose(theta, [0, 0, 0, 0, 3.5e-5, 6e-5], atol=1e-10)
    assert left < 1e-3          # not 0: the chain is second order in the angle error
    truth = ArmModel(nominal, (LateralCompliance(joints=(3,)),))
    p = truth.spec.vector({"j4.lateral_compliance_x": 1e-5})
    fitted = ArmModel(nominal, (JointCompliance(joints=(3,)),))
    from arm_model import PinocchioArm
    from arm_model.model import AuxData
    tg, tc = PinocchioArm(nominal).torques(q, w)
    _, left = hidden_in_fit_terms(fitted, list(fitted.spec.names[fitted.base_size:]), truth, p,
                                  ["j4.lateral_compliance_x"], q, w, (None, AuxData(np.full(40, 20.0), tg, tc)))
    assert left > 0.5


@pytest.mark.slow
def test_two_links_growing_at_different_rates_over_10_K(tmp_path, capsys):
    """Simulator: links j3 and j5 grow at 12 and 23 ppm/K over about 10 K. The library's common growth
    comes first, then each link's own rate from the residual ('temperature per link')."""
    tasks = [{"kind": "ballbar", "positions": 10, "length_mm": 600.0, "points_per_sphere": 4},
             {"kind": "seat", "articulations": 8, "measurements": 4},
             {"kind": "sphere", "points": 8, "measurements": 5}]

    def loop(thermal: bool):
        d = {"seed": 3, "sensor": "xyz", "signals": {"enabled": False}, "noise": {"probing_repeatability_um": 2.0},
             "task": tasks, "environment": {"drift_C_per_h": 8.0}, "operator": {"measurement_gap_s": 300.0}}
        if thermal:
            d["truth"] = {"thermal": {"joints": ["j3", "j5"], "alpha_per_K": [1.2e-5, 2.3e-5]}}
        camp = campaign_from_dict(d)
        sim = simulate(camp)
        return sim, close_loop(sim.points, sim.artefacts, camp.arm, weights=Weights(probe=2e-6), cv_top=2)

    sim, hot = loop(True)
    assert np.ptp(sim.points.temperature) >= 10.0, np.ptp(sim.points.temperature)
    assert [c.name for c in hot.added] == ["thermal growth", "thermal growth per link"], hot.verdict
    assert hot.added[1].origin == RESIDUAL
    final = hot.final.result
    # in the model's terms: the common rate is the longest link's (j3), each other link its own minus it
    truth = {"links.thermal_alpha": 1.2e-5, "j5.thermal_alpha": 1.1e-5}
    truth.update({f"j{i}.thermal_alpha": -1.2e-5 for i in (1, 2, 4, 7)})
    _within_3_sigma(final, truth)
    _, clean = loop(False)
    assert hot.final.heldout["rms_um"] <= 1.3 * clean.final.heldout["rms_um"]
    sim.write(tmp_path / "sim")
    tip_gives_the_loops_points(hot, tmp_path / "sim" / "points.csv", tmp_path)


def test_synthesis_offers_only_what_the_model_lacks():
    nominal = load_description(NOMINAL)
    base = ArmModel(nominal)
    names = [c.name for c in synthesise(["q6 harmonics"], base)]
    assert names == [f"harmonics j6 (h {h})" for h in ("1", "1,2", "1,2,3", "1,2,3,4")]
    with_ecc = base.with_effects(EncoderEccentricity(joints=(5,), harmonics=(1, 2)))
    assert [c.name for c in synthesise(["q6 harmonics"], with_ecc)] == ["harmonics j6 (h 3)", "harmonics j6 (h 3,4)"]
    cands = synthesise(["contact force", "approach direction", "j4 lateral load", "time", "measurement"], base)
    assert [c.name for c in cands] == ["probe compliance axes tilted", "probe compliance matrix", "approach offset",
                                       "lateral compliance j4"]
    assert all(isinstance(c, Candidate) and c.origin == RESIDUAL for c in cands)
    from arm_model.effects import ProbeCompliance
    iso = synthesise(["contact force"], base.with_effects(ProbeCompliance()))[-1]          # the matrix
    assert iso.param_names(nominal) == ["probe.dcompliance_yy", "probe.dcompliance_zz", "probe.dcompliance_xy",
                                        "probe.dcompliance_xz", "probe.dcompliance_yz"]
    assert synthesise(["approach direction"], base.with_effects(ApproachOffset())) == []
