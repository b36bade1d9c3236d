"""The model discrepancy of a fit (:mod:`calibration.discrepancy`): extrapolative cross-validation by group
deletion at the solution, checked against refits without the held-out poses, against simulated campaigns whose
model is exact (no discrepancy) or lacks an effect of the truth (a discrepancy), and carried by the model file
into ``aacmm tip``'s uncertainty."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from arm_model.effects import EncoderEccentricity
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration import FitOptions, Weights, calibrate, make_data
from calibration.discrepancy import extreme_folds, fold_errors, holdable
from calibration.problem import Problem
from calibration.solver import levenberg_marquardt
from calibration.validation import heldout_residuals

SPEC = SynthSpec(ballbars=4, ballbar_points=5, seats=4, articulations=10, spheres=2, sphere_points=10, rings=0,
                 ring_points=0, planes=0, plane_points=0, reference_points=0, force=0.0, noise=5e-6,
                 reference_noise=5e-6)
W = Weights(probe=5e-6, reference=5e-6)


@pytest.fixture(scope="module")
def model(nominal):
    return ArmModel(nominal)


def _campaign(model, seed, truth_model=None, p_true=None):
    rng = np.random.default_rng(seed)
    truth_model = truth_model or model
    p = random_truth(truth_model, rng, length=1e-4, angle=1e-4, probe=1e-4) if p_true is None else p_true
    c = make_campaign(truth_model, SPEC, seed=seed, p_true=p)
    return make_data(c.points, c.artefacts, model)


def test_extreme_folds_take_both_ends_of_every_moving_joint():
    """Per joint whose angle varies: the share's rows of its smallest and of its largest angles, measured from
    the circular mean (a range across +-pi is one interval); a joint at one angle gives no fold."""
    q = np.zeros((20, 3))
    q[:, 0] = np.linspace(-1.0, 1.0, 20)
    q[:, 2] = np.pi + np.linspace(-0.5, 0.5, 20)          # across +-pi
    q[:, 2] = np.angle(np.exp(1j * q[:, 2]))
    folds = extreme_folds(q, 0.15)
    assert len(folds) == 4                                 # joint 2 does not move
    assert sorted(folds[0]) == [0, 1, 2] and sorted(folds[1]) == [17, 18, 19]
    assert sorted(folds[2]) == [0, 1, 2] and sorted(folds[3]) == [17, 18, 19]


def _dense_system(model, res):
    """The joint fit of ``res`` linearised at its solution, built here from the problem's Jacobian (dense):
    the problem, weighted residuals, the scaled Jacobian, a solver of the normal matrix with the prior's
    precision, and that matrix."""
    free = [model.spec.index(n) for n in res.free]
    prob = Problem(model, res.data, res.weights, free, reference=res.reference_mode)
    st = levenberg_marquardt(prob.with_free([]), res.p, prob.initial_states(res.p)).states
    ev = prob.evaluate(res.p, st)
    j = np.hstack([ev.jp, ev.jt.toarray()])
    a = j.T @ j
    a[np.arange(len(free)), np.arange(len(free))] += 1.0 / res.prior_sd ** 2
    return prob, ev.r, sp.csc_matrix(j), (lambda b: np.linalg.solve(a, b)), a, j


def test_group_deletion_predicts_the_refit_without_the_held_out_poses(model):
    """For a fold (the poses at one end of joint 2's range): the held-out errors of the deletion formula equal
    those of a refit on the other poses (same prior and weights, each held-out pose predicted against its feature
    fitted on the rest) to 2 % of their size, and the predicted variances equal noise plus the posterior of the
    fit without them (Woodbury's other side, ``var sigma^2 (1 + j A_-O^-1 j^T)``) to 1e-9."""
    data = _campaign(model, 1)
    res = calibrate(model, data, FitOptions(weights=W, prior_scale=1.0))
    prob, r, js, solve, a, j = _dense_system(model, res)
    used = np.unique(prob.row_point[prob.row_point >= 0])
    held = np.array(sorted(holdable(prob, used[extreme_folds(data.points.q[used], 0.1)[2]])))
    rows = np.flatnonzero((prob.row_distance < 0) & np.isin(prob.row_point, held))
    e, v = fold_errors(prob, r, js, solve, 1.0, rows)
    train = ~np.isin(np.arange(len(data)), held)
    sizes = dict(zip(res.free, res.prior_sd))
    refit = calibrate(model, data.select(train), FitOptions(free=res.free, weights=res.weights, prior_scale=1.0,
                                                              priors=sizes, start={n: res.value(n) for n in res.free}))
    exact = heldout_residuals(model, refit.p, data, res.weights, res.reference_mode, train)["e"]
    assert len(exact) == len(e)
    assert np.linalg.norm(e - exact) <= 0.02 * np.linalg.norm(exact), (np.linalg.norm(e - exact), np.linalg.norm(exact))
    jo = j[rows]
    a_minus = a - jo.T @ jo
    v_other = prob.sigma[rows] ** 2 * (1.0 + np.einsum("ij,ji->i", jo, np.linalg.solve(a_minus, jo.T)))
    np.testing.assert_allclose(v, v_other, rtol=1e-9)


def test_an_exact_model_has_no_discrepancy_and_a_missing_effect_has_one(model, nominal):
    """A campaign the model describes exactly: the held-out ends of the joint ranges are predicted as well as
    the fit says (ratio within 0.85-1.2, discrepancy under 0.6 of the 5 um noise: measured 0-2.6 um, ratio
    0.95-1.08 over seeds 0-7). The same campaign with a second-harmonic encoder error of 100 urad on joints 2
    and 4 in the truth, calibrated without it: the ends are predicted worse than the fit says and the
    discrepancy exceeds the noise (measured 8-23 um, ratio 1.05-1.18: the noise estimated from the residuals
    already holds most of the missing effect)."""
    exact = calibrate(model, _campaign(model, 2), FitOptions(weights=W, weights_from_data=True))
    d = exact.discrepancy
    assert d is not None and d.folds == 14 and 0.85 <= d.ratio <= 1.2 and d.sigma < 3e-6, d
    # the cross-validation error itself: the 5 um noise per axis and a little posterior
    assert 5e-6 * 0.8 < d.rms < 5e-6 * 1.5, d
    assert d.to_dict()["rms_um"] == pytest.approx(d.rms * 1e6, rel=1e-12)
    truth = ArmModel(nominal, (EncoderEccentricity(joints=(1, 3)),))
    p = np.zeros(truth.spec.size)
    p[:model.spec.size] = random_truth(model, np.random.default_rng(2), length=1e-4, angle=1e-4, probe=1e-4)
    p[model.spec.size:] = [0, 0, 1e-4, -1e-4, 0, 0, 1e-4, 1e-4]
    lacking = calibrate(model, _campaign(model, 2, truth, p), FitOptions(weights=W, weights_from_data=True))
    d = lacking.discrepancy
    assert d.ratio > 1.03 and d.sigma > 5e-6, d
    # rms^2 = sigma^2 + the fit's own predicted variance (ratio^2 = rms^2 / that): one definition of the three
    assert d.rms ** 2 == pytest.approx(d.sigma ** 2 * d.ratio ** 2 / (d.ratio ** 2 - 1.0), rel=1e-9)
    assert d.rms > exact.discrepancy.rms


def test_the_model_file_carries_the_discrepancy_into_tip(tmp_path, model):
    """calibrate writes the growing discrepancy (summary.json; the model file's model_discrepancy_um = sigma0 and
    model_discrepancy_growth_um_per_mm to 4 digits, and the training poses' points file); the model file reads
    them back; tip adds sigma_d(q)^2 to every point's variance per axis as the 'model discrepancy' contribution,
    and --u-model-discrepancy-um 0 takes it out."""
    import csv
    import json

    from arm_model.cli import main
    from arm_model.model_file import load_model
    from conftest import ROOT
    panda = ROOT / "examples" / "data" / "real-panda-seats"
    out = tmp_path / "cal"
    assert main(["calibrate", str(panda / "right" / "points.csv"), str(panda / "artefacts.toml"), "--arm",
                 str(panda / "panda-with-inertials.urdf"), "--tip-frame", "ball_link", "--no-plots", "-q",
                 "-o", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    growth = summary["model_discrepancy"]["growth"]
    assert summary["model_discrepancy"]["sigma_um"] > 0 and growth["growth_um_per_mm"] > 0
    arm = load_model(out / "panda-calibrated.toml")
    assert arm.model_discrepancy == pytest.approx(growth["sigma0_um"] * 1e-6, rel=1e-3, abs=1e-10)
    assert arm.discrepancy_growth == pytest.approx(growth["growth_um_per_mm"] * 1e-3, rel=1e-3)
    from arm_model.io import read_points
    training = read_points(arm.training_poses).q
    np.testing.assert_allclose(training, read_points(panda / "right" / "points.csv").q, rtol=0, atol=1e-12)
    q_front = read_points(panda / "front" / "points.csv").q
    u = {}
    for label, extra in (("with", []), ("without", ["--u-model-discrepancy-um", "0"])):
        tip = tmp_path / f"{label}.csv"
        assert main(["tip", str(panda / "front" / "points.csv"), "--arm", str(out / "panda-calibrated.toml"),
                     "-q", "-o", str(tip), *extra]) == 0
        u[label] = np.array([[float(r[f"u_{a}_mm"]) for a in "xyz"] for r in csv.DictReader(open(tip))])
    sd = arm.discrepancy.sd(arm.desc, q_front) * 1e3
    assert sd.max() > 1.5 * sd.min()                      # the front poses lie at various distances from right's
    np.testing.assert_allclose(u["with"] ** 2 - u["without"] ** 2, np.repeat(sd[:, None] ** 2, 3, axis=1), rtol=1e-4)


@pytest.mark.parametrize("value", ["-1.0", "1e9", "\"big\""])
def test_a_bad_model_discrepancy_in_a_model_file_is_refused(tmp_path, value):
    from arm_model import InputError
    from arm_model.model_file import parse_model
    from conftest import NOMINAL
    text = NOMINAL.read_text() + f"\n[calibration]\nmodel_discrepancy_um = {value}\n"
    with pytest.raises(InputError, match="model_discrepancy_um"):
        parse_model(text, str(tmp_path / "m.toml"))
