"""Link masses assumed from the chain's geometry for a robot whose URDF ships without ``<inertial>``
(:func:`calibration.calibrate.with_assumed_masses`, docs/calibration.md "Arms given as a URDF"): uniform rods from
each joint's origin to the next, so the default estimation gives such a robot its joint compliance under gravity."""
from __future__ import annotations

import argparse
import logging

import numpy as np
import pytest

from arm_model.model import ArmModel
from arm_model.urdf_import import load_arm
from calibration.calibrate import ASSUMED_DENSITY, default_effects, with_assumed_masses
from calibration.cli import assume_masses
from conftest import NOMINAL, ROOT

SEATS = ROOT / "examples" / "data" / "real-panda-seats"


def test_each_link_is_a_rod_to_the_next_joint_as_pinocchio_places_it():
    """The bundled Panda URDF (no <inertial>): each joint's link gets ASSUMED_DENSITY x the distance to the next
    joint's origin (the last joint's: to ball_link), its centre of mass half-way, in the joint's frame; the
    reference is Pinocchio's own placement of the next joint (and of the ball frame) in the same file."""
    import pinocchio as pin
    desc = load_arm(SEATS / "panda.urdf", "ball_link")
    assert not any(j.mass for j in desc.joints)
    got = with_assumed_masses(ArmModel(desc))
    assert got is not None and got.effects == ()
    pm = pin.buildModelFromUrdf(str(SEATS / "panda.urdf"))
    nxt = [pm.jointPlacements[pm.getJointId(j.name)].translation for j in desc.joints[1:]]
    nxt.append(pm.frames[pm.getFrameId("ball_link")].placement.translation)
    for row, t in zip(got.desc.joints, nxt, strict=True):
        assert row.mass == pytest.approx(ASSUMED_DENSITY * np.linalg.norm(t), abs=1e-12)
        np.testing.assert_allclose(row.com, t / 2, atol=1e-12)
    assert sum(j.mass for j in got.desc.joints) > 5.0              # a 1.1 m arm at 10 kg/m: about 11 kg
    assert got.desc.masses_assumed and not desc.masses_assumed      # a model file written from it says so
    assert default_effects(got) != () and default_effects(ArmModel(desc)) == ()


def test_nothing_is_assumed_where_masses_or_effects_exist_or_for_a_dh_arm():
    with_masses = load_arm(SEATS / "panda-with-inertials.urdf", "ball_link")
    assert with_assumed_masses(ArmModel(with_masses)) is None
    from arm_model.model_file import parse_model
    dh = parse_model(NOMINAL.read_text(), str(NOMINAL)).desc
    assert with_assumed_masses(ArmModel(dh)) is None             # a measuring arm by DH rows: geometry by default
    bare = load_arm(SEATS / "panda.urdf", "ball_link")
    from arm_model.effects import EncoderEccentricity
    assert with_assumed_masses(ArmModel(bare, (EncoderEccentricity(),))) is None


def test_the_command_says_so_and_a_masses_file_wins(caplog):
    bare = ArmModel(load_arm(SEATS / "panda.urdf", "ball_link"))
    with caplog.at_level(logging.INFO, logger="calibration"):
        got = assume_masses(bare, argparse.Namespace(masses=None))
    assert any(j.mass for j in got.desc.joints)
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "gives no link masses" in said and "--masses FILE" in said and "--effect none" in said, said
    assert assume_masses(bare, argparse.Namespace(masses=SEATS / "m.toml")) is bare


def test_a_tool_alone_with_a_mass_still_gets_the_arm_assumed(tmp_path):
    """The bundled Panda URDF with a 0.2 kg <inertial> on its ball_link alone: the arm's links are still massless,
    so they get their rods, the tool's mass added to the last link's (on the real seats, the compliances under the
    tool's torques alone predicted the other placements at 2.85 mm mean spread, the geometry alone at 2.04); a
    mass on any link before the last joint is the arm's own: nothing assumed."""
    inertial = ('<inertial><mass value="0.2"/><origin xyz="0 0 -0.01"/>'
                '<inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>')
    text = (SEATS / "panda.urdf").read_text()
    tool = tmp_path / "tool.urdf"
    tool.write_text(text.replace('<link name="ball_link">', '<link name="ball_link">' + inertial, 1))
    desc = load_arm(tool, "ball_link")
    assert [j.mass for j in desc.joints] == [0.0] * 6 + [pytest.approx(0.2)]
    got = with_assumed_masses(ArmModel(desc))
    bare = with_assumed_masses(ArmModel(load_arm(SEATS / "panda.urdf", "ball_link")))
    assert got is not None and bare is not None
    assert got.desc.joints[:6] == bare.desc.joints[:6]
    rod, own, both = bare.desc.joints[6], desc.joints[6], got.desc.joints[6]
    assert both.mass == pytest.approx(rod.mass + 0.2, abs=1e-12)
    np.testing.assert_allclose(np.multiply(both.com, both.mass), np.multiply(rod.com, rod.mass)
                               + np.multiply(own.com, own.mass), atol=1e-12)
    arm = tmp_path / "arm.urdf"
    arm.write_text(text.replace('<link name="panda_link3">', '<link name="panda_link3">' + inertial, 1))
    assert with_assumed_masses(ArmModel(load_arm(arm, "ball_link"))) is None
