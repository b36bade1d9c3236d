"""The gross-error test of a point: its rows' group-deletion residual against the covariance the joint fit
predicts for it (:func:`calibration.discrepancy.group_deletions`, :func:`calibration.calibrate.point_tests`),
as a standardized residual of the row-by-row test's false-alarm rate (:func:`calibration.calibrate.
sigma_equivalent`).

Independent references: an explicit least-squares refit without the group (numpy's lstsq on the rows kept,
the prior as extra rows), scipy's chi-square and normal tails, the blunder injected into a simulated campaign."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.stats import chi2, norm

from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from calibration import FitOptions, calibrate, make_data
from calibration.calibrate import sigma_equivalent
from calibration.discrepancy import deletion_shift, group_deletions
from calibration.schur import BlockNormal


def _linear(seed, n=40, k=6, prior=0.5):
    """A random linear problem: Jacobian (n, k), residuals of the fit with a ridge prior of precision
    ``prior``, ``solve`` of its normal matrix, and the data to refit."""
    rng = np.random.default_rng(seed)
    j = rng.normal(size=(n, k))
    y = rng.normal(size=n)
    a = j.T @ j + prior * np.eye(k)
    beta = np.linalg.solve(a, j.T @ y)
    return j, y, beta, a, y - j @ beta


def test_group_deletion_is_the_refit_without_the_group():
    """``e_O`` is the prediction error of the rows O by the fit without them (refitted from scratch, the prior
    as k extra rows), ``d_O`` the change of the unknowns, ``M_O`` the covariance factor of ``e_O``: the rows'
    unit variance plus the posterior of the fit without them, ``I + J_O A_-O^-1 J_O^T``."""
    j, y, beta, a, r = _linear(1)
    prior = 0.5
    groups = [np.array([0, 1, 2]), np.array([7]), np.array([20, 5])]
    factor = BlockNormal(sp.csc_matrix(j), j.shape[1], prior)
    got = group_deletions(factor, -r, groups, chunk=4)
    for o, (e, m) in zip(groups, got, strict=True):
        d = deletion_shift(factor, o, e)
        keep = np.setdiff1d(np.arange(len(y)), o)
        jk = np.vstack([j[keep], np.sqrt(prior) * np.eye(j.shape[1])])
        yk = np.concatenate([y[keep], np.zeros(j.shape[1])])
        b_without = np.linalg.lstsq(jk, yk, rcond=None)[0]
        # residual convention of the fit: r = model - measured, so e_O = J_O b_without - y_O
        np.testing.assert_allclose(e, j[o] @ b_without - y[o], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(d, b_without - beta, rtol=1e-9, atol=1e-12)
        a_without = jk.T @ jk
        np.testing.assert_allclose(m, np.eye(len(o)) + j[o] @ np.linalg.solve(a_without, j[o].T), rtol=1e-10)


def test_group_the_fit_cannot_do_without_is_not_tested():
    """Rows whose deletion leaves an unknown undetermined (the only row on a column): (None, None)."""
    j = np.zeros((5, 2))
    j[:, 0] = 1.0
    j[4, 1] = 1.0
    got = group_deletions(BlockNormal(sp.csc_matrix(j), 2), np.ones(5), [np.array([4]), np.array([0, 1])])
    assert got[0] == (None, None) and got[1][0] is not None


def test_deletion_statistic_is_chi_square_on_clean_gaussian_data():
    """With unit Gaussian noise, ``T = r_O^T M_O r_O`` of a 3-row group is chi-square with 3 degrees of
    freedom (the predicted covariance is exact): its mean within 5 % and its 99th percentile within 10 % over
    3000 groups of 300 random linear fits."""
    t = []
    for seed in range(300):
        j, y, beta, a, r = _linear(seed + 10, n=30, k=8, prior=1e-3)
        groups = [np.arange(3 * i, 3 * i + 3) for i in range(10)]
        for e, m in group_deletions(BlockNormal(sp.csc_matrix(j), j.shape[1], 1e-3), r, groups):
            t.append(float(e @ np.linalg.solve(m, e)))      # = r_O^T M_O r_O
    t = np.array(t)
    assert abs(np.mean(t) / 3.0 - 1.0) < 0.05
    assert abs(np.quantile(t, 0.99) / chi2.ppf(0.99, 3) - 1.0) < 0.1


@pytest.mark.parametrize("rows", [1, 2, 3, 6])
def test_sigma_equivalent_keeps_the_row_by_row_false_alarm_rate(rows):
    """A point of ``rows`` rows flagged at k: ``P(chi2_rows >= T) = 1 - (1 - 2 Phi(-k))^rows``, the rate at which
    the largest of its rows' |z| reaches k on clean data; for one row ``sqrt(T)``; increasing, and finite far
    in the tail."""
    for k in (2.0, 4.0, 6.0, 8.0):
        crit = chi2.isf(-np.expm1(rows * np.log1p(-2 * norm.sf(k))), rows)
        assert sigma_equivalent(crit, rows) == pytest.approx(k, rel=1e-6)
    assert sigma_equivalent(49.0, 1) == pytest.approx(7.0, rel=1e-9)
    far = [sigma_equivalent(t, rows) for t in (1e2, 1e3, 1e4, 1e6)]
    assert np.all(np.isfinite(far)) and np.all(np.diff(far) > 0)
    assert far[-1] == pytest.approx(1e3, rel=0.02)          # sqrt(T) far in the tail


def _tracker_session(model, seed, n=30):
    spec = SynthSpec(ballbars=0, seats=0, spheres=0, rings=0, planes=0, reference_points=n, force=0.0, noise=0.0,
                     reference_noise=5e-6)
    return make_campaign(model, spec, seed=seed).reference_points


def _edge(q):
    half = np.maximum(np.ptp(q, axis=0) / 2, 1e-9)
    return int(np.argmax(np.max(np.abs(q - np.median(q, axis=0)) / half, axis=1)))


def test_a_leveraged_blunder_in_a_small_session_is_found(nominal):
    """A tracker session of 30 postures, one marker reading 12 noise sigmas (60 um) off at the posture at the
    edge of the joint ranges: it pulls the fit towards itself, so its rows' standardized residuals in the fit
    that holds it stay below 6 (4.9 on this seed; 4.9-5.9 on seeds 0-9, every one kept by the row-by-row
    test), while the point test finds it (9.0; 7.6-12.2 on seeds 0-9) and its deletion residual is the
    blunder to 25 %; the same session clean loses no point."""
    model = ArmModel(nominal)
    ref = _tracker_session(model, 4)
    bad = _edge(ref.q)
    x = ref.ref.copy()
    x[bad, 0] += 60e-6 * np.array([0.48, -0.6, 0.64])
    data = make_data(replace(ref, ref=x), None, model)
    kept = calibrate(model, data, FitOptions(gross_threshold=None))
    tab = kept.residuals
    assert 4.0 < np.max(np.abs(tab["standardized"][tab["point"] == bad])) < 6.0
    res = calibrate(model, data, FitOptions())
    assert [g.outlier.point for g in res.gross] == [bad] and res.gross_kept is None
    assert abs(res.gross[0].outlier.standardized) >= 8.0
    assert res.gross[0].residual == pytest.approx(60e-6, rel=0.25)
    assert not calibrate(model, make_data(ref, None, model), FitOptions()).gross


ART = SynthSpec(ballbars=3, ballbar_points=5, seats=3, articulations=8, spheres=1, sphere_points=12, rings=0,
                planes=0, reference_points=0, force=0.0, noise=2e-6)


def _bar_moved(model, seed, shift, bad_seat_sigma):
    """A small artefact session (66 points) with two gross errors: in the first ball-bar placement the B end moved
    ``shift`` [m] along the bar between the probing of its two ends (its sphere points consistent, the certified
    length not: a gross error of the length alone), and one seat point whose shoulder angle reads
    ``bad_seat_sigma`` noise sigmas of ball displacement off. Returns the data, the placement and the seat point."""
    from arm_model.sim.ik import solve_positions
    rng = np.random.default_rng(seed)
    c = make_campaign(model, ART, seed=seed)
    pts = c.points
    m = sorted({m for m, f in zip(pts.measurement, pts.feature, strict=True) if f == "bar-B"})[0]
    a, b = ((pts.measurement == m) & (pts.feature == f) for f in ("bar-A", "bar-B"))
    xa, xb = (model.ball_centres(pts.q[s], None, c.p_true) for s in (a, b))
    u = xb.mean(axis=0) - xa.mean(axis=0)
    q = pts.q.copy()
    q[b] = solve_positions(model, c.p_true, xb + shift * u / np.linalg.norm(u), rng)[0]
    seat = int(rng.choice(np.flatnonzero(pts.feature == "seat")))
    q1 = q[seat:seat + 1].copy()
    q1[0, 1] += 1e-4
    d0 = float(np.linalg.norm(np.diff(model.ball_centres(np.vstack([q[seat:seat + 1], q1]), None, c.p_true), axis=0)))
    q[seat, 1] += 1e-4 * bad_seat_sigma * ART.noise / d0
    return make_data(replace(pts, q=q), c.artefacts, model), m, seat


@pytest.fixture(scope="module")
def bar_moved(nominal):
    """The session of :func:`_bar_moved` (seed 0, the B end 80 um along the bar, an 8-sigma seat blunder) and its
    default fit."""
    model = ArmModel(nominal)
    data, bar, seat = _bar_moved(model, 0, 80e-6, 8.0)
    return model, data, bar, seat, calibrate(model, data, FitOptions())


def test_a_certified_length_is_tested_as_a_point(bar_moved):
    """A ball-bar placement whose B end moved 80 um along the bar (its length 0.1 mm off under a 0.8 um
    certificate; its sphere points are consistent, so no point's test can see it) and an 8-sigma seat blunder:
    the default (level 6) leaves the length out, names it (measurement, the two features; its deletion residual,
    the centres' distance found on their points alone less the certified length, is the shift to 25 %) and keeps
    every point (the seat's test is below 6). Before, a length was never tested."""
    _, data, bar, seat, res = bar_moved
    assert [(g.outlier.kind, g.outlier.measurement, g.outlier.feature) for g in res.gross] == \
        [("distance", bar, "bar-A - bar-B")]
    assert res.data.left_out_lengths == ((bar, ("bar-A", "bar-B")),) and len(res.data) == len(data)
    assert abs(res.gross[0].residual) == pytest.approx(80e-6, rel=0.25)
    t = res.point_tests
    assert len(t["length"]) == len(res.distances) == 2                # the two lengths kept, tested
    assert np.all(t["length_sigma"] < 6.0)
    assert 4.0 < t["sigma"][int(np.flatnonzero(t["point"] == seat)[0])] < 6.0


def test_drop_outliers_drops_what_the_point_test_names(bar_moved):
    """``--drop-outliers`` (level ``--outlier-threshold``, 4) drops the points and lengths the gross-error test
    names at that level (the test's statistic is the default's), the length and the seat point of
    :func:`bar_moved`, and nothing else; before, it judged rows one by one and never a length."""
    model, data, _, seat, res = bar_moved
    dropped = calibrate(model, data, FitOptions(drop_outliers=True, gross_threshold=None))
    assert sorted((o.kind, -1 if o.point is None else o.point) for o in dropped.dropped) == \
        [("distance", -1), ("seat", seat)]
    length = next(o for o in dropped.dropped if o.kind == "distance")
    assert length.standardized == pytest.approx(res.gross[0].outlier.standardized, rel=1e-9)
    assert dropped.data.left_out_lengths == res.data.left_out_lengths and len(dropped.data) == len(data) - 1
    assert not any(abs(s) >= 4.0 for s in np.nan_to_num(np.concatenate(
        [dropped.point_tests["sigma"], dropped.point_tests["length_sigma"]])))
