"""A model discrepancy that grows with how far a pose reaches beyond the poses a calibration was fitted on.

A calibrated model errs, beyond what its parameters' covariance says, by what it lacks (an effect nobody
declared, a geometry the chain cannot represent). Near the training poses the fit has absorbed most of that
error; beyond them it comes back, and the further the arm moves out of the range it was calibrated over, the
more. The standard uncertainty per axis of that error at a pose ``q`` is modelled as::

    sigma_d(q)^2 = sigma_0^2 + (g * d(q))^2
    d(q)^2 = sum_j (L_j(q) * x_j(q))^2

* ``x_j`` [rad] ([m] for a prismatic joint): how far joint ``j``'s reading lies beyond the range the training
  poses span in that joint (0 inside it; a revolute range is taken about its circular mean, so a range across
  +-pi is one interval): :func:`joint_excess`;
* ``L_j`` [m/rad] (1 for a prismatic joint): the lever of joint ``j`` at ``q``, the norm of d(ball centre)/d q_j
  of the rigid chain (the ball's distance from the joint's axis): :func:`joint_levers`. ``d`` [m] is thus how far
  the ball is carried by the joint motions beyond the training range, the same unit on every arm;
* ``sigma_0`` [m]: the discrepancy at the training poses, ``g`` [1]: its growth per metre of ``d``.

Both are estimated by :mod:`calibration.discrepancy` from the same extrapolative folds as the constant
discrepancy (the held-out poses at the ends of each joint's range lie beyond the remaining poses' range). A
model file carries them (``[calibration] model_discrepancy_um``, ``model_discrepancy_growth_um_per_mm`` and one
``[[calibration.training_range]]`` per joint: docs/formats.md), and ``aacmm tip`` adds ``sigma_d(q)^2`` to each
point's variance per axis (:func:`arm_model.uncertainty.propagate`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["TrainingRange", "GrowingDiscrepancy", "training_range", "joint_excess", "joint_levers",
           "excess_distance", "LEVER_STEP"]

#: step [rad] ([m] for a prismatic joint) of the central differences of :func:`joint_levers`
LEVER_STEP = 1e-6


@dataclass(frozen=True)
class TrainingRange:
    """The range each encoder column spans over the training poses of a calibration: ``names`` the joints (the
    description's encoder columns), ``lower`` and ``upper`` (J,) [rad] ([m] for a prismatic joint, ``circular``
    False); a revolute range is an interval about its circular mean, so ``upper`` may exceed pi."""
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    circular: tuple[bool, ...]

    def __post_init__(self):
        lo, hi = (np.asarray(v, dtype=float).reshape(-1) for v in (self.lower, self.upper))
        n = len(self.names)
        if lo.shape != (n,) or hi.shape != (n,) or len(self.circular) != n:
            raise ValueError(f"a training range needs one lower, upper and kind a joint ({n} joints)")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
            raise ValueError("a training range needs finite bounds with lower <= upper")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)


def training_range(q, names, circular) -> TrainingRange:
    """The :class:`TrainingRange` of poses ``q`` (N, J) [rad or m]: per joint its smallest and largest reading,
    a revolute one's measured from its circular mean (``circular[j]``)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    lo, hi = np.empty(q.shape[1]), np.empty(q.shape[1])
    for j in range(q.shape[1]):
        if circular[j]:
            centre = float(np.angle(np.mean(np.exp(1j * q[:, j]))))
            a = np.angle(np.exp(1j * (q[:, j] - centre)))
            lo[j], hi[j] = centre + a.min(), centre + a.max()
        else:
            lo[j], hi[j] = q[:, j].min(), q[:, j].max()
    return TrainingRange(tuple(names), lo, hi, tuple(bool(c) for c in circular))


def joint_excess(q, rng: TrainingRange) -> np.ndarray:
    """(N, J) how far each reading of ``q`` (N, J) lies beyond ``rng`` [rad or m], 0 inside it (a revolute
    joint's reading taken the short way round from the middle of its range)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    mid, half = 0.5 * (rng.lower + rng.upper), 0.5 * (rng.upper - rng.lower)
    off = q - mid
    circ = np.asarray(rng.circular, dtype=bool)
    off[:, circ] = np.angle(np.exp(1j * off[:, circ]))
    return np.clip(np.abs(off) - half, 0.0, None)


def joint_levers(desc, q) -> np.ndarray:
    """(N, J) [m/rad] (1 for a prismatic joint along its axis): the norm of the derivative of the rigid ball
    centre of ``desc`` (zero wrench, the description's own geometry) with respect to each encoder reading, by
    central differences of step :data:`LEVER_STEP`: the ball's distance from a revolute joint's axis."""
    from .kinematics import ball_centres
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, nj = q.shape
    out = np.empty((n, nj))
    for j in range(nj):
        dq = np.zeros(nj)
        dq[j] = LEVER_STEP
        diff = ball_centres(desc, q + dq) - ball_centres(desc, q - dq)
        out[:, j] = np.linalg.norm(diff, axis=1) / (2 * LEVER_STEP)
    return out


def excess_distance(desc, q, rng: TrainingRange, levers=None) -> np.ndarray:
    """(N,) [m]: ``d(q) = sqrt(sum_j (L_j x_j)^2)``, how far the joint motions beyond ``rng`` carry the ball
    (see the module docstring); ``levers`` (N, J) [m/rad] when already computed."""
    x = joint_excess(q, rng)
    if not np.any(x > 0):
        return np.zeros(len(x))
    lev = joint_levers(desc, q) if levers is None else np.asarray(levers, dtype=float)
    return np.sqrt(np.sum((lev * x) ** 2, axis=1))


@dataclass(frozen=True)
class GrowingDiscrepancy:
    """``sigma_d(q)^2 = sigma0^2 + (growth * d(q))^2`` (see the module docstring): ``sigma0`` [m] at the
    training poses, ``growth`` [1] per metre of ball travel beyond ``training`` (None: no growth, the constant
    ``sigma0`` everywhere)."""
    sigma0: float
    growth: float = 0.0
    training: TrainingRange | None = None

    def __post_init__(self):
        for name, v in (("sigma0", self.sigma0), ("growth", self.growth)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"the model discrepancy's {name} must be finite and >= 0, got {v!r}")
        if self.growth > 0 and self.training is None:
            raise ValueError("a growing model discrepancy needs the training range it grows beyond")

    def sd(self, desc, q) -> np.ndarray:
        """(N,) [m]: ``sigma_d`` per axis at each pose of ``q`` (N, J)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if self.growth == 0 or self.training is None:
            return np.full(len(q), self.sigma0)
        if q.shape[1] != len(self.training.names):
            raise ValueError(f"q has {q.shape[1]} joints, the training range {len(self.training.names)}")
        d = excess_distance(desc, q, self.training)
        return np.sqrt(self.sigma0 ** 2 + (self.growth * d) ** 2)
