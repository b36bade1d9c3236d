"""Where a ball bar's seats or a tracker's nests go: inside the task's region, or, when the task gives none and
the arm cannot reach there, anywhere in the chain's own workspace (an arm hung from a ceiling never reaches the
default region near the floor)."""
from __future__ import annotations

import numpy as np
import pytest
from urdf_fixtures import serial_urdf

from arm_model import InputError
from arm_model.sim import campaign_from_dict, simulate

#: a six-joint arm hung 2.5 m up (a ceiling mount), 0.8 m of reach; its tool 0.1 m past the last joint
CEILING_URDF = serial_urdf(
    "ceiling6", "ceiling", [((0, 0, 2.5), (3.14159265, 0, 0), (0, 0, 1), -3, 3),
                            ((0, 0, 0.1), (0, 0, 0), (0, 1, 0), -2, 2),
                            ((0, 0, 0.35), (0, 0, 0), (0, 1, 0), -2.5, 2.5), ((0, 0, 0.3), (0, 0, 0), (0, 0, 1), -3, 3),
                            ((0, 0, 0.05), (0, 0, 0), (0, 1, 0), -2, 2), ((0, 0, 0.05), (0, 0, 0), (0, 0, 1), -3, 3)],
    "tool", (0, 0, 0.1))


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
