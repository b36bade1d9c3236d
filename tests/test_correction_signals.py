"""Force signal processing: one peak a point, the force at each peak, the paper's summary values."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model import InputError
from arm_model.io import ForceSignal, parse_points
from conftest import assert_close
from correction.signals import PointForces, find_point_forces, force_summary, forces_from_columns, signal_noise


def synthetic_signal(forces, rng, period=1e-3, gap=0.6, width=0.08, noise=0.005, tremor=0.0, kind="xyz",
                     baseline=0.0):
    """A signal with one raised-cosine contact a point reaching ``forces[i]`` (3,) at its top, noise,
    optional hand tremor (10 Hz) during contacts. Returns (ForceSignal, exact peak times)."""
    n = len(forces)
    t = np.arange(0, gap * (n + 1), period)
    f = np.zeros((len(t), 3)) + baseline
    peaks = []
    for i, fi in enumerate(forces):
        tc = gap * (i + 1) + rng.uniform(-0.1, 0.1) * gap
        s = np.clip(np.abs(t - tc) / width, 0, 1)
        shape = 0.5 * (1 + np.cos(np.pi * s))
        shape = shape * (1 + tremor * np.sin(2 * np.pi * 10 * t) * (s < 1))
        f += shape[:, None] * np.asarray(fi)[None, :]
        peaks.append(tc)
    f += rng.normal(0, noise, f.shape)
    if kind == "two-channel":
        f[:, 1] = 0.0
    return ForceSignal("sig.csv", t, f, kind), np.array(peaks)


def random_forces(rng, n, kind="xyz"):
    f = rng.uniform(0.3, 4.0, n)[:, None] * rng.normal(size=(n, 3))
    f /= np.linalg.norm(f, axis=1)[:, None]
    f *= rng.uniform(0.3, 4.0, n)[:, None]
    if kind == "two-channel":
        f[:, 1] = 0
    return f


@pytest.mark.parametrize("kind", ["xyz", "two-channel"])
def test_one_peak_a_point_and_the_force_at_it(kind):
    rng = np.random.default_rng(1)
    forces = random_forces(rng, 24, kind)
    sig, times = synthetic_signal(forces, rng, kind=kind)
    pf = find_point_forces(sig, 24, "ring-01")
    assert len(pf) == 24
    assert_close(pf.time, times, atol=0.004)                      # peak within a few samples of the top
    assert_close(pf.force, forces, atol=0.03)                      # noise 5 mN + sampling of the top
    if kind == "two-channel":
        assert np.all(pf.force[:, 1] == 0)
        assert_close(pf.bending, np.abs(forces[:, 0]), atol=0.03)
    else:
        assert_close(pf.bending, np.hypot(forces[:, 0], forces[:, 1]), atol=0.03)
    assert_close(pf.axial, np.abs(forces[:, 2]), atol=0.03)
    assert 0.003 < pf.noise < 0.008                                # the noise estimate finds 5 mN


def test_tremor_and_baseline_do_not_make_extra_peaks():
    rng = np.random.default_rng(2)
    forces = random_forces(rng, 30)
    sig, _ = synthetic_signal(forces, rng, tremor=0.04, baseline=0.05)
    pf = find_point_forces(sig, 30)
    assert len(pf) == 30
    # the top of each contact: the force plus the baseline, within the tremor's +-4 %
    assert_close(np.linalg.norm(pf.force, axis=1), np.linalg.norm(forces + 0.05, axis=1), atol=0.03, rtol=0.045)


def test_count_mismatch_names_both_counts_and_the_file():
    rng = np.random.default_rng(3)
    sig, _ = synthetic_signal(random_forces(rng, 10), rng)
    with pytest.raises(InputError) as exc:
        find_point_forces(sig, 12, "ring-07")
    msg = str(exc.value)
    assert "10 peaks" in msg and "12 points" in msg and "sig.csv" in msg and "ring-07" in msg
    # more peaks than points, all of the same size: not clearly apart, an error naming both counts
    with pytest.raises(InputError) as exc:
        find_point_forces(sig, 8)
    assert "10 peaks" in str(exc.value) and "8 points" in str(exc.value)


def test_a_small_bump_besides_the_contacts_is_left_out_only_when_clearly_apart():
    rng = np.random.default_rng(4)
    forces = np.tile([[1.5, 0.5, 0.2]], (6, 1))
    sig, _ = synthetic_signal(forces, rng, noise=0.002)
    f = sig.force.copy()
    k = np.searchsorted(sig.time, 0.3)
    f[k - 20:k + 20, 0] += 0.15 * np.hanning(40)                    # a 0.15 N brush of the surface
    bumped = ForceSignal(sig.path, sig.time, f, sig.kind)
    pf = find_point_forces(bumped, 6)
    assert np.all(pf.time > 0.35)


@settings(max_examples=20, deadline=None)
@given(n=st.integers(1, 40), seed=st.integers(0, 10_000), noise=st.floats(0.0005, 0.02))
def test_peaks_property(n, seed, noise):
    rng = np.random.default_rng(seed)
    forces = random_forces(rng, n)
    sig, times = synthetic_signal(forces, rng, noise=noise)
    pf = find_point_forces(sig, n)
    assert len(pf) == n
    assert np.all(np.diff(pf.index) > 0)
    # near its top a raised cosine of half-width w drops by F (pi dt / 2w)^2: the noisy maximum can lie
    # anywhere the pulse is within ~6 sigma of its top, |dt| < (2w / pi) sqrt(6 sigma / F) (+ 1 sample)
    width = 0.08
    tol = np.maximum(0.01, 2 * width / np.pi * np.sqrt(6 * noise / np.linalg.norm(forces, axis=1)) + 1e-3)
    assert np.all(np.abs(pf.time - times) <= tol), (pf.time - times, tol)
    with pytest.raises(InputError):
        find_point_forces(sig, n + 1)


def test_force_summary_known_answers():
    v = np.arange(1, 21, dtype=float)                 # 1 .. 20 N
    s = force_summary(v)
    assert s.mean == 10.5 and s.max == 20.0 and s.max10 == np.mean(np.arange(11, 21))
    few = force_summary([1.0, 2.0, 6.0])
    assert few.max10 == 3.0                            # fewer than 10: mean of all
    with pytest.raises(ValueError):
        force_summary([])


def test_noise_estimate_ignores_smooth_signal():
    t = np.linspace(0, 10, 10001)
    rng = np.random.default_rng(5)
    smooth = 3 * np.sin(t) ** 2
    assert signal_noise(smooth) < 1e-5
    assert 0.009 < signal_noise(smooth + rng.normal(0, 0.01, len(t))) < 0.011


def test_forces_from_point_columns():
    text = ("measurement,feature,q1_deg,fx_N,fy_N,fz_N\n"
            "m1,ring,0,1.0,0.0,0.5\nm1,ring,1,-3.0,4.0,0.0\n")
    pts = parse_points(text, "p.csv", 1)
    pf = forces_from_columns(pts)
    assert isinstance(pf, PointForces) and pf.kind == "xyz"
    assert_close(pf.bending, [1.0, 5.0], atol=0)
    assert_close(pf.axial, [0.5, 0.0], atol=0)
    two = parse_points("measurement,feature,q1_deg,f_bend_N,f_axial_N\nm1,ring,0,-2.0,0.3\n", "p.csv", 1)
    assert_close(forces_from_columns(two).bending, [2.0], atol=0)
    none = parse_points("measurement,feature,q1_deg\nm1,ring,0\n", "p.csv", 1)
    with pytest.raises(InputError, match="no force columns"):
        forces_from_columns(none)
