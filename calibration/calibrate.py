"""``calibrate(model, data, FitOptions(...)) -> CalibrationResult``: the whole fit, checked at each step.

The options are one frozen :class:`~calibration.options.FitOptions`; the stages below are named functions
(:func:`_setup`, :func:`_solve`, :func:`_result`; the prior's scales and the noise :func:`_evidence`, the
noise without a prior :func:`reweighted`, the outlier rounds :func:`_without_outliers`).

1. Free set: names or glob patterns over ``model.spec`` (the rest held at ``values``, default 0).
2. Nuisance start: algebraic fits of every feature, polished with the parameters held.
3. Identifiability at the start (:mod:`calibration.identifiability`): the reduced Jacobian, with the
   rigid motions of the base frame (exact symmetries of artefact residuals, and of reference points
   when ``T_ref_base`` is fitted) projected out; one parameter of every exact dependence is held and
   listed with its combination (the base parameters; ``on_unidentifiable="fix"``) or the fit stops with the
   list (``"stop"``).
4. Levenberg-Marquardt (:mod:`calibration.solver`), exact CasADi Jacobians, checked exit status, damped
   restarts, with the Gaussian prior of :mod:`calibration.prior` (default): the maximum a posteriori
   estimate; compliances held at their bound 0 when the data pull them below.
5. Identifiability again at the solution (a new deficiency is held and the fit repeated).
6. With ``prior_scale="evidence"`` (default): the prior's group scales and, with ``weights_from_data``, the
   noise of each row group estimated together by the evidence (:func:`_evidence`).
7. Covariance: the posterior ``(J_red^T J_red / s0^2 + prior precision)^-1`` of the free parameters
   (without a prior ``s0^2 (J_red^T J_red)^-1``), ``s0^2`` the residual variance factor ``2 cost / dof``
   (``covariance="residual"``) or 1 (``"stated"``); standard uncertainties, correlations and each
   parameter's state (free / prior-dominated / fixed / held) by name.
8. Outliers: standardized residuals ``r_w / (s_rob sqrt(1 - h))`` (``h`` the leverage, ``s_rob`` the robust
   scale of the row's observation group, :func:`standardized_residuals`) beyond ``outlier_threshold`` are
   reported with measurement, feature and file line; they are kept unless ``drop_outliers`` (then dropped,
   worst first, and refitted).
"""
from __future__ import annotations

import fnmatch
import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.sparse as sp

from arm_model import InputError, NumericalError
from arm_model.model import ArmModel
from arm_model.tracker import Tracker
from arm_model.units import STATED_SIGMA_M

from .data import CalibrationData, Weights
from .discrepancy import Discrepancy, deletion_shift, group_deletions, model_discrepancy
from .identifiability import (
    Combination,
    Identifiability,
    NuisanceProjection,
    analyse,
    compress_rows,
    point_noise,
    prior_scales,
    reduced_jacobian,
    weakly_determined,
)
from .options import FitOptions
from .prior import (
    GEOMETRY_GROUPS,
    MAX_SCALE_U,
    PRIOR_DOMINATED,
    PriorSpec,
    prior_only,
    prior_spec,
    scale_precision,
    scale_step,
    secant_gains,
    uniform_scale,
    update_scales,
    variance_ratio,
)
from .problem import Problem
from .region import RegionEffect, region_effect
from .schur import BlockNormal
from .solver import Prior, blas_threads, levenberg_marquardt

__all__ = ["FixedParameter", "Outlier", "CalibrationResult", "calibrate", "resolve_parameters",
           "default_free", "rigid_gauge", "display_unit", "blas_threads", "identify", "variance_components",
           "reweighted", "MIN_REDUNDANCY", "row_groups", "row_kinds", "kind_groups", "standardized_residuals",
           "grouped_standardized", "FitOptions", "evidence_scale", "nominal_baseline", "tracker_only",
           "default_effects", "gravity_compliance", "with_assumed_masses", "ASSUMED_DENSITY"]


def display_unit(unit: str) -> tuple[str, float]:
    """User-facing unit and factor from SI: m -> um, rad -> deg, m/N -> um/N, others unchanged."""
    return {"m": ("um", 1e6), "rad": ("deg", 180.0 / math.pi), "m/N": ("um/N", 1e6)}.get(unit, (unit, 1.0))


@dataclass(frozen=True)
class FixedParameter:
    """A parameter held fixed by the identifiability analysis: its value [SI], why, and the
    combination with the free parameters that the data cannot see."""
    name: str
    value: float
    reason: str
    combination: Combination | None = None
    stage: str = "start"
    #: held at its lower bound: the value [SI] the data pulled it to (the fit without the bound) and that value's
    #: standard uncertainty [SI] (None otherwise)
    pulled: tuple[float, float] | None = None

    def to_dict(self) -> dict:
        return {"name": self.name, "value": self.value, "reason": self.reason, "stage": self.stage,
                "combination": None if self.combination is None else self.combination.text()}


@dataclass(frozen=True)
class Outlier:
    """A point (or distance) whose standardized residual exceeds the threshold."""
    kind: str
    measurement: str
    feature: str
    point: int | None          # index into the data's points (None for a distance)
    line: int | None           # line in the points file
    standardized: float
    residual: float            # [m]
    file: str | None = None    # the points file the point is in (None for a distance): a point is (file, line)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "measurement": self.measurement, "feature": self.feature, "point": self.point,
                "file": self.file, "line": self.line, "standardized": self.standardized,
                "residual_um": self.residual * 1e6}


def resolve_parameters(spec, patterns) -> list[int]:
    """Indices of the parameters of ``spec`` named by ``patterns`` (names or globs like ``j*.d``)."""
    out = []
    for pat in patterns:
        hits = [i for i, n in enumerate(spec.names) if fnmatch.fnmatchcase(n, pat)]
        if not hits:
            raise InputError(f"'{pat}' matches no parameter; known: {', '.join(spec.names)}")
        out += [i for i in hits if i not in out]
    return sorted(out)


def tracker_only(data: CalibrationData | None) -> bool:
    """Whether every point of ``data`` is a marker at an unknown offset seen by a tracker (a robot's motion-
    capture or laser-tracker campaign: no artefact feature)."""
    return data is not None and data.marker_offsets == "fit" and not np.any(data.points.feature != "")


def default_free(model: ArmModel, data: CalibrationData | None = None) -> list[str]:
    """Every joint-row error, the probe offset and every effect parameter (compliances only when named).
    On ``data`` whose only points are markers at unknown offsets (a tracker campaign), not the probe
    offset: the markers' offsets on the tip frame take its place (it would move every marker alike)."""
    drop = ("probe.compliance",) + (("probe.x", "probe.y", "probe.z") if tracker_only(data) else ())
    return [n for n in model.spec.names if not n.startswith(drop)]


def default_effects(model: ArmModel, data: CalibrationData | None = None) -> tuple:
    """The effects a default calibration (``calibrate``, ``close-loop``) adds to ``model``: the joint compliance
    under gravity (:func:`gravity_compliance`) when the model holds no effect yet and it is a robot whose links
    carry masses: a description read from a URDF, or any description seen by a tracker only
    (:func:`tracker_only`); else none. A robot held in postures bends under its own weight by an amount its
    geometry cannot represent, on every pose and every placement alike, so held-out poses of one placement
    cannot say what it is worth elsewhere: it is part of the model, not a per-campaign decision. The prior
    (10 mrad at most under each joint's RMS gravity torque, non-negative) keeps a compliance the data do not
    see at 0 (measured in docs/studies/calibration.md: on the shared TALOS campaign the held-out error falls on every
    split, the README's 1.37 -> 1.00 mm; on the shared Panda seats, trained on one placement, the other two's
    seat spread 2.04 -> 1.71 mm; on simulated robots without compliance it costs 1-10 %)."""
    if model.desc.convention != "urdf" and not tracker_only(data):
        return ()
    return gravity_compliance(model)


#: [kg/m] linear density of the links :func:`with_assumed_masses` gives a URDF chain without masses. Its size does
#: not matter to the fit: each compliance's prior is a bound on the product compliance x RMS gravity torque
#: (:mod:`calibration.prior`), so only the torques' shape over the poses does; 10 kg/m is a robot arm's order
#: (a Panda about 16, a Kinova Gen3 about 7).
ASSUMED_DENSITY = 10.0


def with_assumed_masses(model: ArmModel) -> ArmModel | None:
    """``model`` with link masses assumed from the chain's geometry, for a robot read from a URDF whose arm carries
    no mass (shipped without ``<inertial>``, or with one on its tool alone: no mass on any joint but the last) and
    no effect yet; else None. Each moving joint's link is taken as a uniform rod from the joint's origin to the
    next joint's (the last joint's: to the tip point, a tool's given mass added to it),
    :data:`ASSUMED_DENSITY` kg/m, its centre of mass at the rod's middle: a robot held in postures still bends
    under its own weight, and without masses that weight is distributed along the arm as its links are. The
    compliances fitted are then per newton-metre of these torques (their product, the sag, is what the data
    determine). Measured on the shared Panda seats, trained on one placement, the other two's mean seat spread:
    its URDF without masses 2.04 mm, with these masses 1.78 mm, with the published masses 1.74 mm; with a 0.2 kg
    tool the only mass, the compliances under the tool's torques alone 2.85 mm (docs/calibration.md)."""
    desc = model.desc
    if model.effects or desc.convention != "urdf" or any(j.mass > 0 for j in desc.joints[:-1]):
        return None
    ends = [(j.origin or (0.0,) * 6)[:3] for j in desc.joints[1:]] + [desc.probe.p_last]   # in each joint's frame
    rows = []
    for j, e in zip(desc.joints, ends, strict=True):
        rod = ASSUMED_DENSITY * float(np.linalg.norm(e))
        mass = rod + j.mass                                          # (a tool's given mass added to its link's rod)
        com = (rod * np.asarray(e, dtype=float) / 2 + j.mass * np.asarray(j.com)) / mass if mass > 0 else np.zeros(3)
        rows.append(replace(j, mass=mass, com=tuple(float(v) for v in com)))
    out = ArmModel(replace(desc, joints=tuple(rows), masses_assumed=True), model.effects)
    return out if gravity_compliance(out) else None


def gravity_compliance(model: ArmModel) -> tuple:
    """``(JointCompliance(),)``, the compliance of every joint under the gravity torques of the description's
    masses (each with its physical prior, :mod:`calibration.prior`), for a model that holds no effect yet, whose
    links carry masses and at least one of whose joints is revolute (a joint mimicking another: the compliance of
    the master's column, under its torque with the follower's share); else ``()``. The base model of
    ``calibrate`` and ``close-loop`` for a robot (:func:`default_effects`)."""
    from arm_model.effects import JointCompliance
    if model.effects or not any(j.mass > 0 for j in model.desc.joints):
        return ()
    effect = JointCompliance()
    joints = effect.joint_indices(model.desc)
    return (effect,) if joints else ()  # no revolute joint (a gantry): a compliance of no parameter


def rigid_gauge(problem: Problem, p, free) -> np.ndarray:
    """Parameter directions (len(free), k) [SI] that move every ball centre by one rigid motion of the
    base frame (fitted to 1e-9 relative): exact symmetries of the residuals unless the reference
    transform is held at identity."""
    free = np.asarray(free, dtype=int)
    if not len(free) or any(it.kind == "reference" and it.n_theta == 0 for it in problem.instances):
        return np.zeros((len(free), 0))
    x, dx = problem.centres(p, True, free)
    a = dx.reshape(-1, len(free))
    fields = np.column_stack([np.tile(e, (len(x), 1)).ravel() for e in np.eye(3)]
                             + [np.cross(e, x).ravel() for e in np.eye(3)])
    sol = np.linalg.lstsq(a, fields, rcond=None)[0]
    ok = np.linalg.norm(a @ sol - fields, axis=0) <= 1e-9 * np.linalg.norm(fields, axis=0)
    return sol[:, ok]


def _input_variances(model: ArmModel, p, data: CalibrationData) -> dict:
    """The encoder and force-sensor variances [m^2] per axis that the propagation with the default inputs
    gives a probed point of ``data`` (its points on an artefact feature), averaged over the points and
    axes: the share of the residual scatter that these inputs account for (:meth:`CalibrationResult.
    probing_budget`)."""
    from arm_model.uncertainty import default_inputs, propagate
    pts = data.points
    sel = np.flatnonzero(pts.feature != "")
    if not len(sel):
        return {"encoders": 0.0, "force sensor": 0.0}
    inputs = default_inputs(model.desc, compliance=0.0, probing=0.0, has_force=pts.force is not None)
    if not (np.any(inputs.encoder > 0) or np.any(inputs.force > 0)):
        return {"encoders": 0.0, "force sensor": 0.0}
    sub = data.select(sel)
    out = propagate(model, p, sub.points.q, sub.wrench, sub.aux, inputs=inputs, threads=1)
    return {k: float(np.mean(out.contributions[k])) for k in ("encoders", "force sensor")}


@dataclass
class CalibrationResult:
    """Everything a fit produced, by name. Lengths [m], angles [rad] (SI) unless a key says otherwise.

    Attributes:
        model: the model fitted (its ``spec`` names every entry of ``p``).
        p: full parameter vector (free entries estimated, the others at their fixed values).
        free: names of the estimated parameters (order of ``cov``, ``u``, ``corr``).
        fixed: parameters held fixed by the identifiability analysis (with reasons, combinations).
        held: parameters the user did not free (at their given values).
        cov, u, corr: covariance [SI^2], standard uncertainties [SI], correlation matrix of ``free``.
        s0: residual standard deviation factor (weighted residual RMS with dof correction).
        covariance_source: how ``cov`` was scaled.
        status, iterations, evaluations, cost: solver outcome (cost = 0.5 sum r_w^2).
        n_residuals, n_nuisance, dof: problem size.
        identifiability: at the start; identifiability_final: at the solution.
        residuals: per-point table (``Problem.residual_table`` plus ``standardized``, ``measurement``,
            ``feature``, ``file`` and ``line``: a point is its file and line); instances: per artefact instance scalars;
            distances: per certified-length instance.
        tracker: the reference instrument's frame ``T_ref_base`` of each session and the markers' offsets
            on the tip frame (:class:`arm_model.tracker.Tracker`, with the standard uncertainties of their
            increments when fitted), or None without reference coordinates.
        outliers, dropped: outliers found (kept unless dropped); points dropped and refitted.
        data, weights: what was fitted.
    """
    model: ArmModel
    p: np.ndarray
    free: tuple
    fixed: tuple
    held: tuple
    cov: np.ndarray
    u: np.ndarray
    corr: np.ndarray
    s0: float
    covariance_source: str
    status: str
    iterations: int
    evaluations: int
    cost: float
    n_residuals: int
    n_nuisance: int
    dof: int
    identifiability: Identifiability
    identifiability_final: Identifiability
    residuals: dict
    instances: list
    distances: list
    tracker: Tracker | None
    outliers: list
    dropped: list
    data: CalibrationData
    weights: Weights
    reference_mode: str = "fit"
    unused: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    variance: list = field(default_factory=list)
    weights_history: list = field(default_factory=list)
    prior_scales: dict | None = None          # the Gaussian prior's scale of each group (None: no prior)
    prior_centre: np.ndarray | None = None    # its centre (full parameter vector [SI])
    log_evidence: float | None = None         # Laplace log evidence of the fit with its prior (weights as given)
    evidence: list = field(default_factory=list)   # the rounds of the evidence's estimate of scales and noise
    prior_sd: np.ndarray | None = None        # the prior's standard deviation of each free parameter [SI]
    prior_ratio: np.ndarray | None = None     # posterior / prior variance of each free parameter
    prior_groups: dict = field(default_factory=dict)   # per group: scale, parameters, effective parameters
    model_check: dict | None = None           # model_output.model_check of this fit, when refine_torques made it
    discrepancy: Discrepancy | None = None    # the error beyond the fit's own prediction away from its poses
    #: the parameters' random effect between regions of the joint space (calibration.region), in the covariance file
    region: RegionEffect | None = None
    options: FitOptions | None = None         # the options of the fit (calibrate's, as given)
    gross: list = field(default_factory=list)  # GrossError: points left out of the fit (indices into the data given)
    gross_kept: str | None = None             # why a gross-looking point was kept (the model's error), or None
    redundancy: float | None = None           # with a prior: rows less their share of the unknowns (s0's divisor)
    point_tests: dict | None = None           # every point's gross-error test (:func:`point_tests`), when asked
    #: {name: why} of the free parameters the data cannot tell from others, left to the prior alone
    #: (:func:`calibration.prior.prior_only`: prior-dominated, at its centre with its size)
    prior_only: dict = field(default_factory=dict)
    #: the arm's uniform scale in the prior's centre (``FitOptions.arm_scale`` "data"): value, u [1], set_by_data
    arm_scale: dict | None = None

    # -- access by name ----------------------------------------------------------------------------
    @property
    def names(self) -> tuple:
        return self.model.spec.names

    def value(self, name: str) -> float:
        return float(self.p[self.model.spec.index(name)])

    def probing_scatter(self) -> float | None:
        """The scatter of the contact itself per axis [m], net of the encoder and force-sensor noise:
        ``probing_budget()["net"]`` (None when no probed group could be estimated). This is what a model
        file carries and what :func:`arm_model.uncertainty.propagate` adds beside the propagated encoder
        and force-sensor contributions, so that they are not counted twice."""
        budget = self.probing_budget()
        return None if budget is None else budget["net"]

    def probing_budget(self) -> dict | None:
        """How the probing scatter [m, per axis] is estimated from the fit's residuals.

        ``gross``: the variance components of the probed point groups (seats, spheres, rings, cylinders,
        planes; not the reference instrument, not the lengths, :func:`variance_components`), pooled by their
        redundancy, ``sqrt(sum red_g est_g^2 / sum red_g)``. The residuals hold every random error of a
        point, so ``gross`` also holds the encoder and force-sensor noise, which the propagation adds on its
        own: ``encoders`` and ``force sensor`` are their standard uncertainties per axis (RMS over the
        probed points and axes) propagated through the fitted model with the default inputs
        (:func:`arm_model.uncertainty.default_inputs`: the description's encoder resolution / sqrt(12), the
        force sensor's uncertainty when the points carry forces), and
        ``net = sqrt(max(gross^2 - encoders^2 - force_sensor^2, 0))``. ``floored`` is True when the
        propagated inputs alone exceed the residual scatter (their stated uncertainties are larger than
        what this campaign shows; ``net`` is then 0). None when no probed group could be estimated."""
        b = self._probing_budget
        return None if b is None else dict(b)

    @functools.cached_property
    def _probing_budget(self) -> dict | None:
        # the propagation over every probed point runs once a result: the console, the model file and
        # summary.json each ask for the budget
        groups = [v for v in self.variance if v["estimated"] and v["group"] not in ("reference", "length")
                  and v.get("estimate_um") is not None and v["redundancy"] > 0]
        if not groups:
            return None
        red = np.array([v["redundancy"] for v in groups])
        est = np.array([v["estimate_um"] for v in groups]) * 1e-6
        gross = float(np.sqrt(np.sum(red * est ** 2) / np.sum(red)))
        var = _input_variances(self.model, self.p, self.data)
        net2 = gross ** 2 - var["encoders"] - var["force sensor"]
        return {"gross": gross, "encoders": math.sqrt(var["encoders"]), "force sensor": math.sqrt(var["force sensor"]),
                "net": math.sqrt(max(net2, 0.0)), "floored": bool(net2 <= 0.0)}

    def _budget_um(self) -> dict | None:
        b = self.probing_budget()
        return None if b is None else {"gross_um": b["gross"] * 1e6, "encoders_um": b["encoders"] * 1e6,
                                       "force_sensor_um": b["force sensor"] * 1e6, "net_um": b["net"] * 1e6,
                                       "floored": b["floored"]}

    def uncertainty(self, name: str) -> float:
        """Standard uncertainty [SI] of a free parameter (0 for a fixed or held one)."""
        return float(self.u[self.free.index(name)]) if name in self.free else 0.0

    def state(self, name: str) -> str:
        """``free`` (estimated, the data dominate), ``prior-dominated`` (estimated, its posterior variance at
        least :data:`calibration.prior.PRIOR_DOMINATED` of its prior's: the data add no more than the prior),
        ``fixed`` (held by the rank test or at a bound, see ``fixed``) or ``held`` (not freed by the user)."""
        if name in self.free:
            k = self.free.index(name)
            ratio = None if self.prior_ratio is None else float(self.prior_ratio[k])
            return "prior-dominated" if ratio is not None and ratio >= PRIOR_DOMINATED else "free"
        return "fixed" if name in {f.name for f in self.fixed} else "held"

    def parameter_rows(self) -> list[dict]:
        """One row a parameter: name, SI unit, value, u, state (:meth:`state`), the prior's standard deviation
        and the posterior/prior variance ratio (estimated parameters with a prior), display values."""
        rows = []
        for i, (n, unit) in enumerate(zip(self.model.spec.names, self.model.spec.units, strict=True)):
            du, fac = display_unit(unit)
            u = self.uncertainty(n)
            k = self.free.index(n) if n in self.free else None
            prior_u = None if k is None or self.prior_sd is None else float(self.prior_sd[k])
            ratio = None if k is None or self.prior_ratio is None else float(self.prior_ratio[k])
            rows.append({"name": n, "unit": unit, "value": float(self.p[i]), "u": u, "state": self.state(n),
                         "prior_u": prior_u, "prior_ratio": ratio, "display_unit": du,
                         "display_value": float(self.p[i]) * fac, "display_u": u * fac,
                         "display_prior_u": None if prior_u is None else prior_u * fac})
        return rows

    def described(self):
        """The calibrated description (base errors folded in; effect parameters are not representable)."""
        return self.model.described(self.p)

    def equivalent(self, p_other) -> np.ndarray:
        """``p_other`` (e.g. a simulation's truth) moved along the unidentifiable combinations so
        that the fixed parameters take their fixed values: what this fit can estimate of it."""
        p = np.array(p_other, dtype=float)
        spec = self.model.spec
        for f in self.fixed:
            if f.combination is None:
                continue
            shift = p[spec.index(f.name)] - f.value
            for name, coef in f.combination.terms:
                p[spec.index(name)] -= shift * coef
        return p

    # -- held-out data -----------------------------------------------------------------------------
    def predict(self, data: CalibrationData) -> dict:
        """Residuals on other data with the fitted parameters (features re-fitted, nothing else):
        the per-point table of ``Problem.residual_table`` and the weighted RMS."""
        prob = Problem(self.model, data, self.weights, [], reference=self.reference_mode)
        st = levenberg_marquardt(prob, self.p, prob.initial_states(self.p)).states
        table = prob.residual_table(self.p, st)
        ev = prob.evaluate(self.p, st, jac=False)
        table["rms_weighted"] = float(np.sqrt(np.mean(ev.r ** 2)))
        table["measurement"] = data.points.measurement[table["point"]]
        table["feature"] = data.points.feature[table["point"]]
        return table

    def validate(self, data: CalibrationData):
        """:class:`calibration.validation.Validation` of the fitted parameters on ``data``."""
        from .validation import validate
        return validate(self.model, self.p, data, self.weights, self.reference_mode)

    def compare(self, data: CalibrationData, p_before=None) -> list[dict]:
        """Before/after table on ``data``: ``p_before`` (default the nominal, zeros) vs the fit."""
        from .validation import before_after
        before = np.zeros(self.model.spec.size) if p_before is None else p_before
        return before_after(self.model, before, self.p, data, self.weights, self.reference_mode)

    def pooled_groups(self) -> list[str]:
        """The prior's groups that share one scale (``FitOptions.prior_groups="pooled"``), in this fit."""
        if self.prior_scales is None or self.options is None or self.options.prior_groups != "pooled":
            return []
        return [g for g in GEOMETRY_GROUPS if g in self.prior_scales]

    def reference_frame(self) -> dict | None:
        """JSON-ready reference instrument's frames ``T_ref_base`` and markers' offsets, or None without them."""
        if self.tracker is None:
            return None
        return {**self.tracker.to_dict(), "fitted": self.reference_mode == "fit",
                "marker_offsets": self.data.marker_offsets}

    def weights_dict(self) -> dict:
        """The noise the fit weighted its rows by: the standard uncertainties [um] and each row group's factor on
        them (``factors``); ``from_data``: the factors estimated from the residuals (``--weights data``);
        ``defaulted``: those of "probe" and "reference" nobody stated (their value the starting default,
        ``--sigma-*-um`` not given). A default no row of the fit used (``reference_um`` without reference
        coordinates) is null: nothing resolved it."""
        w = self.weights
        ref = self.data.reference
        used = {"probe": True, "reference": ref is not None and bool(np.isfinite(ref).all(axis=1).any())}
        um = {k: None if k in w.defaulted and not used[k] else getattr(w, k) * 1e6 for k in used}
        return {"probe_um": um["probe"], "reference_um": um["reference"],
                "length_um": None if w.length is None else w.length * 1e6,
                "factors": dict(w.factors), "from_data": bool(self.weights_history), "defaulted": list(w.defaulted)}

    def to_dict(self) -> dict:
        """JSON-ready summary (SI values, plus display units in the parameter rows)."""
        return {
            "status": self.status, "iterations": self.iterations, "evaluations": self.evaluations,
            "cost": self.cost, "s0": self.s0, "covariance_source": self.covariance_source,
            **self.data.counts(), "n_residuals": self.n_residuals, "n_nuisance": self.n_nuisance,
            "dof": self.dof, "redundancy": self.redundancy, "parameters": self.parameter_rows(),
            "free": list(self.free),
            "fixed": [f.to_dict() for f in self.fixed], "held": list(self.held),
            "correlation": {"names": list(self.free), "matrix": self.corr.tolist()},
            "identifiability_start": self.identifiability.to_dict(),
            "identifiability_final": self.identifiability_final.to_dict(),
            "reference_frame": self.reference_frame(),
            "weights": self.weights_dict(),
            "variance_components": self.variance, "weights_history": self.weights_history,
            "probing_scatter": self._budget_um(),
            "model_discrepancy": None if self.discrepancy is None else self.discrepancy.to_dict(),
            "region_effect": None if self.region is None else self.region.to_dict(),
            "prior": None if self.prior_scales is None else {
                "scales": dict(self.prior_scales), "groups": self.prior_groups, "log_evidence": self.log_evidence,
                "prior_dominated_ratio": PRIOR_DOMINATED, "evidence_rounds": self.evidence,
                "prior_dominated": [n for n in self.free if self.state(n) == "prior-dominated"],
                "prior_only": dict(self.prior_only), "arm_scale": self.arm_scale, "pooled": self.pooled_groups()},
            "outliers": [o.to_dict() for o in self.outliers], "dropped": [o.to_dict() for o in self.dropped],
            "gross_errors_removed": [g.to_dict() for g in self.gross], "gross_kept": self.gross_kept,
            "instances": self.instances, "distances": self.distances,
            "unused_points": [int(i) for i in self.unused],
        }


def identify(problem: Problem, p, states, candidates, options: FitOptions = FitOptions(), *,
             stage: str = "start"):
    """Which of the ``candidates`` (indices into ``problem.model.spec``) the data identify at ``p`` and
    ``states``: ``(kept indices, [FixedParameter], Identifiability)``.

    Two tests, in order: linear dependence (SVD rank of the reduced Jacobian with the base frame's rigid
    motions projected out; :func:`~calibration.identifiability.keep_choice`, columns scaled by the plausible error
    sizes of :func:`~calibration.identifiability.prior_scales`, chooses which to keep: of two equivalent
    parameters the one whose plausible error moves the data more is kept, an exact tie going to the later one
    along the chain (:func:`hold_keys`), so that the choice depends neither on rounding, nor on the parameters'
    order, nor on unknowns added that the data do not need),
    then practical resolution (``options.min_resolution``,
    :func:`~calibration.identifiability.weakly_determined`). With ``options.on_unidentifiable == "stop"``:
    raise :class:`NumericalError` with the list instead of holding them.
    """
    model = problem.model
    spec = model.spec
    stop = options.on_unidentifiable == "stop"
    kept = list(candidates)
    prob = problem.with_free(kept)
    ev = prob.evaluate(p, states)
    gauge = rigid_gauge(prob, p, kept)
    jred = reduced_jacobian(ev.jp, ev.jt)
    names = [spec.names[i] for i in kept]
    sizes = functools.partial(prior_scales, model, priors=options.priors, noise=point_noise(problem),
                              length=options.prior_length)
    idf = analyse(jred, ev.jp, names, options.rank_tol, sizes(names), gauge=gauge, tie_key=hold_keys(model, kept))
    fixed = []
    if idf.dependent:
        if stop:
            lines = [f"  {k}: {c.text()}" for k, c in idf.combinations.items()]
            raise NumericalError(f"{len(idf.dependent)} parameter combination(s) the data cannot identify "
                                 f"({stage}; rank {idf.rank} of {len(kept)}, rank_tol {options.rank_tol:g}):\n"
                                 + "\n".join(lines) + "\nhold these parameters (--hold) or let them be held and listed "
                                 "(--on-unidentifiable fix, FitOptions.on_unidentifiable='fix')")
        for name in idf.dependent:
            fixed.append(FixedParameter(name, float(p[spec.index(name)]), _dependent_reason(idf, name),
                                        idf.combinations[name], stage))
        kept = [i for i in kept if spec.names[i] not in idf.dependent]
    if options.min_resolution is not None and kept:
        weak = _weak(model, jred, idf, kept, sizes, options.min_resolution)
        if weak and stop:
            raise NumericalError("parameters the data resolve to worse than "
                                 f"{options.min_resolution:g} of a plausible size ({stage}): "
                                 + ", ".join(f"{n} (u ~ {u:.3g} {spec.units[spec.index(n)]})" for n, u, _ in weak)
                                 + "\nhold them (--hold) or let them be held and listed (--on-unidentifiable fix, "
                                 "FitOptions.on_unidentifiable='fix')")
        for name, u, comb in weak:
            du, fac = display_unit(spec.units[spec.index(name)])
            fixed.append(FixedParameter(name, float(p[spec.index(name)]),
                                        f"weakly determined: the data would resolve it only to u ~ {u * fac:.3g}"
                                        f"{'' if du == '1' else ' ' + du}, "
                                        f"more than {options.min_resolution:g} of a plausible size; its effect is "
                                        "below the noise", comb, stage))
        kept = [i for i in kept if spec.names[i] not in {w[0] for w in weak}]
    return kept, fixed, idf


def hold_keys(model: ArmModel, indices) -> list[tuple]:
    """The tie keys of :func:`~calibration.identifiability.keep_choice` for the spec's parameters ``indices``: a
    description's parameter by its place along the chain (the later kept), then an effect's by its name, so
    that effects added, or given in another order, change no tie between the description's parameters."""
    spec = model.spec
    return [(0, i, "") if i < model.base_size else (1, 0, spec.names[i]) for i in indices]


def _dependent_reason(idf: Identifiability, name: str) -> str:
    """Why a parameter of ``idf.dependent`` is held."""
    comb = idf.combinations[name]
    if name in idf.no_effect:
        return "no effect on the data (its Jacobian column is zero)"
    if len(comb.terms) == 1 and name in idf.gauge:
        return "a rigid motion of the base frame: not observable from these data"
    if len(comb.terms) == 1:
        return ("absorbed by the nuisance unknowns (the artefacts' centres, axes and transforms, the reference "
                "instrument's frames, the markers' offsets)")
    return "not separable from the free parameters: " + comb.text()


def _weak(model: ArmModel, jred, idf: Identifiability, kept, sizes, min_resolution: float) -> list:
    """The parameters of ``kept`` held for being weakly determined (:func:`weakly_determined`)."""
    spec = model.spec
    names = [spec.names[i] for i in kept]
    sel = [idf.names.index(n) for n in names]
    # only the description's parameters are held for being weak: an effect's parameters were asked for
    # (an --effect, a loop candidate) and are estimated with their uncertainty (a joint compliance seen
    # through one plate placement is resolved to tens of percent, and holding it at zero would keep
    # its whole signature in the geometry)
    # (an effect of the geometry kind, an encoder's eccentricity or gain, is held as the description's
    # parameters are: left free, a weak one wanders at each fit and the identifiable set never settles)
    geometric = {k for e, sl in model.effect_slices() if e.held_when_weak for k in range(sl.start, sl.stop)}
    return [w for w in weakly_determined(jred[:, sel], names, sizes(names), min_resolution)
            if spec.index(w[0]) < model.base_size or spec.index(w[0]) in geometric]


def calibrate(model: ArmModel, data: CalibrationData, options: FitOptions = FitOptions()) -> CalibrationResult:
    """Identify the parameters ``options.free`` of ``model`` from ``data``.

    Args:
        model: the arm model; p = 0 is its description (parameters are errors).
        data: :class:`~calibration.data.CalibrationData` (``make_data``).
        options: :class:`~calibration.options.FitOptions`, among them:

            * ``prior_scale``: "evidence" (default): a Gaussian prior on every free parameter, centred on
              ``values`` (or ``prior_centre``), standard deviation its group's scale times its plausible
              error size (:mod:`calibration.prior`), the scales (and with ``weights_from_data`` the noise)
              chosen by the evidence (:func:`_evidence`): the maximum a posteriori estimate shrinks what
              the data resolve poorly instead of holding it; a number or a dict {group: scale}: those
              scales; None: no prior.
            * ``min_resolution``: without a prior only, hold parameters the data would resolve only to worse
              than this fraction of a plausible error size (:func:`~calibration.identifiability.
              prior_scales`); None (default) keeps every linearly independent parameter.
            * ``weights_from_data``: take ``weights`` as starting values only: estimate the noise of each
              row group from the fit's residuals and redundancy (:func:`variance_components`): jointly with
              the prior scales, or without a prior by :func:`reweighted`.
            * ``drop_outliers``: drop outlier points and refit, in rounds (:func:`_without_outliers`);
              they are listed in ``dropped`` (indices into ``data``) and ``data`` of the result holds the
              points kept.

    Raises:
        NumericalError: no convergence, too few residuals, or unidentifiable parameters with "stop".
        TypeError: an argument not of its type (a model file's path for ``model``, a dict for ``options``).
    """
    for name, value, kind, how in (("model", model, ArmModel, "arm_model.model.ArmModel(load_description(...))"),
                                   ("data", data, CalibrationData, "calibration.make_data(points, artefacts, model)"),
                                   ("options", options, FitOptions, "calibration.FitOptions(...)")):
        if not isinstance(value, kind):
            raise TypeError(f"calibrate: {name} must be a {kind.__name__} ({how}), got {type(value).__name__}")
    if options.prior_scale == "evidence":
        estimate = _evidence
    elif options.weights_from_data:
        estimate = reweighted
    else:
        estimate = _fit
    with blas_threads(options.blas):
        res = _without_outliers(model, data, options, estimate)
    res.options = options
    _check_plausible(res)
    return res


def _check_plausible(res: CalibrationResult) -> None:
    """A :class:`NumericalError` when a free parameter ended where no arm is: beyond the plausible range of its
    quantity (:func:`arm_model.units.implausible`, the table every reader refuses a value by; a model file with it
    could not be read back). That is the data failing to determine it (a direction they see only far below the
    noise, and no prior to hold it near its nominal value: ``--prior-scale off`` on one placement of a seat plate
    ran a joint compliance to 6.98 rad/(N m) and an angle to 1e15 deg), not a value to publish."""
    from arm_model.model_file import PARAM_QUANTITY
    from arm_model.units import implausible

    bad = []
    for n in res.free:
        i = res.model.spec.index(n)
        unit = res.model.spec.units[i]
        wrong = implausible(float(res.p[i]), PARAM_QUANTITY.get(unit, ""))
        if wrong:
            du, fac = display_unit(unit)
            bad.append(f"{n} = {res.p[i] * fac:.4g} {du} (+- {res.uncertainty(n) * fac:.2g})")
    if bad:
        raise NumericalError(
            f"the fit ended at values no arm has: {'; '.join(bad)}: not a result to publish (a "
            "direction the data see only far below the noise, along which the fit ran away, or data no arm of this "
            "model gives). Calibrate with the prior "
            "(--prior-scale evidence: a parameter the data cannot see stays near its nominal value), or hold "
            "it (--hold NAME), or let the resolution rule hold what the data resolve poorly (--min-resolution 0.1)")


#: rounds of outlier dropping before the fit gives up
DROP_ROUNDS = 10

#: at most this share of the points (and at least one) is left out as gross errors; more is the model's error
GROSS_SHARE = 0.05


@dataclass
class GrossError:
    """A point left out of the fit as a gross error: its outlier entry in the fit that had it
    (``outlier``), the critical value it exceeded (``threshold``) and its deletion residual (under the fit
    without it, [m])."""
    outlier: Outlier
    threshold: float
    residual: float

    def to_dict(self) -> dict:
        return {**self.outlier.to_dict(), "threshold": self.threshold, "deletion_residual_um": self.residual * 1e6}


def _without_outliers(model: ArmModel, data: CalibrationData, options: FitOptions, estimate) -> CalibrationResult:
    """``estimate(model, data, options)`` (:func:`_fit`, :func:`reweighted` or :func:`_evidence`) and, with
    ``options.drop_outliers``, the points and certified lengths whose gross-error test (:func:`point_tests`, the
    test the default leaves gross errors out by) is at ``options.outlier_threshold`` or beyond dropped (the worst
    of each measurement at half the worst statistic or more, :func:`_one_a_measurement`: a gross error also pulls
    its neighbours out, those go only if they stay out) and refitted, until none is left (at most
    :data:`DROP_ROUNDS` rounds; lengths only with ``options.outlier_lengths``); otherwise the gross errors left out
    (:func:`_without_gross`)."""
    if not options.drop_outliers:
        return _without_gross(model, data, options, estimate)
    index = np.arange(len(data))
    dropped: list[Outlier] = []
    limit = options.outlier_limit
    for k in range(DROP_ROUNDS + 1):
        res = estimate(model, data, options)
        cands = [c for c in _tested(res, options.outlier_threshold) if options.outlier_lengths or c.between is None]
        if not cands:
            res.dropped = dropped
            return res
        drop = [] if k == DROP_ROUNDS else _droppable(res.data, _one_a_measurement(cands, options.outlier_threshold))
        if limit is not None and (k == DROP_ROUNDS or drop):
            drop = drop[:limit - len(dropped)]
            if not drop:
                o = cands[0].outlier
                res.dropped = dropped
                res.gross_kept = (f"{o.measurement} {o.feature} line {o.line}: standardized {o.standardized:+.1f}, "
                                  f"kept: {len(dropped)} point(s) left out already (at most {limit}) or {DROP_ROUNDS} "
                                  "rounds done; more is an error of the model, not of the data")
                return res
        if k == DROP_ROUNDS:
            break
        if not drop:
            o = cands[0].outlier
            res.dropped = dropped
            res.gross_kept = (f"{o.measurement} {o.feature} line {o.line}: standardized {o.standardized:+.1f}, kept: "
                              "its feature needs it (no fewer points than its fit needs are left)")
            return res
        dropped += [c.given(index) for c in drop]
        data, index = _left_out(data, drop, index)
    raise NumericalError(f"outliers remain after {DROP_ROUNDS} rounds of dropping; check the data")


def _one_a_measurement(cands: list, level: float) -> list:
    """Of ``cands`` (:class:`_Tested`, the largest first), what one round of ``--drop-outliers`` drops: the worst,
    and those at ``level`` and at half its statistic or more, one a measurement and one length (the worst of each):
    a gross error pulls its own measurement's points and lengths with its feature's unknowns, and a length every
    other through the arm's scale, whose tests then stand high too (a ball bar's end moved along the bar: its
    length, the points of its spheres, the other bars' lengths), and the next round tests them without it."""
    worst = abs(cands[0].outlier.standardized)
    out: list = []
    for c in cands:
        if abs(c.outlier.standardized) >= max(level, 0.5 * worst) and not any(
                c.outlier.measurement == d.outlier.measurement or (c.between is not None and d.between is not None)
                for d in out):
            out.append(c)
    return out


def _droppable(data: CalibrationData, cands: list) -> list:
    """Of ``cands`` (:class:`_Tested`, in order), those that can be dropped together: every length, and a point
    while its feature instance keeps the fewest points its fit needs (:data:`~calibration.kinds.MIN_POINTS`)."""
    from .kinds import MIN_POINTS
    pts, out = data.points, []
    left: dict = {}
    for c in cands:
        o = c.outlier
        if c.between is None and pts.feature[o.point] != "":
            key = (pts.measurement[o.point], pts.feature[o.point])
            if key not in left:
                left[key] = int(np.sum((pts.measurement == key[0]) & (pts.feature == key[1])))
            if left[key] - 1 < MIN_POINTS.get(o.kind, (0, 0))[0]:
                continue
            left[key] -= 1
        out.append(c)
    return out


@dataclass(frozen=True)
class _Tested:
    """A point or a certified length whose gross-error test reached a level: its :class:`Outlier` (``standardized``
    the test's standardized equivalent, signed as its row of the largest standardized residual), and for a length
    the features it is between, its index among the fit's lengths and its certified length [m] (None for a
    point)."""
    outlier: Outlier
    between: tuple | None = None
    item: int | None = None
    certified: float | None = None

    def given(self, index: np.ndarray) -> Outlier:
        """The outlier with its point's index into the data given (``index``: of the data fitted)."""
        o = self.outlier
        return o if o.point is None else replace(o, point=int(index[o.point]))


def _left_out(data: CalibrationData, items: list, index: np.ndarray) -> tuple[CalibrationData, np.ndarray]:
    """``data`` without the points and certified lengths ``items`` (:class:`_Tested`), and ``index`` (the data
    given's index of each point) of the points kept."""
    for c in items:
        if c.between is not None:
            data = data.without_length(c.outlier.measurement, c.between)
    keep = np.setdiff1d(np.arange(len(data)), [c.outlier.point for c in items if c.between is None])
    return data.select(keep), index[keep]


def _without_gross(model: ArmModel, data: CalibrationData, options: FitOptions, estimate) -> CalibrationResult:
    """``estimate(model, data, options)`` with the gross errors left out, one at a time (data snooping):
    while the point or certified length of the largest gross-error test (:func:`point_tests`: its rows'
    group-deletion residual against the covariance the joint fit predicts for it, as a standardized residual of the
    same false-alarm rate) is at ``options.gross_threshold`` (and ``outlier_threshold``) or beyond, it is left out
    and the fit redone. Never more than :data:`GROSS_SHARE` of the points, nor a point its feature needs
    (:data:`~calibration.kinds.MIN_POINTS`, or one whose deletion leaves an unknown undetermined): past that the
    misfit is the model's, kept and said (``gross_kept``). ``options.gross_threshold`` None keeps every point;
    ``options.outlier_limit`` (not None) is the most points left out, ``options.outlier_lengths`` False leaves
    every certified length in (the closed loop's base fit, :mod:`calibration.loop.outliers`)."""
    res = estimate(model, data, options)
    if options.gross_threshold is None:
        return res
    k = max(options.gross_threshold, options.outlier_threshold)
    index = np.arange(len(data))
    gross: list[GrossError] = []
    limit = max(1, int(GROSS_SHARE * len(data))) if options.outlier_limit is None else options.outlier_limit
    share = f"{GROSS_SHARE:.0%} of them" if options.outlier_limit is None else "the most it may leave out"
    while (c := _gross_candidate(res, k, options.outlier_lengths)) is not None:
        o = c.outlier
        need = not _droppable(res.data, [c])          # its feature needs it
        fewer, kept = _left_out(res.data, [c], index)
        try:
            without = None if len(gross) >= limit or need else estimate(model, fewer, options)
        except NumericalError:
            without = None
        if without is None:
            where = f"{o.measurement} line {o.line}" if c.between is None else f"{o.measurement} length {o.feature}"
            res.gross_kept = (f"{where}: standardized {o.standardized:+.1f} (beyond {k:.2f}), "
                              f"kept: leaving out more than {limit} point(s) ({share}), a point its "
                              "feature needs, or one the fit cannot do without is an error of the model, not of the "
                              "data")
            break
        gross.append(GrossError(c.given(index), k, _deletion_residual(without, res.data, c)))
        index, res = kept, without
    res.gross = gross
    return res


def _tested(res: CalibrationResult, k: float) -> list[_Tested]:
    """The points and certified lengths of ``res`` whose gross-error test (``res.point_tests``) is at ``k`` or
    beyond, the largest first (:class:`_Tested`: ``standardized`` the test's standardized equivalent, signed as
    its row of the largest standardized residual, ``residual`` that row's)."""
    t = res.point_tests
    if t is None:
        return []
    tab, pts, out = res.residuals, res.data.points, []
    for i in np.flatnonzero(np.nan_to_num(t["sigma"]) >= k):
        pi = int(t["point"][i])
        rows = np.flatnonzero(tab["point"] == pi)
        row = int(rows[np.argmax(np.abs(tab["standardized"][rows]))])
        out.append(_Tested(Outlier(str(tab["kind"][row]), str(pts.measurement[pi]), str(pts.feature[pi]), pi,
                                   None if pts.lines is None else int(pts.lines[pi]),
                                   math.copysign(float(t["sigma"][i]), float(tab["standardized"][row])),
                                   float(tab["value"][row]), res.data.file_of(pi))))
    for i in np.flatnonzero(np.nan_to_num(t["length_sigma"]) >= k):
        d = res.distances[int(t["length"][i])]
        out.append(_Tested(Outlier("distance", d["measurement"], " - ".join(d["between"]), None, None,
                                   math.copysign(float(t["length_sigma"][i]), d["standardized"]), d["residual"]),
                           tuple(d["between"]), int(t["length"][i]), float(d["certified"])))
    return sorted(out, key=lambda c: -abs(c.outlier.standardized))


def _gross_candidate(res: CalibrationResult, k: float, lengths: bool = True) -> _Tested | None:
    """The point (or, with ``lengths``, certified length) of ``res`` whose gross-error test is the largest, if at
    ``k`` or beyond (:func:`_tested`)."""
    cands = [c for c in _tested(res, k) if lengths or c.between is None]
    return cands[0] if cands else None


def _test_groups(prob: Problem) -> tuple[np.ndarray, np.ndarray, list]:
    """(points, lengths, groups) of :func:`point_tests`: the data's points with residual rows, the rows of the
    certified lengths, and the rows of each (a point's together, in ``points`` order, then one a length)."""
    rp = prob.row_point
    rows = np.flatnonzero((prob.row_distance < 0) & (rp >= 0))
    rows = rows[np.argsort(rp[rows], kind="stable")]
    points, start = np.unique(rp[rows], return_index=True)
    lengths = np.flatnonzero(prob.row_distance >= 0)
    return points, lengths, (np.split(rows, start[1:]) if len(rows) else []) + [np.array([i]) for i in lengths]


def point_tests(prob: Problem, r: np.ndarray, factor: BlockNormal, leverage: np.ndarray, k: float,
                deletions: list | None = None) -> dict:
    """The gross-error test of every point and every certified length of a fit of ``prob`` (``r`` its weighted
    residuals, ``factor`` and ``leverage`` as :func:`~calibration.discrepancy.model_discrepancy` and
    :func:`_normal`): the point's residual rows ``O`` together (a seat's or a marker's three, a sphere's one, a
    point's reference rows with its feature's; a length's one) deleted from the joint fit (parameters, prior and
    every nuisance unknown: :func:`~calibration.discrepancy.group_deletions`), ``e_O = (I - H_OO)^-1 r_O`` with
    covariance ``s^2 (I - H_OO)^-1``; the statistic is its squared Mahalanobis norm ``T = r_O^T (I - H_OO)^-1 r_O
    / s^2``, chi-square with ``m = |O|`` degrees of freedom on clean Gaussian data, given as the standardized
    residual of the same false-alarm rate (:func:`sigma_equivalent`; for one row exactly ``|r| / (s sqrt(1 -
    h))``). ``s`` is the rows' robust scale (:func:`robust_scales`) among the residuals of the fit without the
    point (``r + js d_O``, the point's rows at their deletion residuals): a blunder that pulls a small session
    towards itself spreads into every residual and would otherwise inflate the scale it is judged by. The scale
    without the point is taken for the points at ``k / 2`` or beyond with the fit's own scale (below, a point
    would need to halve the median of every other residual by its own pull to reach ``k``).

    Returns {``point`` (n,) indices into the data, ``rows`` (n,) m, ``chi2`` (n,) T, ``sigma`` (n,) its
    standardized equivalent, ``deletion`` (n,) [m] the norm of the unweighted ``e_O``} and the same of the
    certified lengths, ``length`` (l,) their indices among the fit's lengths (``prob.distance_items``),
    ``length_chi2``, ``length_sigma``, ``length_deletion``; NaN for a point or length the fit cannot do without
    (deleting it leaves an unknown undetermined: a campaign's only length, when it alone sets the scale).
    ``deletions``: the groups' deletions already computed (:func:`_normal` with :func:`_test_groups`)."""
    points, lengths, groups = _test_groups(prob)
    kinds = row_kinds(prob)
    scale = robust_scales(r, leverage, kinds)
    m_rows = np.array([len(o) for o in groups], dtype=int)
    chi2, dele = np.full(len(groups), np.nan), np.full(len(groups), np.nan)
    tests = group_deletions(factor, r, groups) if deletions is None else deletions
    for i, (o, (e, m)) in enumerate(zip(groups, tests, strict=True)):
        if e is not None:
            w = r[o] / scale[o]
            chi2[i] = float(w @ m @ w)
            dele[i] = float(np.linalg.norm(prob.sigma[o] * e))
    sigma = sigma_equivalent(chi2, m_rows) if len(groups) else np.zeros(0)
    for i in np.flatnonzero(np.nan_to_num(sigma) >= 0.5 * k):
        o, (e, m) = groups[i], tests[i]
        h_without = leverage.copy()
        h_without[o] = 0.0
        w = r[o] / robust_scales(r + factor.j @ deletion_shift(factor, o, e), h_without, kinds)[o]
        chi2[i] = float(w @ m @ w)
        sigma[i] = sigma_equivalent(chi2[i], m_rows[i])
    n = len(points)
    return {"point": points, "rows": m_rows[:n], "chi2": chi2[:n], "deletion": dele[:n], "sigma": sigma[:n],
            "length": prob.row_distance[lengths], "length_chi2": chi2[n:], "length_deletion": dele[n:],
            "length_sigma": sigma[n:]}


def sigma_equivalent(chi2, rows):
    """The standardized residual ``k`` whose test on each of ``rows`` independent Gaussian rows flags a clean point
    as often as ``chi2`` on ``rows`` degrees of freedom: ``1 - (1 - 2 Phi(-k))^rows = P(chi2_rows >= chi2)``. So
    a point is a gross error at ``k`` at the false-alarm rate the row-by-row test of its largest standardized
    residual had at ``k``; for one row it is ``sqrt(chi2)``. Computed in logarithms: finite far in the tail.
    Scalars or arrays (NaN stays NaN)."""
    from scipy.special import gammaincc, gammaln, ndtri_exp
    m = np.asarray(rows, dtype=float)
    a, x = 0.5 * m, 0.5 * np.maximum(np.asarray(chi2, dtype=float), 0.0)
    p = gammaincc(a, x)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        exact = np.where(p < 1.0, np.log(-np.expm1(np.log1p(-p) / m)), 0.0)
        # alpha = p / rows to 1e-12 below; the upper incomplete gamma's asymptote where p underflows
        log_p = np.where(p > 0, np.log(p), (a - 1.0) * np.log(x) - x - gammaln(a))
        log_alpha = np.where(p > 1e-12, exact, log_p - np.log(m))
    k = -ndtri_exp(log_alpha - math.log(2.0))
    return float(k) if np.ndim(k) == 0 else k


def _deletion_residual(res: CalibrationResult, data: CalibrationData, c: _Tested) -> float:
    """The residual [m] of ``data``'s point or certified length ``c`` under ``res``, a fit without it: a point's
    with the fit's parameters held, the features and frames refitted on ``data``; a length's, the distance of the
    two centres that fit found (on their points alone) less the certified length."""
    if c.between is not None:
        centre = {it["feature"]: np.asarray(it["centre"]) for it in res.instances
                  if it["measurement"] == c.outlier.measurement and it["feature"] in c.between}
        certified = math.nan if c.certified is None else c.certified
        return float(np.linalg.norm(centre[c.between[0]] - centre[c.between[1]]) - certified)
    table = res.predict(data)
    return float(table["value"][int(np.flatnonzero(table["point"] == c.outlier.point)[0])])


@dataclass
class _Setup:
    """What a fit starts from: the problem over the candidate parameters, the given (``nominal``) and the
    starting (``p0``) parameter vectors [SI], the nuisance states fitted at ``p0``, the prior (None without
    one) with its groups and sizes (``spec``) and group scales, the hold rule's resolution, every parameter's
    lower bound [SI] (``lower``: :meth:`~arm_model.model.ArmModel.lower_bounds`, with a prior or without), and
    {spec index: why} of the candidates the data cannot tell from others (``prior_only``,
    :func:`calibration.prior.prior_only`: left to the prior, held without one)."""
    problem: Problem
    candidates: list
    nominal: np.ndarray
    p0: np.ndarray
    states: list
    prior: Prior | None
    min_resolution: float | None
    spec: PriorSpec | None = None
    scales: dict = field(default_factory=dict)
    lower: np.ndarray | None = None
    prior_only: dict = field(default_factory=dict)
    arm_scale: _ArmScale | None = None


@dataclass(frozen=True)
class _ArmScale:
    """The arm's uniform scale in the prior's centre (``centre = c0 + value * direction``, ``FitOptions.arm_scale``
    "data"): ``value`` and its standard uncertainty ``u`` [1], ``direction`` [SI] (full parameter vector, zero but on
    the free parameters: :func:`_scale_direction`), ``set``: whether the data set it (``u`` at most
    :data:`calibration.prior.MAX_SCALE_U`; else ``value`` is 0 and the prior's centre the given one)."""
    value: float
    u: float
    direction: np.ndarray
    set: bool
    start: float = 0.0

    def to_dict(self) -> dict:
        """``value``: the scale of the prior's centre from the description (``start``, the scale of the centre
        given, projected on the direction in the prior's metric, plus ``value``)."""
        return {"value": self.start + self.value, "u": self.u, "set_by_data": self.set, "max_u": MAX_SCALE_U}


def _prior_spec(model: ArmModel, data: CalibrationData, options: FitOptions) -> PriorSpec:
    """:func:`calibration.prior.prior_spec` with ``options.prior_length`` setting the size of a length error
    (and of an angle: 1 rad/m times it) when given."""
    priors = dict(options.priors or {})
    if options.prior_length is not None:
        spec = model.spec
        for i in range(model.base_size):
            n = spec.names[i]
            if not n.startswith("probe.") and spec.units[i] in ("m", "rad"):
                priors.setdefault(n, options.prior_length)        # [m], and [rad] at 1 rad/m
    return prior_spec(model, data, priors)


def _scales(options: FitOptions, groups) -> dict:
    """The group scales of ``options.prior_scale``: a dict as given (groups it lacks at 1), one factor for every
    group, or "evidence": 1 for every group (the start of :func:`_evidence`)."""
    ps = options.prior_scale
    if isinstance(ps, dict):
        return {g: float(ps.get(g, 1.0)) for g in dict.fromkeys(groups)}
    return {g: 1.0 if ps == "evidence" else float(ps) for g in dict.fromkeys(groups)}


def _setup(model: ArmModel, data: CalibrationData, options: FitOptions) -> _Setup:
    spec = model.spec
    cand = resolve_parameters(spec, default_free(model, data) if options.free is None else options.free)
    nominal = spec.vector(options.values or {})  # a held parameter's value (``start`` only warm-starts the free)
    p0 = nominal.copy()
    for name, v in (options.start or {}).items():
        p0[spec.index(name)] = v
    only = {i: why for i, why in prior_only(model, data).items() if i in cand}
    problem = Problem(model, data, options.weights, cand, reference=options.reference,
                      prior_only=sorted(only) if options.prior_scale is not None else [])
    states = levenberg_marquardt(problem.with_free([]), p0, problem.initial_states(p0),
                                 max_iter=options.max_iter).states
    problem.check_tracker(p0, states)        # frames and marker offsets the data cannot place: say so first
    if options.prior_scale is None:
        return _Setup(problem, cand, nominal, p0, states, None, options.min_resolution, lower=model.lower_bounds(),
                      prior_only=only)
    pspec = _prior_spec(model, data, options)
    scales = _scales(options, [pspec.group[i] for i in cand])
    centre = nominal.copy() if options.prior_centre is None else np.array(options.prior_centre, dtype=float)
    # the prior shrinks what the data resolve poorly: nothing is held for being weak
    return _Setup(problem, cand, nominal, p0, states, Prior(centre, pspec.sizes(scales)), None, pspec, scales,
                  pspec.lower, only)


#: the structural rank test (:func:`_structural`) evaluates about this many times as many rows as candidates
STRUCTURAL_ROWS = 4


def _structural(s: _Setup, kept, p, states) -> Problem | None:
    """With a prior, when the data have fewer degrees of freedom (rows less nuisance unknowns) than there are candidates
    (``kept``) with an effect on them at ``p`` and ``states`` (one without any, an artefact's drift where every
    measurement is one point, is held for that by either test and counts for neither: unknowns the data do not need
    change neither the test nor its poses), the same problem (the same instances: artefacts, frames, markers) over
    poses drawn across the data's joint ranges (each widened by a tenth, at least 0.05 rad or m; seeded), several
    times as many rows: its rank deficiencies are those of the chain and the kind of measurement (a base frame's
    rigid motion, a tool offset along a plane's normal), not those of too few poses. Those are the ones to hold;
    what the data are merely too few to separate stays free under the prior, prior-dominated where the data add
    nothing (a humanoid touching one table on 21 poses: 105 candidates, 18 data dimensions; held by the data's rank,
    the tool offset went and the held-out touches got worse than the nominal's). None otherwise."""
    prob = s.problem
    if s.prior is None or not kept:
        return None
    with_kept = prob.with_free(list(kept))
    n_nuis = sum(it.n_theta for it in with_kept.instances)
    norms = np.linalg.norm(with_kept.evaluate(p, states).jp, axis=0)
    n_seen = int(np.sum(norms > 1e-12 * max(float(norms.max()), 1e-300)))
    if prob.n_rows - n_nuis >= n_seen:
        return None
    data = prob.data
    q = data.points.q
    reps = int(math.ceil(STRUCTURAL_ROWS * n_seen / max(prob.n_rows, 1))) + 1
    rows = np.tile(np.arange(len(q)), reps)
    lo, hi = q.min(axis=0), q.max(axis=0)
    pad = np.maximum(0.1 * (hi - lo), 0.05)
    rich = data.select(rows)
    qr = np.random.default_rng(0).uniform(lo - pad, hi + pad, (len(rows), q.shape[1]))
    rich = replace(rich, points=replace(rich.points, q=qr))
    return Problem(prob.model, rich, prob.weights, list(prob.free), reference=prob.reference)


def _held(s: _Setup, p, states, kept, stage: str, options: FitOptions):
    """:func:`identify` over ``kept``: (kept, the new FixedParameters, Identifiability). A held parameter goes
    back to its given value (not a warm start's, not where a fit moved it along a direction the data do not
    see or see only below the noise: that value would be carried into every pose the model is used at);
    ``p`` is changed in place. With a prior and fewer data dimensions than candidates, the rank test is the
    structural one (:func:`_structural`). The prior-only parameters (``s.prior_only``) take no part in it: with a
    prior they stay estimated (the prior alone holds them), without one they are held with their reason."""
    only = [i for i in kept if i in s.prior_only]
    rest = [i for i in kept if i not in s.prior_only]
    problem = _structural(s, rest, p, states) or s.problem
    kept, new, idf = identify(problem, p, states, rest, replace(options, min_resolution=s.min_resolution),
                              stage=stage)
    spec = s.problem.model.spec
    if s.prior is not None:
        kept = sorted(kept + only)
    else:
        new += [FixedParameter(spec.names[i], 0.0, f"not seen by the data ({s.prior_only[i]}); held at its given value",
                               None, stage) for i in only]
    for k, f in enumerate(new):
        i = spec.index(f.name)
        p[i] = s.nominal[i]
        new[k] = replace(f, value=float(s.nominal[i]))
    return kept, new, idf


#: how the reason of a parameter held at its lower bound begins
AT_BOUND = "at its lower bound"
#: why a parameter has a lower bound, by unit (a compliance otherwise)
_BOUND_WHY = {"rad": "a joint's play cannot be negative"}


def _at_bounds(s: _Setup, p, kept, stage: str, u: dict | None = None):
    """The estimated parameters beyond their lower bound (a compliance that would be negative in total): held
    at the bound (``p`` changed in place), with or without a prior. ``u``: {spec index: standard uncertainty [SI]}
    at the fit without the bound (:func:`_solution_u`), of the value the data pulled each to
    (``FixedParameter.pulled``: whether the pull is significant, e.g. the loop's
    :func:`calibration.loop.decide.resolved`). Returns (kept, [FixedParameter])."""
    low = s.lower
    if low is None:
        return kept, []
    below = [i for i in kept if p[i] < low[i]]
    if not below:
        return kept, []
    spec = s.problem.model.spec
    fixed = []
    for i in below:
        du, fac = display_unit(spec.units[i])
        why = _BOUND_WHY.get(spec.units[i], "a compliance cannot be negative")
        fixed.append(FixedParameter(spec.names[i], float(low[i]),
                                    f"{AT_BOUND} {low[i] * fac:.4g} {du} ({why}): the data pull it to "
                                    f"{p[i] * fac:.4g} {du}", None, stage,
                                    (float(p[i]), (u or {}).get(i, math.nan))))
        p[i] = low[i]
    return [i for i in kept if i not in below], fixed


def _undetermined(s: _Setup, p, kept, stage: str, u: dict):
    """The estimated parameters whose standard uncertainty ``u`` (:func:`_solution_u`) exceeds the plausible range
    of their quantity (:func:`arm_model.units.implausible`, the readers' table: a joint compliance's 1 rad/(N m)):
    the data do not determine them to within any value an arm can have (a compliance of a joint whose torque or
    lever on the tip is nil in the data; only without a prior, which bounds every uncertainty by its size), so
    they are held at their given value (``p`` changed in place) and said, as the rank test holds what the data
    cannot see at all. Returns (kept, [FixedParameter])."""
    from arm_model.model_file import PARAM_QUANTITY
    from arm_model.units import PLAUSIBLE_SI
    spec = s.problem.model.spec
    vague = [i for i in kept if u.get(i, 0.0) > PLAUSIBLE_SI.get(PARAM_QUANTITY.get(spec.units[i], ""), math.inf)]
    fixed = []
    for i in vague:
        du, fac = display_unit(spec.units[i])
        fixed.append(FixedParameter(spec.names[i], float(s.nominal[i]),
                                    f"not determined: u {u[i] * fac:.3g} {du} at the fit (value {p[i] * fac:.3g} "
                                    f"{du}) beyond any plausible value of it; held at its given value", None, stage))
        p[i] = s.nominal[i]
    return [i for i in kept if i not in vague], fixed


def _solution_u(s: _Setup, sol, kept) -> dict:
    """{spec index: standard uncertainty [SI]} of the parameters ``kept`` at the solution ``sol`` (its covariance,
    the weighted residual variance s0^2 when above 1); empty where the covariance cannot be had (singular, no
    redundancy)."""
    try:
        ev = sol.evaluation
        prob = s.problem.with_free(kept)
        dof = _dof(prob, len(ev.r), len(kept), prior=s.prior is not None)[0]
        cov = _covariance(s, ev, kept, max(1.0, 2 * sol.cost / max(dof, 1)))
    except (NumericalError, np.linalg.LinAlgError):
        return {}
    return {i: float(math.sqrt(max(cov[k, k], 0.0))) for k, i in enumerate(kept)}


def _restarted(s: _Setup, prob: Problem, sol, options: FitOptions):
    """The solution ``sol`` of ``prob``, or, when the artefacts' unknowns started again from the fitted arm
    (they were started from the nominal arm and can settle in another basin with large errors) fit better,
    the parameters refitted from there."""
    fresh = levenberg_marquardt(s.problem.with_free([]), sol.p, s.problem.initial_states(sol.p),
                                max_iter=options.max_iter)
    if fresh.cost < sol.cost * (1.0 - 1e-6):
        return levenberg_marquardt(prob, sol.p, fresh.states, max_iter=options.max_iter, prior=s.prior)
    return sol


#: prior scales (times the fit's) of the continuation when a fit does not converge from the nominal
CONTINUATION = (1e-2, 1e-1, 1.0)


def _lm(s: _Setup, prob: Problem, p, states, options: FitOptions):
    """Levenberg-Marquardt of ``prob`` from ``p``, ``states`` with the setup's prior (restarts inside);
    when that does not converge and there is a prior, a continuation in the prior's scale: the fit with the
    prior narrowed to :data:`CONTINUATION` of its size (near the nominal, well conditioned), each started from
    the one before, ending at the prior itself."""
    try:
        return levenberg_marquardt(prob, p, states, max_iter=options.max_iter, prior=s.prior)
    except NumericalError:
        if s.prior is None:
            raise
    for f in CONTINUATION:
        narrowed = Prior(s.prior.centre, s.prior.size * f)
        sol = levenberg_marquardt(prob, p, states, max_iter=options.max_iter, prior=narrowed)
        p, states = sol.p, sol.states
    return sol


#: without a prior: fits whose identifiability analysis at the solution holds more parameters, before the
#: identifiable set must have settled (holds at a bound do not count: a parameter is held at its bound once and
#: for all, so those rounds end by themselves). With a prior every fit is well posed whatever the data resolve,
#: so a combination that falls below the rank test only at the next solution (a harmonic of a joint whose axis
#: passes near the tip) is held in its turn until the set settles: the free set only shrinks, so that ends
#: within as many rounds as there are candidates.
SETTLE_ROUNDS = 4


def _solve(s: _Setup, options: FitOptions):
    """Identifiability at the start, the fit (with :func:`_restarted`), the bounds (:func:`_at_bounds`) and
    identifiability at the solution, and the fit again while the identifiable set changes. Returns (solution,
    kept, fixed, idf0, idf1)."""
    p = s.p0.copy()
    kept, fixed, idf0 = _held(s, p, s.states, list(s.candidates), "start", options)
    n_start = len(fixed)
    states = s.states
    rank_rounds = 0
    limit = SETTLE_ROUNDS if s.prior is None else len(s.candidates) + 1
    while rank_rounds < limit:
        prob = s.problem.with_free(kept)
        sol = _restarted(s, prob, _lm(s, prob, p, states, options), options)
        p, states = sol.p, sol.states
        n_before = len(kept)
        u = _solution_u(s, sol, kept) if len(kept) else {}
        kept, bound = _at_bounds(s, p, kept, "solution", u)
        kept, vague = _undetermined(s, p, kept, "solution", u)
        kept, new, idf1 = _held(s, p, states, kept, "solution", options)
        fixed += bound + vague + new
        if s.candidates and not kept:
            raise NumericalError(f"the data determine none of the {len(s.candidates)} parameters (each held: "
                                 "not observable from these points, e.g. one pose repeated); measure more "
                                 "distinct poses")
        if len(kept) == n_before:
            return sol, kept, fixed, idf0, idf1
        rank_rounds += bool(new)
    raise NumericalError("the identifiable set kept changing between fits (held in turn: "
                         + ", ".join(f.name for f in fixed[n_start:])
                         + "); raise the rank tolerance (--rank-tol) or hold some of these parameters (--hold)")


def _covariance(s: _Setup, ev, kept, var: float) -> np.ndarray:
    """Covariance [SI^2] of the free parameters ``kept`` from the reduced Jacobian at the solution, the data's
    weighted rows with variance ``var`` (s0^2 or 1): ``(J_red^T J_red / var)^-1``, or with a prior the
    posterior ``(J_red^T J_red / var + diag(1 / size^2))^-1``."""
    jred = reduced_jacobian(ev.jp, ev.jt)
    scale = column_scale(ev.jp)
    if s.prior is None:
        _, sv, vt = np.linalg.svd(compress_rows(jred / scale), full_matrices=False)
        if len(kept) and sv[-1] <= 0:
            raise NumericalError("singular covariance: a free parameter has no effect on the residuals")
        return var * (vt.T / sv ** 2) @ vt / np.outer(scale, scale) if len(kept) else np.zeros((0, 0))
    prec = 1.0 / s.prior.size[np.asarray(kept, dtype=int)] ** 2
    js_red = jred / scale
    cov = np.linalg.inv(js_red.T @ js_red / var + np.diag(prec / scale ** 2)) / np.outer(scale, scale)
    return 0.5 * (cov + cov.T)


@dataclass
class _Normal:
    """The column-scaled full Jacobian (parameters and nuisance) at the solution: ``js``, its column scale
    ``jscale``, its normal matrix (prior information included) factored by the Schur complement of the nuisance
    (``factor``, :class:`~calibration.schur.BlockNormal`), the rows' leverage ``h`` and the Laplace log evidence
    (None without a prior)."""
    js: sp.csc_matrix
    jscale: np.ndarray
    factor: BlockNormal
    h: np.ndarray
    log_evidence: float | None
    deletions: list | None = None


def _normal(s: _Setup, sol, kept, groups=None) -> _Normal:
    """:class:`_Normal` of the solution ``sol``; with ``groups`` (of residual rows: :func:`_test_groups`) also their
    deletions (:func:`~calibration.discrepancy.group_deletions`, ``deletions``), which give the leverage of their
    rows (the other rows' by :meth:`~calibration.schur.BlockNormal.leverage`)."""
    ev = sol.evaluation
    j = sp.hstack([sp.csr_matrix(ev.jp), ev.jt], format="csc") if len(kept) else ev.jt.tocsc()
    jscale = np.sqrt(np.asarray(j.multiply(j).sum(axis=0)).ravel())
    jscale[jscale == 0] = 1.0
    js = (j @ sp.diags(1.0 / jscale)).tocsc()
    kept_arr = np.asarray(kept, dtype=int)
    damp = np.zeros(js.shape[1])
    if s.prior is not None:
        damp[:len(kept)] = 1.0 / s.prior.size[kept_arr] ** 2 / jscale[:len(kept)] ** 2
    factor = BlockNormal(js, len(kept), damp)
    log_ev = None
    if s.prior is not None:                 # Laplace: -cost - 0.5 log det(H) + log of the prior's normalisation
        logdet = factor.log_abs_det() + 2.0 * float(np.sum(np.log(jscale)))
        log_ev = -(sol.cost + sol.prior_cost) - 0.5 * logdet - float(np.sum(np.log(s.prior.size[kept_arr])))
    if groups is None:
        return _Normal(js, jscale, factor, np.clip(factor.leverage(), 0.0, 1.0 - 1e-12), log_ev)
    h = np.full(js.shape[0], np.nan)
    deletions = group_deletions(factor, ev.r, groups, leverage=h)
    rest = np.flatnonzero(np.isnan(h))
    if len(rest):
        h[rest] = factor.leverage(rest)
    return _Normal(js, jscale, factor, np.clip(h, 0.0, 1.0 - 1e-12), log_ev, deletions)


def _point_table(prob: Problem, data: CalibrationData, p, states, z: np.ndarray) -> dict:
    """:meth:`Problem.residual_table` with each point's standardized residual (the largest |z| of its rows,
    signed for one-row kinds), measurement, feature, file and line (the file: points of a reference or held-out
    file share line numbers with the points file)."""
    table = prob.residual_table(p, states)
    pts = data.points
    zp = np.zeros(len(table["point"]))
    k = 0
    for g in prob.groups:
        npt, rows = len(g["points"]), g["rows"]
        zz = z[g["row0"]: g["row0"] + npt * rows].reshape(npt, rows)
        pick = np.argmax(np.abs(zz), axis=1)
        zp[k: k + npt] = zz[np.arange(npt), pick]
        k += npt
    table["standardized"] = zp
    table["measurement"] = pts.measurement[table["point"]]
    table["feature"] = pts.feature[table["point"]]
    table["line"] = (pts.lines[table["point"]] if pts.lines is not None else table["point"] + 1)
    table["file"] = data.point_files[table["point"]]
    return table


def _outliers(prob: Problem, data: CalibrationData, table: dict, zd: np.ndarray, threshold: float) -> list:
    """The points and distances whose standardized residual exceeds ``threshold``."""
    pts = data.points
    out = []
    for i in np.flatnonzero(np.abs(table["standardized"]) > threshold):
        pi = int(table["point"][i])
        out.append(Outlier(str(table["kind"][i]), str(pts.measurement[pi]), str(pts.feature[pi]), pi,
                           None if pts.lines is None else int(pts.lines[pi]), float(table["standardized"][i]),
                           float(table["value"][i]), data.file_of(pi)))
    for i in np.flatnonzero(np.abs(zd) > threshold):
        d = prob.distance_items[i]
        out.append(Outlier("distance", d.measurement, " - ".join(d.between), None, None, float(zd[i]),
                           float(table["distance"][i])))
    return out


def _instances(prob: Problem, table: dict, states) -> list[dict]:
    """Per artefact instance: its points, residual RMS and largest residual, and its fitted geometry."""
    out = []
    for i, it in enumerate(prob.instances):
        sel = table["instance"] == i
        v = table["value"][sel]
        st = states[i]
        item = {"measurement": it.measurement, "feature": it.feature, "kind": it.kind,
                "points": [int(x) for x in it.points], "n": int(sel.sum()),
                "rms": float(np.sqrt(np.mean(v ** 2))) if len(v) else 0.0,
                "max_abs": float(np.max(np.abs(v))) if len(v) else 0.0}
        if it.kind in ("seat", "sphere"):
            item["centre"] = st[:3].tolist()
        elif it.kind in ("ring", "cylinder"):
            item["axis_point"], item["axis_direction"] = st[0:3].tolist(), st[3:6].tolist()
        elif it.kind == "plane":
            item["normal"], item["offset"] = st[0:3].tolist(), float(st[9])
        out.append(item)
    return out


def _tracker(prob: Problem, p, states, nrm: _Normal, n_kept: int, var: float) -> Tracker | None:
    """The reference instrument's frames and the markers' offsets (:meth:`Problem.tracker`) with the standard
    uncertainties of their increments, or None without reference rows; a :class:`NumericalError` when the
    data do not determine them (:meth:`Problem.check_tracker`)."""
    prob.check_tracker(p, states)
    u = {}
    for i, it in enumerate(prob.instances):
        if it.kind in ("reference", "marker") and it.n_theta:
            cols = n_kept + it.offset + np.arange(it.n_theta)
            e = np.zeros((nrm.js.shape[1], it.n_theta))
            e[cols, np.arange(it.n_theta)] = 1.0
            blk = nrm.factor.solve(e)[cols] / np.outer(nrm.jscale[cols], nrm.jscale[cols]) * var
            u[i] = np.sqrt(np.diag(blk))
    return prob.tracker(states, u)


def _dof(prob: Problem, n_rows: int, n_kept: int, prior: bool = False) -> tuple[int, int]:
    """(degrees of freedom, nuisance unknowns) of a fit; raises when there is no redundancy: rows minus free
    parameters and nuisance unknowns, or with a prior (which determines what the data leave open) rows minus
    nuisance unknowns (the redundancy itself then comes from the leverages, :func:`_result`)."""
    n_nuis = sum(it.n_theta for it in prob.instances)
    dof = n_rows - n_kept - n_nuis
    if (n_rows - n_nuis if prior else dof) <= 0:
        raise NumericalError(f"{n_rows} residuals for {n_kept} parameters and {n_nuis} nuisance unknowns: "
                             "not enough data for a fit with redundancy: give more points (poses), fewer free "
                             "parameters (--hold, --free) or a smaller --holdout")
    return dof, n_nuis


def _result(s: _Setup, sol, kept, fixed, idfs, options: FitOptions) -> CalibrationResult:
    """The :class:`CalibrationResult` of the solution ``sol`` (free parameters ``kept``): the covariance, the
    leverage, the standardized residuals and outliers, the per-instance figures and, with a prior, each free
    parameter's prior standard deviation and posterior/prior variance ratio."""
    model, data = s.problem.model, s.problem.data
    spec = model.spec
    prob = s.problem.with_free(kept)
    ev = sol.evaluation
    n_rows = len(ev.r)
    dof, n_nuis = _dof(prob, n_rows, len(kept), prior=s.prior is not None)
    level = _test_level(options)
    nrm = _normal(s, sol, kept, None if level is None else _test_groups(prob)[2])
    # with a prior the residuals' share of the unknowns is the leverages' (the prior determines what the data
    # leave open), as in the noise's variance components: s0 = 1 when the noise estimate holds
    red = float(np.sum(1.0 - nrm.h)) if s.prior is not None else float(dof)
    s0 = math.sqrt(2 * sol.cost / red)
    var = s0 ** 2 if options.covariance == "residual" else 1.0
    source = ((f"a posteriori: s0^2 = {s0 ** 2:.4g} (weighted residual variance, dof {dof})" if s.prior is None else
               f"a posteriori: s0^2 = {s0 ** 2:.4g} (weighted residual variance over the redundancy {red:.3g}: rows "
               "less their share of the unknowns, the prior included)")
              if options.covariance == "residual" else "stated uncertainties (s0 = 1)")
    cov = _with_scale_u(s, kept, _covariance(s, ev, kept, var))
    u = np.sqrt(np.diag(cov))
    corr = cov / np.outer(u, u) if len(kept) else cov
    z = standardized_residuals(prob, ev.r, nrm.h)
    table = _point_table(prob, data, sol.p, sol.states, z)
    outliers = _outliers(prob, data, table, z[prob.n_point_rows:], options.outlier_threshold)
    distances = [{"measurement": d.measurement, "between": list(d.between), "certified": d.length,
                  "residual": float(table["distance"][i]), "standardized": float(z[prob.n_point_rows + i]),
                  "sigma": d.sigma} for i, d in enumerate(prob.distance_items)]
    prior_sd = None if s.prior is None else s.prior.size[np.asarray(kept, dtype=int)]
    return CalibrationResult(
        model=model, p=sol.p, free=tuple(spec.names[i] for i in kept), fixed=tuple(fixed),
        held=tuple(n for i, n in enumerate(spec.names) if i not in s.candidates), cov=cov, u=u, corr=corr, s0=s0,
        covariance_source=source, status=sol.status, iterations=sol.iterations, evaluations=sol.evaluations,
        cost=sol.cost, n_residuals=n_rows, n_nuisance=n_nuis, dof=dof, identifiability=idfs[0],
        identifiability_final=idfs[1], residuals=table, instances=_instances(prob, table, sol.states),
        distances=distances, tracker=_tracker(prob, sol.p, sol.states, nrm, len(kept), var), outliers=outliers,
        dropped=[], data=data, weights=prob.weights, reference_mode=options.reference, unused=prob.unused,
        variance=variance_components(prob, ev.r, nrm.h, prob.weights),
        prior_scales=None if s.prior is None else dict(s.scales), log_evidence=nrm.log_evidence,
        prior_centre=None if s.prior is None else s.prior.centre, options=options, prior_sd=prior_sd,
        prior_ratio=None if prior_sd is None else variance_ratio(u ** 2, prior_sd),
        prior_groups=_group_table(s, kept, u), redundancy=None if s.prior is None else red,
        arm_scale=None if s.arm_scale is None else s.arm_scale.to_dict(),
        prior_only={} if s.prior is None else {spec.names[i]: why for i, why in s.prior_only.items() if i in kept},
        discrepancy=model_discrepancy(prob, ev.r, nrm.factor, var)
        if options.discrepancy else None,
        region=region_effect(prob, ev.r, nrm.factor, var, nrm.jscale, u if prior_sd is None else prior_sd,
                             tuple(spec.names[i] for i in kept), _prior_group(s, kept))
        if options.region_effect else None,
        point_tests=None if level is None else point_tests(
            prob, ev.r, nrm.factor, nrm.h, level, nrm.deletions))


def _test_level(options: FitOptions) -> float | None:
    """The level the points' and lengths' gross-error tests (:func:`point_tests`) are taken at: ``--drop-outliers``
    drops what reaches ``outlier_threshold``, the default leaves out what reaches ``gross_threshold`` (and
    ``outlier_threshold``); None (no test) with neither (``--keep-outliers``)."""
    if options.drop_outliers:
        return options.outlier_threshold
    if options.gross_threshold is None:
        return None
    return max(options.gross_threshold, options.outlier_threshold)


def _prior_group(s: _Setup, kept) -> np.ndarray | None:
    """(len(kept),) the index of the prior's group of each free parameter (:meth:`~calibration.prior.PriorSpec.
    groups_of`), or None without a prior."""
    if s.prior is None:
        return None
    kept = np.asarray(kept, dtype=int)
    out = np.zeros(len(kept), dtype=int)
    for g, idx in enumerate(s.spec.groups_of(kept).values()):
        out[np.isin(kept, idx)] = g
    return out


def _group_table(s: _Setup, kept, u) -> dict:
    """{group: scale, parameters, effective (gamma: the parameters the data determine), size source, physical
    (its scale not chosen by the evidence, :attr:`calibration.prior.PriorSpec.physical`), capped (its scale at most 1,
    :attr:`~calibration.prior.PriorSpec.capped`), ceiling (the largest scale the evidence may give it,
    :meth:`calibration.prior.PriorSpec.ceiling`)} of the prior's groups over the
    free parameters ``kept``."""
    if s.prior is None:
        return {}
    spec = s.problem.model.spec
    kept = np.asarray(kept, dtype=int)
    out = {}
    for g, idx in s.spec.groups_of(kept).items():
        sel = np.isin(kept, idx)
        rho = variance_ratio(u[sel] ** 2, s.prior.size[idx])
        out[g] = {"scale": s.scales.get(g, 1.0), "parameters": [spec.names[i] for i in idx],
                  "effective_parameters": float(np.sum(1.0 - rho)),
                  "size_at_scale_1": {spec.names[i]: float(s.spec.size[i]) for i in idx},
                  "size_source": sorted({s.spec.source[i] for i in idx}), "physical": g in s.spec.physical,
                  "capped": g in s.spec.capped, "ceiling": s.spec.ceiling(g)}
    return out


def _fit(model: ArmModel, data: CalibrationData, options: FitOptions) -> CalibrationResult:
    """One fit at the weights and prior scales given: :func:`_setup`, :func:`_solve`, the arm's scale
    (:func:`_scale_rounds`), :func:`_result`."""
    s = _setup(model, data, options)
    sol, kept, fixed, idf0, idf1 = _solve(s, options)
    s, sol, kept, fixed = _scale_rounds(s, sol, kept, fixed, options)
    return _result(s, sol, kept, fixed, (idf0, idf1), options)


def _scale_rounds(s: _Setup, sol, kept, fixed, options: FitOptions):
    """With a prior at given scales and ``options.arm_scale`` "data": the arm's uniform scale of the prior's centre
    (:func:`_arm_scale_round`) and the fit again, until its step is below :data:`EVIDENCE_TOL` of its ``u`` (a fit
    started from an earlier fit's centre, whose scale it holds: one round). Returns (setup, solution, kept, fixed)."""
    if s.prior is None or options.arm_scale != "data":
        return s, sol, kept, fixed
    for _ in range(EVIDENCE_ROUNDS):
        red = float(np.sum(1.0 - _normal(s, sol, kept).h))
        var = 2 * sol.cost / red if options.covariance == "residual" and not options.weights_from_data else 1.0
        new, move = _arm_scale_round(s, sol, kept, _covariance(s, sol.evaluation, kept, var))
        if move <= EVIDENCE_TOL:
            return _settled(s, new), sol, kept, fixed
        s = new
        p = sol.p.copy()
        kept, bound = _at_bounds(s, p, kept, "evidence")
        fixed = fixed + bound
        sol = _lm(s, s.problem.with_free(kept), p, sol.states, options)
    return s, sol, kept, fixed


def _settled(s: _Setup, new: _Setup) -> _Setup:
    """``s`` (the setup its solution was fitted with) with the arm's scale that :func:`_arm_scale_round` found at
    that solution, its value the one of ``s``'s centre."""
    if new.arm_scale is None:
        return replace(s, arm_scale=None)
    value = s.arm_scale.value if s.arm_scale is not None else 0.0
    return replace(s, arm_scale=replace(new.arm_scale, value=value))


def _reweighted_problem(problem: Problem, weights: Weights) -> Problem:
    """``problem`` with the group factors of ``weights`` (same stated uncertainties): each row's sigma rescaled."""
    new = problem.with_free(problem.free)
    kinds = row_kinds(problem)
    old = np.array([problem.weights.factor(k) for k in kinds])
    now = np.array([weights.factor(k) for k in kinds])
    new.sigma = problem.sigma / old * now
    new.weights = weights
    return new


#: rounds of the evidence's joint estimate of the prior scales and the noise
EVIDENCE_ROUNDS = 40
#: the estimate has settled when every scale and noise factor changes by less than this (relative)
EVIDENCE_TOL = 0.02


def _evidence(model: ArmModel, data: CalibrationData, options: FitOptions) -> CalibrationResult:
    """The fit whose prior scales (one a group) and, with ``weights_from_data``, noise (one factor a row group)
    maximise the evidence together (:func:`_evidence_rounds`), from scale 1 and the given weights, on the base
    set of :func:`_solve`. The result carries the rounds in ``evidence`` and the final scales in
    ``prior_scales``."""
    s = _setup(model, data, options)
    sol, kept, fixed, idf0, idf1 = _solve(s, options)
    s, sol, kept, fixed, history = _evidence_rounds(s, sol, kept, fixed, options)
    res = _result(s, sol, kept, fixed, (idf0, idf1), options)
    res.evidence = history
    if options.weights_from_data:
        res.weights_history = [{"round": h["round"], "factors": h["noise_factors"], "s0": h["s0"]} for h in history]
        res.weights_history[-1].update({k: v for k, v in history[-1].items() if k in ("settled", "note")})
    return res


def _evidence_rounds(s: _Setup, sol, kept, fixed, options: FitOptions):
    """From the fit ``sol`` of the base set ``kept``: each round takes every group's scale toward MacKay's fixed
    point (:func:`calibration.prior.update_scales`), its log step lengthened or shortened by its secant over the
    rounds before (:func:`calibration.prior.secant_gains`: a scale the data shrink toward the floor gets there in a
    few rounds rather than by ever equal steps), and, with ``weights_from_data``, every row group's noise to its
    variance component (:func:`variance_components`, the leverages including the prior; damped from the tenth
    round), and refits from the previous solution, until the fixed point's steps are all below
    :data:`EVIDENCE_TOL` (relative): the plain fixed point's own stopping rule and solution, in fewer rounds.
    Returns (setup, solution, kept, fixed, rounds)."""
    history = []
    last: dict = {}
    for k in range(EVIDENCE_ROUNDS):
        prob = s.problem.with_free(kept)
        ev = sol.evaluation
        _dof(prob, len(ev.r), len(kept), prior=True)
        nrm = _normal(s, sol, kept)
        red = float(np.sum(1.0 - nrm.h))          # the redundancy with the prior, as in :func:`_result`
        var = 2 * sol.cost / red if options.covariance == "residual" and not options.weights_from_data else 1.0
        cov = _covariance(s, ev, kept, var)
        kept_arr = np.asarray(kept, dtype=int)
        rho = variance_ratio(np.diag(cov), s.prior.size[kept_arr])
        targets, gamma = update_scales(s.scales, s.spec, kept_arr, sol.p[kept_arr] - s.prior.centre[kept_arr], rho,
                                       GEOMETRY_GROUPS if options.prior_groups == "pooled" else ())
        steps = {g: math.log(targets[g] / tau) for g, tau in s.scales.items()}
        factors = {}
        if options.weights_from_data:
            factors = {v["group"]: v["factor"] for v in variance_components(prob, ev.r, nrm.h, prob.weights)
                       if v["estimated"]}
        history.append({"round": k + 1, "scales": dict(s.scales), "effective_parameters": gamma,
                        "noise_factors": dict(prob.weights.factors), "s0": math.sqrt(2 * sol.cost / red)})
        moves = [abs(r) for r in steps.values()] + [abs(math.log(f)) for f in factors.values()]
        scaled = s
        if options.arm_scale == "data":
            scaled, move = _arm_scale_round(s, sol, kept, cov)
            moves.append(move)
            if scaled.arm_scale is not None:
                history[-1]["arm_scale"] = scaled.arm_scale.to_dict()
        if max(moves, default=0.0) <= EVIDENCE_TOL:
            history[-1]["settled"] = True
            return _settled(s, scaled) if options.arm_scale == "data" else s, sol, kept, fixed, history
        gains = secant_gains(steps, last, EVIDENCE_TOL)
        scales = {g: s.spec.bounded(g, tau * math.exp(gains[g] * steps[g])) for g, tau in s.scales.items()}
        # the first move, from the starting scales (far from the fixed point, where its step is not near linear),
        # is no secant's base
        last = {g: (r, math.log(scales[g] / s.scales[g])) for g, r in steps.items()} if k else {}
        damping = 1.0 if k < 10 else 0.5
        s = replace(scaled, scales=scales, prior=Prior(scaled.prior.centre, s.spec.sizes(scales)),
                    problem=_reweighted_problem(s.problem, prob.weights.scaled(
                        {g: f ** damping for g, f in factors.items()})))
        p = sol.p.copy()
        kept, bound = _at_bounds(s, p, kept, "evidence")
        fixed = fixed + bound
        sol = _lm(s, s.problem.with_free(kept), p, sol.states, options)
    history[-1]["settled"] = False
    history[-1]["note"] = (f"the prior scales and noise did not settle in {EVIDENCE_ROUNDS} rounds; the last "
                           "round's are used")
    return s, sol, kept, fixed, history


#: relative step [1] of the arm's uniform scale in the finite difference of the residuals along it
SCALE_STEP = 1e-6
#: the most the free parameters may miss of the uniform scale's effect on the residuals (relative) for the data's
#: scale to be estimated: beyond it the parameters held (given, or exactly not separable) carry the scale
SCALE_MISS = 0.1


def _scale_direction(s: _Setup, sol, kept) -> np.ndarray | None:
    """The direction of the free parameters ``kept`` (full parameter vector [SI], zero elsewhere) that acts on the
    data as the arm's uniform scale does (:func:`calibration.prior.uniform_scale`, every length of the description
    held or free), the nuisance unknowns eliminated: the least-squares combination of the reduced Jacobian's columns
    that gives the residuals' change along the scale (a finite difference). None when the free parameters miss more
    than :data:`SCALE_MISS` of it (or the arm has no length)."""
    prob = s.problem.with_free(kept)
    full = uniform_scale(prob.model)
    ev = sol.evaluation
    if not np.any(full) or not len(kept):
        return None
    moved = prob.evaluate(sol.p + SCALE_STEP * full, sol.states, jac=False).r
    target = (moved - ev.r)[:, None] / SCALE_STEP
    if ev.jt.shape[1]:
        project = NuisanceProjection(ev.jt)
        target, jred = project(target)[:, 0], project(ev.jp)
    else:
        target, jred = target[:, 0], ev.jp
    x = np.linalg.lstsq(jred, target, rcond=None)[0]
    if not np.linalg.norm(jred @ x - target) <= SCALE_MISS * np.linalg.norm(target):
        return None
    out = np.zeros_like(full)
    out[np.asarray(kept, dtype=int)] = x
    return out


def _arm_scale_round(s: _Setup, sol, kept, cov: np.ndarray) -> tuple[_Setup, float]:
    """One round of the arm's uniform scale under a flat prior (:func:`calibration.prior.scale_step`) from the fit
    ``sol`` (posterior covariance ``cov`` of ``kept``): the setup with the prior's centre at the given centre
    scaled by the new value (or at the given centre when the data do not set the scale: its ``u`` beyond
    :data:`calibration.prior.MAX_SCALE_U`) and the step in units of its ``u`` (0 when not set)."""
    assert s.prior is not None, "the arm's scale is the prior's"
    old = s.arm_scale
    base = s.prior.centre - (old.value * old.direction if old is not None else 0.0)
    d = _scale_direction(s, sol, kept)
    if d is None:
        return replace(s, arm_scale=None, prior=Prior(base, s.prior.size)), 0.0
    idx = np.asarray(kept, dtype=int)
    step, u = scale_step(d[idx], s.prior.size[idx], sol.p[idx] - s.prior.centre[idx], cov)
    before = old.value if old is not None else 0.0
    # the scale of the centre given from the description (p = 0; an earlier fit's centre holds its scale), in the
    # prior's metric
    w = d[idx] / s.prior.size[idx] ** 2
    start = old.start if old is not None else float(w @ base[idx]) / float(w @ d[idx])
    ok = u <= MAX_SCALE_U
    value = before + step if ok else 0.0
    new = _ArmScale(value, u, d, ok, start)
    return replace(s, arm_scale=new, prior=Prior(base + value * d, s.prior.size)), abs(value - before) / u


def _with_scale_u(s: _Setup, kept, cov: np.ndarray) -> np.ndarray:
    """The posterior covariance ``cov`` of ``kept`` with the uncertainty of the arm's scale the data set (a flat
    prior on it: the rank-one term of the prior precision's Schur complement, ``cov L d (cov L d)^T / den``,
    :func:`calibration.prior.scale_step`); ``cov`` as it is without one."""
    a = s.arm_scale
    if a is None or not a.set or s.prior is None or not len(kept):
        return cov
    idx = np.asarray(kept, dtype=int)
    _, g, den = scale_precision(a.direction[idx], s.prior.size[idx], cov)
    return cov + np.outer(g, g) / den if den > 0 else cov


#: fewest redundant rows (rows minus their share of the unknowns) for a group's noise to be estimated
MIN_REDUNDANCY = 5.0
#: below :data:`MIN_REDUNDANCY` (and from one redundant row on) a group of points' noise is still estimated when
#: its residuals refute the stated uncertainty (a certified length's stays the certificate's): chi-square of its
#: weighted residuals on its redundancy beyond this probability in either tail (a humanoid touching a table on 21
#: poses with 18 parameters: 3 redundant rows, residuals of millimetres against a stated 10 um; kept, the stated
#: value made the evidence interpolate)
REFUTED_P = 1e-6
#: rows whose residual exceeds this many robust standard deviations of their group (1.4826 times the median
#: of ``|r| / sqrt(1 - h)``) are gross errors: left out of the group's noise estimate
OUTLIER_ROWS = 4.0


def row_kinds(problem: Problem) -> np.ndarray:
    """The observation group of each residual row of ``problem``: its point kind (seat, sphere, ring, ...,
    ``reference``) or ``length`` for a certified length."""
    kind = np.empty(problem.n_rows, dtype=object)
    for g in problem.groups:
        kind[g["row0"]: g["row0"] + g["rows"] * len(g["points"])] = g["kind"]
    kind[problem.n_point_rows:] = "length"
    return kind


def kind_groups(kinds, by_source: bool = False) -> dict[str, np.ndarray]:
    """{group: row indices} of rows whose observation groups are ``kinds`` (:func:`row_kinds`): one group a
    kind; with ``by_source`` one group a stated uncertainty instead: ``probe`` (the probed points of every
    artefact kind), ``reference`` and ``length``."""
    names = np.array(["probe" if by_source and k not in ("reference", "length") else k for k in kinds],
                     dtype=object)
    return {name: np.flatnonzero(names == name) for name in dict.fromkeys(names.tolist())}


def row_groups(problem: Problem, by_source: bool = False) -> dict[str, np.ndarray]:
    """The residual rows of each observation group of ``problem`` (:func:`kind_groups`): by kind, the groups
    of :func:`variance_components`; both groupings are those of the outlier scale
    (:func:`standardized_residuals`)."""
    return kind_groups(row_kinds(problem), by_source)


def standardized_residuals(problem: Problem, r: np.ndarray, leverage: np.ndarray) -> np.ndarray:
    """Standardized residuals of a fit of ``problem``: :func:`grouped_standardized` with its rows' groups."""
    return grouped_standardized(r, leverage, row_kinds(problem))


def grouped_standardized(r: np.ndarray, leverage, kinds) -> np.ndarray:
    """Standardized residuals ``r_i / (s_i sqrt(1 - h_i))`` with ``s_i`` the robust scale (1.4826 times the
    median of ``|r| / sqrt(1 - h)``) of row i's observation group (``kinds``: each row's, :func:`row_kinds`;
    ``leverage`` h: 0 for held-out rows), so that a group whose stated uncertainty is off (say the
    tracker's against the probe's) does not flag its clean rows or hide the other groups' gross errors.
    Two groupings (:func:`kind_groups`): a kind (seats, spheres, ..., the reference points, the lengths)
    and a stated uncertainty (the probed points of every kind together, the reference points, the
    lengths); ``s_i`` is the larger of row i's two scales. The kind's scale keeps the points of a noisier
    kind (seats: articulations) from being flagged for its noise; the probe's scale keeps a quieter kind's
    points from being flagged for an effect the model lacks that shows more in the other kinds. A group
    with less than :data:`MIN_REDUNDANCY` redundant rows takes the scale of all rows together (a median of
    a few rows is no scale)."""
    leverage = np.broadcast_to(np.asarray(leverage, float), np.shape(r))
    return r / np.sqrt(1.0 - leverage) / robust_scales(r, leverage, kinds)


def robust_scales(r: np.ndarray, leverage, kinds) -> np.ndarray:
    """The robust scale of each row of :func:`grouped_standardized` (weighted units, as ``r``)."""
    leverage = np.broadcast_to(np.asarray(leverage, float), np.shape(r))
    zraw = r / np.sqrt(1.0 - leverage)
    pooled = 1.4826 * float(np.median(np.abs(zraw))) or 1.0
    scale = np.zeros_like(zraw)
    for by_source in (False, True):
        for idx in kind_groups(kinds, by_source).values():
            s = 1.4826 * float(np.median(np.abs(zraw[idx])))
            if float(np.sum(1.0 - leverage[idx])) < MIN_REDUNDANCY or s <= 0:
                s = pooled
            scale[idx] = np.maximum(scale[idx], s)
    return scale


def variance_components(problem: Problem, r: np.ndarray, leverage: np.ndarray, weights: Weights) -> list[dict]:
    """The noise of each row group estimated from a fit (Helmert / Foerstner): for a group g with weighted
    residuals ``r_g`` and redundancy ``red_g = sum(1 - h_i)`` over its rows (``h`` the leverage: the share
    of each row that the unknowns absorb), ``factor_g = sqrt(|r_g|^2 / red_g)`` estimates by how much its
    stated uncertainty must be multiplied. Rows beyond :data:`OUTLIER_ROWS` robust standard deviations of
    their group are left out (a gross error would inflate the estimate). Groups with less than
    :data:`MIN_REDUNDANCY` redundant rows are not estimated (``estimated`` False, factor 1), unless their
    residuals refute the stated uncertainty (:func:`_refutes`; ``stated_refuted`` True); nor are groups whose
    estimate lies below the smallest stated uncertainty, ``arm_model.units.STATED_SIGMA_M`` (``no_scatter``
    True: residuals of rounding size, a pose repeated exactly, hold no noise to estimate).

    Returns one dict a group: ``group``, ``rows``, ``redundancy``, ``factor``, ``estimated``, and
    ``sigma_um`` (the current uncertainty of a point of the group, per axis, factor applied) and
    ``estimate_um`` (times ``factor``) for point groups.
    """
    out = []
    for name, idx in row_groups(problem).items():
        z = np.abs(r[idx]) / np.sqrt(1.0 - leverage[idx])
        s_rob = 1.4826 * float(np.median(z))
        gross = z > OUTLIER_ROWS * s_rob if s_rob > 0 else np.zeros(len(idx), bool)
        idx = idx[~gross]
        red = float(np.sum(1.0 - leverage[idx]))
        # a certified length's uncertainty is its certificate's, not a starting guess: kept (what refutes it is
        # an effect the model lacks, which its weight must keep visible)
        refuted = name != "length" and MIN_REDUNDANCY > red >= 1.0 and _refutes(float(r[idx] @ r[idx]), red)
        ok = red >= MIN_REDUNDANCY or refuted
        factor = math.sqrt(float(r[idx] @ r[idx]) / red) if ok else 1.0
        sig = weights.sigma_of(name)
        # residuals below the smallest uncertainty anyone may state are rounding, not scatter (a pose repeated
        # exactly): no estimate of the noise (a factor of 0 weighted the rows infinitely, and a log of it failed)
        no_scatter = ok and factor * (sig if sig is not None else weights.length_sigma(None)) < STATED_SIGMA_M[0]
        if no_scatter:
            ok, factor = False, 1.0
        out.append({"group": name, "rows": int(len(idx)), "redundancy": red, "factor": factor, "estimated": ok,
                    "stated_refuted": bool(refuted), "no_scatter": bool(no_scatter),
                    "gross_rows_left_out": int(gross.sum()),
                    "sigma_um": None if sig is None else sig * 1e6,
                    "estimate_um": None if sig is None else sig * factor * 1e6})
    return out


def _refutes(chi2: float, red: float) -> bool:
    """Whether a weighted residual sum of squares ``chi2`` on ``red`` redundant rows refutes the stated
    uncertainty: beyond :data:`REFUTED_P` in either tail of the chi-square distribution with ``red`` degrees
    of freedom."""
    from scipy.stats import chi2 as chi2_dist
    return bool(chi2_dist.sf(chi2, red) < REFUTED_P or chi2_dist.cdf(chi2, red) < REFUTED_P)


def reweighted(model: ArmModel, data: CalibrationData, options: FitOptions, tol: float = 0.03,
               rounds: int = 12) -> CalibrationResult:
    """Iterated variance-component estimation without a prior: the fit of ``options`` with every
    group's factor updated from the fit (the free parameters started from the previous round's values),
    until all change by less than ``tol``. From the fifth round on the updates are damped (square root of
    the factor), since a parameter held or freed by the practical-resolution rule can make the estimates
    alternate. The result carries ``weights_history`` (factors and s0 of each round; the last entry says
    whether they settled) and ``options`` as given."""
    history, st = [], {}
    weights = options.weights
    for k in range(rounds):
        res = _fit(model, data, replace(options, weights=weights, weights_from_data=False,
                                        start={**(options.start or {}), **st}))
        est = {v["group"]: v["factor"] for v in res.variance if v["estimated"]}
        history.append({"round": k + 1, "factors": dict(weights.factors), "s0": res.s0})
        if all(abs(f - 1.0) <= tol for f in est.values()):
            history[-1]["settled"] = True
            break
        if k >= 4:
            est = {g: math.sqrt(f) for g, f in est.items()}
        weights = weights.scaled(est)
        st = {n: res.value(n) for n in res.free}
    else:
        history[-1]["settled"] = False
        history[-1]["note"] = (f"the noise estimates did not settle in {rounds} rounds (last residual/stated "
                               f"ratios {', '.join(f'{g} {f:.3g}' for g, f in est.items())}); the last round's "
                               "weights are used")
    res.weights_history = history
    res.options = options
    return res


def column_scale(jp: np.ndarray) -> np.ndarray:
    s = np.linalg.norm(jp, axis=0)
    return np.where(s > 0, s, 1.0)


def nominal_baseline(model: ArmModel, data: CalibrationData, options: FitOptions = FitOptions()) -> CalibrationResult:
    """The nominal model given the same nuisance unknowns as a calibration with ``options``: the description
    (``options.values``) with only the tip offset fitted (probe.x/y/z, where free: a probe's ball whose place
    on the last link may not be known; a tracker's markers at unknown offsets are nuisance unknowns of every
    fit) under the calibration's own prior (``options.prior_scale``: by default the evidence's scale of the tip
    offset, its ceiling and its rule for a direction the data barely see, :mod:`calibration.prior`; without a
    prior, by least squares), the artefacts' unknowns and the
    reference frame solved as in every fit, at the same weights (no noise estimate of its own), on every point
    of ``data`` (give it the fit's ``data``: without the gross errors the fit left out). Its
    ``p``/``reference`` are the baseline every "nominal -> calibrated" figure compares against; it carries no
    model discrepancy (nothing reads one of the baseline's: its extrapolative folds cost a fit's tenth). (Without
    the prior, a ring gauge probed with the stylus along its axis, which sees probe z only through the stylus'
    tilt, moved the bundled ring campaign's probe z by -246 mm.)"""
    spec = model.spec
    cand = resolve_parameters(spec, default_free(model, data) if options.free is None else options.free)
    tip = [spec.names[i] for i in cand if spec.names[i] in ("probe.x", "probe.y", "probe.z")]
    return calibrate(model, data, replace(options, free=tuple(tip), prior_scale=options.prior_scale if tip else None,
                                          min_resolution=None, weights_from_data=False, drop_outliers=False,
                                          gross_threshold=None, start=None, on_unidentifiable="fix",
                                          discrepancy=False))


def evidence_scale(model: ArmModel, data: CalibrationData, options: FitOptions = FitOptions()) -> tuple[dict, list]:
    """The prior scale of each group that the data support best, with the noise when
    ``options.weights_from_data`` (:func:`_evidence`): ``(scales {group: scale}, the rounds)``. A fit with
    ``prior_scale=scales`` reproduces that fit without estimating them again (e.g. on the folds of a
    cross-validation)."""
    res = calibrate(model, data, replace(options, prior_scale="evidence", drop_outliers=False))
    return dict(res.prior_scales), res.evidence
