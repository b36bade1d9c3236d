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
