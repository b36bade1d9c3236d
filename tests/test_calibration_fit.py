"""The fit: exact recovery without noise, uncertainties that cover the truth, outliers reported (not
dropped; gross errors left out), effects calibrated, validation figures by hand, held-out improvement."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from arm_model.effects import ProbeCompliance
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration import FitOptions, Weights, calibrate, make_data, split_holdout, validate
from calibration.validation import _articulation
from conftest import assert_close

SPEC = SynthSpec(ballbars=10, ballbar_points=5, seats=3, articulations=10, spheres=1, sphere_points=12, rings=1,
                 ring_points=12, planes=1, plane_points=8, reference_points=40, force=1.5, noise=2e-6,
                 reference_noise=3e-6)


@pytest.fixture(scope="module")
def model(nominal):
    return ArmModel(nominal)


def _data(model, c):
    return make_data(c.points, c.artefacts, model, reference=c.reference_points)


def test_noise_free_campaign_is_recovered_exactly(model):
    """Without noise the least-squares fit (no prior) returns the truth to 1e-11 (m, rad) and residuals below
    1e-11 m when the unidentifiable parameters are zero in the truth; the default fit (a prior, the noise
    estimated with it) to 1e-9: the noise it finds is nil, so the prior's pull is too."""
    spec = replace(SPEC, noise=0.0, reference_noise=0.0)
    c = make_campaign(model, spec, seed=21)
    w = Weights(probe=1e-6, reference=1e-6)
    res = calibrate(model, _data(model, c), FitOptions(weights=w, prior_scale=None))
    # the fixed parameters' true errors map into the kept ones to first order only: the second-order
    # remainder (~(1e-4 rad)^2 x lever) leaves nanometres; with them zero in the truth the recovery is exact
    assert np.sqrt(np.mean(res.residuals["value"] ** 2)) < 2e-8 and res.status.startswith("converged")
    truth = c.p_true.copy()
    truth[[model.spec.index(f.name) for f in res.fixed]] = 0.0
    c2 = make_campaign(model, spec, seed=21, p_true=truth, T_ref_base=c.T_ref_base)
    res2 = calibrate(model, _data(model, c2), FitOptions(free=list(res.free), weights=w, prior_scale=None))
    assert res2.free == res.free and not res2.fixed
    idx = [model.spec.index(n) for n in res2.free]
    assert_close(res2.p[idx], truth[idx], atol=1e-11)
    assert_close(res2.p, truth, atol=1e-11)
    assert np.sqrt(np.mean(res2.residuals["value"] ** 2)) < 1e-11
    res3 = calibrate(model, _data(model, c2), FitOptions(free=list(res.free), weights=w, weights_from_data=True))
    assert res3.free == res.free and res3.prior_scales is not None
    assert_close(res3.p, truth, atol=1e-9)


@pytest.fixture(scope="module")
def noisy(model):
    c = make_campaign(model, SPEC, seed=22)
    data = _data(model, c)
    train, test = split_holdout(data, 0.3, seed=1)
    res = calibrate(model, train, FitOptions(weights=Weights(probe=2e-6, reference=3e-6)))
    return c, train, test, res


def test_truth_within_three_sigma(noisy, model):
    c, _, _, res = noisy
    peq = res.equivalent(c.p_true)
    z = np.array([(res.value(n) - peq[model.spec.index(n)]) / res.uncertainty(n) for n in res.free])
    assert np.all(np.abs(z) < 3.0), dict(zip(res.free, np.round(z, 2), strict=True))
    assert 0.3 < np.sqrt(np.mean(z ** 2)) < 1.7          # the uncertainties are about right, not inflated
    assert 0.8 < res.s0 < 1.2                             # weights equal to the noise: s0 about 1
    assert_close(np.diag(res.corr), 1.0, atol=1e-12)
    assert np.all(np.abs(res.corr) <= 1 + 1e-12)


def test_held_out_figures_improve_five_fold(noisy, model):
    _, _, test, res = noisy
    rows = {r["key"]: r for r in res.compare(test)}
    assert rows["length_error_max"]["ratio"] >= 5
    assert rows["articulation_2sigma"]["ratio"] >= 5
    assert rows["articulation_2sigma"]["after"] < 15          # um: a few probing sigmas
    assert rows["length_error_max"]["after"] < 15


def test_predict_on_held_out_data(noisy):
    _, _, test, res = noisy
    pred = res.predict(test)
    assert set(pred["measurement"]) <= set(test.measurements())
    assert pred["rms_weighted"] < 3.0                  # held-out residuals at the noise level (sigma units)
    zero = replace(res, p=np.zeros_like(res.p))
    assert zero.predict(test)["rms_weighted"] > 10 * pred["rms_weighted"]


def test_outlier_is_reported_with_its_line_and_kept(model):
    c = make_campaign(model, replace(SPEC, rings=0, planes=0, reference_points=0, force=0.0), seed=23)
    q = c.points.q.copy()
    bad = int(np.flatnonzero(c.points.feature == "seat")[4])
    q[bad, 1] += 5e-4                                    # 0.5 mrad on the shoulder: ~0.3 mm off
    pts = replace(c.points, q=q)
    data = make_data(pts, c.artefacts, model)
    res = calibrate(model, data, FitOptions(weights=Weights(probe=2e-6), gross_threshold=None))
    o = max(res.outliers, key=lambda o: abs(o.standardized))      # the gross error is the worst
    assert o.point == bad and o.line == pts.lines[bad] and o.measurement == pts.measurement[bad]
    assert abs(o.standardized) > 10
    assert bad in res.residuals["point"] and len(res.data) == len(data)          # reported, kept
    dropped = calibrate(model, data, FitOptions(weights=Weights(probe=2e-6), drop_outliers=True))
    assert [o.point for o in dropped.dropped] == [bad]          # only the bad one: its neighbours come back
    assert len(dropped.data) == len(data) - 1 and not dropped.outliers
    assert dropped.s0 < res.s0


def _seat_campaign(model, seed):
    c = make_campaign(model, replace(SPEC, rings=0, planes=0, reference_points=0, force=0.0), seed=seed)
    return c, make_data(c.points, c.artefacts, model)


def test_gross_error_is_left_out_by_default(model):
    """A 50 mm blunder (0.1 rad on the shoulder) on one seat point: the default leaves it out, says so (its
    deletion residual of tens of millimetres) and returns the fit of the data without it; --keep-outliers's
    fit is pulled far off; on the same campaign without the blunder nothing is left out."""
    c, clean = _seat_campaign(model, 23)
    q = c.points.q.copy()
    bad = int(np.flatnonzero(c.points.feature == "seat")[4])
    q[bad, 1] += 0.1
    data = make_data(replace(c.points, q=q), c.artefacts, model)
    opts = FitOptions(weights=Weights(probe=2e-6))
    res = calibrate(model, data, opts)
    assert [g.outlier.point for g in res.gross] == [bad] and res.gross_kept is None
    assert abs(res.gross[0].outlier.standardized) >= opts.gross_threshold and res.gross[0].residual > 0.02
    assert len(res.data) == len(data) - 1 and not res.dropped
    ref = calibrate(model, data.select(np.setdiff1d(np.arange(len(data)), [bad])), opts)
    assert np.max(np.abs(res.p - ref.p)) < 1e-9
    kept = calibrate(model, data, replace(opts, gross_threshold=None))
    assert not kept.gross and len(kept.data) == len(data) and np.max(np.abs(kept.p - ref.p)) > 1e-5
    assert not calibrate(model, clean, opts).gross


def test_gross_errors_beyond_a_small_share_are_the_models(model):
    """More gross-looking points than 5 % of them: the first are left out, the rest kept and said (an error
    of the model, not of the data)."""
    c = make_campaign(model, replace(SPEC, ballbars=4, spheres=0, rings=0, planes=0, reference_points=0,
                                     force=0.0), seed=23)
    q = c.points.q.copy()
    seats = np.flatnonzero(c.points.feature == "seat")
    limit = max(1, int(0.05 * len(q)))
    for k, i in enumerate(seats[:limit + 2]):
        q[i, 1] += 0.02 * (1 + k)
    data = make_data(replace(c.points, q=q), c.artefacts, model)
    res = calibrate(model, data, FitOptions(weights=Weights(probe=2e-6)))
    assert len(res.gross) == limit and res.gross_kept and "error of the model" in res.gross_kept
    assert len(res.data) == len(data) - limit


def test_effect_parameters_are_calibrated(nominal):
    """A model with an effect (probe compliance increment): its parameter is identified with the base ones."""
    model = ArmModel(nominal, (ProbeCompliance(),))
    truth = random_truth(model, np.random.default_rng(24))
    truth[model.spec.index("probe.dcompliance_bend")] = 3e-6
    c = make_campaign(model, replace(SPEC, force=3.0, reference_points=0), seed=24, p_true=truth)
    res = calibrate(model, make_data(c.points, c.artefacts, model), FitOptions(weights=Weights(probe=2e-6)))
    assert "probe.dcompliance_bend" in res.free
    u = res.uncertainty("probe.dcompliance_bend")
    assert abs(res.value("probe.dcompliance_bend") - 3e-6) < 3 * u and u < 5e-7


def test_articulation_figures_by_hand():
    x = np.array([[0.0, 0, 0], [2e-6, 0, 0], [0, 4e-6, 0], [0, 0, -2e-6]])
    a = _articulation(x)
    mean = x.mean(axis=0)
    assert_close(a["centre"], mean, atol=1e-18)
    assert_close(a["half_range"], [1e-6, 2e-6, 1e-6], atol=1e-18)
    assert_close(a["two_sigma"], 2 * np.std(x, axis=0, ddof=1), atol=1e-18)
    d = np.linalg.norm(x - mean, axis=1)
    assert_close(a["two_rms"], 2 * np.sqrt(np.sum(d ** 2) / 3), atol=1e-18)
    assert_close(a["max_radial"], d.max(), atol=1e-18)


def test_validation_at_the_truth_is_at_noise_level(model):
    """Noise-free data, the true parameters: every validation figure is zero to 1e-9 m; the nominal
    parameters give errors of tens of micrometres."""
    c = make_campaign(model, replace(SPEC, noise=0.0, reference_noise=0.0), seed=25)
    data = _data(model, c)
    v = validate(model, c.p_true, data, Weights(probe=1e-6, reference=1e-6)).summary()
    for key, value in v.items():
        assert abs(value) < 1e-9, key
    v0 = validate(model, np.zeros(model.spec.size), data, Weights(probe=1e-6, reference=1e-6)).summary()
    assert v0["length_error_max"] > 10e-6 and v0["articulation_2sigma"] > 10e-6


def test_probing_scatter_is_net_of_the_propagated_encoder_and_force_noise(nominal, model, noisy):
    """The probing budget against a second implementation: central differences of the ball centres in the
    readings, times the default input uncertainties (encoder step / sqrt(12), the force sensor's Table 1
    values), averaged over the probed points and axes; the net scatter by quadrature; and the floor when the
    stated encoder noise alone exceeds the residual scatter (a coarse 0.01 deg step: about 35 um at 0.7 m)."""
    from dataclasses import replace as dc_replace

    from arm_model.uncertainty import FORCE_SENSOR_U_N
    res = noisy[3]
    b = res.probing_budget()
    pts = res.data.points
    sel = pts.feature != ""
    q, w = pts.q[sel], res.data.wrench[sel]
    u_q = np.array([j.encoder_resolution for j in nominal.joints]) / np.sqrt(12.0)
    var_q = var_f = 0.0
    h = 1e-7
    for k in range(q.shape[1]):
        dq = np.zeros_like(q)
        dq[:, k] = h
        d = (res.model.ball_centres(q + dq, w, res.p) - res.model.ball_centres(q - dq, w, res.p)) / (2 * h)
        var_q += np.mean(d ** 2) * u_q[k] ** 2
    for k in range(3):
        dw = np.zeros_like(w)
        dw[:, k] = 1e-3
        d = (res.model.ball_centres(q, w + dw, res.p) - res.model.ball_centres(q, w - dw, res.p)) / 2e-3
        var_f += np.mean(d ** 2) * FORCE_SENSOR_U_N[k] ** 2
    assert b["encoders"] == pytest.approx(np.sqrt(var_q), rel=1e-4)
    assert b["force sensor"] == pytest.approx(np.sqrt(var_f), rel=1e-4)
    assert 0.1e-6 < b["encoders"] < 1e-6 and 0.1e-6 < b["force sensor"] < 1e-6
    assert b["net"] == pytest.approx(np.sqrt(b["gross"] ** 2 - var_q - var_f), rel=1e-6)
    assert res.probing_scatter() == b["net"] and not b["floored"] and b["net"] < b["gross"]
    coarse = dc_replace(nominal, joints=tuple(dc_replace(j, encoder_resolution=np.radians(0.01))
                                              for j in nominal.joints))
    floored = dc_replace(res, model=ArmModel(coarse)).probing_budget()
    assert floored["floored"] and floored["net"] == 0.0 and floored["encoders"] > floored["gross"]
