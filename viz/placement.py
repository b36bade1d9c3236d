"""Placing artefact features in the base frame from the ball centres measured on them.

The artefacts file gives sizes, not placements: each (measurement, feature) group of measured ball
centres is fitted (ring/cylinder: axis, centre and radius, by :func:`correction.cylinder.fit_cylinder`,
or for a ring probed in one plane the plane's normal and a circle in it; sphere: centre; plane:
centroid and normal; seat: the mean point) and drawn with the certified size. A sphere's centre is
fitted at the known radius of its ball centres when the ball diameter is given. For drawing only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arm_model import NumericalError

from ._fit import fit_plane, fit_sphere

__all__ = ["Placement", "place_features", "NEEDED_POINTS"]

#: fewest ball centres that place a feature of each kind
NEEDED_POINTS = {"ring": 5, "cylinder": 5, "sphere": 4, "plane": 3, "seat": 1}


@dataclass(frozen=True)
class Placement:
    """One feature as measured in one measurement, base frame.

    Attributes:
        feature: feature id; kind: its kind; measurement: measurement id.
        centre: (3,) [m] ring/cylinder: the axis point nearest the points' mean; sphere: the centre;
            plane: the points' centroid; seat: the mean ball centre.
        axis: (3,) unit axis (ring/cylinder) or normal (plane), else None.
        radius: [m] the artefact's certified radius (diameter / 2) where it has one, else None.
        fitted_radius: [m] radius of the ball centres' fit (ring/cylinder/sphere; a sphere fitted at
            its known radius gives that radius), else None.
        size: (2,) [m] ring/cylinder: (height spanned by the points, 0); plane: the points' extent
            along two in-plane axes; else zeros.
        n_points: number of ball centres used.
    """
    feature: str
    kind: str
    measurement: str
    centre: np.ndarray
    axis: np.ndarray | None
    radius: float | None
    fitted_radius: float | None
    size: np.ndarray
    n_points: int


def _in_plane_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def _ring_axis(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(point on the axis [m], unit axis, radius [m]) of ball centres on a ring or cylinder: the
    cylinder fit, or, when the points lie in one plane (one row: the tilt of the axis is not
    determined), the plane's normal and the circle fitted in it."""
    from correction.cylinder import fit_circle_2d, fit_cylinder

    centroid, normal = fit_plane(p)
    u, v = _in_plane_basis(normal)
    flat = np.ptp((p - centroid) @ normal) <= 1e-3 * np.ptp((p - centroid) @ u)
    if not flat:
        try:
            cyl = fit_cylinder(p)
            return cyl.point, cyl.axis, cyl.radius
        except NumericalError:
            pass   # no tilt information: fall back to the plane's normal below
    circle = fit_circle_2d(np.column_stack([(p - centroid) @ u, (p - centroid) @ v]))
    return centroid + circle.centre[0] * u + circle.centre[1] * v, normal, circle.radius


def place_features(artefacts, measurement: np.ndarray, feature: np.ndarray, centres: np.ndarray,
                   ball_diameter: float | None = None) -> tuple[list[Placement], list[str]]:
    """Place every (measurement, feature) group of ball centres.

    Args:
        artefacts: :class:`arm_model.Artefacts`.
        measurement, feature: (N,) ids of each point (feature "" = free point, skipped).
        centres: (N, 3) deflection-corrected ball centres [m], base frame.
        ball_diameter: the probe ball's diameter [m]; if given, a sphere's centre is fitted at the known
            radius of its ball centres, (certified diameter + ball diameter) / 2.

    Returns:
        (placements, notes): notes say which groups could not be placed and why (too few points,
        degenerate points), so that nothing is dropped silently.
    """
    centres = np.asarray(centres, dtype=float)
    placements, notes = [], []
    groups = dict.fromkeys(zip(measurement.tolist(), feature.tolist()))
    for meas, fid in groups:
        if not fid or fid not in artefacts.features:
            continue
        feat = artefacts.features[fid]
        if feat.kind not in NEEDED_POINTS:
            continue
        p = centres[(measurement == meas) & (feature == fid)]
        if len(p) < NEEDED_POINTS[feat.kind]:
            notes.append(f"{feat.kind} '{fid}' in measurement '{meas}': {len(p)} point(s), too few to place it "
                         f"(need {NEEDED_POINTS[feat.kind]}); not drawn")
            continue
        radius = None if feat.diameter is None else feat.diameter / 2
        axis, fitted, size = None, None, np.zeros(2)
        try:
            if feat.kind in ("ring", "cylinder"):
                origin, axis, fitted = _ring_axis(p)
                t = (p - origin) @ axis
                centre = origin + axis * (t.min() + t.max()) / 2
                size = np.array([t.max() - t.min(), 0.0])
            elif feat.kind == "sphere":
                known = None if ball_diameter is None else (feat.diameter + ball_diameter) / 2
                centre, fitted = fit_sphere(p, known)
            elif feat.kind == "plane":
                centre, axis = fit_plane(p)
                u, v = _in_plane_basis(axis)
                d = p - centre
                size = np.array([np.ptp(d @ u), np.ptp(d @ v)])
            else:  # seat
                centre = p.mean(axis=0)
        except NumericalError as exc:
            notes.append(f"{feat.kind} '{fid}' in measurement '{meas}': {exc}; not drawn")
            continue
        placements.append(Placement(fid, feat.kind, meas, np.asarray(centre, float), axis, radius, fitted,
                                    size, len(p)))
    return placements, notes
