"""The parameters' random effect between regions of the joint space (calibration/region.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.region import RegionEffect, fit_region_variances, pose_regions, predictive_covariance


def _folds(rng, t, n_folds=40, n=12, k=3):
    """Folds ``(M, G, e)`` with ``e ~ N(0, M + G diag(t) G^T)``: ``M`` a random SPD matrix about the identity."""
    out = []
    for _ in range(n_folds):
        a = rng.normal(size=(n, n)) * 0.3
        m = np.eye(n) + a @ a.T
        g = rng.normal(size=(n, k))
        c = m + (g * t) @ g.T
        out.append((m, g, np.linalg.cholesky(c) @ rng.standard_normal(n)))
    return out


def _loglik(parts, t) -> float:
    """The Gaussian log-likelihood of the folds at ``t``, by dense determinants and solves (an independent reference
    for the Woodbury form the fit uses)."""
    total = 0.0
    for m, g, e in parts:
        c = m + (g * t) @ g.T
        total -= 0.5 * (np.linalg.slogdet(c)[1] + e @ np.linalg.solve(c, e))
    return total


def test_fit_recovers_known_variances_and_its_likelihood_ratio_is_the_dense_one():
    rng = np.random.default_rng(3)
    truth = np.array([0.0, 0.3, 0.8])
    fits = [fit_region_variances(_folds(rng, truth)) for _ in range(6)]
    mean_t = np.mean([f[0] for f in fits], axis=0)
    assert np.all(np.abs(mean_t - truth) <= 0.12), mean_t
    parts = _folds(rng, truth)
    t, lr = fit_region_variances(parts)
    assert lr == pytest.approx(2 * (_loglik(parts, t) - _loglik(parts, np.zeros(3))), rel=1e-6, abs=1e-6)
    for d in np.eye(3) * 1e-3:                    # a maximum within the bounds [0, 1]
        for x in (np.clip(t + d, 0, 1), np.clip(t - d, 0, 1)):
            assert _loglik(parts, x) <= _loglik(parts, t) + 1e-6


def test_fit_with_groups_ties_the_variances_and_stays_near_zero_without_an_effect():
    rng = np.random.default_rng(5)
    parts = _folds(rng, np.zeros(3))
    t, lr = fit_region_variances(parts, group=[0, 0, 1])
    assert t.shape == (2,) and np.all((t >= 0) & (t <= 1))
    assert np.all(t <= 0.1) and lr < 6.0          # 2 variance components at 0: about a chi-square mixture
    t_one, _ = fit_region_variances(parts, group=[0, 0, 0])
    assert t_one.shape == (1,)


def test_pose_regions_split_separate_branches_and_wrap_around_pi():
    rng = np.random.default_rng(0)
    up = np.column_stack([rng.normal(1.0, 0.05, 20), rng.normal(2.5, 0.05, 20)])
    down = np.column_stack([rng.normal(-1.0, 0.05, 15), rng.normal(0.3, 0.05, 15)])
    q = np.vstack([up, down])
    folds = pose_regions(q, splits=(2,))
    assert sorted(map(len, folds)) == [15, 20]
    assert {tuple(f) for f in folds} == {tuple(range(20)), tuple(range(20, 35))}
    across = np.column_stack([np.r_[rng.uniform(3.0, np.pi, 10), rng.uniform(-np.pi, -3.0, 10)], np.zeros(20)])
    near_zero = np.column_stack([rng.uniform(-0.1, 0.1, 10), np.zeros(10)])
    folds = pose_regions(np.vstack([across, near_zero]), splits=(2,))
    assert {tuple(f) for f in folds} == {tuple(range(20)), tuple(range(20, 30))}    # +-pi is one region
    assert pose_regions(q[:2]) == []
    assert len(pose_regions(q)) == 2 + 3 + 4


def test_predictive_covariance_adds_the_effect_by_name():
    class Result:
        free = ("a", "b", "c")
        cov = np.diag([1.0, 2.0, 3.0])
        region = None
    assert predictive_covariance(Result()) is Result.cov
    Result.region = RegionEffect(("c", "a"), np.array([0.5, 0.25]), np.array([0.1, 0.2]), 9.0, 3, 30)
    np.testing.assert_array_equal(predictive_covariance(Result()), np.diag([1.25, 2.0, 3.5]))



def _right_fit(**options):
    from arm_model.effects import JointCompliance
    from arm_model.io import read_artefacts, read_points
    from arm_model.model import ArmModel
    from arm_model.urdf_import import load_arm
    from calibration import FitOptions, calibrate, make_data
    from conftest import ROOT
    panda = ROOT / "examples" / "data" / "real-panda-seats"
    desc = load_arm(panda / "panda-with-inertials.urdf", "ball_link")
    model = ArmModel(desc, (JointCompliance(),))
    points = read_points(panda / "right" / "points.csv", desc.n_joints)
    data = make_data(points, read_artefacts(panda / "artefacts.toml"), model)
    return calibrate(model, data, FitOptions(weights_from_data=True, **options))


def test_the_covariance_file_holds_the_posterior_plus_the_region_effect(tmp_path):
    """A region effect on a fit (here given: a probe offset and a compliance, which the model file's folding of the
    origin angles leaves alone) is in the covariance file written, and in the model file's u of the effect, which
    its reader checks against that file; the result's own u stay the posterior's."""
    from dataclasses import replace

    from arm_model.model_file import load_model, read_covariance
    from calibration.model_output import write_model, written_covariance
    res = _right_fit()
    assert res.region is None                      # off by default
    extra = {"probe.x": 4e-8, "panda_joint3.compliance": 1e-10}
    res = replace(res, region=RegionEffect(tuple(extra), np.array(list(extra.values())), np.array([0.1, 0.2]), 50.0,
                                           9, 540, 20.0))
    files = write_model(res, tmp_path, "panda-calibrated")
    arm = load_model(files["model"])
    cov = read_covariance(arm.covariance)
    names, want = written_covariance(res)
    _, post = written_covariance(replace(res, region=None))
    assert list(cov.names) == names
    np.testing.assert_allclose(cov.matrix, want, rtol=1e-6, atol=1e-30)
    for n, v in extra.items():
        i = names.index(n)
        assert cov.matrix[i, i] - post[i, i] == pytest.approx(v, rel=1e-6)
    k = res.free.index("panda_joint3.compliance")
    assert arm.uncertainties["panda_joint3.compliance"] == pytest.approx(math.sqrt(res.cov[k, k] + 1e-10), rel=1e-6)
    np.testing.assert_allclose(res.u, np.sqrt(np.diag(res.cov)), rtol=1e-12)


@pytest.fixture(scope="module")
def right_region():
    """The real `right` placement's default fit with the region effect."""
    return _right_fit(region_effect=True)


def test_the_real_right_placement_shows_a_region_effect_and_keeps_it(right_region):
    """The real Panda trained on its `right` placement: its pose regions predict each other far worse than the
    posterior says (likelihood ratio 340 against a critical value of 30.8, the 10th largest of 199 draws as the model
    holds: p 0.005), so the effect is kept, each variance within [0, 1] of its prior's, and written for free parameters
    only."""
    res = right_region
    reg = res.region
    assert reg is not None and reg.folds == 9 and reg.lr > 3 * reg.lr_null and reg.ratio.max() > 1e-3
    assert reg.draws == 199 and reg.p_value == pytest.approx(1 / 200)
    assert np.all((reg.ratio >= 0) & (reg.ratio <= 1)) and reg.names == res.free
    assert set(reg.to_dict()["sd_per_prior_sd"]) <= set(res.free)


def test_refining_the_torques_keeps_the_region_effect_without_testing_it_again(right_region, monkeypatch):
    """``refine_torques`` (what calibrate and close-loop do to a model with joint compliance before writing it) keeps
    the fit's region effect, estimated once: its refits move the parameters by the torques' nanometres, and the
    Monte Carlo test would cost seconds each (real `front`: calibrate --region-effect 25.4 -> 12.4 s)."""
    import importlib

    from calibration.model_output import refine_torques
    calls = []
    monkeypatch.setattr(importlib.import_module("calibration.calibrate"), "region_effect",
                        lambda *a, **k: calls.append(1))
    refined = refine_torques(right_region)
    assert refined is not right_region and not calls
    assert refined.region is right_region.region and refined.free == right_region.region.names


def test_a_variance_fit_that_does_not_converge_is_reported(monkeypatch):
    """The optimiser's failure is a NumericalError naming it, never the point where it stopped taken as the fit."""
    import scipy.optimize
    from scipy.optimize import OptimizeResult

    from arm_model.errors import NumericalError
    failed = OptimizeResult(x=np.zeros(3), fun=0.0, success=False, message="ABNORMAL_TERMINATION_IN_LNSRCH")
    monkeypatch.setattr(scipy.optimize, "minimize", lambda *a, **k: failed)
    with pytest.raises(NumericalError, match="did not converge.*ABNORMAL"):
        fit_region_variances(_folds(np.random.default_rng(1), np.zeros(3), n_folds=3))
