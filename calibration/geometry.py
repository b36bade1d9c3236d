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
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

__all__ = ["Kind", "KINDS", "kind_function", "distance_function", "initial_state", "retract",
           "rotation_xyz", "centre_of", "perpendicular_basis", "fit_sphere", "fit_circle_axis",
           "kabsch", "rpy_of"]


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
}


def n_theta(kind: str, free_radius: bool) -> int:
    k = KINDS[kind]
    return k.n_theta + (1 if free_radius and kind in ("sphere", "ring", "cylinder") else 0)


def _normalize(ca, v):
    return v / ca.sqrt(ca.dot(v, v))


def _rot_xyz_ca(ca, w):
    cx, sx, cy, sy, cz, sz = ca.cos(w[0]), ca.sin(w[0]), ca.cos(w[1]), ca.sin(w[1]), ca.cos(w[2]), ca.sin(w[2])
    rx = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, cx, -sx), ca.horzcat(0, sx, cx))
    ry = ca.vertcat(ca.horzcat(cy, 0, sy), ca.horzcat(0, 1, 0), ca.horzcat(-sy, 0, cy))
    rz = ca.vertcat(ca.horzcat(cz, -sz, 0), ca.horzcat(sz, cz, 0), ca.horzcat(0, 0, 1))
    return rz @ ry @ rx


@lru_cache(maxsize=None)
def kind_function(kind: str, free_radius: bool = False):
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


@lru_cache(maxsize=None)
def distance_function():
    """CasADi ``d(ca[3], cb[3], L) -> (r, dr_dca[1x3], dr_dcb[1x3])``, ``r = |ca - cb| - L`` [m]."""
    import casadi as ca

    a, b, length = ca.SX.sym("ca", 3), ca.SX.sym("cb", 3), ca.SX.sym("L")
    r = ca.norm_2(a - b) - length
    return ca.Function("res_distance", [a, b, length], [r, ca.jacobian(r, a), ca.jacobian(r, b)],
                       ["ca", "cb", "L"], ["r", "dr_dca", "dr_dcb"])


# ---------------------------------------------------------------------------------------------
# numeric helpers (starting values and state updates)

def rotation_xyz(w) -> np.ndarray:
    """``Rz(w[2]) Ry(w[1]) Rx(w[0])`` (3x3)."""
    cx, sx, cy, sy, cz, sz = np.cos(w[0]), np.sin(w[0]), np.cos(w[1]), np.sin(w[1]), np.cos(w[2]), np.sin(w[2])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def rpy_of(rot: np.ndarray) -> np.ndarray:
    """(roll, pitch, yaw) [rad] with ``rot = Rz(yaw) Ry(pitch) Rx(roll)``."""
    pitch = np.arcsin(-np.clip(rot[2, 0], -1.0, 1.0))
    return np.array([np.arctan2(rot[2, 1], rot[2, 2]), pitch, np.arctan2(rot[1, 0], rot[0, 0])])


def perpendicular_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit vector ``u`` to a right-handed orthonormal basis."""
    u = u / np.linalg.norm(u)
    helper = np.eye(3)[int(np.argmin(np.abs(u)))]
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(u, e1)


def fit_sphere(x: np.ndarray) -> tuple[np.ndarray, float]:
    """Algebraic sphere through points (n >= 4, not coplanar): centre [m], radius [m]."""
    a = np.column_stack([2 * x, np.ones(len(x))])
    sol = np.linalg.lstsq(a, np.sum(x * x, axis=1), rcond=None)[0]
    c = sol[:3]
    return c, float(np.sqrt(max(sol[3] + c @ c, 0.0)))


def _fit_circle_2d(uv: np.ndarray) -> tuple[np.ndarray, float, float]:
    a = np.column_stack([2 * uv, np.ones(len(uv))])
    sol = np.linalg.lstsq(a, np.sum(uv * uv, axis=1), rcond=None)[0]
    c = sol[:2]
    radius = float(np.sqrt(max(sol[2] + c @ c, 0.0)))
    rms = float(np.sqrt(np.mean((np.linalg.norm(uv - c, axis=1) - radius) ** 2)))
    return c, radius, rms


def fit_circle_axis(x: np.ndarray, radius: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Starting axis (point [m], unit direction) of a cylinder through points ``x``: the axis is
    taken along the principal direction (least or most spread) whose projected points fit a circle
    best (of the given ``radius`` if known)."""
    mean = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - mean)
    best = None
    for u in (vt[2], vt[0]):
        e1, e2 = perpendicular_basis(u)
        uv = np.column_stack([(x - mean) @ e1, (x - mean) @ e2])
        c, rad, rms = _fit_circle_2d(uv)
        score = rms + (abs(rad - radius) if radius is not None else 0.0)
        if best is None or score < best[0]:
            best = (score, mean + c[0] * e1 + c[1] * e2, u, rad)
    return _refine_axis(x, best[1], best[2], radius if radius is not None else best[3])


def _refine_axis(x, p0, u0, radius):
    """A few Levenberg-Marquardt steps (scipy) on the axis, radius fixed (or fitted if None)."""
    from scipy.optimize import least_squares
    e1, e2 = perpendicular_basis(u0)

    def axis(t):
        u = u0 + t[2] * e1 + t[3] * e2
        return p0 + t[0] * e1 + t[1] * e2, u / np.linalg.norm(u)

    def res(t):
        p, u = axis(t)
        v = x - p
        return np.linalg.norm(v - np.outer(v @ u, u), axis=1) - (radius if radius is not None else t[4])

    t0 = np.zeros(4 if radius is not None else 5)
    if radius is None:
        t0[4] = np.mean(np.linalg.norm((x - p0) - np.outer((x - p0) @ u0, u0), axis=1))
    sol = least_squares(res, t0, method="lm", max_nfev=200)
    p, u = axis(sol.x)
    return p, u


def kabsch(x_base: np.ndarray, x_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid ``(R, t)`` with ``x_ref ~ R x_base + t`` (least squares, proper rotation)."""
    mb, mr = x_base.mean(axis=0), x_ref.mean(axis=0)
    h = (x_base - mb).T @ (x_ref - mr)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, mr - rot @ mb


def initial_state(kind: str, x: np.ndarray, radius: float | None = None, x_ref: np.ndarray | None = None) -> np.ndarray:
    """Packed starting state of one instance from its ball centres ``x`` (n, 3) [m].

    ``radius``: the offset radius of sphere, ring, cylinder [m] (None: fitted).
    """
    if kind == "seat":
        return x.mean(axis=0)
    if kind == "sphere":
        if len(x) >= 4:
            c, rad = fit_sphere(x)
        else:
            c, rad = x.mean(axis=0), 0.0
        if radius is not None and len(x) >= 1:
            # move the centre along the mean outward direction so that the known radius fits
            c = _sphere_centre_known_radius(x, c, radius)
        return np.concatenate([c, [radius if radius is not None else rad]])
    if kind in ("ring", "cylinder"):
        p0, u0 = fit_circle_axis(x, radius)
        e1, e2 = perpendicular_basis(u0)
        if radius is None:
            v = x - p0
            radius = float(np.mean(np.linalg.norm(v - np.outer(v @ u0, u0), axis=1)))
        return np.concatenate([p0, u0, e1, e2, [radius]])
    if kind == "plane":
        mean = x.mean(axis=0)
        _, _, vt = np.linalg.svd(x - mean)
        n0 = vt[2]
        e1, e2 = perpendicular_basis(n0)
        return np.concatenate([n0, e1, e2, [float(n0 @ mean)]])
    if kind == "reference":
        rot, t = kabsch(x, x_ref)
        return np.concatenate([rot.reshape(-1, order="F"), t])
    raise ValueError(f"unknown residual kind {kind!r}")


def _sphere_centre_known_radius(x, c, radius, iters: int = 50):
    """Gauss-Newton on the centre with the radius fixed, from ``c``."""
    for _ in range(iters):
        v = x - c
        d = np.linalg.norm(v, axis=1)
        r = d - radius
        jac = -v / d[:, None]
        step = np.linalg.lstsq(jac, -r, rcond=None)[0]
        c = c + step
        if np.linalg.norm(step) < 1e-13:
            break
    return c


def retract(kind: str, state: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """New packed state after the increment ``theta`` (evaluated at zero by the residuals)."""
    s = state.copy()
    if kind == "seat":
        return s + theta[:3]
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
        f1, f2 = perpendicular_basis(u)
        radius = s[12] + (theta[4] if len(theta) > 4 else 0.0)
        return np.concatenate([p, u, f1, f2, [radius]])
    if kind == "plane":
        n0, e1, e2, h = s[0:3], s[3:6], s[6:9], s[9]
        n = n0 + theta[0] * e1 + theta[1] * e2
        n /= np.linalg.norm(n)
        f1, f2 = perpendicular_basis(n)
        return np.concatenate([n, f1, f2, [h + theta[2]]])
    if kind == "reference":
        rot = s[0:9].reshape(3, 3, order="F")
        rot = rotation_xyz(theta[3:6]) @ rot
        u, _, vt = np.linalg.svd(rot)           # keep it a rotation to the last bit
        rot = u @ vt
        return np.concatenate([rot.reshape(-1, order="F"), s[9:12] + theta[0:3]])
    raise ValueError(f"unknown residual kind {kind!r}")


def centre_of(kind: str, state: np.ndarray) -> np.ndarray | None:
    """The centre [m] of a seat or sphere state (the point a distance refers to), else None."""
    return state[:3].copy() if kind in ("seat", "sphere") else None
