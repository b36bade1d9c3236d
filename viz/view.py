"""The viewer for notebooks and the CLI: a headless meshcat server showing one arm and its data.

    import viz
    view = viz.show(desc, q, wrench=[0, 0, 10])     # starts a server on 127.0.0.1, prints nothing
    view.url                                        # open it in a browser; in Jupyter `view` shows itself
    view.write_html("pose.html")                    # the same scene as one self-contained page
    view.close()                                    # or `with viz.View(desc) as view: ...`
"""
from __future__ import annotations

import contextlib
import html as _html
from pathlib import Path

import numpy as np

from arm_model.io import atomic_write_text

from .errors import ViewerError
from .scene import ArmScene, Camera, PoseInfo
from .server import MeshcatServer

__all__ = ["View", "show", "show_residuals", "page_with_legend"]

_LEGEND_STYLE = ("position:absolute;left:8px;top:8px;z-index:10;max-width:60%;padding:6px 9px;"
                 "font:13px/1.4 sans-serif;color:#fff;background:rgba(0,0,0,0.55);border-radius:4px")


def page_with_legend(page: str, title: str, legend: list[str]) -> str:
    """meshcat's static page with ``title`` and a legend box (one line per item) written on it."""
    head, body = "<title>MeshCat</title>", "<body>"
    if head not in page or body not in page:
        raise ViewerError("meshcat's static page does not have the expected <title> and <body>: "
                          "this meshcat version is not supported by the viewer")
    box = (f'<div id="aacmm-legend" style="{_LEGEND_STYLE}"><b>{_html.escape(title)}</b><br>'
           + "<br>".join(_html.escape(line) for line in legend) + "</div>")
    return page.replace(head, f"<title>{_html.escape(title)}</title>", 1).replace(body, body + box, 1)


@contextlib.contextmanager
def _answering(server: MeshcatServer):
    """Turn a server that stopped answering into a :class:`ViewerError`."""
    import zmq

    if not server.running:   # never talk to whatever took its port since
        raise ViewerError(f"the meshcat server at {server.url} has stopped")
    try:
        yield
    except zmq.ZMQError as exc:
        raise ViewerError(f"the meshcat server at {server.url} did not answer ({exc}); it may have stopped"
                          ) from None


class View:
    """A meshcat server (started here, or given) with an :class:`~viz.scene.ArmScene` in it.

    Args:
        arm: :class:`~arm_model.ArmDescription`, :class:`~arm_model.PinocchioArm`, or None (data only).
        port: web port of a new server (None: first free from 7000).
        server: an already running :class:`~viz.server.MeshcatServer` to draw into (not closed here).
        title: the page title.
    """

    def __init__(self, arm=None, *, port: int | None = None, server: MeshcatServer | None = None,
                 title: str | None = None):
        self._own = server is None
        self.server = MeshcatServer(port).start() if server is None else server
        try:
            with _answering(self.server):
                self.scene = ArmScene(self.server.visualizer, arm)
        except BaseException:
            self.close()
            raise
        self.title = title or (f"{self.scene.desc.name}: AACMM viewer" if self.scene.desc else "AACMM viewer")
        self.camera: Camera | None = None
        self._fixed: Camera | None = None

    @property
    def url(self) -> str:
        return self.server.url  # type: ignore[return-value]

    @property
    def legend(self) -> list[str]:
        return self.scene.legend

    # drawing: thin wrappers that keep the camera framing everything drawn
    def show_pose(self, q, wrench=None, scale: float = 1000.0) -> PoseInfo:
        """Arm at ``q`` (J,) [rad] deflected by ``wrench`` (3,)/(6,) [N, N m]; deflection arrow x``scale``."""
        with _answering(self.server):
            info = self.scene.show_pose(q, wrench, scale)
            self._reframe()
        return info

    def animate(self, qs, wrenches=None, fps: float = 2.0, scale: float = 1000.0,
                repetitions: int = 1000) -> list[PoseInfo]:
        """Animate through poses ``qs`` (N, J) [rad] with ``wrenches`` (N, 3|6) or None."""
        with _answering(self.server):
            infos = self.scene.animate(qs, wrenches, fps, scale, repetitions)
            self._reframe()
        return infos

    def show_points(self, p_base, **kw) -> None:
        """Dots at points (N, 3) [m], base frame."""
        with _answering(self.server):
            self.scene.show_points(p_base, **kw)
            self._reframe()

    def show_residuals(self, points, residuals, scale: float = 1000.0) -> None:
        """Residual vectors (N, 3) [m] from ``points`` (N, 3) [m], drawn ``scale`` times long."""
        with _answering(self.server):
            self.scene.show_residuals(points, residuals, scale)
            self._reframe()

    def show_markers(self, predicted, seen=None, scale: float = 1.0) -> None:
        """A tracker's markers (N, 3) [m] where the model puts them and, ``seen`` (N, 3) [m] or None, where the
        instrument saw them (base frame), the difference drawn ``scale`` times long."""
        with _answering(self.server):
            self.scene.show_markers(predicted, seen, scale)
            self._reframe()

    def show_ellipsoids(self, centres, cov, scale: float, level: float = 0.95) -> None:
        """The ``level`` uncertainty ellipsoids of points (N, 3) [m] with covariances (N, 3, 3) [m^2],
        drawn ``scale`` times larger."""
        with _answering(self.server):
            self.scene.show_ellipsoids(centres, cov, scale, level)
            self._reframe()

    def show_artefacts(self, placements, distances=()) -> None:
        """Placed artefact features (:func:`viz.placement.place_features`)."""
        with _answering(self.server):
            self.scene.show_artefacts(placements, distances)
            self._reframe()

    def frame(self, camera: Camera | None = None) -> Camera:
        """Set the camera and keep it; ``None`` (the default) frames everything drawn, again after each
        drawing call. Returns the camera set."""
        self._fixed = camera
        with _answering(self.server):
            self.camera = self.scene.set_camera(camera)
        return self.camera

    def _reframe(self) -> None:
        self.camera = self.scene.set_camera(self._fixed)

    # output
    def html(self) -> str:
        """The scene as one self-contained page (no server needed to open it), with the legend."""
        return page_with_legend(self.server.static_html(), self.title, self.legend)

    def write_html(self, path: str | Path, inputs=()) -> Path:
        """Write :meth:`html` atomically to ``path`` (never over one of ``inputs``)."""
        return atomic_write_text(path, self.html(), inputs=inputs)

    def close(self) -> None:
        if self._own:
            self.server.close()

    def __enter__(self) -> View:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _repr_html_(self) -> str:   # Jupyter: the live scene in an iframe
        return (f'<div style="height:420px;width:100%"><iframe src="{_html.escape(self.url)}" '
                f'style="width:100%;height:100%;border:none"></iframe></div>')


def show(arm, q, wrench=None, *, scale: float = 1000.0, view: View | None = None,
         port: int | None = None) -> View:
    """Show ``arm`` at angles ``q`` (J,) [rad], deflected by ``wrench`` (3,) [N] or (6,) [N, N m] that
    the part exerts on the ball (probe frame), with the deflection arrow drawn ``scale`` times long.

    Draws into ``view`` if given, else starts a new server (close it with ``view.close()``; it also
    stops at exit). Returns the :class:`View` (``.url``, ``.write_html(path)``).
    """
    view = view or View(arm, port=port)
    view.show_pose(np.asarray(q, dtype=float), wrench, scale)
    return view


def show_residuals(points_m, residuals_m, scale: float = 1000.0, *, view: View | None = None,
                   arm=None, port: int | None = None) -> View:
    """Show residual vectors ``residuals_m`` (N, 3) [m] at ``points_m`` (N, 3) [m], base frame, drawn
    ``scale`` times long; into ``view`` if given, else into a new one (with ``arm`` if given)."""
    view = view or View(arm, port=port)
    view.show_residuals(points_m, residuals_m, scale)
    return view
