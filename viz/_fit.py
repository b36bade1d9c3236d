"""Two small linear least-squares fits that place artefacts in the scene (private to the viewer).

Only for drawing. Cylinders and circles come from :mod:`correction.cylinder`. All points [m] in the
base frame; each fit raises :class:`arm_model.NumericalError` when the points do not determine it.
"""
from __future__ import annotations

import numpy as np

from arm_model import NumericalError

__all__ = ["fit_sphere", "fit_plane"]


def _points(p, need: int, what: str) -> np.ndarray:
    p = np.asarray(p, dtype=float).reshape(-1, 3)
    if len(p) < need:
        raise NumericalError(f"{len(p)} points cannot place a {what} (need at least {need})")
    return p


def fit_plane(p) -> tuple[np.ndarray, np.ndarray]:
    """(centroid (3,) [m], unit normal (3,)) of the least-squares plane; >= 3 non-collinear points."""
    p = _points(p, 3, "plane")
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c)
    if s[1] <= 1e-9 * max(s[0], 1e-300):
        raise NumericalError(f"{len(p)} collinear points cannot place a plane")
    return c, vt[2]


def fit_sphere(p, radius: float | None = None) -> tuple[np.ndarray, float]:
    """(centre (3,) [m], radius [m]) of the least-squares sphere; >= 4 points not on one plane.

    Linear (algebraic) fit; with a known ``radius`` [m] the centre is then refined by geometric least
    squares at that radius, which is far better conditioned for points on a small cap.
    """
    p = _points(p, 4, "sphere")
    a = np.column_stack([2 * p, np.ones(len(p))])
    b = np.sum(p * p, axis=1)
    x, _, rank, _ = np.linalg.lstsq(a, b, rcond=None)
    if rank < 4:
        raise NumericalError(f"{len(p)} points on one plane cannot place a sphere")
    centre = x[:3]
    if radius is None:
        return centre, float(np.sqrt(x[3] + centre @ centre))
    from scipy.optimize import least_squares

    sol = least_squares(lambda c: np.linalg.norm(p - c, axis=1) - radius, centre, method="lm")
    if not sol.success:
        raise NumericalError(f"the sphere fit at radius {radius * 1e3:g} mm did not converge: {sol.message}")
    return sol.x, float(radius)
