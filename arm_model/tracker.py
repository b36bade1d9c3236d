"""A reference instrument (laser tracker, motion capture) and the markers it sees on the arm's tip frame.

The instrument reports marker positions ``p_ref`` in its own frame. In session ``s`` (a placement of the
instrument; one frame a session) and for marker ``k`` fixed on the tip frame at ``o_k`` [m]::

    p_ref = T_ref_base[s] @ T_base_tip(q) @ o_k

``T_ref_base`` maps base coordinates to the instrument's; ``o_k`` is the marker in the tip frame (the
probe frame: the ``--tip-frame`` link's frame, origin at the tip point). A calibration estimates both
(``aacmm calibrate`` on tracker data), writes them to the model file (``[[reference_frame]]``,
``[[marker]]``, docs/formats.md §2) and ``aacmm tip --reference-frame`` predicts ``p_ref`` with them.

The marker is evaluated by the arm's own model, the tip point moved by the offset (:func:`offset_matrix`:
``p + M o`` moves the probe point ``probe.x/y/z`` by ``R_last_tip o``), so every effect of the model
acts on a marker as on the tip.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .description import TomlReader, in_unit
from .errors import InputError
from .geometry import rotation_xyz, rpy_from_matrix

__all__ = ["Tracker", "offset_matrix", "marker_positions", "tracker_tables", "tracker_from_tables",
           "check_sessions", "TRACKER_KEYS", "DEFAULT_SESSION"]

#: the session of rows of a file without a ``session`` column
DEFAULT_SESSION = ""
#: top-level keys of a model file that hold a tracker
TRACKER_KEYS = ("reference_frame", "marker")


@dataclass(frozen=True)
class Tracker:
    """Frames of the reference instrument and offsets of the markers on the tip frame.

    Attributes:
        sessions: (S,) session ids (:data:`DEFAULT_SESSION` for a file without a session column).
        frames: (S, 4, 4) ``T_ref_base`` of each session (maps base coordinates [m] to the instrument's).
        offsets: (K, 3) marker k in the tip frame [m]; None: the instrument sees the tip point itself.
        u_frames: (S, 6) standard uncertainties of each frame's increments (translation [m], then a small
            rotation [rad] about the instrument's x, y, z axes), or None.
        u_offsets: (K, 3) standard uncertainties of the offsets [m], or None.
    """
    sessions: tuple[str, ...]
    frames: np.ndarray
    offsets: np.ndarray | None = None
    u_frames: np.ndarray | None = None
    u_offsets: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "sessions", tuple(str(s) for s in self.sessions))
        object.__setattr__(self, "frames", np.asarray(self.frames, float).reshape(len(self.sessions), 4, 4))
        if len(set(self.sessions)) != len(self.sessions):
            raise ValueError(f"a session appears twice: {self.sessions}")
        for name, width in (("offsets", 3), ("u_frames", 6), ("u_offsets", 3)):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, np.asarray(getattr(self, name), float).reshape(-1, width))

    @property
    def n_markers(self) -> int:
        """Markers with an offset (1 when the instrument sees the tip point itself)."""
        return 1 if self.offsets is None else len(self.offsets)

    def frame(self, session: str) -> np.ndarray | None:
        """``T_ref_base`` (4, 4) of a session, or None when this tracker has no frame for it."""
        return self.frames[self.sessions.index(session)] if session in self.sessions else None

    def offset(self, k: int) -> np.ndarray:
        """Marker ``k`` (0-based) in the tip frame [m] (zeros when the instrument sees the tip point)."""
        return np.zeros(3) if self.offsets is None else self.offsets[k]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (SI: m, rad): ``frames`` (one a session: ``session``, ``T_ref_base``, ``u_translation``,
        ``u_rotation``) and ``markers`` (one a marker: ``marker`` (1-based), ``offset``, ``u``), or None
        for markers when the instrument sees the tip point."""
        frames = []
        for i, s in enumerate(self.sessions):
            f = {"session": s, "T_ref_base": self.frames[i].tolist()}
            if self.u_frames is not None:
                f["u_translation"], f["u_rotation"] = self.u_frames[i, :3].tolist(), self.u_frames[i, 3:].tolist()
            frames.append(f)
        markers = None if self.offsets is None else [
            {"marker": k + 1, "offset": o.tolist(), "u": None if self.u_offsets is None else self.u_offsets[k].tolist()}
            for k, o in enumerate(self.offsets)]
        return {"frames": frames, "markers": markers}


def offset_matrix(model: Any) -> np.ndarray:
    """(P, 3) ``M`` with ``model.ball_centres(q, p + M o)`` the point at ``o`` [m] in the tip frame: ``o``
    turned into the last joint frame and added to the probe point (``probe.x``, ``probe.y``, ``probe.z``)."""
    spec = model.spec
    m = np.zeros((spec.size, 3))
    rot = model.desc.probe.rotation
    rows = [spec.index(f"probe.{a}") for a in "xyz"]
    m[rows, :] = np.eye(3) if rot is None else np.asarray(rot, float)
    return m


def marker_positions(model: Any, p: ArrayLike, q: ArrayLike, tracker: Tracker, sessions: Iterable[str],
                     aux: Any = None) -> np.ndarray:
    """(N, K, 3) the markers of ``tracker`` as the instrument would see them [m], in each row's session's
    frame (``sessions`` (N,) ids; every one must have a frame), at joint angles ``q`` (N, J) [rad] and
    parameters ``p`` (full vector, SI), no contact force."""
    p = np.asarray(p, float)
    q = np.atleast_2d(np.asarray(q, float))
    m = offset_matrix(model)
    out = np.empty((len(q), tracker.n_markers, 3))
    frames = np.array([tracker.frame(s) for s in sessions])
    for k in range(tracker.n_markers):
        x = model.ball_centres(q, None, p + m @ tracker.offset(k), aux)
        out[:, k] = np.einsum("nij,nj->ni", frames[:, :3, :3], x) + frames[:, :3, 3]
    return out


# ---------------------------------------------------------------------------------------------
# the model file's tables

_MM, _DEG = 1e-3, np.pi / 180.0
_FRAME_KEYS = {"x": ("length", True), "y": ("length", True), "z": ("length", True), "roll": ("angle", True),
               "pitch": ("angle", True), "yaw": ("angle", True), "u_x": ("length", False),
               "u_y": ("length", False), "u_z": ("length", False), "u_rx": ("angle", False),
               "u_ry": ("angle", False), "u_rz": ("angle", False)}
_MARKER_KEYS = {"x": ("length", True), "y": ("length", True), "z": ("length", True), "u_x": ("length", False),
                "u_y": ("length", False), "u_z": ("length", False)}


def tracker_tables(tracker: Tracker) -> dict[str, Any]:
    """The model file's ``reference_frame`` and ``marker`` arrays of tables (mm, degrees) of ``tracker``;
    :func:`tracker_from_tables` reads them back exactly."""
    frames = []
    for i, s in enumerate(tracker.sessions):
        t = tracker.frames[i]
        row: dict[str, Any] = {} if s == DEFAULT_SESSION else {"session": s}
        row.update({f"{a}_mm": in_unit(v, _MM) for a, v in zip("xyz", t[:3, 3], strict=True)})
        row.update({f"{a}_deg": in_unit(v, _DEG)
                    for a, v in zip(("roll", "pitch", "yaw"), rpy_from_matrix(t[:3, :3]), strict=True)})
        if tracker.u_frames is not None:
            u = tracker.u_frames[i]
            row.update({f"u_{a}_mm": in_unit(v, _MM) for a, v in zip("xyz", u[:3], strict=True)})
            row.update({f"u_r{a}_deg": in_unit(v, _DEG) for a, v in zip("xyz", u[3:], strict=True)})
        frames.append(row)
    out: dict[str, Any] = {"reference_frame": frames}
    if tracker.offsets is not None:
        marks = []
        for k, o in enumerate(tracker.offsets):
            row = {f"{a}_mm": in_unit(v, _MM) for a, v in zip("xyz", o, strict=True)}
            if tracker.u_offsets is not None:
                row.update({f"u_{a}_mm": in_unit(v, _MM) for a, v in zip("xyz", tracker.u_offsets[k], strict=True)})
            marks.append(row)
        out["marker"] = marks
    return out


def _table_list(data: dict[str, Any], key: str, r: TomlReader) -> list[Any]:
    tables = data.get(key, [])
    if not isinstance(tables, list) or not tables or not all(isinstance(t, dict) for t in tables):
        raise r.error(f"'{key}' must be an array of tables ([[{key}]])", key)
    return tables


def _uncertainties(values: dict[str, Any], names: Any, r: TomlReader, where: tuple[Any, ...]) -> np.ndarray | None:
    got = [n for n in names if n in values]
    if not got:
        return None
    if len(got) != len(names):
        raise r.error(f"give all of the uncertainties {', '.join(f'{n}_<unit>' for n in names)} or none", *where)
    u = np.array([values[n] for n in names])
    if (u < 0).any():
        raise r.error("a standard uncertainty must not be negative", *where)
    return u


def tracker_from_tables(data: dict[str, Any], r: TomlReader) -> Tracker | None:
    """The :class:`Tracker` of a parsed model file's ``[[reference_frame]]`` and ``[[marker]]`` tables
    (None without them); errors name the file, line and key."""
    if not any(k in data for k in TRACKER_KEYS):
        return None
    if "reference_frame" not in data:
        raise r.error("[[marker]] tables need the [[reference_frame]] of the instrument that saw them", "marker")
    sessions, frames, uf = [], [], []
    for i, tbl in enumerate(_table_list(data, "reference_frame", r)):
        where = ("reference_frame", i)
        session = tbl.get("session", DEFAULT_SESSION)
        if not isinstance(session, str) or ("session" in tbl and not session.strip()):
            raise r.error("'session' must be a non-empty text (leave it out for a file without sessions)",
                          *where, "session")
        if session in sessions:
            raise r.error(f"session '{session}' has two reference frames", *where, "session")
        v = r.values({k: x for k, x in tbl.items() if k != "session"}, _FRAME_KEYS, where)
        t = np.eye(4)
        t[:3, :3] = rotation_xyz([v["roll"], v["pitch"], v["yaw"]])
        t[:3, 3] = [v["x"], v["y"], v["z"]]
        sessions.append(session)
        frames.append(t)
        uf.append(_uncertainties(v, ("u_x", "u_y", "u_z", "u_rx", "u_ry", "u_rz"), r, where))
    offsets = uo = None
    if "marker" in data:
        vals = [r.values(tbl, _MARKER_KEYS, ("marker", k)) for k, tbl in enumerate(_table_list(data, "marker", r))]
        offsets = np.array([[v["x"], v["y"], v["z"]] for v in vals])
        us = [_uncertainties(v, ("u_x", "u_y", "u_z"), r, ("marker", k)) for k, v in enumerate(vals)]
        uo = None if any(u is None for u in us) else np.array(us)
    return Tracker(tuple(sessions), np.array(frames), offsets, None if any(u is None for u in uf) else np.array(uf), uo)


def check_sessions(tracker: Tracker, sessions: ArrayLike, path: Any) -> None:
    """An :class:`InputError` when a session of ``sessions`` has no frame in ``tracker``."""
    missing = [s for s in dict.fromkeys(np.asarray(sessions).tolist()) if tracker.frame(s) is None]
    if missing:
        have = ", ".join(repr(s) for s in tracker.sessions)
        if missing[0] == DEFAULT_SESSION:
            raise InputError(f"the model file has no reference frame for rows without a session column (its frames: "
                             f"{have}); a points file of a model with several sessions names each row's session in a "
                             "'session' column", path, None, "session")
        raise InputError(f"the model file has no reference frame for session '{missing[0]}' (its frames: {have}): "
                         "it knows the frames of the sessions it was calibrated on; give the rows of those sessions, "
                         "or calibrate with this session's points too", path, None, "session")
