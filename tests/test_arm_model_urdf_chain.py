"""Arms given as a URDF: the chain to --tip-frame, origin-error parameters, three evaluators agree."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import InputError, PinocchioArm, apply_params, ball_centres, casadi_ball_centre, param_spec
from arm_model.description import format_description, parse_description
from arm_model.urdf import urdf_text
from arm_model.urdf_import import description_from_urdf, load_arm
from conftest import assert_close


def arm_urdf(nominal) -> str:
    """The nominal arm as a plain URDF: the probe as a fixed 'tip' link, a side branch, a fixed joint
    inside the chain (the flange), and one joint axis that is not z (j7 turned about -z -> axis 0 0 -1)."""
    text = urdf_text(nominal)
    text = text[: text.index('  <joint name="stylus_root_joint"')]
    text += ('  <joint name="tip_joint" type="fixed"><parent link="flange"/><child link="tip"/>'
             '<origin xyz="0.001 -0.002 0.085" rpy="0.3 0 0"/></joint>\n  <link name="tip"/>\n'
             '  <joint name="finger" type="revolute"><parent link="link_3"/><child link="finger_link"/>'
             '<origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="-1" upper="1" effort="1" '
             'velocity="1"/></joint>\n'
             '  <link name="finger_link"/>\n</robot>\n')
    return text


def test_urdf_chain_matches_the_dh_arm(nominal, tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf(nominal))
    d = description_from_urdf(path, "tip")
    assert d.convention == "urdf" and d.joint_names == nominal.joint_names
    # the last joint frame of a URDF chain is j7's child link: the flange lies d7 = 95 mm beyond it
    assert_close(d.probe.p_last, [0.001, -0.002, 0.180], atol=1e-15)
    assert_close(d.probe.rpy, [0.3, 0, 0], atol=1e-15)     # the tip frame's orientation is the probe's
    ref = nominal.with_probe(p_last=(0.001, -0.002, 0.085), rpy=(0.3, 0.0, 0.0))
    rng = np.random.default_rng(0)
    q = rng.uniform(-3, 3, (50, 7))
    assert_close(ball_centres(d, q), ball_centres(ref, q), atol=1e-12)
    # with force: same first-order deflection C F; the bending hinge sits where the stylus line passes
    # closest to the last joint origin, so the lever differs (173 vs 82 mm) and so does the second-order
    # drop (c F)^2 / 2L < 1e-8 m
    w = rng.normal(0, 1, (50, 3))
    w *= 3.0 / np.linalg.norm(w, axis=1)[:, None]      # 3 N: (c F)^2 (1/0.17 - 1/0.36) = 5.7e-9 m
    assert_close(ball_centres(d, q, w), ball_centres(ref, q, w), atol=6e-9)


def test_urdf_chain_three_evaluators_with_origin_errors(nominal, tmp_path):
    path = tmp_path / "arm.urdf"
    text = arm_urdf(nominal)
    assert '<axis xyz="0.0 0.0 1.0"/>' in text
    path.write_text(text.replace('<axis xyz="0.0 0.0 1.0"/>', '<axis xyz="0 0.6 0.8"/>', 1))
    d = load_arm(path, "tip")
    assert_close(d.joints[0].axis, [0, 0.6, 0.8], atol=1e-15)
    spec = param_spec(d)
    assert spec.names[:6] == ("j1.origin_x", "j1.origin_y", "j1.origin_z", "j1.origin_roll",
                              "j1.origin_pitch", "j1.origin_yaw")
    rng = np.random.default_rng(1)
    p = np.array([rng.normal(0, {"m": 1e-4, "rad": 1e-3, "m/N": 1e-6}[u]) for u in spec.units])
    dp = apply_params(d, p)
    arm, f = PinocchioArm(dp), casadi_ball_centre(d)
    q = rng.uniform(-3, 3, (10, 7))
    w = np.zeros((10, 6))
    w[:, :3] = rng.normal(0, 3, (10, 3))
    batch = ball_centres(d, q, w, p)
    for i in range(10):
        assert_close(arm.ball_centre(q[i], w[i]), batch[i], atol=1e-12)
        assert_close(np.array(f(q[i], w[i], p)).ravel(), batch[i], atol=1e-12)


def test_urdf_description_roundtrips_through_toml(nominal, tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf(nominal))
    d = description_from_urdf(path, "tip")
    back = parse_description(format_description(d))
    q = np.random.default_rng(2).uniform(-3, 3, (20, 7))
    assert_close(ball_centres(back, q), ball_centres(d, q), atol=1e-12)


def test_urdf_bad_tip_frame(nominal, tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf(nominal))
    with pytest.raises(InputError, match="no link named"):
        description_from_urdf(path, "nowhere")


def test_urdf_tip_at_the_last_joint_is_a_rigid_tip(nominal, tmp_path):
    """The last joint's own link (a flange) as the tip: no stylus, compliances 0, the joint origin."""
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf(nominal))
    d = description_from_urdf(path, "link_7")
    assert d.probe.lever == 0.0 and d.probe.stylus_length == 0.0 and not d.probe.compliance.any()
    assert d.probe.p_last == (0.0, 0.0, 0.0)
    q = np.random.default_rng(4).uniform(-3, 3, (5, 7))
    assert_close(ball_centres(d, q, np.ones((5, 3))), ball_centres(d, q), atol=0)   # no stylus, nothing bends


def test_urdf_without_tip_frame_and_bad_xml(tmp_path):
    """Without --tip-frame a URDF is read first: a broken one says where it is broken (a xacro file says to expand
    it), a good one lists the links its chains end at."""
    path = tmp_path / "arm.urdf"
    path.write_text("<robot><link name='a'>")
    for tip in (None, "a"):
        with pytest.raises(InputError, match="not valid XML") as exc:
            load_arm(path, tip)
        assert exc.value.line == 1
    path.write_text("<robot name='r'><link name='a'/><link name='b'/><link name='c'/>"
                    "<joint name='j' type='continuous'><parent link='a'/><child link='b'/></joint>"
                    "<joint name='k' type='fixed'><parent link='b'/><child link='c'/></joint></robot>")
    with pytest.raises(InputError, match=r"needs --tip-frame .*; the chains end at c \(1 moving joint\)$"):
        load_arm(path)


#: three revolute joints, j2's origin at pitch +90 deg and turned in roll and yaw too (gimbal: roll and yaw
#: of Rz Ry Rx turn about one axis there)
GIMBAL_URDF = """<?xml version="1.0"?>
<robot name="gimbal">
  <link name="base_link"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base_link"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.1 0" rpy="0.3 1.5707963267948966 -0.2"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0 0 0.4" rpy="0.1 -0.4 0.7"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="l3"/><child link="tip"/><origin xyz="0.05 0.02 0.35"/></joint>
</robot>
"""


def test_urdf_origin_angle_errors_agree_in_every_evaluator_at_pitch_90_deg(tmp_path):
    """Angle errors (turns about the origin's own axes) at an origin at pitch 90 deg: the batch evaluator, the
    CasADi expression, the joint screws (inverse kinematics, probe rotations) and Pinocchio on the description
    with the errors folded into roll/pitch/yaw (also written and read back as URDF) agree to 1e-12 m; the
    reference: the origin matrix turned by Rz Ry Rx of the errors, by hand."""
    from arm_model.geometry import rotation_xyz
    from arm_model.jacobian import joint_screws
    from arm_model.kinematics import probe_rotations
    from arm_model.params import split_params
    from arm_model.urdf import origin_matrix
    (tmp_path / "g.urdf").write_text(GIMBAL_URDF)
    d = load_arm(tmp_path / "g.urdf", "tip")
    spec = param_spec(d)
    rng = np.random.default_rng(7)
    p = np.array([rng.normal(0, {"m": 1e-4, "rad": 3e-3, "m/N": 1e-6}[u]) for u in spec.units])
    dp = apply_params(d, p)
    # by hand: j2's origin turned about its own axes by its angle errors
    k = spec.index("j2.origin_roll")
    e = p[k: k + 3]
    want = origin_matrix(d.joints[1].origin)[:3, :3] @ rotation_xyz((0, 0, e[2])) @ rotation_xyz((0, e[1], 0)) \
        @ rotation_xyz((e[0], 0, 0))
    assert_close(origin_matrix(dp.joints[1].origin)[:3, :3], want, atol=1e-15)
    q = rng.uniform(-3, 3, (10, 3))
    batch = ball_centres(d, q, None, p)
    rows, p_last, _ = split_params(d, p)
    rot, o, _, _ = joint_screws(d.convention, rows, q, d.chain_joints)
    assert_close(o + rot @ np.asarray(p_last), batch, atol=1e-12)
    assert_close(probe_rotations(d, q, p), probe_rotations(dp, q), atol=1e-12)
    (tmp_path / "calibrated.urdf").write_text(urdf_text(dp))
    again = load_arm(tmp_path / "calibrated.urdf", "ball")
    arm, f = PinocchioArm(dp), casadi_ball_centre(d)
    for i in range(len(q)):
        assert_close(arm.ball_centre(q[i], np.zeros(6)), batch[i], atol=1e-12)
        assert_close(np.array(f(q[i], np.zeros(6), p)).ravel(), batch[i], atol=1e-12)
    assert_close(ball_centres(dp, q), batch, atol=1e-12)
    assert_close(ball_centres(again, q), batch, atol=1e-12)


def _rank(a: np.ndarray) -> int:
    s = np.linalg.svd(a / np.linalg.norm(a, axis=0), compute_uv=False)
    return int(np.sum(s > 1e-6 * s[0]))


def test_the_three_angle_errors_of_an_origin_at_pitch_90_deg_are_three_directions(tmp_path):
    """At pitch 90 deg roll and yaw added to the origin's own turn about one axis (UR3/5/10's shoulder lift and
    wrist 1, TIAGo's arm 4-6, Baxter's e1 and w1): calibrate held the third direction ("not separable") and a
    real tilt about it stayed (UR5: 1 mrad at the shoulder lift left 398 um RMS after the fit). The origin's
    angle errors turn it about its own axes: three directions of the ball, as Pinocchio's placement turned about
    its own x, y, z (the independent reference)."""
    import pinocchio as pin

    (tmp_path / "g.urdf").write_text(GIMBAL_URDF)
    desc = description_from_urdf(tmp_path / "g.urdf", "tip")
    q = np.random.default_rng(4).uniform(-2.0, 2.0, (8, 3))
    names = list(param_spec(desc).names)
    h = 1e-6
    cols = []
    for a in ("roll", "pitch", "yaw"):
        e = np.zeros(len(names))
        e[names.index(f"j2.origin_{a}")] = h
        cols.append(((ball_centres(desc, q, None, e) - ball_centres(desc, q, None, -e)) / (2 * h)).ravel())
    # the reference: Pinocchio's model of the file, j2's placement turned about its own x, y, z
    model = pin.buildModelFromUrdf(str(tmp_path / "g.urdf"))
    fid, jid = model.getFrameId("tip"), model.getJointId("j2")

    def tips(w):
        m = model.copy()
        m.jointPlacements[jid] = m.jointPlacements[jid] * pin.SE3(pin.exp3(w), np.zeros(3))
        d = m.createData()
        out = []
        for qi in q:
            pin.framesForwardKinematics(m, d, qi)
            out.append(d.oMf[fid].translation.copy())
        return np.array(out)

    ref = np.column_stack([((tips(h * e) - tips(-h * e)) / (2 * h)).ravel() for e in np.eye(3)])
    assert np.abs(tips(np.zeros(3)) - ball_centres(desc, q)).max() < 1e-12     # the same arm
    assert _rank(ref) == 3
    assert _rank(np.column_stack(cols)) == 3
