"""Gross points left out before any effect is weighed: the design set's by the base fit, the test set's by
the base model's held-out residuals (decided once, so they favour no model)."""
from __future__ import annotations

import numpy as np

from ..calibrate import CalibrationResult, grouped_standardized
from ..data import CalibrationData, concat
from ..kinds import MIN_POINTS
from ..validation import heldout_residuals

__all__ = ["drop_design_outliers", "drop_test_outliers"]


def drop_design_outliers(result: CalibrationResult, design: CalibrationData, fit, max_share: float = 0.1):
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


def drop_test_outliers(model, p, test: CalibrationData, weights, reference, threshold, design=None):
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

