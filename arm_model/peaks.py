"""Force peaks: the seed paper's extraction of one force value a contact (§2.2), in one place.

The paper takes the absolute value of each force channel and, for each contact, the force maximum.
Both the offline ring pipeline (:func:`correction.signals.find_point_forces`, peaks of a whole
measurement's signal) and a live session (:mod:`arm_model.live`, one contact at a time) find their peaks
here:

* :func:`force_magnitude`: ``|F|`` of each sample from the absolute channels [N];
* :func:`force_peaks`: the peaks of a magnitude signal and their prominences (``scipy.signal.find_peaks``
  on the signal padded with its minimum at both ends, so that a contact at the very start or end of the
  signal still counts as a peak);
* :func:`contact_peak`: the sample of one contact's peak, its most prominent peak (the contact's force
  maximum; on a plateau of equal values, the middle of the plateau as ``find_peaks`` defines it);
* :func:`signal_noise`: a robust noise standard deviation of a sampled signal.
"""
from __future__ import annotations

import numpy as np

__all__ = ["force_magnitude", "force_peaks", "contact_peak", "signal_noise"]


def force_magnitude(force: np.ndarray) -> np.ndarray:
    """(M,) ``|F|`` [N] of (M, C) force channels, each taken as its absolute value first (the paper)."""
    return np.linalg.norm(np.abs(np.asarray(force, float)), axis=1)


def force_peaks(magnitude: np.ndarray, floor: float) -> tuple[np.ndarray, np.ndarray]:
    """Peaks of a force-magnitude signal standing at least ``floor`` [N] above their surroundings.

    Args:
        magnitude: (M,) [N].
        floor: the least prominence of a peak [N] (0: every local maximum).

    Returns:
        (index (K,), prominence (K,) [N]) of the peaks, in signal order.
    """
    m = np.asarray(magnitude, float)
    if len(m) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    from scipy.signal import find_peaks
    padded = np.r_[m.min(), m, m.min()]
    idx, props = find_peaks(padded, prominence=floor)
    return idx - 1, props["prominences"]


def contact_peak(magnitude: np.ndarray | list) -> int:
    """The sample of one contact's force peak: the most prominent peak of its magnitude (M,) [N], which
    is its maximum (the first of equally prominent peaks). A contact of one sample is its own peak."""
    m = np.asarray(magnitude, float)
    if len(m) < 2:
        return 0
    idx, prom = force_peaks(m, 0.0)
    if len(idx) == 0:           # a constant signal: no peak stands out
        return 0
    return int(idx[int(np.argmax(prom))])


def signal_noise(x: np.ndarray) -> float:
    """Robust noise standard deviation of a sampled signal [its unit]: 1.4826 MAD of the second
    differences / sqrt(6) (the second difference of white noise has variance 6 sigma^2)."""
    d2 = np.diff(np.asarray(x, float), n=2)
    if len(d2) == 0:
        return 0.0
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / np.sqrt(6.0))
