"""Well-formed but degenerate data: every value passes its reader, and only the computation can find the data
insufficient. The rule (docs/guarantees.md §4): exit 0 with what the data cannot see held or prior-dominated and
named, or exit 2/4 with one message; never a traceback, a value of rounding size written as if measured, or a
model file its reader refuses. Each test is one case the audit found wrong, named after what it checks."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz"
SEAT = '\n[[feature]]\nid = "seat"\nkind = "seat"\n'


def _run(argv, capsys):
    rc = exit_status([str(a) for a in argv])
    got = capsys.readouterr()
    return rc, got.err, got.out


def _case(tmp_path, rings: int, seat_rows: int):
    """The first ``rings`` measurements of the example ring campaign and ``seat_rows`` copies of its first pose
    as a seat (one pose repeated: an operator who did not articulate)."""
    lines = (RING / "points.csv").read_text().splitlines()
    ids = tuple(f"ring-{k:02d}," for k in range(1, rings + 1))
    rows = [r for r in lines[1:] if ids and r.startswith(ids)]
    seat = "seat-1,seat," + lines[1].split(",", 2)[2]
    pts = tmp_path / "points.csv"
    pts.write_text("\n".join([lines[0], *rows, *[seat] * seat_rows]) + "\n")
    art = tmp_path / "artefacts.toml"
    art.write_text((RING / "artefacts.toml").read_text() + SEAT)
    return pts, art


def test_a_calibration_on_one_pose_repeated_is_a_numerical_failure(tmp_path, capsys):
    """20 rows of one pose on a seat (a seat needs one point, so the reader takes it): the nuisance centre absorbs
    every parameter. The rank test kept one parameter whose reduced column was rounding, scaled to unit size
    (``s > rank_tol * s_max`` with ``s_max`` itself rounding), and the noise estimate of exactly zero residuals
    then failed in ``math.log(0)``: exit 3. Now no parameter is identifiable, and that is exit 4 naming it."""
    pts, art = _case(tmp_path, 0, 20)
    out = tmp_path / "o"
    rc, err, said = _run(["calibrate", pts, art, "--arm", "aacmm7", "--no-plots", "-o", out], capsys)
    assert rc == 4 and "the data determine none of the 31 parameters" in err, err
    assert "internal error" not in err and not out.exists()


def test_a_feature_at_one_pose_repeated_gives_no_noise_estimate(tmp_path, capsys):
    """Two ring measurements and a seat at one pose repeated 10 times: the seat's residuals are exactly zero, and
    its noise was estimated as 7e-11 um and weighted 1e22 times the ring's (written in summary.json as the seat's
    noise). A residual below the smallest uncertainty one may state (1 pm) is rounding: the seat keeps its
    stated (default) uncertainty, said as such."""
    pts, art = _case(tmp_path, 2, 10)
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
