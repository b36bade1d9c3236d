"""The closed loop on simulated campaigns with one undeclared effect each (present in the simulator's
truth, absent from the model): the loop must name the effect and its joint, recover its size within
3 sigma, and at least halve the held-out error of the outer test set."""
from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from arm_model.sim import campaign_from_dict, simulate
from calibration.data import Weights
from calibration.loop import close_loop

#: a small campaign: ball bar, seat articulations, spheres (about 150 points, 19 measurements)
TASKS = [{"kind": "ballbar", "positions": 10, "length_mm": 600.0, "points_per_sphere": 4},
         {"kind": "seat", "articulations": 8, "measurements": 4},
         {"kind": "sphere", "points": 8, "measurements": 5}]
NOISE_UM = 2.0

#: hidden effect -> (campaign sections, expected candidate name, expected joint)
CASES = {
    "eccentricity": ({"truth": {"eccentricity": [{"joint": "j2", "amplitude_deg": 0.004, "phase_deg": 30.0}]}},
                     "eccentricity j2", "j2"),
    "joint_compliance": ({"truth": {"joint_compliance": {"joints": ["j2"], "stiffness_Nm_per_rad": [2e5]}}},
                         "joint compliance j2", "j2"),
    "thermal": ({"truth": {"thermal": {"alpha_per_K": [2.3e-5]}}, "environment": {"drift_C_per_h": 8.0},
                 "operator": {"measurement_gap_s": 300.0}}, "thermal growth", None),
    "force_sensor": ({"truth": {"force_sensor": {"gain": [0.3, 0.0, 0.0]}}, "operator": {"force_mean_N": 6.0}},
                     "force sensor x", None),
    "probe_compliance": ({"truth": {"probe_compliance": {"bending_mm_per_N": 0.0182}},
                          "operator": {"force_mean_N": 4.0}}, "probe compliance (isotropic)", None),
}


def campaign(sections: dict, seed: int = 3) -> dict:
    d = {"seed": seed, "sensor": "xyz", "signals": {"enabled": False},
         "noise": {"probing_repeatability_um": NOISE_UM}, "task": TASKS}
    for k, v in sections.items():
        d[k] = {**d.get(k, {}), **v}
    return d


@cache
def run(case: str):
    camp = campaign_from_dict(campaign(CASES[case][0]))
    sim = simulate(camp)
    loop = close_loop(sim.points, sim.artefacts, camp.arm, reference=sim.reference_points,
                      weights=Weights(probe=NOISE_UM * 1e-6), cv_top=2)
    return sim, loop


def truth_vector(sim, result) -> np.ndarray:
    """The simulator's truth in the fitted model's parameters (names they share; a probe-compliance truth
    in the model's increment names), moved along the fit's unidentifiable combinations."""
    spec = result.model.spec
    truth = dict(sim.truth["p"])
    probe = sim.truth["effects"].get("probe_compliance") if isinstance(sim.truth.get("effects"), dict) else None
    declared = sim.campaign.arm.probe.compliance
    if probe is not None:
        truth.setdefault("probe.dcompliance_bend", probe["bending_x"] - declared[0])
        truth.setdefault("probe.dcompliance_x", probe["bending_x"] - declared[0])
        truth.setdefault("probe.dcompliance_y", probe["bending_y"] - declared[1])
    return result.equivalent(spec.vector({n: v for n, v in truth.items() if n in spec.names}))


#: in make test-slow only (the test time's budget): a harmonic the loop builds, adds and recovers is make test's
#: test_loop_cross_harmonics and test_loop_synthesis [lobing]; the probe's deflection signature, the force_sensor case;
#: a hidden joint compliance, make test's test_model_file (found on this arm, j2's beside an eccentricity),
#: test_loop_sim_seats and test_loop_real_physics (robots: found, recovered within 3 sigma, the held-out spread cut);
#: thermal growth (8 s of CPU): a library effect named, recovered within 3 sigma and the held-out error halved is the
#: force_sensor case, the loop adding a library effect from the command line test_loop_cli close_loop_writes_the_report,
#: the thermal rate recovered from a drifting campaign test_model_file calibrate_writes_a_model (within 20 %)
SLOW_CASES = ("eccentricity", "probe_compliance", "joint_compliance", "thermal")


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c in SLOW_CASES else c for c in CASES])
def test_loop_names_recovers_and_halves(case):
    sim, loop = run(case)
    _, name, joint = CASES[case]
    assert [c.name for c in loop.added] == [name], loop.verdict
    assert loop.added[0].joint == joint
    final = loop.final.result
    p_truth = truth_vector(sim, final)
    effect_names = loop.added[0].param_names(final.model.desc)
    checked = 0
    for n in effect_names:
        if n not in final.free:           # e.g. a force offset: absorbed by the probe offset, held
            continue
        i = final.model.spec.index(n)
        u = final.uncertainty(n)
        assert u > 0
        assert abs(final.p[i] - p_truth[i]) < 3 * u, f"{n}: {final.p[i]:.4g} vs truth {p_truth[i]:.4g} (u {u:.2g})"
        checked += 1
    assert checked >= 1
    rows = loop.before_after()
    assert rows[-1]["rms_um"] <= 0.5 * rows[0]["rms_um"], rows
    # nothing else is claimed, and the verdict says what was added
    assert name in loop.verdict
    assert not loop.remaining, loop.verdict


def test_force_gain_and_compliance_signatures_are_reported_as_indistinguishable():
    """A gain error of the force sensor's x axis deflects the probe like an x bending compliance error: the
    loop keeps the smaller effect and lists the one that explains the same."""
    _, loop = run("force_sensor")
    stage = loop.stages[1]
    assert "probe compliance (anisotropic)" in stage.nested + stage.alternatives


@pytest.mark.slow
@pytest.mark.parametrize("seed", [4, 5])
@pytest.mark.parametrize("case", list(CASES))
def test_loop_names_the_effect_on_other_seeds(case, seed):
    """Not tuned to one draw (slow suite: ten loops, about 50 s of CPU; the normal suite checks each effect on
    seed 3 in test_loop_names_recovers_and_halves): on other seeds (new errors, poses, noise, test set)
    the loop names the same effect and joint and lowers the held-out error. (How much depends on the draw:
    where the effect is small next to the 2 um probing noise the RMS cannot halve; see docs/studies/close-loop.md.)
    Where the outer test set cannot show it (its RMS already at the noise, measured: thermal growth at seed
    4, 1.71 -> 1.83 um) the effect, which passed the held-out folds, is named as not added, never added."""
    camp = campaign_from_dict(campaign(CASES[case][0], seed=seed))
    sim = simulate(camp)
    loop = close_loop(sim.points, sim.artefacts, camp.arm, reference=sim.reference_points,
                      weights=Weights(probe=NOISE_UM * 1e-6), cv_top=2)
    _, name, joint = CASES[case]
    if not loop.added and [v["name"] for v in loop.vetoed][:1] == [name]:
        # it passed the held-out folds, but an outer test set that cannot show it (a few measurements at the
        # noise) got worse with it: never added then, and said
        assert f"Not added, the outer test set got worse with it: {name}" in loop.verdict
        return
    assert [c.name for c in loop.added] == [name], loop.verdict
    assert loop.added[0].joint == joint
    rows = loop.before_after()
    assert rows[-1]["rms_um"] < rows[0]["rms_um"], rows


def test_resolved_counts_a_free_value_below_minus_z_u_as_negative():
    """A parameter resolved below -z u (z two-sided at alpha, Bonferroni over the names: 2.807 for alpha 0.01
    and two of them) is significantly negative; -2 u is not. (Every fit holds a compliance at its bound 0, so a
    compliance is negative here only through the value the data pulled it to: tests/test_compliance_bounds.py.)"""
    from types import SimpleNamespace

    from calibration.loop import resolved
    vals = {"j2.a": (-3.0e-6, 1e-6), "j3.a": (-2.0e-6, 1e-6)}
    res = SimpleNamespace(free=tuple(vals), fixed=(), value=lambda n: vals[n][0], uncertainty=lambda n: vals[n][1])
    assert resolved(res, list(vals), 0.01)[1] == ["j2.a"]
    vals["j2.a"] = (-2.80e-6, 1e-6)
    assert resolved(res, list(vals), 0.01)[1] == []
