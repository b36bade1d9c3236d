"""Redundant inverse kinematics on the true arm: on target to 1 pm, inside the joint limits, the
required stylus direction, different articulations for the same target; unreachable targets raise. The fast
path's position-only IK on the core model; the probe frame against Pinocchio."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import NumericalError
from arm_model.sim import campaign_from_dict, simulate
from arm_model.sim.ik import IKTargets, joint_limits, solve_ik, wrap_into_limits
from arm_model.sim.truth import build_truth
from conftest import assert_close


@pytest.fixture(scope="module")
def seat_and_ring():
    return simulate(campaign_from_dict({
        "seed": 21, "signals": {"enabled": False}, "operator": {"point_period_s": 0.5},
        "task": [{"kind": "seat", "articulations": 25, "stylus_cone_deg": 60.0},
                 {"kind": "ring", "points_per_row": 6, "roll": "bend-along-force", "roll_jitter_deg": 5.0}]}))


def test_inside_joint_limits(seat_and_ring):
    lo, hi = joint_limits(seat_and_ring.campaign.arm)
    q = seat_and_ring.true_q
    assert np.all(q >= lo) and np.all(q <= hi)
    assert np.all(seat_and_ring.points.q >= lo - 1e-9) and np.all(seat_and_ring.points.q <= hi + 1e-9)


def test_articulations_are_redundant_and_varied(seat_and_ring):
    r = seat_and_ring
    seat = r.points.feature == "seat"
    q = r.true_q[seat]
    assert_close(r.true_centres[seat], np.tile(r.truth["placements"]["seat"]["position_m"], (seat.sum(), 1)),
                 atol=1e-12)
    # every pair of articulations differs by more than 0.1 rad in some joint, and each joint varies
    diff = np.abs(q[:, None, :] - q[None, :, :]).max(axis=2)
    assert np.all(diff[~np.eye(len(q), dtype=bool)] > 0.1)
    assert np.all(np.std(q, axis=0) > 0.1)


def test_stylus_and_roll_directions(seat_and_ring):
    r = seat_and_ring
    truth = r.truth["truth"]
    R = truth.rotation(r.true_q, r.points.temperature)       # columns: probe x, y, z in base
    ring = r.points.feature == "ring"
    axis = np.array(r.truth["placements"]["ring"]["axis"])
    assert_close(R[ring][:, :, 2] @ axis, -np.ones(ring.sum()), atol=1e-12)  # stylus parallel to the axis, down
    # roll along the force: probe x within the jitter of the bending force's direction
    f = r.true_wrench[ring]
    angle = np.degrees(np.arctan2(np.abs(f[:, 1]), f[:, 0]))
    assert np.all(angle <= 5.0 + 1e-6)
    # seat: stylus within its cone about -axis
    seat = r.points.feature == "seat"
    cosang = R[seat][:, :, 2] @ np.array([0, 0, -1.0])
    assert np.all(cosang >= np.cos(np.radians(60.0)) - 1e-12)


def test_unreachable_target_raises():
    c = campaign_from_dict({"seed": 1, "task": [{"kind": "seat", "articulations": 1,
                                                 "position_mm": [2500.0, 0.0, 0.0]}]})
    with pytest.raises(NumericalError, match="out of the arm's reach"):
        simulate(c)


def test_solve_ik_directly_on_target_with_given_directions():
    c = campaign_from_dict({"seed": 2, "task": [{"kind": "seat"}]})
    truth = build_truth(c.arm, c.truth, np.random.default_rng(0))
    n = 12
    rng = np.random.default_rng(4)
    pos = np.column_stack([rng.uniform(0.4, 0.7, n), rng.uniform(-0.3, 0.3, n), rng.uniform(0.0, 0.3, n)])
    stylus = np.tile([0.0, 0.0, -1.0], (n, 1))
    force = np.column_stack([np.zeros((n, 2)), rng.uniform(0.5, 3, n)])   # pushing the ball up
    tg = IKTargets(pos, stylus, np.full((n, 3), np.nan), force, np.zeros((n, 3)), rng.uniform(18, 25, n))
    res = solve_ik(truth, tg, rng)
    ball, z, _ = truth.pose(res.q, truth.geometry(tg.temperature), res.wrench)
    assert_close(ball, pos, atol=1e-12)
    assert_close(z, stylus, atol=1e-12)
    # the wrench is the world force in the probe frame: stylus down -> force along -z of the probe
    assert_close(res.wrench[:, 2], -force[:, 2], atol=1e-12)


def test_wrap_into_limits():
    lo, hi = np.array([-2 * np.pi, -2.0]), np.array([2 * np.pi, 2.0])
    q, ok = wrap_into_limits(np.array([[7.0, 2.0 * np.pi + 1.0], [-4.0, 3.0]]), lo, hi)
    assert_close(q, [[7.0 - 2 * np.pi, 1.0], [-4.0 + 2 * np.pi, 3.0]], atol=1e-15)
    assert ok.tolist() == [True, False]


def test_ik_jacobian_matches_pinocchio_and_finite_differences(nominal):
    """The IK's exact Jacobians (one forward pass, :meth:`Truth.pose_jacobian`) against Pinocchio's analytic
    one (ball) and central differences of :meth:`Truth.pose` (ball, probe z and x axes), a fixed wrench."""
    from arm_model import PinocchioArm
    from arm_model.sim.ik import ball_jacobian
    from conftest import fd_jacobian

    c = campaign_from_dict({"seed": 3, "task": [{"kind": "seat"}]})
    truth = build_truth(c.arm, c.truth, np.random.default_rng(1))
    rng = np.random.default_rng(5)
    q = rng.uniform(-2.5, 2.5, (6, 7))
    w = np.column_stack([rng.normal(0, 3, (6, 3)), np.zeros((6, 3))])
    jac = ball_jacobian(truth, q, np.full(6, 20.0), w)
    arm = PinocchioArm(truth.description)
    geom = truth.geometry(np.full(1, 20.0))
    _, _, _, jb, jz, jx, _ = truth.pose_jacobian(q, truth.geometry(np.full(6, 20.0)), w)
    assert_close(jb, jac, atol=0.0)
    for i in range(6):
        jq, _ = arm.jacobians(q[i], w[i, :3])
        assert_close(jac[i], jq, atol=1e-9 * np.abs(jq).max())
        for k, ref in enumerate((jb, jz, jx)):
            fd = fd_jacobian(lambda x: truth.pose(x[None], geom, w[i:i + 1])[k][0], q[i])
            assert_close(ref[i], fd, atol=1e-9 * np.abs(fd).max(), msg=f"point {i} output {k}")


def test_fast_path_ik_puts_the_models_ball_on_target_with_the_force_in_the_probe_frame(nominal):
    """solve_positions (the fast path): the core model's deflected ball centre on each target to 1e-12 m,
    inside the joint limits, through an effect that depends on the pose (approach offset), with the contact
    force rotated into the probe frame of the solution; Pinocchio's probe frame as the reference rotation."""
    from arm_model import PinocchioArm
    from arm_model.effects import ApproachOffset
    from arm_model.kinematics import probe_rotations
    from arm_model.model import ArmModel
    from arm_model.params import apply_params
    from arm_model.sim.ik import solve_positions

    model = ArmModel(nominal, (ApproachOffset(),))
    p = model.spec.vector({"approach.dx_uy": 6e-6, "approach.dz_ux": 5e-6, "j2.d": 3e-5})
    rng = np.random.default_rng(7)
    targets = np.array([0.55, 0.0, 0.15]) + rng.uniform(-0.15, 0.15, (12, 3))
    force = rng.normal(0, 3, (12, 3))
    q, w = solve_positions(model, p, targets, rng, force)
    assert_close(model.ball_centres(q, w, p), targets, atol=1e-12)
    lo, hi = joint_limits(nominal)
    assert np.all(q >= lo) and np.all(q <= hi)
    rot = probe_rotations(nominal, q, p[: model.base_size])
    arm = PinocchioArm(apply_params(nominal, p[: model.base_size]))
    for i in range(12):
        r_ref = arm.T_base_ball(q[i])[:3, :3]
        assert_close(rot[i], r_ref, atol=1e-12)
        assert_close(w[i, :3], r_ref.T @ force[i], atol=1e-12)
    assert_close(w[:, 3:], 0.0, atol=0.0)


def test_probe_rotations_of_a_rotated_probe_are_pinocchios_ball_frame(nominal):
    from arm_model import PinocchioArm
    from arm_model.kinematics import probe_rotations

    desc = nominal.with_probe(rpy=(0.2, -0.1, 0.4))
    q = np.random.default_rng(8).uniform(-2.5, 2.5, (5, desc.n_joints))
    arm = PinocchioArm(desc)
    rot = probe_rotations(desc, q)
    for i in range(5):
        assert_close(rot[i], arm.T_base_ball(q[i])[:3, :3], atol=1e-12)
