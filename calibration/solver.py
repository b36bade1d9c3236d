"""Levenberg-Marquardt on the exact CasADi residual and Jacobian of a :class:`~calibration.problem.Problem`.

Unknowns: the free parameters and every nuisance increment, solved jointly. The Jacobian is sparse
(a dense block for the parameters, small blocks for each artefact instance); each step solves the
damped normal equations of the column-scaled Jacobian with an LU: dense (LAPACK) up to
:data:`DENSE_UNKNOWNS` unknowns, where scipy.sparse's overhead costs more than the arithmetic, sparse
(SuperLU) beyond. Columns are
scaled by their norms (Marquardt), so metres, radians and m/N mix without hand-set weights.
The exit status is always checked: an attempt that runs out of iterations starts again from its best point
and the damping it reached, the column scales renewed (a restart); no convergence after that raises
:class:`arm_model.NumericalError`.
"""
from __future__ import annotations

import warnings
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike

from arm_model import NumericalError, parallel

from .problem import Evaluation, Problem

__all__ = ["LMResult", "Prior", "levenberg_marquardt", "normal_solver", "normal_factor", "NormalFactor",
           "normal_matrix", "column_norms", "scale_columns", "dense_enough", "blas_threads", "RESTARTS",
           "DENSE_UNKNOWNS", "tight_rows", "TIGHT_RATIO", "SINGULAR"]


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
    damping: float = 1e-3         # the damping it ended with (where a restart continues from)


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


#: unknowns (columns of the Jacobian) up to which the normal equations are formed and factored dense (LAPACK)
#: instead of sparse (SuperLU): below it scipy.sparse's per-call overhead outweighs the arithmetic it saves
#: (one step, one BLAS thread, 2026-11-27: 111 unknowns and 226 rows 0.7 ms dense against 3 ms sparse; 460 unknowns
#: and 3000 rows 23 ms against 46 ms; 1560 unknowns and 10 000 rows 615 ms against 122 ms). Same equations, the
#: same results to rounding.
DENSE_UNKNOWNS = 400


#: the message of a normal matrix that is exactly singular ({}: what was singular)
SINGULAR = ("unidentifiable: an unknown does not affect the residuals, the normal matrix is singular ({}) (too few "
            "distinct points on a feature, a pose repeated, or a parameter the data cannot identify)")


class NormalFactor:
    """LU factors of a normal matrix ``J^T J + diag(damping)``: :meth:`solve` and :meth:`log_abs_det`, dense
    (LAPACK ``getrf``) or sparse (SuperLU)."""

    def __init__(self, a: np.ndarray | sp.spmatrix) -> None:
        self.dense = isinstance(a, np.ndarray)
        try:
            if self.dense:
                with np.errstate(all="ignore"), warnings.catch_warnings():
                    warnings.simplefilter("ignore", sla.LinAlgWarning)
                    self._lu = sla.lu_factor(a, check_finite=False)
                if np.any(np.diagonal(self._lu[0]) == 0.0) or not np.all(np.isfinite(self._lu[0])):
                    raise RuntimeError("Factor is exactly singular")
            else:
                self._superlu = spla.splu(sp.csc_matrix(a))
        except RuntimeError as exc:          # exactly singular
            raise NumericalError(SINGULAR.format(exc)) from None

    def solve(self, b: np.ndarray) -> np.ndarray:
        """``A^-1 b`` for a vector or a matrix of columns ``b``."""
        if self.dense:
            out: np.ndarray = sla.lu_solve(self._lu, b, check_finite=False)
            return out
        return np.asarray(self._superlu.solve(np.asarray(b, dtype=float)))

    def log_abs_det(self) -> float:
        """``log |det A|`` (the sum of ``log |U_ii|``)."""
        u = np.diagonal(self._lu[0]) if self.dense else self._superlu.U.diagonal()
        return float(np.sum(np.log(np.abs(u))))


def dense_enough(n_unknowns: int) -> bool:
    """Whether normal equations of ``n_unknowns`` are handled dense (:data:`DENSE_UNKNOWNS`)."""
    return n_unknowns <= DENSE_UNKNOWNS


def _full_jacobian(ev: Evaluation) -> np.ndarray | sp.csc_matrix:
    """``[J_p J_t]``: dense when it has at most :data:`DENSE_UNKNOWNS` columns, else sparse CSC."""
    assert ev.jp is not None and ev.jt is not None, "an evaluation with its Jacobians"
    if dense_enough(ev.jp.shape[1] + ev.jt.shape[1]):
        return np.hstack([ev.jp, ev.jt.toarray()])
    if ev.jp.shape[1] == 0:
        return ev.jt.tocsc()
    return sp.hstack([sp.csr_matrix(ev.jp), ev.jt], format="csc")


def column_norms(j: np.ndarray | sp.spmatrix) -> np.ndarray:
    """The Euclidean norm of each column of ``j`` (dense or sparse)."""
    sq = np.einsum("ij,ij->j", j, j) if isinstance(j, np.ndarray) else np.asarray(j.multiply(j).sum(axis=0)).ravel()
    out: np.ndarray = np.sqrt(sq)
    return out


def scale_columns(j: np.ndarray | sp.spmatrix, factor: np.ndarray) -> np.ndarray | sp.csc_matrix:
    """``j @ diag(factor)`` (dense stays dense, sparse comes back CSC)."""
    if isinstance(j, np.ndarray):
        return j * factor
    return (j @ sp.diags(factor)).tocsc()


def normal_matrix(j: np.ndarray | sp.spmatrix) -> np.ndarray | sp.csc_matrix:
    """``J^T J``: dense for a dense ``j`` or a sparse one of at most :data:`DENSE_UNKNOWNS` columns, else sparse
    CSC."""
    if isinstance(j, np.ndarray):
        return j.T @ j
    jtj = j.T @ j
    return jtj.toarray() if dense_enough(j.shape[1]) else jtj.tocsc()


def normal_solver(j: np.ndarray | sp.spmatrix, damping: np.ndarray | float = 0.0) -> Callable[[np.ndarray], np.ndarray]:
    """A solver ``b -> (J^T J + diag(damping))^-1 b``."""
    return normal_factor(j, damping).solve


def normal_factor(j: np.ndarray | sp.spmatrix, damping: np.ndarray | float = 0.0) -> NormalFactor:
    """The LU factors of the normal matrix ``J^T J + diag(damping)`` (:class:`NormalFactor`)."""
    return _damped_factor(normal_matrix(j), damping)


def _damped_factor(a: np.ndarray | sp.csc_matrix, damping: np.ndarray | float) -> NormalFactor:
    """The LU factors of the normal matrix ``a`` (``J^T J``) plus ``diag(damping)``."""
    n = a.shape[1]
    d = np.broadcast_to(np.asarray(damping, dtype=float), (n,))
    if isinstance(a, np.ndarray):
        a = a.copy()
        a.flat[:: n + 1] += d
        return NormalFactor(a)
    return NormalFactor(a + sp.diags(d, format="csc"))


#: fresh starts of Levenberg-Marquardt from its best point when an attempt runs out of iterations
RESTARTS = 3


def levenberg_marquardt(problem: Problem, p0: ArrayLike, states0: list[np.ndarray], *, max_iter: int = 200,
                        xtol: float = 1e-10, ftol: float = 1e-15, prior: Prior | None = None) -> LMResult:
    """Minimise ``0.5 |r_w|^2`` over the free parameters and the nuisance increments (plus the prior's
    ``0.5 |(p - centre) / size|^2`` with a :class:`Prior`: the maximum a posteriori estimate).

    Args:
        p0: full parameter vector [SI]; entries not in ``problem.free`` stay as given.
        states0: starting nuisance states (``problem.initial_states``).
        max_iter: iterations of one attempt; an attempt that runs out starts again from its best point and
            the damping it reached, its column scales renewed (a restart), up to :data:`RESTARTS` times; a
            restart that reset the damping to its start spent the next attempt's first iterations re-growing it
            (a campaign one attempt fits in 9 iterations did not converge in 4 attempts of 4).
        xtol: stop when the scaled step (its effect on the weighted residuals) is below ``xtol``.
        ftol: stop when the predicted and actual relative cost reductions are below ``ftol``.
        prior: a Gaussian prior on the free parameters, or None.

    The result's ``evaluation`` and ``cost`` are the data rows' (the prior's part is ``prior_cost``); its
    ``iterations`` count every attempt's.
    """
    p, states, done, lam = np.array(p0, dtype=float), list(states0), 0, 1e-3
    for _attempt in range(RESTARTS + 1):
        out = _lm_attempt(problem, p, states, max_iter, xtol, ftol, prior, lam)
        done += out.iterations
        if out.status is not None:
            out.iterations = done
            return out
        p, states, lam = out.p, out.states, out.damping
    cause = tight_rows(problem) or ("the data may not determine the unknowns (a feature probed at too few "
                                    "distinct poses, poses repeated, or an arm far from its description); check "
                                    "the points and the arm")
    raise NumericalError(f"Levenberg-Marquardt did not converge in {done} iterations ({RESTARTS} restarts "
                         f"from its best point; cost {out.cost:.6g}): {cause}")


#: a row whose standard uncertainty is below this fraction of the median row's is held so tightly that
#: Levenberg-Marquardt may not follow it (a certified length of 1 pm beside 0.1 mm of scatter, 1e-9)
TIGHT_RATIO = 1e-6


def tight_rows(problem: Problem) -> str | None:
    """What holds the fit far tighter than its other rows (rows whose standard uncertainty is below
    :data:`TIGHT_RATIO` of the median row's), said for a fit that did not converge; None when nothing is.

    A length ``L`` held at ``u`` is a curved valley of the cost whose floor Levenberg-Marquardt follows by
    steps of about ``sqrt(2 L u)`` (0.3 um at 1 pm on 50 mm): the centres it joins cannot move the millimetres
    a fit asks of them."""
    sig = problem.sigma
    if len(sig) < 2:
        return None
    med = float(np.median(sig))
    k = int(np.argmin(sig))
    if not sig[k] < TIGHT_RATIO * med:
        return None
    if problem.row_distance[k] >= 0:
        d = problem.distance_items[problem.row_distance[k]]
        what = (f"the certified length between '{d.between[0]}' and '{d.between[1]}' (measurement "
                f"'{d.measurement}') held at its stated u {sig[k] * 1e3:.3g} mm")
        ask = "state the certificate's real standard uncertainty (u_length_mm, or --sigma-length-um)"
    else:
        kind = problem.instances[problem.row_instance[k]].kind
        what = f"the {kind} rows held at a standard uncertainty of {sig[k] * 1e3:.3g} mm"
        ask = "state their real standard uncertainty (the --sigma-*-um options)"
    return (f"{what}, {med / sig[k]:.2g} times tighter than the median row ({med * 1e3:.3g} mm): a fit follows a "
            f"constraint that tight by tiny steps and cannot move the unknowns it joins; {ask}")


def _lm_attempt(problem: Problem, p: ArrayLike, states: list[np.ndarray], max_iter: int, xtol: float, ftol: float,
                prior: Prior | None, lam: float = 1e-3) -> LMResult:
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
    scale = column_norms(j)
    scale[scale == 0] = 1.0
    nu = 2.0
    status = None
    it = 0
    scaled = None               # (js, its normal matrix, gradient) of j, scale: kept while a step is rejected
    for it in range(1, max_iter + 1):
        if scaled is None:
            js = scale_columns(j, 1.0 / scale)
            scaled = (js, normal_matrix(js), js.T @ ev.r)
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
            scale = np.maximum(scale, column_norms(j))
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
        return LMResult(p, states, ev, cost, it, n_eval, status, damping=lam)
    assert ev.jp is not None and ev.jt is not None, "an evaluation with its Jacobians"
    data = Evaluation(ev.r[:n_data], ev.x, ev.jp[:n_data], ev.jt[:n_data])
    rd = data.r
    return LMResult(p, states, data, 0.5 * float(rd @ rd), it, n_eval, status, cost - 0.5 * float(rd @ rd), lam)


def blas_threads(n: int | None = 1) -> AbstractContextManager[Any]:
    """Context limiting the BLAS threads (threadpoolctl) to ``n`` (None: unchanged). The matrices here
    are thin (thousands x tens): one thread is as fast, and several threads on a busy machine are
    slower by orders of magnitude (OpenBLAS spin-waits). (:func:`arm_model.parallel.blas_threads`.)"""
    limits: AbstractContextManager[Any] = parallel.blas_threads(n)
    return limits
