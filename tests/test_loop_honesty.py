"""Honesty of the closed loop: with no missing effect it adds nothing (at most 1 in 20 seeds); with an
effect the library does not hold (a third-harmonic encoder error, made by a truth model outside the
library) it reports structured residual, names the regressor, and claims no fix."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model.effects import EncoderEccentricity
from arm_model.model import ArmModel
from arm_model.sim import campaign_from_dict, simulate
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration.data import Weights
from calibration.loop import close_loop

#: tiny campaign: about 100 points, 14 measurements
TINY = [{"kind": "ballbar", "positions": 6, "length_mm": 600.0, "points_per_sphere": 4},
        {"kind": "seat", "articulations": 6, "measurements": 4},
        {"kind": "sphere", "points": 7, "measurements": 4}]


def _clean_loop(seed: int, **settings):
    """The loop on a clean tiny campaign (no effect missing from the model) of ``seed``."""
    camp = campaign_from_dict({"seed": seed, "sensor": "xyz", "signals": {"enabled": False},
                               "noise": {"probing_repeatability_um": 2.0}, "task": TINY})
    sim = simulate(camp)
    return close_loop(sim.points, sim.artefacts, camp.arm, weights=Weights(probe=2e-6), cv_top=2, seed=seed,
                      **settings)


def test_no_missing_effect_adds_nothing_on_seed_1():
    """The study below on its seed 1 (about 4 s of CPU; seed 0 runs in make test-slow's study, seed 4 end to end in
    test_honesty_study_counts_what_the_loop_added_built_and_claimed, and the clean twins of test_loop_cross_harmonics
    and test_loop_synthesis add nothing either): nothing added, no structure claimed. (The docstring of the two-seed
    test this replaces said an over-eager loop, ``alpha=0.5, min_improvement=0``, claimed structure on seed 1; on
    main of 2026-11-28 it claims nothing on seed 0 or 1: the fold rule and the outer test set hold it too.)"""
    loop = _clean_loop(1)
    assert not loop.added and not loop.remaining, loop.verdict


@pytest.mark.slow
def test_no_missing_effect_adds_nothing_in_19_of_20_seeds():
    """(slow: 20 campaigns, about 80 s of CPU; make test runs seed 1 in test_no_missing_effect_adds_nothing_on_seed_1
    and seed 4 end to end in test_honesty_study_counts_what_the_loop_added_built_and_claimed)"""
    added, claims = [], []
    for seed in range(20):
        loop = _clean_loop(seed)
        added.append(bool(loop.added))
        claims.append(bool(loop.remaining))
    assert sum(added) <= 1, f"effects added in {sum(added)} of 20 seeds"
    assert sum(claims) <= 1, f"structure claimed in {sum(claims)} of 20 seeds"


#: the outer test set of these two tests' scenario (drawn at random, seed 0, before the test set became a
#: function of the data; the default one, bar-03, bar-08, seat-03 and sphere-03, lets an eccentricity j2 pass
#: the folds, which the outer test set then refuses, and leaves a "q3 harmonics on j1" claimed after the
#: harmonics are built: docs/studies/close-loop.md, Decisions that carry over)
THIRD_TEST = ("bar-07", "bar-08", "seat-02", "sphere-02")


def _third_harmonic_campaign(nominal):
    truth = ArmModel(nominal, (EncoderEccentricity(joints=(1,), harmonics=(3,)),))
    rng = np.random.default_rng(1)
    p = random_truth(truth, rng, length=30e-6, angle=5e-5, probe=30e-6)
    a = np.radians(0.004)
    p[truth.spec.index("j2.ecc3_cos")] = a * np.sin(0.5)
    p[truth.spec.index("j2.ecc3_sin")] = a * np.cos(0.5)
    return make_campaign(truth, SynthSpec(ballbars=10, ballbar_points=4, seats=4, articulations=8, spheres=5,
                                          sphere_points=8, noise=2e-6), seed=1, p_true=p)


def test_effect_outside_the_library_is_named_not_fixed_by_the_library_alone(nominal):
    """Third harmonic of the j2 encoder error (the library offers harmonics 1 and 2), the loop held to the
    library (``synthesise=False``): structure named, no fix claimed."""
    camp = _third_harmonic_campaign(nominal)
    loop = close_loop(camp.points, camp.artefacts, nominal, weights=Weights(probe=2e-6), cv_top=2, synthesise=False,
                      holdout=THIRD_TEST)
    assert not loop.added, loop.verdict
    assert loop.remaining, loop.verdict
    fam, test, p_adj = loop.remaining[0]
    assert fam.name == "q2 harmonics" and test.best == "cos/sin(3 q2)"
    assert p_adj < 1e-6 and test.explained_cv > 0.5
    assert "Structured residual remains" in loop.verdict and "No fix is claimed" in loop.verdict
    assert "cos/sin(3 q2)" in loop.verdict


#: in make test-slow (a loop of about 150 points, 6-7 s of CPU): make test holds each of its steps, the family found
#: (the test above, on this campaign), its harmonics offered (test_loop_synthesis
#: synthesis_offers_only_what_the_model_lacks) and a harmonic built from the residual, cross-validated, added and
#: recovered within 3 sigma (test_loop_cross_harmonics cross_coupled_harmonic_is_built_added_and_recovered)
@pytest.mark.slow
def test_effect_outside_the_library_is_built_from_the_residual(nominal):
    """The same campaign, the loop free to build effects: the q2 harmonics family becomes a joint-angle
    error of j2 with harmonics up to 3 (the order chosen on held-out data), added and reported as found
    from the residual; nothing remains."""
    camp = _third_harmonic_campaign(nominal)
    loop = close_loop(camp.points, camp.artefacts, nominal, weights=Weights(probe=2e-6), cv_top=2, holdout=THIRD_TEST)
    assert [c.name for c in loop.added] == ["harmonics j2 (h 1,2,3)"], loop.verdict
    assert "harmonics j2 (h 1,2,3) (found from the residual)" in loop.verdict
    assert not loop.remaining and "No structured residual remains" in loop.verdict
    r = loop.final.result
    a = np.radians(0.004)
    for name, true in (("j2.harm3_cos", a * np.sin(0.5)), ("j2.harm3_sin", a * np.cos(0.5))):
        assert abs(r.value(name) - true) <= 3 * r.uncertainty(name), (name, r.value(name), r.uncertainty(name))


def test_honesty_study_counts_what_the_loop_added_built_and_claimed(tmp_path):
    """scripts/honesty_study.py (the study behind docs/studies/close-loop.md's table of larger clean campaigns): one
    seed of the tiny shape runs end to end, and the counts are checked against hand-written rows."""
    import json
    import sys

    from conftest import ROOT
    sys.path.insert(0, str(ROOT / "scripts"))
    import honesty_study

    assert honesty_study.main(["--shape", "tiny", "--seeds", "4", "-o", str(tmp_path)]) == 0
    (row,) = json.loads((tmp_path / "results.json").read_text())
    assert row["seed"] == 4 and row["points"] == 100 and row["temperature_span_K"] > 8.0
    assert row["added"] == [] and row["structure_claimed"] == []
    # the outer test set's judgement leaves a clean campaign's verdict as it was: not worse, nothing escalated
    assert not row["heldout_worse"] and row["escalated"] is None and row["verdict_clean"]
    rows = [{"seed": 0, "added": [], "built": [], "structure_claimed": []},
            {"seed": 1, "added": [{"name": "approach offset", "origin": "residual"}],
             "built": [{"name": "approach offset", "added": True, "why_not_added": None}], "structure_claimed": []},
            {"seed": 2, "added": [{"name": "thermal growth", "origin": "library"}],
             "built": [{"name": "lateral compliance j7", "added": False, "why_not_added": "not significant"}],
             "structure_claimed": ["j7 lateral load"]}]
    assert honesty_study.summary(rows).splitlines()[:5] == [
        "3 clean campaigns", "effect added: 2 of 3 (seeds 1, 2); of them built from the residual: 1",
        "an effect built from the residual (added or not): 2 of 3 (seeds 1, 2)",
        "structure claimed: 1 of 3 (seeds 2)",
        "outer test set worse than stated: 0 of 3; opt-in families offered: 0 of 3"]
    assert honesty_study._seeds("0-2,7") == [0, 1, 2, 7]
