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
