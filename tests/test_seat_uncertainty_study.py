"""scripts/seat_uncertainty_study.py (docs/studies/calibration.md, "On the placements the fit never saw"): the bounded
growth it measures against the default linear one, fitted by maximum likelihood to held-out errors drawn from a
known truth; the leave-one-fold-out check of a discrepancy variant against a known truth; the binomial odds of a
pair outside the band with an exact u, against a direct sum."""
from __future__ import annotations

import math
import sys

import numpy as np

from conftest import ROOT

sys.path.insert(0, str(ROOT / "scripts"))
import seat_uncertainty_study as study  # noqa: E402


def _draw(rng, n, sigma0, g, s):
    """Held-out errors at distances d (0-1.5 m) with fit variances v and a discrepancy of sigma0 [m], growth g [1]
    and bound s [m] (s = inf: linear)."""
    d = rng.uniform(0.0, 1.5, n)
    v = np.full(n, (150e-6) ** 2)
    extra = (g * d) ** 2 if np.isinf(s) else s ** 2 * -np.expm1(-(g * d) ** 2 / s ** 2)
    return rng.normal(0.0, np.sqrt(v + sigma0 ** 2 + extra)), v, d


def test_a_bounded_growth_is_recovered_and_a_linear_one_is_not_bounded():
    rng = np.random.default_rng(7)
    e, v, d = _draw(rng, 6000, 50e-6, 1e-3, 300e-6)            # 1 um/mm, saturating at 300 um (reached at 0.3 m)
    (a, b, s), _ = study.fit_saturating(e, v, d)
    assert np.sqrt(s) == np.clip(np.sqrt(s), 270e-6, 330e-6)
    assert np.sqrt(a) < 90e-6
    e, v, d = _draw(rng, 6000, 0.0, 0.5e-3, np.inf)             # linear 0.5 um/mm: the bound goes beyond the reach
    (a, b, s), _ = study.fit_saturating(e, v, d)
    assert np.sqrt(b) == np.clip(np.sqrt(b), 0.45e-3, 0.55e-3)
    assert np.sqrt(s) > 2 * 0.5e-3 * 1.5                         # the bound lies beyond what the distances show


def test_pooled_weights_each_pair_by_its_values():
    rows = [{k: {"inside": 100.0, "inside_dev": 90.0, "z2_dev": 0.5, "median_u_um": 10.0, "values": 30}
             for k in study.VARIANTS},
            {k: {"inside": 80.0, "inside_dev": 60.0, "z2_dev": 2.5, "median_u_um": 30.0, "values": 90}
             for k in study.VARIANTS}]
    md = study.pooled(rows)
    assert "| linear | 85.0 % (80.0-100.0) | 67.5 % (60.0-90.0) | 1 / 0 / 1 | 1.50 | 20 |" in md


def test_fold_check_says_when_a_variance_holds_on_unseen_folds_and_when_it_is_overstated():
    """Held-out rows from a known linear growth (6 folds): the linear variant fitted without a fold predicts it with
    mean z^2 near 1 and a higher likelihood than the constant one, blind to the growth; the same variance doubled
    gives the z^2 the truth implies (below 0.9)."""
    rng = np.random.default_rng(3)
    n, nj = 1200, 2
    fold = np.repeat(np.arange(6), n // 6)
    c = rng.uniform(0.0, 0.5, (n, nj)) ** 2                    # [m^2] each joint's share of d^2
    v = np.full(n, (150e-6) ** 2)
    e = rng.normal(0.0, np.sqrt(v + (40e-6) ** 2 + c.sum(axis=1) * (0.8e-3) ** 2))

    def doubled(name, *rows):
        a, g2 = study.variant_fit("linear", *rows)
        return 2 * a, 2 * g2                                    # the discrepancy's variance twice its estimate
    got = study.fold_check(e, v, c, fold, names=("linear", "constant"))
    assert got["linear"]["z2"] == np.clip(got["linear"]["z2"], 0.93, 1.07)
    assert got["linear"]["loglik"] > got["constant"]["loglik"] + 10
    far = study.fold_check(e, v, c, fold, fit=doubled, names=("linear",))
    share = np.mean(((0.8e-3) ** 2 * c.sum(axis=1) + (40e-6) ** 2) / (v + (40e-6) ** 2 + (0.8e-3) ** 2 * c.sum(axis=1)))
    expect = np.mean(1 / (1 + share))                           # ~ E[e^2 / (v + 2 discrepancy)]
    assert far["linear"]["z2"] == np.clip(far["linear"]["z2"], expect - 0.08, expect + 0.08)
    assert far["linear"]["z2"] < 0.9


def test_band_odds_is_the_binomial_tail():
    n, p = 180, 0.95
    pmf = [math.comb(n, k) * p ** k * (1 - p) ** (n - k) for k in range(n + 1)]
    below = sum(pmf[k] for k in range(n + 1) if 100 * k / n < 90)     # strictly below 90 %
    above = sum(pmf[k] for k in range(n + 1) if 100 * k / n > 97)      # strictly above 97 %
    got = study.band_odds(n, p)
    assert abs(got[0] - below) < 1e-12 and abs(got[1] - above) < 1e-12
    assert 0.10 < got[1] < 0.12                                 # an exact u lands above 97 % one pair in nine


def test_lifted_is_the_larger_covariance_in_every_direction():
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(4, 4)), rng.normal(size=(4, 4))
    post, other = a @ a.T + 0.1 * np.eye(4), b @ b.T
    got = study.lifted(post, other)
    for m in (post, other):                                     # at least each of the two, as a covariance
        assert np.linalg.eigvalsh(got - m).min() > -1e-9 * np.abs(got).max()
    assert np.allclose(study.lifted(post, 0.5 * post), post)    # the posterior where the other is smaller
    assert np.allclose(study.lifted(post, 3.0 * post), 3.0 * post)


def _line_fit(x, y) -> dict:
    """A straight line fitted by least squares to (x, y), as the linearisation a fit hands on
    (:func:`study.captured_linearisation`): one row a point, its angle ``x``."""
    from types import SimpleNamespace

    from calibration.schur import BlockNormal
    a = np.column_stack([np.ones_like(x), x])
    a_inv = np.linalg.inv(a.T @ a)
    r = y - a @ (a_inv @ a.T @ y)
    prob = SimpleNamespace(row_point=np.arange(len(x)), row_distance=np.full(len(x), -1.0), instances=[],
                           data=SimpleNamespace(points=SimpleNamespace(q=x[:, None])))
    return {"prob": prob, "r": r, "factor": BlockNormal(a, 2), "var": float(r @ r / (len(x) - 2))}


def test_fold_shift_widens_the_slope_where_the_line_misses_a_curvature():
    """A line fitted to a parabola: leaving out either end of the range moves the slope far beyond what the noise
    gives, so the fold-shift covariance of the slope is several times the posterior; fitted to a line it stays near
    it (its positive part keeps some of the noise)."""
    ratios = {}
    for curvature in (0.0, 3.0):
        got = []
        for seed in range(20):
            rng = np.random.default_rng(seed)
            x = rng.uniform(-1.0, 1.0, 60)
            lin = _line_fit(x, 1.0 + 2.0 * x + curvature * x ** 2 + rng.normal(0.0, 1.0, 60))
            post, jack, shift = (study.robust_covariance(c, 2, lin) for c in study.COVARIANCES)
            assert np.linalg.eigvalsh(shift - post).min() > -1e-12 and np.linalg.eigvalsh(jack - post).min() > -1e-12
            got.append(shift[1, 1] / post[1, 1])
        ratios[curvature] = float(np.mean(got))
    assert ratios[0.0] < 1.5                                    # measured 1.27
    assert ratios[3.0] > 5.0                                    # measured 9.5


def test_joint_play_is_recovered_from_deviations_and_not_found_in_an_isotropic_scatter():
    """Deviations drawn from known play of three joints (random levers up to 0.8 m, the third's axis through the
    ball) plus an isotropic scatter: the play of the two seen joints and the scatter come back within 10 %, the
    hidden joint's at 0; an isotropic scatter alone gives a likelihood ratio of chi-square size, no play."""
    rng = np.random.default_rng(11)
    n = 800
    levers = rng.uniform(-0.8, 0.8, (n, 3, 3))                 # [m/rad] the ball's motion per radian, per joint
    levers[:, 2] *= 1e-6                                        # joint 3: its axis passes through the ball
    blocks = np.einsum("nja,njb->njab", levers, levers)
    weight = np.full(n, 1.0)
    play = np.array([300e-6, 150e-6, 0.0])                      # [rad]
    dev = np.einsum("nja,nj->na", levers, rng.normal(size=(n, 3)) * play) + rng.normal(0.0, 80e-6, (n, 3))
    sd_q, iso, lr = study.fit_joint_play(dev, blocks, weight)
    assert np.allclose(sd_q[:2], play[:2], rtol=0.1) and sd_q[2] == 0.0
    assert iso == np.clip(iso, 72e-6, 88e-6) and lr > 100
    sd_q, iso, lr = study.fit_joint_play(rng.normal(0.0, 80e-6, (n, 3)), blocks, weight)
    assert lr < 12 and np.all(sd_q * 0.8 < 40e-6)              # no play worth half the scatter at 0.8 m
