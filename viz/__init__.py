"""Viewer: arm poses, probe deflections, artefacts and residuals in a headless meshcat server.

``viz.show(arm, q, wrench=...)`` starts a meshcat server on 127.0.0.1 and draws the arm (URDF visuals
through Pinocchio's meshcat visualiser) with the probe's elastic joints set by statics, the probe
ball and the deflection arrow (scaled, the scale written in the scene and on the page);
``View.write_html`` writes the same scene as one self-contained page. ``aacmm view`` is the
command line (:mod:`viz.cli`); :mod:`viz.browser` renders pages in headless Chromium.
Heavy backends (meshcat, Pinocchio) load when a view is made, not at import.
"""
from .browser import arm_mask, colour_mask, find_chromium, load_png, screenshot
from .errors import ViewerError
from .placement import Placement, place_features
from .residuals import Residuals, read_residuals, residual_origins
from .scene import ArmScene, Camera, PoseInfo
from .server import MeshcatServer
from .view import View, page_with_legend, show, show_residuals

__all__ = [
    "ViewerError",
    "show", "show_residuals", "View", "page_with_legend",
    "ArmScene", "Camera", "PoseInfo",
    "MeshcatServer",
    "Placement", "place_features",
    "Residuals", "read_residuals", "residual_origins",
    "find_chromium", "screenshot", "load_png", "colour_mask", "arm_mask",
]
