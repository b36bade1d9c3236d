"""docs/own-arm.md, "A robot with a tracker": its commands run as written on the real TALOS motion-capture
campaign (read from ``../shared``: its URDF's licence forbids a copy in the project), and the held-out
figures its table states are the ones they give."""
from __future__ import annotations

import json
import re
import shlex

import numpy as np
import pytest

from arm_model.cli import main
from arm_model.model_file import load_model
from conftest import ROOT

TALOS = ROOT.parent / "shared" / "data" / "real-talos-mocap"
DOC = ROOT / "docs" / "own-arm.md"

pytestmark = pytest.mark.skipif(not (TALOS / "talos_full_v2.urdf").exists(),
                                reason=f"the TALOS campaign is not at {TALOS} (its URDF's licence forbids a copy "
                                       "in the project; it is read from ../shared beside the repository)")


def _section() -> str:
    text = DOC.read_text()
    return text[text.index("### A robot with a tracker"):]


def _commands(tmp_path) -> list[list[str]]:
    block = re.search(r"```\n(aacmm calibrate talos/.*?)```", _section(), flags=re.S).group(1)
    out = []
    for line in block.strip().splitlines():
        argv = shlex.split(line)[1:]
        argv = [str(TALOS / a.split("/", 1)[1]) if a.startswith("talos/") else a for a in argv]
        argv = [str(tmp_path / a) if a.startswith("talos-") else a.replace("talos-cal/", f"{tmp_path}/talos-cal/")
                for a in argv]
        out.append(argv)
    return out


def _stated(row: str) -> tuple[float, float]:
    """(held-out RMS, max) [mm] of the doc table's row that starts with ``row``."""
    line = next(ln for ln in _section().splitlines() if ln.startswith(f"| {row}"))
    rms, mx = re.findall(r"([0-9.]+) mm", line)
    return float(rms), float(mx)


def test_the_tracker_walkthrough_runs_and_gives_the_figures_it_states(tmp_path):
    calibrate, tip = _commands(tmp_path)
    assert calibrate[0] == "calibrate" and "--no-plots" not in calibrate
    assert main(calibrate + ["--no-plots"]) == 0
    assert main(tip) == 0
    summary = json.loads((tmp_path / "talos-cal" / "summary.json").read_text())
    fig = {r["key"]: r for r in summary["validation_holdout"]}
    rms, mx = fig["reference_rms_predicted"], fig["reference_max_predicted"]
    assert (round(rms["before"] / 1e3, 2), round(mx["before"] / 1e3, 2)) == _stated("nominal URDF")
    assert (round(rms["after"] / 1e3, 2), round(mx["after"] / 1e3, 2)) == _stated("**these commands**")
    assert len(summary["holdout"]) == 30 and summary["inputs"]["artefacts"] is None
    # tip's prediction of the held-out rows, from the model file alone, gives the same figure
    arm = load_model(tmp_path / "talos-cal" / "talos-calibrated.toml")
    assert arm.tracker is not None and arm.tracker.offsets.shape == (1, 3)
    t = np.genfromtxt(tmp_path / "talos-tips.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    held = np.isin(t["measurement"], summary["holdout"])
    assert np.sqrt(np.mean(t["error_ref_um"][held] ** 2)) == pytest.approx(rms["after"], rel=1e-6)
