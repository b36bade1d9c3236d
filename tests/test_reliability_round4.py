"""Reliability, round 4: a hostile-input audit of the growing model discrepancy's model-file keys
([calibration] model_discrepancy_growth_um_per_mm, training_poses naming a points file beside the model file)
through the commands that read a model file (tip, view, ring, live) and the Python API. Each test is named after
what it checks; all are fast (a few points, no fit)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from arm_model import InputError
from arm_model.cli import main
from conftest import NOMINAL

GROWTH = "model_discrepancy_um = 5.0\nmodel_discrepancy_growth_um_per_mm = 20.0\n"
Q_DEG = np.array([[10.0, 20.0, -30.0, 40.0, 5.0, -15.0, 25.0], [-10.0, 35.0, 12.0, -40.0, 8.0, 30.0, -5.0]])


def points_text(q_deg) -> str:
    cols = ",".join(f"q{k + 1}_deg" for k in range(q_deg.shape[1]))
    return f"measurement,feature,{cols}\n" + "".join(
        "m,seat," + ",".join(f"{x:.12g}" for x in row) + "\n" for row in q_deg)


@pytest.fixture
def folder(tmp_path):
    """A model file with a growth, its training poses beside it and a points file: tip reads them."""
    (tmp_path / "tp.csv").write_text(points_text(Q_DEG))
    (tmp_path / "points.csv").write_text(points_text(Q_DEG + 3.0))
    return tmp_path


def model(folder, calibration: str, name: str = "m.toml"):
    path = folder / name
    path.write_text(NOMINAL.read_text() + "\n[calibration]\n" + calibration)
    return path


def tip(folder, arm, out, *more) -> int:
    return main(["tip", str(folder / "points.csv"), "--arm", str(arm), "-o", str(out), "--uncertainty", *more])


# ---------------------------------------------------------------------------------------------
# outputs never over the training poses

def test_tip_output_over_the_training_poses_file_is_refused(folder, capsys):
    arm = model(folder, GROWTH + 'training_poses = "tp.csv"\n')
    before = (folder / "tp.csv").read_bytes()
    assert tip(folder, arm, folder / "tp.csv") == 2
    assert "over an input" in capsys.readouterr().err
    assert (folder / "tp.csv").read_bytes() == before


def test_the_arm_inputs_name_the_training_poses_file(folder):
    """Every command guards its outputs against arm_inputs: the training poses file is one of them (an output
    folder holding it, e.g. calibrate's -o of the run that wrote it, is refused as for the covariance file)."""
    import argparse

    from arm_model.cli_options import arm_inputs
    sub = folder / "run1"
    sub.mkdir()
    (sub / "tp.csv").write_text(points_text(Q_DEG))
    arm = model(folder, GROWTH + 'training_poses = "run1/tp.csv"\n')
    args = argparse.Namespace(arm=arm, tip_frame=None, masses=None, base_frame=None)
    assert any(str(p).endswith("tp.csv") for p in arm_inputs(args))


def test_ring_output_folder_holding_the_training_poses_is_refused(folder, capsys):
    from conftest import ROOT
    sub = folder / "poses"
    sub.mkdir()
    (sub / "tp.csv").write_text(points_text(Q_DEG))
    arm = model(folder, GROWTH + 'training_poses = "poses/tp.csv"\n')
    ring = ROOT / "examples" / "data" / "paper-ring-xyz"
    rc = main(["ring", str(ring / "points.csv"), str(ring / "artefacts.toml"), "--arm", str(arm), "-o", str(sub)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "over an input" in err and "tp.csv" in err, err
    assert (sub / "tp.csv").read_text() == points_text(Q_DEG)
