"""Artefact residual kinds: CasADi residual functions, starting fits and state updates.

Each kind maps a ball centre ``x`` [m] (base frame) and the *increment* ``theta`` of its nuisance
unknowns (a centre, an axis, a plane, a rigid transform) to residuals [m]. The nuisance state is kept
outside (``k``, packed floats) and every residual is evaluated at ``theta = 0``: CasADi gives the exact
derivatives with respect to ``x`` and ``theta``; after a step the state is moved by :func:`retract`
(an axis or a rotation stays a unit vector or a rotation matrix).

Kinds (docs/formats.md §4; ``b`` = ball diameter):

* ``seat``: ``x - c`` (3 rows a point); state ``c``.
* ``sphere``: ``|x - c| - R`` with ``R = (D + b) / 2``; state ``(c, R)``; ``theta = dc`` (and ``dR``
  when the radius is fitted).
* ``ring`` / ``cylinder`` (inner, probed from inside): distance to the axis minus ``R = (D - b) / 2``;
  state ``(p0, u0, e1, e2, R)``, ``theta = (s, t, a, b)``: axis point ``p0 + s e1 + t e2``, direction
  ``normalize(u0 + a e1 + b e2)`` (and ``dR``).
* ``plane``: signed distance ``n . x - h`` (``h`` absorbs the ball radius: a plane only tells flatness);
  state ``(n0, e1, e2, h)``, ``theta = (a, b, dh)``.
* ``reference``: ``T_ref_base x - x_ref`` (3 rows a point); state ``(R0, t0)``, ``theta = (dt, w)``
  with ``R = Rz(w3) Ry(w2) Rx(w1) R0``.
* ``distance``: ``|c_A - c_B| - L`` between two centres (seat or sphere) of one measurement.
* ``marker``: no rows of its own; state and ``theta`` the offset ``o`` [m] of a marker on the tip frame,
  which moves the ball centres of its reference rows (:class:`calibration.problem.Problem`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from arm_model import NumericalError, geometry
from arm_model.io import CENTRE_KINDS

__all__ = ["Kind", "KINDS", "MIN_POINTS", "kind_function", "distance_function", "initial_state", "retract", "centre_of",
           "frame_state", "frame_of", "tracker_start"]


@dataclass(frozen=True)
class Kind:
    """One residual kind: rows per point, nuisance increment size, packed state size."""
    name: str
    rows: int
    n_theta: int
    n_state: int


#: kinds by name (``free_radius`` adds one theta entry to sphere, ring and cylinder)
KINDS = {
    "seat": Kind("seat", 3, 3, 3),
    "sphere": Kind("sphere", 1, 3, 4),
    "ring": Kind("ring", 1, 4, 13),
    "cylinder": Kind("cylinder", 1, 4, 13),
    "plane": Kind("plane", 1, 3, 10),
    "reference": Kind("reference", 3, 6, 12),
    "marker": Kind("marker", 0, 3, 3),
}

#: fewest points an instance of each kind needs in a fit (known radius, free radius): one more than its
#: unknowns for the one-row kinds, so that the fit has a residual (viz.placement.NEEDED_POINTS, the fewest
#: that determine a feature for drawing, is a different, smaller count)
MIN_POINTS = {"seat": (1, 1), "sphere": (4, 5), "ring": (5, 6), "cylinder": (5, 6), "plane": (4, 4),
              "reference": (3, 3)}


def n_theta(kind: str, free_radius: bool) -> int:
    k = KINDS[kind]
    return k.n_theta + (1 if free_radius and kind in ("sphere", "ring", "cylinder") else 0)


def _normalize(ca: Any, v: Any) -> Any:
    return v / ca.sqrt(ca.dot(v, v))


def _rot_xyz_ca(ca: Any, w: Any) -> Any:
    """CasADi twin of :func:`arm_model.geometry.rotation_xyz` (``Rz Ry Rx``; symbolic, so hand-written)."""
    cx, sx, cy, sy, cz, sz = ca.cos(w[0]), ca.sin(w[0]), ca.cos(w[1]), ca.sin(w[1]), ca.cos(w[2]), ca.sin(w[2])
    rx = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, cx, -sx), ca.horzcat(0, sx, cx))
    ry = ca.vertcat(ca.horzcat(cy, 0, sy), ca.horzcat(0, 1, 0), ca.horzcat(-sy, 0, cy))
    rz = ca.vertcat(ca.horzcat(cz, -sz, 0), ca.horzcat(sz, cz, 0), ca.horzcat(0, 0, 1))
    return rz @ ry @ rx


@cache
def kind_function(kind: str, free_radius: bool = False) -> Any:
    """CasADi ``f(x[3], theta[n], k[m], xref[3]) -> (r[rows], dr_dx[rows x 3], dr_dtheta[rows x n])``
    of one point of ``kind`` (``xref`` is used by ``reference`` only)."""
    import casadi as ca

    kd = KINDS[kind]
    nt = n_theta(kind, free_radius)
    x = ca.SX.sym("x", 3)
    th = ca.SX.sym("theta", nt)
    k = ca.SX.sym("k", kd.n_state)
    xref = ca.SX.sym("xref", 3)
    if kind == "seat":
        r = x - (k[0:3] + th[0:3])
    elif kind == "sphere":
        c = k[0:3] + th[0:3]
        radius = k[3] + (th[3] if free_radius else 0)
        r = ca.norm_2(x - c) - radius
    elif kind in ("ring", "cylinder"):
        p0, u0, e1, e2, radius = k[0:3], k[3:6], k[6:9], k[9:12], k[12]
        point = p0 + th[0] * e1 + th[1] * e2
        u = _normalize(ca, u0 + th[2] * e1 + th[3] * e2)
        v = x - point
        radial = v - ca.dot(v, u) * u
        r = ca.norm_2(radial) - (radius + (th[4] if free_radius else 0))
    elif kind == "plane":
        n0, e1, e2, h = k[0:3], k[3:6], k[6:9], k[9]
        n = _normalize(ca, n0 + th[0] * e1 + th[1] * e2)
        r = ca.dot(n, x) - (h + th[2])
    elif kind == "reference":
        r0 = ca.reshape(k[0:9], 3, 3)          # column-major packing of R0
        t0 = k[9:12]
        r = _rot_xyz_ca(ca, th[3:6]) @ (r0 @ x) + t0 + th[0:3] - xref
    else:
        raise ValueError(f"unknown residual kind {kind!r}")
    return ca.Function(f"res_{kind}", [x, th, k, xref], [r, ca.jacobian(r, x), ca.jacobian(r, th)],
                       ["x", "theta", "k", "xref"], ["r", "dr_dx", "dr_dtheta"])


@cache
def distance_function() -> Any:
    """CasADi ``d(ca[3], cb[3], L) -> (r, dr_dca[1x3], dr_dcb[1x3])``, ``r = |ca - cb| - L`` [m]."""
    import casadi as ca

    a, b, length = ca.SX.sym("ca", 3), ca.SX.sym("cb", 3), ca.SX.sym("L")
    r = ca.norm_2(a - b) - length
    return ca.Function("res_distance", [a, b, length], [r, ca.jacobian(r, a), ca.jacobian(r, b)],
                       ["ca", "cb", "L"], ["r", "dr_dca", "dr_dcb"])


# ---------------------------------------------------------------------------------------------
# starting states and state updates (the fits themselves are in :mod:`arm_model.geometry`)

#: starting states of fitted instances kept (:func:`initial_state`): the loop fits the same points under many models
STATE_CACHE = 4096
_STATES: dict[tuple[Any, ...], np.ndarray] = {}


def initial_state(kind: str, x: np.ndarray, radius: float | None = None, x_ref: np.ndarray | None = None) -> np.ndarray:
    """Packed starting state of one instance from its ball centres ``x`` (n, 3) [m] (the fits of
    :mod:`arm_model.geometry`; points that do not determine a fit start from their mean).

    ``radius``: the offset radius of sphere, ring, cylinder [m] (None: fitted). The state of a sphere, ring,
    cylinder or plane is fitted once for the same centres and radius (the last :data:`STATE_CACHE` kept: the loop
    starts its many fits of one campaign from the same centres) and returned as a new array.
    """
    if kind not in ("sphere", "ring", "cylinder", "plane"):
        return _initial_state(kind, x, radius, x_ref)
    x = np.ascontiguousarray(x, dtype=float)
    key = (kind, radius, x.shape, x.tobytes())
    state = _STATES.pop(key, None)
    if state is None:
        state = _initial_state(kind, x, radius, x_ref)
        if len(_STATES) >= STATE_CACHE:
            del _STATES[next(iter(_STATES))]
    _STATES[key] = state                 # the most recent last: the oldest goes first
    out: np.ndarray = state.copy()
    return out


def _initial_state(kind: str, x: np.ndarray, radius: float | None, x_ref: np.ndarray | None) -> np.ndarray:
    """:func:`initial_state`, computed."""
    if kind == "seat":
        seat: np.ndarray = x.mean(axis=0)
        return seat
    if kind == "sphere":
        try:
            fit = geometry.fit_sphere(x, radius)
            c, rad = fit.centre, fit.radius
        except NumericalError:
            c, rad = x.mean(axis=0), 0.0
        return np.concatenate([c, [radius if radius is not None else rad]])
    if kind in ("ring", "cylinder"):
        try:
            p0, u0, rad = geometry.fit_ring_axis(x)
        except NumericalError:
            p0, u0, rad = x.mean(axis=0), np.array([0.0, 0.0, 1.0]), 0.0
        e1, e2 = geometry.perpendicular_basis(u0)
        return np.concatenate([p0, u0, e1, e2, [radius if radius is not None else rad]])
    if kind == "plane":
        try:
            plane = geometry.fit_plane(x)
            n0, h = plane.normal, plane.offset
        except NumericalError:
            n0, h = np.array([0.0, 0.0, 1.0]), float(x.mean(axis=0)[2])
        e1, e2 = geometry.perpendicular_basis(n0)
        return np.concatenate([n0, e1, e2, [h]])
    if kind == "reference":
        if x_ref is None:
            raise ValueError("a reference instance starts from its reference coordinates x_ref")
        rot, t = geometry.kabsch(x, x_ref)
        return frame_state(_transform(rot, t))
    raise ValueError(f"unknown residual kind {kind!r}")


def _transform(rot: ArrayLike, t: ArrayLike) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, t
    return out


def frame_state(transform: ArrayLike) -> np.ndarray:
    """The packed ``reference`` state (12,) of a 4x4 transform ``T_ref_base``."""
    t = np.asarray(transform, float)
    return np.concatenate([t[:3, :3].reshape(-1, order="F"), t[:3, 3]])


def frame_of(state: ArrayLike) -> np.ndarray:
    """The 4x4 transform of a packed ``reference`` state (the inverse of :func:`frame_state`)."""
    s = np.asarray(state)
    return _transform(s[0:9].reshape(3, 3, order="F"), s[9:12])


#: most rounds of :func:`tracker_start`'s alternation, and the change of every offset [m] that ends it
TRACKER_ROUNDS, TRACKER_TOL = 200, 1e-8


def tracker_start(base: np.ndarray, turn: np.ndarray, x_ref: np.ndarray, frame: np.ndarray, marker: np.ndarray,
                  frames: list[int], markers: list[int], held_frames: list[np.ndarray | None],
                  held_offsets: list[np.ndarray | None]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Starting states of the reference frames and marker offsets (the algebraic first fit).

    Row ``j`` of the reference rows sees ``x_ref[j] = R_s (base[j] + turn[j] o_m) + t_s`` with ``s =
    frame[j]`` and ``m = marker[j]`` (instance indices; -1: no marker, ``turn[j]`` zero), ``base`` [m] the
    tip point (or a seat centre), ``turn`` (n, 3, 3) d x / d o (the tip frame's axes in the base frame).
    Alternating least squares, each step exact in its block so that the cost never rises: every rotation
    ``R_s`` by Kabsch (:func:`arm_model.geometry.kabsch`) with the offsets held, then every translation
    ``t_s`` and offset ``o_m`` together by linear least squares with the rotations held (the translations
    and offsets are strongly coupled; the rotations far less), from offsets zero, until no offset moves by
    more than :data:`TRACKER_TOL` (at most :data:`TRACKER_ROUNDS` rounds; the Levenberg-Marquardt fit
    that follows polishes the rest). Held frames / offsets (``held_*`` not None, in the order of
    ``frames`` / ``markers``) stay as given. Returns (frame states, offset states) in the order of
    ``frames``, ``markers``."""
    fidx = np.array([frames.index(f) for f in frame], dtype=int)
    midx = np.array([markers.index(m) if m >= 0 else -1 for m in marker], dtype=int)
    offsets = np.array([np.zeros(3) if h is None else np.asarray(h, float) for h in held_offsets]).reshape(-1, 3)
    free_f = [k for k, h in enumerate(held_frames) if h is None]
    free_o = [k for k, h in enumerate(held_offsets) if h is None]
    tf = [np.eye(4) if h is None else frame_of(h) for h in held_frames]    # a free frame: set by the first round
    for _ in range(TRACKER_ROUNDS):
        x = base + np.einsum("nij,nj->ni", turn, _row_offsets(offsets, midx))
        for k in free_f:
            sel = fidx == k
            tf[k] = _transform(*geometry.kabsch(x[sel], x_ref[sel]))
        if not free_o:
            break
        new = _translations_and_offsets(base, turn, x_ref, fidx, midx, tf, free_f, offsets, free_o)
        moved = float(np.max(np.abs(new - offsets)))
        offsets = new
        if moved <= TRACKER_TOL:
            break
    return [frame_state(t) for t in tf], list(offsets)


def _row_offsets(offsets: np.ndarray, midx: np.ndarray) -> np.ndarray:
    """(n, 3) each row's marker offset (zero for a row without a marker)."""
    if not len(offsets):
        return np.zeros((len(midx), 3))
    return np.where((midx >= 0)[:, None], offsets[np.maximum(midx, 0)], 0.0)


def _translations_and_offsets(base: np.ndarray, turn: np.ndarray, x_ref: np.ndarray, fidx: np.ndarray,
                              midx: np.ndarray, tf: list[np.ndarray], free_f: list[int], offsets: np.ndarray,
                              free_o: list[int]) -> np.ndarray:
    """The offsets of :func:`tracker_start`'s linear step: ``x_ref - R_s base = t_s + R_s turn o_m`` in least
    squares over the free translations and offsets, the rotations (and the held parts) fixed; the free
    frames' translations in ``tf`` are updated in place; returns the new offsets (K, 3)."""
    rot = np.array([t[:3, :3] for t in tf])[fidx]
    rhs = x_ref - np.einsum("nij,nj->ni", rot, base)
    a_o = np.einsum("nij,njk->nik", rot, turn)                           # (n, 3, 3): d / d o_m
    cols = 3 * (len(free_f) + len(free_o))
    a = np.zeros((len(base), 3, cols))
    for c, k in enumerate(free_f):
        a[fidx == k, :, 3 * c:3 * c + 3] = np.eye(3)
    held_t = np.array([np.zeros(3) if k in free_f else tf[k][:3, 3] for k in range(len(tf))])[fidx]
    rhs = rhs - held_t
    held_o = [k for k in range(len(offsets)) if k not in free_o]
    for k in held_o:
        sel = midx == k
        rhs[sel] -= np.einsum("nij,j->ni", a_o[sel], offsets[k])
    for c, k in enumerate(free_o):
        sel = midx == k
        a[sel, :, 3 * (len(free_f) + c):3 * (len(free_f) + c) + 3] = a_o[sel]
    sol = np.linalg.lstsq(a.reshape(-1, cols), rhs.reshape(-1), rcond=None)[0]
    for c, k in enumerate(free_f):
        tf[k] = tf[k].copy()
        tf[k][:3, 3] = sol[3 * c:3 * c + 3]
    new: np.ndarray = offsets.copy()
    for c, k in enumerate(free_o):
        new[k] = sol[3 * (len(free_f) + c):3 * (len(free_f) + c) + 3]
    return new


def retract(kind: str, state: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """New packed state after the increment ``theta`` (evaluated at zero by the residuals)."""
    s = state.copy()
    if kind in ("seat", "marker"):
        moved: np.ndarray = s + theta[:3]
        return moved
    if kind == "sphere":
        s[:3] += theta[:3]
        if len(theta) > 3:
            s[3] += theta[3]
        return s
    if kind in ("ring", "cylinder"):
        p0, u0, e1, e2 = s[0:3], s[3:6], s[6:9], s[9:12]
        p = p0 + theta[0] * e1 + theta[1] * e2
        u = u0 + theta[2] * e1 + theta[3] * e2
        u /= np.linalg.norm(u)
        f1, f2 = geometry.perpendicular_basis(u)
        radius = s[12] + (theta[4] if len(theta) > 4 else 0.0)
        return np.concatenate([p, u, f1, f2, [radius]])
    if kind == "plane":
        n0, e1, e2, h = s[0:3], s[3:6], s[6:9], s[9]
        n = n0 + theta[0] * e1 + theta[1] * e2
        n /= np.linalg.norm(n)
        f1, f2 = geometry.perpendicular_basis(n)
        return np.concatenate([n, f1, f2, [h + theta[2]]])
    if kind == "reference":
        rot = s[0:9].reshape(3, 3, order="F")
        # the same x-y-z angles as the CasADi residual; from_matrix keeps it a rotation to the last bit
        rot = Rotation.from_matrix(geometry.rotation_xyz(theta[3:6]) @ rot).as_matrix()
        return np.concatenate([rot.reshape(-1, order="F"), s[9:12] + theta[0:3]])
    raise ValueError(f"unknown residual kind {kind!r}")


def centre_of(kind: str, state: np.ndarray) -> np.ndarray | None:
    """The centre [m] of a seat or sphere state (the point a distance refers to), else None."""
    return state[:3].copy() if kind in CENTRE_KINDS else None
