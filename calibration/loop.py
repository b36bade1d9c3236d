"""Close the loop: calibrate, find the residual's structure, add the effect it points to, repeat.

:func:`close_loop` runs, on points and artefacts of any campaign:

1. An outer **test set** is put aside: the measurements ``holdout`` or a share ``test_fraction`` of them
   (seeded, stratified by feature kind), or, with too few measurements, that share of every feature's
   poses (each predicted against its feature's centre fitted on the design poses). It takes part in no
   decision and gives the before/after figures of the report.
2. The base model is calibrated on the rest (the **design set**).
3. **Screening** (:func:`calibration.diagnostics.screen_candidates`): the score test of every candidate
   effect at the current fit. It only filters: candidates whose p-value is below
   ``screen_alpha / (number of identifiable candidates)`` (Bonferroni), at most ``cv_top`` of them, go on.
4. **Decision on held-out data**: K-fold cross-validation on the design set, by measurement or, when the
   measurements are too few for the test to reach its level (``fold_by="auto"``), by pose inside each
   feature. In each fold the current model and the model plus the candidate are calibrated on the other
   folds and predict the fold's units: whole measurements, whose nuisance unknowns (centres, axes, planes,
   ``T_ref_base``) are solved on the held-out points only, or poses, predicted against their feature's
   centre fitted on its other poses. Whether the test can reach its level (smallest p over n units is
   1/2^n) is reported before it runs. Per held-out unit, the mean squared weighted residual of the two
   models is compared by a one-sided Wilcoxon signed-rank test; a candidate passes with ``p < alpha / (number of
   candidates tested)`` and a relative drop of the pooled held-out RMS of at least ``min_improvement``.
   The passing candidate with the largest drop is added; ties in signature are reported (``nested``,
   ``alternatives``: candidates the data cannot tell from it).
5. Recalibrate on the design set with the new effect; repeat from 3 until no candidate passes, none is
   left, or ``max_effects`` were added.
   **Beyond the library**: when no candidate passes at a stage, the generic structure families still
   significant at the current fit (the forward selection of step 6) become candidate effects
   (:mod:`calibration.synthesis`: a joint's harmonics of order k = 1..4, per-link and probe thermal growth,
   a full probe compliance matrix, an approach-direction offset, a joint's lateral compliance), screened
   and cross-validated in steps 3-4 exactly like the library's, against a Bonferroni level over every
   candidate then offered (screening) and every candidate held-out tested at the stage (Wilcoxon): the
   candidates that already failed the held-out test at this stage are not tested again, so the built
   effects reach it even when failed library candidates rank above them. One that passes is added and reported as found from the residual; one that
   does not is reported with its held-out evidence and not added.
6. The generic structure tests (:func:`calibration.diagnostics.structure_tests`) on the final fit, and a
   forward selection among them (:func:`calibration.diagnostics.remaining_structure`): a family
   significant after Bonferroni's correction (``alpha``), given the families kept before it, with a
   positive held-out explained variance means that **structured residual remains**; the verdict names
   its regressors and claims no fix.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from arm_model import InputError, NumericalError
from arm_model._log import counted, progress_line
from arm_model.description import ArmDescription
from arm_model.effects import JointCompliance, ThermalGrowth
from arm_model.io import Artefacts, PointSet
from arm_model.model import ArmModel

from .calibrate import (CalibrationResult, calibrate, default_free, display_unit, evidence_scale,
                        grouped_standardized, resolve_parameters)
from .candidates import Candidate, library_candidates, needs_model
from .data import CalibrationData, Weights, concat, make_data, split_holdout, split_poses
from .diagnostics import (GroupTest, ResidualSpace, binned_estimates, candidate_family, families, holm,
                          measurement_folds, pose_folds, remaining_structure, residual_space, screen_candidates,
                          structure_tests)
from .identifiability import DEFAULT_RANK_TOL, prior_scales
from .options import FitOptions
from .problem import MIN_POINTS, Problem
from .solver import levenberg_marquardt
from .synthesis import RESIDUAL, synthesise
from .validation import BOOTSTRAP_SAMPLES, FIGURES, bootstrap, resamples, validate

log = logging.getLogger(__name__)

__all__ = ["LoopSettings", "CVResult", "Stage", "LoopResult", "close_loop", "heldout_residuals",
           "heldout_figures", "cross_validate", "display", "effect_summary"]

#: share of a candidate's signature inside another's above which the data cannot tell them apart
SAME_SIGNATURE = 0.99
#: the start of the reason of a candidate included as physics (:func:`_physics_inclusion`)
PHYSICS = "included as physics"
#: held-out improvement (fraction) within which a smaller nested candidate is preferred
PARSIMONY = 0.01
#: the loop's decisions use the noise estimated from the data when a group's residual differs from its
#: stated sigma by more than this factor (the stated sigmas are wrong); within it the stated sigmas are kept,
#: since a missing effect inflates the residual of the groups it acts on and re-weighting would hide it
NOISE_OFF = 2.0
#: how the decisions' folds are made: by whole measurement, by pose inside each feature, or the first
#: that can reach the significance level
FOLD_BY = ("auto", "measurement", "pose")


def wilcoxon_units_needed(alpha: float, tests: int) -> int:
    """Fewest paired units for which a one-sided Wilcoxon signed-rank test can reach ``p < alpha / tests``:
    its smallest p-value over n units is ``1 / 2^n`` (every difference positive)."""
    return int(math.floor(math.log2(tests / alpha))) + 1


@dataclass(frozen=True)
class LoopSettings:
    """Options of :func:`close_loop` (see its docstring)."""
    folds: int = 4
    test_fraction: float = 0.25
    alpha: float = 0.01
    screen_alpha: float = 0.05
    min_improvement: float = 0.02
    max_effects: int = 4
    cv_top: int = 3
    seed: int = 0
    rank_tol: float = DEFAULT_RANK_TOL
    drop_outliers: bool = True
    outlier_threshold: float = 4.0
    holdout: tuple = ()
    fold_by: str = "auto"
    weights_from_data: bool = True
    synthesise: bool = True
    physics: bool = True
    prior_scale: float | str | None = None

    def __post_init__(self):
        object.__setattr__(self, "holdout", tuple(self.holdout or ()))
        if self.fold_by not in FOLD_BY:
            raise ValueError(f"fold_by must be one of {', '.join(FOLD_BY)}, got {self.fold_by!r}")
        if self.folds < 2:
            raise ValueError(f"folds must be at least 2, got {self.folds}")
        if not 0.0 < self.test_fraction < 1.0:
            raise ValueError(f"test_fraction must be in (0, 1), got {self.test_fraction}")
        for name in ("alpha", "screen_alpha"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise ValueError(f"{name} must be in (0, 1), got {v}")
        if self.min_improvement < 0 or self.max_effects < 0 or self.cv_top < 1:
            raise ValueError("min_improvement and max_effects must be >= 0 and cv_top >= 1")

    def to_dict(self) -> dict:
        return dict(self.__dict__)


# ---------------------------------------------------------------------------------------------------
# held-out evaluation

def heldout_residuals(model: ArmModel, p, data: CalibrationData, weights: Weights, reference: str = "fit",
                      train=None) -> dict:
    """Residual rows of held-out points with the parameters ``p`` held: ``r`` weighted (n,), ``e`` [m] (n,),
    ``measurement``, ``kind`` and ``point`` (index into ``data``, -1 for a length) per row.

    ``train`` None: every point of ``data`` is held out and every nuisance unknown (centre, axis, plane,
    ``T_ref_base``) is solved on ``data`` alone. ``train`` a mask: the points where it holds are the
    training poses; the nuisance unknowns are solved on them, and the rows of the other points are
    returned (a held-out pose against the centre fitted on the rest of its feature's poses); the
    lengths then belong to training."""
    prob = Problem(model, data, weights, [], reference=reference)
    if train is None:
        states = levenberg_marquardt(prob, p, prob.initial_states(p)).states
        keep = np.ones(prob.n_rows, bool)
    else:
        train = np.asarray(train, bool)
        sub = Problem(model, data.select(train), weights, [], reference=reference)
        fitted = {(it.measurement, it.feature): st for it, st in
                  zip(sub.instances, levenberg_marquardt(sub, p, sub.initial_states(p)).states)}
        start = prob.initial_states(p)
        states = [fitted.get((it.measurement, it.feature), s0) for it, s0 in zip(prob.instances, start)]
        missing = [f"{it.measurement} {it.feature}" for it in prob.instances
                   if (it.measurement, it.feature) not in fitted]
        if missing:
            raise ValueError(f"no training pose on {', '.join(missing)}: its centre cannot be predicted")
        keep = (prob.row_distance < 0) & ~train[np.maximum(prob.row_point, 0)]
    r = prob.evaluate(p, states, jac=False).r
    pts = data.points
    meas = np.empty(len(r), dtype=object)
    kind = np.empty(len(r), dtype=object)
    ok = prob.row_distance < 0
    meas[ok] = pts.measurement[prob.row_point[ok]]
    kind[ok] = [prob.instances[i].kind for i in prob.row_instance[ok]]
    for row in np.flatnonzero(~ok):
        meas[row] = prob.distance_items[prob.row_distance[row]].measurement
        kind[row] = "length"
    point = np.where(ok, prob.row_point, -1)
    return {"r": r[keep], "e": (r * prob.sigma)[keep], "measurement": meas[keep], "kind": kind[keep],
            "point": point[keep]}


def heldout_figures(model: ArmModel, p, data: CalibrationData, weights: Weights, reference: str = "fit",
                    train=None) -> dict:
    """Figures of ``(model, p)`` on held-out data [um] (``train``: see :func:`heldout_residuals`): RMS and
    max |residual| over the artefact rows (each row a residual component: a sphere/ring/plane distance, a
    seat coordinate, a length error; the reference-instrument rows only when there is nothing else, since
    their noise is the instrument's), the same per kind, the weighted RMS of all rows, and the standard
    test figures (:data:`calibration.validation.FIGURES`) of the held-out points."""
    h = heldout_residuals(model, p, data, weights, reference, train)
    e = h["e"]
    art = h["kind"] != "reference"
    head = e[art] if art.any() else e
    out = {"rms_um": float(np.sqrt(np.mean(head ** 2))) * 1e6, "max_um": float(np.max(np.abs(head))) * 1e6,
           "headline_rows": ("reference points" if not art.any() else "artefact points and lengths"
                             if (h["kind"] == "length").any() else "artefact points"),
           "rms_weighted": float(np.sqrt(np.mean(h["r"] ** 2))), "rows": int(len(e)), "by_kind": {}}
    for k in dict.fromkeys(h["kind"].tolist()):
        ek = e[h["kind"] == k]
        out["by_kind"][k] = {"rows": int(len(ek)), "rms_um": float(np.sqrt(np.mean(ek ** 2))) * 1e6,
                             "max_um": float(np.max(np.abs(ek))) * 1e6}
    u = _bootstrap_rows(head, h["measurement"][art] if art.any() else h["measurement"])
    out["u_rms_um"], out["u_max_um"] = (None, None) if u is None else (u[0] * 1e6, u[1] * 1e6)
    held = data if train is None else data.select(~np.asarray(train, bool))
    try:
        val = validate(model, p, held, weights, reference)
        summary, u_std = val.summary(), bootstrap(val)
    except InputError:                # held-out poses too few on some feature for its own fit
        summary, u_std = {}, {}
    out["standard"] = {k: summary[k] * FIGURES[k][2] for k in FIGURES if k in summary}
    out["u_standard"] = {k: None if u_std.get(k) is None else u_std[k] * FIGURES[k][2] for k in out["standard"]}
    return out


def _bootstrap_rows(e: np.ndarray, measurement: np.ndarray, samples: int = BOOTSTRAP_SAMPLES, seed: int = 0):
    """Standard uncertainties [m] of the RMS and the max |e| of residual rows, by the bootstrap of
    :func:`calibration.validation.bootstrap` (whole measurements resampled with replacement); None
    with fewer than two measurements."""
    groups = [e[measurement == m] for m in dict.fromkeys(measurement.tolist())]
    if len(groups) < 2:
        return None
    rms, mx = np.empty(samples), np.empty(samples)
    for k, idx in enumerate(resamples(len(groups), samples, seed)):
        x = np.concatenate([groups[i] for i in idx])
        rms[k], mx[k] = np.sqrt(np.mean(x ** 2)), np.max(np.abs(x))
    return float(rms.std(ddof=1)), float(mx.std(ddof=1))


# ---------------------------------------------------------------------------------------------------
# cross-validation of one candidate

@dataclass
class FoldFit:
    """The fits of one model on each fold's training part and their held-out residual rows."""
    results: list                     # CalibrationResult per fold
    sse: dict                         # measurement -> (sum of squared weighted residuals, rows)


@dataclass
class CVResult:
    """Held-out evidence for adding one candidate.

    Attributes:
        rms_base, rms_new: pooled held-out weighted RMS of the current model and with the candidate.
        improvement: ``1 - rms_new / rms_base``.
        p_value: one-sided Wilcoxon signed-rank test over held-out measurements (mean squared weighted
            residual of each); threshold: the level it was held to (``alpha / tested``).
        wins: measurements improved, of ``n_measurements``.
    """
    candidate: str
    rms_base: float
    rms_new: float
    improvement: float
    p_value: float
    threshold: float
    n_measurements: int
    wins: int
    passed: bool
    reason: str
    score_p: float = float("nan")
    folds: FoldFit | None = field(default=None, repr=False)
    held: bool = False            # its parameters were held (not resolved) in some fold's training part

    def to_dict(self) -> dict:
        def num(v):
            return float(v) if v is not None and math.isfinite(float(v)) else None
        return {"candidate": self.candidate, "heldout_rms_weighted_before": num(self.rms_base),
                "heldout_rms_weighted_after": num(self.rms_new), "relative_improvement": num(self.improvement),
                "wilcoxon_p_value": num(self.p_value), "threshold": num(self.threshold),
                "measurements": self.n_measurements, "measurements_improved": self.wins, "passed": self.passed,
                "reason": self.reason, "screening_p_value": num(self.score_p)}


@dataclass(frozen=True)
class Folds:
    """The folds of the design set for the held-out decisions.

    Attributes:
        by: "measurement" (whole measurements held out) or "pose" (poses inside each feature, predicted
            against the feature's centre fitted on its other poses).
        k: number of folds.
        assign: measurement id -> fold (by measurement), or the fold of every design point (-1: never held).
        per_pose: by measurement, the units of the paired test are the held-out poses (each against its
            held-out measurement's own centre) instead of whole measurements: with few measurements (one
            plate at a few placements) the test can still reach its level.
        n_poses: held-out poses over all folds (by measurement with ``per_pose``).
    """
    by: str
    k: int
    assign: object
    per_pose: bool = False
    n_poses: int = 0

    @property
    def units(self) -> int:
        """Held-out units of the paired test: measurements, or poses."""
        if self.by == "pose":
            return int(np.sum(np.asarray(self.assign) >= 0))
        return self.n_poses if self.per_pose else len(self.assign)

    @property
    def unit_name(self) -> str:
        return "measurements" if self.by == "measurement" and not self.per_pose else "poses"


def _fold_fit(model: ArmModel, design: CalibrationData, folds: Folds, fit) -> FoldFit:
    results, sse = [], {}
    if folds.by == "pose":
        for f in range(folds.k):
            train = np.asarray(folds.assign) != f
            res = fit(model, design.select(train))
            h = heldout_residuals(model, res.p, design, res.weights, res.reference_mode, train=train)
            for i in np.unique(h["point"]):
                sel = h["point"] == i
                sse[int(i)] = (float(np.sum(h["r"][sel] ** 2)), int(sel.sum()))
            results.append(res)
        return FoldFit(results, sse)
    present = set(design.measurements())
    for f in range(folds.k):
        held = [m for m, g in folds.assign.items() if g == f and m in present]
        train = design.with_measurements([m for m, g in folds.assign.items() if g != f and m in present])
        res = fit(model, train)
        h = heldout_residuals(model, res.p, design.with_measurements(held), res.weights, res.reference_mode)
        keys = [(m, int(i)) for m, i in zip(h["measurement"], h["point"])] if folds.per_pose else h["measurement"]
        for key in dict.fromkeys(keys):
            sel = np.array([k == key for k in keys]) if folds.per_pose else h["measurement"] == key
            sse[key] = (float(np.sum(h["r"][sel] ** 2)), int(sel.sum()))
        results.append(res)
    return FoldFit(results, sse)


def cross_validate(name: str, base: FoldFit, new: FoldFit | None, threshold: float, min_improvement: float,
                   error: str | None = None) -> CVResult:
    """Compare the held-out residuals of two fold fits (see :class:`CVResult`)."""
    nan = float("nan")
    if new is None:
        return CVResult(name, nan, nan, nan, nan, threshold, 0, 0, False, f"a fold fit failed: {error}")
    ms = sorted(base.sse)
    b = np.array([base.sse[m][0] / base.sse[m][1] for m in ms])
    a = np.array([new.sse[m][0] / new.sse[m][1] for m in ms])
    rows = sum(base.sse[m][1] for m in ms)
    rms_b = math.sqrt(sum(base.sse[m][0] for m in ms) / rows)
    rms_a = math.sqrt(sum(new.sse[m][0] for m in ms) / rows)
    imp = 1.0 - rms_a / rms_b if rms_b > 0 else 0.0
    d = b - a
    if np.all(d == 0):
        p = 1.0
    else:
        p = float(stats.wilcoxon(d, alternative="greater", zero_method="wilcox").pvalue)
    wins = int(np.sum(d > 0))
    passed = p < threshold and imp >= min_improvement
    if passed:
        reason = f"held-out RMS {100 * imp:.1f} % lower, Wilcoxon p = {p:.2g} < {threshold:.2g}"
    elif p >= threshold:
        reason = f"not significant on held-out data (Wilcoxon p = {p:.2g} >= {threshold:.2g})"
    else:
        reason = (f"significant but too small: held-out RMS {100 * imp:.1f} % lower "
                  f"(at least {100 * min_improvement:g} % required)")
    return CVResult(name, rms_b, rms_a, imp, p, threshold, len(ms), wins, passed, reason, folds=new)


# ---------------------------------------------------------------------------------------------------
# results

@dataclass
class Stage:
    """One step of the loop: the model after it, its fit and the evidence that led to it.

    Attributes:
        index: 0 for the base model.
        model, result: the model and its fit on the design set.
        added: the candidate added at this stage (None for the base).
        screening: score tests at the previous fit (one per candidate then offered), ranked.
        cv: held-out evidence of the candidates tested.
        nested, alternatives: candidates whose signature lies within the added one's (they cannot be
            told from it), and candidates that alone would explain the same.
        heldout: figures of this model on the outer test set (:func:`heldout_figures`).
        plot_before, plot_after: binned estimates of the added effect's signature family at the
            previous fit and at this fit (:func:`calibration.diagnostics.binned_estimates`).
    """
    index: int
    model: ArmModel
    result: CalibrationResult
    added: Candidate | None = None
    screening: list = field(default_factory=list)
    cv: list = field(default_factory=list)
    nested: list = field(default_factory=list)
    alternatives: list = field(default_factory=list)
    heldout: dict = field(default_factory=dict)
    plot_family: str | None = None
    plot_before: dict | None = None
    plot_after: dict | None = None


@dataclass
class LoopResult:
    """What :func:`close_loop` found.

    Attributes:
        stages: the base model and one stage per effect added.
        final_screening, final_cv: the last screening and held-out tests (nothing passed, or the limit).
        stop_reason: why the loop stopped.
        structure: generic structure tests on the final fit, (Family, GroupTest, Holm-adjusted p), ranked.
        remaining: the families kept by the forward selection (conditional test, Bonferroni-adjusted p).
        verdict: a sentence; candidates, skipped: the candidate set; design, test: measurement ids.
        structure_plots: binned estimates of the significant families at the final fit.
        dropped: outlier points left out ("design": by the base fit, "test": by the base model's
            held-out residuals), with measurement, feature, line.
        test_by: the outer test set holds whole "measurement"s or "pose"s of every feature.
        power: the folds of the decisions and whether their test can reach its level (see ``_choose_folds``).
        model_fit: the final model calibrated on every point (design and test, as ``calibrate`` would with the
            same options): the model to use.
        built: every effect built from the residual (:mod:`calibration.synthesis`), in the order offered:
            name, family, joint, effect, ``added`` and, if not, ``why_not_added`` (the held-out test's or
            the screening's reason).
    """
    stages: list
    final_screening: list
    final_cv: list
    stop_reason: str
    structure: list
    remaining: list
    verdict: str
    candidates: list
    skipped: list
    design: list
    test: list
    settings: LoopSettings
    desc: ArmDescription
    structure_plots: dict = field(default_factory=dict)
    dropped: dict = field(default_factory=dict)
    test_by: str = "measurement"
    power: dict = field(default_factory=dict)
    model_fit: CalibrationResult | None = None
    built: list = field(default_factory=list)

    @property
    def final(self) -> Stage:
        return self.stages[-1]

    @property
    def added(self) -> list[Candidate]:
        return [s.added for s in self.stages[1:]]

    def before_after(self) -> list[dict]:
        """One row a stage: held-out (outer test set) figures [um], with the relative change to the base;
        ``u``: the standard uncertainty of each figure [um] (bootstrap over the test measurements, None
        with fewer than two)."""
        rows = []
        base = self.stages[0].heldout
        for s in self.stages:
            h = s.heldout
            rows.append({"stage": s.index, "model": "base model" if s.added is None else f"+ {s.added.name}",
                         "rms_um": h["rms_um"], "max_um": h["max_um"],
                         "ratio_rms": base["rms_um"] / h["rms_um"] if h["rms_um"] > 0 else float("inf"),
                         **{k: v for k, v in h["standard"].items()},
                         "u": {"rms_um": h["u_rms_um"], "max_um": h["u_max_um"], **h["u_standard"]}})
        return rows


# ---------------------------------------------------------------------------------------------------

def display(value: float, unit: str) -> tuple[float, str]:
    """A value [SI] in the report's unit: m -> um, rad -> deg, m/N -> um/N, rad/(N m) -> urad/(N m),
    1/K -> ppm/K, 1 (a gain) -> %, N unchanged."""
    extra = {"rad/(N m)": ("urad/(N m)", 1e6), "1/K": ("ppm/K", 1e6), "1": ("%", 100.0)}
    if unit in extra:
        u, f = extra[unit]
    else:
        u, f = display_unit(unit)
    return value * f, u


def effect_summary(result: CalibrationResult, cand: Candidate) -> list[dict]:
    """The added effect's parameters: name, SI value and u, display value and u, and for an eccentricity or
    joint harmonics the amplitude and phase of each harmonic (``a sin(h q + phi)``, amplitude u by linear propagation)."""
    desc = result.model.desc
    rows = []
    for name, unit in cand.effect.param_defs(desc):
        v, u = result.value(name), result.uncertainty(name)
        dv, du = display(v, unit)
        state = "free" if name in result.free else "fixed (not identifiable)"
        rows.append({"name": name, "unit": unit, "value": v, "u": u, "display_value": dv,
                     "display_u": display(u, unit)[0], "display_unit": du, "state": state})
    if cand.family in ("eccentricity", "joint_harmonics"):
        defs = [n for n, _ in cand.effect.param_defs(desc)]
        for nc, ns in zip(defs[0::2], defs[1::2]):         # (cos, sin) pairs of each harmonic
            c, s = result.value(nc), result.value(ns)
            a = math.hypot(c, s)
            ua = float("nan")
            if nc in result.free and ns in result.free and a > 0:
                ic, is_ = result.free.index(nc), result.free.index(ns)
                g = np.array([c / a, s / a])
                cov = result.cov[np.ix_([ic, is_], [ic, is_])]
                ua = float(math.sqrt(g @ cov @ g))
            rows.append({"name": nc.replace("_cos", "_amplitude", 1), "unit": "rad", "value": a, "u": ua,
                         "display_value": math.degrees(a), "display_u": math.degrees(ua), "display_unit": "deg",
                         "state": "derived", "phase_deg": math.degrees(math.atan2(c, s))})
    return rows


def _signature_overlap(space: ResidualSpace, a_cols: np.ndarray, b_cols: np.ndarray, rank_tol: float) -> float:
    """Share of b's projected signature (mean squared cosine of the principal angles) inside span(a)."""
    def basis(c):
        pc = space.project(c)
        norm = np.linalg.norm(c, axis=0)
        pc = pc / np.where(norm > 0, norm, 1.0)
        u, s, _ = np.linalg.svd(pc, full_matrices=False)
        return u[:, s > rank_tol]
    ua, ub = basis(a_cols), basis(b_cols)
    if ua.shape[1] == 0 or ub.shape[1] == 0:
        return 0.0
    return float(np.sum((ua.T @ ub) ** 2) / ub.shape[1])


def _plot(space: ResidualSpace, cand: Candidate) -> tuple[str | None, dict | None]:
    fam = candidate_family(space, cand)
    if fam is None:
        return None, None
    return fam.name, binned_estimates(space, fam)


def close_loop(points: PointSet, artefacts: Artefacts, desc: ArmDescription, *, reference: PointSet | None = None,
               effects=(), values: dict | None = None, free=None, weights: Weights | None = None,
               settings: LoopSettings | None = None, families_: tuple | None = None, extra=(), progress=None,
               **kw) -> LoopResult:
    """Calibrate, diagnose, add the best-supported effect, recalibrate ... until nothing passes.

    Args:
        points, artefacts: the campaign (``arm_model.read_points`` / ``read_artefacts``).
        desc: the arm description (nominal).
        reference: a second points file with reference (tracker) coordinates.
        effects: effects already in the base model (not candidates).
        values: starting values [SI] of parameters by name (e.g. the effect parameters of a model file);
            parameters held fixed keep them.
        free: base parameters to calibrate (names or globs; default ``calibration.calibrate.default_free``);
            the parameters of every effect are always free.
        weights: standard uncertainties of the residuals.
        settings: :class:`LoopSettings`; keyword arguments (``folds=5`` ...) override its fields.
        families_: candidate families to offer (default :data:`calibration.candidates.DEFAULT_FAMILIES`: every
            family of :data:`~calibration.candidates.FAMILIES` but ``joint_gain``).
        extra: user candidates (:class:`calibration.candidates.Candidate`).
        progress: ``callable(str)`` for progress lines.

    Raises:
        NumericalError: the base model cannot be calibrated on the design set or a training fold.
    """
    from threadpoolctl import threadpool_limits

    # many small dense solves: threaded BLAS only adds contention (8x slower on a loaded 2-core machine)
    with threadpool_limits(limits=1, user_api="blas"):
        return _close_loop(points, artefacts, desc, reference, effects, free, weights, settings, families_, extra,
                           progress, kw, values)


def _close_loop(points, artefacts, desc, reference, effects, free, weights, settings, families_, extra, progress,
                kw, values=None) -> LoopResult:
    settings = settings or LoopSettings()
    if kw:
        settings = LoopSettings(**{**settings.to_dict(), **kw})
    say = progress or progress_line(log)
    weights = stated = weights or Weights()
    has_t = points.temperature is not None and np.all(np.isfinite(points.temperature))
    need = [JointCompliance()] + ([ThermalGrowth()] if has_t else []) + list(effects) + [c.effect for c in extra]
    data = make_data(points, artefacts, needs_model(desc, need), reference=reference)
    cands, skipped = library_candidates(desc, data, families_, extra)
    design, test, test_by = _outer_split(data, settings)
    if test_by == "measurement":
        say(f"{counted(len(data), 'point')}, {counted(len(data.measurements()), 'measurement')}: {len(design.measurements())} for design, "
            f"{len(test.measurements())} held out for the test ({', '.join(test.measurements())}); "
            f"{counted(len(cands), 'candidate')}")
    else:
        say(f"{len(data)} points in {len(data.measurements())} measurement(s): too few to hold whole measurements "
            f"out, so the test set is {len(test)} poses ({100 * settings.test_fraction:g} % of each feature's), "
            f"each predicted against its feature's centre fitted on the design poses; {len(cands)} candidates")

    def test_figures(m: ArmModel, p, reference: str) -> dict:
        if test_by == "measurement":
            return heldout_figures(m, p, test, weights, reference)
        return heldout_figures(m, p, concat(design, test), weights, reference,
                               np.arange(len(design) + len(test)) < len(design))

    priors: dict[str, float] = {}

    def fit(model: ArmModel, d: CalibrationData, extra_priors: dict | None = None,
            reweight: bool = False, hold: tuple = ()) -> CalibrationResult:
        names = None
        if free is not None:
            names = [model.spec.names[i] for i in resolve_parameters(model.spec, free)]
            names += [n for n in model.spec.names[model.base_size:] if n not in names]
        if hold:
            names = [n for n in (names or default_free(model)) if n not in hold]
        return calibrate(model, d, FitOptions(free=names, values=values, weights=weights, rank_tol=settings.rank_tol,
                                              priors={**priors, **(extra_priors or {})},
                                              outlier_threshold=settings.outlier_threshold,
                                              weights_from_data=reweight and settings.weights_from_data,
                                              prior_scale=prior_scale))

    prior_scale = settings.prior_scale
    if prior_scale == "evidence":
        model0 = ArmModel(desc, tuple(effects))
        names0 = None if free is None else [model0.spec.names[i] for i in resolve_parameters(model0.spec, free)]
        prior_scale, _ = evidence_scale(model0, design, FitOptions(free=names0, values=values, weights=weights,
                                                                   rank_tol=settings.rank_tol, priors=priors))
        say(f"prior scale from the evidence of the design set: {prior_scale:g} x the plausible error sizes")

    def noise(res: CalibrationResult) -> str:
        parts = [f"{v['group']} {v['sigma_um']:.3g} um" for v in res.variance
                 if v["estimated"] and v["sigma_um"] is not None]
        return "; noise from the data: " + ", ".join(parts) if parts and res.weights_history else ""

    model = ArmModel(desc, tuple(effects))
    say("calibrating the base model on the design set")
    result = fit(model, design)
    dropped = {"design": [], "test": []}
    if settings.drop_outliers:
        result, design, dropped["design"] = _drop_design_outliers(result, design, fit)
        if dropped["design"]:
            say(f"  {len(dropped['design'])} outlier point(s) of the design set dropped (base model, robust "
                f"standardized residual > {settings.outlier_threshold:g}); they stay out of every later fit")
    off = [v for v in result.variance if v["estimated"] and not 1 / NOISE_OFF < v["factor"] < NOISE_OFF]
    if settings.weights_from_data and off:
        result = fit(model, design, reweight=True)
        weights = result.weights
        if noise(result):
            say("  " + noise(result)[2:] + " (the stated uncertainties are starting values)")
    if settings.drop_outliers:
        test, dropped["test"] = _drop_test_outliers(model, result.p, test, weights, result.reference_mode,
                                                    settings.outlier_threshold,
                                                    None if test_by == "measurement" else design)
        if dropped["test"]:
            say(f"  {len(dropped['test'])} outlier point(s) of the test set dropped (base model)")
    folds, power = _choose_folds(design, settings)
    if power["note"].startswith("WARNING: "):        # shown with --quiet too
        log.warning(power["note"][len("WARNING: "):])
    else:
        say(power["note"])
    stages = [Stage(0, model, result, heldout=test_figures(model, result.p, result.reference_mode))]
    say(f"  base model: s0 {result.s0:.3g}, held-out test RMS {stages[0].heldout['rms_um']:.2f} um")
    base_folds: FoldFit | None = None
    remaining = list(cands)
    stop, last_tests, last_cv = "", [], []
    synthesised: list[Candidate] = []      # every candidate built from the residual, in the order offered
    synthesised_here = False               # built at this stage already
    fate: dict[str, str] = {}              # synthesised candidate -> why it is not added (ADDED if it is)
    # cross-validated at this stage (reset when an effect is added): after effects are built from the residual
    # the screening runs again, and the candidates already held-out tested at this stage, which failed, are
    # not tested again; the Wilcoxon level is Bonferroni over every candidate tested at the stage
    cv_here: list[CVResult] = []
    physics_here = False                   # the physics inclusion was weighed at this stage
    while True:
        say(f"screening {len(remaining)} candidate(s) at stage {len(stages) - 1}")
        tests, space = screen_candidates(result, remaining, folds.assign, settings.rank_tol)
        ranked = sorted(zip(remaining, tests), key=lambda ct: (ct[1].p_value if np.isfinite(ct[1].p_value) else 2,
                                                               -ct[1].delta_chi2))
        last_tests, last_cv = [t for _, t in ranked], list(cv_here)
        ident = [(c, t) for c, t in ranked if t.identifiable]
        gate = settings.screen_alpha / max(len(ident), 1)
        tried = {cv.candidate for cv in cv_here}
        gated = [(c, t) for c, t in ident if t.p_value < gate and c.name not in tried][: settings.cv_top]
        for c, t in ranked:               # why each effect built from the residual is not (yet) added
            if c.origin == RESIDUAL:
                fate[c.name] = ("absorbed by the fit (the data cannot tell it from what is fitted)"
                                if not t.identifiable else
                                f"not significant at the screening (score p = {t.p_value:.2g} >= {gate:.2g})"
                                if not t.p_value < gate else
                                f"significant at the screening but not among the --cv-top {settings.cv_top} best")
        if not gated:
            if not synthesised_here and _offer_synthesised(result, model, folds.assign, settings, remaining, synthesised,
                                                           say):
                synthesised_here = True
                continue
            stop = ("no screened candidate improves the held-out data significantly" if cv_here else
                    f"no candidate passes the screening (score-test p < {gate:.2g}): nothing significant remains "
                    "that the library or an effect built from the residual explains")
            break
        if len(stages) - 1 >= settings.max_effects:
            stop = f"the maximum number of effects ({settings.max_effects}) was added"
            for c, _ in gated:
                if c.origin == RESIDUAL:
                    fate[c.name] = f"not cross-validated: {stop}"
            break
        if base_folds is None:
            say(f"  cross-validating the current model ({folds.k} folds by {folds.by})")
            base_folds = _fold_fit(model, design, folds, fit)
        threshold = settings.alpha / (len(cv_here) + len(gated))

        def _cv_of(c, t):
            cp = _candidate_priors(model.with_effects(c.effect), c, t)
            try:
                new = _fold_fit(model.with_effects(c.effect), design, folds, lambda m, d: fit(m, d, cp))
                cv = cross_validate(c.name, base_folds, new, threshold, settings.min_improvement)
                held = [k for k, r in enumerate(new.results) if not set(c.param_names(desc)) & set(r.free)]
                cv.held = bool(held)
                if held and cv.passed:
                    cv.passed = False
                    cv.reason = (f"its parameters were held (not resolved) in the training part of fold(s) "
                                 f"{', '.join(str(k + 1) for k in held)}")
            except NumericalError as exc:
                cv = cross_validate(c.name, base_folds, None, threshold, settings.min_improvement, str(exc))
            cv.score_p = t.p_value
            return cv

        def cv_named(c):                   # a candidate's held-out test, its score test looked up
            return _cv_of(c, tests[remaining.index(c)])

        def fit_design(c):                 # a candidate fitted on the design set
            m = model.with_effects(c.effect)
            return fit(m, design, _candidate_priors(m, c, tests[remaining.index(c)]))

        cvs = []
        for c, t in gated:
            say(f"  cross-validating + {c.name} (score p = {t.p_value:.2g})")
            cv = _cv_of(c, t)
            say(f"    {cv.reason}")
            cvs.append(cv)
            if c.origin == RESIDUAL:
                fate[c.name] = cv.reason if not cv.passed else "passed, but another candidate was added"
        passing = [(c, cv) for (c, _), cv in zip(gated, cvs) if cv.passed]
        if not passing and settings.physics and power["can_reach"] and not physics_here:
            physics_here = True
            got = _physics_inclusion(remaining, tests, gate, gated, cvs, cv_named, fit_design,
                                     settings.alpha / max(len(gated), 1), say)
            if got is not None:
                passing = [got]
                if all(c is not got[0] for c, _ in gated):
                    gated.append((got[0], tests[remaining.index(got[0])]))
        last_cv = cv_here + cvs
        if not passing:
            if not synthesised_here and _offer_synthesised(result, model, folds.assign, settings, remaining, synthesised,
                                                           say):
                synthesised_here = True
                cv_here = last_cv
                continue
            stop = "no screened candidate improves the held-out data significantly"
            break
        rank = {c.name: t.rank for c, t in gated}
        cand, cv = max(passing, key=lambda x: x[1].improvement)
        if cand.origin == RESIDUAL and cand.family == "joint_harmonics":
            # the harmonic order: the fewest parameters within the parsimony margin of the best held-out drop
            same = [(c, v) for c, v in passing if c.family == cand.family and c.joint == cand.joint
                    and c.effect.source == cand.effect.source and cv.improvement - v.improvement <= PARSIMONY]
            cand, cv = min(same, key=lambda x: x[0].size(desc))
        if cand.family == "joint_compliance" and cand.joint is not None:
            cand, cv = _whole_family(cand, cv, remaining, gated, cvs, cv_named, fit_design, settings.alpha, say)
        wcols = _candidate_cols(space, remaining, remaining.index(cand), tests[remaining.index(cand)])
        # parsimony: a passing candidate inside the best one's signature, with fewer parameters and nearly
        # the same held-out improvement, explains as much with less
        for c2, cv2 in sorted(passing, key=lambda x: rank[x[0].name]):
            if c2 is cand or rank[c2.name] >= rank[cand.name] or cv.improvement - cv2.improvement > PARSIMONY:
                continue
            c2cols = _candidate_cols(space, remaining, remaining.index(c2), tests[remaining.index(c2)])
            if wcols is not None and c2cols is not None and \
                    _signature_overlap(space, wcols, c2cols, settings.rank_tol) >= SAME_SIGNATURE:
                cand, cv = c2, cv2
                wcols = c2cols
                break
        # signature overlaps with the other candidates (same batch as the winner)
        nested, alternatives = [], []
        wi = remaining.index(cand)
        wcols = _candidate_cols(space, remaining, wi, tests[wi])
        for i, other in enumerate(remaining):
            if i == wi or not tests[i].identifiable:
                continue
            ocols = _candidate_cols(space, remaining, i, tests[i])
            if wcols is None or ocols is None:
                continue
            if _signature_overlap(space, wcols, ocols, settings.rank_tol) >= SAME_SIGNATURE:
                nested.append(other.name)
            if _signature_overlap(space, ocols, wcols, settings.rank_tol) >= SAME_SIGNATURE:
                alternatives.append(other.name)
        fam_name, before = _plot(space, cand)
        model = model.with_effects(cand.effect)
        priors.update(_candidate_priors(model, cand, tests[wi]))
        say(f"adding {cand.name}; recalibrating")
        old_weights, result = weights, fit(model, design, reweight=weights != stated)
        weights = result.weights
        after = None
        if fam_name is not None:
            sp2 = residual_space(result)
            fam2 = next((f for f in families(sp2) if f.name == fam_name), None) or candidate_family(sp2, cand)
            after = binned_estimates(sp2, fam2) if fam2 is not None else None
        stage = Stage(len(stages), model, result, cand, last_tests, cv_here + cvs, nested, alternatives,
                      test_figures(model, result.p, result.reference_mode), fam_name, before, after)
        stages.append(stage)
        say(f"  + {cand.name}: held-out test RMS {stage.heldout['rms_um']:.2f} um "
            f"(base {stages[0].heldout['rms_um']:.2f} um)")
        base_folds = cv.folds if weights == old_weights else None      # compared at the same weights
        synthesised_here = physics_here = False
        cv_here = []
        have = set(model.spec.names)      # e.g. the other harmonic orders of a joint once one is in
        fate[cand.name] = ADDED
        for c in remaining:
            if c is not cand and c.origin == RESIDUAL and set(c.param_names(desc)) & have:
                fate[c.name] = f"shares parameters with {cand.name}, which was added"
        remaining = [c for c in remaining if c is not cand and not set(c.param_names(desc)) & have]
        if not remaining:
            stop = "every candidate was added"
            last_tests, last_cv = [], []
            break
    say("structure tests on the final fit")
    space = residual_space(result)
    st = structure_tests(space, folds.assign, settings.rank_tol)
    adj = holm([t.p_value for _, t in st])
    structure = [(f, t, float(a)) for (f, t), a in zip(st, adj)]
    significant = [(f, t, min(1.0, t.p_value * len(structure)))
                   for f, t in remaining_structure(space, folds.assign, settings.alpha, settings.rank_tol)]
    plots = {f.name: binned_estimates(space, f) for f, _, _ in significant[:4]}
    built = [{"name": c.name, "family": c.family, "joint": c.joint, "effect": c.effect.describe(),
              "added": fate.get(c.name) == ADDED, "why_not_added": None if fate.get(c.name) == ADDED else
              fate.get(c.name, "not screened")} for c in synthesised]
    verdict = _verdict(stages, significant, stop, settings, built, model)
    say(verdict)
    say("calibrating the final model on every point (design and test; outliers kept, as calibrate does)")
    weights = stated                  # the user's uncertainties as the start, as calibrate starts
    model_fit = fit(model, data, reweight=True)
    negative = _negative_compliances(model_fit, settings.alpha)
    if negative:
        say(f"  joint compliance resolved significantly negative in the final fit ({', '.join(negative)}): a "
            "compliance cannot be negative, so it is held at zero and the final model refitted")
        model_fit = fit(model, data, reweight=True, hold=tuple(negative))
    return LoopResult(stages, last_tests, last_cv, stop, structure, significant, verdict, cands + synthesised,
                      skipped, design.measurements(), test.measurements(), settings, desc, plots, dropped, test_by,
                      power, model_fit, built)


def _outer_split(data: CalibrationData, settings: LoopSettings):
    """(design, test, "measurement" | "pose"): the measurements ``settings.holdout`` if named, else a share
    ``test_fraction`` of the measurements (per feature kind), else, with too few measurements for that, the
    same share of the poses of every feature."""
    if settings.holdout:
        design, test = split_holdout(data, list(settings.holdout))
        return design, test, "measurement"
    try:
        design, test = split_holdout(data, settings.test_fraction, settings.seed)
        return design, test, "measurement"
    except InputError:
        pass
    held = split_poses(data, settings.test_fraction, settings.seed)
    if not held.any():
        raise InputError(f"the test set is empty: {len(data.measurements())} measurement(s) and no feature has "
                         "enough poses to hold some out; give more measurements or name a test measurement "
                         "(--holdout ID)", data.points.path, None, "measurement")
    return data.select(~held), data.select(held), "pose"


def _choose_folds(design: CalibrationData, settings: LoopSettings) -> tuple[Folds, dict]:
    """The folds of the decisions and, decided before any test runs, whether the held-out test can reach
    its level with them (a one-sided Wilcoxon test over n units cannot go below p = 1/2^n)."""
    tests = settings.cv_top
    level = settings.alpha / tests
    need = wilcoxon_units_needed(settings.alpha, tests)
    n_meas = len(design.measurements())
    by = settings.fold_by
    if by == "auto":
        by = "measurement" if n_meas >= 2 else "pose"
    if by == "measurement":
        if n_meas < 2:
            raise InputError(f"{n_meas} design measurement(s): folds of whole measurements need at least 2; "
                             "fold by pose (--fold-by pose)")
        k = min(settings.folds, n_meas)
        assign = measurement_folds(design, k, settings.seed)
        per_pose = settings.fold_by == "auto" and n_meas < need
        n_poses = int(sum(np.sum(design.points.feature[design.points.measurement == m] != "") for m in assign))
        folds = Folds("measurement", k, assign, per_pose, n_poses)
    else:
        folds = Folds("pose", settings.folds, pose_folds(design, settings.folds, settings.seed))
    n = folds.units
    smallest = 0.5 ** n if n else 1.0
    ok = smallest < level
    power = {"fold_by": folds.by, "folds": folds.k, "units": n, "unit": folds.unit_name, "needed": need,
             "smallest_p": smallest, "level": level, "can_reach": ok}
    why = ""
    if folds.by == "pose" and settings.fold_by == "auto":
        why = f" (only {n_meas} design measurement: whole measurements cannot be held out)"
    elif folds.per_pose:
        why = (f", {folds.k} of {n_meas} measurements held out in turn, the test over their poses (each against "
               f"its measurement's own centre: {n_meas} measurements are too few units)")
    if ok:
        power["note"] = (f"decisions: {folds.k} folds by {by}{why}; one-sided Wilcoxon over {n} {folds.unit_name} "
                         f"(smallest possible p = 1/2^{n} < {level:.2g} = alpha / {tests} candidates)")
    else:
        fix = ("more measurements, or folds by pose (--fold-by pose)" if by == "measurement"
               else "more poses on each feature, or more measurements")
        power["note"] = (f"WARNING: the held-out test cannot reach its level with these data: one-sided Wilcoxon "
                         f"over {n} {folds.unit_name} has smallest p = 1/2^{n} = {smallest:.3g} >= "
                         f"{level:.2g} = alpha {settings.alpha:g} / {tests} candidates; it needs at least {need} "
                         f"{folds.unit_name} (n >= log2({tests} / {settings.alpha:g})): {fix}, or a larger "
                         f"--alpha or a smaller --cv-top. No effect can be added.")
    return folds, power


def _offer_synthesised(result, model, fold_of, settings, remaining: list, synthesised: list, say) -> bool:
    """When the library is exhausted: the structure families still significant at ``result`` (forward
    selection, Bonferroni, held-out explained variance > 0) become candidate effects
    (:func:`calibration.synthesis.synthesise`), appended to ``remaining`` (and ``synthesised``) to be
    screened and cross-validated like any candidate. Returns whether any new candidate was offered."""
    if not settings.synthesise:
        return False
    kept = remaining_structure(residual_space(result), fold_of, settings.alpha, settings.rank_tol)
    if not kept:
        return False
    known = {c.name for c in remaining} | {c.name for c in synthesised}
    new = [c for c in synthesise([f.name for f, _ in kept], model) if c.name not in known]
    if not new:
        return False
    say(f"  structure remains ({', '.join(f.name for f, _ in kept)}): offering "
        f"{', '.join(c.name for c in new)} (built from the residual)")
    remaining.extend(new)
    synthesised.extend(new)
    return True


def _drop_design_outliers(result: CalibrationResult, design: CalibrationData, fit, max_share: float = 0.1):
    """Drop the worst outlier point of the base fit and refit, in rounds, until none is left (at most
    ``max_share`` of the points); a feature instance left with too few points goes out whole. Returns the
    last fit, the data kept and the dropped points (measurement, feature, line, standardized residual)."""
    out = []
    for _ in range(max(1, int(max_share * len(design)))):
        cands = [o for o in result.outliers if o.point is not None]
        if not cands:
            break
        worst = max(cands, key=lambda o: abs(o.standardized))
        pts = design.points
        inst = (pts.measurement == pts.measurement[worst.point]) & (pts.feature == pts.feature[worst.point])
        kind = design.artefacts.features[pts.feature[worst.point]].kind if pts.feature[worst.point] else "point"
        drop = [worst.point]
        if kind in MIN_POINTS and int(inst.sum()) - 1 < MIN_POINTS[kind][0]:
            drop = list(np.flatnonzero(inst))
        for i in drop:
            out.append({"measurement": str(pts.measurement[i]), "feature": str(pts.feature[i]),
                        "line": None if pts.lines is None else int(pts.lines[i]),
                        "standardized": float(worst.standardized) if i == worst.point else None,
                        "why": "outlier" if i == worst.point else "its feature instance has too few points left"})
        design = design.select(np.setdiff1d(np.arange(len(design)), drop))
        result = fit(result.model, design)
    return result, design, out


def _drop_test_outliers(model, p, test: CalibrationData, weights, reference, threshold, design=None):
    """Points of the test set whose weighted residual under the base model (nuisance solved on the test set,
    or, with ``design``, on the design poses of the same features) exceeds ``threshold`` robust standard
    deviations of its observation group (:func:`calibration.calibrate.grouped_standardized`, the scale
    ``calibrate`` flags outliers on); decided before any effect is added, so it favours no model.
    Returns the test set without them and their descriptions."""
    if design is None:
        h = heldout_residuals(model, p, test, weights, reference)
        point = h["point"]
    else:
        h = heldout_residuals(model, p, concat(design, test), weights, reference,
                              np.arange(len(design) + len(test)) < len(design))
        point = np.where(h["point"] >= 0, h["point"] - len(design), -1)
    z = grouped_standardized(h["r"], 0.0, h["kind"])
    pts = test.points
    bad = sorted(set(int(i) for i in point[(np.abs(z) > threshold) & (point >= 0)]))
    if not bad:
        return test, []
    out = [{"measurement": str(pts.measurement[i]), "feature": str(pts.feature[i]),
            "line": None if pts.lines is None else int(pts.lines[i]),
            "standardized": float(np.max(np.abs(z[point == i]))), "why": "outlier"} for i in bad]
    if design is None:
        # a feature instance left with too few points for its own fit goes out whole (as in the design set)
        for m, f in sorted({(str(pts.measurement[i]), str(pts.feature[i])) for i in bad}):
            kind = test.artefacts.features[f].kind if f else "point"
            inst = np.flatnonzero((pts.measurement == m) & (pts.feature == f))
            if kind in MIN_POINTS and len(np.setdiff1d(inst, bad)) < max(MIN_POINTS[kind]):
                more = [int(i) for i in np.setdiff1d(inst, bad)]
                out += [{"measurement": m, "feature": f, "line": None if pts.lines is None else int(pts.lines[i]),
                         "standardized": None, "why": "its feature instance has too few points left"} for i in more]
                bad = sorted(set(bad) | set(more))
    keep = np.setdiff1d(np.arange(len(test)), bad)
    return test.select(keep), out


def _whole_family(cand: Candidate, cv: CVResult, remaining: list, gated: list, cvs: list, cross_validate_,
                  fit_design, alpha: float, say):
    """A joint compliance is a property of the arm, and under gravity the joints deflect together: when one
    loaded joint's compliance is supported on held-out data, the compliance of every loaded joint (one
    candidate) replaces it if (1) fitted on the design set it resolves the compliance of at least one
    other joint as non-zero (|c| > z u, z two-sided at ``alpha`` with Bonferroni over those joints) and
    (2) it does not predict the held-out data worse (positive relative improvement). Within one plate
    placement the gravity torques of the joints move together, so its held-out poses favour the one joint
    whose signature is plainest; the deflection of every compliant joint is what carries over to the rest
    of the workspace. A compliance of one joint alone (a measuring arm's shoulder) stays that joint's.
    Returns the (candidate, CV result) to add."""
    every = next((c for c in remaining if c.family == cand.family and c.joint is None), None)
    if every is None:
        return cand, cv
    res = fit_design(every)
    own = set(cand.param_names(res.model.desc))
    others = [n for n in every.param_names(res.model.desc) if n not in own and n in res.free]
    if not others:
        return cand, cv
    z, neg, pos = _resolved(res, others, alpha)
    resolved = [n for n in others if n in neg or n in pos]
    if not resolved:
        say(f"  {every.name}: no other joint's compliance resolved as non-zero (|c| > {z:.2f} u); "
            f"keeping {cand.name}")
        return cand, cv
    got = next((v for (c, _), v in zip(gated, cvs) if c is every), None)
    if got is None:
        say(f"  cross-validating + {every.name} (other joints resolved: {', '.join(resolved)})")
        got = cross_validate_(every)
        say(f"    {got.reason}")
        cvs.append(got)
    if np.isfinite(got.improvement) and got.improvement > 0 and not got.held:
        say(f"  {cand.name} is supported and the design set resolves {', '.join(resolved)}: taking "
            f"{every.name} (held-out RMS {100 * got.improvement:.1f} % lower than the current model's)")
        return every, got
    return cand, cv


def _resolved(res: CalibrationResult, names: list, level: float) -> tuple[float, list, list]:
    """``(z, negative, positive)``: the parameters ``names`` of ``res`` resolved below ``-z u`` and above
    ``z u``, z two-sided at ``level`` with Bonferroni over ``names``."""
    z = float(stats.norm.isf(level / (2 * len(names))))
    return (z, [n for n in names if res.value(n) < -z * res.uncertainty(n)],
            [n for n in names if res.value(n) > z * res.uncertainty(n)])


def _negative_compliances(res: CalibrationResult, level: float) -> list[str]:
    """The joint compliances of ``res`` resolved significantly negative (:func:`_resolved` over the free
    joint compliances): not a physical compliance."""
    names = [n for n in res.free if n.endswith(".compliance") and not n.startswith("probe.")]
    return _resolved(res, names, level)[1] if names else []


def _physics_inclusion(remaining, tests, gate, gated, cvs, cross_validate_, fit_design, level, say):
    """Joint compliance under gravity (every loaded joint, the arm's masses) when no candidate improves the
    held-out poses significantly: every arm bends under its own weight, and held-out poses of the same
    plate placement cannot show what a compliance is worth elsewhere (their gravity torques differ little
    from the training poses', so the geometry absorbs most of its signature there; on the real Panda data,
    trained on one placement, the compliances make the held-out poses of that placement 6 % worse and the
    other placements' seat spread 27-44 % smaller). It is included, as physics and not as a held-out gain,
    when all of these hold:

    * its score test is significant (``p < gate``, the screening's Bonferroni level);
    * fitted on the design set, at least one joint's compliance is resolved positive and none is
      significantly negative (``|c| > z u``, z two-sided at ``level`` with Bonferroni over the joints):
      a negative compliance is not a compliance, the signature would be something else's;
    * the held-out poses are not significantly worse (one-sided Wilcoxon ``p_worse >= level``) and its
      parameters were resolved in every fold.

    Returns ``(candidate, CVResult)`` (passed, its reason saying why) or None."""
    every = next((c for c in remaining if c.family == "joint_compliance" and c.joint is None), None)
    if every is None:
        return None
    t = tests[remaining.index(every)]
    if not (t.identifiable and t.p_value < gate):
        return None
    res = fit_design(every)
    names = [n for n in every.param_names(res.model.desc) if n in res.free]
    if not names:
        return None
    z, neg, pos = _resolved(res, names, level)
    say(f"  physics check of {every.name}: score p = {t.p_value:.2g} < {gate:.2g}; resolved positive: "
        f"{', '.join(pos) or 'none'}; significantly negative: {', '.join(neg) or 'none'} (z = {z:.2f})")
    if neg or not pos:
        return None
    got = next((v for (c, _), v in zip(gated, cvs) if c is every), None)
    if got is None:
        got = cross_validate_(every)
        cvs.append(got)
    p_worse = 1.0 - got.p_value if np.isfinite(got.p_value) else 0.0
    if got.held or p_worse < level:
        say(f"    held-out poses significantly worse (p = {p_worse:.2g}) or parameters held: not included")
        return None
    got.passed = True
    got.reason = (f"{PHYSICS}: its gravity signature is significant (score p = {t.p_value:.2g}), the "
                  f"compliances {', '.join(pos)} are resolved positive and none is negative; held-out poses of "
                  f"this placement {100 * got.improvement:+.1f} % (not significantly worse, p = {p_worse:.2g})")
    say(f"    {got.reason}")
    return every, got


def _candidate_priors(model: ArmModel, cand: Candidate, test: GroupTest) -> dict[str, float]:
    """Plausible sizes of a candidate's parameters for ``calibrate``'s practical-identifiability check:
    at least ten times the screening's one-step estimate, so that a parameter the data resolve to better
    than its own estimated size stays free (the held-out test decides whether it helps)."""
    names = cand.param_names(model.desc)
    default = prior_scales(model, names)
    out = {}
    for n, d, b in zip(names, default, test.estimate):
        out[n] = float(max(d, 10.0 * abs(b))) if np.isfinite(b) else float(d)
    return out


def _candidate_cols(space: ResidualSpace, remaining: list, i: int, test: GroupTest):
    """Raw columns of candidate ``i`` in ``space`` without those the screening found absorbed (None if it
    was screened in another batch)."""
    effects = [e for e in space.model.effects]
    try:
        k = next(n for n, e in enumerate(effects[len(space.result.model.effects):]) if e is remaining[i].effect)
    except StopIteration:
        return None
    keep = [j for j, n in enumerate(test.names) if n not in test.absorbed]
    return space.jp[:, space.extra_slices[k]][:, keep]


#: residual standard deviation factor above which the residual is not noise at the stated level
S0_LIMIT = 3.0
#: the fate of a synthesised candidate that was added
ADDED = "added"


def _verdict(stages, significant, stop, settings, built=(), model: ArmModel | None = None) -> str:
    """What was added (and how much the held-out error dropped), what was built from the residual and not
    added (and why), and what structure remains unexplained."""
    def label(s):
        if any(cv.candidate == s.added.name and cv.reason.startswith(PHYSICS) for cv in s.cv):
            return " (included as physics, not for a held-out gain)"
        return " (found from the residual)" if s.added.origin == RESIDUAL else ""

    added = [s.added.name + label(s) for s in stages[1:]]
    s0 = stages[-1].result.s0
    out = ("effects added: " + ", ".join(added) if added else "no effect added")
    base, last = stages[0].heldout, stages[-1].heldout
    if added:
        out += (f"; held-out test RMS {base['rms_um']:.2f} -> {last['rms_um']:.2f} um, "
                f"max {base['max_um']:.2f} -> {last['max_um']:.2f} um")
    not_added = [b for b in built if not b["added"]]
    if not_added:
        out += (". Built from the residual, not supported, not added: "
                + "; ".join(f"{b['name']} ({b['why_not_added']})" for b in not_added))
    if not significant and s0 > S0_LIMIT:
        return out + (f". The final residual is s0 = {s0:.3g} times the stated uncertainties: it is not noise at the "
                      "stated level, but no tested regressor family explains it (wrong weights, or structure "
                      "beyond the tests). No fix is claimed.")
    if not significant:
        return out + (". No structured residual remains (no regressor family is significant after Bonferroni's "
                      "correction).")
    fams = "; ".join(f"{f.name} ({t.best})" if t.best else f.name for f, t, _ in significant)
    nothing = []
    if settings.synthesise and model is not None:
        nothing = [f.name for f, _, _ in significant if not synthesise([f.name], model)]
    why = (" (effects are not built from the residual: library only)" if not settings.synthesise else
           f" (no further effect is built for {', '.join(nothing)})" if nothing else "")
    built_by = " nor by the effects built from it" if not_added else ""
    return (out + f". Structured residual remains, not explained by the effect library{built_by}{why}: it "
            f"correlates with {fams}. No fix is claimed for it.")
