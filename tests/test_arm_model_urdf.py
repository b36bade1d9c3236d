"""The committed URDF is the generator's output; it loads in yourdfpy and Pinocchio and matches the chain."""
from __future__ import annotations

import numpy as np

from arm_model import ball_centres, urdf_text
from arm_model.urdf import ELASTIC_JOINTS
from conftest import ROOT, assert_close


def test_committed_urdf_is_not_stale(nominal):
    committed = (ROOT / "urdf" / "aacmm7.urdf").read_text()
    assert committed == urdf_text(nominal), (
        "urdf/aacmm7.urdf differs from its generator: run `make urdf` (aacmm urdf urdf/aacmm7.dh.toml -o "
        "urdf/aacmm7.urdf)")


def test_urdf_loads_in_yourdfpy_and_matches_chain(nominal):
    import yourdfpy
    robot = yourdfpy.URDF.load(str(ROOT / "urdf" / "aacmm7.urdf"))
    assert robot.actuated_joint_names == [j.name for j in nominal.joints] + list(ELASTIC_JOINTS)
    rng = np.random.default_rng(1)
    for q in rng.uniform(-3, 3, (10, 7)):
        robot.update_cfg(np.concatenate([q, np.zeros(3)]))
        T = robot.get_transform("ball", "base_link")
        assert_close(T[:3, 3], ball_centres(nominal, q), atol=1e-12)
    # visual geometry for the viewer: link tubes, joint housings, stylus and ball
    kinds = [type(v.geometry.cylinder or v.geometry.sphere).__name__
             for link in robot.robot.links for v in link.visuals]
    assert kinds.count("Sphere") == 1 and kinds.count("Cylinder") >= 14


def test_urdf_pinocchio_model_has_elastic_joints(pin_arm):
    names = list(pin_arm.model.names)
    assert names[-3:] == list(ELASTIC_JOINTS)
    assert pin_arm.model.nq == 10
