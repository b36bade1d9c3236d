"""Levenberg-Marquardt on the exact CasADi residual and Jacobian of a :class:`~calibration.problem.Problem`.

Unknowns: the free parameters and every nuisance increment, solved jointly. The Jacobian is sparse
(a dense block for the parameters, small blocks for each artefact instance); each step solves the
damped normal equations of the column-scaled Jacobian with a sparse LU (SuperLU). Columns are
scaled by their norms (Marquardt), so metres, radians and m/N mix without hand-set weights.
The exit status is always checked: an attempt that runs out of iterations starts again from its best point
with the damping reset (a damped restart); no convergence after that raises :class:`arm_model.NumericalError`.
"""
from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike

from arm_model import NumericalError, parallel

from .problem import Evaluation, Problem

__all__ = ["LMResult", "Prior", "levenberg_marquardt", "normal_solver", "normal_factor", "blas_threads",
           "RESTARTS"]


@dataclass
class LMResult:
    p: np.ndarray                 # full parameter vector [SI]
    states: list[np.ndarray]      # nuisance states
    evaluation: Evaluation        # residuals and Jacobians at the solution
    cost: float                   # 0.5 * sum(r_w**2) of the data rows
    iterations: int
    evaluations: int
    status: str | None            # why it stopped (a convergence reason; None only inside an attempt)
    prior_cost: float = 0.0       # 0.5 * sum(((p - centre) / size)**2) over the free parameters (with a prior)


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on the free parameters: ``p[i] ~ N(centre[i], size[i]^2)`` [SI], full-length
    vectors (entries of parameters that are not free are ignored). It enters the fit as one
    pseudo-observation row per free parameter, ``(p - centre) / size``."""
    centre: np.ndarray
    size: np.ndarray

    def rows(self, p: ArrayLike, free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(residual rows (nf,), their Jacobian's diagonal (nf,)) for the free indices ``free``."""
        s = self.size[free]
        return (np.asarray(p)[free] - self.centre[free]) / s, 1.0 / s

    def augment(self, ev: Evaluation, p: ArrayLike, free: np.ndarray) -> Evaluation:
        """``ev`` with the prior rows appended (below the data rows)."""
        r, d = self.rows(p, free)
        if ev.jp is None or ev.jt is None:
            return Evaluation(np.concatenate([ev.r, r]), ev.x)
        return Evaluation(np.concatenate([ev.r, r]), ev.x, np.vstack([ev.jp, np.diag(d)]),
                          sp.vstack([ev.jt, sp.csr_matrix((len(r), ev.jt.shape[1]))], format="csr"))


def _full_jacobian(ev: Evaluation) -> sp.csc_matrix:
    assert ev.jp is not None and ev.jt is not None, "an evaluation with its Jacobians"
    if ev.jp.shape[1] == 0:
        return ev.jt.tocsc()
    return sp.hstack([sp.csr_matrix(ev.jp), ev.jt], format="csc")


def normal_solver(j: sp.spmatrix, damping: np.ndarray | float = 0.0) -> Callable[[np.ndarray], np.ndarray]:
    """A solver ``b -> (J^T J + diag(damping))^-1 b`` (sparse LU of the normal matrix)."""
    solve: Callable[[np.ndarray], np.ndarray] = normal_factor(j, damping).solve
    return solve


def normal_factor(j: sp.spmatrix, damping: np.ndarray | float = 0.0) -> spla.SuperLU:
    """The sparse LU factors of the normal matrix ``J^T J + diag(damping)`` (``.solve``; ``|det|`` is the
    product of ``|U_ii|``)."""
    return _damped_factor((j.T @ j).tocsc(), damping)


def _damped_factor(a: sp.csc_matrix, damping: np.ndarray | float) -> spla.SuperLU:
    """The sparse LU factors of the normal matrix ``a`` (``J^T J``) plus ``diag(damping)``."""
    n = a.shape[1]
    a = a + sp.diags(np.broadcast_to(damping, (n,)).astype(float), format="csc")
    try:
        lu = spla.splu(a)
    except RuntimeError as exc:          # exactly singular
        raise NumericalError(f"unidentifiable: an unknown does not affect the residuals, the normal matrix is "
                             f"singular ({exc}) (too few distinct points on a feature, a pose repeated, or a "
                             "parameter the data cannot identify)") from None
    return lu


#: fresh starts of Levenberg-Marquardt from its best point when an attempt runs out of iterations
RESTARTS = 3


def levenberg_marquardt(problem: Problem, p0: ArrayLike, states0: list[np.ndarray], *, max_iter: int = 200,
                        xtol: float = 1e-10, ftol: float = 1e-15, prior: Prior | None = None) -> LMResult:
    """Minimise ``0.5 |r_w|^2`` over the free parameters and the nuisance increments (plus the prior's
    ``0.5 |(p - centre) / size|^2`` with a :class:`Prior`: the maximum a posteriori estimate).

    Args:
        p0: full parameter vector [SI]; entries not in ``problem.free`` stay as given.
        states0: starting nuisance states (``problem.initial_states``).
        max_iter: iterations of one attempt; an attempt that runs out starts again from its best point with
            the damping reset (a damped restart), up to :data:`RESTARTS` times.
        xtol: stop when the scaled step (its effect on the weighted residuals) is below ``xtol``.
        ftol: stop when the predicted and actual relative cost reductions are below ``ftol``.
        prior: a Gaussian prior on the free parameters, or None.

    The result's ``evaluation`` and ``cost`` are the data rows' (the prior's part is ``prior_cost``); its
    ``iterations`` count every attempt's.
    """
    p, states, done = np.array(p0, dtype=float), list(states0), 0
    for _attempt in range(RESTARTS + 1):
        out = _lm_attempt(problem, p, states, max_iter, xtol, ftol, prior)
        done += out.iterations
        if out.status is not None:
            out.iterations = done
            return out
        p, states = out.p, out.states
    raise NumericalError(f"Levenberg-Marquardt did not converge in {done} iterations ({RESTARTS} damped restarts "
                         f"from its best point; cost {out.cost:.6g}): the data may not determine the unknowns "
                         "(a feature probed at too few distinct poses, poses repeated, or an arm far from its "
                         "description); check the points and the arm")


def _lm_attempt(problem: Problem, p: ArrayLike, states: list[np.ndarray], max_iter: int, xtol: float, ftol: float,
                prior: Prior | None) -> LMResult:
    """One run of Levenberg-Marquardt from ``p``, ``states``: its result, with ``status`` None when it ran out
    of iterations (``p``, ``states`` then its best point)."""
    free = problem.free
    n_data = problem.n_rows

    def evaluate(p: np.ndarray, states: list[np.ndarray], jac: bool = True) -> Evaluation:
        ev = problem.evaluate(p, states, jac=jac)
        return ev if prior is None else prior.augment(ev, p, free)

    p = np.array(p, dtype=float)
    states = list(states)
    ev = evaluate(p, states)
    cost = 0.5 * float(ev.r @ ev.r)
    n_eval = 1
    nf = len(free)
    j = _full_jacobian(ev)
    scale = np.sqrt(np.asarray(j.multiply(j).sum(axis=0)).ravel())
    scale[scale == 0] = 1.0
    lam, nu = 1e-3, 2.0
    status = None
    it = 0
    scaled = None               # (js, its normal matrix, gradient) of j, scale: kept while a step is rejected
    for it in range(1, max_iter + 1):
        if scaled is None:
            js = j @ sp.diags(1.0 / scale)
            scaled = (js, (js.T @ js).tocsc(), js.T @ ev.r)
        js, jtj, g = scaled
        ds = -_damped_factor(jtj, lam).solve(g)
        jds = js @ ds
        pred = -(g @ ds) - 0.5 * float(jds @ jds)
        if pred <= ftol * cost or not np.isfinite(pred):
            status = "converged: predicted cost reduction below tolerance"
            break
        d = ds / scale
        p_new = p.copy()
        p_new[free] += d[:nf]
        states_new = problem.retract(states, d[nf:])
        ev_new = evaluate(p_new, states_new, jac=False)
        n_eval += 1
        cost_new = 0.5 * float(ev_new.r @ ev_new.r)
        actual = cost - cost_new
        rho = actual / pred if pred > 0 else -1.0
        if np.isfinite(cost_new) and rho > 1e-4:
            p, states = p_new, states_new
            ev = evaluate(p, states)
            n_eval += 1
            j = _full_jacobian(ev)
            scale = np.maximum(scale, np.sqrt(np.asarray(j.multiply(j).sum(axis=0)).ravel()))
            scaled = None
            small_step = np.max(np.abs(ds)) < xtol
            small_cost = actual <= ftol * cost_new and pred <= ftol * cost
            cost = cost_new
            lam *= max(1 / 3, 1 - (2 * rho - 1) ** 3)
            nu = 2.0
            if small_step:
                status = "converged: step below tolerance"
                break
            if small_cost:
                status = "converged: cost reduction below tolerance"
                break
        else:
            lam *= nu
            nu *= 2.0
            if lam > 1e20:
                raise NumericalError(f"Levenberg-Marquardt stalled after {it} iterations (no step reduces the "
                                     f"cost {cost:.6g}); the problem may be ill-posed")
    if prior is None:
        return LMResult(p, states, ev, cost, it, n_eval, status)
    assert ev.jp is not None and ev.jt is not None, "an evaluation with its Jacobians"
    data = Evaluation(ev.r[:n_data], ev.x, ev.jp[:n_data], ev.jt[:n_data])
    rd = data.r
    return LMResult(p, states, data, 0.5 * float(rd @ rd), it, n_eval, status, cost - 0.5 * float(rd @ rd))


def blas_threads(n: int | None = 1) -> AbstractContextManager[Any]:
    """Context limiting the BLAS threads (threadpoolctl) to ``n`` (None: unchanged). The matrices here
    are thin (thousands x tens): one thread is as fast, and several threads on a busy machine are
    slower by orders of magnitude (OpenBLAS spin-waits). (:func:`arm_model.parallel.blas_threads`.)"""
    limits: AbstractContextManager[Any] = parallel.blas_threads(n)
    return limits
