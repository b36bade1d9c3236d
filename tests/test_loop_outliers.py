"""The loop's outliers are calibrate's: a point's rows tested together (the point test of
calibration.discrepancy.point_tests), for the design set's base fit and the outer test set's alike."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from calibration import Weights, make_data
from calibration.loop import drop_test_outliers
from calibration.validation import heldout_residuals

SPEC = SynthSpec(ballbars=4, ballbar_points=5, seats=4, articulations=8, spheres=1, sphere_points=12, noise=2e-6)
STATED = Weights(probe=2e-6)


@pytest.fixture(scope="module")
def campaign(nominal):
    model = ArmModel(nominal)
    return model, make_campaign(model, SPEC, seed=7)


def _moved(model, c, i: int, dp) -> np.ndarray:
    """The readings with point ``i``'s ball moved by ``dp`` [m] (base frame): its angles moved along the
    least-norm solution of the ball's Jacobian (central differences)."""
    q = c.points.q.copy()
    cols = []
    for k in range(q.shape[1]):
        d = np.zeros_like(q[i])
        d[k] = 1e-7
        plus = model.ball_centres((q[i] + d)[None], p=c.p_true)
        minus = model.ball_centres((q[i] - d)[None], p=c.p_true)
        cols.append((plus - minus)[0] / 2e-7)
    q[i] += np.linalg.lstsq(np.column_stack(cols), dp, rcond=None)[0]
    return q


def test_a_point_gross_in_its_three_rows_together_is_dropped_whole(campaign):
    """A seat point moved 3.2 sigma along each axis (5.5 sigma in all): no row of it reaches 4 robust standard
    deviations, so the row-by-row rule the loop had kept it; the point test of its three rows together (chi-square
    27 on 3 rows: p 6e-6) drops it, alone and whole (one entry, not one a row), and nothing else."""
    model, c = campaign
    seat = np.flatnonzero(c.points.feature == "seat")
    i = int(seat[3])
    q = _moved(model, c, i, np.full(3, 3.2 * 2e-6))
    data = make_data(replace(c.points, q=q), c.artefacts, model)
    p = c.p_true
    h = heldout_residuals(model, p, data, STATED, "fit")
    rows = h["point"] == i
    assert np.all(np.abs(h["r"][rows]) < 4.0), h["r"][rows]          # row by row: not an outlier
    kept, out = drop_test_outliers(model, p, data, STATED, "fit", 4.0)
    assert [(o["measurement"], o["line"]) for o in out] == [(c.points.measurement[i], int(c.points.lines[i]))], out
    assert out[0]["standardized"] > 4.0 and out[0]["why"] == "outlier"
    assert len(kept) == len(data) - 1
    kept, out = drop_test_outliers(model, p, make_data(c.points, c.artefacts, model), STATED, "fit", 4.0)
    assert out == []
