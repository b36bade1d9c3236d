"""Identifiability: which parameter combinations the data can and cannot separate, and how well.

The nuisance unknowns (centres, axes, planes, the reference transform) are eliminated first: the
reduced Jacobian ``J_red = (I - P_t) J_p`` (``P_t`` the projection onto the nuisance columns) is what
the data say about the parameters. Its columns are scaled by the norms of the *unreduced* columns
(so a parameter whose effect the nuisance absorbs entirely, like the base rotation ``j1.theta_offset``
without reference coordinates, shows as a near-zero column) and decomposed:

* SVD: singular values, numerical rank (``s > rank_tol * max(s_max, 1)``: a scaled column is at most unit, so a
  direction is never kept for being large beside nothing), condition number of the
  identifiable part, and the null-space directions written as named parameter combinations;
* which parameters to hold fixed, one per null direction (:func:`keep_choice`: pivoted Gram-Schmidt on the
  columns scaled by plausible sizes, exact ties by the parameters' own keys, so that neither their order nor
  unknowns the data do not need change the choice); for each, the combination with the kept parameters that
  the data cannot see.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from .solver import dense_enough, normal_solver

if TYPE_CHECKING:
    from arm_model.model import ArmModel

    from .problem import Problem

__all__ = ["Combination", "Identifiability", "NuisanceProjection", "reduced_jacobian", "analyse", "DEFAULT_RANK_TOL",
           "prior_scales", "point_noise", "plausible_length", "weakly_determined", "NOISE_MULTIPLE"]

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

    def to_dict(self) -> dict[str, Any]:
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
    combinations: dict[str, Combination] = field(default_factory=dict)
    null: tuple[Combination, ...] = ()
    weakest: tuple[Combination, ...] = ()
    no_effect: tuple[str, ...] = ()
    gauge: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"parameters": list(self.names), "rank": self.rank, "rank_tol": self.rank_tol,
                "condition_number": self.condition,
                "singular_values": [float(s) for s in self.singular_values],
                "dependent": list(self.dependent),
                "combinations": {k: v.to_dict() for k, v in self.combinations.items()},
                "null_space": [c.to_dict() for c in self.null],
                "weakest": [c.to_dict() for c in self.weakest],
                "no_effect": list(self.no_effect), "rigid_motion_parameters": list(self.gauge)}


def compress_rows(a: np.ndarray) -> np.ndarray:
    """``R`` of ``a = Q R`` (Q orthonormal): the same column norms, inner products, singular values
    and least-squares relations between columns, in ``n`` rows instead of thousands."""
    if a.shape[0] <= a.shape[1]:
        return a
    return np.linalg.qr(a, mode="r")  # type: ignore[return-value]  # numpy 2.4 stubs: mode "r" returns R alone


class NuisanceProjection:
    """``J -> J - J_t (J_t^T J_t)^-1 J_t^T J``: columns with the nuisance unknowns of ``jt`` (rows x nuisance)
    eliminated, its normal equations factored once for every call. Up to
    :data:`~calibration.solver.DENSE_UNKNOWNS` nuisance unknowns ``J_t`` is held dense (its products and the
    factors: LAPACK), beyond it sparse (SuperLU): the same projection to rounding."""

    def __init__(self, jt: sp.spmatrix | np.ndarray) -> None:
        self.n = int(jt.shape[1])
        dense = dense_enough(self.n)
        self.jt = (jt if isinstance(jt, np.ndarray) else jt.toarray()) if dense else sp.csc_matrix(jt)
        self._solve = normal_solver(self.jt) if self.n else None

    def __call__(self, jp: np.ndarray) -> np.ndarray:
        if self._solve is None or jp.shape[1] == 0:
            return jp.copy()
        jt, solve = self.jt, self._solve
        x = solve(np.asarray(jt.T @ jp))
        red = jp - jt @ x
        # one refinement step (iterative refinement of the projection)
        x2 = solve(np.asarray(jt.T @ red))
        out: np.ndarray = red - jt @ x2
        return out


def reduced_jacobian(jp: np.ndarray, jt: sp.spmatrix) -> np.ndarray:
    """``J_p - J_t (J_t^T J_t)^-1 J_t^T J_p``: the parameter Jacobian with the nuisance eliminated
    (:class:`NuisanceProjection`)."""
    if jt.shape[1] == 0 or jp.shape[1] == 0:
        return jp.copy()
    return NuisanceProjection(jt)(jp)


def _terms(names: Sequence[str], vec: np.ndarray, scale_in_si: np.ndarray | float, rel: float = 1e-3,
           lead: int | None = None, most: int = 12) -> tuple[tuple[str, float], ...]:
    """Named terms of a direction ``vec`` (SI) whose scaled size exceeds ``rel`` of the largest
    (at most ``most``, the largest first, ``lead`` first if given)."""
    mag = np.abs(vec) * scale_in_si
    keep = np.flatnonzero(mag > rel * mag.max())
    order = sorted((int(k) for k in keep), key=lambda k: (k != lead, -mag[k]))[:most]
    norm = vec[order[0]]
    return tuple((names[k], float(vec[k] / norm)) for k in order)


def analyse(jred: np.ndarray, jp: np.ndarray, names: Sequence[str], rank_tol: float = DEFAULT_RANK_TOL,
            pivot_scale: np.ndarray | None = None, n_weak: int = 3, gauge: np.ndarray | None = None,
            tie_key: Sequence[Any] | None = None) -> Identifiability:
    """Identifiability of the parameters ``names`` from the reduced (``jred``) and full (``jp``)
    weighted Jacobians (rows x len(names)).

    Args:
        rank_tol: relative singular value below which a direction is not identifiable.
        pivot_scale: column scale [SI] for the choice of the parameters to keep (:func:`keep_choice`; e.g.
            plausible error sizes, :func:`prior_scales`: of two equivalent parameters the one whose plausible
            error moves the data more is kept); default the column norms.
        tie_key: a sort key per parameter for exact ties of that choice (the largest kept); default the place
            in ``names`` (the later kept).
        gauge: (len(names), k) parameter directions [SI] known to leave the cost unchanged (exact
            symmetries, e.g. rigid motions of the base frame): projected out, so they count as null.
    """
    names = tuple(names)
    n = len(names)
    if n == 0:
        return Identifiability(names, np.zeros(0), np.zeros(0), 0, rank_tol, 1.0, ())
    jred = compress_rows(jred)            # the same column geometry in n rows: every step below is cheap
    full_norm = np.linalg.norm(jp, axis=0)
    tiny = full_norm <= 1e-12 * max(full_norm.max(), 1e-300)
    scale = np.where(tiny, 1.0, full_norm)
    a = jred / scale
    a[:, tiny] = 0.0
    gauge_names: set[str] = set()
    if gauge is not None and gauge.size:
        gs = gauge * scale[:, None]
        q, _ = np.linalg.qr(gs)
        a = a - (a @ q) @ q.T
        mag = np.abs(gs) / np.abs(gs).max(axis=0)
        gauge_names = {names[k] for k in np.flatnonzero(mag.max(axis=1) > 1e-6)}
    _, s, vt = np.linalg.svd(a)           # vt square: every null direction, also with fewer rows than columns
    # relative to the largest, and never to less than a whole column's own effect (``a``'s columns are at most
    # unit): when the nuisance absorbs every parameter (one pose repeated), rounding is not a direction
    smax = max(s[0], 1.0) if s.size else 1.0
    rank = int(np.sum(s > rank_tol * smax))
    condition = float(s[0] / s[rank - 1]) if rank else float("inf")
    # the columns scaled for the choice (same null space as ``a``)
    b = a if pivot_scale is None else a * (scale * np.asarray(pivot_scale, dtype=float))
    chosen = set(keep_choice(b, rank, range(n) if tie_key is None else tie_key))
    kept = np.array(sorted(chosen), dtype=int)
    dep = [k for k in range(n) if k not in chosen]
    dependent = tuple(names[k] for k in dep)
    combos = {}
    dep = sorted(dep)
    coefs = np.linalg.lstsq(a[:, kept], a[:, dep], rcond=None)[0] if rank and dep else None
    for j, k in enumerate(dep):
        v = np.zeros(n)
        v[k] = 1.0
        if coefs is not None:          # rank > 0 (``dep`` is not empty here)
            v[kept] = -coefs[:, j]
        v_si = v / scale * scale[k]
        combos[names[k]] = Combination(_terms(names, v_si, scale, lead=k),
                                       float(np.linalg.norm(a @ v)))
    null = tuple(Combination(_terms(names, vt[i] / scale, scale, 1e-2, most=6), float(s[i]))
                 for i in range(rank, len(s)))
    weak = tuple(Combination(_terms(names, vt[i] / scale, scale, 1e-2, most=6), float(s[i]))
                 for i in range(max(rank - n_weak, 0), rank))[::-1]
    return Identifiability(names, scale, s, rank, rank_tol, condition, dependent, combos, null, weak,
                           tuple(names[k] for k in np.flatnonzero(tiny)), tuple(sorted(gauge_names)))


#: two columns whose lengths (:func:`keep_choice`) agree to this (relative) are tied: the tie key decides
TIE_TOL = 1e-6


def keep_choice(b: np.ndarray, rank: int, tie_key: Sequence[Any]) -> list[int]:
    """The ``rank`` columns of ``b`` (rows x n; each column a parameter's effect over its plausible error size) to
    keep, in the order chosen: greedily the longest column once the chosen ones are taken out of all (pivoted
    Gram-Schmidt, each length computed afresh rather than downdated), so of two equivalent parameters the one whose
    plausible error moves the data more is kept. Columns within :data:`TIE_TOL` of the longest are tied and the
    largest key is kept: a tie is decided by the parameters' own keys, never by their order, by rounding, or by
    how many other parameters there are (a column without effect never competes)."""
    r = np.array(b, dtype=float)
    kept: list[int] = []
    for _ in range(rank):
        norms = np.linalg.norm(r, axis=0)
        norms[kept] = -1.0
        if norms.max() <= 0.0:              # nothing left to keep (a rank counted beyond the columns' own)
            break
        tied = np.flatnonzero(norms >= norms.max() * (1.0 - TIE_TOL))
        j = int(max(tied, key=lambda i: tie_key[int(i)]))
        kept.append(j)
        d = r[:, j] / norms[j]
        for _ in range(2):                  # twice: orthogonal to rounding
            r = r - np.outer(d, d @ r)
    return kept


# ---------------------------------------------------------------------------------------------
# practical identifiability: is the effect of a parameter over a plausible range above the noise?

#: plausible size of a parameter error, by SI unit (compliances: from the description, see
#: :func:`prior_scales`); a parameter the data resolve only to more than ``min_resolution`` of it is
#: not identifiable in practice
#: a link length's drift in time ([1/s], [1/s^2]: :class:`~arm_model.effects.ThermalDrift`): 100 ppm an hour
#: (an aluminium arm, 23 ppm/K, in a room drifting by about 4 K an hour), and per hour squared
PRIOR_SCALES = {"m": 1e-3, "rad": 1e-2, "1": 0.1, "N": 1.0, "N m": 0.1, "rad/(N m)": 1e-4, "1/K": 1e-4,
                "1/s": 1e-4 / 3600.0, "1/s^2": 1e-4 / 3600.0**2}


#: plausible size of a length error in units of the noise of one point: with a robot's scatter (tenths of a
#: millimetre) the plausible errors of its lengths are larger than a measuring arm's
NOISE_MULTIPLE = 10.0


def point_noise(problem: Problem) -> float | None:
    """The largest standard uncertainty [m] of a point of ``problem`` (stated, times the group's factor)."""
    stated = (problem.weights.sigma_of(g["kind"]) for g in problem.groups)
    sig = [v for v in stated if v is not None]
    return max(sig) if sig else None


def plausible_length(noise: float | None = None) -> float:
    """Plausible size [m] of a length error: the larger of 1 mm and :data:`NOISE_MULTIPLE` times ``noise`` (the
    standard uncertainty of one point [m])."""
    return max(PRIOR_SCALES["m"], NOISE_MULTIPLE * (noise or 0.0))


def prior_scales(model: ArmModel, names: Sequence[str], priors: dict[str, float] | None = None,
                 noise: float | None = None,
                 length: float | None = None) -> np.ndarray:
    """Plausible error size [SI] of each parameter: ``priors`` (names or glob patterns -> value) first,
    then the effect's own (``Effect.plausible_size``, e.g. 1 % for a joint gain), then :data:`PRIOR_SCALES`
    by unit; a compliance [m/N] gets 10 times the description's compliance
    along its axis (``*_z``: axial, else bending), at least 1e-8 m/N.

    Lengths [m] and angles [rad] scale together: a length error's plausible size is ``length`` if given,
    else the larger of 1 mm and :data:`NOISE_MULTIPLE` times ``noise`` (the standard uncertainty of one
    point, [m]); an angle's is 0.01 rad times the same factor."""
    import fnmatch
    spec = model.spec
    probe = model.desc.probe
    lsize = length if length is not None else plausible_length(noise)
    factor = lsize / PRIOR_SCALES["m"]
    own = {spec.names[k]: e.plausible_size for e, sl in getattr(model, "effect_slices", lambda: [])()
           if e.plausible_size is not None for k in range(sl.start, sl.stop)}
    out = []
    for n in names:
        hit = [v for pat, v in (priors or {}).items() if fnmatch.fnmatchcase(n, pat)]
        unit = spec.units[spec.index(n)]
        if hit:
            out.append(float(hit[0]))
        elif n in own:
            out.append(float(own[n]))
        elif unit == "m/N":
            c = probe.axial_compliance if n.endswith("_z") else max(probe.bending_compliance_x,
                                                                    probe.bending_compliance_y)
            out.append(max(10.0 * c, 1e-8))
        elif unit in ("m", "rad"):
            out.append(PRIOR_SCALES[unit] * factor)
        else:
            out.append(PRIOR_SCALES.get(unit, 1.0))
    return np.array(out)


def weakly_determined(jred: np.ndarray, names: Sequence[str], prior: np.ndarray, min_resolution: float = 0.1
                      ) -> list[tuple[str, float, Combination]]:
    """Parameters whose standard uncertainty (stated weights, the others free) would exceed
    ``min_resolution * prior``: pivoted QR of ``J_red diag(prior)``; a column whose remaining norm
    ``|R_kk|`` (residual change, in sigmas, over one prior size, beyond what the better-determined
    parameters explain) is below ``1 / min_resolution`` is weak.

    Returns ``[(name, predicted u [SI], Combination with the kept ones)]``, weakest last.
    """
    names = list(names)
    if not names:
        return []
    a = compress_rows(jred) * prior
    _, r, piv = sla.qr(a, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    cut = int(np.sum(d >= 1.0 / min_resolution))
    kept, weak = np.sort(piv[:cut]), piv[cut:]
    out = []
    coefs = np.linalg.lstsq(a[:, kept], a[:, weak], rcond=None)[0] if len(kept) and len(weak) else None
    for j, k in enumerate(weak):
        v = np.zeros(len(names))
        v[k] = 1.0
        if coefs is not None:          # ``kept`` is not empty (``weak`` is not, here)
            v[kept] = -coefs[:, j]
        v_si = v * prior / prior[k]
        u = prior[k] / max(d[list(piv).index(k)], 1e-300)
        out.append((names[k], float(u), Combination(_terms(names, v_si, 1.0 / prior, lead=k))))
    return out
