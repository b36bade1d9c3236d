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
