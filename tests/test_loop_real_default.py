"""Default ``aacmm close-loop`` on the real Panda seat data (examples/data/real-panda-seats), trained on one
placement, its model file applied by ``aacmm tip`` to the other placements (calibration.placements, the study of
scripts/real_seats_study.py), against the published tool MUKCa (independent reference: its held-out seat
spread and distance error on the same pairs, platonics-delft/kinematics_calibration; their means are the
published 2.073 mm and 0.666 mm, docs/studies/calibration.md).

A robot read from a URDF whose links carry masses starts from joint compliance under gravity (each
compliance with its physical prior, the geometry's prior scaled by the evidence: ``--prior-scale auto``), on
every placement alike; the loop then adds what the held-out poses support."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

REAL = Path(__file__).resolve().parents[1] / "examples" / "data" / "real-panda-seats"
PLACES = ("front", "right", "back-high")
#: MUKCa trained on the first placement, the second predicted: (spread hole-0, spread hole-1, distance error) [mm]
MUKCA = {("front", "right"): (0.562, 1.348, -0.261), ("front", "back-high"): (2.020, 1.601, -0.955),
         ("right", "front"): (1.246, 1.250, 0.441), ("right", "back-high"): (2.584, 2.017, -0.906),
         ("back-high", "front"): (3.141, 3.575, 1.171), ("back-high", "right"): (1.997, 3.530, -0.262)}
#: the effects the loop adds on the base model, per training placement (measured at --seed 0, 1 and 2)
#: (on ``right`` joint 1's eccentricity: joints 1 and 3 explain its held-out poses alike (paired p = 0.19), a tie the
#: stated rule resolves (equal parameters, then the stronger score test: joint 1's, 2.7e-6 against 6.8e-5); by the
#: held-out drop alone the choice moved with the fit's last 0.04 u: joints 1 and 3 together before the evidence's
#: secant step, joint 1 alone with the loop's earlier outlier rule, joint 3 after both)
ADDED = {"front": (), "right": ("eccentricity panda_joint1",), "back-high": ()}


def _study(tmp_path, train, options=()):
    from calibration.placements import placement_study
    return placement_study(REAL, REAL / "panda-with-inertials.urdf", "ball_link", tmp_path, train=list(train),
                           methods=("close-loop",), options={"close-loop": list(options)})


def _ratio(row) -> float:
    m = MUKCA[(row.train, row.test)]
    return row.figures["spread_mean_mm"] / (0.5 * (m[0] + m[1]))


def test_default_loop_starts_from_joint_compliance_with_its_prior(tmp_path):
    """Trained on ``front`` (its pair with back-high is the one most above MUKCa's): joint compliance is the base
    model, fitted with the evidence's prior, every compliance in the model file non-negative, the model file read
    by ``tip`` (the study applies it with ``aacmm tip``); right within MUKCa's spread, back-high within 1.4x
    (measured 0.91x and 1.30x; the loop's earlier default 0.93x and 1.39x)."""
    rows = _study(tmp_path, ["front"])
    s = json.loads((tmp_path / "front" / "close-loop" / "summary.json").read_text())
    assert s["base_effects"] == ["joint_compliance"] and s["estimation"]["prior_scale"] == "evidence"
    assert tuple(r.effects for r in rows) == (ADDED["front"],) * 2
    from arm_model.model_file import load_model
    arm = load_model(tmp_path / "front" / "close-loop" / "panda-calibrated.toml")
    comp = {n: v for n, v in arm.values.items() if n.endswith(".compliance")}
    assert len(comp) >= 5 and all(v >= 0 for v in comp.values()), comp
    by = {r.test: r for r in rows}
    assert _ratio(by["right"]) <= 1.0 and _ratio(by["back-high"]) <= 1.4, [r.figures for r in rows]


@pytest.mark.slow
def test_default_loop_on_every_placement_beats_the_published_tool(tmp_path):
    """Each placement trains, the other two are predicted (six pairs): mean spread at most 0.85x MUKCa's
    (measured 1.634 mm, 0.79x, joint 1's eccentricity from right by the tie rule; joint 3's alone 1.703 mm, joints 1
    and 3 together 1.642 mm; the loop before this default 1.795 mm, 0.87x), no pair above 1.35x its MUKCa pair
    (measured worst 1.30x, front -> back-high), the mean |distance error| within 0.15 mm of MUKCa's (measured 0.782
    against 0.666 mm: not yet no worse, docs/studies/close-loop.md says why) and the same effects at seeds 0 and 2 (the
    seed only draws the bootstrap of the held-out figures' uncertainties)."""
    rows = _study(tmp_path / "s0", PLACES)
    spread = np.mean([r.figures["spread_mean_mm"] for r in rows])
    dist = np.mean([abs(r.figures["distance_error_mm"]) for r in rows])
    assert spread <= 0.85 * 2.073, [(r.train, r.test, r.figures) for r in rows]
    assert max(_ratio(r) for r in rows) <= 1.35, [(r.train, r.test, _ratio(r)) for r in rows]
    assert dist <= 0.666 + 0.15, dist
    assert {r.train: r.effects for r in rows} == ADDED
    again = _study(tmp_path / "s2", ["right"], ["--seed", "2"])
    assert [r.effects for r in again] == [ADDED["right"]] * 2
    assert [r.figures for r in again] == [r.figures for r in rows if r.train == "right"]
