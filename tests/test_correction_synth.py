"""Exact synthetic ring campaigns for the correction tests.

Joint angles are found by the simulator's inverse kinematics (:func:`arm_model.sim.ik.solve_ik` on the
nominal arm as the true one) so that the deflected ball centre (``arm_model.ball_centres(desc, q,
wrench)``) lies exactly on the ring's centre-line cylinder with the stylus parallel to the ring axis; the
ring pushes the ball towards the axis (the force the part exerts on the ball). The rigid centres then
show the paper's larger diameter.
"""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import ball_centres
from arm_model.kinematics import probe_rotations
from arm_model.model import ArmModel
from arm_model.sim.ik import IKTargets, solve_ik
from arm_model.sim.truth import Truth

RING_D = 0.174996            # the paper's ring gauge [m]
RING_CENTRE = np.array([0.55, 0.10, 0.05])


def solve(desc, targets, f_base, rng):
    """q (N, J) [rad] with the deflected ball at ``targets`` under the base-frame force ``f_base`` and the
    stylus along -base z, and that force in the probe frame (N, 3) [N]."""
    model = ArmModel(desc)
    truth = Truth(model, np.zeros(model.spec.size), np.zeros((3, 3)), np.zeros(3), np.zeros(3))
    n = len(targets)
    res = solve_ik(truth, IKTargets(position=targets, stylus=np.tile([0.0, 0.0, -1.0], (n, 1)),
                                    x_dir=np.full((n, 3), np.nan), force=f_base, torque=np.zeros((n, 3)),
                                    temperature=np.full(n, 20.0)), rng)
    return res.q, res.wrench[:, :3]


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
    q, f_probe = solve(desc, P, f_base, rng)
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
    # the probe frames from the chain (not the IK): stylus along -base z, and the force, back in the base
    # frame, pushes towards the axis and up by 0.3 of its horizontal part
    R = probe_rotations(nominal, q)
    assert np.max(np.abs(R[:, :, 2] - [0.0, 0.0, -1.0])) < 1e-9
    f_base = np.einsum("nij,nj->ni", R, f)
    inward = (RING_CENTRE[:2] - P[:, :2]) / r[:, None]
    horizontal = np.linalg.norm(f_base[:, :2], axis=1)
    assert np.max(np.abs(f_base[:, :2] / horizontal[:, None] - inward)) < 1e-9
    assert np.max(np.abs(f_base[:, 2] / horizontal - 0.3)) < 1e-9
