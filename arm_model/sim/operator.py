"""The operator: contact forces, capture times, temperatures and the 1 kHz force signal.

Force magnitudes follow the seed paper (17 ring measurements): each measurement has a level
(mean ``force_mean``, log-normal spread ``level_log_sd``), each point a gamma draw around it
(coefficient of variation ``point_cv``), a rare spike (probability ``spike_probability``) between
three times the level and ``max_force``, everything inside [``min_force``, ``max_force``]. With the
defaults the measurement means fall between about 0.5 and 2 N, the measurement maxima around
2-2.5 N, reaching 5 N in some measurements, and a rare point up to 8 N.

Direction: the force the part exerts on the ball lies along the contact normal plus a friction
component drawn uniformly in the cone ``|f_t| <= mu |f_n|`` (a seat: inside its force cone).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import perpendicular_basis
from .artefacts import Plan

__all__ = ["OperatorDraw", "draw_operator", "force_signal", "measurement_slices"]


@dataclass(frozen=True)
class OperatorDraw:
    """Per point: ``force`` (N, 3) [N] and ``torque`` (N, 3) [N m] (about the ball centre) the part
    exerts on the ball, base frame; ``time`` (N,) [s] capture time; ``temperature`` (N,) [°C] true
    arm temperature; ``level`` per measurement id [N]; ``windows`` per measurement id (start, end) [s]."""
    force: np.ndarray
    torque: np.ndarray
    time: np.ndarray
    temperature: np.ndarray
    level: dict
    windows: dict


def measurement_slices(measurement) -> dict[str, np.ndarray]:
    """Row indices of each measurement id, in order of first appearance."""
    out: dict[str, list] = {}
    for i, m in enumerate(measurement):
        out.setdefault(m, []).append(i)
    return {k: np.array(v) for k, v in out.items()}


def _magnitudes(rng, op: dict, n: int) -> tuple[float, np.ndarray]:
    s = op["level_log_sd"]
    level = op["force_mean"] * np.exp(rng.normal(0.0, s) - s * s / 2) if s > 0 else op["force_mean"]
    level = float(np.clip(level, op["min_force"], op["max_force"]))
    cv = op["point_cv"]
    if cv * cv > 0:             # a spread so small that its square underflows: none
        shape = 1.0 / (cv * cv)
        f = rng.gamma(shape, level / shape, n)
    else:
        f = np.full(n, level)
    spikes = rng.uniform(size=n) < op["spike_probability"]
    hi = op["max_force"]
    f = np.where(spikes, rng.uniform(min(3 * level, hi), hi, n), f)
    return level, np.clip(f, op["min_force"], op["max_force"])


def _directions(rng, normal, cone) -> np.ndarray:
    out = np.empty_like(normal)
    for i, (nrm, mu) in enumerate(zip(normal, cone, strict=True)):
        e1, e2 = perpendicular_basis(nrm)
        phi = rng.uniform(0, 2 * np.pi)
        rho = mu * np.sqrt(rng.uniform())
        d = nrm + rho * (np.cos(phi) * e1 + np.sin(phi) * e2)
        out[i] = d / np.linalg.norm(d)
    return out


def draw_operator(plan: Plan, operator: dict, environment: dict, signals: dict,
                  rng: np.random.Generator) -> OperatorDraw:
    """Forces, times and temperatures for every point of ``plan`` (measurements in plan order,
    one after the other with ``measurement_gap`` between them); a posture (``plan.posture``) has no contact
    force."""
    n = len(plan.measurement)
    force = np.empty((n, 3))
    time = np.empty(n)
    levels, windows = {}, {}
    t0 = 0.0
    lead = signals["rise"] + 0.5
    for mid, idx in measurement_slices(plan.measurement).items():
        if plan.posture[idx].all():           # a posture seen by motion capture: nothing touched
            levels[mid], force[idx] = 0.0, 0.0
        else:
            level, mag = _magnitudes(rng, operator, idx.size)
            levels[mid] = level
            force[idx] = mag[:, None] * _directions(rng, plan.normal[idx], plan.cone[idx])
        gaps = operator["point_period"] * rng.uniform(0.7, 1.3, idx.size)
        gaps[0] = lead
        # capture times on the sample grid, so the signal's peak sample is the capture
        ts = np.round((t0 + np.cumsum(gaps)) / signals["sample_period"]) * signals["sample_period"]
        time[idx] = ts
        end = ts[-1] + signals["decay"] + 0.5
        windows[mid] = (t0, end)
        t0 = end + operator["measurement_gap"]
    if operator["friction_torque"]:
        torque = np.cross(-plan.normal * plan.lever[:, None], force)  # type: ignore[call-overload, operator]
    else:
        torque = np.zeros((n, 3))
    env = environment
    temperature = (env["temperature"] + env["drift"] * time
                   + env["cycle_amplitude"] * np.sin(2 * np.pi * time / env["cycle_period"]))
    return OperatorDraw(force, torque, time, temperature, levels, windows)


def force_signal(times, peaks, offset, window, signals: dict, noise: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """One measurement's force signal.

    Args:
        times: (M,) capture times [s] (on the sample grid).
        peaks: (M, C) the sensor reading at each capture [N] (what the points file holds).
        offset: (C,) the sensor's zero offset [N] (the reading with no contact).
        window: (start, end) [s].
        signals: the campaign's signal options (sample_period, rise, decay [s]).
        noise: standard deviation of each sample [N].

    Returns (time (S,) [s], force (S, C) [N]): each capture is one pulse that rises over ``rise``,
    peaks at the capture with exactly the point's reading, and decays over ``decay``; the rest is
    the offset plus noise.
    """
    dt = signals["sample_period"]
    start = int(np.round(window[0] / dt))
    stop = int(np.round(window[1] / dt))
    t = np.arange(start, stop + 1) * dt
    peaks = np.atleast_2d(np.asarray(peaks, dtype=float))
    offset = np.asarray(offset, dtype=float)
    f = np.tile(offset, (t.size, 1))
    rise, decay = signals["rise"], signals["decay"]
    peak_rows = np.round(np.asarray(times) / dt).astype(np.int64) - start
    n_rise, n_decay = int(np.ceil(rise / dt)), int(np.ceil(decay / dt))
    for i, row in enumerate(peak_rows):
        a, b = max(row - n_rise, 0), min(row + n_decay, t.size)
        x = (np.arange(a, b) - row) * dt                      # time from the capture [s]
        s = np.where(x <= 0, np.sin(0.5 * np.pi * np.clip(1 + x / rise, 0, 1)) ** 3,
                     (1 - np.clip(x / decay, 0, 1)) ** 2 * np.exp(-3 * x / decay))
        f[a:b] += s[:, None] * (peaks[i] - offset)
    if noise > 0:
        f = f + rng.normal(0.0, noise, f.shape)
    f[peak_rows] = peaks
    return t, f
