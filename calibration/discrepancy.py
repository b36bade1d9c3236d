"""Model discrepancy: how much more a fit errs on poses beyond those it was fitted on than its posterior says.

The posterior covariance of a fit covers the parameters' uncertainty under the model; an error the model lacks
(an effect nobody declared, a geometry the chain cannot represent) is absorbed by the parameters near the
training poses and comes back away from them. Its size is estimated from the data by **extrapolative
cross-validation**: for each joint, the poses at either end of the range the data span in that joint
(:data:`EXTREME_SHARE` of the poses each end, :func:`extreme_folds`) are held out in turn, the fit is
repeated on the rest and each held-out pose is predicted (against its feature fitted on the remaining poses:
a seat's centre, a sphere, a plane; a tracker's frame and marker); the discrepancy variance is the excess
of the squared prediction errors over what the fit itself predicts for them (noise and posterior), per
axis, pooled over the folds (a method-of-moments estimate, floored at 0)::

    sigma_d^2 = max(0, sum_O sum_i (e_i^2 - v_i) / sum_O n_O)

Each fold's fit is the full fit with the held-out rows deleted, computed exactly for the model linearised at
the solution (the prior's scales and the noise held): with ``H = J A^-1 J^T`` the hat matrix of the joint
fit (parameters and every nuisance unknown, ``A`` its normal matrix with the prior's precision) and ``r_O``
the weighted residuals of the held-out rows, the held-out prediction errors are ``(I - H_OO)^-1 r_O`` and
their predicted covariance ``s0^2 (I - H_OO)^-1`` (noise plus the posterior of the fit without them; the
group-deletion identity of linear regression, Cook and Weisberg 1982, "Residuals and Influence in
Regression", ch. 3). A fold keeps every feature's fewest points plus one (as :func:`calibration.data.
split_poses`), so that its centre (axis, plane, frame) stays determined.

The same held-out rows also show how the error grows with the distance ``d`` of each held-out pose from the
poses left in its fold (:func:`arm_model.discrepancy.pose_distance`: how far the joint motions from the
nearest of them carry the ball): :func:`fit_growth` fits ``e_i ~ N(0, v_i + sigma_0^2 + g^2 d_i^2)`` by maximum
likelihood (``sigma_0, g >= 0``; started from the method of moments, the least squares of ``e_i^2 - v_i`` on
``(1, d_i^2)``), with delete-one-fold jackknife uncertainties and the likelihood ratio over the constant.
The same rows are also fitted joint by joint (:func:`fit_joint_growth`: ``e_i ~ N(0, v_i + sigma_0^2 + sum_j
g_j^2 c_ij)``, ``c_ij`` joint j's share of ``d_i^2``, :func:`arm_model.discrepancy.travel_shares`), so that an
error growing with one joint's motion grows where that joint moves. What :func:`arm_model.uncertainty.propagate`
adds, per axis, to every corrected point of the calibrated model is :attr:`Discrepancy.written`: the per-joint
growths and ``sigma_0`` with their jackknife uncertainty carried (``sqrt(x^2 + u^2)``), each at least the single
growth's carried the same way (the model file's ``[calibration] model_discrepancy_um`` = ``sigma_0``,
``model_discrepancy_growth_um_per_mm`` = ``g_j``, one a joint, and its training poses; ``aacmm tip``'s ``model
discrepancy`` contribution). Both are 0 (to their sampling scatter) when the model holds the physics of the data; they
grow with what the model lacks as far as the data reach beyond their own poses: an error that shows only far
beyond what the folds span is an extrapolation of ``g``.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from arm_model import NumericalError
from arm_model.discrepancy import TrainingPoses, joint_levers, travel_shares

from .data import centred_angles
from .schur import BlockNormal

__all__ = ["EXTREME_SHARE", "RESOLVED_TRAVEL", "Discrepancy", "Growth", "JointGrowth", "extreme_folds", "fit_growth",
           "fit_joint_growth", "fold_errors", "group_deletions", "deletion_shift", "LARGE_FOLD", "holdable",
           "model_discrepancy"]

log = logging.getLogger(__name__)

#: share of the poses held out at each end of a joint's range
EXTREME_SHARE = 0.15
#: a joint whose RMS ball travel in the folds' held-out rows is below this fraction of the largest joint's is not
#: resolved by them: it grows at the growth of every joint together (:func:`fit_joint_growth`)
RESOLVED_TRAVEL = 0.01


@dataclass(frozen=True)
class Growth:
    """The growing discrepancy ``sigma_d(q)^2 = sigma0^2 + (growth * d(q))^2`` fitted to the held-out rows of
    the extrapolative folds (:func:`fit_growth`, :mod:`arm_model.discrepancy`).

    Attributes:
        sigma0: [m] the discrepancy at the training poses (``d = 0``); growth: [1] its growth per metre of ball
            travel from the nearest training pose (:func:`arm_model.discrepancy.pose_distance`); both floored at 0.
        u_sigma0, u_growth: their standard uncertainties, by the delete-one-fold jackknife (the folds share
            poses and a fold's rows are correlated, which the jackknife over folds respects).
        lr: twice the log-likelihood gained over a constant discrepancy (0 when the growth is floored at 0;
            about chi-square with 1 degree of freedom when there is no growth).
        d_max, d_rms: [m] the largest and RMS ``d`` (:func:`arm_model.discrepancy.pose_distance` from the poses
            left in the fold) of the held-out rows: the reach over which the growth was measured (beyond
            ``d_max`` it is an extrapolation).
        d, e, v: (rows,) the held-out rows it was fitted to: distance [m], error [m], predicted variance [m^2]
            (for the report's plot); fold: (rows,) the fold of each (for studies that refit without a fold).
    """
    sigma0: float
    growth: float
    u_sigma0: float
    u_growth: float
    lr: float
    d_max: float
    d_rms: float
    d: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False, repr=False)
    e: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False, repr=False)
    v: np.ndarray = field(default_factory=lambda: np.zeros(0), compare=False, repr=False)
    fold: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int), compare=False, repr=False)

    def to_dict(self) -> dict:
        return {"sigma0_um": self.sigma0 * 1e6, "growth_um_per_mm": self.growth * 1e3,
                "u_sigma0_um": self.u_sigma0 * 1e6, "u_growth_um_per_mm": self.u_growth * 1e3,
                "likelihood_ratio": self.lr, "d_max_mm": self.d_max * 1e3, "d_rms_mm": self.d_rms * 1e3}


@dataclass(frozen=True)
class JointGrowth:
    """The discrepancy growing with each joint's own motion, ``sigma_d(q)^2 = sigma0^2 + sum_j g_j^2 c_j(q)``
    (:func:`fit_joint_growth`, :class:`arm_model.discrepancy.GrowingDiscrepancy`), fitted to the same held-out rows
    as :class:`Growth`.

    Attributes:
        sigma0: [m] at the training poses; growth: (J,) [1] per metre of ball travel of each joint from the nearest
            training pose (``c_j``: :func:`arm_model.discrepancy.travel_shares`); maximum likelihood, floored at 0.
        u_sigma0, u_growth: their delete-one-fold jackknife standard uncertainties.
        resolved: (J,) whether the folds moved the ball along the joint (RMS travel at least
            :data:`RESOLVED_TRAVEL` of the largest joint's); a joint they did not resolve takes the growth of every
            joint together (:class:`Growth`'s, with its uncertainty) instead of an estimate nothing constrains.
        lr: twice the log-likelihood gained over one growth for every joint (:class:`Growth`).
        c: (rows, J) [m^2] each joint's share of the squared distance of the held-out rows (:class:`Growth`'s
            ``d``, ``e``, ``v``, ``fold``), for studies that refit without a fold.
    """
    sigma0: float
    growth: tuple[float, ...]
    u_sigma0: float
    u_growth: tuple[float, ...]
    resolved: tuple[bool, ...]
    lr: float
    c: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)), compare=False, repr=False)

    def predictive(self) -> tuple[float, tuple[float, ...]]:
        """``(sigma0, growth)`` with their estimation uncertainty carried: ``sqrt(sigma0^2 + u(sigma0)^2)`` and
        ``sqrt(g_j^2 + u(g_j)^2)`` (the mean of the squares that enter ``sigma_d^2`` when the estimates scatter by
        their u): what the model file writes and ``tip`` adds."""
        return (math.hypot(self.sigma0, self.u_sigma0),
                tuple(math.hypot(g, u) for g, u in zip(self.growth, self.u_growth, strict=True)))

    def to_dict(self) -> dict:
        return {"sigma0_um": self.sigma0 * 1e6, "growth_um_per_mm": [x * 1e3 for x in self.growth],
                "u_sigma0_um": self.u_sigma0 * 1e6, "u_growth_um_per_mm": [x * 1e3 for x in self.u_growth],
                "resolved": list(self.resolved), "likelihood_ratio_over_one_growth": self.lr}


@dataclass(frozen=True)
class Discrepancy:
    """The model discrepancy of a fit (:func:`model_discrepancy`).

    Attributes:
        sigma: standard deviation per axis [m] of the error beyond the fit's own prediction (0 when the
            held-out poses are predicted as well as the fit says).
        ratio: RMS held-out prediction error over the RMS the fit predicts for it (1 when the model holds).
        folds: number of folds (held-out ends of joint ranges); rows: held-out residual rows, pooled.
        share: share of the poses held out at each end of a joint's range.
        rms: RMS per axis [m] of the held-out prediction errors themselves (noise, posterior and
            discrepancy together): the extrapolative cross-validation error of the fit.
        growth: the discrepancy growing away from the training poses (:class:`Growth`), fitted to the same
            held-out rows; None when it could not be fitted.
        joints: the same growing with each joint's own motion (:class:`JointGrowth`), what the model file carries
            (:attr:`written`); None when it could not be fitted.
        training: the poses of the fit (what the growth is measured away from); training_rows: their rows in
            the fit's points.
    """
    sigma: float
    ratio: float
    folds: int
    rows: int
    share: float = EXTREME_SHARE
    rms: float = float("nan")
    growth: Growth | None = None
    training: TrainingPoses | None = field(default=None, compare=False)
    training_rows: np.ndarray | None = field(default=None, compare=False)
    joints: JointGrowth | None = None

    @property
    def written(self) -> tuple[float, float | tuple[float, ...] | None]:
        """``(sigma0 [m], growth [1])`` the model file carries and ``tip`` adds, every estimate with its uncertainty
        carried (``sqrt(x^2 + u(x)^2)``): the growth of each joint (:attr:`joints`, :meth:`JointGrowth.predictive`),
        each at least the growth of every joint together (:attr:`growth`, the same way; and ``sigma0`` at least
        its), so that the per-joint fit says where the discrepancy grows but never makes it smaller than the pooled
        fit does; the pooled growth alone when the joints' could not be fitted; ``(sigma, None)``, a constant, when
        nothing grows (the held-out errors do not grow, to their uncertainty: nothing was resolved, so the
        discrepancy is written as a constant, never as a measured zero growth)."""
        pooled = self.growth
        if pooled is None:
            return self.sigma, None
        s0 = math.hypot(pooled.sigma0, float(np.nan_to_num(pooled.u_sigma0)))
        one = math.hypot(pooled.growth, float(np.nan_to_num(pooled.u_growth)))
        g: float | tuple[float, ...] = one
        if self.joints is not None:
            s0_j, g_j = self.joints.predictive()
            s0, g = max(s0, s0_j), tuple(max(x, one) for x in g_j)
        if max(np.atleast_1d(g)) > 0:
            return s0, g
        return self.sigma, None

    def _written_dict(self) -> dict:
        s0, g = self.written
        return {"sigma0_um": s0 * 1e6,
                "growth_um_per_mm": None if g is None else (np.atleast_1d(g) * 1e3).tolist()}

    @property
    def written_growth(self) -> float | tuple[float, ...] | None:
        """The growth [1] the model file carries (:attr:`written`): one a joint, or one for every joint, or None (a
        constant)."""
        return self.written[1]

    def to_dict(self) -> dict:
        return {"sigma_um": self.sigma * 1e6, "ratio": self.ratio, "folds": self.folds, "rows": self.rows,
                "share": self.share, "rms_um": self.rms * 1e6,
                "growth": None if self.growth is None else self.growth.to_dict(),
                "growth_per_joint": None if self.joints is None else self.joints.to_dict(),
                "written": self._written_dict(),
                "method": "extrapolative cross-validation: the poses at each end of every joint's range held out "
                          "in turn (group deletion at the solution), the excess of their squared prediction "
                          "errors over the fit's own prediction (noise and posterior), per axis"}


def _neg_log_likelihood(x, e2, v, cols) -> tuple[float, np.ndarray]:
    """Half the negative Gaussian log-likelihood of errors with squares ``e2`` and variances ``v + cols @ x``, and
    its gradient with respect to ``x``."""
    tot = v + cols @ x
    w = 0.5 * (1.0 / tot - e2 / tot ** 2)
    return 0.5 * float(np.sum(np.log(tot) + e2 / tot)), cols.T @ w


def _ml(e2, v, cols) -> tuple[np.ndarray, float]:
    """``x >= 0`` [m^2, 1, ...] maximising the likelihood of ``e2`` under variances ``v + cols @ x`` (``cols``
    (rows, k): a column of ones, then the squared distances each variance grows with), and the minimised
    :func:`_neg_log_likelihood`. The unknowns are scaled to order 1 and started from the non-negative least squares
    of ``e2 - v`` on ``cols`` (the method of moments); a column that is 0 on every row keeps its unknown at 0."""
    from scipy.optimize import minimize, nnls
    v = _floored(e2, v)
    means = cols.mean(axis=0)
    live = means > 0
    scale = np.where(live, float(np.mean(v)) / np.where(live, means, 1.0), 0.0)
    x0 = np.zeros(cols.shape[1])
    x0[live] = nnls(cols[:, live] * scale[live], e2 - v)[0] + 1e-3
    bounds = [(0.0, None) if ok else (0.0, 0.0) for ok in live]

    def cost(x):
        f, grad = _neg_log_likelihood(x * scale, e2, v, cols)
        return f, grad * scale
    res = minimize(cost, x0, jac=True, method="L-BFGS-B", bounds=bounds)
    if not res.success:
        raise NumericalError(f"the model discrepancy's likelihood was not maximised: {res.message}")
    return res.x * scale, float(res.fun)


def _floored(e2, v) -> np.ndarray:
    """The predicted variances ``v`` floored far below any error (1e-12 of the mean square), so that a noise-free
    fit keeps a finite likelihood."""
    return np.maximum(v, max(1e-12 * float(np.mean(e2 + v)), 1e-100))


def _jackknife(fits: list) -> np.ndarray:
    """The delete-one-fold jackknife standard uncertainty of each column of ``fits`` (one row a fold left out);
    NaN with fewer than 3 folds."""
    if len(fits) < 3:
        return np.full(np.shape(fits)[1] if len(fits) else 2, float("nan"))
    a = np.asarray(fits)
    return np.sqrt((len(a) - 1) / len(a) * np.sum((a - a.mean(axis=0)) ** 2, axis=0))


def fit_growth(e, v, d, fold) -> Growth:
    """The :class:`Growth` of held-out errors ``e`` (rows,) [m] whose fit predicts the variances ``v`` [m^2]
    (noise and posterior), at distances ``d`` [m] from the nearest of the poses each was predicted from
    (:func:`arm_model.discrepancy.pose_distance`), in folds ``fold`` (rows,): the maximum likelihood of
    ``e ~ N(0, v + sigma0^2 + growth^2 d^2)`` (rows taken as independent), ``sigma0`` and ``growth`` floored at 0,
    with their delete-one-fold jackknife uncertainties."""
    from arm_model.parallel import blas_threads
    e2, v, d2, fold = np.asarray(e) ** 2, np.asarray(v, dtype=float), np.asarray(d, dtype=float) ** 2, np.asarray(fold)
    cols = np.column_stack([np.ones_like(d2), d2])
    folds = np.unique(fold)
    # two unknowns: the solver's tiny products spin-wait on every BLAS thread (15 x slower on a busy machine)
    with blas_threads(1):
        (a, b), nll = _ml(e2, v, cols)
        _, nll0 = _ml(e2, v, cols[:, :1])
        jack = [np.sqrt(_ml(e2[fold != f], v[fold != f], cols[fold != f])[0]) for f in folds] if len(folds) > 2 else []
    u = _jackknife(jack)
    return Growth(math.sqrt(a), math.sqrt(b), float(u[0]), float(u[1]), max(2 * (nll0 - nll), 0.0),
                  float(np.sqrt(d2.max())) if len(d2) else 0.0, float(np.sqrt(d2.mean())) if len(d2) else 0.0,
                  np.sqrt(d2), np.asarray(e, dtype=float), v, fold)


def fit_joint_growth(e, v, c, fold, pooled: Growth) -> JointGrowth:
    """The :class:`JointGrowth` of held-out errors ``e`` (rows,) [m] whose fit predicts the variances ``v`` [m^2],
    with ``c`` (rows, J) [m^2] each joint's share of the squared distance from the nearest pose left in the fold
    (:func:`arm_model.discrepancy.travel_shares`), in folds ``fold``: the maximum likelihood of ``e ~ N(0, v +
    sigma0^2 + sum_j g_j^2 c_j)`` over the joints the folds resolve (:data:`RESOLVED_TRAVEL`; the others take
    ``pooled``'s growth and its uncertainty), with delete-one-fold jackknife uncertainties, and the likelihood
    ratio over ``pooled`` (one growth for every joint)."""
    from arm_model.parallel import blas_threads
    e2, v, c, fold = np.asarray(e) ** 2, np.asarray(v, dtype=float), np.asarray(c, dtype=float), np.asarray(fold)
    travel = np.sqrt(c.mean(axis=0))
    resolved = travel >= RESOLVED_TRAVEL * max(float(travel.max()), 1e-300)
    other = c[:, ~resolved].sum(axis=1) * pooled.growth ** 2     # the unresolved joints' share, at the pooled growth
    cols = np.column_stack([np.ones(len(e2)), c[:, resolved]])
    with blas_threads(1):
        x, nll = _ml(e2, v + other, cols)
        jack = [np.sqrt(_ml(e2[fold != f], (v + other)[fold != f], cols[fold != f])[0]) for f in np.unique(fold)] \
            if len(np.unique(fold)) > 2 else []
    u = np.nan_to_num(_jackknife(jack) if jack else np.full(len(x), np.nan))
    g, ug = np.full(c.shape[1], pooled.growth), np.full(c.shape[1], np.nan_to_num(pooled.u_growth))
    g[resolved], ug[resolved] = np.sqrt(x[1:]), u[1:]
    both = np.column_stack([np.ones(len(e2)), c.sum(axis=1)])
    nll_pooled = _neg_log_likelihood(np.array([pooled.sigma0 ** 2, pooled.growth ** 2]), e2, _floored(e2, v), both)[0]
    return JointGrowth(math.sqrt(x[0]), tuple(g.tolist()), float(u[0]), tuple(ug.tolist()),
                       tuple(bool(r) for r in resolved), max(2 * (nll_pooled - nll), 0.0), c)


def extreme_folds(q: np.ndarray, share: float = EXTREME_SHARE) -> list[np.ndarray]:
    """Index arrays into the rows of ``q`` (N, J) [rad]: for each joint whose angle varies, the
    ``round(share * N)`` (at least 1) rows of its smallest and of its largest angles (measured from their
    circular mean, so that a range across +-pi is one interval), ties broken by row order."""
    q = np.asarray(q, dtype=float)
    n = len(q)
    out = []
    if n < 2:
        return out
    k = max(1, int(round(share * n)))
    angles = centred_angles(q)
    for a in angles.T:
        if np.ptp(a) <= 1e-9:
            continue
        order = np.argsort(a, kind="stable")
        out += [order[:k], order[-k:]]
    return out


def holdable(prob, held) -> set:
    """``held`` (point indices of ``prob``'s data) less, for every instance (feature, frame, marker) that
    would keep fewer than its fewest points plus one, its first held points: what a fold may hold out."""
    from .kinds import MIN_POINTS
    out = {int(i) for i in held}
    for it in prob.instances:
        pts = [int(i) for i in it.points]
        inter = [i for i in pts if i in out]
        spare = len(pts) - (MIN_POINTS.get(it.kind, (3, 3))[0] + 1)
        for i in inter[:max(len(inter) - max(spare, 0), 0)]:
            out.discard(i)
    return out


def group_deletions(factor: BlockNormal, r: np.ndarray, groups, chunk: int = 2000, tol: float = 1e-9,
                    leverage: np.ndarray | None = None) -> list:
    """The group-deletion identity of a linearised joint fit, for each group of residual rows ``O`` in ``groups``
    (index arrays; Cook and Weisberg 1982, ch. 3): ``(e_O, M_O)`` with ``M_O = (I - H_OO)^-1``, ``H = J A^-1
    J^T`` the hat matrix of the joint fit (``factor`` the normal matrix ``A`` of the column-scaled Jacobian ``J``
    of every unknown, the prior's precision in it: :class:`~calibration.schur.BlockNormal`) and ``e_O = M_O r_O``
    the group's prediction errors by the fit without it, in weighted units (``r`` the weighted residuals); their
    covariance is ``var M_O`` (``var`` the variance of a weighted row). ``(None, None)`` for a group the fit cannot
    do without (an eigenvalue of ``I - H_OO`` at ``tol`` or below: deleting it leaves an unknown undetermined).
    ``H_OO`` is formed from the factor's blocks (:meth:`~calibration.schur.BlockNormal.parts`), the groups
    ``chunk`` rows at a time. The change of the unknowns the group makes is :func:`deletion_shift`. ``leverage``: an
    array (rows,) whose groups' rows take the diagonal of ``H_OO`` (their leverage)."""
    out: list = []
    i = 0
    while i < len(groups):
        batch, n = [], 0
        while i < len(groups) and (not batch or n + len(groups[i]) <= chunk):
            batch.append(np.asarray(groups[i], dtype=int))
            n += len(batch[-1])
            i += 1
        out += _deletion_batch(factor, r, batch, tol, leverage)
    return out


def deletion_shift(factor: BlockNormal, rows: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``d_O = A^-1 J_O^T e_O``: the change of the (scaled) unknowns from the fit without the rows ``O`` to the fit
    with them (``e_O`` their prediction errors, :func:`group_deletions`; the other rows' residuals without them are
    ``r + J d_O``)."""
    return factor.solve(factor.j[rows].T @ e)


def _hat_blocks(parts, pos: np.ndarray) -> np.ndarray:
    """``H_OO`` (groups, size, size) of the groups at positions ``pos`` (groups, size) of the rows of ``parts``
    (:meth:`~calibration.schur.BlockNormal.parts`): the parameters' part by one product, the nuisance part (rows
    of one component only) by one sparse product a group for large groups, one a pair of positions for small
    ones."""
    g, gs, y, jn = parts
    h = np.einsum("gip,gjp->gij", gs[pos], g[pos])
    size = pos.shape[1]
    if y is None:                                       # no nuisance block
        return h
    if size > 16:
        return h + np.stack([(y[p] @ jn[p].T).toarray() for p in pos])
    for i in range(size):
        rows = y[pos[:, i]]
        for k in range(size):
            h[:, i, k] += np.asarray(rows.multiply(jn[pos[:, k]]).sum(axis=1)).ravel()
    return h


def _deletion_batch(factor: BlockNormal, r: np.ndarray, batch: list, tol: float, leverage: np.ndarray | None) -> list:
    """:func:`group_deletions` of the groups ``batch`` (the groups of one size together)."""
    parts = factor.parts(np.concatenate(batch))
    start = np.cumsum([0] + [len(o) for o in batch])
    out: list = [None] * len(batch)
    for size in np.unique(np.diff(start)):
        which = np.flatnonzero(np.diff(start) == size)
        pos = start[which][:, None] + np.arange(size)   # (groups, size) positions in the batch's rows
        h = _hat_blocks(parts, pos)
        rows = np.stack([batch[g] for g in which])
        if leverage is not None:
            leverage[rows] = np.einsum("gii->gi", h)
        ih = np.eye(size) - 0.5 * (h + np.swapaxes(h, 1, 2))
        ok = np.linalg.eigvalsh(ih)[:, 0] > tol
        m = np.full_like(ih, np.nan)
        m[ok] = np.linalg.inv(ih[ok])
        e = np.einsum("gij,gj->gi", m, r[rows])
        for g, k in enumerate(which):
            out[k] = (e[g], m[g]) if ok[g] else (None, None)
    return out


#: a fold of more residual rows than this is deleted by the normal matrix of the fit without it
#: (:func:`_fold_without`) instead of by ``(I - H_OO)^-1`` in full (rows^2 memory, rows^3 time)
LARGE_FOLD = 500


def _fold_without(factor: BlockNormal, r: np.ndarray, rows: np.ndarray, tol: float) -> tuple | None:
    """``(e_O, diag M_O)`` of :func:`group_deletions` for a large group ``rows``, by the other side of Woodbury's
    identity: ``M_O = I + J_O A_-O^-1 J_O^T`` with ``A_-O = A - J_O^T J_O`` the normal matrix of the fit without
    the group (:meth:`~calibration.schur.BlockNormal.without`), so ``e_O = r_O + J_O A_-O^-1 J_O^T r_O``; None when
    the smallest eigenvalue of ``I - H_OO``, ``1 / (1 + mu)`` with ``mu`` the largest of ``J_O A_-O^-1 J_O^T``
    (Lanczos), is at ``tol`` or below, or ``A_-O`` is singular: the criterion of :func:`group_deletions`."""
    from scipy.sparse.linalg import LinearOperator, eigsh
    try:
        rest = factor.without(rows)
    except NumericalError:
        return None
    jo = factor.j[rows]
    n = len(rows)
    if n > 1:
        op = LinearOperator((n, n), matvec=lambda x: jo @ rest.solve(jo.T @ np.ravel(x)), dtype=float)
        mu = float(eigsh(op, k=1, which="LA", tol=1e-3, v0=np.ones(n), return_eigenvectors=False)[0])
    else:
        mu = float(rest.leverage(jo)[0])
    if 1.0 / (1.0 + mu) <= tol:
        return None
    return r[rows] + jo @ rest.solve(jo.T @ r[rows]), 1.0 + rest.leverage(jo)


def fold_errors(prob, r: np.ndarray, factor: BlockNormal, var: float, rows: np.ndarray,
                tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray] | None:
    """The prediction errors [m] of the residual ``rows`` of a fit of ``prob`` by the fit without them, and the
    variances [m^2] that fit predicts for them (noise and posterior), for the model linearised at the solution:
    ``(I - H_OO)^-1 r_O`` and the diagonal of ``var (I - H_OO)^-1`` (:func:`group_deletions`; beyond
    :data:`LARGE_FOLD` rows by :func:`_fold_without`), in metres (each row times its sigma); None when the fit
    cannot do without the rows. Arguments as :func:`model_discrepancy`."""
    if len(rows) > LARGE_FOLD:
        got = _fold_without(factor, r, rows, tol)
        if got is None:
            return None
        e, m_diag = got
    else:
        e, m = group_deletions(factor, r, [rows], tol=tol)[0]
        if e is None:
            return None
        m_diag = np.diag(m)
    sig = prob.sigma[rows]
    return sig * e, var * m_diag * sig ** 2


def model_discrepancy(prob, r: np.ndarray, factor: BlockNormal, var: float,
                      share: float = EXTREME_SHARE) -> Discrepancy | None:
    """The model discrepancy of a fit of ``prob`` (see the module docstring).

    Args:
        prob: the :class:`~calibration.problem.Problem` fitted (its rows, their points and sigmas [m]).
        r: (rows,) weighted residuals at the solution.
        factor: the normal matrix ``A`` of the column-scaled Jacobian (rows x unknowns: free parameters and
            nuisance) plus the prior's precision (scaled alike): :class:`~calibration.schur.BlockNormal`.
        var: the variance of a weighted row (``s0^2``, or 1 with stated uncertainties).

    Returns None when no fold can be formed (no joint varies, too few points)."""
    rp = prob.row_point
    point_rows = (prob.row_distance < 0) & (rp >= 0)
    used = np.unique(rp[point_rows])
    if len(used) < 2:
        return None
    desc = prob.model.desc
    q = prob.data.points.q
    levers = np.zeros((len(q), q.shape[1]))
    levers[used] = joint_levers(desc, q[used])
    errors, variances, shares, fold_of = [], [], [], []
    for fold in extreme_folds(q[used], share):
        held = holdable(prob, used[fold])
        rows = np.flatnonzero(point_rows & np.isin(rp, sorted(held)))
        if not len(rows):
            continue
        got = fold_errors(prob, r, factor, var, rows)
        if got is None:
            continue
        e, v = got
        rest = used[~np.isin(used, sorted(held))]
        errors.append(e)
        variances.append(v)
        shares.append(travel_shares(desc, q[rp[rows]], TrainingPoses.of(desc, q[rest]), levers[rp[rows]])[1])
        fold_of.append(np.full(len(rows), len(fold_of)))
    if not errors:
        return None
    e, v = np.concatenate(errors), np.concatenate(variances)
    observed, predicted, n_rows = float(e @ e), float(np.sum(v)), len(e)
    c, fold_of = np.concatenate(shares), np.concatenate(fold_of)
    growth = joints = None
    try:
        growth = fit_growth(e, v, np.sqrt(c.sum(axis=1)), fold_of)
        joints = fit_joint_growth(e, v, c, fold_of, growth)
    except NumericalError as exc:
        log.warning(f"{exc}: the model discrepancy is written as a constant (no growth away from the training poses)")
    return Discrepancy(math.sqrt(max((observed - predicted) / n_rows, 0.0)),
                       math.sqrt(observed / predicted) if predicted > 0 else float("nan"), len(errors), n_rows, share,
                       math.sqrt(observed / n_rows), growth, TrainingPoses.of(desc, q[used]), used, joints)
