"""Force signal processing of the seed paper (§2.2): one peak a captured point, the force at each peak,
and the summary values of a measurement (mean, maximum, 10Max).

Per-point forces, defined once here and used by every model:

* ``force`` (N, 3) [N], probe frame: the signed force vector at the peak sample (for the full-wrench
  correction; with the two-channel sensor its probe-y component is zero: not measured).
* ``bending`` (N,) [N]: the magnitude of the bending force, ``hypot(fx, fy)``; with the two-channel
  sensor this is ``|f_bend|``, the paper's absolute value of its one bending channel. The paper's four
  models use this value (its Eq. 9 uses the bending force only).
* ``axial`` (N,) [N]: ``|fz|``.

Peak picking (:func:`find_point_forces`): the paper takes absolute values and the force maximum of each
contact. The signal's force magnitude is searched by :func:`arm_model.peaks.force_peaks` (the one peak
finder, which a live session uses too); the prominence
threshold comes from the signal itself: ten times its noise (a robust estimate from second
differences, so smooth contacts do not inflate it). If more candidates than points stand above the
noise, the points' peaks must stand clearly apart from the rest (the n-th most prominent at least twice
the (n+1)-th); anything else is an :class:`arm_model.InputError` that names both counts and the file.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arm_model import InputError
from arm_model.io import ForceSignal
from arm_model.peaks import force_magnitude, force_peaks, signal_noise

__all__ = ["PointForces", "ForceSummary", "find_point_forces", "forces_from_columns", "force_summary",
           "signal_noise", "NOISE_FACTOR", "SEPARATION"]

#: a peak must stand this many noise standard deviations above its surroundings
NOISE_FACTOR = 10.0
#: when extra peaks stand above the noise, the points' peaks must be this many times more prominent
SEPARATION = 2.0


@dataclass(frozen=True)
class PointForces:
    """Per-point forces of one measurement.

    Attributes:
        force: (N, 3) force the part exerts on the ball at each point, probe frame [N] (signed).
        kind: "xyz" or "two-channel" (probe y not measured, zero).
        source: the signal file, or the points file when the forces come from its columns.
        index: (N,) sample index of each peak in the signal, or None.
        time: (N,) time of each peak [s], or None.
        prominence: (N,) prominence of each peak [N], or None.
        noise: the signal's noise standard deviation [N], or None.
    """
    force: np.ndarray
    kind: str
    source: str
    index: np.ndarray | None = None
    time: np.ndarray | None = None
    prominence: np.ndarray | None = None
    noise: float | None = None

    def __len__(self) -> int:
        return len(self.force)

    @property
    def bending(self) -> np.ndarray:
        """(N,) bending force magnitude hypot(fx, fy) [N] (|f_bend| for the two-channel sensor)."""
        return np.hypot(self.force[:, 0], self.force[:, 1])

    @property
    def axial(self) -> np.ndarray:
        """(N,) axial force magnitude |fz| [N]."""
        return np.abs(self.force[:, 2])

    @property
    def magnitude(self) -> np.ndarray:
        """(N,) |F| [N]."""
        return np.linalg.norm(self.force, axis=1)


@dataclass(frozen=True)
class ForceSummary:
    """The seed paper's significant values of a measurement's per-point forces [N]: ``mean``, ``max``
    and ``max10`` (10Max: the mean of the 10 largest, or of all when fewer than 10 points)."""
    mean: float
    max: float
    max10: float

    def as_dict(self) -> dict:
        return {"mean": self.mean, "max10": self.max10, "max": self.max}


def force_summary(values, top: int = 10) -> ForceSummary:
    """Mean, maximum and mean of the ``top`` largest of per-point force values (N,) [N]."""
    v = np.asarray(values, float)
    if v.ndim != 1 or len(v) == 0:
        raise ValueError("need a non-empty 1-D array of per-point forces")
    largest = np.sort(v)[::-1][:top]
    return ForceSummary(mean=float(v.mean()), max=float(v.max()), max10=float(largest.mean()))


def find_point_forces(signal: ForceSignal, n_points: int, measurement: str | None = None) -> PointForces:
    """One peak of the force magnitude a captured point; the force vector at each peak.

    Args:
        signal: the measurement's force signal (``arm_model.read_force_signal``).
        n_points: number of points of the measurement in the points file (capture order = peak order).
        measurement: measurement id, for messages.

    Raises:
        InputError: the number of peaks differs from ``n_points`` (both counts and the file named), or
            the peaks of the points are not clearly separated from other bumps of the signal.
    """
    m = force_magnitude(signal.force)          # the paper takes absolute values of each channel
    what = f" of measurement '{measurement}'" if measurement else ""
    if len(m) < 3:
        raise InputError(f"force signal{what} has {len(m)} samples: too short for peaks", signal.path)
    sigma = signal_noise(m)
    floor = NOISE_FACTOR * sigma if sigma > 0 else 1e-12 * max(float(m.max()), 1e-300)
    idx, prom = force_peaks(m, floor)
    found = len(idx)
    if found > n_points:
        order = np.argsort(prom)[::-1]
        nth, extra = prom[order[n_points - 1]] if n_points > 0 else np.inf, prom[order[n_points]]
        if n_points == 0 or nth < SEPARATION * extra:
            raise InputError(
                f"force signal{what}: {found} peaks stand above the noise ({NOISE_FACTOR:g} x "
                f"{sigma:.3g} N), but the points file has {n_points} points for this measurement, and the "
                f"{n_points} largest are not clearly apart from the others (prominence {nth:.3g} N vs "
                f"{extra:.3g} N); expected exactly one peak a captured point", signal.path)
        keep = np.sort(order[:n_points])
        idx, prom = idx[keep], prom[keep]
    elif found < n_points and not m.any():
        raise InputError(f"force signal{what}: the force is zero in every sample, but the points file has "
                         f"{n_points} points for this measurement (one peak a captured point)", signal.path)
    elif found < n_points:
        raise InputError(f"force signal{what}: {found} peaks found (above {NOISE_FACTOR:g} x the noise, "
                         f"{floor:.3g} N) but the points file has {n_points} points for this measurement; "
                         "expected exactly one peak a captured point", signal.path)
    return PointForces(force=np.asarray(signal.force, float)[idx], kind=signal.kind, source=signal.path,
                       index=idx, time=signal.time[idx], prominence=prom, noise=sigma)


def forces_from_columns(points, mask=None) -> PointForces:
    """Per-point forces taken directly from a points file's force columns (no signals).

    Args:
        points: an :class:`arm_model.PointSet` with force columns.
        mask: optional row selection (bool or index array).
    """
    if points.force is None:
        raise InputError("the points file has no force columns (fx_N, fy_N, fz_N or f_bend_N, f_axial_N) "
                         "and no force signals were given (--signals DIR)", points.path)
    f = points.force if mask is None else points.force[mask]
    return PointForces(force=np.asarray(f, float), kind=points.force_kind, source=points.path)
