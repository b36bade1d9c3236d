"""Well-formed but degenerate data: every value passes its reader, and only the computation can find the data
insufficient. The rule (docs/guarantees.md §4): exit 0 with what the data cannot see held or prior-dominated and
named, or exit 2/4 with one message; never a traceback, a value of rounding size written as if measured, or a
model file its reader refuses. Each test is one case the audit found wrong, named after what it checks."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
SEAT = '\n[[feature]]\nid = "seat"\nkind = "seat"\n'


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    got = capsys.readouterr()
    return rc, got.err, got.out


def _case(tmp_path, rings: int, seat_rows: int, step_deg: float = 0.0):
    """The first ``rings`` measurements of the example ring campaign and ``seat_rows`` copies of its first pose
    as a seat (one pose repeated: an operator who did not articulate), the last joint of copy k moved by k
    ``step_deg``."""
    lines = (RING / "points.csv").read_text().splitlines()
    ids = tuple(f"ring-{k:02d}," for k in range(1, rings + 1))
    rows = [r for r in lines[1:] if ids and r.startswith(ids)]
    cells = lines[1].split(",")
    q7 = lines[0].split(",").index("q7_deg")
    seat = [",".join(["seat-1", "seat", *cells[2:q7], f"{float(cells[q7]) + k * step_deg:.12f}", *cells[q7 + 1:]])
            for k in range(seat_rows)]
    pts = tmp_path / "points.csv"
    pts.write_text("\n".join([lines[0], *rows, *seat]) + "\n")
    art = tmp_path / "artefacts.toml"
    art.write_text((RING / "artefacts.toml").read_text() + SEAT)
    return pts, art


def test_a_seat_at_one_reading_repeated_is_refused(tmp_path, capsys):
    """20 rows of one reading on a seat (a seat needs one point, so the count check took it): the copies' residuals
    are exactly 0, counted as redundancy and as the seat's noise. The fit then failed in ``math.log(0)`` (exit 3);
    beside other features the seat's noise came out at 7e-11 um, weighted 1e22 times theirs, and close-loop stopped
    on a weight factor of 0 (exit 3). As for every other kind (docs/guarantees.md, "one pose repeated"): exit 2 at
    the seat's first line, nothing written."""
    pts, art = _case(tmp_path, 0, 20)
    for command in ("calibrate", "close-loop"):
        out = tmp_path / command
        rc, err, _ = _run([command, pts, art, "--arm", "aacmm7", "--no-plots", "-o", out], capsys)
        assert rc == 2 and "line 2, column 'feature': measurement 'seat-1', feature 'seat' (seat): its " in err
        assert "points are one reading repeated" in err, err
        assert not out.exists()


def test_a_feature_whose_residuals_are_rounding_gives_no_noise_estimate(tmp_path, capsys):
    """Two ring measurements and a seat at one pose repeated 10 times, the last joint 1e-11 deg apart (rounding of
    a reading written two ways; no longer one reading repeated): the seat's residuals are 1e-16 m, and its noise was
    estimated at that size and weighted 1e20 times the ring's (written in summary.json as the seat's noise). A
    residual below the smallest uncertainty one may state (1 pm) is rounding: the seat keeps its stated (default)
    uncertainty, said as such."""
    pts, art = _case(tmp_path, 2, 10, step_deg=1e-11)
    out = tmp_path / "o"
    rc, err, said = _run(["calibrate", pts, art, "--arm", "aacmm7", "--no-plots", "-o", out], capsys)
    assert rc == 0, err
    s = json.loads((out / "summary.json").read_text())
    seat = next(v for v in s["variance_components"] if v["group"] == "seat")
    assert seat["no_scatter"] and not seat["estimated"] and seat["factor"] == 1.0, seat
    assert s["weights"]["factors"].get("seat", 1.0) == pytest.approx(1.0), s["weights"]
    ring = next(v for v in s["variance_components"] if v["group"] == "ring")
    assert ring["estimated"] and 1.0 < ring["estimate_um"] < 10.0, ring
    # the seat's articulation is rounding before and after: no ratio (it was "infx"), never "worse than nominal"
    art = [r for r in s["validation_training"] if r["key"].startswith("articulation")]
    assert art and all(r["ratio"] is None for r in art), art
    assert "(no ratio: the calibrated figure is below 1 pm)" in said and "infx" not in said, said


def test_a_ring_measurement_at_one_pose_repeated_is_named(tmp_path, capsys):
    """`ring` on a measurement whose points are one pose repeated said "no principal direction gives a circle seed:
    the points are collinear" (their spread was 1e-17 m of rounding, not 0), without the measurement. Now: the
    file, line and measurement, and that the points coincide; exit 4, nothing written."""
    lines = (RING / "points.csv").read_text().splitlines()
    pts = tmp_path / "points.csv"
    pts.write_text("\n".join([lines[0], *[lines[1]] * 8]) + "\n")
    out = tmp_path / "o"
    rc, err, _ = _run(["ring", pts, RING / "artefacts.toml", "--arm", "aacmm7", "--no-plots", "-o", out], capsys)
    assert rc == 4 and "points.csv, line 2, measurement 'ring-01': all points coincide (to rounding)" in err, err
    assert not out.exists()


@pytest.mark.parametrize("points", [
    np.tile([0.5, -0.3, 0.2], (10, 1)),                                     # one pose repeated
    np.tile([0.5, -0.3, 0.2], (10, 1)) + 1e-15 * np.arange(30).reshape(10, 3) % 3,   # and rounding
    [0.5, -0.3, 0.2] + np.outer(np.linspace(0, 0.1, 10), [1, 2, 3]),       # collinear
])
@pytest.mark.parametrize("fit", ["fit_plane", "fit_sphere", "fit_cylinder", "ring_fit"])
def test_every_feature_fit_refuses_degenerate_points(points, fit):
    """Coinciding or collinear points determine no plane, sphere or cylinder: a NumericalError (exit 4 in a
    command), never a fit returned."""
    from arm_model import NumericalError, geometry
    f = getattr(geometry, fit)
    with pytest.raises(NumericalError):
        f(points, 0.006, 0.175) if fit == "ring_fit" else f(points)


@settings(max_examples=30, deadline=None)
@given(rows=st.integers(8, 40), cols=st.integers(2, 8), seed=st.integers(0, 2**32 - 1),
       rounding=st.floats(1e-18, 1e-13))
def test_the_rank_of_columns_the_nuisance_absorbs_is_zero(rows, cols, seed, rounding):
    """``analyse`` on a reduced Jacobian of pure rounding (every parameter absorbed by the nuisance unknowns, as
    when one pose is repeated) kept a direction: its threshold was relative to the largest singular value, itself
    rounding. Now rank 0, every parameter named; and an exact copy of a visible column (two joints moving
    together) is one direction, the copy held with the combination."""
    from calibration.identifiability import analyse
    rng = np.random.default_rng(seed)
    jp = rng.standard_normal((rows, cols))
    idf = analyse(rounding * rng.standard_normal((rows, cols)), jp, [f"p{k}" for k in range(cols)])
    assert idf.rank == 0 and len(idf.dependent) == cols, idf
    twin = np.column_stack([jp, jp[:, 0]])
    idf = analyse(twin, twin, [f"p{k}" for k in range(cols + 1)])
    assert idf.rank == cols and len(idf.dependent) == 1, idf
    held = idf.dependent[0]
    assert {n for n, _ in idf.combinations[held].terms} == {"p0", f"p{cols}"}, idf.combinations
