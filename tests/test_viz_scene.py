"""Viewer, pure parts (no server, no browser): camera model, arrows, artefact placement, the residuals
reader, the page legend, the colour test and the browser lookup."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import InputError
from arm_model.io import parse_artefacts
from arm_model.urdf import ARM_RGBA, BALL_RGBA
from conftest import assert_close
from viz import Camera, ViewerError, colour_mask, find_chromium, page_with_legend, place_features
from viz.residuals import parse_residuals, residual_origins
from viz.scene import arrow_parts, coverage_factor, ellipsoid_mesh, rotation_y_to

# --- camera --------------------------------------------------------------------------------------

def test_camera_projection_by_hand():
    # camera on +x at 2 m looking at the origin: +y is to the right, +z up, vertical fov 75 deg
    cam = Camera((2.0, 0.0, 0.0))
    t = math.tan(math.radians(37.5))
    px = cam.project([[0, 0, 0], [0, 0.5, 0], [0, 0, 0.5], [3.0, 0, 0]], 800, 600)
    assert_close(px[0], [400, 300], 1e-9)
    assert_close(px[1], [400 + 0.5 / (2 * t * 800 / 600) * 400, 300], 1e-9)
    assert_close(px[2], [400, 300 - 0.5 / (2 * t) * 300], 1e-9)
    assert np.all(np.isnan(px[3]))    # behind the camera


def test_camera_target_shifts_everything():
    a = Camera((2.0, -1.0, 1.0))
    shift = np.array([0.3, -0.2, 0.5])
    b = Camera(tuple(np.add(a.position, shift)), tuple(shift))
    p = np.random.default_rng(0).normal(size=(20, 3)) * 0.3
    assert_close(b.project(p + shift, 800, 600), a.project(p, 800, 600), 1e-9)
    # meshcat's camera node is y-up and relative to the target
    assert b.meshcat_position() == pytest.approx([2.0, 1.0, 1.0])


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-1.5, 1.5)] * 3), min_size=1, max_size=30))
def test_framing_sees_every_point(points):
    p = np.array(points)
    cam = Camera.framing(p, fill=0.8, pad=0.0)
    px = cam.project(p, 800, 600)
    assert np.all(np.isfinite(px))
    assert np.all(np.abs(px / [400, 300] - 1) <= 0.8 + 1e-9)


def test_framing_rejects_a_vertical_view():
    with pytest.raises(ValueError, match="vertical"):
        Camera.framing(np.zeros((1, 3)), direction=(0, 0, 1))


# --- arrows --------------------------------------------------------------------------------------

@pytest.mark.parametrize("length", [0.5, 0.1, 0.035, 0.01, 0.0])
def test_arrow_parts_span_the_length(length):
    parts = arrow_parts(length)
    (shaft_pos, shaft_scale), (head_pos, head_scale) = parts["shaft"], parts["head"]
    tip = head_pos[1] + head_scale[1] / 2
    assert tip == pytest.approx(max(length, 2e-9), abs=1e-9)
    assert shaft_pos[1] - shaft_scale[1] / 2 == pytest.approx(0.0, abs=1e-15)   # starts at the root
    assert head_scale[1] <= 0.5 * length + 1e-9                                   # the head never dominates


@given(st.tuples(*[st.floats(-1, 1)] * 3).filter(lambda v: np.linalg.norm(v) > 1e-6))
def test_rotation_puts_y_along_the_vector(v):
    r = rotation_y_to(np.array(v))
    assert_close(r.T @ r, np.eye(3), 1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    assert_close(r[:, 1], np.array(v) / np.linalg.norm(v), 1e-12)


# --- artefact placement ---------------------------------------------------------------------------

ARTEFACTS = parse_artefacts("""
[[feature]]
id = "ring"
kind = "ring"
diameter_mm = 174.996
[[feature]]
id = "sphere-A"
kind = "sphere"
diameter_mm = 25.0
[[feature]]
id = "sphere-B"
kind = "sphere"
diameter_mm = 25.0
[[feature]]
id = "table"
kind = "plane"
[[feature]]
id = "seat"
kind = "seat"
[[distance]]
between = ["sphere-A", "sphere-B"]
length_mm = 600.0
""", "artefacts.toml")


def _frame(axis):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    u = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    return a, u, np.cross(a, u)


def _ring_points(centre, axis, radius, heights, n=12):
    a, u, v = _frame(axis)
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.vstack([centre + h * a + radius * (np.outer(np.cos(ang + h), u) + np.outer(np.sin(ang + h), v))
                      for h in heights])


def _place(groups):
    meas = np.concatenate([[m] * len(p) for m, _, p in groups]).astype(object)
    feat = np.concatenate([[f] * len(p) for _, f, p in groups]).astype(object)
    return place_features(ARTEFACTS, meas, feat, np.vstack([p for _, _, p in groups]))


@pytest.mark.parametrize("heights", [(0.0,), (-0.006, 0.006)], ids=["one row", "two rows"])
def test_ring_placed_on_its_axis(heights):
    centre, axis, r = np.array([0.6, -0.2, 0.1]), np.array([0.2, 0.1, 1.0]), (0.174996 - 0.004) / 2
    placed, notes = _place([("m1", "ring", _ring_points(centre, axis, r, heights))])
    assert notes == [] and len(placed) == 1
    pl = placed[0]
    a = axis / np.linalg.norm(axis)
    assert_close(abs(pl.axis @ a), 1.0, 1e-9)
    assert_close(pl.centre, centre, 1e-9)
    assert pl.fitted_radius == pytest.approx(r, abs=1e-9)
    assert pl.radius == pytest.approx(0.174996 / 2, abs=1e-12)       # drawn with the certified size
    assert pl.size[0] == pytest.approx(heights[-1] - heights[0], abs=1e-9)


def test_spheres_plane_seat_and_notes():
    rng = np.random.default_rng(3)
    ca, cb = np.array([0.5, 0.3, 0.2]), np.array([-0.1, 0.5, 0.2])
    dirs = rng.normal(size=(9, 3))
    dirs[:, 2] = np.abs(dirs[:, 2])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    rb = (0.025 + 0.004) / 2
    n = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    _, u, v = _frame(n)
    plane = np.array([0.4, 0.0, 0.05]) + rng.uniform(-0.1, 0.1, (8, 1)) * u + rng.uniform(-0.1, 0.1, (8, 1)) * v
    seat = np.array([0.3, 0.3, 0.3]) + rng.normal(0, 1e-7, (5, 3))
    placed, notes = _place([("bar-1", "sphere-A", ca + rb * dirs), ("bar-1", "sphere-B", cb + rb * dirs),
                            ("flat", "table", plane), ("s", "seat", seat),
                            ("bar-2", "sphere-A", ca[None] + rb * dirs[:2]),          # too few
                            ("flat-2", "table", np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2.0]])),  # collinear
                            ("free", "", np.zeros((3, 3)))])
    got = {(p.measurement, p.feature): p for p in placed}
    assert set(got) == {("bar-1", "sphere-A"), ("bar-1", "sphere-B"), ("flat", "table"), ("s", "seat")}
    assert_close(got["bar-1", "sphere-A"].centre, ca, 1e-12)
    assert got["bar-1", "sphere-B"].fitted_radius == pytest.approx(rb, abs=1e-12)
    assert_close(abs(got["flat", "table"].axis @ n), 1.0, 1e-12)
    assert_close(got["s", "seat"].centre, seat.mean(axis=0), 1e-15)
    assert len(notes) == 2
    assert "sphere 'sphere-A' in measurement 'bar-2': 2 point(s), too few" in notes[0]
    assert "plane 'table' in measurement 'flat-2'" in notes[1] and "collinear" in notes[1]


# --- residuals reader -----------------------------------------------------------------------------

UNITS = {"mm": 1e-3, "um": 1e-6, "m": 1.0}


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(*[st.floats(-1e3, 1e3, allow_nan=False)] * 6), min_size=1, max_size=8),
       st.sampled_from(sorted(UNITS)), st.sampled_from(sorted(UNITS)), st.booleans())
def test_residuals_roundtrip_any_length_unit(rows, pu, ru, text_columns):
    head = [f"x_{pu}", f"y_{pu}", f"z_{pu}", f"rx_{ru}", f"ry_{ru}", f"rz_{ru}"]
    lines = [",".join((["measurement", "feature"] if text_columns else []) + head)]
    for k, r in enumerate(rows):
        lines.append(",".join(([f"m{k}", "ring"] if text_columns else []) + [repr(v) for v in r]))
    res = parse_residuals("\n".join(lines) + "\n", "res.csv")
    arr = np.array(rows)
    assert_close(res.points, arr[:, :3] * UNITS[pu], 1e-15, 1e-15)
    assert_close(res.vectors, arr[:, 3:] * UNITS[ru], 1e-15, 1e-15)
    assert res.lines.tolist() == list(range(2, len(rows) + 2))
    assert res.measurement.tolist() == ([f"m{k}" for k in range(len(rows))] if text_columns else [""] * len(rows))


def test_residuals_by_points_file_line(nominal):
    """The calibration's residuals.csv names points by line: vectors start at those ball centres; a
    line of another file (other measurement) is counted, not drawn."""
    from arm_model.io import parse_points

    pts = parse_points("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\n\n"
                       "ring-01,ring,0,30,0,60,0,45,0\nring-01,ring,10,30,0,60,0,45,0\n"
                       "bar-01,bar-A,20,30,0,60,0,45,0\n", "p.csv", 7)
    centres = np.arange(9.0).reshape(3, 3)
    res = parse_residuals("measurement,feature,kind,line,residual_um,dx_um,dy_um,dz_um,standardized\n"
                          "bar-01,bar-A,sphere,5,1,1,0,0,0.1\nring-01,ring,ring,3,2,0,2,0,0.2\n"
                          "nest-01,nest-01,reference,4,3,0,0,3,0.3\n", "res.csv")
    assert res.points is None and res.point_lines.tolist() == [5, 3, 4]
    origins, vectors, skipped = residual_origins(res, pts, centres)
    assert_close(origins, centres[[2, 0]], 0.0)
    assert_close(vectors, [[1e-6, 0, 0], [0, 2e-6, 0]], 1e-18)
    assert skipped == 1


@pytest.mark.parametrize("second", ["./sim/points.csv", ""])
def test_a_point_given_twice_under_two_spellings_of_its_file_is_refused(second, tmp_path, monkeypatch):
    """The reader refuses a (file, line) given twice as text; the same point named by 'sim/points.csv' and
    './sim/points.csv' (or with the file left empty on one row) passed it and was drawn twice (110 vectors for 109
    points): refused where the rows are matched to the points shown, naming the second row's line."""
    from arm_model.io import parse_points
    text = ("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\n"
            "seat-01,seat,0,30,0,60,0,45,0\nseat-01,seat,10,30,0,60,0,45,0\n")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sim").mkdir()
    (tmp_path / "sim" / "points.csv").write_text(text)
    pts = parse_points(text, "sim/points.csv", 7)
    head = "measurement,feature,kind,file,line,dx_um,dy_um,dz_um\n"
    res = parse_residuals(head + "seat-01,seat,seat,sim/points.csv,2,1,0,0\nseat-01,seat,seat,sim/points.csv,3,0,1,0\n"
                          f"seat-01,seat,seat,{second},2,0,0,1\n", "res.csv")
    with pytest.raises(InputError, match="point line 2 of sim/points.csv .* given twice") as e:
        residual_origins(res, pts, np.arange(6.0).reshape(2, 3))
    assert e.value.line == 4 and e.value.column == "line"


def test_residuals_name_a_point_by_file_and_line(tmp_path):
    """A point is its file and line: a seat of the points file and one of the reference file on the same line are
    two points (read, not refused as one given twice); the one of another file is counted, not drawn; the same
    file and line twice is still refused. The file named as written, by a path to the same file, or, once moved,
    by its name when no other file has that name (:func:`viz.residuals.shown_file`)."""
    from arm_model.io import parse_points
    from viz.residuals import shown_file

    pts = parse_points("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\n"
                       "seat-01,seat,0,30,0,60,0,45,0\nseat-01,seat,10,30,0,60,0,45,0\n", "sim/points.csv", 7)
    centres = np.arange(6.0).reshape(2, 3)
    head = "measurement,feature,kind,file,line,dx_um,dy_um,dz_um\n"
    text = head + ("seat-01,seat,seat,sim/points.csv,2,1,0,0\nseat-01,seat,seat,sim/points.csv,3,0,1,0\n"
                   "seat-01,seat,seat,sim/points-ref.csv,2,0,0,1\n")
    res = parse_residuals(text, "res.csv")
    assert res.file.tolist() == ["sim/points.csv", "sim/points.csv", "sim/points-ref.csv"]
    origins, vectors, skipped = residual_origins(res, pts, centres)
    assert_close(origins, centres, 0.0)
    assert_close(vectors, [[1e-6, 0, 0], [0, 1e-6, 0]], 1e-18)
    assert skipped == 1
    with pytest.raises(InputError, match="point line 2 of sim/points.csv .* given twice") as e:
        parse_residuals(text + "seat-01,seat,seat,sim/points.csv,2,1,1,1\n", "res.csv")
    assert e.value.line == 5 and e.value.column == "line"
    files = ["sim/points.csv", "sim/points-ref.csv", ""]
    assert shown_file(files, "sim/points.csv") == {"sim/points.csv"}
    assert shown_file(files, "moved/points.csv") == {"sim/points.csv"}          # moved: by its name
    assert shown_file(files + ["other/points.csv"], "moved/points.csv") == set()  # two of that name: neither
    real = tmp_path / "a" / "points.csv"
    real.parent.mkdir()
    real.write_text("x")
    assert shown_file([str(real), str(tmp_path / "b" / "points.csv")], tmp_path / "a" / ".." / "a" / "points.csv") \
        == {str(real)}                                                           # the same file on disk


GOOD = "x_mm,y_mm,z_mm,rx_um,ry_um,rz_um\n1,2,3,0.1,0.2,0.3\n"


@pytest.mark.parametrize("text, where", [
    ("", "res.csv, line 1"),
    ("x_mm,y_mm,z_mm,rx_um,ry_um,rz_um\n", "res.csv, line 2"),
    ("x_mm,y_mm,z_mm,rx_um,ry_um\n1,2,3,4,5\n", "missing residual columns: expected rx, ry, rz"),
    ("rx_um,ry_um,rz_um\n1,2,3\n", "or 'line' (its line in the points file)"),
    ("line,dx_um,dy_um,dz_um\n2.5,1,2,3\n", "res.csv, line 2, column 'line': expected a line number"),
    ("x_mm,y_mm,z_mm,rx_um,ry_um,rz_deg\n1,2,3,4,5,6\n", "column 'rz_deg'"),
    (GOOD + "1,2,3,0.1,oops,0.3\n", "res.csv, line 3, column 'ry_um'"),
    (GOOD + "1,2,3,0.1,inf,0.3\n", "res.csv, line 3, column 'ry_um'"),
    (GOOD + "1,2,3\n", "res.csv, line 3"),
    ("x_mm,y_mm,z_mm,rx_um,ry_um,rz_um,norm\n1,2,3,4,5,6,7\n", "res.csv, line 1, column 'norm': unknown column"),
    # unknown columns are errors whatever they hold (text, a unit, no data rows), naming line 1
    ("x_mm,y_mm,z_mm,rx_um,ry_um,rz_um,note\n1,2,3,4,5,6,hello\n", "res.csv, line 1, column 'note': unknown column"),
    ("x_mm,y_mm,z_mm,rx_um,ry_um,rz_um,norm_um\n1,2,3,4,5,6,7\n", "res.csv, line 1, column 'norm_um'"),
    ("x_mm,y_mm,z_mm,rx_um,ry_um,rz_um,measurment\n", "did you mean 'measurement'?"),
    ("x_mm,x_m,y_mm,z_mm,rx_um,ry_um,rz_um\n1,1,2,3,4,5,6\n", "column 'x_m': 'x_m' and 'x_mm' give the same"),
    ("line,dx_um,dy_um,dz_um,residual_deg\n2,1,2,3,4\n", "column 'residual_deg'"),
    ("x_mm,x_mm,y_mm,z_mm,rx_um,ry_um,rz_um\n1,1,2,3,4,5,6\n", "column 'x_mm'"),
])
def test_residuals_errors_name_file_line_column(text, where):
    with pytest.raises(InputError) as exc:
        parse_residuals(text, "res.csv")
    assert where in str(exc.value), str(exc.value)


# --- page, colours, browser lookup ------------------------------------------------------------------

def test_page_with_legend_escapes_and_refuses_unknown_pages():
    page = "<html><head><title>MeshCat</title></head><body><div></div></body></html>"
    out = page_with_legend(page, "arm <7>", ["drawn x1000", "a & b"])
    assert "<title>arm &lt;7&gt;</title>" in out and "drawn x1000" in out and "a &amp; b" in out
    assert out.count('id="aacmm-legend"') == 1
    with pytest.raises(ViewerError, match="meshcat version"):
        page_with_legend("<html><body></body></html>", "t", [])


def test_colour_mask_finds_shaded_orange_only():
    arm = np.array(ARM_RGBA[:3])
    shades = [arm * k for k in (1.0, 0.8, 0.55)] + [np.clip(arm * 1.1, 0, 1)]
    others = [np.array(BALL_RGBA[:3]), [0.53, 0.81, 0.98], [0.1, 0.1, 0.44], [0.25, 0.25, 0.28], [0.5, 0.5, 0.5],
              [0.09, 0.75, 0.09], [0.88, 0.13, 0.88], [0.69, 0.77, 0.87], [1, 1, 1], [0, 0, 0]]
    img = (np.array([shades + others]) * 255).round().astype(np.uint8)
    assert colour_mask(img, ARM_RGBA).tolist() == [[True] * len(shades) + [False] * len(others)]


def test_find_chromium_errors_say_what_to_do(monkeypatch, tmp_path):
    with pytest.raises(ViewerError, match="no browser at '/nonexistent/chromium'"):
        find_chromium("/nonexistent/chromium")
    monkeypatch.setenv("PATH", str(tmp_path))
    with pytest.raises(ViewerError, match="install Debian's 'chromium' package"):
        find_chromium()


# --- uncertainty ellipsoids -----------------------------------------------------------------------

def test_ellipsoid_mesh_vertices_lie_on_the_95_percent_ellipsoid():
    # k^2 of a 95 % region of a 3D normal: 7.8147 (chi-square table, 3 dof); every vertex of point i at
    # Mahalanobis distance scale * k from its centre (checked with a solve, not the eigen-decomposition)
    assert coverage_factor(0.95) == pytest.approx(math.sqrt(7.8147), rel=1e-4)
    rng = np.random.default_rng(2)
    m = rng.standard_normal((5, 3, 3)) * 2e-6
    cov = np.einsum("nij,nkj->nik", m, m)
    cov[0] = np.diag([1e-12, 4e-12, 9e-12])                 # 1, 2, 3 um along x, y, z
    c = rng.uniform(-1, 1, (5, 3))
    verts, faces, k = ellipsoid_mesh(c, cov, 2000.0)
    assert k == pytest.approx(math.sqrt(7.8147), rel=1e-4)
    v = verts.reshape(5, -1, 3)
    assert v.shape[1] == 42 and faces.shape == (5 * 80, 3)
    assert faces[80:160].min() == 42 and faces.max() == 5 * 42 - 1   # each point owns its vertices
    d = v - c[:, None, :]
    m2 = np.einsum("nvi,nvi->nv", d, np.linalg.solve(cov, d.transpose(0, 2, 1)).transpose(0, 2, 1))
    assert_close(np.sqrt(m2), 2000.0 * k, 1e-6)
    # the diagonal one spans +-2000 k (1, 2, 3) um along the axes at most
    assert np.all(np.abs(d[0]).max(axis=0) <= 2000 * k * np.array([1e-6, 2e-6, 3e-6]) * (1 + 1e-12))
    with pytest.raises(ValueError, match="level"):
        ellipsoid_mesh(c, cov, 1.0, level=1.5)


def test_transform_frames_are_meshcats_own():
    """The set_transform frames packed by the live view are byte for byte those meshcat's Visualizer
    sends (umsgpack of its command)."""
    import umsgpack
    from meshcat.commands import SetTransform
    from meshcat.path import Path as MPath

    from viz.scene import transform_frames
    rng = np.random.default_rng(0)
    for name in ("a", "aacmm/arm/link_3_0", "x" * 40, "long/" * 60):
        path = MPath(("meshcat",) + tuple(name.split("/")))
        m = rng.normal(size=(4, 4))
        cmd = SetTransform(m, path).lower()
        assert transform_frames(path.lower(), m) == [b"set_transform", path.lower().encode(), umsgpack.packb(cmd)]
