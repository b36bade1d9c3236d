"""The reference instrument's frames and markers as a fit sees them, for predictions on other data.

A held-out figure on reference (tracker) points is a prediction only when the frames of the instrument
and the markers' offsets come from the training fit (:meth:`calibration.data.CalibrationData.
with_tracker`): fitted again on the held-out points they would absorb part of the model's error. The
nominal model is compared like for like: its own frames and offsets, fitted on the same training data
(:func:`fit_tracker`).
"""
from __future__ import annotations

import numpy as np

from arm_model.model import ArmModel
from arm_model.tracker import Tracker

from .data import CalibrationData, Weights
from .kinds import MIN_POINTS
from .problem import Problem
from .solver import levenberg_marquardt

__all__ = ["fit_tracker", "has_reference", "own_frames_fit", "as_predicted", "held_unknowns"]


def has_reference(data: CalibrationData) -> bool:
    """True when some row of ``data`` carries reference coordinates."""
    ref = data.reference
    return ref is not None and bool(np.any(np.all(np.isfinite(ref), axis=1)))


def own_frames_fit(data: CalibrationData) -> bool:
    """True when every session of ``data`` has the reference points a frame of its own needs
    (:data:`calibration.kinds.MIN_POINTS`)."""
    ref = data.reference
    rows = np.all(np.isfinite(ref), axis=1) if ref is not None else np.zeros(len(data), bool)
    _, counts = np.unique(data.sessions[rows].astype(str), return_counts=True)
    return bool(np.all(counts >= MIN_POINTS["reference"][0]))


def fit_tracker(model: ArmModel, p, data: CalibrationData, weights: Weights | None = None,
                reference: str = "fit") -> Tracker | None:
    """The frames and marker offsets that fit ``data`` best with the parameters held at ``p`` (full vector,
    SI; every other nuisance unknown fitted with them), or None when ``data`` has no reference coordinates."""
    if not has_reference(data):
        return None
    prob = Problem(model, data, weights or Weights(), [], distances=False, reference=reference)
    states = levenberg_marquardt(prob, np.asarray(p, float), prob.initial_states(p)).states
    prob.check_tracker(p, states)
    return prob.tracker(states)


def as_predicted(data: CalibrationData, tracker: Tracker | None, reference: str = "fit") -> CalibrationData:
    """Held-out ``data`` as a prediction sees them, the one rule of every held-out figure (``calibrate``'s
    validation, :func:`calibration.validation.validate` and :func:`~calibration.validation.heldout_residuals`, and
    so the loop's outer test set and folds): the instrument's frame of every session ``tracker`` (the training
    fit's) has one for, and the markers' offsets, held at the training fit's values; a session the training data
    never saw keeps its frame unknown, to be solved on the held-out points (for the nominal baseline exactly as
    for the calibrated model). ``data`` unchanged without a tracker, reference coordinates or ``reference``
    "fit" (frames not estimated)."""
    if tracker is None or reference != "fit" or not has_reference(data):
        return data
    return data.with_tracker(tracker)


def held_unknowns(data: CalibrationData, reference: str = "fit") -> int:
    """How many nuisance unknowns of ``data``'s reference rows are held at another fit's values
    (:func:`as_predicted`): 6 for each session's frame its tracker has, 3 for each marker's offset when the
    offsets are unknowns."""
    tr, ref = data.tracker, data.reference
    if tr is None or reference != "fit" or ref is None:
        return 0
    rows = np.all(np.isfinite(ref), axis=1)
    frames = sum(6 for s in set(data.sessions[rows].astype(str).tolist()) if tr.frame(s) is not None)
    free = rows & (np.asarray(data.points.feature) == "")            # a marker on the tip, not a tracker nest
    markers = (3 * len(set(data.markers[free].tolist()))
               if data.marker_offsets == "fit" and tr.offsets is not None else 0)
    return frames + markers
