"""The viewer in a real browser: headless Chromium (Debian's ``chromium``; ``make test`` installs it)
renders the static page and the live server's page; the screenshot must show the arm's orange where
the camera model puts the arm's links, and a page without the arm must fail the same check.

The camera model itself is checked first against Chromium with coloured markers at known points.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from test_viz_server import no_server_left  # noqa: F401  (checks that no server is left)

from arm_model import PinocchioArm
from arm_model.urdf import ARM_RGBA
from viz import Camera, View, arm_mask, colour_mask, load_png, screenshot

pytestmark = pytest.mark.browser

W_PX, H_PX = 800, 600
CAMERA = Camera(position=(0.6, -1.5, 0.9), target=(-0.25, 0.0, 0.35))
POSE_A = np.radians([0, 30, 0, 60, 0, 45, 0])
POSE_B = np.radians([-70, -35, 20, 95, 0, -40, 0])
FORCE = np.array([8.0, 0.0, 3.0])


def render(page, tmp_path, name, budget_ms=5000) -> np.ndarray:
    png = screenshot(page, tmp_path / f"{name}.png", width=W_PX, height=H_PX, budget_ms=budget_ms)
    return load_png(png)


def link_segments(desc, q, wrench=None) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """(end, end, radius) [m] of every orange link cylinder at the pose, from the URDF (independently
    of the viewer's scene code)."""
    import pinocchio as pin

    arm = PinocchioArm(desc)
    geom = pin.buildGeomFromUrdfString(arm.model, arm.urdf, pin.GeometryType.VISUAL)
    gdata = geom.createData()
    x = arm.full_q(q, None if wrench is None else arm.elastic_q(q, wrench))
    pin.forwardKinematics(arm.model, arm.data, x)
    pin.updateGeometryPlacements(arm.model, arm.data, geom, gdata)
    out = []
    for k, g in enumerate(geom.geometryObjects):
        if np.allclose(g.meshColor, ARM_RGBA, atol=1e-6):
            m = gdata.oMg[k]
            h = g.geometry.halfLength
            out.append((m.act(np.array([0, 0, -h])), m.act(np.array([0, 0, h])), g.geometry.radius))
    assert out, "the URDF has no orange link visuals"
    return out


def arm_check(img: np.ndarray, segments, camera: Camera) -> dict:
    """Where the orange pixels are against where the camera puts the link cylinders."""
    mask = arm_mask(img)
    ys, xs = np.nonzero(mask)
    pix = np.column_stack([xs, ys]).astype(float) + 0.5
    f_px = (H_PX / 2) / math.tan(math.radians(camera.fov_deg) / 2)
    fwd = np.subtract(camera.target, camera.position)
    fwd /= np.linalg.norm(fwd)
    dist = np.full(len(pix), np.inf)
    mid_hits = []
    for p0, p1, radius in segments:
        a, b = camera.project([p0, p1], W_PX, H_PX)
        depth = (((p0 + p1) / 2) - np.asarray(camera.position)) @ fwd
        band = radius * f_px / depth + 4.0
        ab = b - a
        t = np.clip(((pix - a) @ ab) / max(ab @ ab, 1e-12), 0, 1)
        dist = np.minimum(dist, np.linalg.norm(pix - (a + t[:, None] * ab), axis=1) - band)
        mid = (a + b) / 2
        near = mask[max(int(mid[1]) - 4, 0):int(mid[1]) + 5, max(int(mid[0]) - 4, 0):int(mid[0]) + 5]
        mid_hits.append(bool(near.any()) if np.linalg.norm(ab) >= 20 else True)
    return {"orange": int(mask.sum()), "inside": float(np.mean(dist <= 0)) if len(pix) else 0.0,
            "midpoints": mid_hits}


def arm_drawn(check: dict) -> bool:
    return check["orange"] >= 1500 and check["inside"] >= 0.95 and all(check["midpoints"])


@pytest.fixture(scope="module")
def pages(tmp_path_factory, nominal):
    """Static pages: the arm at pose A, at pose B, pose A with the arm hidden, an animation A -> B."""
    d = tmp_path_factory.mktemp("pages")
    with View(nominal) as view:
        view.show_pose(POSE_A, FORCE)
        view.frame(CAMERA)
        view.write_html(d / "a.html")
        view.show_pose(POSE_B, FORCE)
        view.write_html(d / "b.html")
        view.show_pose(POSE_A, FORCE)
        view.server.visualizer["aacmm/arm"].set_property("visible", False)
        view.write_html(d / "hidden.html")
    with View(nominal) as view:
        view.animate(np.array([POSE_A, POSE_B]), np.array([FORCE, FORCE]), fps=2.0, repetitions=1)
        view.frame(CAMERA)
        view.write_html(d / "anim.html")
    return d


def test_camera_model_matches_chromium(tmp_path):
    """Coloured spheres at known points land where Camera.project says, within 2 px."""
    import meshcat.geometry as mg

    markers = {(1.0, 0.0, 0.0): [0.3, 0.2, 0.6], (0.0, 1.0, 0.0): [-0.6, 0.3, 0.1],
               (0.0, 0.0, 1.0): [-0.2, -0.1, 0.9], (1.0, 0.0, 1.0): [0.1, -0.4, 0.0]}
    with View() as view:
        vis = view.server.visualizer
        for k, (rgb, p) in enumerate(markers.items()):
            colour = int(rgb[0] * 255) << 16 | int(rgb[1] * 255) << 8 | int(rgb[2] * 255)
            vis[f"aacmm/marker{k}"].set_object(mg.Sphere(0.03), mg.MeshBasicMaterial(color=colour))
            t = np.eye(4)
            t[:3, 3] = p
            vis[f"aacmm/marker{k}"].set_transform(t)
        vis["/Grid"].set_property("visible", False)
        vis["aacmm/base frame"].set_property("visible", False)
        view.frame(CAMERA)
        page = tmp_path / "markers.html"
        view.write_html(page)
    img = render(page, tmp_path, "markers")
    for rgb, p in markers.items():
        mask = colour_mask(img, rgb, hue_tol_deg=4, min_saturation=0.9, min_value=0.9)
        ys, xs = np.nonzero(mask)
        assert len(xs) > 20, f"marker {rgb} not drawn"
        seen = np.array([xs.mean() + 0.5, ys.mean() + 0.5])
        expected = CAMERA.project([p], W_PX, H_PX)[0]
        assert np.linalg.norm(seen - expected) < 2.0, (rgb, seen, expected)


def test_arm_is_drawn_where_it_must_be(pages, tmp_path, nominal):
    img_a = render(pages / "a.html", tmp_path, "a")
    check_a = arm_check(img_a, link_segments(nominal, POSE_A, FORCE), CAMERA)
    assert arm_drawn(check_a), check_a
    # the check tells poses apart: pose A's screenshot does not show pose B
    check_ab = arm_check(img_a, link_segments(nominal, POSE_B, FORCE), CAMERA)
    assert not arm_drawn(check_ab), check_ab
    img_b = render(pages / "b.html", tmp_path, "b")
    assert arm_drawn(arm_check(img_b, link_segments(nominal, POSE_B, FORCE), CAMERA))


def test_a_page_without_the_arm_fails(pages, tmp_path, nominal):
    img = render(pages / "hidden.html", tmp_path, "hidden")
    check = arm_check(img, link_segments(nominal, POSE_A, FORCE), CAMERA)
    assert check["orange"] < 50 and not arm_drawn(check), check
    blank = tmp_path / "blank.html"
    blank.write_text("<html><body style='background:#87cefa'></body></html>")
    assert not arm_drawn(arm_check(render(blank, tmp_path, "blank", 500), link_segments(nominal, POSE_A), CAMERA))


def test_the_animation_plays_in_the_static_page(pages, tmp_path, nominal):
    """Two poses at 2 per second, played once: after 5 s of page time the arm rests at the last pose."""
    img = render(pages / "anim.html", tmp_path, "anim", budget_ms=5000)
    assert arm_drawn(arm_check(img, link_segments(nominal, POSE_B, FORCE), CAMERA))
    assert not arm_drawn(arm_check(img, link_segments(nominal, POSE_A, FORCE), CAMERA))


def test_live_server_page(tmp_path, nominal):
    """The server's own page (http://127.0.0.1:PORT/static/) gets the scene over its websocket."""
    with View(nominal) as view:
        view.show_pose(POSE_A, FORCE)
        view.frame(CAMERA)
        t0 = time.monotonic()
        img = render(view.url, tmp_path, "live")
        assert view.server.running
    assert time.monotonic() - t0 < 60
    assert arm_drawn(arm_check(img, link_segments(nominal, POSE_A, FORCE), CAMERA))
