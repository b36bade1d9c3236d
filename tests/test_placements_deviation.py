"""The standard uncertainty of a centre's deviation from its seat's mean (calibration.placements.deviation_u),
against the covariance of all the points of a hole built as one matrix and centred by hand."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model.uncertainty import Propagation
from calibration.placements import deviation_u, seat_figures


def _propagation(rng, n, rows, own_sd):
    """A Propagation of n points whose shared errors are ``rows`` random rows a point and whose own covariance
    is a random positive definite 3 x 3 of about ``own_sd`` [m] a point."""
    s = rng.normal(scale=1e-4, size=(n, rows, 3))
    own = []
    for _ in range(n):
        a = rng.normal(scale=own_sd, size=(3, 3))
        own.append(a @ a.T)
    own = np.array(own)
    cov = np.einsum("nri,nrj->nij", s, s) + own
    return Propagation(np.zeros((n, 3)), cov, {}, {}, s), own


def test_deviation_u_is_the_centred_covariance_of_the_hole():
    rng = np.random.default_rng(3)
    feature = np.array(["a"] * 7 + ["b"] * 5 + ["c"] * 2)
    prop, own = _propagation(rng, len(feature), 4, 5e-5)
    got = deviation_u(prop, feature, ("a", "b"))
    for h in ("a", "b"):
        idx = np.flatnonzero(feature == h)
        n = len(idx)
        # the joint covariance of the hole's 3n coordinates: shared rows S_i^T S_k, each point's own on its block
        full = np.zeros((3 * n, 3 * n))
        for a, i in enumerate(idx):
            for b, k in enumerate(idx):
                full[3 * a:3 * a + 3, 3 * b:3 * b + 3] = prop.systematic[i].T @ prop.systematic[k]
            full[3 * a:3 * a + 3, 3 * a:3 * a + 3] += own[i]
        centre = np.kron(np.eye(n) - np.full((n, n), 1.0 / n), np.eye(3))
        want = np.sqrt(np.diag(centre @ full @ centre.T)).reshape(n, 3)
        np.testing.assert_allclose(got[idx], want, rtol=1e-10, atol=0.0)
    assert np.all(np.isnan(got[feature == "c"]))            # a point of no hole asked for


def test_a_shared_shift_of_the_whole_seat_is_no_deviation():
    """Shared rows equal at every point (the seat's whole position uncertain) leave only each point's own
    scatter, (1 - 1/n) of its variance for equal points; seat_figures counts against u_dev."""
    n = 10
    s = np.tile(np.array([[3e-4, -2e-4, 1e-4], [0.0, 5e-4, 0.0]]), (n, 1, 1))
    own = np.tile(np.eye(3) * (1e-4) ** 2, (n, 1, 1))
    prop = Propagation(np.zeros((n, 3)), np.einsum("nri,nrj->nij", s, s) + own, {}, {}, s)
    feature = np.array(["h0"] * 5 + ["h1"] * 5)
    u = deviation_u(prop, feature, ("h0", "h1"))
    np.testing.assert_allclose(u, 1e-4 * np.sqrt(1 - 1 / 5), rtol=1e-12)
    assert np.all(prop.u > u) and np.all(prop.u[:, 0] > 3 * u[:, 0])   # tip's u holds the shift, the deviation not
    x = np.zeros((n, 3))
    x[0] = [3e-4, 0.0, 0.0]              # a deviation of 2.4e-4 m along x: beyond 1.96 u_dev, within tip's 1.96 u
    f = seat_figures(x, feature, ("h0", "h1"), 0.0, u=prop.u, u_dev=u)
    assert f["values"] == 30 and f["inside"] == 30 and f["inside_dev"] == 29


def test_deviation_u_needs_the_shared_rows():
    rng = np.random.default_rng(0)
    prop, _ = _propagation(rng, 3, 2, 1e-5)
    with pytest.raises(ValueError, match="systematic=True"):
        deviation_u(Propagation(prop.centres, prop.cov, {}, {}, None), np.array(["a"] * 3), ("a",))
