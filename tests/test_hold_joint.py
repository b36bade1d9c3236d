"""``--hold-joint``: a moving joint of a URDF's chain that the points do not give (a tool changer's joint past
the arm's last, always at rest) held at a stated value as a fixed joint."""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_sim_mocap import LIFT_ARM_URDF

from arm_model import InputError
from arm_model.cli import main
from arm_model.kinematics import probe_rotations
from arm_model.model_file import load_model
from conftest import assert_close, pin_configuration

CHANGER = """  <link name="mount"><inertial><origin xyz="0 0 0.02"/><mass value="0.3"/>
    <inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="holder"><inertial><origin xyz="0.01 0 0.01"/><mass value="0.2"/>
    <inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="tool_mount" type="continuous"><parent link="flange"/><child link="mount"/>
    <origin xyz="0.01 0 0.1" rpy="0 0 0.3"/><axis xyz="0 0 1"/></joint>
  <joint name="holder_joint" type="fixed"><parent link="mount"/><child link="holder"/>
    <origin xyz="0.03 0 0.04"/></joint>
</robot>"""
URDF = LIFT_ARM_URDF.replace("</robot>", CHANGER)


@pytest.fixture()
def urdf(tmp_path):
    p = tmp_path / "changer.urdf"
    p.write_text(URDF)
    return p


def test_a_held_joint_is_pinocchio_s_placement_with_that_joint_at_the_value(urdf):
    """The held chain is Pinocchio's placement of the tip in the user's file with the held joint at its value
    (1e-12 m, 1e-12 rotation), and the masses beyond it hang from the last moving joint as before."""
    import pinocchio as pin
    free = load_model(urdf, "holder")
    assert free.desc.joint_names[-1] == "tool_mount"
    arm = load_model(urdf, "holder", hold={"tool_mount": 30.0})
    assert arm.desc.joint_names == free.desc.joint_names[:-1]
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    q = np.random.default_rng(4).uniform(-1.0, 1.0, (6, arm.desc.n_joints))
    q[:, 0] = np.abs(q[:, 0]) * 0.3
    x, r = arm.model.ball_centres(q, None, arm.p), probe_rotations(arm.desc, q)
    for qi, xi, ri in zip(q, x, r, strict=True):
        held = ("tool_mount", math.radians(30.0))
        full = pin_configuration(model, [*zip(arm.desc.joint_names, qi, strict=True), held])
        pin.framesForwardKinematics(model, data, full)
        T = data.oMf[model.getFrameId("holder")]
        assert_close(xi, T.translation, atol=1e-12)
        assert_close(ri, T.rotation, atol=1e-12)
    held_last, free_rows = arm.desc.joints[-1], free.desc.joints
    assert held_last.mass == pytest.approx(free_rows[-2].mass + free_rows[-1].mass, abs=1e-12)   # 0.8 + 0.5 kg
    assert held_last.mass == pytest.approx(1.3, abs=1e-12)


@pytest.mark.parametrize("hold,words", [({"tool_mont": 0.0}, "did you mean 'tool_mount'"),
                                        ({"holder_joint": 0.0}, "a fixed joint"),
                                        ({"finger_joint": 0.0}, "not a joint of the chain")])
def test_a_joint_that_cannot_be_held_is_named(urdf, hold, words):
    with pytest.raises(InputError) as e:
        load_model(urdf, "holder", hold=hold)
    assert e.value.column == "key '--hold-joint'" and words in str(e.value)


def test_calibrate_on_a_tool_changer_tip_needs_and_takes_the_held_joint(urdf, tmp_path, capsys):
    """A simulated campaign read at the flange (6 joint columns), calibrated with the tool holder as the tip:
    without the option the joint count is refused (exit 2, nothing written); with it the fit runs, writes a
    model file and a URDF that read back to the same arm, and a repeated or malformed option is refused."""
    (tmp_path / "c.toml").write_text('arm = "changer.urdf"\ntip_frame = "flange"\nsensor = "none"\n[truth]\n'
                                     'length_error_mm = 0.5\n[[task]]\nkind = "mocap"\npostures = 30\n'
                                     'noise_mm = 0.1\n')
    assert main(["simulate", str(tmp_path / "c.toml"), "-o", str(tmp_path / "sim")]) == 0
    pts = str(tmp_path / "sim" / "points.csv")
    base = ["calibrate", pts, "--arm", str(urdf), "--tip-frame", "holder", "--effect", "none", "--no-plots"]
    assert main([*base, "-o", str(tmp_path / "no")]) == 2
    assert not (tmp_path / "no").exists()
    capsys.readouterr()
    assert main([*base, "--hold-joint", "tool_mount=30", "-o", str(tmp_path / "cal")]) == 0
    cal = load_model(tmp_path / "cal" / "liftarm-calibrated.urdf", "holder", hold={"tool_mount": 30.0})
    fitted = load_model(tmp_path / "cal" / "liftarm-calibrated.toml")
    q = np.random.default_rng(5).uniform(-1.0, 1.0, (4, fitted.desc.n_joints))
    q[:, 0] = np.abs(q[:, 0]) * 0.3
    assert_close(cal.model.ball_centres(q, None, cal.p), fitted.model.ball_centres(q, None, fitted.p), atol=1e-9)
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main([*base, "--hold-joint", "tool_mount", "--hold-joint", "tool_mount=5", "-o", str(tmp_path / "x")])
    assert e.value.code == 2 and "tool_mount given more than once" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main([*base, "--hold-joint", "tool_mount=abc", "-o", str(tmp_path / "y")])
    assert e.value.code == 2 and "VALUE must be a number" in capsys.readouterr().err
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()
