"""The operator's forces: statistics as asked (and like the seed paper's), directions inside the
friction cone along the right normal, signals with one pulse a point whose peak is the point's force."""
from __future__ import annotations

import math

import numpy as np
import pytest

from arm_model import read_force_signal
from arm_model.sim import campaign_from_dict, simulate
from arm_model.sim.artefacts import make_plan
from arm_model.sim.operator import draw_operator, force_signal, measurement_slices
from conftest import assert_close


def _draw(op=None, measurements=17, points=24, seed=0, kind="ring"):
    task = {"kind": kind, "measurements": measurements}
    task.update({"ring": {"points_per_row": points // 3}, "seat": {"articulations": points}}.get(
        kind, {"points": points}))
    c = campaign_from_dict({"seed": seed, "operator": op or {}, "task": [task]})
    rng = np.random.default_rng(seed)
    plan = make_plan(c, rng)             # no truth: the points are not settled (no inverse kinematics)
    return c, plan, draw_operator(plan, c.operator, c.environment, c.signals, rng)


def test_force_statistics_match_the_request():
    op = {"force_mean_N": 1.4, "level_log_sd": 0.3, "point_cv": 0.4, "spike_probability": 0.0,
          "min_force_N": 0.01, "max_force_N": 50.0}
    c, plan, d = _draw(op, measurements=400, points=60)
    mag = np.linalg.norm(d.force, axis=1)
    levels = np.array(list(d.level.values()))
    assert np.mean(levels) == pytest.approx(1.4, rel=0.04)
    assert np.std(np.log(levels)) == pytest.approx(0.3, rel=0.1)
    within = [mag[idx] / d.level[m] for m, idx in measurement_slices(plan.measurement).items()]
    within = np.concatenate(within)
    assert np.mean(within) == pytest.approx(1.0, rel=0.02)
    assert np.std(within) == pytest.approx(0.4, rel=0.05)
    assert np.mean(mag) == pytest.approx(1.4, rel=0.05)


def test_default_forces_look_like_the_papers():
    """17 measurements of 72 points: measurement means about 0.5-2 N around 1 N, maxima typically
    2-3 N, never above 8 N (seed paper, section 4.1)."""
    c, plan, d = _draw(measurements=17, points=72, seed=2013)
    mag = np.linalg.norm(d.force, axis=1)
    per = measurement_slices(plan.measurement)
    means = np.array([mag[i].mean() for i in per.values()])
    maxes = np.array([mag[i].max() for i in per.values()])
    assert 0.8 < means.mean() < 1.25
    assert 0.3 < means.min() and means.max() < 2.5
    assert 1.5 < np.median(maxes) < 3.5
    assert mag.max() <= 8.0 and mag.min() >= c.operator["min_force"]


def test_rare_spikes_reach_up_to_the_maximum():
    op = {"spike_probability": 0.05}
    _, _, d = _draw(op, measurements=40, points=72, seed=1)
    mag = np.linalg.norm(d.force, axis=1)
    assert mag.max() > 5.0 and mag.max() <= 8.0


@pytest.mark.parametrize("kind", ["ring", "sphere", "plane", "seat"])
def test_force_direction_inside_the_cone_about_the_normal(kind):
    mu = 0.15
    c, plan, d = _draw({"friction_coefficient": mu}, measurements=3, points=30, kind=kind)
    u = d.force / np.linalg.norm(d.force, axis=1, keepdims=True)
    cosang = np.einsum("ni,ni->n", u, plan.normal)
    limit = math.atan(mu) if kind != "seat" else c.tasks[0].opts["force_cone"]
    assert np.all(cosang >= math.cos(limit) - 1e-12)
    assert np.degrees(np.arccos(cosang.min())) > 0.3 * np.degrees(limit)   # the cone is used
    if kind == "ring":   # probed from inside: the wall pushes the ball towards the axis
        centre = np.array(c.tasks[0].opts["centre"])
        radial = plan.position - centre
        radial[:, 2] = 0
        assert np.all(np.einsum("ni,ni->n", plan.normal, radial) < 0)
    if kind == "sphere":  # outer sphere: along the outward normal
        out = plan.position - np.array(c.tasks[0].opts["centre"])
        assert np.all(np.einsum("ni,ni->n", plan.normal, out) > 0)


def test_signal_pulse_peaks_are_the_point_forces():
    sig = {"sample_period": 1e-3, "rise": 0.1, "decay": 0.2}
    times = np.array([1.0, 2.2, 3.1])
    peaks = np.array([[1.2, -0.3], [0.4, 0.1], [2.5, 0.9]])
    offset = np.array([0.05, -0.02])
    t, f = force_signal(times, peaks, offset, (0.5, 3.8), sig, 0.0, np.random.default_rng(0))
    assert_close(np.diff(t), np.full(len(t) - 1, 1e-3), atol=1e-12)
    for tc, p in zip(times, peaks, strict=True):
        k = int(round((tc - t[0]) / 1e-3))
        assert_close(f[k], p, atol=0)
        assert_close(f[k - 110], offset, atol=1e-15)       # before the rise: the sensor's zero
    # one local maximum of |f - offset| a point
    mag = np.linalg.norm(f - offset, axis=1)
    peaks_found = np.flatnonzero((mag[1:-1] > mag[:-2]) & (mag[1:-1] >= mag[2:]) & (mag[1:-1] > 0.05))
    assert len(peaks_found) == 3


@pytest.fixture(scope="module")
def with_signals():
    return simulate(campaign_from_dict({
        "seed": 8, "sensor": "two-channel", "noise": {"force_noise_N": 0.005},
        "truth": {"force_sensor": {"offset_N": [0.02, 0.0, -0.01]}},
        "task": [{"kind": "ring", "measurements": 2, "points_per_row": 5}]}))


def test_campaign_signals_have_one_peak_a_point(with_signals):
    r = with_signals
    for mid, idx in measurement_slices(r.points.measurement).items():
        s = r.signals[mid]
        assert s.kind == "two-channel"
        rows = np.round((r.points.time[idx] - s.time[0]) / 1e-3).astype(int)
        assert_close(s.force[rows], r.points.force[idx], atol=0)        # the i-th peak is the i-th point
        mag = np.linalg.norm(s.force - np.array([0.02, 0.0, -0.01]), axis=1)
        smooth = np.convolve(mag, np.ones(15) / 15, mode="same")
        above = smooth > 0.1
        assert np.count_nonzero(np.diff(above.astype(int)) == 1) == len(idx)


def test_written_signal_reads_back(with_signals, tmp_path):
    r = with_signals
    r.write(tmp_path)
    for mid, s in r.signals.items():
        back = read_force_signal(tmp_path / "signals" / f"{mid}.csv")
        assert back.kind == s.kind
        assert_close(back.time, s.time, atol=0)
        assert_close(back.force, s.force, atol=0)
