"""Cross-validation of one candidate: the current model and the model with the candidate calibrated on each
fold's training part, their held-out residuals per unit, and the one-sided Wilcoxon signed-rank test that
compares them (:class:`CVResult`)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from arm_model.model import ArmModel

from ..data import CalibrationData
from ..validation import heldout_residuals, unit_sse
from .folds import Folds
from .settings import STABLE_MARGIN

__all__ = ["FoldFit", "CVResult", "fold_fit", "warm_start", "cross_validate"]


@dataclass
class FoldFit:
    """The fits of one model on each fold's training part and their held-out residual rows."""
    results: list                     # CalibrationResult per fold
    sse: dict                         # measurement -> (sum of squared weighted residuals, rows)
    fold: dict = field(default_factory=dict)   # unit (a key of ``sse``) -> the fold that held it out


@dataclass
class CVResult:
    """Held-out evidence for adding one candidate.

    Attributes:
        rms_base, rms_new: pooled held-out weighted RMS of the current model and with the candidate.
        improvement: ``1 - rms_new / rms_base``.
        p_value: one-sided Wilcoxon signed-rank test over held-out measurements (mean squared weighted
            residual of each); threshold: the level it was held to (``alpha / tested``).
        wins: measurements improved, of ``n_measurements``.
        fold_change: each fold's relative held-out RMS change with the candidate (:func:`fold_changes`, positive:
            better); stability: the share of the folds better. Passing needs ``p_value < threshold`` and the
            held-out RMS lower by at least ``min_improvement`` in the pool, and in every fold when ``p_value`` is
            within ``STABLE_MARGIN`` of the threshold (``stable_needed``;
            :data:`~calibration.loop.settings.STABILITY_RULE`).
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
    fold_change: tuple = ()
    stable_needed: bool = True    # p within STABLE_MARGIN of the level: every fold must be better

    @property
    def stability(self) -> float:
        """Share of the folds whose held-out RMS the candidate lowers (nan: no fold figures)."""
        return float(np.mean([c > 0 for c in self.fold_change])) if self.fold_change else float("nan")

    def to_dict(self) -> dict:
        def num(v):
            return float(v) if v is not None and math.isfinite(float(v)) else None
        return {"candidate": self.candidate, "heldout_rms_weighted_before": num(self.rms_base),
                "heldout_rms_weighted_after": num(self.rms_new), "relative_improvement": num(self.improvement),
                "wilcoxon_p_value": num(self.p_value), "threshold": num(self.threshold),
                "measurements": self.n_measurements, "measurements_improved": self.wins, "passed": self.passed,
                "reason": self.reason, "screening_p_value": num(self.score_p), "stability": num(self.stability),
                "stability_required": 1.0 if self.stable_needed else 0.0,
                "fold_relative_improvements": [num(v) for v in self.fold_change]}

def _not_worse_than_nested(res, nested, model: ArmModel, data: CalibrationData, fit):
    """``res``, or, when it ends at a higher cost than ``nested`` (the fit of a model that ``model`` contains, on
    the same data and weights: its own optimum can be no higher, so ``res`` stopped in another basin), the fit
    started from ``nested``'s solution (the added parameters at zero) if that ends lower."""
    if nested is None or not res.cost > nested.cost:
        return res
    again = fit(model, data, discrepancy=False, start=warm_start(nested))
    return again if again.cost < res.cost else res


def warm_start(result) -> dict:
    """The free parameters of a fit by name [SI]: the start of another fit of the same or a larger model."""
    return {n: float(v) for n, v in zip(result.model.spec.names, result.p, strict=True) if n in result.free}


def fold_fit(model: ArmModel, design: CalibrationData, folds: Folds, fit, nested: FoldFit | None = None,
             start: dict | None = None) -> FoldFit:
    """``model`` fitted on each fold's training part by ``fit(model, data, discrepancy=False)`` (the loop's
    :meth:`~calibration.loop.state.LoopState.fit`; a fold's fit only predicts its held-out units, so it estimates
    no model discrepancy) and its held-out residuals per unit. ``nested``: the same folds' fits of a model that
    ``model`` contains (the current model, ``model`` that plus a candidate): a fold whose fit ends at a higher
    cost than the nested model's is fitted again from the nested solution (:func:`_not_worse_than_nested`;
    measured: a linear coupling of two joints fitted from the nominal stopped at 4.7 times the noise in two folds
    of four, where the nested model stopped at 1). ``start``: where every fold's fit starts (:func:`warm_start`
    of the design set's fit: the folds' training parts are most of it; from the nominal, the current model's own
    fold fits stopped at 4.4-4.8 times the noise in two folds of four on that campaign, its design fit at 1).
    A fold's held-out units are predicted as the outer test set is (:func:`~calibration.validation.heldout_residuals`):
    the instrument's frames and marker offsets those of the fold's training fit, never refitted on the units."""
    results, sse, fold = [], {}, {}
    if folds.by == "pose":
        for f in range(folds.k):
            train = np.asarray(folds.assign) != f
            res = fit(model, design.select(train), discrepancy=False, start=start)
            res = _not_worse_than_nested(res, None if nested is None else nested.results[f], model,
                                         design.select(train), fit)
            h = heldout_residuals(model, res.p, design, res.weights, res.reference_mode, train=train)
            got = unit_sse([int(i) for i in h["point"]], h["r"])
            sse.update(got)
            fold.update(dict.fromkeys(got, f))
            results.append(res)
        return FoldFit(results, sse, fold)
    present = set(design.measurements())
    for f in range(folds.k):
        held = [m for m, g in folds.assign.items() if g == f and m in present]  # type: ignore[attr-defined]
        train = design.with_measurements([m for m, g in folds.assign.items() if g != f and m in present])  # type: ignore[attr-defined]
        res = fit(model, train, discrepancy=False, start=start)
        res = _not_worse_than_nested(res, None if nested is None else nested.results[f], model, train, fit)
        h = heldout_residuals(model, res.p, design.with_measurements(held), res.weights, res.reference_mode,
                              tracker=res.tracker)
        keys = ([(m, int(i)) for m, i in zip(h["measurement"], h["point"], strict=True)] if folds.per_pose
                else list(h["measurement"]))
        got = unit_sse(keys, h["r"])
        sse.update(got)
        fold.update(dict.fromkeys(got, f))
        results.append(res)
    return FoldFit(results, sse, fold)


def one_sided(d: np.ndarray) -> float:
    """One-sided Wilcoxon signed-rank p-value that the differences ``d`` are positive (1 when all are 0 or none)."""
    if len(d) == 0 or np.all(d == 0):
        return 1.0
    return float(stats.wilcoxon(d, alternative="greater", zero_method="wilcox").pvalue)


def fold_changes(base: FoldFit, new: FoldFit, units: list) -> tuple:
    """Relative change of each fold's held-out RMS with the candidate (``1 - rms_new / rms_base`` over the rows of
    the fold's held-out ``units``; positive: better), in fold order."""
    out = []
    for f in sorted({base.fold.get(m, -1) for m in units}):
        mine = [m for m in units if base.fold.get(m, -1) == f]
        b, a = sum(base.sse[m][0] for m in mine), sum(new.sse[m][0] for m in mine)
        out.append(1.0 - math.sqrt(a / b) if b > 0 else 0.0)
    return tuple(out)


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
    p = one_sided(d)
    change = fold_changes(base, new, ms)
    near = p >= threshold / STABLE_MARGIN
    worse = [k + 1 for k, c in enumerate(change) if not (c > 0 and c >= min_improvement)] if near else []
    wins = int(np.sum(d > 0))
    passed = p < threshold and not worse and imp >= min_improvement
    folds = ", ".join(f"{100 * c:+.1f} %" for c in change)
    if passed:
        reason = (f"held-out RMS {100 * imp:.1f} % lower, Wilcoxon p = {p:.2g} < {threshold:.2g}, "
                  + ("every fold better" if near else f"below the level by more than {STABLE_MARGIN:g}x")
                  + f" (by fold: {folds})")
    elif p >= threshold:
        reason = f"not significant on held-out data (Wilcoxon p = {p:.2g} >= {threshold:.2g})"
    elif worse:
        reason = (f"not stable: Wilcoxon p = {p:.2g} < {threshold:.2g} (within {STABLE_MARGIN:g}x of it), but fold(s) "
                  f"{', '.join(str(k) for k in worse)} of {len(change)} not "
                  + (f"{100 * min_improvement:g} % " if min_improvement > 0 else "")
                  + f"better with it (held-out RMS {folds} lower by fold)")
    else:
        reason = (f"significant but too small: held-out RMS {100 * imp:.1f} % lower "
                  f"(at least {100 * min_improvement:g} % required)")
    return CVResult(name, rms_b, rms_a, imp, p, threshold, len(ms), wins, passed, reason, folds=new,
                    fold_change=change, stable_needed=near)


