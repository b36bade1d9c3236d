"""scripts/noise_projection_study.py (the study behind docs/uncertainty.md's account of j5.a in
``study montecarlo``): on a small clean campaign (no effect the model lacks, no quantisation, no force
noise), the run's own reading noise projected on the linearised sensitivity reproduces the parameter's
error, and the reported u is the spread that sensitivity gives under the simulator's probing noise."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CAMPAIGN = """
name = "small-clean"
seed = 3
arm = "aacmm7"
sensor = "xyz"

[truth]
length_error_um = 30.0
angle_error_deg = 0.004
probe_error_um = 30.0

[noise]
encoder_resolution_deg = 0.0
probing_repeatability_um = 2.0
force_noise_N = 0.0

[[task]]
kind = "ballbar"
id = "bar"
positions = 10
length_mm = 600.004
u_length_mm = 0.0008
ends = "sphere"
sphere_diameter_mm = 25.4
points_per_sphere = 5
radius_mm = [300.0, 800.0]
height_mm = [-200.0, 600.0]

[[task]]
kind = "seat"
id = "seat"
position_mm = [550.0, -250.0, 20.0]
axis = [0.0, 0.0, 1.0]
articulations = 15
stylus_cone_deg = 60.0

[[task]]
kind = "sphere"
id = "sphere"
diameter_mm = 25.4
centre_mm = [500.0, 300.0, 100.0]
points = 15
measurements = 2

[[task]]
kind = "plane"
id = "table"
point_mm = [650.0, 0.0, 0.0]
normal = [0.0, 0.0, 1.0]
size_mm = [300.0, 400.0]
points = 15
"""


def test_reading_noise_projected_on_the_sensitivity_is_the_error(tmp_path):
    spec = importlib.util.spec_from_file_location("noise_projection_study",
                                                  ROOT / "scripts" / "noise_projection_study.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    from arm_model.sim import load_campaign
    path = tmp_path / "small.toml"
    path.write_text(CAMPAIGN)
    r = mod.one(load_campaign(path), 5, "j5.a", 2000)
    # linear in the noise and nothing but the noise: the projection is the error (0.3 % of u is the
    # fit's non-linearity at 2 um and the differences' rounding)
    assert abs(r["z_rest"]) < 0.05, r
    # u is the spread of the estimate under the noise the simulator draws (the weights are estimated from
    # this run's residuals: a few per cent off), and the fresh draws' spread agrees with |a| sigma / u
    assert 0.85 < r["spread_over_u"] < 1.15, r
    assert r["fresh_sd"] == pytest.approx(r["spread_over_u"], rel=0.05)
