"""The live view of a measurement session (:class:`arm_model.live.Session`) in the headless meshcat server.

At display rate (``fps``, default 10 frames a second, whatever the sample rate) :meth:`LiveView.update`
draws the arm at the latest sample (the probe deflected by its wrench), the force arrow at the ball
(along the force the part exerts on the ball, 10 mm/N long, coloured by its magnitude against the probe's
limit: green below half of it, yellow below 80 %, orange below 100 %, red beyond), each new point as it
comes (cyan dots), the fitted features (light blue, with their measured size, placed by the fit) and a
text panel: the force, the deflection, the last point and its uncertainty, the current feature's fit, the
counts of dropped, late and bad samples, the last event.

The page with the panel is the server's ``/live/`` (:data:`viz.bridge.LIVE_PAGE`); meshcat's own page
(``/static/``) shows the same scene without it. :meth:`LiveView.write_html` writes the scene as one
self-contained page, the panel's last text as its legend.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from arm_model.live import Sample, Session

from .bridge import PANEL_NODE
from .placement import Placement
from .scene import (
    Camera,
    arrow_parts,
    rotation_y_to,
    send_transform,
    transform_matrix,
)
from .view import View, page_with_legend

__all__ = ["LiveView", "LIVE_POINTS_RGB", "FORCE_COLOURS", "FORCE_MM_PER_N", "DEFAULT_FPS", "panel_lines"]

#: the colour of the live points (cyan)
LIVE_POINTS_RGB = 0x00D8FF
#: (fraction of the probe's force limit below which, colour) of the force arrow; beyond the limit: red
FORCE_COLOURS = ((0.5, 0x20C020), (0.8, 0xE8D020), (1.0, 0xFF8C00), (math.inf, 0xFF1010))
#: force arrow length per newton [mm/N]
FORCE_MM_PER_N = 10.0
#: display frames a second
DEFAULT_FPS = 10.0
_LIVE = "aacmm/live"
#: the arm is drawn again when a joint moved more than this [rad] (0.017 deg) since it was last drawn
MOVE_RAD = 3e-4
#: the force arrow is drawn again when its base or tip moved more than this [m]
MOVE_M = 1e-3


class _PanelCommand:
    """A meshcat ``set_object`` of an empty object whose user data carries the panel's lines: the live
    page shows them in its panel; any other page draws nothing."""

    def __init__(self, path: str, lines: list[str]):
        self.path, self.lines = path, lines

    def lower(self) -> dict:
        obj = {"metadata": {"version": 4.5, "type": "Object"}, "geometries": [], "materials": [],
               "object": {"uuid": "aacmm-live-panel", "type": "Object3D", "userData": {"lines": self.lines},
                          "matrix": [1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 1.0]}}
        return {"type": "set_object", "object": obj, "path": self.path.lower()}


def panel_lines(session: Session, deflection: float | None = None) -> list[str]:
    """The text panel of a session [mm, um, N]: time and samples, force, deflection, the last point and
    its uncertainty, the current feature's fit, the counts, the last event."""
    s, c = session.latest, session.counts
    lines = [f"aacmm live: {session.desc.name}, {session.measurement}"
             + ("" if s is None else f"   t = {s.t:.3f} s") + f"   samples {c['samples']}"]
    m = session.latest_magnitude
    lines.append(f"|F| {m:6.2f} N ({100 * m / session.max_force:3.0f} % of {session.max_force:g} N)"
                 + ("" if deflection is None else f"   deflection {deflection * 1e6:6.1f} um")
                 + ("   IN CONTACT" if session.in_contact else ""))
    if session.points:
        p = session.points[-1]
        x, u = p.corrected * 1e3, p.u * 1e6
        lines.append(f"point {p.index}{' (' + p.feature + ')' if p.feature else ''}: ({x[0]:.4f}, {x[1]:.4f}, "
                     f"{x[2]:.4f}) mm   u ({u[0]:.1f}, {u[1]:.1f}, {u[2]:.1f}) um   |F| {p.contact.peak_force:.2f} N"
                     + ("   OVER-FORCE" if p.over_force else ""))
        fit = session.fits.get(p.feature)
        if fit is not None:
            lines.append(fit.describe())
    else:
        lines.append("points 0")
    nxt = session.tracker.current
    if nxt:
        left = session.tracker.remaining
        lines.append(f"next: {nxt}" + ("" if left is None else f" ({left} more)"))
    jumps = "".join(f"{what} {c[k]}   " for k, what in (("time_jumps", "bad times"), ("clock_jumps", "clock jumps"))
                    if c[k])
    lines.append(f"points {c['points']}   dropped {c['dropped']}   late {c['late']}   bad lines {c['bad_lines']}   "
                 f"{jumps}over-force {c['over_force']}   joint limits {c['joint_limit']}")
    if session.events:
        lines.append(f"last event: {session.events[-1]}"[:160])
    return lines


class LiveView:
    """A meshcat server showing a live session (see the module doc).

    Args:
        session: the :class:`arm_model.live.Session` to show.
        port: the server's web port (None: the first free one from 7000).
        fps: display frames a second.
        camera: a :class:`viz.Camera` to keep (None: framing the arm at its first pose, then the points).
    """

    def __init__(self, session: Session, *, port: int | None = None, fps: float = DEFAULT_FPS,
                 camera: Camera | None = None):
        self.session = session
        self.view = View(session.desc, port=port, title=f"{session.desc.name}: aacmm live")
        self.scene = self.view.scene
        self.vis = self.view.server.visualizer
        self.period = 1.0 / float(fps)
        self._next = 0.0
        self._shown_points = 0
        self._fits_drawn = 0        # the number of points when the features were last drawn
        self._colour = None
        self._q = None              # the angles the arm was last drawn at
        self._arrow = None          # the force arrow last drawn
        self._arrow_paths = None
        self._framed = camera is not None     # a given camera stays; else the view frames the arm, then the points
        self._camera_given = camera is not None
        if camera is not None:
            self.view.frame(camera)
        self.lines: list[str] = ["waiting for the first sample ..."]
        self.frames = 0
        self._panel()

    @property
    def url(self) -> str:
        """The live page (with the panel)."""
        return self.view.url.rsplit("/static/", 1)[0] + "/live/"

    def update(self, now: float | None = None, force: bool = False) -> bool:
        """Draw the session when a frame is due (``force``: now); True when it drew."""
        now = time.monotonic() if now is None else now
        if not force and now < self._next:
            return False
        self._next = now + self.period
        s = self.session.latest
        deflection = None
        if s is not None:
            deflection = self._pose(s)
        if len(self.session.points) > self._shown_points:
            self._points()
        if self.session.fits and self._fits_drawn != len(self.session.points):
            self._features()
        self.lines = panel_lines(self.session, deflection)
        self._panel()
        self.frames += 1
        return True

    def _pose(self, s: Sample) -> float:
        """The arm and the force arrow at sample ``s``; returns the deflection [m]."""
        q = np.asarray(s.q)
        moved = self._q is None or float(np.max(np.abs(q - self._q))) > MOVE_RAD
        info = self.scene.move(q, None if s.wrench is None else np.asarray(s.wrench), redraw=moved,
                               extent=not self._framed)
        if moved:
            self._q = q
        if not self._framed:
            self.view.frame()
            self._framed = True
        self._force_arrow(s, info.corrected)
        return float(np.linalg.norm(info.deflection))

    def _force_arrow(self, s: Sample, ball: np.ndarray) -> None:
        import meshcat.geometry as mg
        f = np.zeros(3) if s.wrench is None else np.asarray(s.wrench[:3])
        m = float(np.linalg.norm(f))
        colour = next(c for limit, c in FORCE_COLOURS if m < limit * self.session.max_force)
        node = f"{_LIVE}/force"
        if colour != self._colour:
            mat = mg.MeshLambertMaterial(color=colour)
            self.vis[f"{node}/shaft"].set_object(mg.Cylinder(1.0, 0.004), mat)
            self.vis[f"{node}/head"].set_object(mg.Cylinder(1.0, radiusTop=0.0, radiusBottom=0.010), mat)
            self._colour = colour
        arm = self.scene.arm               # its frames are those of the pose just computed (move)
        rot = arm.data.oMf[arm.ball_id].rotation
        vec = rot @ f * FORCE_MM_PER_N * 1e-3
        key = np.r_[ball, vec]
        if self._arrow is not None and float(np.max(np.abs(key - self._arrow))) < MOVE_M:
            return
        self._arrow = key
        length = float(np.linalg.norm(vec))
        paths = self._arrow_paths
        if paths is None:
            paths = self._arrow_paths = {k: self.vis[n].path.lower() for k, n in
                                         (("", node), ("shaft", f"{node}/shaft"), ("head", f"{node}/head"))}
        send_transform(self.vis, paths[""], transform_matrix(ball, rotation_y_to(vec) if length > 0 else None))
        for part, (pos, scl) in arrow_parts(max(length, 1e-6)).items():
            send_transform(self.vis, paths[part], transform_matrix(pos, None, scl))

    def _points(self) -> None:
        pts = np.array([p.corrected for p in self.session.points])
        self.scene.show_points(pts, name="live/points", color=LIVE_POINTS_RGB, size=0.012, legend="cyan dots")
        first = self._shown_points == 0
        self._shown_points = len(pts)
        if first and not self._camera_given:
            self.view.frame()

    def _features(self) -> None:
        places = []
        for fit in self.session.fits.values():
            if fit.centre is None or fit.kind in ("distance", "point"):
                continue
            radius = None if fit.size is None else fit.size / 2
            places.append(Placement(fit.feature, fit.kind, "live", fit.centre, fit.axis, radius, fit.radius,
                                    fit.extent if fit.extent is not None else np.zeros(2), fit.n_points))
        self.scene.show_artefacts(places, self.session.tracker.distances)
        self._fits_drawn = len(self.session.points)

    def _panel(self) -> None:
        self.vis.window.send(_PanelCommand(self.vis[PANEL_NODE].path, self.lines))

    def html(self) -> str:
        """The scene as one self-contained page, the panel's text as its legend."""
        return page_with_legend(self.view.server.static_html(), self.view.title, self.lines + self.view.legend)

    def write_html(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(self.html(), encoding="utf-8")
        return path

    def close(self) -> None:
        self.view.close()

    def __enter__(self) -> LiveView:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
