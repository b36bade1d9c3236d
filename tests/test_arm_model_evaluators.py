"""The three evaluators of one model agree, with an independent hand-written DH product too."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import PinocchioArm, apply_params, ball_centres, casadi_ball_centre, param_spec
from conftest import assert_close, fd_jacobian


def hand_dh_point(desc, q, p_last):
    """Independent reference: 4x4 matrix product of the DH formula of docs/formats.md §2."""
    def rz(t):
        c, s = math.cos(t), math.sin(t)
        return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])

    def rx(t):
        c, s = math.cos(t), math.sin(t)
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])

    def tz(d):
        m = np.eye(4); m[2, 3] = d; return m

    def tx(a):
        m = np.eye(4); m[0, 3] = a; return m

    T = np.eye(4)
    for j, qi in zip(desc.joints, q):
        if desc.convention == "dh":
            T = T @ rz(j.theta_offset + qi) @ tz(j.d) @ tx(j.a) @ rx(j.alpha)
        else:
            T = T @ rx(j.alpha) @ tx(j.a) @ rz(j.theta_offset + qi) @ tz(j.d)
    return (T @ np.array([*p_last, 1.0]))[:3], T


def random_inputs(rng, n, desc):
    q = rng.uniform(-math.pi, math.pi, (n, desc.n_joints))
    w = np.zeros((n, 6))
    w[:, :3] = rng.normal(0, 3.0, (n, 3))
    w[:, 3:] = rng.normal(0, 0.05, (n, 3))
    return q, w


def random_params(rng, desc):
    spec = param_spec(desc)
    p = np.zeros(spec.size)
    for i, u in enumerate(spec.units):
        p[i] = rng.normal(0, {"rad": 1e-3, "m": 1e-4, "m/N": 3e-6}[u])
    return p


@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_three_evaluators_agree_to_1e12(nominal, convention):
    rng = np.random.default_rng(11)
    desc = nominal if convention == "dh" else _mdh_variant(nominal)
    f = casadi_ball_centre(desc)
    for trial in range(3):
        p = random_params(rng, desc)
        d_p = apply_params(desc, p)
        arm = PinocchioArm(d_p)
        q, w = random_inputs(rng, 20, desc)
        batch = ball_centres(desc, q, w, p)
        for i in range(len(q)):
            assert_close(arm.ball_centre(q[i], w[i]), batch[i], atol=1e-12)
            assert_close(np.array(f(q[i], w[i], p)).ravel(), batch[i], atol=1e-12)


def _mdh_variant(desc):
    from dataclasses import replace
    return replace(desc, convention="mdh", name="aacmm7-mdh")


@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_rigid_matches_hand_written_dh_product(nominal, convention):
    rng = np.random.default_rng(3)
    desc = nominal if convention == "dh" else _mdh_variant(nominal)
    p = random_params(rng, desc)
    d_p = apply_params(desc, p)
    q, _ = random_inputs(rng, 50, desc)
    batch = ball_centres(desc, q, None, p)
    for i in range(len(q)):
        ref, _ = hand_dh_point(d_p, q[i], d_p.probe.p_last)
        assert_close(batch[i], ref, atol=1e-12)


def test_zero_position_by_hand(nominal):
    """At q = 0 the nominal arm stands in the x-z plane: hand-derived ball centre."""
    # j1: z up 200, alpha 90; j2: a 45, alpha -90; j3: d 420 ...: at q=0 the chain is
    # x = 45 + 45 = 90 mm, z = 200 + 420 + 380 + 95 + 85 = 1180 mm.
    assert_close(ball_centres(nominal, np.zeros(7)), [0.090, 0.0, 1.180], atol=1e-15)


def test_zero_force_gives_rigid(nominal):
    rng = np.random.default_rng(5)
    q, _ = random_inputs(rng, 100, nominal)
    assert_close(ball_centres(nominal, q, np.zeros((100, 6))), ball_centres(nominal, q), atol=0)


def test_small_force_moves_ball_by_compliance_times_force(nominal, pin_arm):
    """For any force direction the ball moves by R_base_probe @ diag(c) @ F (first order)."""
    rng = np.random.default_rng(7)
    c = nominal.probe.compliance
    q, _ = random_inputs(rng, 30, nominal)
    F = rng.normal(0, 1.0, (30, 3))
    F /= np.linalg.norm(F, axis=1)[:, None]
    F *= 5.0  # N, the paper's common maximum
    moved = ball_centres(nominal, q, F) - ball_centres(nominal, q)
    for i in range(30):
        R = pin_arm.T_base_ball(q[i])[:3, :3]
        # second-order term: L theta^2 / 2 with theta = c F / L  -> < 1e-7 m at 5 N
        assert_close(moved[i], R @ (c * F[i]), atol=1e-7)
    # and the paper's figure: 1 N of bending force -> 0.0142 mm
    q0 = np.zeros(7)
    d = ball_centres(nominal, q0, [1.0, 0, 0]) - ball_centres(nominal, q0)
    assert abs(np.linalg.norm(d) - 0.0142e-3) < 1e-11


def test_deflection_is_odd_and_nearly_linear_in_force(nominal):
    """Bending is a rotation of the stylus: the deflection is linear in F up to the even,
    second-order drop L(1 - cos theta) ~ L theta^2 / 2 along the stylus, with theta = c F / L."""
    rng = np.random.default_rng(8)
    q, _ = random_inputs(rng, 40, nominal)
    F = rng.normal(0, 1, (40, 3))
    F *= 5.0 / np.linalg.norm(F, axis=1)[:, None]          # 5 N: the paper's high forces
    r = ball_centres(nominal, q)
    plus, minus = ball_centres(nominal, q, F) - r, ball_centres(nominal, q, -F) - r
    lever = nominal.probe.stylus_length
    theta = nominal.probe.bending_compliance_x * 5.0 / lever
    bound = lever * theta**2 / 2 * 1.01                     # 3.0e-8 m
    assert bound < 3.1e-8
    assert_close(plus, -minus, atol=2 * bound)
    double = ball_centres(nominal, q, 2 * F) - r
    assert_close(double, 2 * plus, atol=6 * bound)


def test_two_channel_force_is_probe_x_and_z(nominal):
    q = np.zeros((1, 7))
    only = ball_centres(nominal, q, [[2.0, 0.0, -1.0]]) - ball_centres(nominal, q)
    # at q = 0 the probe frame is the base frame. Hand-derived exact values of the elastic joint:
    # theta_y = c F_x / L, s = c_z F_z, ball = hinge + (L + s)(sin theta_y, 0, cos theta_y)
    L, theta, s = 0.085, 1.42e-5 * 2.0 / 0.085, -8.76e-8
    assert_close(only[0], [(L + s) * math.sin(theta), 0.0, (L + s) * math.cos(theta) - L], atol=1e-15)
    assert_close(only[0], [2 * 1.42e-5, 0.0, -8.76e-8], atol=5e-9)  # first order: C F


def test_pinocchio_jacobians_match_finite_differences(nominal, pin_arm):
    rng = np.random.default_rng(9)
    q, w = random_inputs(rng, 5, nominal)
    for i in range(5):
        jq, jw = pin_arm.jacobians(q[i], w[i])
        assert_close(jq, fd_jacobian(lambda x: pin_arm.ball_centre(x, w[i]), q[i]), atol=1e-8)
        assert_close(jw, fd_jacobian(lambda x: pin_arm.ball_centre(q[i], x), w[i], eps=1e-3), atol=1e-12)


def test_casadi_jacobian_wrt_parameters_matches_finite_differences(nominal):
    import casadi as ca
    rng = np.random.default_rng(10)
    f = casadi_ball_centre(nominal)
    qs, ws, ps = ca.SX.sym("q", 7), ca.SX.sym("w", 6), ca.SX.sym("p", param_spec(nominal).size)
    jac = ca.Function("J", [qs, ws, ps], [ca.jacobian(f(qs, ws, ps), ps)])
    q, w = random_inputs(rng, 3, nominal)
    p = random_params(rng, nominal)
    for i in range(3):
        analytic = np.array(jac(q[i], w[i], p))
        numeric = fd_jacobian(lambda x: ball_centres(nominal, q[i], w[i], x), p, eps=1e-7)
        # compliance columns have unit m/N: FD step 1e-7 m/N on a 3 N force is fine
        assert_close(analytic, numeric, atol=1e-7)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-6.3, 6.3), min_size=7, max_size=7),
       st.lists(st.floats(-13, 13), min_size=3, max_size=3))
def test_batch_equals_pinocchio_property(nominal, pin_arm, q, f):
    assert_close(ball_centres(nominal, np.array(q), np.array(f)),
                 pin_arm.ball_centre(np.array(q), np.array(f)), atol=1e-12)


def test_batch_chunking_and_threads_do_not_change_results(nominal):
    rng = np.random.default_rng(12)
    q, w = random_inputs(rng, 5000, nominal)
    a = ball_centres(nominal, q, w, threads=1, chunk=5000)
    b = ball_centres(nominal, q, w, threads=2, chunk=333)
    assert np.array_equal(a, b)


def test_gravity_torques_hand_derived(nominal, pin_arm):
    """Pinocchio's RNEA holding torque on each joint equals, by hand, minus the moment about the
    joint axis of the weights of every link beyond it (point masses at the DH frame origins,
    positions from the independent DH product)."""
    rng = np.random.default_rng(13)
    g = np.array([0.0, 0.0, -9.81])
    for q in rng.uniform(-2, 2, (5, 7)):
        frames = [np.eye(4)]
        for k in range(7):
            _, T = hand_dh_point(_prefix(nominal, k + 1), q[: k + 1], (0, 0, 0))
            frames.append(T)
        tau = pin_arm.gravity_torques(q)
        for i in range(7):   # joint i+1 turns about z of DH frame i
            axis, point = frames[i][:3, 2], frames[i][:3, 3]
            moment = sum(np.cross(frames[k + 1][:3, 3] - point, nominal.joints[k].mass * g)
                         for k in range(i, 7))
            assert abs(tau[i] - (-(axis @ moment))) < 1e-9
    q = np.zeros(7)
    q[1] = math.pi / 2
    assert abs(pin_arm.gravity_torques(q)[1]) > 5.0   # stretched out: a real load [N m]


def _prefix(desc, k):
    from dataclasses import replace
    return replace(desc, joints=desc.joints[:k])


#: probe frames turned away from the last joint frame: tool along x, along -y, and an arbitrary rpy;
#: (p_last [m], rpy [rad]) with the ball ahead along the probe's own z axis
ROTATED_PROBES = {
    "tool along x": ((0.10, 0.0, 0.02), (0.0, math.pi / 2, 0.0)),
    "tool along -y": ((0.0, -0.08, 0.03), (math.pi / 2, 0.0, 0.0)),
    "arbitrary rpy": ((0.03, 0.04, 0.07), (0.4, -0.7, 2.1)),
}


@pytest.mark.parametrize("tool", ROTATED_PROBES)
@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_three_evaluators_agree_with_a_rotated_probe(nominal, convention, tool):
    p_last, rpy = ROTATED_PROBES[tool]
    desc = (nominal if convention == "dh" else _mdh_variant(nominal)).with_probe(p_last=p_last, rpy=rpy)
    rng = np.random.default_rng(17)
    f = casadi_ball_centre(desc)
    p = random_params(rng, desc)
    arm = PinocchioArm(apply_params(desc, p))
    q, w = random_inputs(rng, 15, desc)
    batch = ball_centres(desc, q, w, p)
    for i in range(len(q)):
        assert_close(arm.ball_centre(q[i], w[i]), batch[i], atol=1e-12)
        assert_close(np.array(f(q[i], w[i], p)).ravel(), batch[i], atol=1e-12)


@pytest.mark.parametrize("tool", ROTATED_PROBES)
def test_rotated_probe_deflects_along_its_own_axes(nominal, tool):
    """The rigid ball is the hand-written DH product of p_last; a small force F given in the probe frame
    moves it by R_base_last R_last_probe diag(c) F, the rotation built here from the rpy by hand."""
    from scipy.spatial.transform import Rotation
    p_last, rpy = ROTATED_PROBES[tool]
    desc = nominal.with_probe(p_last=p_last, rpy=rpy)
    R_last_probe = Rotation.from_euler("xyz", rpy).as_matrix()
    rng = np.random.default_rng(19)
    q, _ = random_inputs(rng, 20, desc)
    F = rng.normal(0, 1.0, (20, 3))
    F *= 2.0 / np.linalg.norm(F, axis=1)[:, None]
    rigid = ball_centres(desc, q)
    moved = ball_centres(desc, q, F) - rigid
    c = desc.probe.compliance
    for i in range(20):
        ref, T = hand_dh_point(desc, q[i], p_last)
        assert_close(rigid[i], ref, atol=1e-12)
        # second order: c F^2 c / L < 2e-8 m at 2 N
        assert_close(moved[i], T[:3, :3] @ R_last_probe @ (c * F[i]), atol=2e-8)
