"""The uncertainty of every corrected ball centre: linear propagation with exact Jacobians, and Monte Carlo.

The corrected ball centre ``x = f(p, q, w)`` of a model (:class:`arm_model.model.ArmModel`, every
effect applied) depends on the model parameters ``p``, the encoder readings ``q`` and the measured
wrench ``w``. Its covariance, to first order, is the sum of named contributions

    parameters      J_p Sigma_p J_p^T         (the calibration's covariance of the free parameters)
    encoders        J_q diag(u_q^2) J_q^T     (u_q = resolution / sqrt(12) per joint: rectangular)
    force sensor    J_w diag(u_w^2) J_w^T     (probe frame: bending x, y and axial z)
    compliance      J_c diag(u_c^2) J_c^T     (the probe's compliances, unless the covariance has them)
    probing         u_probe^2 I               (the scatter of the contact itself, per axis)
    model discrepancy  u_d(q)^2 I             (the error of the model away from its calibration's poses, per
                                               axis: calibration.discrepancy; it grows with how far the pose
                                               lies from the training poses: arm_model.discrepancy)

with the Jacobians exact (:mod:`arm_model.jacobian`: the geometric Jacobian of the chain and dual
numbers through the effects' own code), evaluated for N points in chunks on two threads.
:func:`monte_carlo` samples the same inputs (parameters from their covariance, rectangular encoder
errors, normal force and compliance errors, normal probing scatter) and re-evaluates the model.

Everything here is SI: metres, radians, newtons, m/N.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from .discrepancy import GrowingDiscrepancy, growth_text
from .effects import ModelInputs
from .jacobian import DUAL_OPS, Dual, chain_jacobian, geometry_entries, value
from .kinematics import run_chunks
from .log import Progress
from .model import ArmModel, AuxData
from .parallel import blas_threads

__all__ = ["FORCE_SENSOR_U_N", "COMPLIANCE_U_RELATIVE", "CONTRIBUTIONS", "InputUncertainty",
           "ParameterCovariance", "Propagation", "Propagator", "default_inputs", "propagate", "monte_carlo",
           "covariance_columns", "directional_ratio"]

log = logging.getLogger(__name__)

#: standard uncertainty [N] of the force along probe x, y (bending) and z (axial): the seed paper's
#: Table 1, the root-sum-square of its printed terms (the printed bending total, 0.00723 N, is a
#: misprint of 0.0723 N; ``correction.paper.table1_reproduction`` recomputes both)
FORCE_SENSOR_U_N = (0.0723, 0.0723, 0.0464)
#: standard uncertainty of a declared probe compliance, relative to its value: the standard error of
#: the series compliance fitted on the seed paper's Table 2 (0.0028 mm/N, ``correction.paper.close_loop``
#: through the origin) relative to the paper's FEM bending compliance (0.0142 mm/N)
COMPLIANCE_U_RELATIVE = 0.2
#: the contributions, in report order
CONTRIBUTIONS = ("parameters", "encoders", "force sensor", "compliance", "probing", "model discrepancy")


@dataclass(frozen=True)
class InputUncertainty:
    """Standard uncertainties of the inputs (SI) and where each comes from.

    Attributes:
        encoder: (J,) per encoder column [rad] ([m] for a prismatic joint): the resolution / sqrt(12) of a
            rectangular quantisation.
        force: (3,) force along probe x, y, z [N]; torque: (3,) [N m].
        compliance: (3,) of the probe compliances along x, y, z [m/N] (used only for compliances the
            parameter covariance does not hold).
        probing: per axis [m], the scatter of the contact itself.
        sources: contribution name -> a sentence saying where the value comes from.
        discrepancy: per axis [m], the model discrepancy (the error of the model beyond its parameters'
            uncertainty away from the poses it was calibrated on; independent from point to point).
        growing: the model discrepancy growing away from the training poses (:class:`~arm_model.discrepancy.
            GrowingDiscrepancy`, its ``sigma0`` = ``discrepancy``) or None (``discrepancy`` at every pose).
    """
    encoder: np.ndarray
    force: np.ndarray
    torque: np.ndarray
    compliance: np.ndarray
    probing: float = 0.0
    sources: dict = field(default_factory=dict)
    discrepancy: float = 0.0
    growing: GrowingDiscrepancy | None = None

    def discrepancy_sd(self, desc, q) -> np.ndarray:
        """(N,) [m] the model discrepancy per axis at each pose of ``q`` (N, J)."""
        if self.growing is not None:
            return self.growing.sd(desc, q)
        return np.full(len(np.atleast_2d(q)), self.discrepancy)


@dataclass(frozen=True)
class ParameterCovariance:
    """The covariance [SI^2] of the named model parameters (the free ones of a calibration)."""
    names: tuple
    cov: np.ndarray
    source: str = "the calibration's covariance"

    def __post_init__(self):
        c = np.asarray(self.cov, dtype=float)
        if c.shape != (len(self.names), len(self.names)):
            raise ValueError(f"covariance has shape {c.shape}, expected {len(self.names)} x {len(self.names)}")
        if not np.all(np.isfinite(c)) or not np.allclose(c, c.T, rtol=1e-9, atol=0.0):
            raise ValueError("the parameter covariance must be finite and symmetric")
        object.__setattr__(self, "cov", c)

    def factor(self) -> np.ndarray:
        """L (k, r) with ``L L^T = cov``, r its rank: the eigen-decomposition of the correlation matrix, scaled back
        by the standard deviations. Parameters of widely different scales (m beside rad/(N m)) keep their relative
        precision: the raw covariance's eigenvectors carry the rounding of its largest variance into the smallest
        (J cov J^T off by 2e-2 relative for scales over nine decades, 3e-15 scaled: tests/test_uncertainty_plans.py).
        A positive semi-definite cov is accepted: a correlation matrix with an eigenvalue below -1e-9 is a
        ValueError naming the parameters of its eigenvector."""
        var = np.diag(self.cov)
        if var.size and var.min() < 0:
            raise ValueError(f"the parameter covariance has a negative variance ({self.names[int(np.argmin(var))]}: "
                             f"{var.min():.3g})")
        sd = np.sqrt(var)
        sd = np.where(sd > 0, sd, 1.0)      # a parameter held exactly: its row of the correlations is 0 (or not PSD)
        w, v = np.linalg.eigh(self.cov / np.outer(sd, sd))
        if w.size and w.min() < -1e-9 * max(w.max(), 0.0):
            along = np.argsort(-np.abs(v[:, 0]))[:3]
            raise ValueError(f"the parameter covariance is not positive semi-definite (an eigenvalue of its "
                             f"correlations is {w[0]:.3g}, mostly along {', '.join(self.names[i] for i in along)})")
        keep = w > 0
        return sd[:, None] * (v[:, keep] * np.sqrt(w[keep]))


def default_inputs(desc, *, encoder=None, force=None, torque=None, compliance=None, probing=None,
                   has_force: bool = True, model_probing: float | None = None, discrepancy=None,
                   model_discrepancy: float | GrowingDiscrepancy | None = None) -> InputUncertainty:
    """The input uncertainties of ``desc`` with their sources; any argument overrides its default.

    Args:
        encoder: standard uncertainty [rad] ([m] for a prismatic joint), one value or one an encoder column
            (default: each joint's
            ``encoder_resolution`` of the description / sqrt(12), 0 where not given).
        force: [N], one value or (x, y, z) (default :data:`FORCE_SENSOR_U_N`).
        torque: [N m] (default 0: no torque is measured by the seed paper's sensor).
        compliance: [m/N], one value or (x, y, z) (default :data:`COMPLIANCE_U_RELATIVE` times the
            description's compliances).
        probing: [m] per axis (default ``model_probing``, else 0).
        has_force: False when the points carry no force (then no force-sensor contribution).
        model_probing: [m] the probing scatter a model file carries (``[calibration]
            probing_scatter_um``: its calibration's variance components), the default of ``probing``.
        discrepancy: [m] per axis (default ``model_discrepancy``, else 0).
        model_discrepancy: [m] the model discrepancy a model file carries (``[calibration]
            model_discrepancy_um``: its calibration's extrapolative cross-validation), or the
            :class:`~arm_model.discrepancy.GrowingDiscrepancy` it carries (with
            ``model_discrepancy_growth_um_per_mm`` and the training poses), the default of ``discrepancy`` (a
            given ``discrepancy`` is a constant: it replaces the growth too).
    """
    j = desc.n_joints
    src = {}
    if encoder is None:
        res = np.array([getattr(jt, "encoder_resolution", None) or 0.0 for jt in desc.encoders])
        enc = res / math.sqrt(12.0)
        given = [jt.name for jt in desc.encoders if getattr(jt, "encoder_resolution", None)]
        src["encoders"] = ("resolution / sqrt(12) from the description's encoder_resolution"
                           + ("" if len(given) == j else f" (given for {len(given)} of {j} joints; 0 elsewhere)")
                           if given else "none: the description gives no encoder_resolution (0 assumed)")
    else:
        enc = np.broadcast_to(np.asarray(encoder, dtype=float), (j,)).copy()
        src["encoders"] = "given"
    if not has_force:
        f = np.zeros(3)
        src["force sensor"] = "no force in the points"
    elif force is None:
        f = np.array(FORCE_SENSOR_U_N)
        src["force sensor"] = "seed paper Table 1: 0.0723 N bending (x, y), 0.0464 N axial (z)"
    else:
        f = np.broadcast_to(np.asarray(force, dtype=float), (3,)).copy()
        src["force sensor"] = "given"
    t = np.zeros(3) if torque is None else np.broadcast_to(np.asarray(torque, dtype=float), (3,)).copy()
    if compliance is None:
        c = COMPLIANCE_U_RELATIVE * np.asarray(desc.probe.compliance, dtype=float)
        src["compliance"] = (f"{COMPLIANCE_U_RELATIVE:.0%} of the declared compliances (the seed paper's Table 2 "
                             "fit: 0.0028 mm/N on 0.0142 mm/N)")
    else:
        c = np.broadcast_to(np.asarray(compliance, dtype=float), (3,)).copy()
        src["compliance"] = "given"
    probing, src["probing"] = _model_input(
        probing, model_probing, "probing_scatter_um",
        "its calibration's variance components, net of the encoder and force-sensor noise",
        "a model file from calibrate on probed points does; a reference instrument's own noise is not the probe's")
    growing = model_discrepancy if isinstance(model_discrepancy, GrowingDiscrepancy) else None
    sigma0 = growing.sigma0 if growing is not None else model_discrepancy
    if discrepancy is not None or growing is None or not growing.grows:   # a given value is a constant
        growing = None
    discrepancy, src["model discrepancy"] = _model_input(discrepancy, sigma0, "model_discrepancy_um",
                                                         "its calibration's extrapolative cross-validation")
    if growing is not None:
        src["model discrepancy"] += (f", growing by {growth_text(growing.growths)} um per mm of ball travel from the "
                                     "nearest training pose (model_discrepancy_growth_um_per_mm)")
    for name, arr in (("encoder", enc), ("force", f), ("torque", t), ("compliance", c)):
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise ValueError(f"{name} uncertainty must be finite and >= 0, got {arr}")
    pr = 0.0 if probing is None else float(probing)
    dr = 0.0 if discrepancy is None else float(discrepancy)
    for name, v, given in (("probing", pr, probing), ("model discrepancy", dr, discrepancy)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} uncertainty must be finite and >= 0, got {given}")
    return InputUncertainty(enc, f, t, c, pr, src, dr, growing)


def _model_input(given, from_model, key: str, how: str, who: str = "a model file from calibrate does") -> tuple:
    """(value [m] or None, source) of an input a model file may carry as ``key`` [um]: ``given`` when given,
    else the model file's (``how`` it was found), else none (``who`` would give it)."""
    if given is not None:
        return given, "given"
    if from_model is not None:
        return from_model, f"the model file's {key} {from_model * 1e6:.4g} um ({how})"
    return None, f"none (0): the arm gives no {key} ({who})"


@dataclass
class Propagation:
    """Per point: the corrected centre (N, 3) [m], its covariance (N, 3, 3) [m^2], and each named
    contribution's variances along x, y, z (N, 3) [m^2]; ``sources`` says where each input came from."""
    centres: np.ndarray
    cov: np.ndarray
    contributions: dict
    sources: dict
    #: (N, R, 3) [m], with ``systematic=True``: the rows of the errors every point shares (the
    #: parameters' factor L^T J_p^T, then the three compliances'), so that the covariance of points i
    #: and j from them is ``systematic[i].T @ systematic[j]``; None otherwise
    systematic: np.ndarray | None = None

    @property
    def u(self) -> np.ndarray:
        """(N, 3) standard uncertainties along x, y, z [m]."""
        return np.sqrt(np.einsum("nii->ni", self.cov))

    def summary(self) -> dict:
        """Per contribution: the RMS over the points of its standard uncertainty per axis [m]."""
        return {k: np.sqrt(v.mean(axis=0)) for k, v in self.contributions.items()}


def covariance_columns(cov: np.ndarray) -> dict:
    """The six terms of (N, 3, 3) covariances [m^2] as columns ``cov_xx_um2`` ... [um^2]."""
    out = {}
    for a, b in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
        out[f"cov_{'xyz'[a]}{'xyz'[b]}_um2"] = cov[:, a, b] * 1e12
    return out


def directional_ratio(cov_ref: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(N, 2): per point the smallest and largest ratio ``sqrt(v^T C v / v^T C_ref v)`` over all unit
    directions ``v`` (the square roots of the extreme generalized eigenvalues of ``C`` against
    ``C_ref``): how far the standard uncertainty of ``cov`` along any direction, the covariance terms
    included, is from that of ``cov_ref``. NaN for a point whose ``cov_ref`` is not positive definite."""
    cov_ref, cov = np.asarray(cov_ref, dtype=float), np.asarray(cov, dtype=float)
    out = np.full((len(cov_ref), 2), np.nan)
    ok = np.all(np.linalg.eigvalsh(cov_ref) > 0, axis=1)
    if ok.any():
        li = np.linalg.inv(np.linalg.cholesky(cov_ref[ok]))
        ev = np.linalg.eigvalsh(li @ cov[ok] @ np.swapaxes(li, 1, 2))
        out[ok] = np.sqrt(np.clip(ev[:, [0, -1]], 0.0, None))
    return out


def beyond_note(d) -> str:
    """``"; these points lie M mm (median), up to D mm from the nearest training pose"`` for the distances ``d``
    [m] of the points from it (:func:`arm_model.discrepancy.pose_distance`)."""
    if not len(d):
        return ""
    median = float(d[0]) if len(d) == 1 else np.median(d)          # one point (a live one's): itself
    return (f"; these points lie {median * 1e3:.1f} mm (median), up to {d.max() * 1e3:.1f} mm from the nearest "
            "training pose (ball travel of the joint motions)")


def _compliance_covered(names) -> bool:
    return any(n.startswith(("probe.compliance", "probe.dcompliance")) for n in names)


def _prepare(model: ArmModel, q, wrench, aux):
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, j = q.shape
    if j != model.desc.n_joints:
        raise ValueError(f"q must have shape (N, {model.desc.n_joints}), got {q.shape}")
    w = np.zeros((n, 6))
    if wrench is not None:
        wr = np.atleast_2d(np.asarray(wrench, dtype=float))
        if wr.shape[0] != n or wr.shape[1] not in (3, 6):
            raise ValueError(f"wrench must have shape (N, 3) or (N, 6), got {wr.shape}")
        w[:, : wr.shape[1]] = wr
    aux = model._check_aux(aux, n)
    return q, w, aux


@dataclass(frozen=True)
class _Plan:
    """What :func:`propagate` sets up once for all chunks: the directions of the total Jacobian (the
    parameters in the covariance, the encoder columns, the wrench) and the matrix ``S`` mapping them to
    the rows of one stacked product ``A = S T`` (each block of rows of ``A`` squared and summed gives one
    contribution)."""
    pidx: list
    lfac: np.ndarray
    directions: list
    d_index: dict
    s_mat: np.ndarray
    spans: dict
    comp_cols: list
    use_compliance: bool


def _make_plan(model: ArmModel, parameters, inputs: InputUncertainty, n_q: int) -> _Plan:
    spec = model.spec
    pnames = () if parameters is None else tuple(parameters.names)
    pidx = [spec.index(nm) for nm in pnames]
    lfac = parameters.factor() if parameters is not None and len(pnames) else np.zeros((0, 0))
    use_compliance = bool(not _compliance_covered(pnames) and np.any(inputs.compliance > 0))
    u_w = np.concatenate([inputs.force, inputs.torque])
    entries = geometry_entries(model.desc.convention, len(model.desc.joints), n_q)
    directions = [("p", i) for i in pidx] + [("q", i) for i in range(n_q)] + [("w", k) for k in range(6)]
    blocks = {"parameters": lfac.T, "encoders": np.diag(inputs.encoder), "force sensor": np.diag(u_w)}
    s_mat = np.zeros((sum(b.shape[0] for b in blocks.values()), len(directions)))
    spans, r0, c0 = {}, 0, 0
    for name, b in blocks.items():
        s_mat[r0: r0 + b.shape[0], c0: c0 + b.shape[1]] = b
        spans[name] = slice(r0, r0 + b.shape[0])
        r0, c0 = r0 + b.shape[0], c0 + b.shape[1]
    return _Plan(pidx, lfac, directions, {d: k for k, d in enumerate(directions)}, s_mat, spans,
                 [entries.index(("compliance", k)) for k in range(3)], use_compliance)


def _chunk_jacobian(model: ArmModel, plan: _Plan, p, q, w, aux: AuxData):
    """For one chunk of points: (centres (n, 3) [m], the chain's Jacobian g (E, 3, n) by geometry entry,
    the chain rule from the directions to the entries: a constant matrix M (directions x E) and per-point
    coefficients {direction: (3, n) slab}), by dual numbers through the effects' own code."""
    nj = q.shape[1]
    seeded, wanted = set(plan.pidx), model.needs()
    pd = [Dual(float(v), {("p", i): 1.0}) if i in seeded else float(v) for i, v in enumerate(p)]
    inp = ModelInputs(
        q=[Dual(q[:, i], {("q", i): 1.0}) for i in range(nj)],
        wrench=[Dual(w[:, k], {("w", k): 1.0}) for k in range(6)],
        temperature=aux.temperature, time=aux.time, motion=None if aux.motion is None else list(aux.motion.T),
        tau_gravity=None if aux.tau_gravity is None or "tau_gravity" not in wanted else list(aux.tau_gravity.T),
        tau_contact=None if aux.tau_contact is None or "tau_contact" not in wanted else list(aux.tau_contact.T))
    geom = model._apply_effects(pd, inp, DUAL_OPS)
    flat = [x for r in geom.rows for x in r] + list(geom.p_last) + list(geom.compliance) + list(inp.q) \
        + list(inp.wrench)
    vals = [value(x) for x in flat]
    m, nr = len(geom.rows[0]), len(geom.rows)
    k0 = m * nr
    desc = model.desc
    cen, g = chain_jacobian(desc.convention, [vals[m * i: m * i + m] for i in range(nr)], vals[k0: k0 + 3],
                            vals[k0 + 3: k0 + 6], vals[k0 + 6: k0 + 6 + nj], vals[k0 + 6 + nj:], desc.chain_joints,
                            desc.probe.rotation, desc.probe.lever)
    mmat = np.zeros((len(plan.directions), len(flat)))
    per_point = {}
    for col, x in enumerate(flat):
        if not isinstance(x, Dual):
            continue
        for key, coef in x.der.items():
            k = plan.d_index.get(key)
            if k is None:
                continue
            if not isinstance(coef, np.ndarray) or coef.ndim == 0:
                mmat[k, col] += coef
            else:
                t = g[col] * coef
                per_point[k] = per_point[k] + t if k in per_point else t
    return cen, g, mmat, per_point


#: at most this many points are propagated without limiting the BLAS threads (their products are tiny)
_FEW = 16
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _add_squares(a, out_cov, contribution) -> None:
    """Add sum_r a[r, i] a[r, j] (a: (R, 3, n)) to the covariance (3, 3, n); its diagonal is also the
    ``contribution`` (n, 3)."""
    for i, j in _PAIRS:
        v = np.einsum("rn,rn->n", a[:, i], a[:, j])
        out_cov[i, j] += v
        if i == j:
            contribution[:, i] = v


def propagate(model: ArmModel, p, q, wrench=None, aux: AuxData | None = None, *,
              parameters: ParameterCovariance | None = None, inputs: InputUncertainty,
              threads: int | None = None, chunk: int = 8192, systematic: bool = False) -> Propagation:
    """Linear propagation to the corrected ball centres of N points (see the module docstring).

    Args:
        model: the arm model (every effect applied); p: its full parameter vector [SI] (None: zeros).
        q: (N, J) encoder readings [rad] (prismatic joints [m]); wrench: (N, 3) or (N, 6) measured wrench
            (probe frame) or None.
        aux: per-point temperature / joint torques when the model's effects need them.
        parameters: the covariance of named parameters (None: the parameters are taken as exact).
        inputs: :func:`default_inputs`.
        systematic: also keep :attr:`Propagation.systematic` (for features fitted to several points,
            whose shared errors do not average out).
    """
    return Propagator(model, parameters, inputs)(p, q, wrench, aux, threads=threads, chunk=chunk,
                                                 systematic=systematic)


class Propagator:
    """:func:`propagate` for one model, parameter covariance and input uncertainties, its plan (the covariance's
    factor, the directions of the Jacobian, the stacked matrix) made once, when it is built: for many calls on the
    same objects (a live session propagates each point alone). The plan is this object's own state, read only once
    built: models, covariances or inputs used alternately, in one thread or several, each have their own (a
    module-wide cache of the last plan, found by the objects' identity, served a covariance changed in place with
    the plan of its old values)."""

    def __init__(self, model: ArmModel, parameters: ParameterCovariance | None, inputs: InputUncertainty):
        self.model, self.parameters, self.inputs = model, parameters, inputs
        self._plan = _make_plan(model, parameters, inputs, model.desc.n_joints)

    def __call__(self, p, q, wrench=None, aux: AuxData | None = None, *, threads: int | None = None,
                 chunk: int = 8192, systematic: bool = False) -> Propagation:
        """:func:`propagate` of the points ``q`` (with ``wrench``, ``aux``) at the parameters ``p``."""
        model, parameters, inputs, plan = self.model, self.parameters, self.inputs, self._plan
        q, w, aux = _prepare(model, q, wrench, aux)
        n = len(q)
        spec = model.spec
        p = np.zeros(spec.size) if p is None else np.asarray(p, dtype=float)
        if p.shape != (spec.size,):
            raise ValueError(f"p has shape {p.shape}, expected ({spec.size},)")
        # the model discrepancy at each pose, once for all chunks (its distance from the training poses is blocked)
        growing, dist, sd_disc = inputs.growing, None, np.full(n, inputs.discrepancy)
        if growing is not None:
            dist, sd_disc = growing.at(model.desc, q)
        span = plan.spans["parameters"]
        npar = span.stop - span.start       # the rows of the covariance's factor (fewer than the names when singular)
        cov = np.empty((n, 3, 3))
        contrib = {k: np.zeros((n, 3)) for k in CONTRIBUTIONS}
        centres = np.empty((n, 3))
        sys_rows = np.zeros((n, npar + 3, 3)) if systematic else None

        def work(s: int) -> None:
            e = min(s + chunk, n)
            cen, g, mmat, per_point = _chunk_jacobian(model, plan, p, q[s:e], w[s:e], aux.select(slice(s, e)))
            centres[s:e] = cen
            b = plan.s_mat @ mmat
            gf = g.reshape(g.shape[0], -1)
            pp = np.stack([per_point[k] for k in per_point]).reshape(len(per_point), -1) if per_point else None
            cv = np.zeros((3, 3, e - s))
            for name, sl in plan.spans.items():
                blk = b[sl]
                if not blk.shape[0]:
                    continue
                nz = np.flatnonzero(np.any(blk != 0, axis=0))
                a = blk[:, nz] @ gf[nz]
                if pp is not None:
                    a += plan.s_mat[sl][:, list(per_point)] @ pp
                a = a.reshape(len(blk), 3, e - s)
                if sys_rows is not None and name == "parameters":
                    sys_rows[s:e, :npar] = a.transpose(2, 0, 1)
                _add_squares(a, cv, contrib[name][s:e])
            if plan.use_compliance:
                a = g[plan.comp_cols] * inputs.compliance[:, None, None]
                if sys_rows is not None:
                    sys_rows[s:e, npar:] = a.transpose(2, 0, 1)
                _add_squares(a, cv, contrib["compliance"][s:e])
            for name, sd in (("probing", np.full(e - s, inputs.probing)), ("model discrepancy", sd_disc[s:e])):
                for i in range(3):
                    cv[i, i] += sd ** 2
                contrib[name][s:e] = sd[:, None] ** 2
            for i, j in _PAIRS:
                cov[s:e, i, j] = cv[i, j]
                cov[s:e, j, i] = cv[i, j]

        # the products are thin (tens x chunk): one BLAS thread each; more spin-wait on a busy machine (a few points'
        # products are below BLAS's own threshold for threads: setting the limit would cost more than them)
        with blas_threads(1 if n > _FEW else None):
            run_chunks(work, n, chunk, threads)
        sources = dict(inputs.sources)
        sources["parameters"] = "none (parameters taken as exact)" if parameters is None else parameters.source
        if dist is not None:
            sources["model discrepancy"] += beyond_note(dist)
        if _compliance_covered(tuple(() if parameters is None else parameters.names)):
            sources["compliance"] = "in the parameter covariance (calibrated)"
        return Propagation(centres, cov, contrib, sources, sys_rows)


def monte_carlo(model: ArmModel, p, q, wrench=None, aux: AuxData | None = None, *,
                parameters: ParameterCovariance | None = None, inputs: InputUncertainty, samples: int = 1000,
                seed: int = 0, progress: bool = True) -> Propagation:
    """The covariance of the corrected centres by sampling the inputs of :func:`propagate`: the
    parameters from their covariance (normal), each encoder reading uniformly within +-sqrt(3) u
    (its quantisation), the wrench and the compliances normal, the probing scatter normal.
    ``contributions`` is empty (the samples do not separate them). ``progress``: a progress display with
    the time left (:class:`arm_model.log.Progress`, shown when logging is configured for INFO: a
    million samples take minutes)."""
    if samples < 2:
        raise ValueError(f"samples must be at least 2, got {samples}")
    q, w, aux = _prepare(model, q, wrench, aux)
    n, nj = q.shape
    spec = model.spec
    p = np.zeros(spec.size) if p is None else np.asarray(p, dtype=float)
    pnames = () if parameters is None else tuple(parameters.names)
    pidx = np.array([spec.index(nm) for nm in pnames], dtype=int)
    lfac = parameters.factor() if parameters is not None and len(pnames) else np.zeros((0, 0))
    comp_idx = [spec.index(f"probe.compliance_{a}") for a in "xyz"]
    use_compliance = not _compliance_covered(pnames) and np.any(inputs.compliance > 0)
    u_w = np.concatenate([inputs.force, inputs.torque])
    rng = np.random.default_rng(seed)
    nominal = model.ball_centres(q, w if wrench is not None else None, p, aux)
    s1 = np.zeros((n, 3))
    s2 = np.zeros((n, 3, 3))
    half = math.sqrt(3.0) * inputs.encoder
    sd_disc = inputs.discrepancy_sd(model.desc, q)
    bar = Progress(samples, f"Monte Carlo, {n} point{'s' * (n != 1)}: samples", logger=log, enabled=progress,
                   estimate=True)
    step = max(1, samples // 1000)            # the display updated a thousand times at most
    for k in range(samples):
        if k and k % step == 0:
            bar.update(step)
        ps = p.copy()
        if len(pidx):
            ps[pidx] += lfac @ rng.standard_normal(lfac.shape[1])
        if use_compliance:
            ps[comp_idx] += inputs.compliance * rng.standard_normal(3)
        qs = q + rng.uniform(-1.0, 1.0, q.shape) * half
        ws = w + rng.standard_normal(w.shape) * u_w if wrench is not None else None
        d = model.ball_centres(qs, ws, ps, aux) - nominal
        for sd in (inputs.probing, sd_disc):
            if np.any(sd > 0):
                d += np.reshape(sd, (-1, 1)) * rng.standard_normal(d.shape)
        s1 += d
        s2 += d[:, :, None] * d[:, None, :]
    bar.update(samples - bar.done)
    mean = s1 / samples
    cov = (s2 - samples * mean[:, :, None] * mean[:, None, :]) / (samples - 1)
    sources = dict(inputs.sources)
    sources["parameters"] = "none (parameters taken as exact)" if parameters is None else parameters.source
    return Propagation(nominal, cov, {}, sources | {"method": f"Monte Carlo, {samples} samples, seed {seed}"})
