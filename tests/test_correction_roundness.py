"""Polar roundness plots of a ring campaign: the plotted radial deviations of a ring with a known 3-lobe
form equal the hand-computed ``A cos(3 theta)``, initially and after the correction, in the data the plot is
drawn from and in roundness.csv."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from conftest import assert_close
from correction.models import RingCampaign, RingMeasurement, correct_ring
from correction.report import ring_budgets, ring_report, roundness_data, roundness_models
from correction.signals import PointForces, force_summary

R = 0.08             # ball-centre radius [m]
BALL = 0.006
CENTRE = np.array([0.5, 0.1, 0.2])
N_ROW = 24
THETA = np.radians(7.5) + 2 * np.pi * np.arange(N_ROW) / N_ROW        # not starting at 0


def lobed(amplitude, phase, dr=0.0):
    """Ball centres in 3 rows on a cylinder of axis +z through CENTRE, radius R + dr + A cos(3 theta + phase)."""
    th = np.tile(THETA, 3)
    rho = R + dr + amplitude * np.cos(3 * th + phase)
    z = np.repeat([0.0, 0.005, 0.010], N_ROW)
    return CENTRE + np.column_stack([rho * np.cos(th), rho * np.sin(th), z]), th


@pytest.fixture(scope="module")
def campaign():
    """Three measurements: initial lobing A1 (5, 8, 3 um), after the full wrench A2 (2, 1, 0.5 um), shifted."""
    meas = []
    for k, (a1, a2) in enumerate(((5e-6, 2e-6), (8e-6, 1e-6), (3e-6, 0.5e-6))):
        rigid, _ = lobed(a1, 0.0, dr=(1 + 2 * k) * 1e-6)        # diameters differ: something to correlate
        corrected, _ = lobed(a2, 0.4)
        f = np.zeros((len(rigid), 3))
        f[:, 0] = 1.0 + k
        forces = PointForces(f, "xyz", "synthetic")
        fits = correct_ring(rigid, BALL, 2 * R + BALL, 0.0, forces, corrected)
        meas.append(RingMeasurement(f"m{k + 1}", forces, force_summary(forces.bending), fits))
    return RingCampaign("ring", 2 * R + BALL, BALL, 0.0, "xyz", meas)


AMPLITUDES = {"m1": (5.0, 2.0), "m2": (8.0, 1.0), "m3": (3.0, 0.5)}     # um: initial, full wrench


def expected(mid, model):
    """Hand-computed: angle theta about +z from base x, deviation A cos(3 theta + phase) [um] (the least-
    squares cylinder of a pure 3-lobe sampled evenly is the nominal one: its radius the mean, its axis z)."""
    th = np.tile(THETA, 3)
    a, phase = (AMPLITUDES[mid][0], 0.0) if model == "initial" else (AMPLITUDES[mid][1], 0.4)
    dev = a * np.cos(3 * th + phase)
    o = np.argsort(th, kind="stable")
    return np.degrees(th[o]), dev[o]


def test_plotted_deviations_are_the_lobing(campaign):
    assert roundness_models(campaign) == ("initial", "wrench")
    data = roundness_data(campaign)
    assert list(data) == ["m1", "m2", "m3"]
    for mid, per in data.items():
        assert set(per) == {"initial", "wrench"}
        for m, (ang, dev) in per.items():
            ang_e, dev_e = expected(mid, m)
            assert_close(np.sort(ang), np.sort(ang_e), atol=1e-6, msg=f"{mid} {m} angles")
            # match each point by its angle (three rows share each angle and each deviation)
            for a, d in zip(ang_e, dev_e, strict=True):
                near = np.abs(((ang - a + 180) % 360) - 180) < 1e-6
                assert_close(dev[near], np.full(near.sum(), d), atol=1e-4, msg=f"{mid} {m} at {a:.1f} deg")
            # max - min of what is drawn is the fit's form error
            assert_close(np.ptp(dev), campaign.measurements[int(mid[1]) - 1].form_error(m) * 1e6, atol=1e-9)


def test_report_writes_the_plot_and_its_data(campaign, tmp_path):
    written = ring_report(campaign, tmp_path / "out", {"points": None}, ring_budgets(campaign))
    names = {p.relative_to(tmp_path / "out").as_posix() for p in written}
    assert {"figures/roundness.png", "roundness.csv"} <= names
    assert (tmp_path / "out" / "figures" / "roundness.png").read_bytes()[:4] == b"\x89PNG"
    assert "figures/roundness.png" in (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    with open(tmp_path / "out" / "roundness.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 * 2 * 3 * N_ROW
    for mid in AMPLITUDES:
        for m in ("initial", "wrench"):
            sel = [r for r in rows if r["measurement"] == mid and r["model"] == m]
            ang = np.array([float(r["angle_deg"]) for r in sel])
            dev = np.array([float(r["radial_deviation_um"]) for r in sel])
            ang_e, dev_e = expected(mid, m)
            assert_close(ang, ang_e, atol=2e-6)
            o = np.lexsort((dev, ang))
            oe = np.lexsort((dev_e, ang_e))
            assert_close(dev[o], dev_e[oe], atol=1e-4)
