"""The calibration problem of one data set: residual structure, evaluation and exact Jacobians.

Built once per problem structure (model, data, weights, which kinds): the ball centres and their
Jacobian with respect to the parameters come from the model's CasADi Function mapped over the
points, the artefact residuals and their Jacobians from the kind functions of
:mod:`calibration.geometry`; the chain rule joins them. Unknowns are the free parameters and the
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
from arm_model.model import ArmModel

from . import geometry as geo
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
        pts, arte = self.data.points, self.data.artefacts
        ball = self.model.desc.probe.ball_diameter
        n = len(pts)
        lines = pts.lines if pts.lines is not None else np.arange(1, n + 1)
        use_ref = pts.ref is not None and self.reference != "off"
        instances: list[Instance] = []
        by_key: dict[tuple[str, str], int] = {}
        ref_rows, unused = [], []
        offset = 0
        for m in pts.measurements():
            rows_m = np.flatnonzero(pts.measurement == m)
            feats = list(dict.fromkeys(pts.feature[rows_m].tolist()))
            for f in feats:
                rows = rows_m[pts.feature[rows_m] == f]
                kind = arte.features[f].kind if f else "point"
                if kind == "point":
                    (ref_rows if use_ref else unused).append(rows)
                    continue
                feat = arte.features[f]
                radius = None
                if kind == "sphere":
                    radius = (feat.diameter + ball) / 2
                elif kind in ("ring", "cylinder"):
                    radius = (feat.diameter - ball) / 2
                    if radius <= 0:
                        raise InputError(f"feature '{f}': diameter {feat.diameter * 1e3:g} mm is not larger than "
                                         f"the ball ({ball * 1e3:g} mm)", arte.path, None, f"key 'feature {f}'")
                free_r = self.free_radius and kind in ("sphere", "ring", "cylinder")
                need = MIN_POINTS[kind][1 if free_r else 0]
                if len(rows) < need:
                    raise InputError(f"measurement '{m}', feature '{f}' ({kind}): {len(rows)} point(s), at least "
                                     f"{need} needed", pts.path, int(lines[rows[0]]), "feature")
                nt = geo.n_theta(kind, free_r)
                by_key[(m, f)] = len(instances)
                instances.append(Instance(m, f, kind, rows, offset, nt, None if free_r else radius, free_r))
                offset += nt
        if ref_rows:
            rows = np.sort(np.concatenate(ref_rows))
            if len(rows) < 3:
                raise InputError(f"{len(rows)} reference point(s): a rigid transform needs at least 3",
                                 pts.path, int(lines[rows[0]]), "x_ref_mm")
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
        self.groups = []          # (kind, free_radius, inst indices per point, point indices, row0)
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
                self.groups.append(dict(kind=kind, free_radius=fr, inst=iidx, uinst=insts, local=local,
                                        points=pidx, row0=row, rows=rows,
                                        fn=geo.kind_function(kind, fr).map(len(pidx))))
                used.append(pidx)
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
        self._fxj = ca.Function("xj", [q, w, aux, p], [x, ca.jacobian(x, p)]).map(nu)
        jn = self.model.desc.n_joints
        self._q = np.ascontiguousarray(pts.q[self.used].T)
        self._w = np.ascontiguousarray(self.data.wrench[self.used].T)
        self._aux = np.ascontiguousarray(ArmModel.aux_matrix(self.data.aux, n, jn)[self.used].T)
        self._xref = (np.ascontiguousarray(pts.ref[self.used].T) if pts.ref is not None
                      else np.zeros((3, nu)))
        sig = np.empty(self.n_rows)
        for g in self.groups:
            s = self.weights.reference_sigma if g["kind"] == "reference" else self.weights.probe
            sig[g["row0"]: g["row0"] + g["rows"] * len(g["points"])] = s
        sig[self.n_point_rows:] = [d.sigma for d in items]
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
    def centres(self, p, jac: bool = False):
        """Ball centres (n_used, 3) [m] of the used points and, with ``jac``, d x / d p (n_used, 3, P)."""
        p = np.asarray(p, dtype=float)
        if not jac:
            return np.asarray(self._fx(self._q, self._w, self._aux, p)).T, None
        x, dx = self._fxj(self._q, self._w, self._aux, p)
        x = np.asarray(x).T
        dx = np.asarray(dx).reshape(3, len(self.used), len(p)).transpose(1, 0, 2)
        return x, dx

    def initial_states(self, p) -> list[np.ndarray]:
        """Starting nuisance states from the ball centres at ``p`` (algebraic fits)."""
        x, _ = self.centres(p)
        pts = self.data.points
        states = []
        for it in self.instances:
            xi = x[self._pos[it.points]]
            xr = None if pts.ref is None else pts.ref[it.points]
            if it.kind == "reference" and it.n_theta == 0:
                states.append(np.concatenate([np.eye(3).reshape(-1, order="F"), np.zeros(3)]))
                continue
            states.append(geo.initial_state(it.kind, xi, it.radius, xr))
        return states

    def retract(self, states: list[np.ndarray], dtheta: np.ndarray) -> list[np.ndarray]:
        out = []
        for it, s in zip(self.instances, states):
            out.append(s if it.n_theta == 0 else geo.retract(it.kind, s, dtheta[it.offset: it.offset + it.n_theta]))
        return out

    def evaluate(self, p, states: list[np.ndarray], jac: bool = True) -> Evaluation:
        """Weighted residuals (and Jacobians) at parameters ``p`` (full vector, SI) and ``states``."""
        x, dx = self.centres(p, jac)
        r = np.empty(self.n_rows)
        nf = len(self.free)
        if jac:
            jp = np.zeros((self.n_rows, nf))
            ti, tj, tv = [], [], []
        for g in self.groups:
            kind, rows, npt = g["kind"], g["rows"], len(g["points"])
            insts = g["inst"]
            kst = np.stack([states[i] for i in g["uinst"]])[g["local"]].T
            nt = geo.n_theta(kind, g["free_radius"])
            res, drdx, drdt = g["fn"](x[g["pos"]].T, np.zeros((nt, npt)), kst, self._xref[:, g["pos"]])
            sl = slice(g["row0"], g["row0"] + rows * npt)
            r[sl] = np.asarray(res).T.reshape(-1)
            if jac:
                drdx = np.asarray(drdx).reshape(rows, npt, 3).transpose(1, 0, 2)        # (npt, rows, 3)
                if nf:
                    jp[sl] = np.einsum("nrk,nkp->nrp", drdx, dx[g["pos"]][:, :, self.free]).reshape(-1, nf)
                drdt = np.asarray(drdt).reshape(rows, npt, nt).transpose(1, 0, 2)         # (npt, rows, nt)
                off = np.array([self.instances[i].offset for i in insts])
                active = np.array([self.instances[i].n_theta > 0 for i in insts])
                if active.any():
                    rr = (g["row0"] + np.arange(npt * rows).reshape(npt, rows))[active]
                    cc = off[active][:, None] + np.arange(nt)[None, :]
                    ti.append(np.repeat(rr.reshape(-1), nt))
                    tj.append(np.broadcast_to(cc[:, None, :], (active.sum(), rows, nt)).reshape(-1))
                    tv.append(drdt[active].reshape(-1))
        if self.distance_items:
            items = self.distance_items
            ca_ = np.array([states[d.a][:3] for d in items]).T
            cb_ = np.array([states[d.b][:3] for d in items]).T
            res, da, db = self._dist_fn(ca_, cb_, np.array([d.length for d in items]))
            r[self.n_point_rows:] = np.asarray(res).reshape(-1)
            if jac:
                da = np.asarray(da).reshape(len(items), 3)
                db = np.asarray(db).reshape(len(items), 3)
                rows = self.n_point_rows + np.arange(len(items))
                for i_attr, d in (("a", da), ("b", db)):
                    offs = np.array([self.instances[getattr(it, i_attr)].offset for it in items])
                    ti.append(np.repeat(rows, 3))
                    tj.append((offs[:, None] + np.arange(3)[None, :]).reshape(-1))
                    tv.append(d.reshape(-1))
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
            kst = np.stack([states[i] for i in g["uinst"]])[g["local"]].T
            res, drdx, _ = g["fn"](x[g["pos"]].T, np.zeros((nt, npt)), kst, self._xref[:, g["pos"]])
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
