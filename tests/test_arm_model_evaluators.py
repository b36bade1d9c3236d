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
        m = np.eye(4)
        m[2, 3] = d
        return m

    def tx(a):
        m = np.eye(4)
        m[0, 3] = a
        return m

    T = np.eye(4)
    for j, qi in zip(desc.joints, q, strict=True):
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
    for _trial in range(3):
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


# ---------------------------------------------------------------------------------------------
# prismatic and mimic joints (a URDF robot as it ships: a lift, a gripper finger following another)

#: a URDF-convention arm: a prismatic lift along an oblique axis, a joint mimicking another joint of the
#: chain (it takes no encoder column), and a prismatic finger mimicking a joint off the chain (its column
#: holds that master's value)
SLIDER = """name = "slider"
convention = "urdf"
[[joint]]
name = "base"
origin_x_mm = 0.0
origin_y_mm = 0.0
origin_z_mm = 150.0
origin_roll_deg = 0.0
origin_pitch_deg = 0.0
origin_yaw_deg = 0.0
axis = [0.0, 0.0, 1.0]
lower_deg = -170.0
upper_deg = 170.0
[[joint]]
name = "lift"
type = "prismatic"
origin_x_mm = 50.0
origin_y_mm = 10.0
origin_z_mm = 100.0
origin_roll_deg = 5.0
origin_pitch_deg = -3.0
origin_yaw_deg = 20.0
axis = [0.3, -0.2, 0.9]
lower_mm = -100.0
upper_mm = 400.0
encoder_resolution_mm = 0.001
[[joint]]
name = "elbow"
origin_x_mm = 300.0
origin_y_mm = 0.0
origin_z_mm = 20.0
origin_roll_deg = 90.0
origin_pitch_deg = 0.0
origin_yaw_deg = 0.0
axis = [1.0, 0.0, 0.0]
lower_deg = -120.0
upper_deg = 120.0
[[joint]]
name = "elbow_follower"
origin_x_mm = 250.0
origin_y_mm = -30.0
origin_z_mm = 0.0
origin_roll_deg = 0.0
origin_pitch_deg = 40.0
origin_yaw_deg = 0.0
axis = [0.0, 0.6, 0.8]
mimic_joint = "elbow"
mimic_multiplier = -0.7
mimic_offset_deg = 12.0
[[joint]]
name = "wrist"
origin_x_mm = 80.0
origin_y_mm = 0.0
origin_z_mm = 40.0
origin_roll_deg = 0.0
origin_pitch_deg = 0.0
origin_yaw_deg = -30.0
axis = [0.0, 1.0, 0.0]
[[joint]]
name = "finger"
type = "prismatic"
origin_x_mm = 0.0
origin_y_mm = 20.0
origin_z_mm = 60.0
origin_roll_deg = 0.0
origin_pitch_deg = 0.0
origin_yaw_deg = 0.0
axis = [0.0, -1.0, 0.0]
lower_mm = 0.0
upper_mm = 40.0
mimic_joint = "gripper"
mimic_multiplier = 0.5
mimic_offset_mm = 3.0
[probe]
x_mm = 10.0
y_mm = 5.0
z_mm = 80.0
roll_deg = 10.0
pitch_deg = -20.0
yaw_deg = 0.0
ball_diameter_mm = 4.0
max_force_N = 13.0
bending_compliance_mm_per_N = 0.0142
axial_compliance_mm_per_N = 0.0000876
"""


def _dh_with_prismatic(nominal, convention):
    """The nominal arm with its joint 3 prismatic (d + q, lower/upper -50..250 mm), as a DH or MDH table."""
    from dataclasses import replace
    joints = list(nominal.joints)
    joints[2] = replace(joints[2], kind="prismatic", lower=-0.05, upper=0.25, encoder_resolution=1e-6)
    return replace(nominal, joints=tuple(joints), convention=convention, name=f"prismatic-{convention}")


def _q_within(desc, rng, n):
    from arm_model.sim.ik import random_q
    return random_q(desc, n, rng)


def _arms(nominal):
    from arm_model.description import parse_description
    return {"dh": _dh_with_prismatic(nominal, "dh"), "mdh": _dh_with_prismatic(nominal, "mdh"),
            "urdf": parse_description(SLIDER, "slider.toml")}


@pytest.mark.parametrize("arm", ["dh", "mdh", "urdf"])
def test_three_evaluators_agree_with_prismatic_and_mimic_joints(nominal, arm):
    """Batch, CasADi and Pinocchio (built from the generated URDF, prismatic joints as Pinocchio's own)
    agree to 1e-12 m with parameter errors and a wrench; the model file written reads back to the same
    centres."""
    from arm_model.description import format_description, parse_description
    desc = _arms(nominal)[arm]
    rng = np.random.default_rng(31)
    f = casadi_ball_centre(desc)
    q = _q_within(desc, rng, 12)
    _, w = random_inputs(rng, 12, desc)
    for _trial in range(2):
        p = random_params(rng, desc)
        pin_arm = PinocchioArm(apply_params(desc, p))
        batch = ball_centres(desc, q, w, p)
        for i in range(len(q)):
            assert_close(pin_arm.ball_centre(q[i], w[i]), batch[i], atol=1e-12)
            assert_close(np.array(f(q[i], w[i], p)).ravel(), batch[i], atol=1e-12)
    back = parse_description(format_description(desc))
    assert [j.kind for j in back.joints] == [j.kind for j in desc.joints] and back.joint_names == desc.joint_names
    assert_close(ball_centres(back, q, w), ball_centres(desc, q, w), atol=1e-12)


def test_prismatic_dh_row_by_hand(nominal):
    """A prismatic DH row slides by q along z: Rz(theta_offset) Tz(d + q) Tx(a) Rx(alpha), by hand."""
    desc = _dh_with_prismatic(nominal, "dh")
    q = _q_within(desc, np.random.default_rng(5), 10)
    for qi, x in zip(q, ball_centres(desc, q), strict=True):
        T = np.eye(4)
        for k, j in enumerate(desc.joints):
            theta, d = (j.theta_offset, j.d + qi[k]) if j.prismatic else (j.theta_offset + qi[k], j.d)
            c, s, ca, sa = math.cos(theta), math.sin(theta), math.cos(j.alpha), math.sin(j.alpha)
            T = T @ np.array([[c, -s * ca, s * sa, j.a * c], [s, c * ca, -c * sa, j.a * s], [0, sa, ca, d],
                              [0, 0, 0, 1.0]])
        assert_close(x, (T @ np.array([*desc.probe.p_last, 1.0]))[:3], atol=1e-12)


def test_mimic_joint_on_the_chain_is_applied_not_an_encoder(nominal, tmp_path):
    """Issue 22 item 3: a <mimic> joint on the chain follows its master as the URDF says (multiplier,
    offset) and takes no column: the arm has one column fewer than moving joints, a points file with a
    column for it is refused, and the ball equals Pinocchio's own mimic model of the user's URDF."""
    import pinocchio as pin

    from arm_model.cli import main
    from arm_model.urdf import urdf_text
    from arm_model.urdf_import import description_from_urdf
    desc = _arms(nominal)["urdf"]
    assert desc.n_joints == 5 and len(desc.joints) == 6 and desc.coupled
    assert desc.joint_names == ("base", "lift", "elbow", "wrist", "gripper")
    urdf = tmp_path / "slider.urdf"
    text = urdf_text(desc)
    # the finger's master, off the chain, is written as a joint of its own branch (ahead of the chain:
    # Pinocchio's mimic model needs the master parsed first), so that the mimic tag keeps its formula
    assert '<mimic joint="elbow" multiplier="-0.7"' in text
    assert '<mimic joint="gripper" multiplier="0.5" offset="0.003"/>' in text
    assert text.index('<joint name="gripper" type="prismatic">') < text.index('<joint name="finger"')
    urdf.write_text(text)
    d = description_from_urdf(urdf, "ball")
    assert d.joint_names == desc.joint_names and d.joints[3].mimic.joint == "elbow"
    # Pinocchio's mimic model follows the elbow; it takes masters on the mimic's own branch only, so the
    # finger (its master on another branch) is set here by the URDF's formula, 0.5 q + 3 mm
    model = pin.buildModelFromXML(text.replace('<mimic joint="gripper" multiplier="0.5" offset="0.003"/>', ""),
                                  mimic=True)
    data = model.createData()
    q = _q_within(d, np.random.default_rng(6), 8)
    for qi, x in zip(q, ball_centres(d, q), strict=True):
        cfg = pin.neutral(model)
        for name, v in zip(d.joint_names, qi, strict=True):
            cfg[model.joints[model.getJointId(name)].idx_q] = v
        cfg[model.joints[model.getJointId("finger")].idx_q] = 0.5 * qi[4] + 0.003
        pin.framesForwardKinematics(model, data, cfg)
        assert_close(x, data.oMf[model.getFrameId("ball")].translation, atol=1e-12)
    units = d.joint_column_units
    header = "measurement,feature," + ",".join(f"q{k + 1}_{u}" for k, (u, _) in enumerate(units))
    rows = [",".join(["m", ""] + [repr(float(v * f)) for v, (_, f) in zip(qi, units, strict=True)]) for qi in q]
    (tmp_path / "p.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    out = tmp_path / "tips.csv"
    assert main(["tip", str(tmp_path / "p.csv"), "--arm", str(urdf), "--tip-frame", "ball", "-o", str(out), "-q"]) == 0
    got = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(2, 3, 4)) * 1e-3
    assert_close(got, ball_centres(d, q), atol=1e-9)            # the file's resolution: 1e-6 mm
    wrong = header + ",q6_deg\n" + "\n".join(r + ",0.0" for r in rows) + "\n"     # a column for the mimic
    (tmp_path / "p6.csv").write_text(wrong)
    assert main(["tip", str(tmp_path / "p6.csv"), "--arm", str(urdf), "--tip-frame", "ball", "-o",
                 str(tmp_path / "t6.csv"), "-q"]) == 2
    assert not (tmp_path / "t6.csv").exists()


@pytest.mark.parametrize("arm", ["mdh", "urdf"])
def test_jacobians_with_prismatic_and_mimic_joints_match_finite_differences(nominal, arm):
    """The exact chain Jacobian (uncertainty), the joint screws (inverse kinematics) and Pinocchio's,
    by encoder column, against central differences of the batch evaluator."""
    from arm_model.jacobian import chain_jacobian, joint_screws, point_jacobian
    from arm_model.params import split_params
    desc = _arms(nominal)[arm]
    rng = np.random.default_rng(41)
    q = _q_within(desc, rng, 4)
    _, w = random_inputs(rng, 4, desc)
    rows, pl, c = split_params(desc)
    cen, g = chain_jacobian(desc.convention, rows, pl, c, list(q.T), list(w.T), desc.chain_joints,
                            desc.probe.rotation, desc.probe.lever)
    nq, nr, m = desc.n_joints, len(desc.joints), len(desc.row_fields)
    jq = g[m * nr + 6: m * nr + 6 + nq]                     # (J, 3, N)
    _, o, u, cc = joint_screws(desc.convention, rows, q, desc.chain_joints)
    rigid = ball_centres(desc, q)
    screws = point_jacobian(u, cc, rigid, desc.chain_joints, nq)
    pin_arm = PinocchioArm(desc)
    for i in range(len(q)):
        fd = fd_jacobian(lambda x: ball_centres(desc, x, w[i]), q[i], eps=1e-7)
        assert_close(jq[:, :, i].T, fd, atol=1e-7)
        assert_close(pin_arm.jacobians(q[i], w[i])[0], fd, atol=1e-7)
        assert_close(screws[i], fd_jacobian(lambda x: ball_centres(desc, x), q[i], eps=1e-7), atol=1e-7)
    rest = np.zeros(6)                     # the probe's errors, zero
    fd_p = fd_jacobian(lambda x: ball_centres(desc, q[0], w[0], np.concatenate([x, rest])), np.zeros(m * nr), eps=1e-7)
    assert_close(g[: m * nr, :, 0].T, fd_p, atol=1e-7)


def test_joint_angle_effects_skip_prismatic_joints_and_act_on_a_coupled_arm_s_readings(nominal):
    """An effect on a joint angle (eccentricity, joint compliance) acts on the revolute joints: by default it
    leaves a prismatic joint out, named it is refused. On an arm with a joint mimicking another of its chain
    an effect on the readings acts on the master's column, the follower following through its formula (the
    ball where the corrected readings put it); an effect on the chain's rows (thermal growth) is refused
    there (its rows and columns differ); probe effects still apply."""
    from arm_model.effects import EncoderEccentricity, JointCompliance, ProbeCompliance, ThermalGrowth
    from arm_model.model import ArmModel, AuxData
    arms = _arms(nominal)
    m = ArmModel(arms["dh"], (EncoderEccentricity(harmonics=(1,)),))
    assert [n for n in m.spec.names if "ecc" in n] == [f"j{i}.ecc1_{t}" for i in (1, 2, 4, 5, 6, 7)
                                                       for t in ("cos", "sin")]
    with pytest.raises(ValueError, match="'j3' is prismatic"):
        ArmModel(arms["dh"], (JointCompliance(joints=(2,)),))
    with pytest.raises(ValueError, match="mimics another joint"):
        ArmModel(arms["urdf"], (ThermalGrowth(per_joint=True),))
    desc = arms["urdf"]
    rng = np.random.default_rng(8)
    q = _q_within(desc, rng, 5)
    tau = rng.normal(0.0, 20.0, q.shape)                    # N m, any numbers: the effect only reads them
    m = ArmModel(desc, (JointCompliance(contact=False), EncoderEccentricity(harmonics=(1,))))
    comp = {"base": 2e-4, "elbow": -3e-4, "wrist": 1e-4}    # rad/(N m); the prismatic lift and gripper: none
    ecc = {"elbow": (1e-3, -2e-3)}
    p = np.zeros(m.spec.size)
    for k, name in enumerate(m.spec.names):
        joint, _, par = name.partition(".")
        cos_sin = ecc.get(joint, (0.0, 0.0))
        p[k] = {"compliance": comp.get(joint, 0.0), "ecc1_cos": cos_sin[0], "ecc1_sin": cos_sin[1]}.get(par, 0.0)
    assert sorted(n for n in m.spec.names if n.endswith(".compliance")) == [f"{j}.compliance" for j in sorted(comp)]
    got = m.ball_centres(q, None, p, AuxData(None, tau, np.zeros_like(tau)))
    q_true = q.copy()
    for c, name in enumerate(desc.joint_names):             # the effects in the model's order
        q_true[:, c] -= comp.get(name, 0.0) * tau[:, c]
        cos_sin = ecc.get(name, (0.0, 0.0))
        q_true[:, c] += cos_sin[0] * np.cos(q_true[:, c]) + cos_sin[1] * np.sin(q_true[:, c])
    assert np.abs(q_true - q).max() > 1e-3
    assert_close(got, ball_centres(desc, q_true), atol=1e-12)
    m = ArmModel(desc, (ProbeCompliance(),))
    q = _q_within(arms["urdf"], np.random.default_rng(3), 4)
    assert_close(m.ball_centres(q), ball_centres(arms["urdf"], q), atol=1e-15)


def test_gravity_torques_of_a_coupled_arm_are_the_potential_energy_s_slope_by_encoder_column(nominal):
    """On an arm with a joint mimicking another of its chain (masses on every link), the torque each encoder
    column holds against gravity (what joint compliance reads) is dV/dq of that column, V the potential energy
    by Pinocchio at the joints the URDF's formula sets (the follower's share carried to its master), by central
    differences: an energy route, independent of the RNEA and of the coupling matrix."""
    from dataclasses import replace

    import pinocchio as pin
    desc = _arms(nominal)["urdf"]
    joints = tuple(replace(j, mass=1.0 + k, com=(0.03 * k, -0.02, 0.05)) for k, j in enumerate(desc.joints))
    desc = replace(desc, joints=joints)
    arm = PinocchioArm(desc)
    model, data = arm.model, arm.model.createData()
    column = {n: c for c, n in enumerate(desc.joint_names)}

    def energy(qc):
        x = pin.neutral(model)
        for j in desc.joints:
            m = j.mimic
            v = qc[column[j.name]] if m is None else m.multiplier * qc[column[m.joint]] + m.offset
            x[model.joints[model.getJointId(j.name)].idx_q] = v
        return pin.computePotentialEnergy(model, data, x)

    for qc in _q_within(desc, np.random.default_rng(12), 3):
        h = 1e-6
        slope = [(energy(qc + h * e) - energy(qc - h * e)) / (2 * h) for e in np.eye(len(qc))]
        tau = arm.gravity_torques(qc)
        assert abs(tau[column["elbow"]]) > 0.1                   # a real load on the master [N m]
        assert_close(tau, np.array(slope), atol=1e-6)


def test_numpy_function_gives_a_plain_calls_arrays_bit_for_bit(nominal):
    """NumpyFunction (the buffer path calibration evaluates) returns np.asarray of a plain CasADi call's outputs,
    bit for bit: a mapped ball centre with its sparse Jacobian, a shared parameter vector repeated over the points,
    a vector given as a row or a 1-D array, a scalar input; a wrong shape is refused naming the input."""
    import casadi as ca

    from arm_model.casadi_model import NumpyFunction
    from calibration.kinds import distance_function, kind_function
    rng = np.random.default_rng(4)
    f = casadi_ball_centre(nominal)
    q, w, p = ca.SX.sym("q", f.size1_in(0)), ca.SX.sym("w", 6), ca.SX.sym("p", f.size1_in(2))
    x = f(q, w, p)
    g = ca.Function("xj", [q, w, p], [x, ca.jacobian(x, p), ca.jacobian(x, w)]).map(50)
    assert not g.sparsity_out(1).is_dense()
    args = (rng.uniform(-2, 2, (f.size1_in(0), 50)), rng.normal(size=(6, 50)), 1e-4 * rng.normal(size=f.size1_in(2)))
    for got, want in zip(NumpyFunction(g)(*args), g(*args), strict=True):
        want = np.asarray(want)
        assert got.shape == want.shape and got.flags.c_contiguous and np.array_equal(got, want)
    d = distance_function().map(7)
    a, b, length = rng.normal(size=(3, 7)), rng.normal(size=(3, 7)), rng.uniform(0.1, 1, 7)
    for lengths in (length, length[None, :], 0.5):
        for got, want in zip(NumpyFunction(d)(a, b, lengths), d(a, b, lengths), strict=True):
            assert np.array_equal(got, np.asarray(want))
    seat = kind_function("seat").map(5)          # constant, structurally sparse Jacobians
    xs, k = rng.normal(size=(3, 5)), rng.normal(size=3)
    for got, want in zip(NumpyFunction(seat)(xs, np.zeros((3, 5)), k, np.zeros(3)),
                         seat(xs, np.zeros((3, 5)), k, np.zeros(3)), strict=True):
        assert np.array_equal(got, np.asarray(want))
    with pytest.raises(ValueError, match="input cb has shape"):
        NumpyFunction(d)(a, b[:, :4], length)


_ONE_POINT_ARMS: dict = {}


def _one_point_arms(nominal):
    """Arms of every convention and probe kind for :func:`test_one_point_on_floats_is_the_batch_bit_for_bit` (made
    once)."""
    if _ONE_POINT_ARMS:
        return _ONE_POINT_ARMS
    arms = _ONE_POINT_ARMS
    arms.update(_arms(nominal))
    p_last, rpy = ROTATED_PROBES["arbitrary rpy"]
    arms["dh-rotated-lever"] = nominal.with_probe(p_last=p_last, rpy=rpy, lever=0.05)
    arms["mdh-no-stylus"] = _mdh_variant(nominal).with_probe(lever=0.0)
    arms["dh-nominal"] = nominal
    return arms


@settings(max_examples=30, deadline=None)
@given(arm=st.sampled_from(["dh", "mdh", "urdf", "dh-rotated-lever", "mdh-no-stylus", "dh-nominal"]),
       seed=st.integers(0, 2 ** 32 - 1), wrench=st.sampled_from([None, 3, 6]), errors=st.booleans(),
       zero=st.booleans())
def test_one_point_on_floats_is_the_batch_bit_for_bit(nominal, arm, seed, wrench, errors, zero):
    """One point (a live session's tip) runs on Python floats (:data:`arm_model.chain.FLOAT_OPS`): the same ball
    centre as the same point among others on numpy columns, to the last bit (so within 1e-12 m), on DH, MDH and URDF
    chains with prismatic and mimic joints, rotated probes, a stylus lever and none, rigid or with a force or a wrench,
    with parameter errors or without; a joint at exactly 0 and a zero wrench included (the batch turns them, the
    floats must not skip them); and Pinocchio's centre of the same point to 1e-12 m (an independent evaluator)."""
    desc = _one_point_arms(nominal)[arm]
    rng = np.random.default_rng(seed)
    q = _q_within(desc, rng, 4)
    w = None if wrench is None else np.column_stack([rng.normal(0, 3.0, (4, 3)), rng.normal(0, 0.05, (4, 3))])
    if zero:
        q[1, :2] = 0.0
        if w is not None:
            w[2] = 0.0
    w = None if w is None else w[:, :wrench]
    p = random_params(rng, desc) if errors else None
    batch = ball_centres(desc, q, w, p)
    for i in range(len(q)):
        one = ball_centres(desc, q[i: i + 1], None if w is None else w[i: i + 1], p)
        assert one.shape == (1, 3) and np.array_equal(one[0], batch[i]), (i, one[0] - batch[i])
        assert np.array_equal(ball_centres(desc, q[i], None if w is None else w[i], p), batch[i])
    if arm == "dh-nominal":
        pin = PinocchioArm(desc if p is None else apply_params(desc, p))
        assert_close(ball_centres(desc, q[0], None if w is None else w[0], p),
                     pin.ball_centre(q[0], None if w is None else w[0]), atol=1e-12)
