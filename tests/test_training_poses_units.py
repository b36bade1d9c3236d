"""A model file's training-poses file (the poses its growing discrepancy is measured from) is a points file: angles
that look like radians under its `_deg` columns are warned of as in every points file (arm_model.checks)."""
from __future__ import annotations

import numpy as np

from conftest import ROOT, exit_status

RING = ROOT / "examples" / "data" / "paper-ring-xyz" / "points.csv"


def _model(tmp_path, scale: float):
    """A model file of aacmm7 with a growing discrepancy and its training poses: the ring's first 5 poses in degrees
    times ``scale`` (np.pi / 180: the same angles written in radians)."""
    rows = RING.read_text().splitlines()
    head = rows[0].split(",")
    joints = [i for i, h in enumerate(head) if h.endswith("_deg")]
    lines = [",".join(["measurement", "feature", *(head[i] for i in joints)])]
    for row in rows[1:6]:
        cells = row.split(",")
        lines.append(",".join([cells[0], cells[1], *(repr(float(cells[i]) * scale) for i in joints)]))
    (tmp_path / "train.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "points.csv").write_text("\n".join(rows[:11]) + "\n")          # 10 points to correct
    model = tmp_path / "m.toml"
    model.write_text((ROOT / "urdf" / "aacmm7.dh.toml").read_text() + "\n[calibration]\nmodel_discrepancy_um = 5.0\n"
                     'model_discrepancy_growth_um_per_mm = 1.0\ntraining_poses = "train.csv"\n')
    return model


def test_training_poses_in_radians_under_deg_columns_are_warned_of(tmp_path, capsys):
    model = _model(tmp_path, np.pi / 180.0)
    rc = exit_status(["tip", str(tmp_path / "points.csv"), "--arm", str(model), "-o", str(tmp_path / "t.csv"),
                      "--uncertainty"])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "were the angles written in radians?" in err and f"{tmp_path / 'train.csv'} lines 2, 3, 4, 5, 6" in err, err


def test_training_poses_in_degrees_are_not_warned_of(tmp_path, capsys):
    model = _model(tmp_path, 1.0)
    rc = exit_status(["tip", str(tmp_path / "points.csv"), "--arm", str(model), "-o", str(tmp_path / "t.csv"),
                      "--uncertainty"])
    err = capsys.readouterr().err
    assert rc == 0 and "radians" not in err, err
