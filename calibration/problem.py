"""The calibration problem of one data set: residual structure, evaluation and exact Jacobians.

Built once per problem structure (model, data, weights, which kinds): the ball centres and their
Jacobian with respect to the parameters come from the model's CasADi Function mapped over the
points, the artefact residuals and their Jacobians from the kind functions of
:mod:`calibration.kinds`; the chain rule joins them. Unknowns are the free parameters and the
nuisance increments of every artefact instance (a feature within one measurement) and of the
reference transform ``T_ref_base``.

Residual rows, in this order: each point kind (seat, sphere, ring, cylinder, plane, reference)
with ``rows`` rows a point, then the distances. Every row is divided by its standard uncertainty
(:class:`~calibration.data.Weights`), so the cost is ``0.5 * sum(r_w**2)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from arm_model import InputError
from arm_model.geometry import ball_centre_radius
from arm_model.model import ArmModel

from . import kinds as geo
from .data import CalibrationData, Weights

__all__ = ["Instance", "DistanceItem", "Problem", "Evaluation", "MIN_POINTS", "POINT_KINDS"]

#: point kinds in row order
POINT_KINDS = ("seat", "sphere", "ring", "cylinder", "plane", "reference")

#: fewest points an instance needs (known radius, free radius)
MIN_POINTS = {"seat": (1, 1), "sphere": (4, 5), "ring": (5, 6), "cylinder": (5, 6), "plane": (4, 4),
              "reference": (3, 3)}


@dataclass
class Instance:
    """One artefact feature within one measurement (or the reference transform)."""
    measurement: str
    feature: str
    kind: str
    points: np.ndarray          # indices into the data's points
    offset: int                 # first column of its nuisance increments
    n_theta: int                # 0 for a frozen instance (reference transform held at identity)
    radius: float | None        # offset radius [m] of sphere / ring / cylinder, None if fitted
    free_radius: bool = False


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
        reference: "fit" (``T_ref_base`` a nuisance unknown), "identity" (reference coordinates are
            base coordinates) or "off" (reference columns ignored).
    """
    model: ArmModel
    data: CalibrationData
    weights: Weights = field(default_factory=Weights)
    free: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    free_radius: bool = False
    distances: bool = True
    reference: str = "fit"

    def __post_init__(self):
        self.free = np.asarray(self.free, dtype=int)
        self._build()

    # -- structure --------------------------------------------------------------------------------
    def _build(self) -> None:
        pts, arte, data = self.data.points, self.data.artefacts, self.data
        ball = self.model.desc.probe.ball_diameter
        n = len(pts)
        lines = pts.lines if pts.lines is not None else np.arange(1, n + 1)
        has_ref = (np.all(np.isfinite(pts.ref), axis=1) if pts.ref is not None and self.reference != "off"
                   else np.zeros(n, bool))
        instances: list[Instance] = []
        by_key: dict[tuple[str, str], int] = {}
        unused = []
        offset = 0
        for m in pts.measurements():
            rows_m = np.flatnonzero(pts.measurement == m)
            for f in dict.fromkeys(pts.feature[rows_m].tolist()):
                rows = rows_m[pts.feature[rows_m] == f]
                kind = arte.features[f].kind if f else "point"
                if kind == "point":
                    unused.append(rows[~has_ref[rows]])
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
                if len(rows) < need:
                    raise InputError(f"measurement '{m}', feature '{f}' ({kind}): {len(rows)} point(s), at least "
                                     f"{need} needed", data.file_of(rows[0]), int(lines[rows[0]]), "feature")
                distinct = len(np.unique(pts.q[rows], axis=0))
                if kind != "seat" and distinct < need:
                    raise InputError(f"measurement '{m}', feature '{f}' ({kind}): {len(rows)} points but only "
                                     f"{distinct} distinct pose(s) (the same encoder angles repeated): the {kind}'s "
                                     f"unknowns are unidentifiable; at least {need} distinct points needed",
                                     data.file_of(rows[0]), int(lines[rows[0]]), "feature")
                nt = geo.n_theta(kind, free_r)
                by_key[(m, f)] = len(instances)
                instances.append(Instance(m, f, kind, rows, offset, nt, None if free_r else radius, free_r))
                offset += nt
        # reference rows: on a free point the ball centre, on a seat the seat's centre (a tracker nest)
        ref_rows, anchor = [], []
        for i in np.flatnonzero(has_ref):
            f = pts.feature[i]
            kind = arte.features[f].kind if f else "point"
            if kind == "point":
                ref_rows.append(i)
                anchor.append(-1)
            elif kind == "seat":
                ref_rows.append(i)
                anchor.append(by_key[(pts.measurement[i], f)])
        self.ref_anchor = np.array(anchor, dtype=int)
        if ref_rows:
            rows = np.array(ref_rows)
            if len(rows) < 3:
                raise InputError(f"{len(rows)} reference point(s): a rigid transform needs at least 3",
                                 data.file_of(rows[0]), int(lines[rows[0]]), "x_ref_mm")
            nt = 6 if self.reference == "fit" else 0
            instances.append(Instance("*", "", "reference", rows, offset, nt, None))
            offset += nt
        self.n_nuisance = offset
        self.instances = instances
        self.unused = np.sort(np.concatenate(unused)) if unused else np.zeros(0, int)
        # distances
        items: list[DistanceItem] = []
        if self.distances:
            for dist in arte.distances:
                fa, fb = dist.between
                for m in pts.measurements():
                    if (m, fa) in by_key and (m, fb) in by_key:
                        ia, ib = by_key[(m, fa)], by_key[(m, fb)]
                        for i, fid in ((ia, fa), (ib, fb)):
                            if instances[i].kind not in ("seat", "sphere"):
                                raise InputError(f"a distance needs feature centres: '{fid}' is a "
                                                 f"{instances[i].kind} (use seats or spheres)", arte.path, None,
                                                 "key 'distance.between'")
                        items.append(DistanceItem(m, (fa, fb), ia, ib, dist.length,
                                                  self.weights.length_sigma(dist.u_length)))
        self.distance_items = items
        # point rows, grouped by kind
        self.groups = []
        row = 0
        used = []
        for kind in POINT_KINDS:
            for fr in (False, True):
                insts = [i for i, it in enumerate(instances) if it.kind == kind and it.free_radius == fr]
                if not insts:
                    continue
                pidx = np.concatenate([instances[i].points for i in insts])
                iidx = np.concatenate([np.full(len(instances[i].points), i) for i in insts])
                local = np.concatenate([np.full(len(instances[i].points), k) for k, i in enumerate(insts)])
                rows = geo.KINDS[kind].rows
                g = dict(kind=kind, free_radius=fr, inst=iidx, uinst=insts, local=local, points=pidx, row0=row,
                         rows=rows, fn=geo.kind_function(kind, fr).map(len(pidx)))
                if kind == "reference":
                    g["anchor"] = self.ref_anchor
                    g["on_point"] = self.ref_anchor < 0
                    used.append(pidx[g["on_point"]])
                else:
                    used.append(pidx)
                self.groups.append(g)
                row += rows * len(pidx)
        self.n_point_rows = row
        self.n_rows = row + len(items)
        self.used = np.unique(np.concatenate(used)) if used else np.zeros(0, int)
        if self.n_rows == 0:
            raise InputError("no usable points: no point belongs to a seat, sphere, ring, cylinder or plane, "
                             "and there are no reference coordinates", pts.path)
        # positions of used points in the centre arrays
        self._pos = np.full(n, -1)
        self._pos[self.used] = np.arange(len(self.used))
        for g in self.groups:
            g["pos"] = self._pos[g["points"]]
        self._dist_fn = geo.distance_function().map(len(items)) if items else None
        # CasADi ball centres of the used points
        f = self.model.casadi_function()
        import casadi as ca
        q, w, aux, p = (ca.SX.sym(nm, f.size1_in(i)) for i, nm in enumerate(("q", "w", "aux", "p")))
        x = f(q, w, aux, p)
        nu = len(self.used)
        self._fx = ca.Function("x", [q, w, aux, p], [x]).map(nu)
        self._fxj_full = ca.Function("xj", [q, w, aux, p], [x, ca.jacobian(x, p)]).map(nu)
        self._sym = (q, w, aux, p, x)
        self._fxj_cache = {}          # free set -> mapped Function of (x, d x / d p[free]), shared by copies
        jn = self.model.desc.n_joints
        self._q = np.ascontiguousarray(pts.q[self.used].T)
        self._w = np.ascontiguousarray(self.data.wrench[self.used].T)
        self._aux = np.ascontiguousarray(ArmModel.aux_matrix(self.data.aux, n, jn)[self.used].T)
        self._xref_all = pts.ref if pts.ref is not None else None
        sig = np.empty(self.n_rows)
        for g in self.groups:
            sl = slice(g["row0"], g["row0"] + g["rows"] * len(g["points"]))
            if g["kind"] == "reference":
                sig[sl] = np.repeat(np.where(g["on_point"], self.weights.reference_sigma, self.weights.reference), 3)
            else:
                sig[sl] = self.weights.probe
            sig[sl] *= self.weights.factor(g["kind"])
        sig[self.n_point_rows:] = [d.sigma * self.weights.factor("length") for d in items]
        self.sigma = sig
        # row metadata
        self.row_point = np.full(self.n_rows, -1)
        self.row_instance = np.full(self.n_rows, -1)
        for g in self.groups:
            sl = slice(g["row0"], g["row0"] + g["rows"] * len(g["points"]))
            self.row_point[sl] = np.repeat(g["points"], g["rows"])
            self.row_instance[sl] = np.repeat(g["inst"], g["rows"])
        self.row_distance = np.full(self.n_rows, -1)
        self.row_distance[self.n_point_rows:] = np.arange(len(items))

    # -- evaluation -------------------------------------------------------------------------------
    def centres(self, p, jac: bool = False, columns=None):
        """Ball centres (n_used, 3) [m] of the used points and, with ``jac``, d x / d p (n_used, 3, P),
        or only the ``columns`` (indices into p) of it."""
        p = np.asarray(p, dtype=float)
        ncol = len(p) if columns is None else len(columns)
        if len(self.used) == 0:
            return np.zeros((0, 3)), (np.zeros((0, 3, ncol)) if jac else None)
        if not jac:
            return np.asarray(self._fx(self._q, self._w, self._aux, p)).T, None
        if columns is None:
            fn = self._fxj_full
        else:
            key = tuple(int(c) for c in columns)
            fn = self._fxj_cache.get(key)
            if fn is None:
                import casadi as ca
                q, w, aux, ps, x = self._sym
                jcols = ca.jacobian(x, ps)[:, list(key)] if key else ca.DM.zeros(3, 0)
                fn = ca.Function("xj", [q, w, aux, ps], [x, jcols]).map(len(self.used))
                self._fxj_cache[key] = fn
        x, dx = fn(self._q, self._w, self._aux, p)
        x = np.asarray(x).T
        dx = np.asarray(dx).reshape(3, len(self.used), ncol).transpose(1, 0, 2)
        return x, dx

    def _group_inputs(self, g, x, states):
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
        return xin, kst, self._xref_all[g["points"]].T

    def initial_states(self, p) -> list[np.ndarray]:
        """Starting nuisance states from the ball centres at ``p`` (algebraic fits)."""
        x, _ = self.centres(p)
        states = []
        for it in self.instances:
            if it.kind == "reference":
                if it.n_theta == 0:
                    states.append(np.concatenate([np.eye(3).reshape(-1, order="F"), np.zeros(3)]))
                    continue
                pos = self._pos[it.points]
                xi = np.where((pos >= 0)[:, None], x[np.maximum(pos, 0)], 0.0)
                for k, a in enumerate(self.ref_anchor):
                    if a >= 0:
                        xi[k] = states[a][:3]
                states.append(geo.initial_state("reference", xi, None, self._xref_all[it.points]))
                continue
            states.append(geo.initial_state(it.kind, x[self._pos[it.points]], it.radius))
        return states

    def retract(self, states: list[np.ndarray], dtheta: np.ndarray) -> list[np.ndarray]:
        out = []
        for it, s in zip(self.instances, states):
            out.append(s if it.n_theta == 0 else geo.retract(it.kind, s, dtheta[it.offset: it.offset + it.n_theta]))
        return out

    def evaluate(self, p, states: list[np.ndarray], jac: bool = True) -> Evaluation:
        """Weighted residuals (and Jacobians) at parameters ``p`` (full vector, SI) and ``states``."""
        nf = len(self.free)
        x, dx = self.centres(p, jac and nf > 0, self.free)
        r = np.empty(self.n_rows)
        if jac:
            jp = np.zeros((self.n_rows, nf))
            ti, tj, tv = [], [], []

        def add(rows_idx, cols_idx, vals):
            ti.append(rows_idx.reshape(-1))
            tj.append(cols_idx.reshape(-1))
            tv.append(vals.reshape(-1))

        for g in self.groups:
            kind, rows, npt = g["kind"], g["rows"], len(g["points"])
            nt = geo.n_theta(kind, g["free_radius"])
            xin, kst, xref = self._group_inputs(g, x, states)
            res, drdx, drdt = g["fn"](xin, np.zeros((nt, npt)), kst, xref)
            sl = slice(g["row0"], g["row0"] + rows * npt)
            r[sl] = np.asarray(res).T.reshape(-1)
            if not jac:
                continue
            drdx = np.asarray(drdx).reshape(rows, npt, 3).transpose(1, 0, 2)        # (npt, rows, 3)
            rr = g["row0"] + np.arange(npt * rows).reshape(npt, rows)
            on = g.get("on_point", np.ones(npt, bool))
            if nf and on.any():
                blk = np.einsum("nrk,nkp->nrp", drdx[on], dx[g["pos"][on]])
                jp[rr[on].reshape(-1)] = blk.reshape(-1, nf)
            if (~on).any():            # reference rows on a seat: d r / d (seat centre)
                off = np.array([self.instances[a].offset for a in g["anchor"][~on]])
                cols = off[:, None, None] + np.arange(3)[None, None, :]
                add(np.broadcast_to(rr[~on][:, :, None], (len(off), rows, 3)),
                    np.broadcast_to(cols, (len(off), rows, 3)), drdx[~on])
            drdt = np.asarray(drdt).reshape(rows, npt, nt).transpose(1, 0, 2)         # (npt, rows, nt)
            off = np.array([self.instances[i].offset for i in g["inst"]])
            active = np.array([self.instances[i].n_theta > 0 for i in g["inst"]])
            if active.any():
                cols = off[active][:, None, None] + np.arange(nt)[None, None, :]
                add(np.broadcast_to(rr[active][:, :, None], (int(active.sum()), rows, nt)),
                    np.broadcast_to(cols, (int(active.sum()), rows, nt)), drdt[active])
        if self.distance_items:
            items = self.distance_items
            ca_ = np.array([states[d.a][:3] for d in items]).T
            cb_ = np.array([states[d.b][:3] for d in items]).T
            res, da, db = self._dist_fn(ca_, cb_, np.array([d.length for d in items]))
            r[self.n_point_rows:] = np.asarray(res).reshape(-1)
            if jac:
                rows = self.n_point_rows + np.arange(len(items))
                for attr, d in (("a", da), ("b", db)):
                    d = np.asarray(d).reshape(len(items), 3)
                    offs = np.array([self.instances[getattr(it, attr)].offset for it in items])
                    add(np.repeat(rows, 3), offs[:, None] + np.arange(3)[None, :], d)
        r /= self.sigma
        if not jac:
            return Evaluation(r, x)
        jp /= self.sigma[:, None]
        if ti:
            ti, tj, tv = np.concatenate(ti), np.concatenate(tj), np.concatenate(tv)
            tv = tv / self.sigma[ti]
        else:
            ti = tj = np.zeros(0, int)
            tv = np.zeros(0)
        jt = sp.csr_matrix((tv, (ti, tj)), shape=(self.n_rows, self.n_nuisance))
        return Evaluation(r, x, jp, jt)

    def with_free(self, free) -> "Problem":
        """The same structure with another free set (CasADi functions are reused)."""
        new = object.__new__(Problem)
        new.__dict__.update(self.__dict__)
        new.free = np.asarray(free, dtype=int)
        return new

    # -- per-point and per-instance views -------------------------------------------------------
    def residual_table(self, p, states) -> dict:
        """Unweighted residuals by point and by distance at ``p`` and ``states``.

        Returns a dict of arrays: ``point`` (n,) indices into the data, ``kind``, ``instance``,
        ``value`` (n,) [m] (signed distance for scalar kinds, the norm for seat and reference points),
        ``vector`` (n, 3) [m] in the base frame (a scalar residual times its gradient direction),
        ``distance`` (k,) [m] of the distances (measured minus certified).
        """
        x, _ = self.centres(p)
        pts, kinds, insts, vals, vecs = [], [], [], [], []
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
        cat = (lambda a, shape: np.concatenate(a) if a else np.zeros(shape))
        return {"point": cat(pts, (0,)).astype(int), "kind": np.array(kinds, dtype=object),
                "instance": cat(insts, (0,)).astype(int), "value": cat(vals, (0,)),
                "vector": cat(vecs, (0, 3)), "distance": dist}
