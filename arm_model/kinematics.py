"""The fast batch evaluator: deflection-aware ball centres for (N, J) joint arrays.

Chunks of the input are evaluated by :func:`arm_model.chain.ball_centre_expr` on numpy columns
(structure of arrays, three numbers a point carried from the probe inwards) in a small thread pool;
memory is the output plus a few chunk-sized temporaries, linear in N.
"""
from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .chain import FLOAT_OPS, NUMPY_OPS, ball_centre_expr
from .description import ArmDescription
from .params import chain_floats, split_params

__all__ = ["ball_centres", "rigid_centres", "as_wrench", "probe_rotations"]

_CHUNK = 16384
#: worker threads of every evaluation in this process (None: up to 2, one a core); a worker process of a
#: command that splits its input over the cores sets 1
THREADS: int | None = None


def as_wrench(wrench: ArrayLike | None, n: int | None = None) -> np.ndarray | None:
    """Check a wrench array: (N, 3) force [N] or (N, 6) force [N] then torque [N m], probe frame."""
    if wrench is None:
        return None
    w = np.asarray(wrench, dtype=float)
    if w.ndim == 1:
        w = w[None, :]
    if w.ndim != 2 or w.shape[1] not in (3, 6):
        raise ValueError(f"wrench must have shape (N, 3) or (N, 6), got {w.shape}")
    if n is not None and w.shape[0] != n:
        raise ValueError(f"wrench has {w.shape[0]} rows, joint angles have {n}")
    return w


def _default_threads() -> int:
    if THREADS:
        return THREADS
    return max(1, min(2, os.cpu_count() or 1))


def run_chunks(work: Callable[[int], None], n: int, chunk: int, threads: int | None = None) -> None:
    """Call ``work(start)`` for every chunk start of ``range(0, n, chunk)``: in a thread pool of
    ``threads`` (default :func:`_default_threads`) when there is more than one chunk, else in line.
    ``work`` writes its own slice of a preallocated output (numpy releases the GIL)."""
    starts = range(0, n, chunk)
    if n <= chunk or (threads or _default_threads()) == 1:
        for s in starts:
            work(s)
    else:
        with ThreadPoolExecutor(max_workers=threads or _default_threads()) as pool:
            list(pool.map(work, starts))


def ball_centres(desc: ArmDescription, q: ArrayLike, wrench: ArrayLike | None = None, p: ArrayLike | None = None, *,
                 threads: int | None = None,
                 chunk: int = _CHUNK) -> np.ndarray:
    """Deflection-aware ball centres [m] in the base frame.

    Args:
        desc: the arm.
        q: (N, J) encoder readings (or (J,) for one point): joint angles [rad], prismatic joints' positions
            [m] (:attr:`~arm_model.description.ArmDescription.encoders`).
        wrench: None (rigid), (N, 3) force [N] or (N, 6) force [N] and torque [N m] at the ball,
            in the probe frame: the force the part exerts on the ball.
        p: parameter errors (see :mod:`arm_model.params`), None for the description itself.
        threads: worker threads (default: up to 2).

    Returns:
        (N, 3) ball centres [m] (or (3,) for one point).
    """
    q = np.asarray(q, dtype=float)
    single = q.ndim == 1
    q2 = q[None, :] if single else q
    if q2.ndim != 2 or q2.shape[1] != desc.n_joints:
        raise ValueError(f"q must have shape (N, {desc.n_joints}), got {q.shape}")
    n = q2.shape[0]
    w = as_wrench(wrench, n)
    if n == 1:          # one point (a live session's): on Python floats, the batch's numbers bit for bit (FLOAT_OPS)
        floats = chain_floats(desc, p)
        x, y, z = ball_centre_expr(desc.convention, floats[0], floats[1], floats[2], q2[0].tolist(),
                                   None if w is None else w[0].tolist(), FLOAT_OPS, desc.chain_joints,
                                   floats[3], desc.probe.lever)
        return np.array([x, y, z]) if single else np.array([[x, y, z]])
    rows, p_last, compliance = split_params(desc, None if p is None else np.asarray(p, dtype=float))
    out = np.empty((n, 3))

    def work(start: int) -> None:
        stop = min(start + chunk, n)
        qt = np.ascontiguousarray(q2[start:stop].T)
        wt = None if w is None else np.ascontiguousarray(w[start:stop].T)
        x, y, z = ball_centre_expr(desc.convention, rows, p_last, compliance, qt,
                                   None if wt is None else list(wt), NUMPY_OPS, desc.chain_joints,
                                   desc.probe.rotation, desc.probe.lever)
        out[start:stop, 0] = x
        out[start:stop, 1] = y
        out[start:stop, 2] = z

    run_chunks(work, n, chunk, threads)
    return out[0] if single else out


def rigid_centres(desc: ArmDescription, q: ArrayLike, p: ArrayLike | None = None, **kw: Any) -> np.ndarray:
    """Ball centres [m] with a rigid stylus (zero wrench)."""
    return ball_centres(desc, q, None, p, **kw)


def probe_rotations(desc: ArmDescription, q: ArrayLike, p: ArrayLike | None = None) -> np.ndarray:
    """(N, 3, 3) rotation R_base_probe (columns: the probe frame's x, y, z axes in the base frame) at joint
    angles ``q`` (N, J) [rad] with base parameter errors ``p`` (rigid chain;
    :func:`arm_model.jacobian.joint_screws`)."""
    from .jacobian import joint_screws

    rows, _, _ = split_params(desc, None if p is None else np.asarray(p, dtype=float))
    rot: np.ndarray = joint_screws(desc.convention, rows, np.atleast_2d(np.asarray(q, dtype=float)),
                                   desc.chain_joints)[0]
    return rot if desc.probe.rotation is None else rot @ np.asarray(desc.probe.rotation, dtype=float)
