"""The calibration problem of one data set: residual structure, evaluation and exact Jacobians.

Built once per problem structure (model, data, weights, which kinds): the ball centres and their
Jacobian with respect to the parameters come from the model's CasADi Function mapped over the
points, the artefact residuals and their Jacobians from the kind functions of
:mod:`calibration.kinds`; the chain rule joins them. Unknowns are the free parameters and the
nuisance increments of every artefact instance (a feature within one measurement), of the reference
instrument's frame ``T_ref_base`` of each session and of the markers' offsets on the tip frame when they
are unknown (``data.marker_offsets`` "fit"; :mod:`arm_model.tracker`). A marker at offset ``o`` is the
model's own tip point with the probe point moved by ``o``, so its Jacobian comes from the same CasADi
Function.

Residual rows, in this order: each point kind (seat, sphere, ring, cylinder, plane, reference)
with ``rows`` rows a point, then the distances. Every row is divided by its standard uncertainty
(:class:`~calibration.data.Weights`), so the cost is ``0.5 * sum(r_w**2)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from arm_model import InputError, NumericalError
from arm_model.casadi_model import NumpyFunction
from arm_model.checks import repeated_readings
from arm_model.geometry import ball_centre_radius
from arm_model.io import CENTRE_KINDS
from arm_model.model import CASADI_CACHE, ArmModel
from arm_model.tracker import DEFAULT_SESSION, Tracker, offset_matrix

from . import kinds as geo
from .data import CalibrationData, Weights
from .kinds import MIN_POINTS

__all__ = ["Instance", "DistanceItem", "Problem", "Evaluation", "POINT_KINDS", "CentreKernel", "centre_kernel"]

#: point kinds in row order
POINT_KINDS = ("seat", "sphere", "ring", "cylinder", "plane", "reference")

#: a group of point rows of one kind (:meth:`Problem._point_groups`): its instances, points, rows and CasADi map
Group = dict[str, Any]
#: Jacobian triplets (rows, columns, values) of the nuisance increments, as lists of arrays
Triplets = tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]


@dataclass
class Instance:
    """One artefact feature within one measurement, or the reference instrument's frame of one session
    (kind ``reference``, ``feature`` the session), or one marker's offset on the tip frame (kind
    ``marker``, ``feature`` "marker k"; no rows of its own: its points are the marker's reference rows)."""
    measurement: str
    feature: str
    kind: str
    points: np.ndarray          # indices into the data's points
    offset: int                 # first column of its nuisance increments
    n_theta: int                # 0 for a frozen instance (reference transform held at identity)
    radius: float | None        # offset radius [m] of sphere / ring / cylinder, None if fitted
    free_radius: bool = False
    state: np.ndarray | None = None     # the state of a held instance (n_theta 0): a given frame or offset


@dataclass
class DistanceItem:
    """A certified length between the centres of two instances of one measurement."""
    measurement: str
    between: tuple[str, str]
    a: int                      # instance indices
    b: int
    length: float               # [m]
    sigma: float                # [m]


@dataclass
class Evaluation:
    """Residuals at one point of the unknowns: weighted ``r`` (rows,), ``x`` (n_used, 3) ball
    centres [m]; with ``jac``: ``jp`` (rows, n_free) and ``jt`` (rows, n_nuisance, sparse CSR)."""
    r: np.ndarray
    x: np.ndarray
    jp: np.ndarray | None = None
    jt: sp.csr_matrix | None = None


@dataclass
class Problem:
    """Structure and evaluation of the residuals of ``data`` under ``model``.

    Args:
        model: the arm model (base chain and effects), parameters ``model.spec``.
        data: points, artefacts and aux inputs.
        weights: standard uncertainties of the residuals.
        free: indices into ``model.spec`` of the parameters that are unknowns.
        free_radius: fit the radius of spheres, rings and cylinders (validation) instead of using
            the certified diameter.
        distances: include the certified distances.
        reference: "fit" (``T_ref_base`` of each session a nuisance unknown, or held at the frame of
            ``data.tracker`` when it has one), "identity" (reference coordinates are base coordinates) or
            "off" (reference columns ignored).
        prior_only: indices into ``model.spec`` of free parameters the data cannot tell from others
            (:func:`calibration.prior.prior_only`): their columns of the Jacobian are left out (zero), so that only
            a prior holds them.
    """
    model: ArmModel
    data: CalibrationData
    weights: Weights = field(default_factory=Weights)
    free: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    free_radius: bool = False
    distances: bool = True
    reference: str = "fit"
    prior_only: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    def __post_init__(self) -> None:
        self.free = np.asarray(self.free, dtype=int)
        self.prior_only = np.asarray(self.prior_only, dtype=int)
        self._build()

    # -- structure --------------------------------------------------------------------------------
    def _build(self) -> None:
        """The residual structure, in named steps: the artefact instances, the reference instrument's
        frames and markers, the certified distances, the rows grouped by kind, the CasADi ball centres,
        and each row's weight and origin."""
        pts = self.data.points
        self._lines = pts.lines if pts.lines is not None else np.arange(1, len(pts) + 1)
        xref = self.data.reference
        self._has_ref = (np.all(np.isfinite(xref), axis=1) if xref is not None and self.reference != "off"
                         else np.zeros(len(pts), bool))
        self._xref_all = xref
        self._nuisance_csr = _TripletsCsr()       # the nuisance Jacobian's rows and columns are the same each time
        #: the rows that repeat an earlier reading of their feature (:func:`arm_model.checks.repeated_readings`; the
        #: marker of a row of several markers told apart): counted once, as the first (their residuals would be the
        #: first's, counted as independent observations: every uncertainty narrowed by sqrt(copies))
        self.repeats = np.flatnonzero(repeated_readings(pts, (self.data.markers,)) >= 0)
        self._repeat = np.zeros(len(pts), bool)
        self._repeat[self.repeats] = True
        self.instances: list[Instance] = []
        self.n_nuisance = 0
        by_key = self._artefact_instances()
        self._reference_instances(by_key)
        self.distance_items = self._distances(by_key)
        self._dist_fn = mapped(geo.distance_function(), len(self.distance_items)) if self.distance_items else None
        self._point_groups()
        self._centre_functions()
        self._row_weights()

    def _add(self, inst: Instance) -> int:
        """Append an instance, its increments after the others'; returns its index."""
        inst.offset = self.n_nuisance
        self.instances.append(inst)
        self.n_nuisance += inst.n_theta
        return len(self.instances) - 1

    def _artefact_instances(self) -> dict[tuple[str, str], int]:
        """One instance a feature within a measurement; ``self.unused``: free points without a reference.
        Returns ``{(measurement, feature): instance index}``."""
        pts, arte, data = self.data.points, self.data.artefacts, self.data
        ball = self.model.desc.probe.ball_diameter
        by_key: dict[tuple[str, str], int] = {}
        unused: list[np.ndarray] = []
        for m, rows_m in pts.measurement_rows().items():
            for f in dict.fromkeys(pts.feature[rows_m].tolist()):
                rows = rows_m[pts.feature[rows_m] == f]
                kind = arte.features[f].kind if f else "point"
                if kind == "point":
                    unused.append(rows[~self._has_ref[rows] & ~self._repeat[rows]])
                    continue
                feat = arte.features[f]
                radius = None
                if kind in ("sphere", "ring", "cylinder"):
                    radius = ball_centre_radius(kind, feat.diameter, ball)
                    if radius <= 0:
                        raise InputError(f"feature '{f}': diameter {feat.diameter * 1e3:g} mm is not larger than "
                                         f"the ball ({ball * 1e3:g} mm)", arte.path, None, f"key 'feature {f}'")
                free_r = self.free_radius and kind in ("sphere", "ring", "cylinder")
                need = MIN_POINTS[kind][1 if free_r else 0]
                where = (data.file_of(rows[0]), int(self._lines[rows[0]]), "feature")
                if len(rows) < need:
                    raise InputError(f"measurement '{m}', feature '{f}' ({kind}): {len(rows)} point(s), at least "
                                     f"{need} needed", *where)
                distinct = len(np.unique(pts.q[rows], axis=0))
                if kind != "seat" and distinct < need:
                    raise InputError(f"measurement '{m}', feature '{f}' ({kind}): {len(rows)} points but only "
                                     f"{distinct} distinct pose(s) (the same encoder angles repeated): the {kind}'s "
                                     f"unknowns are unidentifiable; at least {need} distinct points needed", *where)
                if kind == "seat" and len(rows) > 1 and self._repeat[rows].sum() == len(rows) - 1:
                    # one seat row repeated: its copies' residuals are exactly 0, counted as redundancy and noise
                    # (the noise of the seat came out at 7e-11 um, close-loop's s0 at 0.03 with p-values of 1e-198)
                    raise InputError(f"measurement '{m}', feature '{f}' (seat): its {len(rows)} points are one "
                                     "reading repeated (the same encoder angles and force): they say no more than "
                                     "one point and would count as independent; articulate the seat, or keep one "
                                     "row", *where)
                rows = rows[~self._repeat[rows]]
                by_key[(m, f)] = self._add(Instance(m, f, kind, rows, 0, geo.n_theta(kind, free_r),
                                                    None if free_r else radius, free_r))
        self.unused = np.sort(np.concatenate(unused)) if unused else np.zeros(0, int)
        return by_key

    def _reference_instances(self, by_key: dict[tuple[str, str], int]) -> None:
        """The reference rows: on a free point the marker (the tip point, or a marker at its offset on the
        tip frame), on a seat the seat's centre (a tracker nest). One ``reference`` instance a session
        (its frame ``T_ref_base``), one ``marker`` instance a marker when the offsets are unknowns.
        ``self._ref_anchor`` / ``self._ref_marker``: {row: seat instance} / {row: marker instance}."""
        pts, arte, data = self.data.points, self.data.artefacts, self.data
        given = data.tracker
        self._ref_anchor: dict[int, int] = {}
        self._ref_marker: dict[int, int] = {}
        ref_rows: list[int] = []
        for i in np.flatnonzero(self._has_ref & ~self._repeat):
            f = pts.feature[i]
            kind = arte.features[f].kind if f else "point"
            if kind in ("point", "seat"):
                ref_rows.append(int(i))
                self._ref_anchor[int(i)] = by_key[(pts.measurement[i], f)] if kind == "seat" else -1
        rows = np.array(ref_rows, dtype=int)
        sessions = data.sessions
        for s in dict.fromkeys(sessions[rows].tolist()):
            sr = rows[sessions[rows] == s]
            frame = None if self.reference == "fit" else np.eye(4)
            if frame is None and given is not None:
                frame = given.frame(s)
            if frame is None and len(sr) < MIN_POINTS["reference"][0]:
                what = "" if s == DEFAULT_SESSION else f" in session '{s}'"
                column = "x_ref_mm" if pts.n_markers == 1 else f"x{data.markers[sr[0]] + 1}_ref_mm"
                raise InputError(f"{len(sr)} reference point(s){what}: a rigid transform needs at least 3",
                                 data.file_of(sr[0]), int(self._lines[sr[0]]), column)
            held = None if frame is None else geo.frame_state(frame)
            self._add(Instance("*", s, "reference", sr, 0, 6 if held is None else 0, None, state=held))
        if data.marker_offsets != "fit":
            return
        on_point = np.array([i for i in rows if self._ref_anchor[i] < 0], dtype=int)
        marker = data.markers
        for k in sorted(set(marker[on_point].tolist())):
            mr = on_point[marker[on_point] == k]
            held = None if given is None or given.offsets is None else given.offset(k).copy()
            idx = self._add(Instance("*", f"marker {k + 1}", "marker", mr, 0, 3 if held is None else 0, None,
                                     state=held))
            self._ref_marker.update(dict.fromkeys(mr.tolist(), idx))

    def _distances(self, by_key: dict[tuple[str, str], int]) -> list[DistanceItem]:
        """The certified lengths between the centres of two instances of one measurement (but those the data
        leave out, ``data.left_out_lengths``)."""
        arte, pts = self.data.artefacts, self.data.points
        items: list[DistanceItem] = []
        if not self.distances:
            return items
        left_out = set(self.data.left_out_lengths)
        for dist in arte.distances:
            fa, fb = dist.between
            for m in pts.measurements():
                if (m, fa) in by_key and (m, fb) in by_key and (m, (fa, fb)) not in left_out:
                    ia, ib = by_key[(m, fa)], by_key[(m, fb)]
                    for i, fid in ((ia, fa), (ib, fb)):
                        if self.instances[i].kind not in CENTRE_KINDS:
                            raise InputError(f"a distance needs feature centres: '{fid}' is a "
                                             f"{self.instances[i].kind} (use seats or spheres)", arte.path, None,
                                             "key 'distance.between'")
                    items.append(DistanceItem(m, (fa, fb), ia, ib, dist.length,
                                              self.weights.length_sigma(dist.u_length)))
        return items

    def _point_groups(self) -> None:
        """The point rows grouped by kind (and free radius), in :data:`POINT_KINDS` order; the used points
        and their positions in the centre arrays."""
        self.groups: list[Group] = []
        row = 0
        used: list[np.ndarray] = []
        for kind in POINT_KINDS:
            for fr in (False, True):
                insts = [i for i, it in enumerate(self.instances) if it.kind == kind and it.free_radius == fr]
                if not insts:
                    continue
                members = [self.instances[i].points for i in insts]
                pidx = np.concatenate(members)
                rows = geo.KINDS[kind].rows
                g: Group = dict(kind=kind, free_radius=fr, uinst=insts, points=pidx, row0=row, rows=rows,
                         inst=np.concatenate([np.full(len(m), i) for m, i in zip(members, insts, strict=True)]),
                         local=np.concatenate([np.full(len(m), k) for k, m in enumerate(members)]),
                         fn=mapped(geo.kind_function(kind, fr), len(pidx)))
                if kind == "reference":
                    g["anchor"] = np.array([self._ref_anchor[i] for i in pidx], dtype=int)
                    g["marker"] = np.array([self._ref_marker.get(i, -1) for i in pidx], dtype=int)
                    g["on_point"] = g["anchor"] < 0
                    used.append(pidx[g["on_point"]])
                else:
                    used.append(pidx)
                self.groups.append(g)
                row += rows * len(pidx)
        self.n_point_rows = row
        self.n_rows = row + len(self.distance_items)
        self.used = np.unique(np.concatenate(used)) if used else np.zeros(0, int)
        if self.n_rows == 0:
            raise InputError("no usable points: no point belongs to a seat, sphere, ring, cylinder or plane, "
                             "and there are no reference coordinates", self.data.points.path)
        self._pos = np.full(len(self.data), -1)
        self._pos[self.used] = np.arange(len(self.used))
        for g in self.groups:
            g["pos"] = self._pos[g["points"]]
        self._used_marker = np.array([self._ref_marker.get(i, -1) for i in self.used], dtype=int)
        self._marker_unknowns = any(it.kind == "marker" and it.n_theta for it in self.instances)

    def _centre_functions(self) -> None:
        """CasADi ball centres of the used points: ``x(q, w, aux, p, o)``, the tip point moved by ``o`` [m]
        in the tip frame (a marker's offset; zero for a probed point), mapped over the used points (the
        functions of one point are the model's :class:`CentreKernel`, built once for equal models)."""
        nu = len(self.used)
        self._kernel = centre_kernel(self.model)
        self._fx = mapped(self._kernel.fx, nu)
        n, jn = len(self.data), self.model.desc.n_joints
        self._q = np.ascontiguousarray(self.data.points.q[self.used].T)
        self._w = np.ascontiguousarray(self.data.wrench[self.used].T)
        aux = ArmModel.aux_matrix(self.data.aux, n, jn, len(self.model.capture_measurements))
        self._aux = np.ascontiguousarray(aux[self.used].T)

    def _row_weights(self) -> None:
        """The standard uncertainty of every row (``sigma``) and the point, instance and distance it comes from."""
        w = self.weights
        sig = np.empty(self.n_rows)
        self.row_point = np.full(self.n_rows, -1)
        self.row_instance = np.full(self.n_rows, -1)
        for g in self.groups:
            sl = slice(g["row0"], g["row0"] + g["rows"] * len(g["points"]))
            if g["kind"] == "reference":
                sig[sl] = np.repeat(np.where(g["on_point"], w.reference_sigma, w.reference), 3)
            else:
                sig[sl] = w.probe
            sig[sl] *= w.factor(g["kind"])
            self.row_point[sl] = np.repeat(g["points"], g["rows"])
            self.row_instance[sl] = np.repeat(g["inst"], g["rows"])
        sig[self.n_point_rows:] = [d.sigma * w.factor("length") for d in self.distance_items]
        self.sigma = sig
        self.row_distance = np.full(self.n_rows, -1)
        self.row_distance[self.n_point_rows:] = np.arange(len(self.distance_items))

    # -- evaluation -------------------------------------------------------------------------------
    def centres(self, p: ArrayLike, jac: bool = False, columns: ArrayLike | None = None,
                offsets: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Ball centres (n_used, 3) [m] of the used points and, with ``jac``, d x / d p (n_used, 3, P),
        or only the ``columns`` (indices into p) of it. ``offsets``: (n_used, 3) each point's marker
        offset in the tip frame [m] (:meth:`marker_offsets`; None: the tip point itself)."""
        x, dx, _ = self._centres(p, jac, columns, offsets)
        return x, dx

    def marker_offsets(self, states: list[np.ndarray]) -> np.ndarray | None:
        """(n_used, 3) the marker offset [m] of each used point at ``states`` (zero for probed points), or
        None when no point is a marker at an offset."""
        if not (self._used_marker >= 0).any():
            return None
        out = np.zeros((len(self.used), 3))
        on = self._used_marker >= 0
        out[on] = np.array([states[i][:3] for i in self._used_marker[on]])
        return out

    def _centres(self, p: ArrayLike, jac: bool, columns: ArrayLike | None, offsets: ArrayLike | None
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """(x, d x / d p[columns] or None, d x / d o (n_used, 3, 3) or None) of :meth:`centres`."""
        p = np.asarray(p, dtype=float)
        cols = None if columns is None else [int(c) for c in np.asarray(columns).reshape(-1)]
        ncol = len(p) if cols is None else len(cols)
        nu = len(self.used)
        if nu == 0:
            return np.zeros((0, 3)), (np.zeros((0, 3, ncol)) if jac else None), (np.zeros((0, 3, 3)) if jac else None)
        o = np.zeros((3, nu)) if offsets is None else np.ascontiguousarray(np.asarray(offsets, float).T)
        if not jac:
            return self._fx(self._q, self._w, self._aux, p, o)[0].T, None, None
        fn = mapped(self._kernel.columns(None if cols is None else tuple(cols)), nu)
        x, dx, dxo = fn(self._q, self._w, self._aux, p, o)
        x = np.asarray(x).T
        dx = np.asarray(dx).reshape(3, nu, ncol).transpose(1, 0, 2)
        dxo = np.asarray(dxo).reshape(3, nu, 3).transpose(1, 0, 2)
        return x, dx, dxo

    def _group_inputs(self, g: Group, x: np.ndarray, states: list[np.ndarray]
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x_in (3, n), states (k, n), xref (3, n)) of a group: reference rows anchored on a seat take
        the seat's centre instead of the ball centre."""
        kst = np.stack([states[i] for i in g["uinst"]])[g["local"]].T
        if g["kind"] != "reference":
            return x[g["pos"]].T, kst, np.zeros((3, len(g["points"])))
        xin = np.empty((3, len(g["points"])))
        on = g["on_point"]
        xin[:, on] = x[g["pos"][on]].T
        if (~on).any():
            xin[:, ~on] = np.array([states[a][:3] for a in g["anchor"][~on]]).T
        assert self._xref_all is not None, "reference rows come with reference coordinates"
        return xin, kst, self._xref_all[g["points"]].T

    def initial_states(self, p: ArrayLike) -> list[np.ndarray]:
        """Starting nuisance states from the ball centres at ``p``: the algebraic fits of the artefacts,
        then the reference frames and marker offsets (:func:`calibration.kinds.tracker_start`); held
        instances keep their state."""
        has_markers = bool((self._used_marker >= 0).any())
        x, _, dxo = self._centres(p, has_markers, [] if has_markers else None, None)
        states: list[Any] = [None] * len(self.instances)
        for i, it in enumerate(self.instances):
            if it.kind not in ("reference", "marker"):
                states[i] = geo.initial_state(it.kind, x[self._pos[it.points]], it.radius)
        ref = [g for g in self.groups if g["kind"] == "reference"]
        if not ref:
            return states
        g = ref[0]
        on = g["on_point"]
        base = np.empty((len(g["points"]), 3))
        base[on] = x[g["pos"][on]]
        if (~on).any():
            base[~on] = np.array([states[a][:3] for a in g["anchor"][~on]])
        turn = np.zeros((len(base), 3, 3))
        if dxo is not None:
            turn[on] = dxo[g["pos"][on]]
        frames = [i for i, it in enumerate(self.instances) if it.kind == "reference"]
        markers = [i for i, it in enumerate(self.instances) if it.kind == "marker"]
        held_f = [self.instances[i].state for i in frames]
        held_o = [self.instances[i].state for i in markers]
        assert self._xref_all is not None, "reference rows come with reference coordinates"
        fstates, ostates = geo.tracker_start(base, turn, self._xref_all[g["points"]], g["inst"], g["marker"],
                                             frames, markers, held_f, held_o)
        for i, st in zip(frames + markers, fstates + ostates, strict=True):
            states[i] = st
        return states

    def retract(self, states: list[np.ndarray], dtheta: np.ndarray) -> list[np.ndarray]:
        out = []
        for it, s in zip(self.instances, states, strict=True):
            out.append(s if it.n_theta == 0 else geo.retract(it.kind, s, dtheta[it.offset: it.offset + it.n_theta]))
        return out

    def evaluate(self, p: ArrayLike, states: list[np.ndarray], jac: bool = True) -> Evaluation:
        """Weighted residuals (and Jacobians) at parameters ``p`` (full vector, SI) and ``states``."""
        nf = len(self.free)
        x, dx, dxo = self._centres(p, jac and (nf > 0 or self._marker_unknowns), self.free,
                                   self.marker_offsets(states))
        r = np.empty(self.n_rows)
        jp = np.zeros((self.n_rows, nf)) if jac else None
        sparse: Triplets = ([], [], [])
        for g in self.groups:
            self._group_rows(g, x, dx, dxo, states, r, jp, sparse)
        if self.distance_items:
            self._distance_rows(states, r, sparse if jac else None)
        r /= self.sigma
        if jp is None:
            return Evaluation(r, x)
        jp /= self.sigma[:, None]
        jp[:, np.isin(self.free, self.prior_only)] = 0.0
        ti, tj, tv = (np.concatenate(a) if a else np.zeros(0, int) for a in sparse)
        tv = tv.astype(float) / self.sigma[ti] if len(ti) else np.zeros(0)
        return Evaluation(r, x, jp, self._nuisance_csr(ti, tj, tv, (self.n_rows, self.n_nuisance)))

    def _group_rows(self, g: Group, x: np.ndarray, dx: np.ndarray | None, dxo: np.ndarray | None,
                    states: list[np.ndarray], r: np.ndarray, jp: np.ndarray | None, sparse: Triplets) -> None:
        """The rows of one group into ``r`` and, with ``jp``, their Jacobians: d r / d p[free] into ``jp``,
        d r / d (nuisance) as triplets into ``sparse`` (rows, columns, values)."""
        def add(rows_idx: np.ndarray, cols_idx: np.ndarray, vals: np.ndarray) -> None:
            for lst, a in zip(sparse, (rows_idx, cols_idx, vals), strict=True):
                lst.append(np.reshape(a, -1))

        kind, rows, npt = g["kind"], g["rows"], len(g["points"])
        nt = geo.n_theta(kind, g["free_radius"])
        xin, kst, xref = self._group_inputs(g, x, states)
        res, drdx, drdt = g["fn"](xin, np.zeros((nt, npt)), kst, xref)
        r[g["row0"]: g["row0"] + rows * npt] = np.asarray(res).T.reshape(-1)
        if jp is None:
            return
        nf = jp.shape[1]
        drdx = np.asarray(drdx).reshape(rows, npt, 3).transpose(1, 0, 2)        # (npt, rows, 3)
        rr = g["row0"] + np.arange(npt * rows).reshape(npt, rows)
        on = g.get("on_point", np.ones(npt, bool))
        if nf and on.any():
            assert dx is not None, "d x / d p with the Jacobians"
            blk = np.einsum("nrk,nkp->nrp", drdx[on], dx[g["pos"][on]])
            jp[rr[on].reshape(-1)] = blk.reshape(-1, nf)
        if (~on).any():            # reference rows on a seat: d r / d (seat centre)
            off = np.array([self.instances[a].offset for a in g["anchor"][~on]])
            cols = off[:, None, None] + np.arange(3)[None, None, :]
            add(np.broadcast_to(rr[~on][:, :, None], (len(off), rows, 3)),
                np.broadcast_to(cols, (len(off), rows, 3)), drdx[~on])
        mk = g.get("marker")
        if mk is not None:         # reference rows of a marker at an unknown offset: d r / d (offset)
            sel = np.flatnonzero((mk >= 0) & np.array([self.instances[m].n_theta > 0 if m >= 0 else False
                                                       for m in mk], bool))
            if len(sel):
                assert dxo is not None, "d x / d o with the Jacobians"
                off = np.array([self.instances[m].offset for m in mk[sel]])
                blk = np.einsum("nrk,nkj->nrj", drdx[sel], dxo[g["pos"][sel]])
                add(np.broadcast_to(rr[sel][:, :, None], (len(sel), rows, 3)),
                    np.broadcast_to(off[:, None, None] + np.arange(3)[None, None, :], (len(sel), rows, 3)), blk)
        drdt = np.asarray(drdt).reshape(rows, npt, nt).transpose(1, 0, 2)         # (npt, rows, nt)
        off = np.array([self.instances[i].offset for i in g["inst"]])
        active = np.array([self.instances[i].n_theta > 0 for i in g["inst"]])
        if active.any():
            cols = off[active][:, None, None] + np.arange(nt)[None, None, :]
            add(np.broadcast_to(rr[active][:, :, None], (int(active.sum()), rows, nt)),
                np.broadcast_to(cols, (int(active.sum()), rows, nt)), drdt[active])

    def _distance_rows(self, states: list[np.ndarray], r: np.ndarray, sparse: Triplets | None) -> None:
        """The certified-length rows into ``r`` and, with ``sparse``, their Jacobian triplets."""
        items = self.distance_items
        assert self._dist_fn is not None, "the distance function of the distance rows"
        ca_ = np.array([states[d.a][:3] for d in items]).T
        cb_ = np.array([states[d.b][:3] for d in items]).T
        res, da, db = self._dist_fn(ca_, cb_, np.array([d.length for d in items]))
        r[self.n_point_rows:] = np.asarray(res).reshape(-1)
        if sparse is None:
            return
        rows = self.n_point_rows + np.arange(len(items))
        for attr, d in (("a", da), ("b", db)):
            d = np.asarray(d).reshape(len(items), 3)
            offs = np.array([self.instances[getattr(it, attr)].offset for it in items])
            for lst, a in zip(sparse, (np.repeat(rows, 3), offs[:, None] + np.arange(3)[None, :], d), strict=True):
                lst.append(np.reshape(a, -1))

    def with_free(self, free: ArrayLike) -> Problem:
        """The same structure with another free set (CasADi functions are reused)."""
        new = object.__new__(Problem)
        new.__dict__.update(self.__dict__)
        new.free = np.asarray(free, dtype=int)
        return new

    # -- per-point and per-instance views -------------------------------------------------------
    def residual_table(self, p: ArrayLike, states: list[np.ndarray]) -> dict[str, np.ndarray]:
        """Unweighted residuals by point and by distance at ``p`` and ``states``.

        Returns a dict of arrays: ``point`` (n,) indices into the data, ``kind``, ``instance``,
        ``value`` (n,) [m] (signed distance for scalar kinds, the norm for seat and reference points),
        ``vector`` (n, 3) [m] in the base frame (a scalar residual times its gradient direction),
        ``distance`` (k,) [m] of the distances (measured minus certified).
        """
        x, _ = self.centres(p, offsets=self.marker_offsets(states))
        pts: list[np.ndarray] = []
        kinds: list[str] = []
        insts: list[np.ndarray] = []
        vals: list[np.ndarray] = []
        vecs: list[np.ndarray] = []
        for g in self.groups:
            kind, rows, npt = g["kind"], g["rows"], len(g["points"])
            nt = geo.n_theta(kind, g["free_radius"])
            xin, kst, xref = self._group_inputs(g, x, states)
            res, drdx, _ = g["fn"](xin, np.zeros((nt, npt)), kst, xref)
            res = np.asarray(res).T                                                   # (npt, rows)
            if rows == 1:
                grad = np.asarray(drdx).reshape(1, npt, 3)[0]
                vec = res * grad
                val = res[:, 0]
            elif kind == "reference":     # residual in the reference frame: back to base axes
                rot = kst[0:9].T.reshape(npt, 3, 3, order="F")
                vec = np.einsum("nji,nj->ni", rot, res)
                val = np.linalg.norm(res, axis=1)
            else:
                vec = res
                val = np.linalg.norm(res, axis=1)
            pts.append(g["points"])
            kinds += [kind] * npt
            insts.append(g["inst"])
            vals.append(val)
            vecs.append(vec)
        dist = np.array([np.linalg.norm(states[d.a][:3] - states[d.b][:3]) - d.length for d in self.distance_items])

        def cat(a: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
            return np.concatenate(a) if a else np.zeros(shape)

        return {"point": cat(pts, (0,)).astype(int), "kind": np.array(kinds, dtype=object),
                "instance": cat(insts, (0,)).astype(int), "value": cat(vals, (0,)),
                "vector": cat(vecs, (0, 3)), "distance": dist}

    def check_tracker(self, p: ArrayLike, states: list[np.ndarray], rtol: float = 1e-9) -> None:
        """A :class:`NumericalError` when the data at ``p`` and ``states`` do not determine the unknown frames
        and marker offsets apart (their weighted Jacobian columns, each scaled to unit length, have a
        singular value below ``rtol`` of the largest): poses whose tip frame turns about one axis only, say,
        cannot tell a marker's offset along that axis from the frame's translation."""
        inst = [it for it in self.instances if it.kind in ("reference", "marker") and it.n_theta]
        if not inst:
            return
        cols = np.concatenate([np.arange(it.offset, it.offset + it.n_theta) for it in inst])
        jt = self.with_free([]).evaluate(p, states).jt
        assert jt is not None, "an evaluation with its Jacobians"
        j = jt[:, cols].toarray()
        norm = np.linalg.norm(j, axis=0)
        s = np.linalg.svd(j / np.where(norm > 0, norm, 1.0), compute_uv=False) if len(j) else np.zeros(1)
        if len(j) < len(cols) or not (norm > 0).all() or s[-1] < rtol * s[0]:
            what = " and the markers' offsets" if any(it.kind == "marker" for it in inst) else ""
            raise NumericalError(f"the reference points do not determine the instrument's frame{what}: "
                                 f"{len(cols)} unknowns, condition {s[0] / max(s[-1], 1e-300):.3g}. The poses must "
                                 "turn the tip frame about more than one axis (a marker's offset along the only axis "
                                 "of rotation moves it as the frame's translation does), in every session; or, "
                                 "where the instrument sees the tip point itself, --marker-offset zero")

    def tracker(self, states: list[np.ndarray], u: dict[int, np.ndarray] | None = None) -> Tracker | None:
        """The :class:`~arm_model.tracker.Tracker` at ``states``: each session's frame and, when the
        markers sit at unknown offsets, their offsets (else None: the instrument sees the tip point);
        ``u``: {instance index: standard uncertainties of its increments} (a fit's), for every frame and
        marker or none. None without reference rows."""
        frames = [i for i, it in enumerate(self.instances) if it.kind == "reference"]
        if not frames:
            return None
        markers = [i for i, it in enumerate(self.instances) if it.kind == "marker"]
        numbers = [int(self.data.markers[self.instances[i].points[0]]) for i in markers]
        if numbers != list(range(len(numbers))):
            missing = min(set(range(max(numbers) + 1)) - set(numbers))
            raise NumericalError(f"marker {missing + 1} has no reference point left (the others have): its offset "
                                 "is unknown")
        u = u or {}
        have_u = all(i in u for i in frames + markers)
        return Tracker(tuple(self.instances[i].feature for i in frames),
                       np.array([geo.frame_of(states[i]) for i in frames]),
                       None if not markers or self.data.marker_offsets != "fit"
                       else np.array([states[i][:3] for i in markers]),
                       np.array([u[i] for i in frames]) if have_u else None,
                       np.array([u[i] for i in markers]) if have_u and markers else None)


class CentreKernel:
    """The CasADi functions of one point's ball centre under a model: ``fx(q, w, aux, p, o) -> x`` and, per
    set of parameter columns, ``(x, d x / d p[columns], d x / d o)`` (:meth:`columns`), built on first use."""

    def __init__(self, model: ArmModel) -> None:
        import casadi as ca
        f = model.casadi_function()
        q, w, aux, p = (ca.SX.sym(nm, f.size1_in(i)) for i, nm in enumerate(("q", "w", "aux", "p")))
        o = ca.SX.sym("o", 3)
        x = f(q, w, aux, p + ca.DM(offset_matrix(model)) @ o)
        self._sym = (q, w, aux, p, o, x)
        self.fx = ca.Function("x", [q, w, aux, p, o], [x])
        self._columns: dict[tuple[int, ...] | None, Any] = {}

    def columns(self, key: tuple[int, ...] | None) -> Any:
        """``(x, d x / d p[key], d x / d o)`` of one point (``key`` None: every parameter)."""
        fn = self._columns.get(key)
        if fn is None:
            import casadi as ca
            q, w, aux, p, o, x = self._sym
            jp: Any = ca.jacobian(x, p)
            if key is not None:
                jp = jp[:, list(key)] if key else ca.DM.zeros(3, 0)
            fn = self._columns[key] = ca.Function("xj", [q, w, aux, p, o], [x, jp, ca.jacobian(x, o)])
        return fn


class _TripletsCsr:
    """``csr_matrix((values, (rows, columns)), shape)`` for triplets whose rows and columns repeat from call to call
    (the nuisance Jacobian of each evaluation of a problem). The first call builds it as scipy does (sorted by row,
    then column) and keeps the order that puts the values there; a call with the same rows, columns and shape only
    reorders its values into a copy of the kept index arrays: the same matrix bit for bit, five times faster.
    Triplets that repeat a (row, column) pair (scipy sums them) are never kept."""

    def __init__(self) -> None:
        self._kept: tuple[tuple[int, int], np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    def __call__(self, rows: np.ndarray, columns: np.ndarray, values: np.ndarray, shape: tuple[int, int]
                 ) -> sp.csr_matrix:
        kept = self._kept
        if kept is not None and kept[0] == shape and np.array_equal(kept[1], rows) and np.array_equal(kept[2], columns):
            order, indices, indptr = kept[3:]
            return sp.csr_matrix((values[order], indices.copy(), indptr.copy()), shape=shape)
        out = sp.csr_matrix((values, (rows, columns)), shape=shape)
        order = np.lexsort((columns, rows))
        if out.nnz == len(values) and np.array_equal(out.indices, columns[order]) \
                and np.array_equal(out.data, values[order]):
            self._kept = (shape, rows.copy(), columns.copy(), order, out.indices.copy(), out.indptr.copy())
        return out


@lru_cache(maxsize=8 * CASADI_CACHE)
def mapped(fn: Any, n: int) -> NumpyFunction:
    """The CasADi Function ``fn`` of one point mapped over ``n`` points, as a :class:`NumpyFunction`: made once for
    the same Function and count (the problems of a loop share their kind, distance and centre functions)."""
    return NumpyFunction(fn.map(n))


@lru_cache(maxsize=CASADI_CACHE)
def _kernel_of(model: ArmModel) -> CentreKernel:
    return CentreKernel(model)


def centre_kernel(model: ArmModel) -> CentreKernel:
    """The :class:`CentreKernel` of ``model``, shared by the problems of equal models (same description and
    effects), as :meth:`arm_model.model.ArmModel.casadi_function` is."""
    try:
        hash(model)
    except TypeError:               # a model with an effect that cannot be hashed: its own kernel
        return CentreKernel(model)
    return _kernel_of(model)
