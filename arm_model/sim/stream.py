"""A simulated campaign as a live sample stream (``aacmm simulate --samples``, docs/simulator.md).

The stream is what the arm and its force sensor would send while the operator probes the campaign's
points one after the other: one sample a ``sample_period`` (1 kHz by default) from the start of the first
measurement's force signal to the end of the last, in the live sample format (docs/formats.md §8):

* ``time_s`` on the sample grid;
* the joint angles: at each point's capture the encoder readings of the points file; held over its
  contact (from ``rise`` before the capture to ``decay`` after it: the operator holds still while
  touching), moved between two contacts along a smooth step (zero velocity at both ends), quantised to
  the encoder resolution;
* the force of the campaign's force signals (:func:`arm_model.sim.operator.force_signal`: one pulse a
  point peaking at the capture with the points file's reading), and between measurements the sensor's
  offset plus its noise;
* ``trigger``: 1 from ``rise / 2`` before each capture to ``decay / 2`` after it (the button held).

The points the stream holds are the campaign's points (their captures); the truth stays in the
simulator's own files. The same campaign and seed give the same bytes.
"""
from __future__ import annotations

import math

import numpy as np

from ..live.plan import PlanFeature, SessionPlan
from .operator import measurement_slices
from .run import SimResult

__all__ = ["sample_stream", "stream_plan", "SAMPLES_FILE", "PLAN_FILE"]

SAMPLES_FILE = "samples.csv"
PLAN_FILE = "plan.toml"
_DEG = 180.0 / math.pi


def _plain(values: np.ndarray, decimals: int) -> list[str]:
    """Fixed-point text of ``values`` with trailing zeros dropped ("12.3400" -> "12.34", "3.000" -> "3")."""
    out = []
    for v in values:
        s = f"{v:.{decimals}f}"
        if "." in s:
            s = s.rstrip("0").rstrip(".")
        out.append("0" if s in ("-0", "") else s)
    return out


def _joint_track(t: np.ndarray, capture: np.ndarray, q: np.ndarray, rise: float, decay: float) -> np.ndarray:
    """(S, J) joint angles at sample times ``t``: each point's ``q`` held over its contact, a smooth step
    between contacts."""
    hold_a, hold_b = capture - rise, capture + decay
    k = np.searchsorted(capture, t, side="right") - 1          # the last capture at or before t
    out = np.empty((len(t), q.shape[1]))
    before = k < 0
    out[before] = q[0]
    after = k >= len(capture) - 1
    out[after] = q[-1]
    mid = ~before & ~after
    i = k[mid]
    tm = t[mid]
    a, b = hold_b[i], hold_a[i + 1]
    x = np.clip((tm - a) / np.maximum(b - a, 1e-12), 0.0, 1.0)
    x = np.where(tm < hold_a[i + 1], x, 1.0)
    s = x * x * (3.0 - 2.0 * x)
    out[mid] = q[i] + s[:, None] * (q[i + 1] - q[i])
    return out


def sample_stream(result: SimResult, seed: int = 0) -> str:
    """The CSV text of the sample stream of a :class:`~arm_model.sim.SimResult` (see the module doc).
    ``seed`` draws the noise between measurements."""
    c = result.campaign
    if result.points is None or not result.signals:
        raise ValueError("a sample stream needs a campaign with points and force signals (a force sensor, signals on)")
    pts, sg = result.points, c.signals
    dt, rise, decay = sg["sample_period"], sg["rise"], sg["decay"]
    order = measurement_slices(pts.measurement)
    times, forces = [], []
    rng = np.random.default_rng([seed, 7_146_557])
    offset = np.asarray(result.truth["truth"].force_offset, float)
    noise = float(result.truth["noise"].get("force_noise", 0.0))
    kind = None
    for mid in order:
        sig = result.signals[mid]
        kind = sig.kind
        if times:            # the sensor between two measurements: its offset and its noise
            gap = np.arange(int(round(times[-1][-1] / dt)) + 1, int(round(sig.time[0] / dt))) * dt
            f = offset + (rng.normal(0.0, noise, (len(gap), 3)) if noise > 0 else 0.0)
            if kind == "two-channel":
                f[:, 1] = 0.0
            times.append(gap)
            forces.append(np.round(np.broadcast_to(f, (len(gap), 3)), 6))
        times.append(sig.time)
        forces.append(sig.force)
    t = np.concatenate(times)
    f = np.concatenate(forces)
    capture = np.asarray(pts.time, float)
    q = _joint_track(t, capture, pts.q, rise, decay)
    res = c.noise.get("encoder_resolution", 0.0)
    q_deg = q * _DEG
    if res > 0:
        step = res * _DEG
        q_deg = np.round(q_deg / step) * step
    for j, tc in enumerate(capture):                             # the readings themselves at their contact
        inside = (t >= tc - rise) & (t <= tc + decay)
        q_deg[inside] = pts.q[j] * _DEG
    trigger = np.zeros(len(t), np.int64)
    for tc in capture:
        trigger[(t >= tc - rise / 2) & (t <= tc + decay / 2)] = 1
    cols = [_plain(t, 6)] + [_plain(q_deg[:, j], 12) for j in range(q.shape[1])]
    names = ["time_s"] + [f"q{j + 1}_deg" for j in range(q.shape[1])]
    if kind == "two-channel":
        cols += [_plain(f[:, 0], 6), _plain(f[:, 2], 6)]
        names += ["f_bend_N", "f_axial_N"]
    else:
        cols += [_plain(f[:, k], 6) for k in range(3)]
        names += ["fx_N", "fy_N", "fz_N"]
    cols.append([str(v) for v in trigger])
    names.append("trigger")
    return ",".join(names) + "\n" + "".join(",".join(row) + "\n" for row in zip(*cols, strict=True))


def stream_plan(result: SimResult) -> SessionPlan | None:
    """The session plan of the stream (each feature of the points file with its count, in the order they
    are probed, and the certified distances), or None when a feature is probed in two separate runs."""
    pts = result.points
    entries, seen = [], set()
    prev = None
    for fid in pts.feature.tolist():
        if fid != prev:
            if fid in seen or not fid:
                return None
            seen.add(fid)
            entries.append([fid, 0])
            prev = fid
        entries[-1][1] += 1
    feats = result.artefacts.features
    plan = [PlanFeature(feats[fid], n) for fid, n in entries]
    dist = tuple(d for d in result.artefacts.distances if set(d.between) <= seen)
    return SessionPlan(tuple(plan), dist, None, None)
