"""Gross points: the design set's left out before any effect is weighed, by the base fit; the test set's flagged,
never left out, by the base model with its parameters held (decided once, so they favour no model). Both are
``calibrate``'s own default gross-error rule (:func:`calibration.calibrate.calibrate` with its ``gross_threshold``,
:data:`~calibration.options.GROSS_THRESHOLD`, at the noise the fit estimates): a point's rows tested together by
their group deletion (the shared leverage solve of :func:`calibration.discrepancy.point_tests`), the largest left
out and the fit redone, one at a time; a point its feature needs is kept. One rule, one threshold: the loop's own
at 4 at the stated sigmas dropped clean postures of the real TALOS capture that ``calibrate`` keeps (random
halves 0.793 / 0.674 mm against ``calibrate``'s 0.684 / 0.679). Points only: a certified length off under the
base model is the evidence of what the model lacks (thermal growth, a scale error), which the loop is there to
find (dropped, a simulated thermal campaign's test set lost its 14.6-sigma ball bar and the held-out gain of
thermal growth fell from 53 % to 16 %). A held-out figure that leaves out the points the test flags is not a
prediction of the test set: it drops the hardest points, so the loop's figures keep them and give the figures
without them beside, labelled."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..calibrate import GROSS_SHARE, CalibrationResult, Outlier, calibrate
from ..data import CalibrationData, concat
from ..kinds import MIN_POINTS
from ..options import FitOptions

__all__ = ["drop_design_outliers", "flag_test_outliers", "dropped_entry", "outlier_budget"]


def outlier_budget(points: int) -> int:
    """The most points the loop leaves out as gross errors in a campaign of ``points`` (design and test sets
    together): :data:`~calibration.calibrate.GROSS_SHARE` of them, at least one, as ``calibrate``'s default. More
    is not gross errors but what the base model lacks, the very thing the loop looks for (dropped, a hidden
    encoder gain's largest errors went out of the test set and the loop stopped with "outliers remain")."""
    return max(1, int(GROSS_SHARE * points))


def dropped_entry(o: Outlier) -> dict:
    """The loop's description of a point left out (``summary.json`` ``outliers_dropped``)."""
    return {"measurement": o.measurement, "feature": o.feature, "file": o.file, "line": o.line,
            "standardized": abs(float(o.standardized)), "why": "outlier"}


def drop_design_outliers(design: CalibrationData, fit) -> tuple[CalibrationResult, CalibrationData, list]:
    """The base fit of ``design`` by ``fit(data, gross=True)`` (the loop's
    :meth:`~calibration.loop.state.LoopState.fit` of the base model): calibrate's default fit with its gross
    errors left out; returns that fit, the data it kept and what it left out (:func:`dropped_entry`)."""
    res = fit(design, gross=True)
    return res, res.data, [dropped_entry(g.outlier) for g in res.gross]


def flag_test_outliers(model, p, test: CalibrationData, weights, reference, design=None, limit=None):
    """The gross points of the test set under the base model ``(model, p)``: those calibrate's gross-error rule
    (:data:`~calibration.options.GROSS_THRESHOLD`) leaves out with every parameter held at ``p`` and the noise
    ``weights`` (only the nuisance unknowns fitted: the test measurements' centres and frames, or, with
    ``design``, each feature's over its design and test poses, only the test poses then being tested); with them
    the other points of a test instance they leave with too few points for its own fit (:func:`_too_small`); at
    most ``limit`` points tested out (None: calibrate's 5 %).
    Returns (a (len(test),) bool mask of those points, their entries, :func:`dropped_entry`)."""
    data = test if design is None else concat(design, test)
    offset = 0 if design is None else len(design)
    values = {n: float(v) for n, v in zip(model.spec.names, p, strict=True)}
    res = calibrate(model, data, FitOptions(values=values, free=[], weights=weights, reference=reference,
                                            prior_scale=None, discrepancy=False, outlier_lengths=False,
                                            outlier_limit=limit))
    mine = [replace(g.outlier, point=g.outlier.point - offset) for g in res.gross
            if g.outlier.point is not None and g.outlier.point >= offset]
    out = [dropped_entry(o) for o in mine]
    bad = [o.point for o in mine]
    if design is None:
        bad += _too_small(test, bad, out)
    mask = np.zeros(len(test), bool)
    mask[np.asarray(bad, int)] = True
    return mask, out


def _too_small(test: CalibrationData, bad: list, out: list) -> list:
    """The other points of every test instance that losing its gross points ``bad`` left with no more points than
    its own fit needs (:data:`~calibration.kinds.MIN_POINTS`, the larger count: a held-out instance is predicted by
    its own fit): none of them can be tested by deletion any more, and an instance half gross masks its gross
    points (a sphere of eight, four of them 1 mm off: the point test dropped three, one a clean one, and left
    five); their entries are appended to ``out``."""
    pts, more = test.points, []
    for m, f in sorted({(str(pts.measurement[i]), str(pts.feature[i])) for i in bad}):
        kind = test.artefacts.features[f].kind if f else "point"
        left = np.setdiff1d(np.flatnonzero((pts.measurement == m) & (pts.feature == f)), bad)
        if kind in MIN_POINTS and len(left) <= max(MIN_POINTS[kind]):
            more += [int(i) for i in left]
            out += [{"measurement": m, "feature": f, "file": test.file_of(i),
                     "line": None if pts.lines is None else int(pts.lines[i]),
                     "standardized": None, "why": "its feature instance has too few points left"} for i in left]
    return more
