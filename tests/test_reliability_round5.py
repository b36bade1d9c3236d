"""Reliability, round 5: a hostile-input audit of every command and of the Python API (arm_model, calibration,
correction). Each test is named after what it checks; all are fast (a few points, no long fit)."""
from __future__ import annotations

import dataclasses
import math

import pytest

from arm_model.cli import main
from conftest import NOMINAL


# ---------------------------------------------------------------------------------------------
# the Python API: an Arm refuses what its model file's reader would refuse

@pytest.mark.parametrize("kw, match", [
    ({"discrepancy_growth": 0.02}, "needs 'model_discrepancy_um'"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": 0.02}, "needs 'training_poses'"),
    ({"model_discrepancy": 5e-6, "discrepancy_growth": -0.02}, "model_discrepancy_growth_um_per_mm"),
    ({"model_discrepancy": math.nan}, "model_discrepancy_um"),
    ({"model_discrepancy": 1.0}, "model_discrepancy_um"),
    ({"probing_scatter": math.inf}, "probing_scatter_um"),
])
def test_an_arm_built_in_python_refuses_a_growth_it_would_ignore(kw, match):
    """Arm(model_discrepancy=None, discrepancy_growth>0) silently dropped the growth (discrepancy was then None);
    it is a ValueError now, as the model file's reader refuses the same [calibration] table."""
    from arm_model.model_file import load_model
    arm = load_model(str(NOMINAL))
    with pytest.raises(ValueError, match=match):
        dataclasses.replace(arm, **kw)


def test_an_arm_with_its_growth_and_poses_is_accepted(tmp_path):
    from arm_model.model_file import load_model
    arm = dataclasses.replace(load_model(str(NOMINAL)), model_discrepancy=5e-6, discrepancy_growth=0.0)
    assert arm.discrepancy == 5e-6
    arm = dataclasses.replace(arm, discrepancy_growth=0.02, training_poses=tmp_path / "tp.csv")
    assert arm.discrepancy_growth == 0.02


# ---------------------------------------------------------------------------------------------
# a long text cell: memory in proportion to the file, not to the square of the cell

def test_a_long_measurement_id_reads_and_writes_in_memory_in_proportion_to_the_file(tmp_path):
    """A 10 000-character measurement id in a 2000-row points file: the fast reader built a (width + 1, width)
    mask table (800 MB here, 20 GB for a 100 kB id in a 30-row file: `tip` ended "out of memory") and both the
    reader and the CSV writer a (rows, widest cell) matrix (a 17 MB file with one 100 kB id: 94 s, 4.9 GB)."""
    import tracemalloc

    import numpy as np

    from arm_model.csv_io import format_csv
    from arm_model.io import read_points
    from arm_model.model_file import load_model
    joints = load_model(str(NOMINAL)).desc.joint_quantities
    long_id = "m" * 10_000
    cols = ",".join(f"q{k + 1}_deg" for k in range(7))
    rows = [f"{long_id if i == 0 else 'short'},seat," + ",".join(f"{10 + k + i * 1e-3:.6f}" for k in range(7)) + "\n"
            for i in range(2000)]
    (tmp_path / "p.csv").write_text(f"measurement,feature,{cols}\n" + "".join(rows))
    tracemalloc.start()
    try:
        pts = read_points(tmp_path / "p.csv", joints)
        text = format_csv({"measurement": np.asarray(pts.measurement, dtype=object), "x_mm": pts.q[:, 0]})
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert pts.measurement[0] == long_id and pts.measurement[1] == "short" and len(pts.q) == 2000
    assert text.decode().splitlines()[1].startswith(long_id + ",")
    assert peak < 30e6, f"peak {peak / 1e6:.0f} MB for a {(tmp_path / 'p.csv').stat().st_size / 1e6:.1f} MB file"


def test_a_megabyte_value_in_an_error_is_cut_in_its_middle(tmp_path, capsys):
    """A key holding a 1 MB text where a number belongs: the error quoted it whole (one 1 MB line on standard
    error); the line keeps its start (file, line, key) and end, the middle cut and counted."""
    from arm_model.log import MAX_LINE
    text = NOMINAL.read_text().replace("d_mm = 200.0", 'd_mm = "' + "a" * 1_000_000 + '"', 1)
    (tmp_path / "arm.toml").write_text(text)
    (tmp_path / "p.csv").write_text("measurement,feature," + ",".join(f"q{k}_deg" for k in range(1, 8)) + "\n"
                                    "m,f,1,2,3,4,5,6,7\n")
    assert main(["tip", str(tmp_path / "p.csv"), "--arm", str(tmp_path / "arm.toml"), "-o", str(tmp_path / "o.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and len(err) < MAX_LINE + 100, len(err)
    assert "arm.toml, line 11, key 'joint[1].d_mm'" in err and "characters left out" in err
    assert not (tmp_path / "o.csv").exists()
