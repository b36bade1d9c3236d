"""Features of a live session, refitted after each point: size, form and their uncertainties, against the
certificate.

Each point's corrected ball centre comes with its covariance and the rows of the errors every point
shares (:attr:`arm_model.uncertainty.Propagation.systematic`: the model's parameters, the probe's
compliances), so a fit's uncertainty counts a shared error once, not as if it averaged out. The fits are
those of :mod:`arm_model.geometry`, the uncertainties those of :mod:`arm_model.feature_uncertainty`:

=================  ======  ====================================================  ==============================
kind               points  size (its standard uncertainty)                       form (one more point)
=================  ======  ====================================================  ==============================
ring, cylinder     4       diameter, ball compensated: the cylinder fit from 8   max - min radial deviation
                           points spread along the axis by 5 % of their width,
                           else the circle in their plane (a ring in one row)
sphere             5       diameter of the sphere fit, ball compensated          max - min radial deviation
plane              3       (none)                                                flatness (max - min distance)
seat               1       (none); its centre: the mean ball centre              max over axes of (max-min)/2
point              1       (none)                                                (none)
=================  ======  ====================================================  ==============================

With fewer points a fit says how many it needs. A size is compared with the certified one: the deviation
``size - certified`` agrees with the certificate when ``|deviation| <= 2 sqrt(u^2 + u_certified^2)``
(k = 2). A certified ``[[distance]]`` between two features' centres is checked the same way once both are
placed. Form uncertainties are sampled (:func:`~arm_model.feature_uncertainty.residual_form_uncertainty`,
seeded: the same points give the same figures).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import NumericalError
from ..feature_uncertainty import (
    cylinder_jacobian,
    diameter_uncertainty,
    fit_sensitivity,
    plane_jacobian,
    residual_form_uncertainty,
    sphere_jacobian,
)
from ..geometry import (
    CylinderFit,
    feature_diameter,
    fit_circle_2d,
    fit_cylinder,
    fit_plane,
    fit_sphere,
    perpendicular_basis,
)
from ..io import Distance, Feature
from .plan import NEEDED_POINTS, PlanFeature, SessionPlan

__all__ = ["FeatureFit", "FeatureTracker", "NEEDED_POINTS", "COVERAGE_K", "FORM_SAMPLES_LIVE"]

#: coverage factor of the agreement test against a certificate
COVERAGE_K = 2.0
#: a ring or cylinder is fitted as a cylinder (its axis tilt free) from this many points on, when they spread
#: along the axis by at least this fraction of their width; else as a circle in their plane
CYLINDER_POINTS, CYLINDER_SPREAD = 8, 0.05
#: samples of the form uncertainty after each point
FORM_SAMPLES_LIVE = 1000


@dataclass(frozen=True)
class FeatureFit:
    """A feature (or a certified distance) as fitted after a point. Lengths in metres.

    Attributes:
        feature: its id (a distance: ``"A--B"``); kind: its kind (``"distance"``); n_points: points used.
        size, u_size: diameter (a distance: its length) and its standard uncertainty, or None.
        form, u_form: form error and its standard uncertainty, or None.
        certified, u_certified: the certificate's size and its standard uncertainty, or None.
        centre: (3,) base frame, or None; axis: (3,) unit axis (ring, cylinder) or normal (plane), or None.
        radius: fitted radius of the ball centres (ring, cylinder, sphere), or None.
        extent: (2,) height the points span (ring, cylinder) or the plane's extent, else zeros.
        note: why a figure is missing (too few points, degenerate points), else "".
    """
    feature: str
    kind: str
    n_points: int
    size: float | None = None
    u_size: float | None = None
    form: float | None = None
    u_form: float | None = None
    certified: float | None = None
    u_certified: float | None = None
    centre: np.ndarray | None = None
    axis: np.ndarray | None = None
    radius: float | None = None
    extent: np.ndarray | None = None
    note: str = ""

    @property
    def deviation(self) -> float | None:
        """size - certified [m], or None."""
        return None if self.size is None or self.certified is None else self.size - self.certified

    @property
    def agrees(self) -> bool | None:
        """|deviation| <= k sqrt(u_size^2 + u_certified^2) (k = :data:`COVERAGE_K`), or None."""
        if self.deviation is None or self.u_size is None or not math.isfinite(self.u_size):
            return None
        return abs(self.deviation) <= COVERAGE_K * math.hypot(self.u_size, self.u_certified or 0.0)

    def row(self, point: int) -> dict:
        """The row of ``features.csv`` after point number ``point`` (mm)."""
        def mm(v: float | None) -> str:
            return "" if v is None or not math.isfinite(v) else f"{v * 1e3:.6f}"
        agrees = self.agrees
        return {"point": point, "feature": self.feature, "kind": self.kind, "points": self.n_points,
                "size_mm": mm(self.size), "u_size_mm": mm(self.u_size), "certified_mm": mm(self.certified),
                "deviation_mm": mm(self.deviation), "agrees": "" if agrees is None else int(agrees),
                "form_mm": mm(self.form), "u_form_mm": mm(self.u_form), "note": self.note}

    def describe(self) -> str:
        """One line for people (mm, um)."""
        name = f"{self.kind} '{self.feature}' ({self.n_points} pt)"
        parts = []
        if self.size is not None:
            parts.append(f"{'length' if self.kind == 'distance' else 'D'} {self.size * 1e3:.4f} mm"
                         + (f" ± {self.u_size * 1e6:.1f} um"
                            if self.u_size is not None and math.isfinite(self.u_size) else ""))
        if self.deviation is not None:
            parts.append(f"vs certified {self.deviation * 1e6:+.1f} um"
                         + ("" if self.agrees is None else (" (agrees)" if self.agrees else " (DIFFERS)")))
        if self.form is not None:
            parts.append(f"{'spread' if self.kind == 'seat' else 'form'} {self.form * 1e6:.1f} um"
                         + (f" ± {self.u_form * 1e6:.1f}" if self.u_form is not None else ""))
        if self.kind in ("seat", "point", "sphere") and self.centre is not None:
            c = self.centre * 1e3
            parts.append(f"centre ({c[0]:.4f}, {c[1]:.4f}, {c[2]:.4f}) mm")
        if self.note:
            parts.append(self.note)
        return f"{name}: " + ", ".join(parts)


@dataclass
class _Group:
    """The points of one feature: ball centres (N, 3) [m], covariances (N, 3, 3) [m^2] and shared rows
    (N, R, 3) [m]; ``centre_sens`` (N, 3, 3) d centre / d point of its last fit, or None."""
    points: list
    cov: list
    shared: list
    centre_sens: np.ndarray | None = None
    centre: np.ndarray | None = None


class FeatureTracker:
    """Which feature the next point belongs to, and the fits after each point.

    Args:
        plan: the session plan (None or an empty plan: every point is a free point).
        ball_diameter: the probe ball's diameter [m] (sizes are ball compensated).
        n_parameters: how many of the shared rows are the model parameters' (the rest: compliances).
    """

    def __init__(self, plan: SessionPlan | None, ball_diameter: float, n_parameters: int = 0):
        plan = plan or SessionPlan()
        self.entries: list[PlanFeature] = list(plan.entries)
        self.distances = tuple(plan.distances)
        self.ball_diameter = float(ball_diameter)
        self.n_parameters = int(n_parameters)
        self._entry = 0             # index of the current entry
        self._taken = 0             # points it has taken
        self.groups: dict[str, _Group] = {}
        self.fits: dict[str, FeatureFit] = {}
        self._advance()

    def _advance(self) -> None:
        while (self._entry < len(self.entries) and self.entries[self._entry].points is not None
               and self._taken >= self.entries[self._entry].points):  # type: ignore[operator]
            self._entry, self._taken = self._entry + 1, 0

    @property
    def current(self) -> str:
        """The id of the feature the next point belongs to ("" beyond the plan: a free point)."""
        return self.entries[self._entry].feature.id if self._entry < len(self.entries) else ""

    @property
    def remaining(self) -> int | None:
        """Points the current feature still takes (None: open-ended; 0 beyond the plan)."""
        if self._entry >= len(self.entries):
            return 0
        n = self.entries[self._entry].points
        return None if n is None else n - self._taken

    @property
    def features(self) -> dict:
        """id -> :class:`arm_model.io.Feature` of every entry so far."""
        return {e.feature.id: e.feature for e in self.entries}

    def begin(self, feature: Feature, points: int | None = None) -> None:
        """Start an ad hoc feature (an :class:`arm_model.io.Feature` with a new id) now: the next ``points``
        points belong to it (None: all until the next ``begin``). The current entry ends with the points
        it has taken; the rest of the plan follows the new feature."""
        if feature.id in self.features:
            raise ValueError(f"feature id '{feature.id}' is already in the session")
        if points is not None and points < 1:
            raise ValueError(f"points must be at least 1, got {points}")
        if self._entry < len(self.entries) and self._taken:
            done = self.entries[self._entry]
            self.entries[self._entry] = PlanFeature(done.feature, self._taken)
            self._entry += 1
        self.entries.insert(self._entry, PlanFeature(feature, points))
        self._taken = 0

    def add(self, feature: str, centre: np.ndarray, cov: np.ndarray, shared: np.ndarray) -> list[FeatureFit]:
        """Add a point of ``feature`` (the :attr:`current` one, or "" for a free point; its centre (3,) [m],
        covariance (3, 3) [m^2], shared rows (R, 3) [m]) and refit: the feature's fit and the fits of the
        certified distances it takes part in."""
        if not feature:
            return []
        if feature != self.current:
            raise ValueError(f"the point's feature '{feature}' is not the current one '{self.current}'")
        self._taken += 1
        g = self.groups.setdefault(feature, _Group([], [], []))
        g.points.append(np.asarray(centre, float))
        g.cov.append(np.asarray(cov, float))
        g.shared.append(np.asarray(shared, float))
        fit = self._fit(self.entries[self._entry].feature, g)
        self._advance()
        self.fits[feature] = fit
        out = [fit]
        for d in self.distances:
            if feature in d.between:
                dist = self._distance(d)
                self.fits[dist.feature] = dist
                out.append(dist)
        return out

    def _fit(self, spec: Feature, g: _Group) -> FeatureFit:
        p = np.array(g.points)
        need = NEEDED_POINTS[spec.kind]
        base = dict(feature=spec.id, kind=spec.kind, n_points=len(p), certified=spec.diameter,
                    u_certified=spec.u_diameter)
        g.centre_sens, g.centre = None, None
        if len(p) < need:
            return FeatureFit(**base, note=f"{len(p)} of the {need} points a {spec.kind} needs")
        cov, shared = np.array(g.cov), np.array(g.shared)
        try:
            if spec.kind in ("ring", "cylinder"):
                return self._fit_cylinder(spec, g, p, cov, shared, base)
            if spec.kind == "sphere":
                return self._fit_sphere(spec, g, p, cov, shared, base)
            if spec.kind == "plane":
                return self._fit_plane(g, p, cov, shared, base)
        except NumericalError as exc:
            return FeatureFit(**base, note=str(exc))
        return self._fit_seat(g, p, cov, shared, base)

    def _form(self, residuals: np.ndarray, n: np.ndarray, jac: np.ndarray, cov: np.ndarray,
              shared: np.ndarray) -> float:
        return residual_form_uncertainty(residuals, n, jac, cov, shared, samples=FORM_SAMPLES_LIVE).u

    def _fit_cylinder(self, spec: Feature, g: _Group, p: np.ndarray, cov: np.ndarray, shared: np.ndarray,
                      base: dict) -> FeatureFit:
        cyl, circle = _cylinder_or_circle(p)
        t = (p - cyl.point) @ cyl.axis
        n, jac = cylinder_jacobian(p, cyl)
        if circle:                          # the axis offsets and the radius only
            jac = jac[:, [0, 1, 4]]
        e1, e2 = perpendicular_basis(cyl.axis)
        sens = 2.0 * fit_sensitivity(n, jac, jac.shape[1] - 1)
        u = diameter_uncertainty(sens, cov, shared, self.n_parameters).u
        g.centre_sens = (np.einsum("i,nj->nij", e1, fit_sensitivity(n, jac, 0))
                         + np.einsum("i,nj->nij", e2, fit_sensitivity(n, jac, 1)))
        g.centre = cyl.point
        form, u_form = self._form_of(cyl.residuals, n, jac, cov, shared)
        return FeatureFit(**base, size=feature_diameter(spec.kind, cyl.radius, self.ball_diameter), u_size=u,
                          form=form, u_form=u_form, centre=cyl.point + cyl.axis * (t.min() + t.max()) / 2,
                          axis=cyl.axis, radius=cyl.radius, extent=np.array([np.ptp(t), 0.0]),
                          note="" if form is not None else "form needs one more point")

    def _form_of(self, residuals: np.ndarray, n: np.ndarray, jac: np.ndarray, cov: np.ndarray,
                 shared: np.ndarray) -> tuple:
        """(form, its uncertainty) [m], or (None, None) with no more points than the fit's parameters."""
        if len(residuals) <= jac.shape[1]:
            return None, None
        res = np.asarray(residuals, float)
        return float(res.max() - res.min()), self._form(res, n, jac, cov, shared)

    def _fit_sphere(self, spec: Feature, g: _Group, p: np.ndarray, cov: np.ndarray, shared: np.ndarray,
                    base: dict) -> FeatureFit:
        fit = fit_sphere(p)
        n, jac = sphere_jacobian(p, fit.centre)
        sens = 2.0 * fit_sensitivity(n, jac, 3)
        g.centre_sens = np.stack([fit_sensitivity(n, jac, k) for k in range(3)], axis=1)
        g.centre = fit.centre
        return FeatureFit(**base, size=feature_diameter("sphere", fit.radius, self.ball_diameter),
                          u_size=diameter_uncertainty(sens, cov, shared, self.n_parameters).u,
                          **dict(zip(("form", "u_form"), self._form_of(fit.residuals, n, jac, cov, shared),
                                     strict=True)),
                          centre=fit.centre, radius=fit.radius, extent=np.zeros(2))

    def _fit_plane(self, g: _Group, p: np.ndarray, cov: np.ndarray, shared: np.ndarray, base: dict) -> FeatureFit:
        plane = fit_plane(p)
        n, jac = plane_jacobian(p, plane)
        u, v = perpendicular_basis(plane.normal)
        d = p - plane.point
        g.centre_sens = np.tile(np.eye(3) / len(p), (len(p), 1, 1))
        g.centre = plane.point
        form, u_form = self._form_of(plane.residuals, n, jac, cov, shared)
        return FeatureFit(**{**base, "certified": None, "u_certified": None}, form=form, u_form=u_form,
                          note="" if form is not None else "flatness needs one more point", centre=plane.point,
                          axis=plane.normal, extent=np.array([np.ptp(d @ u), np.ptp(d @ v)]))

    def _fit_seat(self, g: _Group, p: np.ndarray, cov: np.ndarray, shared: np.ndarray, base: dict) -> FeatureFit:
        g.centre_sens = np.tile(np.eye(3) / len(p), (len(p), 1, 1))
        g.centre = p.mean(axis=0)
        spread = float(np.max(np.ptp(p, axis=0)) / 2) if len(p) > 1 else None
        return FeatureFit(**{**base, "certified": None, "u_certified": None}, form=spread, centre=g.centre,
                          extent=np.zeros(2))

    def _distance(self, d: Distance) -> FeatureFit:
        """The certified distance ``d`` between two features' centres, once both are placed."""
        a, b = (self.groups.get(f) for f in d.between)
        name = f"{d.between[0]}--{d.between[1]}"
        base = dict(feature=name, kind="distance", certified=d.length, u_certified=d.u_length)
        if a is None or b is None or a.centre_sens is None or b.centre_sens is None:
            return FeatureFit(**base, n_points=sum(len(x.points) for x in (a, b) if x is not None),
                              note="needs both features placed")
        v = b.centre - a.centre  # type: ignore[operator]
        length = float(np.linalg.norm(v))
        e = v / length
        sens = np.concatenate([-np.einsum("i,nij->nj", e, a.centre_sens), np.einsum("i,nij->nj", e, b.centre_sens)])
        cov = np.concatenate([np.array(a.cov), np.array(b.cov)])
        shared = np.concatenate([np.array(a.shared), np.array(b.shared)])
        u = diameter_uncertainty(sens, cov, shared, self.n_parameters).u
        return FeatureFit(**base, n_points=len(cov), size=length, u_size=u, centre=(a.centre + b.centre) / 2, axis=e,  # type: ignore[operator]
                          extent=np.zeros(2))


def _cylinder_or_circle(p: np.ndarray) -> tuple[CylinderFit, bool]:
    """(fit, True for a circle): the cylinder fit of ball centres when they determine an axis (at least
    :data:`CYLINDER_POINTS` of them, spread along the axis by at least :data:`CYLINDER_SPREAD` of their
    width), else the circle fitted in their plane, as a cylinder along its normal (a ring probed in one
    row: its axis tilt is not determined)."""
    plane = fit_plane(p)
    u, v = perpendicular_basis(plane.normal)
    d = p - plane.point
    if len(p) >= CYLINDER_POINTS and np.ptp(d @ plane.normal) >= CYLINDER_SPREAD * np.ptp(d @ u):
        try:
            return fit_cylinder(p), False
        except NumericalError:
            pass
    circle = fit_circle_2d(np.column_stack([d @ u, d @ v]))
    point = plane.point + circle.centre[0] * u + circle.centre[1] * v
    r = p - point
    t = r @ plane.normal
    perp = r - np.outer(t, plane.normal)
    rho = np.linalg.norm(perp, axis=1)
    radial = perp / rho[:, None]
    return CylinderFit(point=point, axis=plane.normal, radius=circle.radius, residuals=rho - circle.radius,
                       heights=t, angles=np.arctan2(radial @ v, radial @ u) % (2 * np.pi), radial=radial, nfev=0,
                       u_radius=circle.u_radius), True
