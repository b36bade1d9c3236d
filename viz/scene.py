"""Drawing an arm and its measurement into a meshcat scene.

:class:`ArmScene` draws, under one root node of a :class:`meshcat.Visualizer`: the arm from its URDF
visuals (Pinocchio's meshcat visualiser), posed with the probe's elastic joints set by statics from
the wrench; the probe ball (true size, plus a marker that stays visible at arm scale); the deflection
as an arrow from the rigid to the corrected ball centre, scaled; the measured ball centres; artefacts
placed by fitting (:mod:`viz.placement`); residual vectors, scaled; the 95 % uncertainty ellipsoids of
the ball centres, scaled (:func:`ellipsoid_mesh`). Poses can be animated
(a meshcat animation, which a static page embeds). All inputs SI, base frame.

Every scaled quantity is named with its scale in the scene tree (``deflection x1000``) and in
:attr:`ArmScene.legend`, which the CLI prints and the static page shows.
"""
from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from arm_model import ArmDescription, load_description
from arm_model.geometry import frame_along

log = logging.getLogger(__name__)

__all__ = ["ArmScene", "Camera", "PoseInfo", "ROOT", "DEFLECTION_RGB", "RESIDUAL_RGB", "POINTS_RGB",
           "ARTEFACT_RGB", "ELLIPSOID_RGB", "ellipsoid_mesh", "coverage_factor", "transform_frames", "send_transform"]

ROOT = "aacmm"
DEFLECTION_RGB = 0x18C018     # green arrow
RESIDUAL_RGB = 0xE020E0       # magenta residual vectors
POINTS_RGB = 0xFFFFFF         # measured ball centres
ARTEFACT_RGB = 0xB0C4DE       # light steel blue, translucent
BALL_MARKER_RGB = 0xD01818
ELLIPSOID_RGB = 0xFFD700      # yellow, translucent uncertainty ellipsoids
MARKER_RGB = 0xFFA0FF         # pink: a tracker's markers where the model puts them
SEEN_RGB = 0x20D0F0           # cyan: where the instrument saw them
_ARROW_RADIUS = 0.005         # [m] shaft radius of the deflection arrow
_HEAD = (0.012, 0.035)        # [m] head radius and length


# -------------------------------------------------------------------------------------------------
# camera

@dataclass(frozen=True)
class Camera:
    """meshcat's default perspective camera at ``position``, looking at ``target`` with z up.

    meshcat's orbit controls always look at the scene origin, so :meth:`ArmScene.set_camera` shifts
    the drawing (and the floor grid) by ``-target``; coordinates stay base-frame everywhere else.

    Attributes:
        position: (3,) camera centre [m], base frame.
        target: (3,) the point at the centre of the page [m], base frame.
        fov_deg: vertical field of view [deg] (meshcat's default camera has 75).
    """
    position: tuple
    target: tuple = (0.0, 0.0, 0.0)
    fov_deg: float = 75.0

    def project(self, p_base, width: int, height: int) -> np.ndarray:
        """(N, 2) pixel coordinates (x right, y down) of points (N, 3) [m] on a ``width`` x ``height``
        page; NaN for points behind the camera."""
        p = np.atleast_2d(np.asarray(p_base, dtype=float))
        c = np.asarray(self.position, dtype=float)
        f = np.asarray(self.target, dtype=float) - c
        f /= np.linalg.norm(f)
        r = np.cross(f, [0.0, 0.0, 1.0])
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        d = p - c
        x, y, z = d @ r, d @ u, d @ f
        t = np.tan(np.radians(self.fov_deg) / 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            nx = np.where(z > 0, x / (z * t * width / height), np.nan)
            ny = np.where(z > 0, y / (z * t), np.nan)
        return np.column_stack([(nx + 1) / 2 * width, (1 - ny) / 2 * height])

    @classmethod
    def framing(cls, p_base, direction=(0.45, -1.0, 0.45), aspect: float = 4 / 3,
                fill: float = 0.8, pad: float = 0.06, fov_deg: float = 75.0) -> Camera:
        """The camera looking along ``-direction`` at the middle of the points ``p_base`` (N, 3) [m],
        as close as keeps them, grown by ``pad`` [m] on every axis, within ``fill`` of the
        half-width and half-height of a page of the given aspect."""
        p = np.atleast_2d(np.asarray(p_base, dtype=float))
        p = np.vstack([p] + [p + s * pad * e for e in np.eye(3) for s in (-1, 1)])
        u = np.asarray(direction, dtype=float)
        u = u / np.linalg.norm(u)
        if abs(u[2]) > 0.99:
            raise ValueError("the camera direction must not be vertical (z is up on the page)")
        target = (p.min(axis=0) + p.max(axis=0)) / 2
        dist = max(0.3, float(np.max(np.linalg.norm(p - target, axis=1))))
        for _ in range(200):
            cam = cls(tuple(target + dist * u), tuple(target), fov_deg)
            ndc = np.abs(cam.project(p, 1000 * aspect, 1000) / [500 * aspect, 500] - 1)
            if np.all(np.isfinite(ndc)) and ndc.max() <= fill:
                return cam
            dist *= 1.05
        return cam

    def meshcat_position(self) -> list[float]:
        """The position in meshcat's camera node (``/Cameras/default/rotated``: y up, origin at the
        target)."""
        x, y, z = (float(v) for v in np.subtract(self.position, self.target))
        return [x, z, -y]


# -------------------------------------------------------------------------------------------------
# arrows

def rotation_y_to(v: np.ndarray) -> np.ndarray:
    """A rotation whose y axis is along ``v`` (meshcat cylinders and cones lie along y)."""
    return frame_along(v, 1)


def arrow_parts(length: float) -> dict[str, tuple[list, list]]:
    """Local (position, scale) of the unit shaft and unit head of an arrow of ``length`` [m]."""
    head_len = min(_HEAD[1], 0.5 * length)
    k = head_len / _HEAD[1]
    shaft = max(length - head_len, 1e-9)
    return {"shaft": ([0.0, shaft / 2, 0.0], [max(k, 1e-9), shaft, max(k, 1e-9)]),
            "head": ([0.0, shaft + head_len / 2, 0.0], [max(k, 1e-9), max(head_len, 1e-9), max(k, 1e-9)])}


def coverage_factor(level: float = 0.95) -> float:
    """k of the ``level`` ellipsoid of a 3D normal: ``sqrt`` of the chi-square quantile of 3 dof (2.796
    for 95 %)."""
    from scipy.stats import chi2
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level}")
    return float(np.sqrt(chi2.ppf(level, 3)))


def ellipsoid_mesh(centres, cov, scale: float, level: float = 0.95, subdivisions: int = 1):
    """One triangle mesh of the ``level`` uncertainty ellipsoids of points with covariances.

    The ellipsoid of a 3D normal that holds the point with probability ``level`` is
    ``(x - c)^T cov^-1 (x - c) = k^2`` with ``k^2`` the chi-square quantile of 3 degrees of freedom
    (k = 2.796 for 95 %); each is drawn ``scale`` times larger about its centre, as an icosphere
    (trimesh; 42 vertices a point with ``subdivisions=1``) mapped by ``c + scale k V diag(sqrt(w)) v``
    (``cov = V diag(w) V^T``).

    Args:
        centres: (N, 3) [m]; cov: (N, 3, 3) [m^2]; scale: drawn size per true size.
    Returns:
        vertices (N V, 3) [m], faces (N F, 3) (indices; point i owns vertices i V ... i V + V - 1), k.
    """
    import trimesh

    c = np.atleast_2d(np.asarray(centres, dtype=float))
    cov = np.asarray(cov, dtype=float).reshape(-1, 3, 3)
    if len(c) != len(cov) or c.shape[1] != 3:
        raise ValueError(f"centres {c.shape} and covariances {cov.shape} must be (N, 3) and (N, 3, 3)")
    k = coverage_factor(level)
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    v0, f0 = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    w, vec = np.linalg.eigh(cov)
    a = vec * (scale * k * np.sqrt(np.maximum(w, 0.0)))[:, None, :]
    verts = c[:, None, :] + np.einsum("nij,vj->nvi", a, v0)
    faces = f0[None] + (np.arange(len(c)) * len(v0))[:, None, None]
    return verts.reshape(-1, 3), faces.reshape(-1, 3), k


def _msgpack_str(b: bytes) -> bytes:
    n = len(b)
    if n < 32:
        return bytes([0xA0 | n]) + b
    if n < 256:
        return bytes([0xD9, n]) + b
    return b"\xda" + n.to_bytes(2, "big") + b


_MATRIX_HEAD = _msgpack_str(b"matrix") + b"\xdc\x00\x10"      # an array of 16 (msgpack array 16)
_FLOATS = struct.Struct(">" + "Bd" * 16)


def transform_frames(path: str, matrix: np.ndarray) -> list[bytes]:
    """The ZMQ frames of meshcat's ``set_transform`` command for the node ``path`` (its full path, as
    ``meshcat.path.Path.lower`` gives it) and the (4, 4) ``matrix``: the bytes ``Visualizer.set_transform``
    sends (msgpack of ``{"type", "path", "matrix"}``, the matrix column-major in doubles), packed here
    directly (a live view sends hundreds a second)."""
    pb = path.encode("utf-8")
    m = np.asarray(matrix, dtype=float).T.reshape(-1).tolist()
    body = (b"\x83" + _msgpack_str(b"type") + _msgpack_str(b"set_transform") + _msgpack_str(b"path")
            + _msgpack_str(pb) + _MATRIX_HEAD + _FLOATS.pack(*[x for v in m for x in (0xCB, v)]))
    return [b"set_transform", pb, body]


def send_transform(vis, path: str, matrix: np.ndarray) -> None:
    """Set the transform of the node ``path`` (full path) of a :class:`meshcat.Visualizer` (one round
    trip to its server, as ``set_transform``)."""
    sock = vis.window.zmq_socket
    sock.send_multipart(transform_frames(path, matrix))
    sock.recv()


def _dots(mg, p: np.ndarray, rgb: int, size: float):
    """A meshcat points object (meshcat's PointsMaterial always uses per-vertex colours)."""
    colour = np.array([(rgb >> 16) & 255, (rgb >> 8) & 255, rgb & 255], dtype=np.float32) / 255
    return mg.Points(mg.PointsGeometry(p.T.astype(np.float32), np.tile(colour[:, None], (1, len(p)))),
                     mg.PointsMaterial(size=size))


def _tube(mg, height: float, radius: float):
    """An open-ended cylinder along y (a ring's bore), meshcat's Cylinder without its caps."""
    tube = mg.Cylinder(height, radius)
    lower = tube.lower
    tube.lower = lambda object_data: {**lower(object_data), "openEnded": True}
    return tube


def transform_matrix(position, rotation=None, scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = (np.eye(3) if rotation is None else rotation) @ np.diag(scale)
    t[:3, 3] = position
    return t


@dataclass(frozen=True)
class PoseInfo:
    """Ball centres of one drawn pose [m], base frame: ``rigid`` (no deflection), ``corrected``
    (deflection-aware), and ``deflection`` = corrected - rigid."""
    rigid: np.ndarray
    corrected: np.ndarray

    @property
    def deflection(self) -> np.ndarray:
        return self.corrected - self.rigid


# -------------------------------------------------------------------------------------------------
# the scene

class ArmScene:
    """An arm drawn into a meshcat visualizer.

    Args:
        vis: a :class:`meshcat.Visualizer` (e.g. ``MeshcatServer().start().visualizer``).
        arm: an :class:`~arm_model.ArmDescription`, an :class:`~arm_model.PinocchioArm`, the path of a
            description file, or None for a scene of data only (residuals, points).
        root: the scene node everything is drawn under.
    """

    def __init__(self, vis, arm, root: str = ROOT):
        import meshcat.geometry as mg
        import pinocchio as pin
        from pinocchio.visualize import MeshcatVisualizer

        from arm_model import PinocchioArm

        self._pin, self._mg = pin, mg
        self.vis = vis
        self.root = root
        self.legend: list[str] = []
        self._extent: list[np.ndarray] = [np.zeros((1, 3))]
        if isinstance(arm, (str, Path)):
            arm = load_description(arm)
        self.arm = PinocchioArm(arm) if isinstance(arm, ArmDescription) else arm
        self.desc = None if arm is None else self.arm.desc
        self._pv = None
        if self.arm is not None:
            geom = self._visual_model(pin)
            self._pv = MeshcatVisualizer(self.arm.model, None, geom)
            self._pv.initViewer(viewer=vis)
            self._pv.loadViewerModel(rootNodeName=f"{root}/arm")
            self._legend(f"arm '{self.desc.name}': " + ("its URDF's own visuals" if self.desc.visuals else
                                                          "links orange") + ", probe ball red (marker 24 mm wide)")
            missing = self.desc.missing_meshes
            if missing:
                line = (f"{len(missing)} mesh file{'s' if len(missing) > 1 else ''} of the URDF not found (e.g. "
                        f"'{missing[0]}'; package:// is looked for in a folder of that name beside or above the "
                        "URDF, then in ROS_PACKAGE_PATH and AMENT_PREFIX_PATH/share): the arm is drawn without them")
                log.warning(line)
                self._legend(line)
        vis["/Axes"].set_property("visible", False)   # its x axis fades to orange, the arm's colour
        vis[f"{root}/base frame"].set_object(mg.LineSegments(
            mg.PointsGeometry(position=(0.15 * np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0], [0, 1, 0],
                                                          [0, 0, 0], [0, 0, 1]])).T.astype(np.float32),
                              color=np.array([[1, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0],
                                              [0, 0, 1], [0, 0, 1]]).T.astype(np.float32)),
            mg.LineBasicMaterial(vertexColors=True)))
        self._arrow_path = None
        self._nodes = None

    def _visual_model(self, pin):
        """Pinocchio's visual model of the arm: the URDF's own visuals where the arm was read from one and its
        meshes load; else (a mesh Pinocchio cannot read) the generated links, saying so."""
        desc = self.desc
        assert desc is not None, "called for a scene with an arm"
        try:
            return pin.buildGeomFromUrdfString(self.arm.model, self.arm.urdf, pin.GeometryType.VISUAL)
        except (RuntimeError, ValueError) as exc:
            if not desc.visuals:
                raise
            why = " ".join(str(exc).split())
            log.warning(f"the URDF's own visuals cannot be drawn ({why[:300]}): the arm is drawn as generated links")
            from arm_model import PinocchioArm
            self.arm = PinocchioArm(replace(desc, visuals=()))
            self.desc = self.arm.desc
            return pin.buildGeomFromUrdfString(self.arm.model, self.arm.urdf, pin.GeometryType.VISUAL)

    # -- poses --------------------------------------------------------------------------------
    def pose(self, q, wrench=None) -> tuple[np.ndarray, PoseInfo]:
        """(Pinocchio configuration with the elastic joints, ball centres) for angles ``q`` (J,) [rad]
        and ``wrench`` (3,) [N] or (6,) [N, N m] of the part on the ball, probe frame."""
        if self.arm is None:
            raise ValueError("this scene has no arm (ArmScene(vis, arm=None))")
        q = np.asarray(q, dtype=float)
        if q.shape != (self.desc.n_joints,):
            raise ValueError(f"q must have {self.desc.n_joints} angles, got shape {q.shape}")
        rigid = self.arm.ball_centre(q)
        if wrench is None or not np.any(wrench):
            return self.arm.full_q(q), PoseInfo(rigid, rigid.copy())
        x = self.arm.full_q(q, self.arm.elastic_q(q, np.asarray(wrench, dtype=float)))
        return x, PoseInfo(rigid, self.arm.ball_centre(q, np.asarray(wrench, dtype=float)))

    def move(self, q, wrench=None, redraw: bool = True, extent: bool = False) -> PoseInfo:
        """Put the arm at ``q`` [rad] deflected by ``wrench`` and nothing else (no arrow): a live view's
        frame, many a second. ``redraw=False``: only compute the pose; ``extent``: add the arm's joints to
        the extent the camera frames. The same transforms as the visualiser's ``display``, sent directly
        (:func:`send_transform`)."""
        x, info = self.pose(q, wrench)
        if redraw:
            pin, pv = self._pin, self._pv
            if self._nodes is None:     # (geometry id, node path, mesh scale) of every visual
                self._nodes = [(pv.visual_model.getGeometryId(g.name),
                                pv.viewer[pv.getViewerNodeName(g, pin.GeometryType.VISUAL)].path.lower(),
                                np.diag([*g.meshScale, 1.0])) for g in pv.visual_model.geometryObjects]
            pin.forwardKinematics(pv.model, pv.data, x)
            pin.updateGeometryPlacements(pv.model, pv.data, pv.visual_model, pv.visual_data)
            for gid, path, scale in self._nodes:  # type: ignore[attr-defined]
                send_transform(self.vis, path, pv.visual_data.oMg[gid].homogeneous @ scale)
        if extent:
            self._extent.append(self._joint_points(x))
        return info

    def _joint_points(self, x) -> np.ndarray:
        pin = self._pin
        pin.framesForwardKinematics(self.arm.model, self.arm.data, x)
        return np.array([m.translation for m in self.arm.data.oMf])

    def _arrow_node(self, scale: float) -> str:
        name = f"{self.root}/deflection x{scale:g}"
        if self._arrow_path != name:
            mg = self._mg
            if self._arrow_path is not None:
                self.vis[self._arrow_path].delete()
                self.legend[:] = [line for line in self.legend if not line.startswith("green arrow:")]
            mat = mg.MeshLambertMaterial(color=DEFLECTION_RGB)
            self.vis[f"{name}/shaft"].set_object(mg.Cylinder(1.0, _ARROW_RADIUS), mat)
            self.vis[f"{name}/head"].set_object(mg.Cylinder(1.0, radiusTop=0.0, radiusBottom=_HEAD[0]), mat)
            marker = mg.MeshLambertMaterial(color=BALL_MARKER_RGB, opacity=0.45)
            self.vis[f"{self.root}/probe ball marker"].set_object(mg.Sphere(0.012), marker)
            self._arrow_path = name
            self._legend(f"green arrow: deflection, from the rigid to the corrected ball centre, drawn x{scale:g}")
        return name

    def _legend(self, line: str) -> None:
        if line not in self.legend:
            self.legend.append(line)

    def show_pose(self, q, wrench=None, scale: float = 1000.0) -> PoseInfo:
        """Draw the arm at ``q`` [rad] deflected by ``wrench``, the ball marker, and the deflection
        arrow from the rigid centre, ``scale`` times the deflection long."""
        x, info = self.pose(q, wrench)
        self._pv.display(x)
        name = self._arrow_node(scale)
        vec = scale * info.deflection
        self.vis[name].set_transform(transform_matrix(info.rigid, rotation_y_to(vec)))
        for part, (pos, scl) in arrow_parts(float(np.linalg.norm(vec))).items():
            self.vis[f"{name}/{part}"].set_transform(transform_matrix(pos, None, scl))
        self.vis[f"{self.root}/probe ball marker"].set_transform(transform_matrix(info.corrected))
        self._extent += [self._joint_points(x), (info.rigid + vec)[None]]
        return info

    def animate(self, qs, wrenches=None, fps: float = 2.0, scale: float = 1000.0,
                repetitions: int = 1000) -> list[PoseInfo]:
        """Animate the arm through poses ``qs`` (N, J) [rad] with ``wrenches`` (N, 3|6) or None, one
        pose every 1/``fps`` s, ``repetitions`` times; the arm is also left at the first pose.
        Static pages embed the animation."""
        import meshcat.animation as ma

        pin = self._pin
        qs = np.atleast_2d(np.asarray(qs, dtype=float))
        ws = [None] * len(qs) if wrenches is None else np.asarray(wrenches, dtype=float)
        if len(ws) != len(qs):
            raise ValueError(f"{len(qs)} poses but {len(ws)} wrenches")
        self.show_pose(qs[0], ws[0], scale)
        name = self._arrow_node(scale)
        pv = self._pv
        anim = ma.Animation(default_framerate=fps)   # frame i is shown at time i / fps
        infos = []
        for i, (q, w) in enumerate(zip(qs, ws, strict=True)):
            x, info = self.pose(q, w)
            infos.append(info)
            pin.forwardKinematics(pv.model, pv.data, x)
            pin.updateGeometryPlacements(pv.model, pv.data, pv.visual_model, pv.visual_data)
            with anim.at_frame(self.vis, i) as frame:
                for g in pv.visual_model.geometryObjects:
                    t = pv.visual_data.oMg[pv.visual_model.getGeometryId(g.name)].homogeneous
                    frame[pv.getViewerNodeName(g, pin.GeometryType.VISUAL)].set_transform(
                        t @ np.diag([*g.meshScale, 1.0]))
                vec = scale * info.deflection
                frame[name].set_transform(transform_matrix(info.rigid, rotation_y_to(vec)))
                for part, (pos, scl) in arrow_parts(float(np.linalg.norm(vec))).items():
                    frame[f"{name}/{part}"].set_property("position", "vector3", pos)
                    frame[f"{name}/{part}"].set_property("scale", "vector3", scl)
                frame[f"{self.root}/probe ball marker"].set_transform(transform_matrix(info.corrected))
            self._extent += [self._joint_points(x), (info.rigid + vec)[None]]
        self.vis.set_animation(anim, play=True, repetitions=int(repetitions))
        self._legend(f"animation: {len(qs)} pose(s), {fps:g} per second")
        return infos

    # -- data ---------------------------------------------------------------------------------
    def show_points(self, p_base, name: str = "ball centres", color: int = POINTS_RGB,
                    size: float = 0.006, legend: str | None = "white dots") -> None:
        """Draw points (N, 3) [m] as dots ``size`` [m] wide; ``legend`` names their colour."""
        mg = self._mg
        p = np.atleast_2d(np.asarray(p_base, dtype=float))
        self.vis[f"{self.root}/{name}"].set_object(_dots(mg, p, color, size))
        self._extent.append(p)
        if legend:
            self._legend(f"{legend}: {len(p)} {name}")

    def show_residuals(self, points, residuals, scale: float = 1000.0) -> None:
        """Draw residual vectors (N, 3) [m] as lines from ``points`` (N, 3) [m], ``scale`` times long."""
        mg = self._mg
        p = np.atleast_2d(np.asarray(points, dtype=float))
        r = np.atleast_2d(np.asarray(residuals, dtype=float))
        if p.shape != r.shape or p.shape[1] != 3:
            raise ValueError(f"points {p.shape} and residuals {r.shape} must both be (N, 3)")
        seg = np.empty((2 * len(p), 3))
        seg[0::2], seg[1::2] = p, p + scale * r
        name = f"{self.root}/residuals x{scale:g}"
        self.vis[f"{name}/vectors"].set_object(mg.LineSegments(
            mg.PointsGeometry(seg.T.astype(np.float32)), mg.LineBasicMaterial(color=RESIDUAL_RGB, linewidth=2)))
        self.vis[f"{name}/points"].set_object(_dots(mg, p, RESIDUAL_RGB, 0.004))
        self._extent.append(seg)
        self._legend(f"magenta lines: {len(p)} residual vector(s), drawn x{scale:g}")

    def show_markers(self, predicted, seen=None, scale: float = 1.0) -> None:
        """Draw markers (N, 3) [m] where the model puts them as pink dots, and where the instrument saw them,
        ``seen`` (N, 3) [m] (base frame; or None), as cyan lines from each predicted marker ``scale`` times the
        difference long, a cyan dot at their end."""
        mg = self._mg
        p = np.atleast_2d(np.asarray(predicted, dtype=float))
        self.vis[f"{self.root}/markers"].set_object(_dots(mg, p, MARKER_RGB, 0.008))
        self._extent.append(p)
        self._legend(f"pink dots: {len(p)} marker(s) where the model puts them")
        if seen is None:
            return
        end = p + scale * (np.atleast_2d(np.asarray(seen, dtype=float)) - p)
        seg = np.empty((2 * len(p), 3))
        seg[0::2], seg[1::2] = p, end
        name = f"{self.root}/instrument x{scale:g}"
        self.vis[f"{name}/lines"].set_object(mg.LineSegments(
            mg.PointsGeometry(seg.T.astype(np.float32)), mg.LineBasicMaterial(color=SEEN_RGB, linewidth=2)))
        self.vis[f"{name}/points"].set_object(_dots(mg, end, SEEN_RGB, 0.004))
        self._extent.append(end)
        self._legend(f"cyan lines: to where the instrument saw each marker (base frame, by the model's frame of "
                     f"its session), the difference drawn x{scale:g}")

    def show_ellipsoids(self, centres, cov, scale: float, level: float = 0.95) -> None:
        """Draw the ``level`` uncertainty ellipsoids (:func:`ellipsoid_mesh`) of points (N, 3) [m] with
        covariances (N, 3, 3) [m^2], ``scale`` times larger about each point, as one translucent mesh."""
        mg = self._mg
        verts, faces, k = ellipsoid_mesh(centres, cov, scale, level)
        name = f"{self.root}/uncertainty ellipsoids {level * 100:g}% x{scale:g}"
        self.vis[name].set_object(mg.TriangularMeshGeometry(verts, faces),
                                  mg.MeshLambertMaterial(color=ELLIPSOID_RGB, opacity=0.55))
        self._extent.append(verts)
        self._legend(f"yellow: {len(np.atleast_2d(centres))} {level * 100:g} % uncertainty ellipsoid(s) of the "
                     f"corrected ball centres (k = {k:.3f}, chi-square of 3 dof), drawn x{scale:g}")

    def show_artefacts(self, placements, distances=()) -> None:
        """Draw placed features (:func:`viz.placement.place_features`) with their certified size, and
        a rod for each certified ``distance`` between two features placed in one measurement."""
        mg = self._mg
        mat = mg.MeshLambertMaterial(color=ARTEFACT_RGB, opacity=0.4)
        by_key = {(pl.measurement, pl.feature): pl for pl in placements}
        for pl in placements:
            node = self.vis[f"{self.root}/artefacts/{pl.measurement}/{pl.feature}"]
            radius = pl.radius if pl.radius is not None else pl.fitted_radius
            if pl.kind in ("ring", "cylinder"):
                height = max(float(pl.size[0]) + 0.01, 0.015)
                node.set_object(_tube(mg, height, radius), mat)
                node.set_transform(transform_matrix(pl.centre, rotation_y_to(pl.axis)))
                self._extent.append(pl.centre + radius * np.eye(3))
            elif pl.kind == "sphere":
                node.set_object(mg.Sphere(radius), mat)
                node.set_transform(transform_matrix(pl.centre))
            elif pl.kind == "plane":
                size = np.asarray(pl.size) + 0.04
                node.set_object(mg.Box([size[0], 0.001, size[1]]), mat)
                rot = rotation_y_to(pl.axis)
                node.set_transform(transform_matrix(pl.centre, rot))
            else:  # seat: a small marker at the ball centre
                node.set_object(mg.Sphere(0.008), mat)
                node.set_transform(transform_matrix(pl.centre))
            self._extent.append(pl.centre[None])
        for d in distances:
            for meas in dict.fromkeys(pl.measurement for pl in placements):
                a, b = by_key.get((meas, d.between[0])), by_key.get((meas, d.between[1]))
                if a is None or b is None:
                    continue
                v = b.centre - a.centre
                node = self.vis[f"{self.root}/artefacts/{meas}/{d.between[0]}--{d.between[1]}"]
                node.set_object(mg.Cylinder(float(np.linalg.norm(v)), 0.004), mat)
                node.set_transform(transform_matrix((a.centre + b.centre) / 2, rotation_y_to(v)))
        if placements:
            self._legend(f"blue: {len(placements)} artefact feature(s), certified size, placed by fitting "
                         "the ball centres")

    # -- camera -------------------------------------------------------------------------------
    @property
    def extent(self) -> np.ndarray:
        """(N, 3) [m] points the drawn scene spans (for framing the camera)."""
        return np.vstack(self._extent)

    def set_camera(self, camera: Camera | None = None, aspect: float = 4 / 3) -> Camera:
        """Place meshcat's camera (default: framing everything drawn so far) and return it."""
        camera = camera or Camera.framing(self.extent, aspect=aspect)
        shift = transform_matrix(-np.asarray(camera.target, dtype=float))
        self.vis[self.root].set_transform(shift)
        self.vis["/Grid"].set_transform(shift)
        self.vis["/Cameras/default/rotated/<object>"].set_property("position", camera.meshcat_position())
        return camera
