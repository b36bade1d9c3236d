"""Beyond the library: an effect hidden in the truth that the library does not hold leaves a significant
structure family; the loop builds the effect from it, cross-validates it like a library candidate, adds it
(reported as found from the residual), recovers its size within 3 sigma, and brings the held-out RMS within
1.3 times that of the same campaign without the effect."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from arm_model import load_description
from arm_model.effects import (ApproachOffset, EncoderEccentricity, JointHarmonics, LateralCompliance,
                               ProbeComplianceMatrix)
from arm_model.model import ArmModel
from arm_model.sim import campaign_from_dict, simulate
from calibration.candidates import Candidate
from calibration.data import Weights
from calibration.loop import close_loop
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration.synthesis import RESIDUAL, synthesise
from conftest import NOMINAL

NOISE = 2e-6
SPEC = SynthSpec(ballbars=10, ballbar_points=4, seats=4, articulations=8, spheres=5, sphere_points=8, noise=NOISE)

#: case -> (hidden effects, true values, force [N], expected added names in order)
CASES = {
    "wrist third harmonic": ((JointHarmonics(joints=(5,), harmonics=(3,)),),
                             {"j6.harm3_cos": 3.5e-5, "j6.harm3_sin": 6.0e-5}, 0.0, ["harmonics j6 (h 1,2,3)"]),
    "elbow lateral compliance": ((LateralCompliance(joints=(3,)),),
                                 {"j4.lateral_compliance_x": 1e-5, "j4.lateral_compliance_y": -8e-6}, 0.0,
                                 ["lateral compliance j4"]),
    "anisotropic probe": ((ProbeComplianceMatrix(),),
                          {"probe.dcompliance_xx": 3e-6, "probe.dcompliance_yy": -3e-6, "probe.dcompliance_xy": 4e-6},
                          3.0, ["probe compliance matrix"]),
    "lobing": ((ApproachOffset(),), {"approach.dx_uy": 6e-6, "approach.dy_ux": -4e-6, "approach.dz_ux": 5e-6}, 0.0,
               ["approach offset"]),
    "library and residual": ((EncoderEccentricity(joints=(1,), harmonics=(1, 2)), ApproachOffset()),
                             {"j2.ecc1_cos": 3e-5, "j2.ecc1_sin": 5e-5, "approach.dx_uy": 6e-6,
                              "approach.dy_ux": -4e-6, "approach.dz_ux": 5e-6}, 0.0,
                             ["eccentricity j2", "approach offset"]),
}


def _truth(effects, values, seed=1):
    nominal = load_description(NOMINAL)
    truth = ArmModel(nominal, tuple(effects))
    p = random_truth(truth, np.random.default_rng(seed), length=30e-6, angle=5e-5, probe=30e-6)
    p[truth.base_size:] = 0.0
    for k, v in values.items():
        p[truth.spec.index(k)] = v
    return nominal, truth, p


@lru_cache(maxsize=None)
def run(case: str | None, force: float = 0.0):
    """The loop on a small synthetic campaign (152 points, 19 measurements) with ``case`` hidden (None:
    the same campaign, same base errors, without it)."""
    effects, values, force = CASES[case][:3] if case else ((), {}, force)
    nominal, truth, p = _truth(effects, values)
    camp = make_campaign(truth, SynthSpec(**{**SPEC.__dict__, "force": force}), seed=1, p_true=p)
    return close_loop(camp.points, camp.artefacts, nominal, weights=Weights(probe=NOISE), cv_top=2)


def _within_3_sigma(result, values, names):
    checked = 0
    for n in names:
        if n not in result.free:            # held: not identifiable (e.g. the approach offset's trace)
            continue
        v, u = result.value(n), result.uncertainty(n)
        assert abs(v - values.get(n, 0.0)) <= 3 * u, f"{n}: {v:.4g} +- {u:.2g}, true {values.get(n, 0.0):.4g}"
        checked += 1
    assert checked


@pytest.mark.parametrize("case", list(CASES))
def test_loop_builds_adds_and_recovers_the_hidden_effect(case):
    effects, values, force, expected = CASES[case]
    loop = run(case)
    names = [c.name for c in loop.added]
    assert names[-len(expected):] == expected, loop.verdict
    assert [names.index(e) for e in expected] == sorted(names.index(e) for e in expected)     # in this order
    final = loop.final.result
    desc = final.model.desc
    built = [c for c in loop.added if c.name in expected and c.origin == RESIDUAL]
    assert built
    for c in built:                 # the size of what was built from the residual
        assert f"{c.name} (found from the residual)" in loop.verdict
        _within_3_sigma(final, values, c.param_names(desc))
    clean = run(None, force)
    assert loop.final.heldout["rms_um"] <= 1.3 * clean.final.heldout["rms_um"], (
        loop.final.heldout["rms_um"], clean.final.heldout["rms_um"])
    assert not loop.remaining, loop.verdict


def test_two_links_growing_at_different_rates_over_10_K():
    """Simulator: links j3 and j5 grow at 12 and 23 ppm/K over about 10 K. The library's common growth
    comes first, then each link's own rate from the residual ('temperature per link')."""
    tasks = [{"kind": "ballbar", "positions": 10, "length_mm": 600.0, "points_per_sphere": 4},
             {"kind": "seat", "articulations": 8, "measurements": 4},
             {"kind": "sphere", "points": 8, "measurements": 5}]

    def loop(thermal: bool):
        d = {"seed": 3, "sensor": "xyz", "signals": {"enabled": False}, "noise": {"probing_repeatability_um": 2.0},
             "task": tasks, "environment": {"drift_C_per_h": 8.0}, "operator": {"measurement_gap_s": 300.0}}
        if thermal:
            d["truth"] = {"thermal": {"joints": ["j3", "j5"], "alpha_per_K": [1.2e-5, 2.3e-5]}}
        camp = campaign_from_dict(d)
        sim = simulate(camp)
        return sim, close_loop(sim.points, sim.artefacts, camp.arm, weights=Weights(probe=2e-6), cv_top=2)

    sim, hot = loop(True)
    assert np.ptp(sim.points.temperature) > 9.0
    assert [c.name for c in hot.added] == ["thermal growth", "thermal growth per link"], hot.verdict
    assert hot.added[1].origin == RESIDUAL
    final = hot.final.result
    # in the model's terms: the common rate is the longest link's (j3), each other link its own minus it
    truth = {"links.thermal_alpha": 1.2e-5, "j5.thermal_alpha": 1.1e-5}
    truth.update({f"j{i}.thermal_alpha": -1.2e-5 for i in (1, 2, 4, 7)})
    _within_3_sigma(final, truth, list(truth))
    _, clean = loop(False)
    assert hot.final.heldout["rms_um"] <= 1.3 * clean.final.heldout["rms_um"]


def test_synthesis_offers_only_what_the_model_lacks():
    nominal = load_description(NOMINAL)
    base = ArmModel(nominal)
    names = [c.name for c in synthesise(["q6 harmonics"], base)]
    assert names == [f"harmonics j6 (h {h})" for h in ("1", "1,2", "1,2,3", "1,2,3,4")]
    with_ecc = base.with_effects(EncoderEccentricity(joints=(5,), harmonics=(1, 2)))
    assert [c.name for c in synthesise(["q6 harmonics"], with_ecc)] == ["harmonics j6 (h 3)", "harmonics j6 (h 3,4)"]
    cands = synthesise(["contact force", "approach direction", "j4 lateral load", "time", "measurement"], base)
    assert [c.name for c in cands] == ["probe compliance matrix", "approach offset", "lateral compliance j4"]
    assert all(isinstance(c, Candidate) and c.origin == RESIDUAL for c in cands)
    from arm_model.effects import ProbeCompliance
    iso = synthesise(["contact force"], base.with_effects(ProbeCompliance()))[0]
    assert iso.param_names(nominal) == ["probe.dcompliance_yy", "probe.dcompliance_zz", "probe.dcompliance_xy",
                                        "probe.dcompliance_xz", "probe.dcompliance_yz"]
    assert synthesise(["approach direction"], base.with_effects(ApproachOffset())) == []
