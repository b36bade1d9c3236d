"""The uncertainty of a fitted cylinder's diameter from the covariances of its points.

The orthogonal least-squares cylinder (:func:`arm_model.geometry.fit_cylinder`) has parameters
theta = (two axis offsets, two axis tilts, radius) and residuals r_i = rho_i - R, rho_i the distance
of point i from the axis. Moving point i by dp_i changes r_i by n_i . dp_i (n_i the unit radial
direction), and the refit changes theta by ``-(J^T J)^-1 J^T (n . dp)`` (J the residuals' Jacobian
in theta; Gauss-Newton, first order). So the diameter D = 2 R (+ the ball diameter) has the
sensitivity ``s_i = dD/dp_i`` (3,) to each point, and

    var(D) = sum_i s_i^T C_i s_i            errors of each point alone (encoders, force, probing)
           + |sum_i S_i s_i|^2              errors shared by all points (parameters, compliance)

with C_i the point's covariance without the shared part and S_i its rows of shared factors
(:attr:`arm_model.uncertainty.Propagation.systematic`): a shared error (a wrong link length, a wrong
compliance) moves every point the same way and does not average out over the points.

The form error F = max_i r_i - min_i r_i is not smooth in the points (which point is the extreme
changes), so :func:`form_uncertainty` samples instead of differentiating: each sample draws the point
errors from the same covariances (independent parts per point, shared factors once per sample),
maps them to residual changes through the refit to first order, ``dr = (I - J J^+) (n . dp)``, and
takes max - min of ``r + dr``. The spread of the samples is the standard uncertainty of F; their mean
minus F is how much the errors alone inflate a form error (max - min of noise is positive).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import CylinderFit, perpendicular_basis

__all__ = ["DiameterUncertainty", "diameter_sensitivity", "diameter_uncertainty", "FormUncertainty",
           "form_uncertainty", "FORM_SAMPLES", "fit_sensitivity", "sphere_jacobian", "plane_jacobian",
           "residual_form_uncertainty", "cylinder_jacobian"]

#: samples of :func:`form_uncertainty` (a standard deviation from B samples is known to about 1/sqrt(2B))
FORM_SAMPLES = 2000


def cylinder_jacobian(points, cylinder: CylinderFit) -> tuple[np.ndarray, np.ndarray]:
    """The unit radial directions (N, 3) and the residuals' Jacobian (N, 5) in the cylinder's
    parameters (two axis offsets, two tilts, the radius)."""
    p = np.asarray(points, float)
    d = p - cylinder.point
    t = d @ cylinder.axis
    perp = d - np.outer(t, cylinder.axis)
    n = perp / np.linalg.norm(perp, axis=1)[:, None]
    e1, e2 = perpendicular_basis(cylinder.axis)
    jac = np.column_stack([-n @ e1, -n @ e2, -t * (n @ e1), -t * (n @ e2), -np.ones(len(p))])
    return n, jac


def sphere_jacobian(points, centre) -> tuple[np.ndarray, np.ndarray]:
    """The unit radial directions (N, 3) of points about a fitted sphere's ``centre`` and the residuals'
    Jacobian (N, 4) in the sphere's parameters (the centre, the radius)."""
    d = np.asarray(points, float) - np.asarray(centre, float)
    n = d / np.linalg.norm(d, axis=1)[:, None]
    return n, np.column_stack([-n, -np.ones(len(n))])


def plane_jacobian(points, plane) -> tuple[np.ndarray, np.ndarray]:
    """The plane's normal at every point (N, 3) and the residuals' Jacobian (N, 3) in the plane's
    parameters (two tilts of the normal, the offset) of a :class:`arm_model.geometry.PlaneFit`."""
    d = np.asarray(points, float) - plane.point
    e1, e2 = perpendicular_basis(plane.normal)
    n = np.tile(plane.normal, (len(d), 1))
    return n, np.column_stack([d @ e1, d @ e2, -np.ones(len(d))])


def fit_sensitivity(n: np.ndarray, jac: np.ndarray, row: int) -> np.ndarray:
    """(N, 3) the first-order change of a fit's parameter ``row`` per metre of each point's coordinates,
    for residuals whose change is ``n_i . dp_i`` (``n`` (N, 3)) and Jacobian ``jac`` (N, P) in the
    parameters: the Gauss-Newton refit moves the parameters by ``-pinv(jac) dr``."""
    # the parameter's row of the least-squares pseudo-inverse (stable for tall thin Jacobians)
    g = np.linalg.pinv(jac)[row]
    return -g[:, None] * n


def diameter_sensitivity(points, cylinder: CylinderFit) -> np.ndarray:
    """(N, 3) dD/dp_i: the fitted diameter's first-order change per metre of each point's coordinates."""
    n, jac = cylinder_jacobian(points, cylinder)
    return 2.0 * fit_sensitivity(n, jac, 4)


@dataclass(frozen=True)
class DiameterUncertainty:
    """Standard uncertainties of a fitted diameter [m]: ``u`` in total, from the errors of each point
    alone (``independent``) and from the errors the points share (``parameters``, ``compliance``), and
    ``if_independent``: what ``u`` would be if every point's whole covariance were independent of the
    others' (the naive sum, shown to say how much the shared errors matter)."""
    u: float
    independent: float
    parameters: float
    compliance: float
    if_independent: float

    def as_dict(self) -> dict:
        return {"u_mm": self.u * 1e3, "independent_mm": self.independent * 1e3,
                "parameters_mm": self.parameters * 1e3, "compliance_mm": self.compliance * 1e3,
                "if_independent_mm": self.if_independent * 1e3}


def diameter_uncertainty(sens: np.ndarray, cov: np.ndarray, systematic: np.ndarray | None = None,
                         n_parameters: int | None = None) -> DiameterUncertainty:
    """Propagate point covariances to a fitted diameter.

    Args:
        sens: (N, 3) from :func:`diameter_sensitivity`.
        cov: (N, 3, 3) each point's whole covariance [m^2] (shared part included).
        systematic: (N, R, 3) shared factor rows (``Propagation.systematic``) or None (all independent).
        n_parameters: how many of the R rows are the parameters' (the rest: the compliances); None: all.
    """
    s = np.asarray(sens, float)
    cov = np.asarray(cov, float)
    naive = float(np.einsum("ni,nij,nj->", s, cov, s))
    if systematic is None or systematic.shape[1] == 0:
        return DiameterUncertainty(*(np.sqrt(max(naive, 0.0)),) * 2, 0.0, 0.0, float(np.sqrt(max(naive, 0.0))))
    shared_cov = np.einsum("nri,nrj->nij", systematic, systematic)
    indep = float(np.einsum("ni,nij,nj->", s, cov - shared_cov, s))
    v = np.einsum("nri,ni->r", systematic, s)
    k = systematic.shape[1] if n_parameters is None else int(n_parameters)
    par, comp = float(v[:k] @ v[:k]), float(v[k:] @ v[k:])
    indep = max(indep, 0.0)
    return DiameterUncertainty(float(np.sqrt(indep + par + comp)), float(np.sqrt(indep)), float(np.sqrt(par)),
                               float(np.sqrt(comp)), float(np.sqrt(max(naive, 0.0))))


@dataclass(frozen=True)
class FormUncertainty:
    """The form error (max - min of the residuals) of a fitted cylinder and its uncertainty [m]:
    ``u`` the standard deviation of the sampled form errors, ``inflation`` their mean minus the
    measured form error (what the point errors alone add to a form error), ``samples`` how many."""
    form: float
    u: float
    inflation: float
    samples: int

    def as_dict(self) -> dict:
        return {"form_mm": self.form * 1e3, "u_form_mm": self.u * 1e3, "inflation_mm": self.inflation * 1e3,
                "samples": self.samples}


def form_uncertainty(points, cylinder: CylinderFit, cov: np.ndarray, systematic: np.ndarray | None = None,
                     samples: int = FORM_SAMPLES, seed: int = 0) -> FormUncertainty:
    """Sample the form error of the cylinder fitted to ``points`` under the point errors of
    ``cov`` (N, 3, 3) [m^2] with the shared factor rows ``systematic`` (N, R, 3) (see the module
    docstring); seeded, so the same data give the same figure."""
    n, jac = cylinder_jacobian(points, cylinder)
    return residual_form_uncertainty(cylinder.residuals, n, jac, cov, systematic, samples, seed)


def residual_form_uncertainty(residuals, n: np.ndarray, jac: np.ndarray, cov: np.ndarray,
                              systematic: np.ndarray | None = None, samples: int = FORM_SAMPLES,
                              seed: int = 0) -> FormUncertainty:
    """:func:`form_uncertainty` for any least-squares fit: its ``residuals`` (N,) [m], the directions
    ``n`` (N, 3) along which a point's move changes its residual, and the residuals' Jacobian ``jac``
    (N, P) in the fit's parameters (:func:`sphere_jacobian`, :func:`plane_jacobian`)."""
    if samples < 2:
        raise ValueError(f"samples must be at least 2, got {samples}")
    cov = np.asarray(cov, float)
    shared = None
    if systematic is not None and systematic.shape[1]:
        cov = cov - np.einsum("nri,nrj->nij", systematic, systematic)
        shared = np.einsum("nri,ni->nr", systematic, n)              # (N, R) radial parts
    var = np.maximum(np.einsum("ni,nij,nj->n", n, cov, n), 0.0)      # radial variance of each point alone
    pinv = np.linalg.pinv(jac)
    rng = np.random.default_rng(seed)
    eps = rng.standard_normal((len(n), samples)) * np.sqrt(var)[:, None]
    if shared is not None:
        eps += shared @ rng.standard_normal((shared.shape[1], samples))
    res = np.asarray(residuals, float)
    r = res[:, None] + eps - jac @ (pinv @ eps)    # after the refit
    f = r.max(axis=0) - r.min(axis=0)
    form = float(res.max() - res.min())
    return FormUncertainty(form, float(f.std(ddof=1)), float(f.mean() - form), samples)
