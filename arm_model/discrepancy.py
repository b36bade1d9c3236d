"""A model discrepancy that grows with how far a pose lies from the poses a calibration was fitted on.

A calibrated model errs, beyond what its parameters' covariance says, by what it lacks (an effect nobody
declared, a geometry the chain cannot represent). At the training poses the fit has absorbed most of that
error; away from them it comes back, the more the further the arm is from every pose it was calibrated on. The
standard uncertainty per axis of that error at a pose ``q`` is modelled as::

    sigma_d(q)^2 = sigma_0^2 + (g * d(q))^2
    d(q) = min over training poses t of sqrt(sum_j (L_j(q) * (q_j - t_j))^2)

* ``q_j - t_j`` [rad] ([m] for a prismatic joint): the joint's difference from the training pose (a revolute one
  taken the short way round);
* ``L_j`` [m/rad] (1 for a prismatic joint): the lever of joint ``j`` at ``q``, the norm of d(ball centre)/d q_j
  of the rigid chain (the ball's distance from the joint's axis): :func:`joint_levers`. ``d`` [m] is thus, to
  first order, how far the joint motions from the nearest training pose carry the ball: the same unit and
  meaning on every arm (a wrist joint's difference counts less than a shoulder's);
* ``sigma_0`` [m]: the discrepancy at the training poses, ``g`` [1]: its growth per metre of ``d``.

The growth may also be given **per joint** (``g_j``, one per encoder joint; automatic relevance determination,
as a Gaussian process's length scale per input): with ``t*`` the nearest training pose (by ``d``) and
``c_j(q) = (L_j(q) (q_j - t*_j))^2`` the joint's share of ``d^2``::

    sigma_d(q)^2 = sigma_0^2 + sum_j g_j^2 c_j(q)

(a single ``g`` is every ``g_j = g``: ``sum_j c_j = d^2``). An error the model lacks that grows with one joint's
motion (a gain error, a load on one joint) then grows where that joint moved, not wherever the arm did.

Both are estimated by :mod:`calibration.discrepancy` from the extrapolative folds of the constant discrepancy
(the poses held out at the ends of each joint's range, each at its ``d`` from the poses left in the fold). The
nearest training pose was chosen over how far a pose lies beyond the box of the training joint ranges (the
same lever weighting) because, on the shared real seat data, it explains the held-out errors better (likelihood
ratio over a constant 129 and 10 where the box gives 111 and 3; docs/uncertainty.md): a pose inside every
joint's range can still be far from any pose the fit saw. A model file carries ``sigma_0`` and ``g``
(``[calibration] model_discrepancy_um``, ``model_discrepancy_growth_um_per_mm``) and the training poses (a
points file named by ``training_poses``: docs/formats.md), and ``aacmm tip`` adds ``sigma_d(q)^2`` to each
point's variance per axis (:func:`arm_model.uncertainty.propagate`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["TrainingPoses", "GrowingDiscrepancy", "joint_levers", "pose_distance", "nearest_pose", "travel_shares",
           "growth_text",
           "checked_poses", "LEVER_STEP"]

#: step [rad] ([m] for a prismatic joint) of the central differences of :func:`joint_levers`
LEVER_STEP = 1e-6
#: the most elements (poses x joints) :func:`joint_levers` passes to the chain at once
_BLOCK = 2_000_000
#: the most elements (query poses x training poses) of one block of :func:`pose_distance` (256 kB of doubles)
_CACHE_BLOCK = 32_768


@dataclass(frozen=True, eq=False)
class TrainingPoses:
    """The poses a calibration was fitted on: ``names`` the joints (the description's encoder columns), ``q``
    (T, J) their readings [rad] ([m] for a prismatic joint, ``circular`` False)."""
    names: tuple[str, ...]
    q: np.ndarray
    circular: tuple[bool, ...]

    def __post_init__(self):
        q = np.atleast_2d(np.asarray(self.q, dtype=float))
        if q.shape[1] != len(self.names) or len(self.circular) != len(self.names) or not len(q):
            raise ValueError(f"training poses need at least one pose of {len(self.names)} joints, got {q.shape}")
        checked_poses(q, self.circular, "training poses")
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "circular", tuple(bool(c) for c in self.circular))

    @cached_property
    def scaled(self) -> tuple[np.ndarray, np.ndarray]:
        """``(tn, columns)``: the poses in turns (metres for a prismatic joint), (T, J), and the same as (J, T)
        contiguous columns: what every search divides and reads (computed once, not per query: a live point)."""
        tn = self.q / np.where(np.asarray(self.circular, dtype=bool), 2 * math.pi, 1.0)
        return tn, np.ascontiguousarray(tn.T)

    @classmethod
    def of(cls, desc, q) -> TrainingPoses:
        """The training poses ``q`` (T, J) of the arm ``desc`` (its encoder columns: revolute ones circular)."""
        return cls(tuple(desc.joint_names), q, tuple(not j.prismatic for j in desc.encoders))


def checked_poses(q: np.ndarray, circular, what: str) -> None:
    """A ValueError naming ``what`` unless every joint value of ``q`` (N, J) is finite and plausible (an angle for a
    ``circular`` joint, else a length: :data:`arm_model.units.PLAUSIBLE_SI`, the points reader's range); beyond it
    the levers' central differences vanish (q + :data:`LEVER_STEP` == q) and a pose would lie at d = 0."""
    from .units import PLAUSIBLE_SI, implausible
    if len(q) == 1:                  # one pose (a live point's): its plain floats first, the messages only if wrong
        limit = (PLAUSIBLE_SI["angle"], PLAUSIBLE_SI["length"])
        if all(abs(x) <= limit[0 if c else 1] for x, c in zip(q[0].tolist(), circular, strict=True)):
            return                   # (a NaN fails the comparison: it goes on to its message)
    bad = np.argwhere(~np.isfinite(q))
    if len(bad):
        raise ValueError(f"{what}: pose {bad[0][0]}, joint {bad[0][1] + 1} is {q[tuple(bad[0])]!r}, not a finite value")
    for circ in (True, False):
        cols = np.flatnonzero(np.asarray(circular, dtype=bool) == circ)
        wrong = implausible(q[:, cols], "angle" if circ else "length") if len(cols) and len(q) else None
        if wrong:
            raise ValueError(f"{what}: pose {wrong[0][0]}, joint {cols[wrong[0][1]] + 1}: {wrong[1]}")


def joint_levers(desc, q) -> np.ndarray:
    """(N, J) [m/rad] (1 for a prismatic joint along its axis): the norm of the derivative of the rigid ball
    centre of ``desc`` (zero wrench, the description's own geometry) with respect to each encoder reading, by
    central differences of step :data:`LEVER_STEP`: the ball's distance from a revolute joint's axis. The 2 J
    shifted poses of a point go through one call of the chain (a live point's levers in one pass)."""
    from .kinematics import ball_centres
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, nj = q.shape
    out = np.empty((n, nj))
    step = max(1, _BLOCK // (2 * nj * nj))
    shift = np.concatenate([np.eye(nj), -np.eye(nj)]) * LEVER_STEP          # (2J, J): +step, then -step
    for s in range(0, n, step):
        qs = q[s: s + step]
        c = ball_centres(desc, (qs[:, None, :] + shift[None]).reshape(-1, nj)).reshape(len(qs), 2 * nj, 3)
        out[s: s + step] = np.linalg.norm(c[:, :nj] - c[:, nj:], axis=2) / (2 * LEVER_STEP)
    return out


def pose_distance(desc, q, train: TrainingPoses, levers=None) -> np.ndarray:
    """(N,) [m]: ``d(q)``, how far the joint motions from the nearest of the ``train`` poses carry the ball
    (see the module docstring); ``levers`` (N, J) [m/rad] of ``q`` when already computed
    (:func:`nearest_pose`'s distances)."""
    return nearest_pose(desc, q, train, levers)[0]


def _queries(q, train: TrainingPoses) -> np.ndarray:
    """``q`` as an (N, J) float array of poses the distance from ``train`` can be asked of: a ValueError unless it
    has the training poses' joints and every value is finite and plausible (:func:`checked_poses`), checked before
    any lever is evaluated (the chain at an infinite angle is NaN)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[1] != len(train.names):
        raise ValueError(f"q has {q.shape[1]} joints, the training poses {len(train.names)}")
    checked_poses(q, train.circular, "the poses whose distance from the training poses is asked")
    return q


def nearest_pose(desc, q, train: TrainingPoses, levers=None) -> tuple[np.ndarray, np.ndarray]:
    """``(d, index)``: (N,) [m] :func:`pose_distance` of each pose of ``q`` and (N,) the row of ``train.q`` that is
    its nearest training pose (of equally near ones, the first).

    Exact. The metric weighs each joint by the lever at the query pose (a revolute joint's difference wrapped to
    [-pi, pi], in turns: ``x - rint(x)``; a joint whose axis passes through the ball weighs nothing), so it is no
    fixed one a k-d tree is built for. Repeated queries (a point's rows) are searched once. Beyond
    :data:`_TREE_PAIRS` query x training poses the queries are grouped by the shape of their levers (k-means of
    their logarithms, :data:`_TREE_GROUPS` groups) and each group searched in a ``scipy.spatial.cKDTree`` of the
    training poses scaled by the group's levers (periodic in the revolute joints): the tree metric times the
    smallest ratio of a query's lever to the group's is a lower bound of the query's distance, so every pose
    within the best of :data:`_TREE_FIRST` tree neighbours' distance over that ratio is a candidate, and the
    nearest candidate is the nearest pose. The queries whose levers the group's fit badly (the candidates' volume
    :data:`_TREE_SPREAD` times the query's own ball or more, or a lever of 0) are searched exhaustively, as every
    query is below that size: in blocks of query and training poses (a few hundred kB each), joint by joint, the
    distances computed by the same operations in both searches (the same numbers: tests/test_calibration_discrepancy.py
    checks both against a plain loop, and the trees against the exhaustive search bit for bit). Measured (2 shared
    cores, CPU; ``benchmarks/bench_uncertainty.py``, ``discrepancy_folds``): a fold of ``calibrate``'s model
    discrepancy on 10^5 random poses of aacmm7 (15 000 against 85 000) 25.3 s exhaustive, 4.3 s by the trees (the
    same numbers); its 14 folds 64.5 s by the trees (about 355 s exhaustive); 10^4 x 10^4 1.7 -> 0.9 s.

    One query alone (a live point) is searched against every training pose at once (:meth:`_PoseSearch.one`, the
    same numbers). Trees do not pay for it: with trees of the training poses built once (8 or 32 groups of their
    levers' shapes, the bound above, a query's 16 tree neighbours), one query of aacmm7 took 0.53 ms against 0.29 ms
    exhaustive at 10 000 poses, and 0.94 against 1.95 ms at 100 000 for 3.5 s of building (a single tree query
    alone 40-80 us: 6 weighted, periodic dimensions); a chordal bound by one matrix product kept one candidate but
    cost more than the search (2 shared cores, CPU, 2026-11-28)."""
    q = _queries(q, train)
    return _nearest(q, train, joint_levers(desc, q) if levers is None else np.asarray(levers, dtype=float))


def _nearest(q: np.ndarray, train: TrainingPoses, lev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`nearest_pose` of poses ``q`` (N, J) checked by :func:`_queries`, their levers ``lev`` (N, J)."""
    if len(q) > 1:
        unique, inverse = np.unique(np.hstack([q, lev]), axis=0, return_inverse=True)
        inverse = inverse.ravel()
        q, lev = unique[:, :q.shape[1]], unique[:, q.shape[1]:]
    else:                                                   # one query (a live point): nothing to share
        inverse = np.zeros(len(q), dtype=int)
    circ = np.asarray(train.circular, dtype=bool)
    turn = np.where(circ, 2 * math.pi, 1.0)                 # revolute joints in turns, prismatic ones in metres
    tn, columns = train.scaled                              # the training poses divided once, not per query
    search = _PoseSearch(q / turn, tn, lev * turn, circ, columns)
    best = np.full(len(q), np.inf)
    index = np.zeros(len(q), dtype=int)
    rest = np.arange(len(q))
    if len(q) == 1 and len(train.q) * len(train.names) <= _ONE_QUERY_ELEMENTS:
        search.one(best, index)
        rest = rest[:0]
    elif len(q) * len(train.q) >= _TREE_PAIRS:
        rest = search.by_trees(best, index)
    search.exhaustive(rest, best, index)
    return np.sqrt(best)[inverse], index[inverse]


#: the most training poses x joints that one query is searched against at once (:meth:`_PoseSearch.one`: 1 MB of
#: differences; beyond, the blocked search is faster: measured 2.0 against 1.6 ms at 10^5 poses of aacmm7)
_ONE_QUERY_ELEMENTS = 131_072
#: query x training poses from which :func:`nearest_pose` searches k-d trees (below, the exhaustive search is as fast)
_TREE_PAIRS = 50_000_000
#: groups of queries by the shape of their levers, one k-d tree each
_TREE_GROUPS = 32
#: a query is searched exhaustively when its candidates' ball holds this many times its own (the product over the
#: joints of its lever ratios to the group's over the smallest): measured, 1000 left 0.5 % of random aacmm7 poses
#: to the exhaustive search and 12 candidates a query to the trees
_TREE_SPREAD = 1000.0
#: the tree neighbours whose exact distance bounds the search of each query
_TREE_FIRST = 4


@dataclass(frozen=True)
class _PoseSearch:
    """The nearest training pose of each query, exactly (:func:`nearest_pose`): queries ``qn`` (N, J) and training
    poses ``tn`` (T, J) in turns (metres for a prismatic joint), ``wn`` (N, J) the queries' levers [m per turn],
    ``circ`` (J,) the revolute joints, ``columns`` (J, T) ``tn`` transposed, contiguous (each joint's values read in
    one run). The searches fill ``best`` (N,) (squared distances) and ``index`` (N,)."""
    qn: np.ndarray
    tn: np.ndarray
    wn: np.ndarray
    circ: np.ndarray
    columns: np.ndarray

    @cached_property
    def used(self) -> np.ndarray:
        return np.flatnonzero(np.any(self.wn != 0, axis=0))   # a joint whose lever is 0 at every query adds nothing

    def squared(self, qi: np.ndarray, ti: np.ndarray) -> np.ndarray:
        """The squared distances of the pairs (queries ``qi``, training poses ``ti``), broadcast together, by the
        operations of the exhaustive search in its order (the same numbers)."""
        acc = np.zeros(np.broadcast_shapes(np.shape(qi), np.shape(ti)))
        for j in self.used:
            d = self.qn[qi, j] - self.tn[ti, j]
            if self.circ[j]:
                d -= np.rint(d)
            d *= self.wn[qi, j]
            d *= d
            acc += d
        return acc

    def one(self, best: np.ndarray, index: np.ndarray) -> None:
        """The one query (a live point) against every training pose at once, each joint's differences a row of one
        (J_used, T) array: the operations of :meth:`exhaustive` on each element, the joints summed in the same
        order (the same numbers, in a third of its numpy calls: 0.09 against 0.16 ms at 300 poses)."""
        used = self.used
        if not len(used):                       # every lever 0: every pose at 0, the first the nearest
            best[0], index[0] = 0.0, 0
            return
        d = self.qn[0, used, None] - self.columns[used]
        circ = self.circ[used]
        if circ.all():
            d -= np.rint(d)
        elif circ.any():
            d[circ] -= np.rint(d[circ])
        d *= self.wn[0, used, None]
        d *= d
        acc = d[0].copy()                        # 0 + d_0 of the blocked search: d_0 itself (>= 0)
        for row in d[1:]:
            acc += row
        k = int(acc.argmin())
        best[0], index[0] = acc[k], k

    def exhaustive(self, rows: np.ndarray, best: np.ndarray, index: np.ndarray) -> None:
        """Queries ``rows`` against every training pose, in cache-sized blocks."""
        if not len(rows):
            return
        qn, wn, circ = self.qn[rows], self.wn[rows], self.circ
        tb = max(1, min(len(self.tn), _CACHE_BLOCK))
        qb = max(1, _CACHE_BLOCK // tb)
        for t0 in range(0, len(self.tn), tb):
            tt = self.columns[:, t0: t0 + tb]
            for s in range(0, len(rows), qb):
                r = rows[s: s + qb]
                acc = np.zeros((len(r), tt.shape[1]))
                d = np.empty_like(acc)
                for j in self.used:             # as squared(), in place
                    np.subtract(qn[s: s + qb, j, None], tt[None, j], out=d)
                    if circ[j]:
                        d -= np.rint(d)
                    d *= wn[s: s + qb, j, None]
                    d *= d
                    acc += d
                k = acc.argmin(axis=1)
                low = acc[np.arange(len(acc)), k]
                better = low < best[r]
                best[r[better]] = low[better]
                index[r[better]] = t0 + k[better]

    def by_trees(self, best: np.ndarray, index: np.ndarray) -> np.ndarray:
        """The queries that the k-d trees search (see :func:`nearest_pose`); returns the others."""
        import warnings

        from scipy.cluster.vq import kmeans2
        used = self.used
        w = self.wn[:, used]
        rest = np.flatnonzero(~np.all(w > 0, axis=1))
        fit = np.flatnonzero(np.all(w > 0, axis=1))
        if len(fit) < 2 * _TREE_GROUPS:
            return np.arange(len(w))
        logs = np.log(w[fit])
        with warnings.catch_warnings():           # a group left empty: no tree for it, nothing lost
            warnings.simplefilter("ignore")
            centres, label = kmeans2(logs - logs.mean(axis=1, keepdims=True), _TREE_GROUPS, seed=0, minit="++")
        for g, centre in enumerate(centres):
            mine = fit[label == g]
            if len(mine):
                rest = np.concatenate([rest, self._tree_group(mine, np.exp(centre), best, index)])
        return np.sort(rest)

    def _tree_group(self, rows: np.ndarray, scale: np.ndarray, best: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Queries ``rows`` in a tree of the training poses scaled by ``scale`` (J_used,); returns those left to
        the exhaustive search."""
        from scipy.spatial import cKDTree
        used = self.used
        ratio = self.wn[rows][:, used] / scale
        low = ratio.min(axis=1)
        far = np.sum(np.log(ratio / low[:, None]), axis=1) > math.log(_TREE_SPREAD)
        left, rows, low = rows[far], rows[~far], low[~far]
        periodic = self.circ[used]

        def coords(x: np.ndarray) -> np.ndarray:
            c = x[:, used] * scale
            c[:, periodic] = x[:, used][:, periodic] % 1.0 * scale[periodic] % scale[periodic]   # in [0, scale)
            return c

        tree = cKDTree(coords(self.tn), boxsize=np.where(periodic, scale, 0.0))
        at = coords(self.qn[rows])
        k = min(_TREE_FIRST, len(self.tn))
        _, first = tree.query(at, k=k)
        first = np.asarray(first).reshape(len(rows), k)
        bound = np.sqrt(self.squared(rows[:, None], first).min(axis=1))
        radius = bound / low * (1 + 1e-9) + 1e-12 * float(scale.max())      # rounding of either metric
        found = tree.query_ball_point(at, radius, return_sorted=False)
        counts = np.fromiter((len(f) for f in found), dtype=int, count=len(found))
        qi = np.repeat(rows, counts)
        ti = np.fromiter((t for f in found for t in f), dtype=int, count=int(counts.sum()))
        d2 = self.squared(qi, ti)
        order = np.lexsort((ti, d2, qi))                  # by query, then distance, then training row
        head = order[np.r_[0, np.flatnonzero(np.diff(qi[order])) + 1]]
        best[qi[head]] = d2[head]
        index[qi[head]] = ti[head]
        return left


def travel_shares(desc, q, train: TrainingPoses, levers=None) -> tuple[np.ndarray, np.ndarray]:
    """``(d, c)``: (N,) [m] :func:`pose_distance` of each pose of ``q`` and (N, J) [m^2] each joint's share ``c_j =
    (L_j (q_j - t*_j))^2`` of ``d^2`` from the nearest training pose ``t*`` (a revolute difference the short way
    round; ``sum_j c_j = d^2``): how far each joint's motion from that pose carries the ball, squared."""
    q = _queries(q, train)
    lev = joint_levers(desc, q) if levers is None else np.asarray(levers, dtype=float)
    d, index = _nearest(q, train, lev)
    diff = q - train.q[index]
    circ = np.asarray(train.circular, dtype=bool)
    diff[:, circ] -= 2 * math.pi * np.rint(diff[:, circ] / (2 * math.pi))
    return d, (lev * diff) ** 2


@dataclass(frozen=True)
class GrowingDiscrepancy:
    """``sigma_d(q)^2 = sigma0^2 + sum_j growth_j^2 c_j(q)`` (see the module docstring): ``sigma0`` [m] at the
    training poses, ``growth`` [1] per metre of ball travel from the nearest of the ``training`` poses, one number
    for every joint (``sigma0^2 + (growth d)^2``) or a tuple of one per joint (encoder order); 0 (or None
    training poses): the constant ``sigma0`` everywhere."""
    sigma0: float
    growth: float | tuple[float, ...] = 0.0
    training: TrainingPoses | None = None

    def __post_init__(self):
        if isinstance(self.growth, (tuple, list, np.ndarray)):
            object.__setattr__(self, "growth", tuple(float(g) for g in self.growth))
            if self.training is not None and len(self.growth) != len(self.training.names):
                raise ValueError(f"the model discrepancy's growth has {len(self.growth)} joints, the training poses "
                                 f"{len(self.training.names)}")
        for name, v in (("sigma0", self.sigma0), *(("growth", g) for g in self.growths)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"the model discrepancy's {name} must be finite and >= 0, got {v!r}")
        if self.grows and self.training is None:
            raise ValueError("a growing model discrepancy needs the training poses it grows away from")

    @property
    def growths(self) -> tuple[float, ...]:
        """The growth as a tuple: one value (every joint) or one per joint [1]."""
        return self.growth if isinstance(self.growth, tuple) else (float(self.growth),)

    @property
    def grows(self) -> bool:
        """True when some joint's growth is above 0."""
        return max(self.growths, default=0.0) > 0

    def distance(self, desc, q) -> np.ndarray:
        """(N,) [m] ``d`` of each pose of ``q`` (N, J) (zeros without training poses)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return np.zeros(len(q)) if self.training is None else pose_distance(desc, q, self.training)

    def at(self, desc, q) -> tuple[np.ndarray, np.ndarray]:
        """``(d, sd)``: (N,) [m] the distance ``d`` of each pose of ``q`` (N, J) from the nearest training pose
        (zeros without a growth) and ``sigma_d`` per axis there [m]."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if not self.grows or self.training is None:
            return np.zeros(len(q)), np.full(len(q), self.sigma0)
        d, c = travel_shares(desc, q, self.training)
        g2 = np.broadcast_to(np.square(self.growths), (c.shape[1],))
        return d, np.sqrt(self.sigma0 ** 2 + c @ g2)

    def sd(self, desc, q) -> np.ndarray:
        """(N,) [m]: ``sigma_d`` per axis at each pose of ``q`` (N, J)."""
        return self.at(desc, q)[1]


def growth_text(growths) -> str:
    """A growth [1] for people, in um per mm: ``"0.7"`` for one value, ``"0, 0.29, ... (joints 1-7)"`` for one a
    joint."""
    g = [float(x) * 1e3 for x in growths]
    if len(g) == 1:
        return f"{g[0]:.4g}"
    return ", ".join(f"{x:.3g}" for x in g) + f" (joints 1-{len(g)})"
