"""A chain whose base frame is not on the way from the URDF's root to the tip: a humanoid standing on its
left foot, touching something with its hand (the chain foot -> leg walked backwards -> pelvis -> torso ->
arm). The reference is a second URDF of the same robot written by hand with the foot as its root, evaluated
by Pinocchio: its placements and its gravity torques (RNEA) are what the chain read from the pelvis-rooted
file must give."""

import numpy as np
import pytest

from arm_model.model_file import load_model
from arm_model.pinocchio_model import PinocchioArm
from conftest import pin_configuration

pin = pytest.importorskip("pinocchio")


def _link(name, mass=None, com=(0, 0, 0)):
    if mass is None:
        return f'<link name="{name}"/>'
    return (f'<link name="{name}"><inertial><origin xyz="{com[0]} {com[1]} {com[2]}" rpy="0 0 0"/>'
            f'<mass value="{mass}"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'
            '</link>')


def _joint(name, jtype, parent, child, xyz, axis=None, extra=""):
    ax = "" if axis is None else f'<axis xyz="{axis}"/>'
    lim = '<limit lower="-2" upper="2" effort="1" velocity="1"/>' if jtype in ("revolute", "prismatic") else ""
    return (f'<joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="0 0 0"/>{ax}{lim}{extra}</joint>')


LINKS = [("pelvis", 10.0, (0.0, 0.01, 0.05)), ("l_thigh", 4.0, (0.01, 0.0, -0.2)), ("l_shin", 3.0, (0.0, 0.02, -0.2)),
         ("l_foot", 1.0, (0.05, 0.0, -0.03)), ("l_sole", None, None), ("r_thigh", 4.0, (0.0, 0.0, -0.2)),
         ("torso", 8.0, (0.02, 0.0, 0.2)), ("upper", 2.0, (0.0, 0.03, -0.15)), ("fore", 1.5, (0.0, 0.0, -0.1)),
         ("hand", 0.5, (0.03, 0.0, -0.05)), ("tool", None, None)]
LINK_XML = "".join(_link(n, m, c) for n, m, c in LINKS)
# what lies above the pelvis (and the other leg), the same in both writings
ABOVE_PELVIS = (_joint("r_hip", "revolute", "pelvis", "r_thigh", "0 -0.1 -0.05", "0 0 1")
                + _joint("waist", "prismatic", "pelvis", "torso", "0 0 0.1", "0 0 1")
                + _joint("shoulder", "revolute", "torso", "upper", "0 0.2 0.4", "0 1 0")
                + _joint("elbow", "revolute", "upper", "fore", "0 0 -0.3", "0 1 0",
                         '<mimic joint="l_knee" multiplier="0.5" offset="0.1"/>')
                + _joint("wrist", "continuous", "fore", "hand", "0 0 -0.2", "1 0 0")
                + _joint("tool_fix", "fixed", "hand", "tool", "0.05 0 -0.1"))
# the robot as it is usually written: the pelvis at the root
PELVIS_ROOTED = ('<robot name="walker">' + LINK_XML
                 + _joint("l_hip", "revolute", "pelvis", "l_thigh", "0 0.1 -0.05", "0 0 1")
                 + _joint("l_knee", "revolute", "l_thigh", "l_shin", "0 0 -0.4", "0 1 0")
                 + _joint("l_ankle", "revolute", "l_shin", "l_foot", "0 0 -0.4", "1 0 0")
                 + _joint("l_sole_fix", "fixed", "l_foot", "l_sole", "0.02 0 -0.05")
                 + ABOVE_PELVIS + "</robot>")
# the same robot written by hand from the sole: each leg joint's motion about the opposite axis at its child's
# frame, then the negated translation of its origin
SOLE_ROOTED = ('<robot name="walker">' + LINK_XML
               + "".join(_link(n) for n in ("m_ankle", "m_knee", "m_hip"))
               + _joint("l_sole_fix", "fixed", "l_sole", "l_foot", "-0.02 0 0.05")
               + _joint("l_ankle", "revolute", "l_foot", "m_ankle", "0 0 0", "-1 0 0")
               + _joint("l_ankle_o", "fixed", "m_ankle", "l_shin", "0 0 0.4")
               + _joint("l_knee", "revolute", "l_shin", "m_knee", "0 0 0", "0 -1 0")
               + _joint("l_knee_o", "fixed", "m_knee", "l_thigh", "0 0 0.4")
               + _joint("l_hip", "revolute", "l_thigh", "m_hip", "0 0 0", "0 0 -1")
               + _joint("l_hip_o", "fixed", "m_hip", "pelvis", "0 -0.1 0.05")
               + ABOVE_PELVIS + "</robot>")


def _full(model, names, qi):
    full = pin_configuration(model, zip(names, qi, strict=True))
    knee = model.joints[model.getJointId("l_knee")]
    elbow = model.joints[model.getJointId("elbow")]
    full[elbow.idx_q] = 0.5 * full[knee.idx_q] + 0.1        # Pinocchio reads <mimic> as a joint of its own
    return full


def test_chain_from_a_foot_matches_the_robot_written_from_that_foot(tmp_path):
    """Foot -> hand of the pelvis-rooted file: the tool's placement in the sole frame equals Pinocchio's on
    both files (1e-12 m), the leg joints come first, nearest the foot, with a mimic of a walked-back joint
    followed on the arm; the gravity torques of the robot standing on that foot equal Pinocchio's RNEA on the
    sole-rooted file (1e-9 N m), the other leg hanging from the pelvis like any side branch."""
    a, b = tmp_path / "pelvis.urdf", tmp_path / "sole.urdf"
    a.write_text(PELVIS_ROOTED)
    b.write_text(SOLE_ROOTED)
    arm = load_model(a, "tool", base_frame="l_sole")
    assert arm.desc.joint_names == ("l_ankle", "l_knee", "l_hip", "waist", "shoulder", "wrist")
    ma, mb = pin.buildModelFromUrdf(str(a)), pin.buildModelFromUrdf(str(b))
    da, db = ma.createData(), mb.createData()
    q = np.random.default_rng(4).uniform(-1.0, 1.0, (6, 6))
    x = arm.model.ball_centres(q, None, arm.p)
    pa = PinocchioArm(arm.desc)
    tau = np.array([pa.gravity_torques(qi) for qi in q])
    assert np.abs(tau).max() > 10.0                 # the pelvis, torso and other leg over the ankle: tens of N m
    for qi, xi, ti in zip(q, x, tau, strict=True):
        pin.framesForwardKinematics(ma, da, _full(ma, arm.desc.joint_names, qi))
        T = da.oMf[ma.getFrameId("l_sole")].inverse() * da.oMf[ma.getFrameId("tool")]
        np.testing.assert_allclose(xi, T.translation, rtol=0, atol=1e-12)
        fb = _full(mb, arm.desc.joint_names, qi)
        pin.framesForwardKinematics(mb, db, fb)
        np.testing.assert_allclose(xi, db.oMf[mb.getFrameId("tool")].translation, rtol=0, atol=1e-12)
        g = pin.computeGeneralizedGravity(mb, db, fb)
        idx = [mb.joints[mb.getJointId(n)].idx_q for n in arm.desc.joint_names]
        # the mimic elbow's own torque is not a chain joint's (it follows l_knee): only the arm's own
        # joints beyond the mimic and the leg's below it are compared where no mimic load enters
        np.testing.assert_allclose(ti[[0, 2, 3, 5]], g[[idx[0], idx[2], idx[3], idx[5]]], rtol=0, atol=1e-9)


def test_calibrated_urdf_of_a_chain_from_a_foot_is_the_chains_own(tmp_path):
    """The user's file cannot take a walked-back chain's origins: the calibrated URDF is the chain's own,
    which Pinocchio reads and which places the tool as the model does."""
    from arm_model.urdf_import import calibrated_urdf_text
    a = tmp_path / "pelvis.urdf"
    a.write_text(PELVIS_ROOTED)
    arm = load_model(a, "tool", base_frame="l_sole")
    text = calibrated_urdf_text(arm.desc, arm.desc)
    out = tmp_path / "cal.urdf"
    out.write_text(text)
    assert 'name="l_sole~' not in text and "l_hip_o" not in text
    back = load_model(out, "tool", base_frame="l_sole")    # the generated chain keeps its base's and tip's names
    assert back.desc.joint_names == arm.desc.joint_names
    q = np.random.default_rng(5).uniform(-1.0, 1.0, (4, 6))
    np.testing.assert_allclose(back.model.ball_centres(q, None, back.p), arm.model.ball_centres(q, None, arm.p),
                               rtol=0, atol=1e-12)
