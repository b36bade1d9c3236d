"""The simulator hides the synthesised effects that act on the angles or the geometry: joint harmonics (of
a joint's own angle or another's) and per-link and probe thermal growth, declared in the campaign's truth."""
from __future__ import annotations

import math

import numpy as np
import pytest

from arm_model import InputError
from arm_model.sim import campaign_from_dict, simulate
from conftest import assert_close

TASKS = [{"kind": "sphere", "points": 8, "measurements": 3}, {"kind": "seat", "articulations": 6, "measurements": 2}]


def _campaign(truth, **more):
    return {"seed": 5, "sensor": "xyz", "signals": {"enabled": False}, "task": TASKS, "truth": truth, **more}


def test_hidden_harmonics_and_growth_reach_the_truth_and_the_readings():
    truth = {"harmonics": [{"joint": "j6", "harmonic": 3, "amplitude_deg": 0.004, "phase_deg": 20.0},
                           {"joint": "j3", "of": "j2", "harmonic": 1, "amplitude_deg": 0.002}],
             "thermal": {"joints": ["j2", "j4"], "alpha_per_K": [2e-5, 5e-5], "probe_alpha_per_K": 1e-5}}
    sim = simulate(campaign_from_dict(_campaign(truth, environment={"drift_C_per_h": 8.0})))
    p = sim.truth["p"]
    a = math.radians(0.004)
    assert p["j6.harm3_cos"] == pytest.approx(a * math.sin(math.radians(20.0)), rel=1e-12)
    assert p["j6.harm3_sin"] == pytest.approx(a * math.cos(math.radians(20.0)), rel=1e-12)
    assert p["j3.harm1_sin_by_j2"] == pytest.approx(math.radians(0.002), rel=1e-12)
    assert (p["j2.thermal_alpha"], p["j4.thermal_alpha"], p["probe.thermal_alpha"]) == (2e-5, 5e-5, 1e-5)
    assert sim.truth["effects"]["harmonics"][1]["of"] == "j2"


def test_hidden_harmonic_is_in_the_encoder_readings():
    """Same seed with and without a third harmonic of j6: the true poses are the same, the readings of j6
    differ by the harmonic (q_true = q_enc + a sin(3 q_enc + phi)), the other joints not at all."""
    entry = {"joint": "j6", "harmonic": 3, "amplitude_deg": 0.01, "phase_deg": 40.0}
    with_h = simulate(campaign_from_dict(_campaign({"harmonics": [entry]}))).points.q
    plain = simulate(campaign_from_dict(_campaign({}))).points.q
    a, phi = math.radians(0.01), math.radians(40.0)
    assert_close(plain[:, 5] - with_h[:, 5], a * np.sin(3 * with_h[:, 5] + phi), atol=5e-9)   # readings: 1e-9 deg
    assert_close(np.delete(plain, 5, axis=1), np.delete(with_h, 5, axis=1), atol=5e-9)


@pytest.mark.parametrize("entry, message", [
    ({"joint": "j6", "harmonic": 5, "amplitude_deg": 0.001}, "1 to 4"),
    ({"joint": "j9", "harmonic": 3, "amplitude_deg": 0.001}, "j9"),
    ({"joint": "j6", "amplitude_deg": 0.001}, "harmonic"),
])
def test_bad_harmonics_tables_are_refused(entry, message):
    with pytest.raises(InputError, match=message):
        campaign_from_dict(_campaign({"harmonics": [entry]}))
