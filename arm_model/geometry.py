"""Geometry of artefacts: the one place for fits, ball compensation and rotations.

Every fit of the toolkit lives here and is used by the simulator, the calibration (starting values of
its nuisance states), the ring pipeline (:mod:`correction`) and the viewer:

* circles (:func:`kasa_circle` algebraic, :func:`fit_circle_2d` geometric), cylinders
  (:func:`fit_cylinder`, orthogonal distances), circles of a cylinder's rows (:func:`fit_row_circles`),
  a ring's axis even when it was probed in one plane (:func:`fit_ring_axis`), spheres
  (:func:`fit_sphere`, free or known radius), planes (:func:`fit_plane`) and the smallest sphere enclosing
  points (:func:`smallest_enclosing_sphere`, Welzl);
* ball compensation: the radius on which the ball centres of a feature lie (:func:`ball_centre_radius`)
  and back (:func:`feature_diameter`); an inner ring measured with ball centres (:func:`ring_fit`);
* standard uncertainties of the fitted radii (``u_radius``) from the residuals and the Jacobian at the
  solution, ``s^2 (J^T J)^-1`` with ``s^2 = sum r^2 / (N - parameters)`` (the scatter of the points
  about the fitted shape, nothing else: the uncertainty of the ball diameter is not included);
* rotations through :class:`scipy.spatial.transform.Rotation` (:func:`rotation_xyz` and its inverse
  :func:`rpy_from_matrix`, :func:`random_rotation`, :func:`kabsch`), frames from a direction
  (:func:`perpendicular_basis`, :func:`frame_along`), random directions in a cone (:func:`cone_directions`).

Geometric fits minimise orthogonal distances with Levenberg-Marquardt (scipy ``least_squares``,
analytic Jacobians) from an algebraic seed; the solver status and the rank of the Jacobian at the
solution are checked, and a failure raises :class:`arm_model.NumericalError` (points that do not
determine the shape: too few, coplanar, collinear). All lengths in the unit of the input (the code
uses metres); angles [rad].
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from .chain import cross
from .errors import NumericalError

__all__ = ["CircleFit", "CylinderFit", "RingFit", "SphereFit", "PlaneFit", "kasa_circle", "fit_circle_2d",
           "fit_cylinder", "fit_row_circles", "split_rows", "ring_fit", "fit_ring_axis", "fit_sphere", "fit_plane",
           "smallest_enclosing_sphere", "ball_centre_radius", "feature_diameter", "perpendicular_basis",
           "angle_frame", "rotation_xyz", "rpy_from_matrix", "frame_along", "random_rotation", "kabsch",
           "sphere_seed", "cone_directions"]


# ---------------------------------------------------------------------------------------------
# frames and rotations

def perpendicular_basis(u: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``(e1, e2)`` completing the unit vector ``u`` to a right-handed orthonormal
    frame ``(e1, e2, u)``: ``e1 = u x ref / |u x ref|`` with ref = base x (base y when ``u`` is within
    26 degrees of x), ``e2 = u x e1``."""
    u = np.asarray(u, float)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = cross(u, ref)
    e1 /= np.linalg.norm(e1)
    return e1, cross(u, e1)


def angle_frame(a: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Reference directions for angular positions about the unit axis ``a``: the projection of base x
    (or of base y when x is nearly parallel to ``a``), then ``a x e1``."""
    a = np.asarray(a, float)
    for ref in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        e1 = ref - (ref @ a) * a
        if np.linalg.norm(e1) > 0.1:
            e1 /= np.linalg.norm(e1)
            return e1, cross(a, e1)
    raise AssertionError("unreachable: base x and y cannot both be parallel to a unit axis")


def rotation_xyz(w: ArrayLike) -> np.ndarray:
    """``Rz(w[2]) Ry(w[1]) Rx(w[0])`` (3x3): fixed-axis x-y-z angles [rad] (roll, pitch, yaw)."""
    rot: np.ndarray = Rotation.from_euler("xyz", np.asarray(w, float)).as_matrix()
    return rot


def rpy_from_matrix(r: ArrayLike) -> tuple[float, float, float]:
    """The angles ``(roll, pitch, yaw)`` [rad] of a rotation matrix, ``r = Rz(yaw) Ry(pitch) Rx(roll)``
    (the inverse of :func:`rotation_xyz`, URDF's ``rpy``), exact to rounding everywhere: near gimbal lock
    (pitch +-90 degrees) roll and yaw are each ill-determined but the matrix fixes their difference (or sum)
    from its large entries, which is taken from those; at the lock itself yaw is 0.

    (Angles read one by one, as scipy's ``as_euler`` does, reproduce a rotation 1e-11 from the lock only to
    about 1e-11: a URDF joint origin of a real robot, folded, lost that much against Pinocchio.)"""
    r = np.asarray(r, float)
    sp = -r[2, 0]
    cp = math.hypot(r[2, 1], r[2, 2])
    pitch = math.atan2(sp, math.hypot(r[0, 0], r[1, 0]))
    roll, yaw = math.atan2(r[2, 1], r[2, 2]), math.atan2(r[1, 0], r[0, 0])
    if cp > 0.1:
        return roll, pitch, yaw
    if cp < 1e-15:                        # the lock itself: the small entries are rounding noise
        roll = yaw = 0.0
    if sp > 0:      # r[0,1] - r[1,2] = (1 + sp) sin(roll - yaw), r[0,2] + r[1,1] = (1 + sp) cos(roll - yaw)
        big = math.atan2(r[0, 1] - r[1, 2], r[0, 2] + r[1, 1])
        small = roll - yaw
    else:           # r[0,1] + r[1,2] = (sp - 1) sin(roll + yaw), r[0,2] - r[1,1] = (sp - 1) cos(roll + yaw)
        big = math.atan2(-(r[0, 1] + r[1, 2]), -(r[0, 2] - r[1, 1]))
        small = roll + yaw
    big += 2 * math.pi * round((small - big) / (2 * math.pi))    # the branch nearest the small entries'
    other = roll + yaw if sp > 0 else roll - yaw                  # the combination the large entries leave
    if sp > 0:
        roll, yaw = (other + big) / 2, (other - big) / 2
    else:
        roll, yaw = (big + other) / 2, (big - other) / 2
    if cp < 1e-15:                        # yaw 0 at the lock (the roll carries the whole combination)
        roll, yaw = (roll - yaw if sp > 0 else roll + yaw), 0.0
    return roll, pitch, yaw


def frame_along(v: ArrayLike, axis: int) -> np.ndarray:
    """A rotation matrix (3, 3) whose column ``axis`` (0 x, 1 y, 2 z) is along the vector ``v`` (base
    ``axis`` when ``v`` is zero); the other two columns from :func:`perpendicular_basis` (a right-handed
    frame)."""
    v = np.asarray(v, float)
    n = np.linalg.norm(v)
    u = np.eye(3)[axis] if n < 1e-15 else v / n
    e1, e2 = perpendicular_basis(u)
    cols: list[np.ndarray] = [u, u, u]
    cols[axis], cols[(axis + 1) % 3], cols[(axis + 2) % 3] = u, e1, e2
    return np.column_stack(cols)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A (3, 3) rotation drawn uniformly: a unit quaternion ``(w, x, y, z)`` from four normal draws of
    ``rng`` (the same draws, in the same order, whatever scipy's own sampler does)."""
    qv = rng.normal(size=4)
    rot: np.ndarray = Rotation.from_quat(qv[[1, 2, 3, 0]]).as_matrix()
    return rot


def cone_directions(rng: np.random.Generator, axis: ArrayLike, half_angle: float, n: int) -> np.ndarray:
    """(n, 3) unit directions uniform on the spherical cap of ``half_angle`` [rad] about ``axis``."""
    axis = np.asarray(axis, float)
    e1, e2 = perpendicular_basis(axis)
    cos_t = rng.uniform(np.cos(half_angle), 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    sin_t = np.sqrt(np.maximum(0.0, 1 - cos_t ** 2))
    out: np.ndarray = cos_t[:, None] * axis + sin_t[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    return out


def kabsch(x_from: ArrayLike, x_to: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Rigid ``(R, t)`` with ``x_to ~ R x_from + t`` in least squares, ``R`` a proper rotation (Kabsch,
    :meth:`scipy.spatial.transform.Rotation.align_vectors`). Fewer than three non-collinear points do
    not determine ``R``; the answer is then one of the rotations that fit."""
    import warnings

    x_from, x_to = _points(x_from, 1, "rotation"), _points(x_to, 1, "rotation")
    if x_from.shape != x_to.shape:
        raise ValueError(f"x_from and x_to must have one shape, got {x_from.shape} and {x_to.shape}")
    mf, mt = x_from.mean(axis=0), x_to.mean(axis=0)
    with warnings.catch_warnings():     # rank-deficient sets: any of the optimal rotations will do
        warnings.simplefilter("ignore", UserWarning)
        rot = Rotation.align_vectors(x_to - mt, x_from - mf)[0].as_matrix()
    return rot, mt - rot @ mf


# ---------------------------------------------------------------------------------------------
# ball compensation

#: feature kinds probed from outside (ball centres farther from the centre than the surface)
_OUTER = ("sphere",)
#: feature kinds probed from inside
_INNER = ("ring", "cylinder")


def ball_centre_radius(kind: str, diameter: float, ball_diameter: float) -> float:
    """Radius [m] of the surface the ball centres lie on, for a feature of certified ``diameter`` [m]:
    ``(D + b) / 2`` for a sphere (probed from outside), ``(D - b) / 2`` for a ring or cylinder (probed
    from inside)."""
    if kind in _OUTER:
        return (diameter + ball_diameter) / 2.0
    if kind in _INNER:
        return (diameter - ball_diameter) / 2.0
    raise ValueError(f"a {kind!r} has no diameter to compensate")


def feature_diameter(kind: str, centre_radius: float, ball_diameter: float) -> float:
    """The feature's diameter [m] from the radius of its ball centres (inverse of
    :func:`ball_centre_radius`)."""
    if kind in _OUTER:
        return 2.0 * centre_radius - ball_diameter
    if kind in _INNER:
        return 2.0 * centre_radius + ball_diameter
    raise ValueError(f"a {kind!r} has no diameter to compensate")


# ---------------------------------------------------------------------------------------------
# circles, cylinders, rings

# relative rank threshold of the column-normalised Jacobian at the solution
_RANK_TOL = 1e-9


class _RadialFit:
    """Diameter and form error of a fit with ``radius`` and radial ``residuals`` [m]."""
    radius: float
    residuals: np.ndarray

    @property
    def diameter(self) -> float:
        return 2.0 * self.radius

    @property
    def form_error(self) -> float:
        """max - min radial deviation [m]."""
        return float(self.residuals.max() - self.residuals.min())


@dataclass(frozen=True)
class CylinderFit(_RadialFit):
    """A fitted cylinder.

    Attributes:
        point: (3,) the point of the axis nearest the centroid of the data [m].
        axis: (3,) unit axis direction (sign: positive dot product with the seed principal direction,
            or with base z when that is not defined).
        radius: fitted radius [m].
        residuals: (N,) orthogonal distances to the surface, outward positive [m]; they sum to zero.
        heights: (N,) coordinate of each point along the axis, from ``point`` [m].
        angles: (N,) angular position of each point about the axis [rad] in [0, 2 pi), measured from
            the projection of the base x axis (or y when x is nearly parallel to the axis), right-handed
            about ``axis``.
        radial: (N, 3) unit vectors from the axis to each point, perpendicular to the axis.
        nfev: function evaluations used.
        u_radius: standard uncertainty of ``radius`` from the scatter of the points [m] (NaN with
            no more points than parameters).
    """
    point: np.ndarray
    axis: np.ndarray
    radius: float
    residuals: np.ndarray
    heights: np.ndarray
    angles: np.ndarray
    radial: np.ndarray
    nfev: int
    u_radius: float = math.nan

    def to_axis(self, p: ArrayLike) -> np.ndarray:
        """(N, 3) unit vectors from points ``p`` (N, 3) towards the axis, perpendicular to it (Eq. 3-7 of
        the seed paper: the intersection of the plane through the point normal to the axis)."""
        d = np.asarray(p, float) - self.point
        perp = d - np.outer(d @ self.axis, self.axis)
        n = np.linalg.norm(perp, axis=1)
        if np.any(n == 0):
            raise NumericalError("a point lies on the cylinder axis: no direction to the axis")
        out: np.ndarray = -perp / n[:, None]
        return out


@dataclass(frozen=True)
class CircleFit(_RadialFit):
    """A fitted circle in a plane: ``centre`` (2,) in plane coordinates, ``radius``, ``residuals`` (N,)
    (outward positive) [m], for circles of a cylinder's rows ``centre_3d`` (3,), ``height`` [m], and
    the standard uncertainty ``u_radius`` [m] (NaN with 3 points)."""
    centre: np.ndarray
    radius: float
    residuals: np.ndarray
    centre_3d: np.ndarray | None = None
    height: float | None = None
    u_radius: float = math.nan


@dataclass(frozen=True)
class RingFit:
    """An inner ring (ring gauge) measured from inside with ball centres.

    Attributes:
        cylinder: the fit of the ball centres (centre line of the ball).
        ball_diameter: [m].
        diameter: ring diameter = centre-line diameter + ball diameter [m].
        form_error: max - min radial deviation [m] (the ball compensation does not change it).
        point_errors: (N,) each contact point's radial error against ``reference_diameter`` / 2 [m]
            (the seed paper's Figure 6), or against the fitted radius when no reference is given.
        angles_deg: (N,) angular position of each point [deg].
        reference_diameter: [m] or None.
        centres: (N, 3) the ball centres fitted [m].
    """
    cylinder: CylinderFit
    ball_diameter: float
    diameter: float
    form_error: float
    point_errors: np.ndarray
    angles_deg: np.ndarray
    reference_diameter: float | None
    centres: np.ndarray | None = None

    def rows(self, rows: int | None = None) -> list[dict[str, float | None]]:
        """Circles per row (see :func:`fit_row_circles`), lowest first: ``height`` along the axis,
        ``diameter`` (ball compensated) and ``form_error`` [m]."""
        if self.centres is None:
            raise ValueError("this ring fit keeps no ball centres to split in rows")
        return [{"height": c.height, "diameter": c.diameter + self.ball_diameter, "form_error": c.form_error}
                for c in fit_row_circles(self.centres, self.cylinder, rows)]

    @property
    def u_diameter(self) -> float:
        """Standard uncertainty of ``diameter`` from the scatter of the points [m] (the ball diameter's
        own uncertainty is not included)."""
        return 2.0 * self.cylinder.u_radius

    @property
    def diameter_error(self) -> float | None:
        """Measured minus reference diameter [m], or None without a reference."""
        return None if self.reference_diameter is None else self.diameter - self.reference_diameter


def kasa_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Algebraic (Kasa) circle through 2-D points: linear least squares of
    ``x^2 + y^2 = 2 cx x + 2 cy y + k``. Returns (centre (2,), radius)."""
    xy = np.asarray(xy, float)
    A = np.column_stack([2 * xy, np.ones(len(xy))])
    b = (xy**2).sum(axis=1)
    sol, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
    if rank < 3:
        raise NumericalError("points are collinear or too few for a circle (algebraic seed is rank deficient)")
    c = sol[:2]
    r2 = sol[2] + c @ c
    if r2 <= 0:
        raise NumericalError("algebraic circle seed has no real radius")
    return c, math.sqrt(r2)


def _param_std(jac: np.ndarray, resid: np.ndarray) -> np.ndarray:
    """Standard uncertainties of least-squares parameters: sqrt(diag(s^2 (J^T J)^-1)),
    ``s^2 = |r|^2 / (N - parameters)``; NaN when N <= parameters."""
    n, k = jac.shape
    if n <= k:
        return np.full(k, np.nan)
    s2 = float(resid @ resid) / (n - k)
    std: np.ndarray = np.sqrt(np.maximum(np.diag(np.linalg.pinv(jac.T @ jac)), 0.0) * s2)
    return std


def _check_status(res: Any, what: str) -> None:
    if not res.success or res.status <= 0:
        raise NumericalError(f"{what}: the least-squares solver did not converge "
                             f"(status {res.status}: {res.message})")
    if not np.all(np.isfinite(res.x)):
        raise NumericalError(f"{what}: non-finite parameters")


def _check_rank(jac: np.ndarray, what: str, names: tuple[str, ...]) -> None:
    norms = np.linalg.norm(jac, axis=0)
    if np.any(norms == 0):
        zero = ", ".join(n for n, v in zip(names, norms, strict=True) if v == 0)
        raise NumericalError(f"{what}: parameter(s) {zero} "
                             "not determined by the points (rank-deficient Jacobian)")
    s = np.linalg.svd(jac / norms, compute_uv=False)
    if s[-1] < _RANK_TOL * s[0]:
        raise NumericalError(f"{what}: rank-deficient Jacobian at the solution (condition {s[0] / s[-1]:.2g}); "
                             "the points do not determine the fit")


#: points whose RMS spread about their centroid is at most this share of their largest coordinate coincide: the
#: spread is the rounding of double precision (a pose repeated gives 1e-17 m, and was called "collinear")
COINCIDE = 1e-12


def _normalised(p: np.ndarray, what: str) -> tuple[np.ndarray, float, np.ndarray]:
    """``(origin, scale, z)``: the points about their centroid in units of their RMS distance from it (the
    fits solve on ``z``, well scaled whatever the unit and placement)."""
    o = p.mean(axis=0)
    scale = float(np.sqrt(((p - o) ** 2).sum(axis=1).mean()))
    if scale <= COINCIDE * float(np.abs(p).max()):      # a spread of rounding (one pose repeated) is none
        raise NumericalError(f"all points coincide (to rounding): no {what}")
    return o, scale, (p - o) / scale


Fn = Callable[[np.ndarray], np.ndarray]


#: Gauss-Newton steps :func:`_gauss_newton` takes at most, and the relative step that ends it
GN_STEPS, GN_XTOL = 30, 1e-13


def _gauss_newton(fun: Fn, jac: Fn, x0: ArrayLike) -> Any:
    """Undamped Gauss-Newton from ``x0`` while every step lowers the cost, to a relative step below
    :data:`GN_XTOL`: the result (``x``, ``fun``), or None when a step does not lower the cost, the Jacobian is
    rank-deficient or it has not converged in :data:`GN_STEPS` steps (the caller then runs Levenberg-Marquardt).
    From a good seed (the algebraic sphere) it reaches the same minimum in a few steps, at a fraction of the cost
    of the general solver's set-up."""
    x = np.array(x0, dtype=float)
    r = fun(x)
    cost = float(r @ r)
    for _ in range(GN_STEPS):
        step, _, rank, _ = np.linalg.lstsq(jac(x), -r, rcond=None)
        if rank < len(x) or not np.all(np.isfinite(step)):
            return None
        x_new = x + step
        r_new = fun(x_new)
        cost_new = float(r_new @ r_new)
        if not cost_new <= cost * (1 + 1e-12) + 1e-300:
            return None
        x, r, cost = x_new, r_new, cost_new
        if np.linalg.norm(step) <= GN_XTOL * (1.0 + np.linalg.norm(x)):
            return SimpleNamespace(x=x, fun=r)
    return None


def _solve(fun: Fn, jac: Fn, x0: ArrayLike, what: str, names: tuple[str, ...], gauss_newton: bool = False,
           **kw: Any) -> tuple[Any, np.ndarray]:
    """Levenberg-Marquardt to tight tolerances, its status and the rank of its Jacobian checked:
    ``(result, standard uncertainties of the parameters)``. ``gauss_newton``: try :func:`_gauss_newton` first
    (Levenberg-Marquardt only when it does not converge)."""
    res = _gauss_newton(fun, jac, x0) if gauss_newton else None
    if res is None:
        from scipy.optimize import least_squares  # here: a command that fits nothing starts faster
        res = least_squares(fun, x0, jac=jac, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14, **kw)
        _check_status(res, what)
    jac_x = jac(res.x)
    _check_rank(jac_x, what, names)
    return res, _param_std(jac_x, res.fun)


def fit_circle_2d(xy: ArrayLike) -> CircleFit:
    """Geometric least-squares circle through 2-D points (N >= 3), Kasa seed then Levenberg-Marquardt.

    Args:
        xy: (N, 2) points [m].
    """
    xy = _points(xy, 0, "circle", dim=2)
    if len(xy) < 3:
        raise ValueError(f"need (N >= 3, 2) points, got {xy.shape}")
    o, s, z = _normalised(xy, "circle")
    c0, r0 = kasa_circle(z)

    def fun(x: np.ndarray) -> np.ndarray:
        d = z - x[:2]
        r: np.ndarray = np.hypot(d[:, 0], d[:, 1]) - x[2]
        return r

    def jac(x: np.ndarray) -> np.ndarray:
        d = z - x[:2]
        rho = np.hypot(d[:, 0], d[:, 1])
        return np.column_stack([-d / rho[:, None], -np.ones(len(z))])

    res, u = _solve(fun, jac, np.r_[c0, r0], "circle fit", ("centre x", "centre y", "radius"))
    centre = o + s * res.x[:2]
    return CircleFit(centre=centre, radius=float(s * res.x[2]), residuals=s * fun(res.x), u_radius=float(s * u[2]))


def fit_cylinder(points: ArrayLike, axis_hint: ArrayLike | None = None) -> CylinderFit:
    """Orthogonal-distance least-squares cylinder through points (N >= 5).

    Args:
        points: (N, 3) points [m], any frame; the result is expressed in the same frame.
        axis_hint: optional (3,) approximate axis direction; if given it is used as the seed direction
            instead of the principal-direction search (it only seeds: the axis is fitted).

    Raises:
        NumericalError: the solver did not converge, or the points do not determine a cylinder (all in
            one plane normal to the axis, too few, collinear).
    """
    p = _points(points, 0, "cylinder")
    if len(p) < 5:
        raise NumericalError(f"a cylinder needs at least 5 points, got {len(p)}")
    centroid, scale, z = _normalised(p, "cylinder")

    # algebraic seed: principal directions as candidate axes, Kasa circle in the normal plane
    if axis_hint is not None:
        a = np.asarray(axis_hint, float)
        candidates = [a / np.linalg.norm(a)]
    else:
        _, _, vt = np.linalg.svd(z, full_matrices=False)
        candidates = list(vt)
    best = None
    for a0 in candidates:
        e1, e2 = perpendicular_basis(a0)
        uv = np.column_stack([z @ e1, z @ e2])
        try:
            c2, r0 = kasa_circle(uv)
        except NumericalError:
            continue
        rms = float(np.sqrt(np.mean((np.hypot(*(uv - c2).T) - r0) ** 2)))
        if best is None or rms < best[0]:
            best = (rms, a0, e1, e2, c2, r0)
    if best is None:
        raise NumericalError("no principal direction gives a circle seed: the points are collinear")
    _, a0, e1, e2, c2, r0 = best
    c0 = c2[0] * e1 + c2[1] * e2

    def geometry(x: np.ndarray) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
        w = a0 + x[2] * e1 + x[3] * e2
        nw = float(np.linalg.norm(w))
        a = w / nw
        c = c0 + x[0] * e1 + x[1] * e2
        d = z - c
        t = d @ a
        perp = d - np.outer(t, a)
        rho = np.linalg.norm(perp, axis=1)
        return a, nw, t, perp, rho

    def fun(x: np.ndarray) -> np.ndarray:
        r: np.ndarray = geometry(x)[4] - x[4]
        return r

    def jac(x: np.ndarray) -> np.ndarray:
        a, nw, t, perp, rho = geometry(x)
        if np.any(rho == 0):
            raise NumericalError("cylinder fit: a point lies on the current axis estimate")
        n = perp / rho[:, None]
        return np.column_stack([-n @ e1, -n @ e2, -t * (n @ e1) / nw, -t * (n @ e2) / nw,
                                -np.ones(len(z))])

    res, u = _solve(fun, jac, np.array([0.0, 0.0, 0.0, 0.0, r0]), "cylinder fit",
                       ("axis offset 1", "axis offset 2", "axis tilt 1", "axis tilt 2", "radius"), max_nfev=2000)
    a, _, t, perp, rho = geometry(res.x)
    if res.x[4] <= 0:
        raise NumericalError("cylinder fit converged to a non-positive radius")
    c = c0 + res.x[0] * e1 + res.x[1] * e2
    # axis point nearest the centroid (the origin of the scaled frame), unscaled
    c = c - (c @ a) * a
    sign = 1.0 if a @ a0 >= 0 else -1.0
    a = sign * a
    t = (z - c) @ a
    radial = perp / rho[:, None]
    f1, f2 = angle_frame(a)
    ang = np.mod(np.arctan2(radial @ f2, radial @ f1), 2 * np.pi)
    return CylinderFit(point=centroid + scale * c, axis=a, radius=float(scale * res.x[4]),
                       residuals=scale * (rho - res.x[4]), heights=scale * t, angles=ang, radial=radial,
                       nfev=int(res.nfev), u_radius=float(scale * u[4]))


def split_rows(heights: ArrayLike, rows: int | None = None) -> np.ndarray:
    """Row label (0 = lowest) of each point from its height along the axis.

    Args:
        heights: (N,) coordinate along the axis [m].
        rows: number of rows; None finds them: the sorted heights are cut at their k widest gaps, with k the
            count at which the k-th widest gap is the most times (and at least 3 times) wider than the
            (k+1)-th, i.e. than any gap left inside a row; every row must keep at least 3 points, else the
            points are one row.
    """
    h = np.asarray(heights, float)
    order = np.argsort(h)
    gaps = np.diff(h[order])
    if rows is None:
        desc = np.sort(gaps)[::-1]
        best, best_ratio = 0, 3.0
        for k in range(1, len(desc)):
            if (k + 1) * 3 > len(h):
                break
            ratio = desc[k - 1] / desc[k] if desc[k] > 0 else np.inf
            if ratio > best_ratio:
                cut = np.sort(np.argsort(gaps)[::-1][:k])
                sizes = np.diff(np.r_[0, cut + 1, len(h)])
                if np.all(sizes >= 3):
                    best, best_ratio = k, ratio
        cut = np.sort(np.argsort(gaps)[::-1][:best])
    else:
        if rows < 1 or rows > len(h):
            raise ValueError(f"rows must be in 1..{len(h)}, got {rows}")
        cut = np.sort(np.argsort(gaps)[::-1][: rows - 1])
    labels_sorted = np.zeros(len(h), int)
    for k in cut:
        labels_sorted[k + 1:] += 1
    out = np.empty(len(h), int)
    out[order] = labels_sorted
    return out


def fit_row_circles(points: ArrayLike, cylinder: CylinderFit, rows: int | None = None) -> list[CircleFit]:
    """Circles per row: the points of each row projected on the plane normal to the cylinder axis, a
    geometric circle fitted there (as arm software reports circles of a cylinder's sections).

    Args:
        points: (N, 3) [m], the points of ``cylinder``.
        cylinder: the cylinder fit giving the axis.
        rows: (N,) row labels, an int number of rows, or None to find the rows (:func:`split_rows`).

    Returns: one :class:`CircleFit` a row, lowest row first (``centre_3d`` on the row's mean height).
    """
    p = np.asarray(points, float)
    if rows is None or isinstance(rows, (int, np.integer)):
        labels = split_rows(cylinder.heights, None if rows is None else int(rows))
    else:
        labels = np.asarray(rows)
        if labels.shape != (len(p),):
            raise ValueError(f"rows must have one label a point ({len(p)}), got shape {labels.shape}")
    e1, e2 = angle_frame(cylinder.axis)
    out = []
    keys = sorted(set(labels.tolist()), key=lambda k: float(np.mean(cylinder.heights[labels == k])))
    for k in keys:
        m = labels == k
        d = p[m] - cylinder.point
        fit = fit_circle_2d(np.column_stack([d @ e1, d @ e2]))
        h = float(np.mean(d @ cylinder.axis))
        c3 = cylinder.point + fit.centre[0] * e1 + fit.centre[1] * e2 + h * cylinder.axis
        out.append(CircleFit(fit.centre, fit.radius, fit.residuals, c3, h, fit.u_radius))
    return out


def ring_fit(ball_centres: ArrayLike, ball_diameter: float, reference_diameter: float | None = None,
             axis_hint: ArrayLike | None = None) -> RingFit:
    """Fit an inner ring measured from inside with ball centres (the centres lie on a cylinder of
    diameter D - ball diameter, :func:`ball_centre_radius`).

    Args:
        ball_centres: (N, 3) [m].
        ball_diameter: [m].
        reference_diameter: the ring's certified diameter [m], for the per-point errors.
        axis_hint: optional seed direction of the axis.
    """
    cyl = fit_cylinder(ball_centres, axis_hint)
    diameter = feature_diameter("ring", cyl.radius, ball_diameter)
    ref_r = (diameter if reference_diameter is None else reference_diameter) / 2.0
    errors = cyl.radius + cyl.residuals + ball_diameter / 2.0 - ref_r
    return RingFit(cylinder=cyl, ball_diameter=ball_diameter, diameter=diameter, form_error=cyl.form_error,
                   point_errors=errors, angles_deg=np.degrees(cyl.angles), reference_diameter=reference_diameter,
                   centres=np.asarray(ball_centres, float))


def fit_ring_axis(points: ArrayLike) -> tuple[np.ndarray, np.ndarray, float]:
    """(point on the axis [m], unit axis, radius [m]) of ball centres on a ring or cylinder: the
    cylinder fit, or, when the points lie in one plane (one row: the tilt of the axis is not
    determined) or do not determine a cylinder, the plane's normal and the circle fitted in it.

    Raises:
        NumericalError: fewer than 3 points, or points on one line.
    """
    p = _points(np.reshape(points, (-1, 3)), 0, "ring axis")
    plane = fit_plane(p)
    u, v = perpendicular_basis(plane.normal)
    d = p - plane.point
    flat = np.ptp(d @ plane.normal) <= 1e-3 * np.ptp(d @ u)
    if not flat and len(p) >= 5:
        try:
            cyl = fit_cylinder(p)
            return cyl.point, cyl.axis, cyl.radius
        except NumericalError:
            pass   # no tilt information: fall back to the plane's normal below
    circle = fit_circle_2d(np.column_stack([d @ u, d @ v]))
    return plane.point + circle.centre[0] * u + circle.centre[1] * v, plane.normal, circle.radius


# ---------------------------------------------------------------------------------------------
# spheres and planes

@dataclass(frozen=True)
class SphereFit(_RadialFit):
    """A fitted sphere: ``centre`` (3,), ``radius`` (the given one when it was known), ``residuals`` (N,)
    distances to the surface (outward positive) [m]; ``u_centre`` (3,), ``u_radius`` standard
    uncertainties [m] (``u_radius`` 0 for a known radius; NaN with no more points than parameters)."""
    centre: np.ndarray
    radius: float
    residuals: np.ndarray
    u_centre: np.ndarray
    u_radius: float


@dataclass(frozen=True)
class PlaneFit:
    """A fitted plane: ``point`` (3,) the centroid of the points, unit ``normal`` (3,) (sign as the
    SVD gives it), ``residuals`` (N,) signed distances along ``normal`` [m]."""
    point: np.ndarray
    normal: np.ndarray
    residuals: np.ndarray

    @property
    def offset(self) -> float:
        """``normal . x`` of the plane's points [m]."""
        return float(self.normal @ self.point)

    @property
    def form_error(self) -> float:
        """Flatness: max - min signed distance [m]."""
        return float(self.residuals.max() - self.residuals.min())


def _points(points: ArrayLike, need: int, what: str, dim: int = 3) -> np.ndarray:
    """``points`` as an (N, ``dim``) float array of finite numbers (a ValueError: a NaN or an infinity reached
    LAPACK, which printed its own lines and raised LinAlgError), at least ``need`` of them (a NumericalError)."""
    try:
        p = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"points must be an (N, {dim}) array of numbers, got {type(points).__name__}") from None
    if p.ndim != 2 or p.shape[1] != dim:
        raise ValueError(f"points must have shape (N, {dim}), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"points must be finite: row {int(np.argmin(np.isfinite(p).all(axis=1)))} is "
                         f"{p[np.argmin(np.isfinite(p).all(axis=1))].tolist()}")
    if len(p) < need:
        raise NumericalError(f"{len(p)} points cannot place a {what} (need at least {need})")
    return p


def fit_plane(points: ArrayLike) -> PlaneFit:
    """Least-squares (orthogonal) plane through >= 3 non-collinear points."""
    p = _points(points, 3, "plane")
    c, _, z = _normalised(p, "plane")
    _, s, vt = np.linalg.svd(z, full_matrices=False)
    if s[1] <= 1e-9 * s[0]:
        raise NumericalError(f"{len(p)} collinear points cannot place a plane")
    return PlaneFit(point=c, normal=vt[2], residuals=(p - c) @ vt[2])


def sphere_seed(points: ArrayLike) -> tuple[np.ndarray, float]:
    """Algebraic sphere (linear least squares of ``|x|^2 = 2 c.x + k``): (centre, radius) [m].

    Raises:
        NumericalError: fewer than 4 points, or points on one plane.
    """
    p = _points(points, 4, "sphere")
    o, _, _ = _normalised(p, "sphere")
    z = p - o
    a = np.column_stack([2 * z, np.ones(len(z))])
    sol, _, rank, _ = np.linalg.lstsq(a, np.sum(z * z, axis=1), rcond=None)
    if rank < 4:
        raise NumericalError(f"{len(p)} points on one plane cannot place a sphere")
    c = sol[:3]
    return o + c, float(np.sqrt(max(sol[3] + c @ c, 0.0)))


def fit_sphere(points: ArrayLike, radius: float | None = None, centre: ArrayLike | None = None) -> SphereFit:
    """Geometric least-squares sphere through points, from the algebraic seed (:func:`sphere_seed`).

    Args:
        points: (N, 3) [m]; N >= 4 not on one plane (with a known ``radius`` and a ``centre`` to start
            from, N >= 3 is enough).
        radius: known radius [m] (e.g. the ball-centre radius of a reference sphere,
            :func:`ball_centre_radius`): only the centre is fitted, which is far better conditioned
            for points on a small cap.
        centre: optional (3,) starting centre [m] instead of the algebraic seed.
    """
    p = _points(points, 0, "sphere")
    if centre is None:
        c0, r0 = sphere_seed(p)
    else:
        p = _points(p, 3 if radius is not None else 4, "sphere")
        c0 = np.asarray(centre, float)
        r0 = float(np.mean(np.linalg.norm(p - c0, axis=1)))
    scale = float(np.sqrt(((p - c0) ** 2).sum(axis=1).mean())) or 1.0
    z = (p - c0) / scale
    known = radius is not None
    r_known = radius / scale if radius is not None else math.nan

    def fun(x: np.ndarray) -> np.ndarray:
        r: np.ndarray = np.linalg.norm(z - x[:3], axis=1) - (r_known if known else x[3])
        return r

    def jac(x: np.ndarray) -> np.ndarray:
        d = z - x[:3]
        n = d / np.linalg.norm(d, axis=1)[:, None]
        return -n if known else np.column_stack([-n, -np.ones(len(z))])

    x0 = np.zeros(3) if known else np.r_[np.zeros(3), r0 / scale]
    res, u = _solve(fun, jac, x0, "sphere fit", ("centre x", "centre y", "centre z", "radius")[: len(x0)],
                    gauss_newton=True)
    u = scale * u
    r = float(radius) if radius is not None else float(scale * res.x[3])
    return SphereFit(centre=c0 + scale * res.x[:3], radius=r, residuals=scale * res.fun, u_centre=u[:3],
                     u_radius=0.0 if known else float(u[3]))


def smallest_enclosing_sphere(points: ArrayLike) -> tuple[np.ndarray, float]:
    """Centre (3,) and radius of the smallest sphere enclosing ``points`` (N, 3) (Welzl's algorithm, the
    points visited in a fixed order: deterministic; exact up to rounding)."""
    x = _points(points, 1, "sphere")
    mean = x.mean(axis=0)
    scale = float(np.max(np.linalg.norm(x - mean, axis=1))) or 1.0
    y = (x - mean) / scale                          # centred and scaled: no cancellation

    def ball(r: list[np.ndarray]) -> tuple[np.ndarray, float]:
        if not r:
            return np.zeros(3), -1.0
        p0 = r[0]
        if len(r) == 1:
            return p0, 0.0
        a = np.array([p - p0 for p in r[1:]])
        # centre c = p0 + a^T l with 2 a (a^T l) = |a|^2 row by row: the circumcentre in the points' span
        g = a @ a.T
        lam = np.linalg.lstsq(2 * g, np.sum(a * a, axis=1), rcond=None)[0]
        c = p0 + a.T @ lam
        return c, float(np.linalg.norm(c - p0))

    def welzl(n: int, r: list[np.ndarray]) -> tuple[np.ndarray, float]:
        if n == 0 or len(r) == 4:
            return ball(r)
        c, rad = welzl(n - 1, r)
        p = y[n - 1]
        if rad >= 0 and np.linalg.norm(p - c) <= rad * (1 + 1e-12) + 1e-15:
            return c, rad
        return welzl(n - 1, r + [p])

    import sys
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 4 * len(y) + 100))
    try:
        c, rad = welzl(len(y), [])
    finally:
        sys.setrecursionlimit(limit)
    return mean + c * scale, rad * scale
