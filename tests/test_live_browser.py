"""The live view in a real browser (headless Chromium): a replay of the bundled session is pushed into a
session shown by :class:`viz.live.LiveView`; the server's live page must show each point as it arrives
(cyan where the camera projects it, nothing yet where the next points will come) and its panel must
say how many points there are and the last one's coordinates."""
from __future__ import annotations

import html
import re

import numpy as np
import pytest
from test_viz_server import no_server_left  # noqa: F401  (checks that no server is left)

from arm_model.live import SampleLayout, Session
from conftest import ROOT
from viz import Camera, colour_mask, load_png
from viz.browser import screenshot_and_dom
from viz.live import LIVE_POINTS_RGB, LiveView

pytestmark = pytest.mark.browser

SAMPLES = ROOT / "examples" / "live" / "samples.csv"
PLAN = ROOT / "examples" / "live" / "plan.toml"
W_PX, H_PX = 800, 600


def stream():
    lines = SAMPLES.read_text().splitlines()
    layout = SampleLayout(lines[0].split(","), 7, str(SAMPLES))
    return layout, [(no, text, layout.parse(text, no)) for no, text in enumerate(lines[1:], start=2)]


def push_until(session, samples, start: int, points: int) -> int:
    """Push samples from ``start`` until the session has ``points`` points; the next index."""
    k = start
    while session.counts["points"] < points:
        no, text, s = samples[k]
        session.push_sample(s, text, no)
        k += 1
    return k


def cyan_near(img, xy, radius: int = 4) -> bool:
    mask = colour_mask(img, [c / 255 for c in ((LIVE_POINTS_RGB >> 16) & 255, (LIVE_POINTS_RGB >> 8) & 255,
                                               LIVE_POINTS_RGB & 255)], hue_tol_deg=12, min_saturation=0.6,
                       min_value=0.6)
    x, y = int(round(xy[0])), int(round(xy[1]))
    return bool(mask[max(y - radius, 0):y + radius + 1, max(x - radius, 0):x + radius + 1].any())


def panel(dom: str) -> str:
    m = re.search(r'<pre id="aacmm-panel"[^>]*>(.*?)</pre>', dom, re.S)
    assert m, "the live page has no panel"
    return html.unescape(m.group(1))


def shot(url, png):
    """A screenshot and the DOM of the live page. Chromium stalled once past its 90 s timeout on a fresh clone
    (2 workers, 2026-11-27, the second of this test's two screenshots; not reproduced in five runs under an
    artificial load): a stall is given 45 s and one more try, so that it costs CI time, not a false failure.
    What the page shows is checked as strictly either way."""
    from viz.errors import ViewerError
    for attempt in (1, 2):
        try:
            return screenshot_and_dom(url, png, width=W_PX, height=H_PX, budget_ms=2500, timeout=45.0)
        except ViewerError as e:
            if attempt == 2 or "did not render" not in str(e):
                raise
    raise AssertionError("unreachable")


def test_the_live_page_shows_the_points_as_they_arrive(tmp_path, nominal):
    from arm_model.live import read_plan
    layout, samples = stream()
    plan = read_plan(PLAN)
    # the points of the whole replay, to place the camera and know where the next ones will be
    first = Session(nominal, plan=plan, layout=layout)
    push_until(first, samples, 0, 19)
    pts = np.array([p.corrected for p in first.points])
    camera = Camera.framing(pts, fill=0.7)
    session = Session(nominal, plan=plan, layout=layout)
    with LiveView(session, camera=camera) as view:
        k = push_until(session, samples, 0, 9)          # the ring (8 points) and the plane's first
        view.update(force=True)
        png, dom = shot(view.url, tmp_path / "nine.png")
        img = load_png(png)
        xy = camera.project(pts, W_PX, H_PX)
        shown = [cyan_near(img, p) for p in xy]
        assert all(shown[:9]), shown
        far = [j for j in range(9, 19) if np.min(np.linalg.norm(xy[:9] - xy[j], axis=1)) > 12]
        assert far and not any(shown[j] for j in far), (far, shown)
        text = panel(dom)
        assert "points 9 " in text and "point 9 (table)" in text
        x = session.points[-1].corrected * 1e3
        assert f"({x[0]:.4f}, {x[1]:.4f}, {x[2]:.4f}) mm" in text
        assert "over-force 1" in text and "plane 'table' (1 pt)" in text and "next: table (4 more)" in text
        push_until(session, samples, k, 19)
        view.update(force=True)
        png, dom = shot(view.url, tmp_path / "all.png")
        img = load_png(png)
        # every point, but those behind the probe that now stands on the last seat
        ball = camera.project([session.points[-1].corrected], W_PX, H_PX)[0]
        seen = [cyan_near(img, p) for p, d in zip(xy, np.linalg.norm(xy - ball, axis=1), strict=True) if d > 15]
        assert len(seen) >= 16 and all(seen)
        text = panel(dom)
        assert "points 19 " in text and "point 19 (plate-B)" in text and "seat 'plate-B' (3 pt)" in text
