"""Exact synthetic ring campaigns for the correction tests (independent of arm_model.sim).

Joint angles are found by a batch damped Newton inverse kinematics so that the deflected ball centre
(``arm_model.ball_centres(desc, q, wrench)``) lies exactly on the ring's centre-line cylinder with the
stylus parallel to the ring axis; the ring pushes the ball towards the axis (the force the part exerts on
the ball). The rigid centres then show the paper's larger diameter.
"""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import ball_centres

RING_D = 0.174996            # the paper's ring gauge [m]
RING_CENTRE = np.array([0.55, 0.10, 0.05])


def probe_rotation(desc, q) -> np.ndarray:
    """(N, 3, 3) R_base_probe from the rigid chain: columns are differences of ball centres with the probe
    point moved by one unit along probe x, y, z (exact: the probe point enters linearly)."""
    p0 = np.array(desc.probe.p_last)
    base = ball_centres(desc, q)
    cols = []
    for k in range(3):
        p = p0.copy()
        p[k] += 0.01
        cols.append((ball_centres(desc.with_probe(p_last=tuple(p)), q) - base) / 0.01)
    return np.stack(cols, axis=2)


def solve_ik(desc, targets, f_base, q0, iters: int = 60):
    """q (N, J) with ball_centres(desc, q, R^T f_base) == targets and probe z == -base z."""
    n, J = len(targets), desc.n_joints
    q = np.tile(q0, (n, 1)).astype(float)
    zdes = np.array([0.0, 0.0, -1.0])
    lever = 0.1

    def residual(qq):
        R = probe_rotation(desc, qq)
        w = np.einsum("nji,nj->ni", R, f_base)
        x = ball_centres(desc, qq, w)
        return np.concatenate([x - targets, lever * (R[:, :, 2] - zdes)], axis=1)

    for _ in range(iters):
        r = residual(q)
        if np.max(np.abs(r[:, :3])) < 1e-13 and np.max(np.abs(r[:, 3:])) < 1e-12:
            break
        Jm = np.empty((n, 6, J))
        h = 1e-7
        for k in range(J):
            dq = np.zeros(J)
            dq[k] = h
            Jm[:, :, k] = (residual(q + dq) - residual(q - dq)) / (2 * h)
        lam = 1e-8
        A = np.einsum("nij,nik->njk", Jm, Jm) + lam * np.eye(J)
        b = np.einsum("nij,ni->nj", Jm, r)
        q = q - np.linalg.solve(A, b[:, :, None])[:, :, 0]
    r = residual(q)
    assert np.max(np.abs(r[:, :3])) < 1e-11, np.max(np.abs(r[:, :3]))
    return q


def ring_measurement(desc, rng, n_rows=3, per_row=8, row_gap=0.008, force_mean=1.0, axial=0.3,
                     centre=RING_CENTRE, diameter=RING_D, start=0.0, arc=2 * np.pi):
    """One exact ring measurement: q (N, J) [rad], force (N, 3) probe frame [N], true centres (N, 3) [m]."""
    r = (diameter - desc.probe.ball_diameter) / 2
    th = start + np.linspace(0, arc, per_row, endpoint=arc < 2 * np.pi - 1e-9)
    pts, inward, fmag = [], [], []
    for k in range(n_rows):
        t = th + rng.uniform(-0.05, 0.05, per_row)
        radial = np.column_stack([np.cos(t), np.sin(t), np.zeros(per_row)])
        h = (k - (n_rows - 1) / 2) * row_gap + rng.uniform(-5e-4, 5e-4, per_row)
        pts.append(centre + r * radial + np.outer(h, [0, 0, 1]))
        inward.append(-radial)
        fmag.append(force_mean * rng.uniform(0.3, 2.2, per_row))
    P, U, fm = np.vstack(pts), np.vstack(inward), np.concatenate(fmag)
    # the ring pushes the ball towards the axis; the stylus is also pushed up (axial, towards the flange)
    f_base = fm[:, None] * U + axial * fm[:, None] * np.array([0, 0, 1.0])
    q0 = np.radians([5.0, 40.0, 0.0, 80.0, 0.0, 60.0, 0.0])
    q = solve_ik(desc, P, f_base, q0)
    R = probe_rotation(desc, q)
    f_probe = np.einsum("nji,nj->ni", R, f_base)
    return q, f_probe, P


@pytest.fixture(scope="module")
def synth_measurement(nominal):
    rng = np.random.default_rng(7)
    return ring_measurement(nominal, rng)


def test_synthetic_measurement_is_exact(nominal, synth_measurement):
    q, f, P = synth_measurement
    # deflected centres lie on the ring; the force has no probe-frame inconsistency
    assert np.max(np.abs(ball_centres(nominal, q, f) - P)) < 1e-11
    r = np.hypot(*(P[:, :2] - RING_CENTRE[:2]).T)
    assert np.max(np.abs(r - (RING_D - nominal.probe.ball_diameter) / 2)) < 1e-15 + 1e-12
    # the rigid centres lie further out (the paper's larger diameter)
    rigid = ball_centres(nominal, q)
    rr = np.hypot(*(rigid[:, :2] - RING_CENTRE[:2]).T)
    assert np.all(rr > r)
