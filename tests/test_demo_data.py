"""The bundled data are what the simulator writes for their campaign (not stale).

Compared value by value rather than byte by byte: a newer numpy/scipy (or another BLAS) may move the
simulator's inverse kinematics in the last bits, which can flip the last printed digit of a force (1e-6 N)
or end the redundant arm on a slightly different articulation (seen between two machines: one or two
quantisation steps of 1e-4 deg on 10 % of the readings of a joint). So the encoder readings are compared
through what they measure: the ball centres the nominal arm computes from them agree within 2 um (a few
quantisation steps at the arm's reach), and each reading within 0.01 deg. Anything larger means the bundled
data are stale. The forces are given in the probe frame, which turns with the articulation: they agree
within 0.1 mN.
"""
from __future__ import annotations

import csv

import numpy as np

from arm_model.kinematics import ball_centres
from arm_model.sim import load_campaign, simulate
from conftest import ROOT

BUNDLED = ROOT / "examples" / "data" / "paper-ring-xyz"
#: one or two printed digits per column unit (encoder readings: see the module's text)
TOLERANCE = {"_deg": 1e-2, "_N": 1e-4, "_C": 2.01e-6, "_s": 1.01e-3, "_mm": 2.01e-6}


def _table(path):
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def test_bundled_ring_campaign_is_regenerable(tmp_path):
    result = simulate(load_campaign(ROOT / "examples" / "campaigns" / "paper-ring-xyz.toml"))
    result.write(tmp_path)
    hint = "regenerate it with aacmm simulate examples/campaigns/paper-ring-xyz.toml -o DIR --no-signals"
    assert (tmp_path / "artefacts.toml").read_bytes() == (BUNDLED / "artefacts.toml").read_bytes(), \
        f"examples/data/paper-ring-xyz/artefacts.toml is stale: {hint}"
    head_new, new = _table(tmp_path / "points.csv")
    head_old, old = _table(BUNDLED / "points.csv")
    assert head_new == head_old and len(new) == len(old), f"points.csv is stale: {hint}"
    for j, name in enumerate(head_new):
        a = [r[j] for r in new]
        b = [r[j] for r in old]
        unit = next((u for u in TOLERANCE if name.endswith(u)), None)
        if unit is None:
            assert a == b, f"points.csv column {name} is stale: {hint}"
            continue
        diff = np.abs(np.array(a, float) - np.array(b, float))
        assert diff.max() <= TOLERANCE[unit], (f"points.csv column {name} differs by {diff.max():.3g} "
                                               f"(> {TOLERANCE[unit]}): {hint}")
        if unit not in ("_deg", "_N"):        # these two follow the articulation
            assert np.mean(diff > 0) < 0.05, f"points.csv column {name}: over 5 % of values differ: {hint}"
    cols = [head_new.index(f"q{i + 1}_deg") for i in range(result.campaign.arm.n_joints)]
    q_new, q_old = (np.deg2rad(np.array([[float(r[j]) for j in cols] for r in t])) for t in (new, old))
    gap = np.linalg.norm(ball_centres(result.campaign.arm, q_new) - ball_centres(result.campaign.arm, q_old), axis=1)
    assert gap.max() < 2e-6, f"points.csv: the readings put the ball {gap.max() * 1e6:.3g} um elsewhere: {hint}"
