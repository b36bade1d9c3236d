"""Least-squares cylinder and circle fits as measuring-arm software does them (orthogonal distances).

A cylinder is fitted to points (ball centres) by minimising the sum of squared orthogonal distances
to its surface, ``r_i = |(p_i - c) x a| - R``, with Levenberg-Marquardt (scipy ``least_squares``,
analytic Jacobian). The seed is algebraic: each principal direction of the point cloud is tried as
the axis, the points are projected onto the plane normal to it and a Kasa circle is fitted; the
direction with the smallest geometric residual seeds the iteration. The solver status and the rank
of the Jacobian at the solution are checked; a failure raises :class:`arm_model.NumericalError`.

All lengths are in the unit of the input (the code uses metres); angles [rad] unless named _deg.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from arm_model import NumericalError

__all__ = ["CylinderFit", "CircleFit", "RingFit", "fit_cylinder", "fit_circle_2d", "fit_row_circles",
           "ring_fit", "split_rows", "kasa_circle"]

# relative rank threshold of the column-normalised Jacobian at the solution
_RANK_TOL = 1e-9


class _RadialFit:
    """Diameter and form error of a fit with ``radius`` and radial ``residuals`` [m]."""

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
    """
    point: np.ndarray
    axis: np.ndarray
    radius: float
    residuals: np.ndarray
    heights: np.ndarray
    angles: np.ndarray
    radial: np.ndarray
    nfev: int

    def to_axis(self, p) -> np.ndarray:
        """(N, 3) unit vectors from points ``p`` (N, 3) towards the axis, perpendicular to it (Eq. 3-7 of
        the seed paper: the intersection of the plane through the point normal to the axis)."""
        d = np.asarray(p, float) - self.point
        perp = d - np.outer(d @ self.axis, self.axis)
        n = np.linalg.norm(perp, axis=1)
        if np.any(n == 0):
            raise NumericalError("a point lies on the cylinder axis: no direction to the axis")
        return -perp / n[:, None]


@dataclass(frozen=True)
class CircleFit(_RadialFit):
    """A fitted circle in a plane: ``centre`` (2,) in plane coordinates, ``radius``, ``residuals`` (N,)
    (outward positive) [m], and for circles of a cylinder's rows ``centre_3d`` (3,), ``height`` [m]."""
    centre: np.ndarray
    radius: float
    residuals: np.ndarray
    centre_3d: np.ndarray | None = None
    height: float | None = None


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

    def rows(self, rows=None) -> list[dict]:
        """Circles per row (see :func:`fit_row_circles`), lowest first: ``height`` along the axis,
        ``diameter`` (ball compensated) and ``form_error`` [m]."""
        return [{"height": c.height, "diameter": c.diameter + self.ball_diameter, "form_error": c.form_error}
                for c in fit_row_circles(self.centres, self.cylinder, rows)]

    @property
    def diameter_error(self) -> float | None:
        """Measured minus reference diameter [m], or None without a reference."""
        return None if self.reference_diameter is None else self.diameter - self.reference_diameter


def _orthonormal(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``a`` to a right-handed orthonormal frame (e1, e2, a)."""
    ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ a) * a
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def _angle_frame(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference directions for angular positions: projection of base x (or y), then a x e1."""
    for ref in (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        e1 = ref - (ref @ a) * a
        if np.linalg.norm(e1) > 0.1:
            e1 /= np.linalg.norm(e1)
            return e1, np.cross(a, e1)
    raise AssertionError("unreachable: base x and y cannot both be parallel to a unit axis")


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


def _check_status(res, what: str) -> None:
    if not res.success or res.status <= 0:
        raise NumericalError(f"{what}: the least-squares solver did not converge "
                             f"(status {res.status}: {res.message})")
    if not np.all(np.isfinite(res.x)):
        raise NumericalError(f"{what}: non-finite parameters")


def _check_rank(jac: np.ndarray, what: str, names: tuple[str, ...]) -> None:
    norms = np.linalg.norm(jac, axis=0)
    if np.any(norms == 0):
        raise NumericalError(f"{what}: parameter(s) {', '.join(n for n, v in zip(names, norms) if v == 0)} "
                             "not determined by the points (rank-deficient Jacobian)")
    s = np.linalg.svd(jac / norms, compute_uv=False)
    if s[-1] < _RANK_TOL * s[0]:
        raise NumericalError(f"{what}: rank-deficient Jacobian at the solution (condition {s[0] / s[-1]:.2g}); "
                             "the points do not determine the fit")


def fit_circle_2d(xy) -> CircleFit:
    """Geometric least-squares circle through 2-D points (N >= 3), Kasa seed then Levenberg-Marquardt.

    Args:
        xy: (N, 2) points [m].
    """
    xy = np.asarray(xy, float)
    if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 3:
        raise ValueError(f"need (N >= 3, 2) points, got {xy.shape}")
    o = xy.mean(axis=0)
    s = float(np.sqrt(((xy - o) ** 2).sum(axis=1).mean()))
    if s == 0:
        raise NumericalError("all points coincide: no circle")
    z = (xy - o) / s
    c0, r0 = kasa_circle(z)

    def fun(x):
        d = z - x[:2]
        return np.hypot(d[:, 0], d[:, 1]) - x[2]

    def jac(x):
        d = z - x[:2]
        rho = np.hypot(d[:, 0], d[:, 1])
        return np.column_stack([-d / rho[:, None], -np.ones(len(z))])

    res = least_squares(fun, np.r_[c0, r0], jac=jac, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    _check_status(res, "circle fit")
    _check_rank(jac(res.x), "circle fit", ("centre x", "centre y", "radius"))
    centre = o + s * res.x[:2]
    return CircleFit(centre=centre, radius=float(s * res.x[2]), residuals=s * fun(res.x))


def fit_cylinder(points, axis_hint=None) -> CylinderFit:
    """Orthogonal-distance least-squares cylinder through points (N >= 5).

    Args:
        points: (N, 3) points [m], any frame; the result is expressed in the same frame.
        axis_hint: optional (3,) approximate axis direction; if given it is used as the seed direction
            instead of the principal-direction search (it only seeds: the axis is fitted).

    Raises:
        NumericalError: the solver did not converge, or the points do not determine a cylinder (all in
            one plane normal to the axis, too few, collinear).
    """
    p = np.asarray(points, float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {p.shape}")
    if len(p) < 5:
        raise NumericalError(f"a cylinder needs at least 5 points, got {len(p)}")
    centroid = p.mean(axis=0)
    scale = float(np.sqrt(((p - centroid) ** 2).sum(axis=1).mean()))
    if scale == 0:
        raise NumericalError("all points coincide: no cylinder")
    z = (p - centroid) / scale

    # algebraic seed: principal directions as candidate axes, Kasa circle in the normal plane
    if axis_hint is not None:
        a = np.asarray(axis_hint, float)
        candidates = [a / np.linalg.norm(a)]
    else:
        _, _, vt = np.linalg.svd(z, full_matrices=False)
        candidates = list(vt)
    best = None
    for a0 in candidates:
        e1, e2 = _orthonormal(a0)
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

    def geometry(x):
        w = a0 + x[2] * e1 + x[3] * e2
        nw = np.linalg.norm(w)
        a = w / nw
        c = c0 + x[0] * e1 + x[1] * e2
        d = z - c
        t = d @ a
        perp = d - np.outer(t, a)
        rho = np.linalg.norm(perp, axis=1)
        return a, nw, t, perp, rho

    def fun(x):
        return geometry(x)[4] - x[4]

    def jac(x):
        a, nw, t, perp, rho = geometry(x)
        if np.any(rho == 0):
            raise NumericalError("cylinder fit: a point lies on the current axis estimate")
        n = perp / rho[:, None]
        return np.column_stack([-n @ e1, -n @ e2, -t * (n @ e1) / nw, -t * (n @ e2) / nw,
                                -np.ones(len(z))])

    res = least_squares(fun, np.array([0.0, 0.0, 0.0, 0.0, r0]), jac=jac, method="lm",
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=2000)
    _check_status(res, "cylinder fit")
    _check_rank(jac(res.x), "cylinder fit", ("axis offset 1", "axis offset 2", "axis tilt 1", "axis tilt 2",
                                             "radius"))
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
    f1, f2 = _angle_frame(a)
    ang = np.mod(np.arctan2(radial @ f2, radial @ f1), 2 * np.pi)
    return CylinderFit(point=centroid + scale * c, axis=a, radius=float(scale * res.x[4]),
                       residuals=scale * (rho - res.x[4]), heights=scale * t, angles=ang, radial=radial,
                       nfev=int(res.nfev))


def split_rows(heights, rows: int | None = None) -> np.ndarray:
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


def fit_row_circles(points, cylinder: CylinderFit, rows=None) -> list[CircleFit]:
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
    e1, e2 = _angle_frame(cylinder.axis)
    out = []
    keys = sorted(set(labels.tolist()), key=lambda k: float(np.mean(cylinder.heights[labels == k])))
    for k in keys:
        m = labels == k
        d = p[m] - cylinder.point
        fit = fit_circle_2d(np.column_stack([d @ e1, d @ e2]))
        h = float(np.mean(d @ cylinder.axis))
        c3 = cylinder.point + fit.centre[0] * e1 + fit.centre[1] * e2 + h * cylinder.axis
        out.append(CircleFit(fit.centre, fit.radius, fit.residuals, c3, h))
    return out


def ring_fit(ball_centres, ball_diameter: float, reference_diameter: float | None = None,
             axis_hint=None) -> RingFit:
    """Fit an inner ring measured from inside with ball centres (docs/formats.md §4: the centres lie on a
    cylinder of diameter D - ball diameter).

    Args:
        ball_centres: (N, 3) [m].
        ball_diameter: [m].
        reference_diameter: the ring's certified diameter [m], for the per-point errors.
        axis_hint: optional seed direction of the axis.
    """
    cyl = fit_cylinder(ball_centres, axis_hint)
    diameter = cyl.diameter + ball_diameter
    ref_r = (diameter if reference_diameter is None else reference_diameter) / 2.0
    errors = cyl.radius + cyl.residuals + ball_diameter / 2.0 - ref_r
    return RingFit(cylinder=cyl, ball_diameter=ball_diameter, diameter=diameter, form_error=cyl.form_error,
                   point_errors=errors, angles_deg=np.degrees(cyl.angles), reference_diameter=reference_diameter,
                   centres=np.asarray(ball_centres, float))
