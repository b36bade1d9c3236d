"""The effects the closed loop synthesises from the residual (joint harmonics of its own or another joint's
angle, probe thermal growth, a full probe compliance matrix, an approach-direction offset, lateral joint
compliance): numpy, CasADi and Pinocchio agree; zero parameters change nothing; each does its physics,
checked by hand with Pinocchio's own frames and RNEA as the reference."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from arm_model import PinocchioArm, ball_centres
from arm_model.effects import (
    EFFECTS,
    ApproachOffset,
    JointHarmonics,
    LateralCompliance,
    ProbeComplianceMatrix,
    ProbeThermalGrowth,
    ThermalGrowth,
)
from arm_model.model import ArmModel, AuxData
from arm_model.urdf import urdf_text
from arm_model.urdf_import import load_arm
from conftest import assert_close

NEW = (JointHarmonics(joints=(5,), harmonics=(1, 2, 3, 4)), JointHarmonics(joints=(2,), source=1, harmonics=(1, 3)),
       ThermalGrowth(joints=(1, 3), per_joint=True), ProbeThermalGrowth(), ProbeComplianceMatrix(), ApproachOffset(),
       LateralCompliance(joints=(2,)), LateralCompliance(joints=(0, 5), contact=False))


def _data(desc, n, seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, (n, desc.n_joints))
    w = np.zeros((n, 6))
    w[:, :3] = rng.normal(0, 2, (n, 3))
    w[:, 3:] = rng.normal(0, 0.02, (n, 3))
    tg, tc = PinocchioArm(desc).torques(q, w)
    return rng, q, w, AuxData(rng.uniform(15, 30, n), tg, tc)


def _urdf_arm(nominal, tmp_path):
    """The nominal arm as a URDF chain with one tilted joint axis (lateral axes then not x/y)."""
    text = urdf_text(nominal)
    text = text[: text.index('  <joint name="stylus_root_joint"')]
    text += ('  <joint name="tip_joint" type="fixed"><parent link="flange"/><child link="tip"/>'
             '<origin xyz="0.001 -0.002 0.085" rpy="0 0 0"/></joint>\n  <link name="tip"/>\n</robot>\n')
    text = text.replace('<axis xyz="0.0 0.0 1.0"/>', '<axis xyz="0 0.6 0.8"/>', 3)
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    return load_arm(path, "tip")


@pytest.mark.parametrize("convention", ["dh", "mdh", "urdf"])
def test_three_evaluators_agree_with_every_new_effect(nominal, convention, tmp_path):
    desc = {"dh": nominal, "mdh": replace(nominal, convention="mdh", name="aacmm7-mdh")}.get(convention) \
        or _urdf_arm(nominal, tmp_path)
    model = ArmModel(desc, NEW)
    rng, q, w, aux = _data(desc, 6, 1)
    p = np.zeros(model.spec.size)
    p[model.base_size:] = rng.normal(0, 1e-5, model.spec.size - model.base_size)
    p[: model.base_size] = rng.normal(0, 1e-6, model.base_size)
    batch = model.ball_centres(q, w, p, aux)
    assert np.max(np.abs(batch - model.ball_centres(q, w, p * np.r_[np.ones(model.base_size),
                                                                     np.zeros(model.spec.size - model.base_size)],
                                                     aux))) > 1e-5      # the effects do something
    f = model.casadi_function()
    a = ArmModel.aux_matrix(aux, len(q), desc.n_joints)
    for i in range(len(q)):
        assert_close(np.array(f(q[i], w[i], a[i], p)).ravel(), batch[i], atol=1e-12)
        # Pinocchio: the lateral compliance's moments come from its RNEA, not from the shared code
        assert_close(model.pinocchio_ball_centre(q[i], w[i], p, dict(temperature=aux.temperature[i])), batch[i],
                     atol=1e-12)


def test_new_effects_zero_parameters_give_the_base_model(nominal):
    model = ArmModel(nominal, NEW)
    _, q, w, aux = _data(nominal, 30, 2)
    assert_close(model.ball_centres(q, w, None, aux), ball_centres(nominal, q, w), atol=1e-15)


def test_new_effects_are_in_the_registry():
    for e in NEW:
        assert EFFECTS[e.key] is type(e)


def test_harmonics_of_own_and_other_angle_by_hand(nominal):
    model = ArmModel(nominal, (JointHarmonics(joints=(5,), harmonics=(3,)),
                               JointHarmonics(joints=(2,), source=1, harmonics=(2,))))
    assert model.spec.names[model.base_size:] == ("j6.harm3_cos", "j6.harm3_sin", "j3.harm2_cos_by_j2",
                                                   "j3.harm2_sin_by_j2")
    a, phi, b = 4e-5, 0.4, 3e-5
    p = model.spec.vector({"j6.harm3_cos": a * math.sin(phi), "j6.harm3_sin": a * math.cos(phi),
                           "j3.harm2_sin_by_j2": b})
    q = np.random.default_rng(3).uniform(-3, 3, (20, 7))
    q_true = q.copy()
    q_true[:, 5] += a * np.sin(3 * q[:, 5] + phi)
    q_true[:, 2] += b * np.sin(2 * q[:, 1])
    assert_close(model.ball_centres(q, None, p), ball_centres(nominal, q_true), atol=1e-15)


def test_probe_thermal_growth_by_hand(nominal):
    model = ArmModel(nominal, (ProbeThermalGrowth(),))
    alpha, temp = 1.1e-5, 30.0
    got = model.ball_centres(np.zeros((1, 7)), None, model.spec.vector({"probe.thermal_alpha": alpha}),
                             AuxData(temperature=np.array([temp])))
    # at q = 0 the probe (85 mm) points along base z; the links do not grow
    assert_close(got[0], [0.090, 0.0, 1.095 + 0.085 * (1 + alpha * (temp - 20.0))], atol=1e-15)


def test_probe_compliance_matrix_moves_the_ball_by_dC_f(nominal, pin_arm):
    model = ArmModel(nominal, (ProbeComplianceMatrix(),))
    dc = {"xx": 2e-6, "yy": -1e-6, "zz": 0.5e-6, "xy": 1.5e-6, "xz": -0.7e-6, "yz": 0.9e-6}
    p = model.spec.vector({f"probe.dcompliance_{k}": v for k, v in dc.items()})
    m = np.array([[dc["xx"], dc["xy"], dc["xz"]], [dc["xy"], dc["yy"], dc["yz"]], [dc["xz"], dc["yz"], dc["zz"]]])
    rng = np.random.default_rng(4)
    for _ in range(5):
        q = rng.uniform(-2.5, 2.5, 7)
        f = rng.normal(0, 0.1, 3)                        # small: the bending is first order in the force
        rot = pin_arm.T_base_ball(q)[:3, :3]             # probe frame axes in the base frame (Pinocchio)
        moved = model.ball_centres(q[None], f[None], p)[0] - ball_centres(nominal, q[None], f[None])[0]
        # the second order (c f dC f / L, bending is a rotation) is below 1e-11 m at 0.2 N
        assert_close(moved, rot @ (m @ f), atol=1e-11)
        assert np.linalg.norm(m @ f) > 1e-7


def test_approach_offset_moves_the_ball_by_B_u(nominal, pin_arm):
    model = ArmModel(nominal, (ApproachOffset(),))
    b = np.random.default_rng(5).normal(0, 2e-5, (3, 3))
    p = model.spec.vector({f"approach.d{a}_u{c}": b[i, k] for i, a in enumerate("xyz") for k, c in enumerate("xyz")})
    q = np.random.default_rng(6).uniform(-2.5, 2.5, (10, 7))
    got = model.ball_centres(q, None, p) - ball_centres(nominal, q)
    for i in range(len(q)):
        u = pin_arm.T_base_ball(q[i])[:3, 2]                 # the stylus direction, base frame
        assert_close(got[i], b @ u, atol=1e-15)


def test_lateral_compliance_by_hand_from_pinocchio_frames(nominal, pin_arm):
    """The ball turns about the joint frame's x and y axes through its origin by c M, M the moment of
    gravity on the links the joint moves plus the contact wrench's, summed here from Pinocchio's frames,
    centres of mass and the probe frame (an independent sum, not RNEA, not the effect's code)."""
    import pinocchio as pin

    j = 2                                       # the elbow (j3)
    model = ArmModel(nominal, (LateralCompliance(joints=(j,)),))
    cx, cy = 3e-6, -2e-6
    p = model.spec.vector({"j3.lateral_compliance_x": cx, "j3.lateral_compliance_y": cy})
    rng = np.random.default_rng(7)
    arm = pin_arm
    for _ in range(4):
        q = rng.uniform(-2.5, 2.5, 7)
        w = np.r_[rng.normal(0, 3, 3), rng.normal(0, 0.05, 3)]
        pin.forwardKinematics(arm.model, arm.data, arm.full_q(q))
        pin.updateFramePlacements(arm.model, arm.data)
        jid = arm.model.getJointId("j3")
        o_m = arm.data.oMi[jid]
        o, axes = o_m.translation, o_m.rotation
        m_grav = np.zeros(3)
        for k in range(jid, jid + 7 - j):                 # links j3 .. j7
            inert = arm.model.inertias[k]
            m_grav += np.cross(arm.data.oMi[k].act(inert.lever) - o, inert.mass * np.array([0, 0, -9.81]))
        ball = arm.data.oMf[arm.ball_id]
        m_cont = np.cross(ball.translation - o, ball.rotation @ w[:3]) + ball.rotation @ w[3:]
        tg, tc = arm.torques(q[None], w[None])
        assert_close((m_grav + m_cont) @ axes[:, 2], tc[0, j] - tg[0, j], atol=1e-12)  # axial part: the torque
        rigid = ball_centres(nominal, q[None])[0]

        def move(m):
            e = cx * (m @ axes[:, 0]) * axes[:, 0] + cy * (m @ axes[:, 1]) * axes[:, 1]
            return np.cross(e, rigid - o)

        # no wrench: gravity alone, exact
        assert_close(model.ball_centres(q[None], None, p)[0], rigid + move(m_grav), atol=1e-15)
        assert np.linalg.norm(move(m_grav)) > 1e-6                                    # a real move
        # with the wrench: the move shifts the probe point, so the stylus lever of the bending changes by up
        # to |move|, and the deflection (deflected - rigid) by about |move| / L of itself
        deflected = ball_centres(nominal, q[None], w[None])[0]
        mv = move(m_grav + m_cont)
        tol = 2 * np.linalg.norm(mv) * np.linalg.norm(deflected - rigid) / nominal.probe.stylus_length + 1e-13
        assert_close(model.ball_centres(q[None], w[None], p)[0], deflected + mv, atol=tol)
        assert np.linalg.norm(move(m_cont)) > 1e-8


def test_lateral_compliance_gravity_and_contact_parts(nominal):
    """Without masses or without a wrench, the part that is off moves nothing."""
    massless = replace(nominal, joints=tuple(replace(jr, mass=0.0) for jr in nominal.joints))
    q = np.random.default_rng(8).uniform(-2.5, 2.5, (5, 7))
    for desc, eff, w in ((massless, LateralCompliance(joints=(1,)), None),
                         (massless, LateralCompliance(joints=(1,), contact=False), np.ones((5, 3))),
                         (nominal, LateralCompliance(joints=(1,), gravity=False), np.zeros((5, 3)))):
        model = ArmModel(desc, (eff,))
        p = model.spec.vector({"j2.lateral_compliance_x": 1e-5, "j2.lateral_compliance_y": 1e-5})
        assert_close(model.ball_centres(q, w, p), ball_centres(desc, q, w), atol=1e-15)


#: a lift carrying a wrist and a hand, written here: the carriage massless, the hand 2 kg, 0.1 m out from the
#: wrist axis, which stands 0.3 m out from the lift's; the tool point 0.2 m out from the wrist axis
LIFT_URDF = """<?xml version="1.0"?>
<robot name="lift">
  <link name="base"/><link name="carriage"/>
  <link name="hand"><inertial><mass value="2"/><origin xyz="0.1 0 0"/>
    <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
  <link name="tool"/>
  <joint name="lift" type="prismatic"><parent link="base"/><child link="carriage"/>
    <origin xyz="0 0 0.5"/><axis xyz="0 0 1"/><limit lower="0" upper="0.4" effort="100" velocity="1"/></joint>
  <joint name="wrist" type="revolute"><parent link="carriage"/><child link="hand"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="hand"/><child link="tool"/><origin xyz="0.2 0 0"/></joint>
</robot>
"""


def test_a_lift_s_carriage_tilts_under_what_it_carries(tmp_path):
    """Lateral compliance of a prismatic joint, by hand: with the wrist at q (the hand's mass at 0.3 m + 0.1 m
    turned by q from the lift's axis), gravity's moment about the carriage is m g r_perp (horizontal,
    perpendicular to the mass' lever); tilting by c times it about the carriage's origin drops the tool point
    (0.3 m + 0.2 m turned by q out) by c m g (lever of the mass . lever of the tool), its height's only move.
    The three evaluators agree, and the lift's travel does not change the tilt (the carriage carries the same)."""
    (tmp_path / "lift.urdf").write_text(LIFT_URDF)
    desc = load_arm(tmp_path / "lift.urdf", "tool")
    model = ArmModel(desc, (LateralCompliance(contact=False),))
    assert [n for n in model.spec.names if "lateral" in n] == [
        "lift.lateral_compliance_x", "lift.lateral_compliance_y", "wrist.lateral_compliance_x",
        "wrist.lateral_compliance_y"]
    c, mass, g = 1e-3, 2.0, 9.81
    p = model.spec.vector({"lift.lateral_compliance_x": c, "lift.lateral_compliance_y": c})
    q = np.array([[0.0, 0.0], [0.25, 0.7], [0.1, -2.0]])
    rigid = model.ball_centres(q, None, None)
    bent = model.ball_centres(q, None, p)
    for k, (lift, wrist) in enumerate(q):
        turn = np.array([math.cos(wrist), math.sin(wrist), 0.0])
        lever_mass = np.array([0.3, 0, 0]) + 0.1 * turn
        lever_tool = np.array([0.3, 0, 0]) + 0.2 * turn
        assert_close(rigid[k], np.r_[lever_tool[:2], 0.5 + lift], atol=1e-15)
        drop = c * mass * g * float(lever_mass @ lever_tool)
        assert_close(bent[k] - rigid[k], [0.0, 0.0, -drop], atol=1e-9 * drop)
    f = model.casadi_function()
    a = ArmModel.aux_matrix(None, len(q), desc.n_joints)
    for k in range(len(q)):
        assert_close(np.array(f(q[k], np.zeros(6), a[k], p)).ravel(), bent[k], atol=1e-12)
        assert_close(model.pinocchio_ball_centre(q[k], np.zeros(6), p, {}), bent[k], atol=1e-12)
