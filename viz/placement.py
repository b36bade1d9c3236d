"""Placing artefact features in the base frame from the ball centres measured on them.

The artefacts file gives sizes, not placements: each (measurement, feature) group of measured ball
centres is fitted with :mod:`arm_model.geometry` (ring/cylinder: axis, centre and radius by
:func:`~arm_model.geometry.fit_ring_axis`, i.e. the cylinder fit, or for a ring probed in one plane the plane's
normal and a circle in it; sphere: centre; plane: centroid and normal; seat: the mean point) and drawn with the
certified size. A sphere's centre is
fitted at the known radius of its ball centres when the ball diameter is given. For drawing only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arm_model import NumericalError
from arm_model.geometry import ball_centre_radius, fit_plane, fit_ring_axis, fit_sphere, perpendicular_basis

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
    groups = dict.fromkeys(zip(measurement.tolist(), feature.tolist(), strict=True))
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
                origin, axis, fitted = fit_ring_axis(p)
                t = (p - origin) @ axis
                centre = origin + axis * (t.min() + t.max()) / 2
                size = np.array([t.max() - t.min(), 0.0])
            elif feat.kind == "sphere":
                known = None if ball_diameter is None else ball_centre_radius("sphere", feat.diameter, ball_diameter)
                fit = fit_sphere(p, known)
                centre, fitted = fit.centre, fit.radius
            elif feat.kind == "plane":
                plane = fit_plane(p)
                centre, axis = plane.point, plane.normal
                u, v = perpendicular_basis(axis)
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
