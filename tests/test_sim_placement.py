"""Where a ball bar's seats or a tracker's nests go: inside the task's region, or, when the task gives none and
the arm cannot reach there, anywhere in the chain's own workspace (an arm hung from a ceiling never reaches the
default region near the floor)."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import InputError
from arm_model.sim import campaign_from_dict, simulate

#: a six-joint arm hung 2.5 m up (a ceiling mount), 0.8 m of reach; its tool 0.1 m past the last joint
CEILING_URDF = """<?xml version="1.0"?>
<robot name="ceiling6">
  <link name="ceiling"/>
  <link name="l1"/><link name="l2"/><link name="l3"/><link name="l4"/><link name="l5"/><link name="l6"/>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="ceiling"/><child link="l1"/>
    <origin xyz="0 0 2.5" rpy="3.14159265 0 0"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="10" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/><origin xyz="0 0 0.35"/>
    <axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" effort="10" velocity="1"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/><origin xyz="0 0 0.3"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="j5" type="revolute"><parent link="l4"/><child link="l5"/><origin xyz="0 0 0.05"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="10" velocity="1"/></joint>
  <joint name="j6" type="revolute"><parent link="l5"/><child link="l6"/><origin xyz="0 0 0.05"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="l6"/><child link="tool"/><origin xyz="0 0 0.1"/></joint>
</robot>
"""


def _campaign(task: dict) -> dict:
    return {"name": "ceiling", "seed": 4, "arm": "ceiling6.urdf", "tip_frame": "tool", "sensor": "none",
            "truth": {"length_error_mm": 0.2, "angle_error_deg": 0.02}, "task": [task]}


@pytest.fixture(scope="module")
def urdf_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("ceiling")
    (d / "ceiling6.urdf").write_text(CEILING_URDF)
    return d


def test_seat_pairs_are_placed_in_the_chain_s_workspace(urdf_dir):
    """The default region (0.3-0.8 m from the base axis, -0.2 to 0.6 m high) is out of this arm's reach (its
    shoulder 2.4 m up): the seats go where it reaches, a bar's length apart, each seat articulated with the
    stylus in its cone about the seat's axis, every ball centre on its seat."""
    task = {"kind": "ballbar", "ends": "seat", "length_mm": 150, "positions": 2, "articulations": 2}
    sim = simulate(campaign_from_dict(_campaign(task), base_dir=urdf_dir))
    placed = sim.truth["placements"]["bar"]["positions"]
    assert len(placed) == 2
    for pos in placed:
        a, b, axis = (np.array(pos[k]) for k in ("A_m", "B_m", "axis"))
        assert np.linalg.norm(b - a) == pytest.approx(0.150, abs=1e-12)
        assert a[2] > 1.2 and b[2] > 1.2                       # near the ceiling, not in the default region
        assert np.linalg.norm(axis) == pytest.approx(1.0, abs=1e-12)
    pts = sim.points
    assert len(pts) == 2 * 2 * 2
    for pos in placed:
        for end, seat in (("A", "A_m"), ("B", "B_m")):
            rows = (pts.measurement == pos["measurement"]) & (pts.feature == f"bar-{end}")
            assert rows.sum() == 2
            assert np.max(np.linalg.norm(sim.true_centres[rows] - np.array(pos[seat]), axis=1)) < 1e-9
    assert sim.stats["truth_residual_max_m"] < 1e-9


def test_a_region_the_task_gives_is_kept_and_its_failure_said(urdf_dir):
    """A region of the task's own is the user's: out of reach, it is an error that says how to let the
    workspace decide (nothing is moved elsewhere)."""
    task = {"kind": "ballbar", "ends": "seat", "length_mm": 150, "positions": 2, "articulations": 3,
            "height_mm": [0, 300]}
    with pytest.raises(InputError, match="give none: the chain's own workspace is then used"):
        simulate(campaign_from_dict(_campaign(task), base_dir=urdf_dir))
