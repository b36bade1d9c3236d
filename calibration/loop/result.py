"""What the closed loop returns: one :class:`Stage` per model (the base and one per effect added) and the
:class:`LoopResult`, with the display helpers of the added effects' parameters."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from arm_model.description import ArmDescription
from arm_model.model import ArmModel

from ..calibrate import CalibrationResult, display_unit
from ..candidates import Candidate
from ..data import CalibrationData
from .settings import LoopSettings

__all__ = ["Stage", "LoopResult", "display", "effect_summary"]


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
        tie: the candidates the held-out units could not tell from the one added, their scores, the one chosen
            and the rule (:func:`calibration.loop.decide.resolve_tie`); None when there was no tie.
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
    tie: dict | None = None


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
        dropped: outlier points left out ("design": by the base fit), with measurement, feature, file and line.
        test_by: the outer test set holds whole "measurement"s or "pose"s of every feature.
        power: the folds of the decisions and whether their test can reach its level (see
        :func:`~calibration.loop.folds.choose_folds`).
        model_fit: the final model calibrated on every point (design and test, as ``calibrate`` would with the
            same options): the model to use.
        built: every effect built from the residual (:mod:`calibration.synthesis`), in the order offered:
            name, family, joint, effect, ``added`` and, if not, ``why_not_added`` (the held-out test's or
            the screening's reason).
        data: every point of the campaign (outliers included).
        vetoed: candidates that passed the held-out folds of the design set but made the outer test set worse:
            name, origin, ``heldout_rms_before_um``, ``heldout_rms_after_um``, the cross-validation's reason.
        residual_over_stated: the final design fit's residual scatter over the stated uncertainties
            (:func:`~calibration.loop.verdict.residual_over_stated`; above
            :data:`~calibration.loop.verdict.S0_LIMIT` with no family left, the verdict says it is not noise).
        heldout_check: the judgement of the outer test set of the final model
            (:func:`~calibration.loop.verdict.heldout_check`): ``worse_than_stated`` and its figures, None when it
            cannot be made.
        escalated: the opt-in families offered because the outer test set was worse than stated after the default
            ones (``families``, ``candidates``, ``check``), None if not.
        flagged: the test points the base model's point test flags, as ``dropped``'s entries: kept in every
            held-out figure (the stages' ``heldout`` also give the headline figures without them, labelled).
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
    vetoed: list = field(default_factory=list)
    data: CalibrationData | None = None
    residual_over_stated: float | None = None
    heldout_check: dict | None = None
    escalated: dict | None = None
    flagged: list = field(default_factory=list)

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
                         "rms_um_unflagged": h.get("rms_um_unflagged"), "max_um_unflagged": h.get("max_um_unflagged"),
                         # below 1 pm a figure is rounding: no ratio (as calibrate's, validation.figure_rows)
                         "ratio_rms": base["rms_um"] / h["rms_um"] if h["rms_um"] >= 1e-6 else None,
                         **{k: v for k, v in h["standard"].items()},
                         "u": {"rms_um": h["u_rms_um"], "max_um": h["u_max_um"], **h["u_standard"]}})
        return rows


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
    joint harmonics the amplitude and phase of each harmonic (``a sin(h q + phi)``, amplitude u by linear
    propagation); a pair's, part by part."""
    if cand.parts:
        return [row for c in cand.parts for row in effect_summary(result, c)]
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
        for nc, ns in zip(defs[0::2], defs[1::2], strict=True):         # (cos, sin) pairs of each harmonic
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


