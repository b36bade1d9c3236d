"""Identifiability: which parameter combinations the data can and cannot separate, and how well.

The nuisance unknowns (centres, axes, planes, the reference transform) are eliminated first: the
reduced Jacobian ``J_red = (I - P_t) J_p`` (``P_t`` the projection onto the nuisance columns) is what
the data say about the parameters. Its columns are scaled by the norms of the *unreduced* columns
(so a parameter whose effect the nuisance absorbs entirely, like the base rotation ``j1.theta_offset``
without reference coordinates, shows as a near-zero column) and decomposed:

* SVD: singular values, numerical rank (``s > rank_tol * s_max``), condition number of the
  identifiable part, and the null-space directions written as named parameter combinations;
* QR with column pivoting (LAPACK ``geqp3``): which parameters to hold fixed, one per null direction;
  for each, the combination with the kept parameters that the data cannot see.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .solver import normal_solver

__all__ = ["Combination", "Identifiability", "reduced_jacobian", "analyse", "DEFAULT_RANK_TOL"]

#: relative singular value below which a direction counts as not identifiable
DEFAULT_RANK_TOL = 1e-4


@dataclass(frozen=True)
class Combination:
    """A direction in parameter space: ``sum(coef_k * delta(name_k))`` (SI units of each parameter).

    For a dependent parameter, its own coefficient is 1: moving it by 1 (its SI unit) and the others by
    their coefficients leaves every residual unchanged to first order.
    """
    terms: tuple[tuple[str, float], ...]
    singular_value: float | None = None

    def text(self, digits: int = 4) -> str:
        out = []
        for k, (name, c) in enumerate(self.terms):
            mag = f"{abs(c):.{digits}g}"
            coef = "" if mag == "1" else f"{mag}*"
            sign = ("-" if c < 0 else "") if k == 0 else (" - " if c < 0 else " + ")
            out.append(f"{sign}{coef}{name}")
        return "".join(out)

    def to_dict(self) -> dict:
        return {"text": self.text(), "terms": {n: c for n, c in self.terms},
                "singular_value": self.singular_value}


@dataclass(frozen=True)
class Identifiability:
    """Result of :func:`analyse` for the parameters ``names``.

    Attributes:
        names: the candidate free parameters analysed (columns).
        scale: column scale [1 / SI unit], the unreduced column norms of the weighted Jacobian.
        singular_values: of the scaled reduced Jacobian, descending (dimensionless).
        rank: numerical rank (``s > rank_tol * s[0]``).
        condition: ``s[0] / s[rank - 1]``: conditioning of the identifiable part.
        dependent: parameters that QR with column pivoting puts after the rank (to hold fixed).
        combinations: per dependent parameter, the null combination with the kept ones.
        null: the SVD null-space directions as combinations (largest terms first).
        weakest: the least identifiable kept directions (smallest singular values above the rank).
    """
    names: tuple[str, ...]
    scale: np.ndarray
    singular_values: np.ndarray
    rank: int
    rank_tol: float
    condition: float
    dependent: tuple[str, ...]
    combinations: dict = field(default_factory=dict)
    null: tuple[Combination, ...] = ()
    weakest: tuple[Combination, ...] = ()
    no_effect: tuple[str, ...] = ()
    gauge: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {"parameters": list(self.names), "rank": self.rank, "rank_tol": self.rank_tol,
                "condition_number": self.condition,
                "singular_values": [float(s) for s in self.singular_values],
                "dependent": list(self.dependent),
                "combinations": {k: v.to_dict() for k, v in self.combinations.items()},
                "null_space": [c.to_dict() for c in self.null],
                "weakest": [c.to_dict() for c in self.weakest],
                "no_effect": list(self.no_effect), "rigid_motion_parameters": list(self.gauge)}


def reduced_jacobian(jp: np.ndarray, jt: sp.spmatrix) -> np.ndarray:
    """``J_p - J_t (J_t^T J_t)^-1 J_t^T J_p``: the parameter Jacobian with the nuisance eliminated."""
    if jt.shape[1] == 0 or jp.shape[1] == 0:
        return jp.copy()
    solve = normal_solver(jt.tocsc())
    x = solve(np.asarray(jt.T @ jp))
    red = jp - jt @ x
    # one refinement step (iterative refinement of the projection)
    x2 = solve(np.asarray(jt.T @ red))
    return red - jt @ x2


def _terms(names, vec, scale_in_si, rel: float = 1e-3, lead: int | None = None, most: int = 12) -> tuple:
    """Named terms of a direction ``vec`` (SI) whose scaled size exceeds ``rel`` of the largest
    (at most ``most``, the largest first, ``lead`` first if given)."""
    mag = np.abs(vec) * scale_in_si
    keep = np.flatnonzero(mag > rel * mag.max())
    order = sorted(keep, key=lambda k: (k != lead, -mag[k]))[:most]
    norm = vec[order[0]]
    return tuple((names[k], float(vec[k] / norm)) for k in order)


def analyse(jred: np.ndarray, jp: np.ndarray, names, rank_tol: float = DEFAULT_RANK_TOL,
            prefer=None, n_weak: int = 3, gauge: np.ndarray | None = None) -> Identifiability:
    """Identifiability of the parameters ``names`` from the reduced (``jred``) and full (``jp``)
    weighted Jacobians (rows x len(names)).

    Args:
        rank_tol: relative singular value below which a direction is not identifiable.
        prefer: optional list of names in order of preference to keep (they are offered to the
            pivoting first when columns tie).
        gauge: (len(names), k) parameter directions [SI] known to leave the cost unchanged (exact
            symmetries, e.g. rigid motions of the base frame): projected out, so they count as null.
    """
    names = tuple(names)
    n = len(names)
    if n == 0:
        return Identifiability(names, np.zeros(0), np.zeros(0), 0, rank_tol, 1.0, ())
    full_norm = np.linalg.norm(jp, axis=0)
    tiny = full_norm <= 1e-12 * max(full_norm.max(), 1e-300)
    scale = np.where(tiny, 1.0, full_norm)
    a = jred / scale
    a[:, tiny] = 0.0
    gauge_names: set = set()
    if gauge is not None and gauge.size:
        gs = gauge * scale[:, None]
        q, _ = np.linalg.qr(gs)
        a = a - (a @ q) @ q.T
        mag = np.abs(gs) / np.abs(gs).max(axis=0)
        gauge_names = {names[k] for k in np.flatnonzero(mag.max(axis=1) > 1e-6)}
    _, s, vt = np.linalg.svd(a, full_matrices=False)
    smax = s[0] if s.size and s[0] > 0 else 1.0
    rank = int(np.sum(s > rank_tol * smax))
    condition = float(s[0] / s[rank - 1]) if rank else float("inf")
    # pivoted QR, columns offered in preference order
    order = np.arange(n)
    if prefer:
        pref = {nm: i for i, nm in enumerate(prefer)}
        order = np.array(sorted(range(n), key=lambda k: pref.get(names[k], len(pref) + k)))
    _, _, piv = sla.qr(a[:, order], mode="economic", pivoting=True)
    piv = order[piv]
    kept, dep = np.sort(piv[:rank]), piv[rank:]
    dependent = tuple(names[k] for k in sorted(dep))
    combos = {}
    for k in sorted(dep):
        v = np.zeros(n)
        v[k] = 1.0
        if rank:
            coef = np.linalg.lstsq(a[:, kept], a[:, k], rcond=None)[0]
            v[kept] = -coef
        v_si = v / scale * scale[k]
        combos[names[k]] = Combination(_terms(names, v_si, scale, lead=k),
                                       float(np.linalg.norm(a @ v)))
    null = tuple(Combination(_terms(names, vt[i] / scale, scale, 1e-2, most=6), float(s[i]))
                 for i in range(rank, len(s)))
    weak = tuple(Combination(_terms(names, vt[i] / scale, scale, 1e-2, most=6), float(s[i]))
                 for i in range(max(rank - n_weak, 0), rank))[::-1]
    return Identifiability(names, scale, s, rank, rank_tol, condition, dependent, combos, null, weak,
                           tuple(names[k] for k in np.flatnonzero(tiny)), tuple(sorted(gauge_names)))
