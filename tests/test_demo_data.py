"""The bundled data are what the simulator writes for their campaign (not stale).

Compared value by value rather than byte by byte: a newer numpy/scipy may move the simulator's inverse
kinematics in the last bits, which can flip one quantisation step of an encoder reading (1e-4 deg) or the
last printed digit of a force (1e-6 N). Anything larger means the bundled data are stale.
"""
from __future__ import annotations

import csv

import numpy as np

from arm_model.sim import load_campaign, simulate
from conftest import ROOT

BUNDLED = ROOT / "examples" / "data" / "paper-ring-xyz"
#: one encoder quantisation step [deg] or one printed digit, per column unit
TOLERANCE = {"_deg": 1.01e-4, "_N": 2.01e-6, "_C": 2.01e-6, "_s": 1.01e-3, "_mm": 2.01e-6}


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
        assert np.mean(diff > 0) < 0.05, f"points.csv column {name}: over 5 % of values differ: {hint}"
