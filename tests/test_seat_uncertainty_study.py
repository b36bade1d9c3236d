"""scripts/seat_uncertainty_study.py (docs/calibration.md, "On the placements the fit never saw"): the bounded
growth it measures against the default linear one, fitted by maximum likelihood to held-out errors drawn from a
known truth."""
from __future__ import annotations

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
    rows = [{k: {"inside": 100.0, "inside_dev": 90.0, "median_u_um": 10.0, "values": 30} for k in study.VARIANTS},
            {k: {"inside": 80.0, "inside_dev": 60.0, "median_u_um": 30.0, "values": 90} for k in study.VARIANTS}]
    md = study.pooled(rows)
    assert "| linear | 85.0 % (80.0-100.0) | 67.5 % (60.0-90.0) | 20 |" in md
