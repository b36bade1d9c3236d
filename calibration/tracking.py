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

__all__ = ["fit_tracker", "has_reference", "own_frames_fit"]


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
