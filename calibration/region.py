"""The parameters' random effect between regions of the joint space: what the posterior misses where a model's
best parameters depend on the region of poses they were fitted on.

A model that lacks an effect (a load the joints feel differently on each branch of a redundant arm, a contact
that pushes the ball in a direction the plate's placement sets) is absorbed by the parameters, and the values
that absorb it best differ from one region of the joint space to the next: a fit on one region predicts another
worse than its posterior says, in the directions of the parameters, not as a scatter of each point. The
extrapolative folds of :mod:`calibration.discrepancy` (the ends of each joint's range) do not show it when the
training poses fall into separate regions (the elbow-up and elbow-down branches of a 7-joint arm reaching one
seat): each end is still predicted from poses of its own branch.

So the training poses are split into regions (:func:`pose_regions`: Ward's hierarchical clustering of the poses
on the circle of each joint, cut into 2, 3 and 4 regions, :data:`REGION_SPLITS`), each region is held out in turn
and predicted by the fit without it (the group deletion at the solution, :func:`calibration.discrepancy.
group_deletions`: prediction errors ``e_O`` with covariance ``var M_O`` when the model holds, against each
feature fitted on the remaining poses), and the variance of a random shift ``b`` of the free parameters that a
region draws on its own, ``b ~ N(0, diag(t) P)`` (``P`` the prior's variance of each parameter: its plausible
size, the posterior's without a prior; one ``t`` for each of the prior's groups, lengths, angles, each effect's
parameters), is fitted by maximum likelihood to those errors::

    e_O ~ N(0, var M_O + G_O diag(t) G_O^T),   0 <= t <= 1

(``G_O`` the held-out rows' Jacobian with respect to the free parameters). ``t = 0`` when the model holds (the
regions predict each other as the posterior says); at most 1: a region's parameters do not differ from another's by
more than the parameter's plausible size. The folds overlap (every pose is in one region of each partition), so the
likelihood ratio over ``t = 0`` is not chi-square: it is judged against up to :data:`NULL_DRAWS` draws of the same
folds' errors as the model holds (a sequential Monte Carlo test at 5 %, :data:`NULL_EXCEED`), and the effect is kept
only when it passes, less the mean ``t`` of those draws (the variance that noise alone gives the fit).

With ``FitOptions(region_effect=True)`` (``aacmm calibrate --region-effect``; ``aacmm close-loop --region-effect``,
``LoopSettings(region_effect=True)``, on its final model's fit) the covariance file written with the model
holds ``posterior + diag(t) P`` (:func:`predictive_covariance`, and the model file's u of each effect with it), so
``aacmm tip``'s u of a point the fit never saw carries the shift its region may draw, through the Jacobian at that
point: it grows where the parameters' effect differs from the training poses', and a deviation from a feature's mean
keeps the part that varies over the feature's poses. The parameters' own u (console, report) stay the posterior's. It is
added on top of the model discrepancy (:mod:`calibration.discrepancy`), which on a training placement whose folds'
excess it explains counts that excess twice; the discrepancy net of it was measured and not kept (the worst real pair
84.4 -> 61.1 %). Off by default: on the real Panda seats and the simulated seat robots it brings no held-out
placement pair into 90-97 % and puts more above it, at 3-4 s of CPU a command (docs/studies/calibration.md, "On by
default?").

Constants: :data:`REGION_SPLITS` (2 to 4 regions), the bound ``t <= 1`` (the prior's size, the model's own statement
of what a parameter may plausibly be) and the test's level, 5 % (at most :data:`NULL_DRAWS` draws: a p-value near the
level, 0.015 on the real `front` placement, is judged the same at every seed, where 19 draws kept it at 12 of 20).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from arm_model.errors import NumericalError

from .discrepancy import LARGE_FOLD, group_deletions, holdable
from .schur import BlockNormal

__all__ = ["REGION_SPLITS", "RegionEffect", "pose_regions", "fit_region_variances", "region_effect",
           "predictive_covariance"]

#: the numbers of regions the training poses are cut into (each partition's regions are held out in turn)
REGION_SPLITS = (2, 3, 4)
#: the most draws of the null (the model holds) the likelihood ratio is judged against, and how many of them may reach
#: it: a sequential Monte Carlo test at NULL_EXCEED / (NULL_DRAWS + 1) = 5 % (Besag & Clifford 1991: the draws stop
#: as soon as NULL_EXCEED reach the ratio, the effect then rejected; kept when fewer do of all NULL_DRAWS). Their mean
#: ``t`` is the bias taken off the estimate. NULL_DRAWS 0: no test, no bias.
NULL_DRAWS = 199
NULL_EXCEED = 10
NULL_SEED = 20261127
#: the largest ``t`` (a parameter's random-effect variance per prior variance): the prior's own
T_MAX = 1.0


@dataclass(frozen=True)
class RegionEffect:
    """The parameters' random effect between regions of the joint space (:func:`region_effect`).

    Attributes:
        names: the free parameters; variance: (k,) [SI^2] each one's random-effect variance (``t_j P_j``).
        ratio: (k,) ``t_j``, the variance per prior variance (0 when the regions predict each other as the
            posterior says, at most 1).
        lr: twice the log-likelihood gained over no random effect (about chi-square with up to k degrees of freedom
            when there is none; the bound at 0 makes it smaller).
        folds: the regions held out; rows: their residual rows, pooled.
        lr_null: the test's critical value: the :data:`NULL_EXCEED`-th largest likelihood ratio of the draws of the
            same folds' errors as the model holds: the effect is taken (``t`` less its mean over those draws, floored
            at 0) only when ``lr`` passes it, else ``t = 0``.
        p_value: the Monte Carlo p-value of ``lr`` (Besag & Clifford: ``(1 + reached) / (draws + 1)`` over all the
            draws, ``NULL_EXCEED / draws`` when they stopped early); draws: how many were drawn.
    """
    names: tuple[str, ...]
    variance: np.ndarray
    ratio: np.ndarray
    lr: float
    folds: int
    rows: int
    lr_null: float = float("nan")
    p_value: float = float("nan")
    draws: int = 0

    def summary(self) -> str:
        """One line for the console: the test, and what the covariance file gets from it."""
        null = (f"critical {self.lr_null:.3g}, p {self.p_value:.2g} over {self.draws} null draws; " if self.draws
                else "no Monte Carlo test; ")
        test = f"likelihood ratio {self.lr:.3g} ({null}{self.folds} regions)"
        big = np.argsort(-self.ratio)[:3]
        shown = [f"{self.names[i]} {math.sqrt(float(self.ratio[i])):.2g}" for i in big if self.ratio[i] > 1e-6]
        if shown:
            return f"kept: {test}; shift between regions per prior sd, largest: {', '.join(shown)}"
        return f"not kept (nothing added to the covariance): {test}"

    def to_dict(self) -> dict:
        order = np.argsort(-self.ratio)
        return {"likelihood_ratio": self.lr, "likelihood_ratio_critical": self.lr_null, "p_value": self.p_value,
                "null_draws": self.draws, "folds": self.folds, "rows": self.rows,
                "sd_per_prior_sd": {self.names[i]: math.sqrt(float(self.ratio[i])) for i in order
                                    if self.ratio[i] > 1e-6},
                "method": "leave one region of the joint space out (Ward's clusters of the training poses, 2-4 "
                          "regions): the variance of each free parameter's shift between regions, per its prior "
                          "variance, by maximum likelihood on the regions' prediction errors (group deletion at the "
                          "solution); added to the covariance file"}


def pose_regions(q: np.ndarray, splits=REGION_SPLITS) -> list[np.ndarray]:
    """Index arrays into the rows of ``q`` (N, J) [rad]: for each number of regions ``k`` in ``splits`` (below N),
    the rows of each of the ``k`` clusters of Ward's hierarchical clustering of the poses as points
    ``(cos q_j, sin q_j)`` (each angle on its circle: a range across +-pi is one region). A joint that does not move
    adds nothing to the distances."""
    from scipy.cluster.hierarchy import fcluster, linkage
    q = np.asarray(q, dtype=float)
    if len(q) < 3:
        return []
    tree = linkage(np.column_stack([np.cos(q), np.sin(q)]), "ward")
    out = []
    for k in splits:
        if k >= len(q):
            continue
        lab = fcluster(tree, k, "maxclust")
        out += [np.flatnonzero(lab == c) for c in np.unique(lab)]
    return out


def fit_region_variances(parts, group=None) -> tuple[np.ndarray, float]:
    """``(t (k,), lr)``: the maximum likelihood of ``t`` (bounded to [0, :data:`T_MAX`]) for errors ``e_O`` of
    folds ``parts = [(M_O, G_O, e_O)]`` distributed ``N(0, M_O + G_O diag(t) G_O^T)`` (``M_O`` (n, n), ``G_O`` (n, k),
    in units of a row's noise and of each parameter's prior standard deviation), and twice the log-likelihood it
    gains over ``t = 0``. ``group``: (k,) the group of each parameter, one ``t`` a group (``t`` then has one entry a
    group, 0 to its largest); None: one a parameter."""
    terms = []
    for m, g, e in parts:
        c = np.linalg.cholesky(m)
        gt, et = np.linalg.solve(c, g), np.linalg.solve(c, e)
        terms.append((gt.T @ gt, gt.T @ et))
    return _fit_terms(terms, group)


def _fit_terms(terms, group=None) -> tuple[np.ndarray, float]:
    """:func:`fit_region_variances` on each fold's ``(Q, b)`` whitened by ``M_O`` (``L L^T = M_O``, ``G~ = L^-1 G``,
    ``e~ = L^-1 e``, ``Q = G~^T G~``, ``b = G~^T e~``): with ``D = diag(t)^1/2``, ``K = I + D Q D``, ``W = D K^-1 D``,
    the log-likelihood's terms that depend on ``t`` are ``log det K`` and ``- b^T W b``, so each evaluation costs
    k x k (Woodbury), every fold at once. Optimised in ``t`` from 0 (L-BFGS-B within the bounds, the analytic gradient
    ``1/2 (Q_jj - (QWQ)_jj - a_j^2)``, ``a = b - Q W b``)."""
    from scipy.optimize import minimize
    q = np.array([x[0] for x in terms])             # (F, k, k)
    b = np.array([x[1] for x in terms])             # (F, k)
    k = q.shape[1]
    group = np.arange(k) if group is None else np.asarray(group, dtype=int)
    n_t = int(group.max()) + 1
    eye = np.eye(k)
    q_diag = np.einsum("fjj->j", q)

    def nll(tg):
        t = np.maximum(tg, 0.0)[group]
        d = np.sqrt(t)
        c = np.linalg.cholesky(eye + d[:, None] * q * d[None, :])
        half = np.linalg.solve(c, np.broadcast_to(np.diag(d), q.shape))
        w = np.einsum("fij,fik->fjk", half, half)
        qw = q @ w
        a = b - np.einsum("fij,fj->fi", qw, b)
        f = float(np.sum(np.log(np.einsum("fjj->fj", c))) - 0.5 * np.einsum("fi,fij,fj->", b, w, b))
        grad = 0.5 * (q_diag - np.einsum("fij,fji->i", qw, q) - np.einsum("fi,fi->i", a, a))
        return f, np.bincount(group, grad, minlength=n_t)
    best = minimize(nll, np.zeros(n_t), jac=True, method="L-BFGS-B", bounds=[(0.0, T_MAX)] * n_t)
    if not best.success:
        raise NumericalError(f"the region effect's variance fit did not converge (L-BFGS-B: {best.message}); run "
                             "without --region-effect")
    return np.clip(best.x, 0.0, T_MAX), max(2 * (nll(np.zeros(n_t))[0] - float(best.fun)), 0.0)


def region_effect(prob, r: np.ndarray, factor: BlockNormal, var: float, jscale: np.ndarray, size: np.ndarray,
                  names, group=None) -> RegionEffect | None:
    """The parameters' random effect between regions of a fit of ``prob`` (module docstring).

    Args:
        prob, r, factor, var: as :func:`calibration.discrepancy.model_discrepancy` (the first ``len(names)`` columns
            of ``factor.j`` are the free parameters).
        jscale: the column scale of ``factor.j`` (``J = factor.j * jscale`` per SI unit of each unknown).
        size: (k,) [SI] the prior's standard deviation of each free parameter (the posterior's without a prior).
        names: the free parameters.
        group: (k,) the prior's group of each (:meth:`calibration.prior.PriorSpec.groups_of`): one ``t`` a group;
            None: one a parameter.

    A region whose rows pass :data:`calibration.discrepancy.LARGE_FOLD` is held out by an evenly spaced subset of its
    poses within that many rows. None when no region can be held out (too few poses, nothing free)."""
    k = len(names)
    rp = prob.row_point
    point_rows = (prob.row_distance < 0) & (rp >= 0)
    used = np.unique(rp[point_rows])
    if not k or len(used) < 3:
        return None
    per_point = max(1, int(np.sum(point_rows)) // len(used))
    if var != 1.0:          # rows of unit variance, the prior as the fit put it: the posterior is A^-1 itself
        factor, r = BlockNormal(factor.j / math.sqrt(var), factor.n_par, factor.damping), r / math.sqrt(var)
    parts, n_rows = [], 0
    g_scale = jscale[:k] * np.asarray(size, dtype=float)
    for region in pose_regions(prob.data.points.q[used]):
        region = region[np.linspace(0, len(region) - 1, min(len(region), LARGE_FOLD // per_point)).astype(int)]
        rows = np.flatnonzero(point_rows & np.isin(rp, sorted(holdable(prob, used[region]))))
        if not len(rows) or len(rows) > LARGE_FOLD:
            continue
        e, m = group_deletions(factor, r, [rows])[0]
        if e is None:
            continue
        g = factor.j[rows][:, :k]
        g = (g.toarray() if hasattr(g, "toarray") else np.asarray(g)) * g_scale
        c = np.linalg.cholesky(0.5 * (m + m.T))
        gt = np.linalg.solve(c, g)
        parts.append((gt.T @ gt, gt, c.T, np.linalg.solve(c, e), rows))
        n_rows += len(rows)
    if not parts:
        return None
    group = np.arange(k) if group is None else np.asarray(group, dtype=int)
    tg, lr = _fit_terms([(q, gt.T @ et) for q, gt, _, et, _ in parts], group)
    crit = p_value = float("nan")
    null_lr = np.zeros(0)
    if NULL_DRAWS:
        null_t, null_lr = _null_fits(factor, parts, r.shape[0], group, lr)
        reached = int(np.sum(null_lr >= lr))
        crit = float(np.sort(null_lr)[-min(NULL_EXCEED, len(null_lr))])
        p_value = reached / len(null_lr) if reached >= NULL_EXCEED else (1 + reached) / (len(null_lr) + 1)
        tg = np.zeros_like(tg) if reached >= NULL_EXCEED else np.maximum(tg - null_t.mean(axis=0), 0.0)
    t = tg[group]
    return RegionEffect(tuple(names), t * np.asarray(size, dtype=float) ** 2, t, lr, len(parts), n_rows, crit,
                        p_value, len(null_lr))


def _null_fits(factor: BlockNormal, parts, n_rows: int, group, lr: float) -> tuple[np.ndarray, np.ndarray]:
    """``(t (n, k), lr (n,))`` of :func:`fit_region_variances` on folds' errors drawn as the model holds, up to
    :data:`NULL_DRAWS` of them, stopped once :data:`NULL_EXCEED` reach ``lr``: unit noise on every row, the residuals
    of the linearised fit ``r* = (I - J A^-1 J^T) z``, each fold's prediction errors ``M_O r*_O``, whitened
    ``L^-1 M_O r*_O = L^T r*_O`` (seeded: the same draws for the same fit)."""
    rng = np.random.default_rng(NULL_SEED)
    ts, lrs = [], []
    while len(lrs) < NULL_DRAWS and sum(x >= lr for x in lrs) < NULL_EXCEED:
        z = rng.standard_normal(n_rows)
        rz = z - factor.j @ factor.solve(factor.j.T @ z)
        t, lr_z = _fit_terms([(q, gt.T @ (ct @ rz[rows])) for q, gt, ct, _, rows in parts], group)
        ts.append(t)
        lrs.append(lr_z)
    return np.array(ts), np.array(lrs)


def predictive_covariance(result) -> np.ndarray:
    """The covariance [SI^2] of ``result.free`` for predicting poses the fit never saw: the posterior ``result.cov``
    plus the parameters' random effect between regions (``result.region``, :class:`RegionEffect`, matched by name;
    none: the posterior itself). What the covariance file holds."""
    reg = getattr(result, "region", None)
    if reg is None:
        return result.cov
    extra = dict(zip(reg.names, reg.variance, strict=True))
    return result.cov + np.diag([float(extra.get(n, 0.0)) for n in result.free])
