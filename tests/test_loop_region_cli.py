"""``aacmm close-loop --region-effect``: the final model's fit estimates the parameters' random effect between regions
of the joint space (calibration/region.py) and its covariance file carries it, as ``calibrate --region-effect``'s."""
from __future__ import annotations

import importlib
import json

import numpy as np
import pytest

from arm_model.cli import main
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from conftest import NOMINAL

COV = "aacmm7-calibrated-covariance.csv"


@pytest.fixture(scope="module")
def files(tmp_path_factory, nominal):
    """A small campaign whose model holds (the loop's close-loop run on it: about 1.5 s of CPU)."""
    c = make_campaign(ArmModel(nominal), SynthSpec(ballbars=3, ballbar_points=5, seats=2, articulations=8, spheres=0,
                                                   noise=2e-6), seed=4)
    return c.write(tmp_path_factory.mktemp("campaign"))


def _loop(f, out, *extra, quiet: bool = True) -> dict:
    assert main(["close-loop", str(f["points"]), str(f["artefacts"]), "--arm", str(NOMINAL), "--effect", "none",
                 "--max-effects", "0", "--library-only", "--folds", "2", *(["--quiet"] if quiet else []), "--no-plots",
                 "-o", str(out), *extra]) == 0
    return json.loads((out / "summary.json").read_text())


def test_close_loop_region_effect_reaches_the_model_file(files, tmp_path, monkeypatch, capsys):
    """Off by default; ``--region-effect`` with the Monte Carlo test switched off (no null draws: the variances kept
    as estimated) puts the effect into summary.json (``model.region_effect``) and into the covariance file, whose
    variances hold the region's on top of the posterior's; the effect is estimated once, on the final model's fit
    (the loop's folds and the torques' refinement do without it)."""
    from arm_model.model_file import read_covariance
    from calibration import region
    from calibration.loop import LoopSettings
    assert LoopSettings().region_effect is False
    monkeypatch.setattr(region, "NULL_DRAWS", 0)
    state = importlib.import_module("calibration.loop.state")
    seen, flags = [], []
    original, fit = region.region_effect, state.calibrate

    def spy(*args, **kwargs):
        seen.append(original(*args, **kwargs))
        return seen[-1]

    def counted(model, data, options):
        flags.append(options.region_effect)
        return fit(model, data, options)
    monkeypatch.setattr(importlib.import_module("calibration.calibrate"), "region_effect", spy)
    monkeypatch.setattr(state, "calibrate", counted)
    on = _loop(files, tmp_path / "on", "--region-effect", quiet=False)
    assert "region effect (the model file's covariance): kept: likelihood ratio" in capsys.readouterr().out
    assert flags[-1] and not any(flags[:-1]) and seen         # the final model's fit only, not the loop's folds
    reg = on["model"]["region_effect"]
    assert on["settings"]["region_effect"] is True and reg["folds"] > 0 and reg["sd_per_prior_sd"]
    cov = read_covariance(tmp_path / "on" / COV)
    added = dict(zip(seen[0].names, seen[0].variance, strict=True))
    var = np.diag(cov.matrix)
    assert set(reg["sd_per_prior_sd"]) <= set(cov.names)
    for name in reg["sd_per_prior_sd"]:                 # the file holds the posterior plus the region's variance
        i = cov.names.index(name)
        assert var[i] > added[name] > 0
