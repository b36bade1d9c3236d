"""The loop's verdict judges the outer test set too (calibration.loop.verdict.heldout_check): a model that predicts
the data it never saw several times worse than its design fit's scatter and its own uncertainty give is not called
complete, and the families off by default are then offered once (calibration.loop.stages.escalate). Before, the
verdict judged the design fit's residual alone: on the simulated UR5 seat pairs with a hidden shoulder gain it said
"No structured residual remains" at a held-out RMS of 297 um against the truth's 98 um and the stated 100 um
(scripts/robot_hidden_study.py, docs/studies/close-loop.md)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from arm_model import load_description
from arm_model.model import ArmModel
from calibration.candidates import OPT_IN_FAMILIES
from calibration.data import make_data
from calibration.loop import LoopSettings, verdict_text
from calibration.loop.stages import escalate
from calibration.loop.verdict import heldout_check
from conftest import NOMINAL

#: a design fit of the UR5 seat pairs' shape: 312 rows, 54 nuisance unknowns (the seats' centres), redundancy 240:
#: the parameters' share of the leverage (312 - 240 - 54) / 312
DESIGN = dict(n_residuals=312, n_nuisance=54, redundancy=240.0, dof=230)
#: its outer test set: 3 placements, 111 rows, 18 nuisance unknowns solved on them (93 degrees of freedom)
ROWS, NUIS = 111, 18


def _stage(rms_over_u: float, s0: float = 1.0, nuisance: int = NUIS, fit_over_stated: float = 1.0):
    """A stand-in final stage whose held-out rows have the RMS ``rms_over_u`` times their stated uncertainty
    (100 um), the design fit's scatter ``s0`` times its weights, which are ``fit_over_stated`` times the stated
    uncertainties (the noise the loop estimated from the data when they were off); no covariance at hand."""
    held = {"rms_um": 100.0 * rms_over_u, "max_um": 300.0 * rms_over_u, "rows": ROWS, "nuisance": nuisance,
            "chi2": ROWS * (rms_over_u / fit_over_stated) ** 2, "rms_weighted": rms_over_u / fit_over_stated,
            "rms_over_stated": rms_over_u, "chi2_stated": ROWS * rms_over_u ** 2, "rows_stated": ROWS,
            "propagated": None}
    return SimpleNamespace(added=None, heldout=held, result=SimpleNamespace(s0=s0, **DESIGN), cv=[], tie=None)


def test_a_test_set_three_times_its_stated_u_is_not_called_complete():
    """The held-out rows at 3 times their stated u while the design fit sits at it (s0 = 1): hand-derived,
    F = 111 * 9 / (93 (1 + 18/312)) = 10.16 on (93, 240) degrees of freedom, far beyond any level; the verdict
    says so and does not say "No structured residual remains" (which today's code said)."""
    stage = _stage(3.0)
    check = heldout_check(stage, "measurement", 0.01)
    f = ROWS * 9.0 / (93 * (1.0 + 18.0 / 312.0))
    assert check["dof"] == 93 and abs(check["leverage"] - 18.0 / 312.0) < 1e-12
    assert abs(check["ratio"] - np.sqrt(f)) < 1e-12 and abs(check["ratio_stated"] - np.sqrt(f)) < 1e-12
    # an independent bound: 93 F is about chi-square(93) for a large redundancy; its 1e-6 quantile is below 190
    assert 93 * f > 190 and check["p_value"] < 1e-30 and check["p_stated"] < 1e-30 and check["worse_than_stated"]
    v = verdict_text([stage], [], "", LoopSettings(), [], None, (), None, check)
    assert "No structured residual remains" not in v
    assert v == ("no effect added. No regressor family is significant on the design fit's residual (after "
                 "Bonferroni's correction), but: the outer test set is worse than a complete model predicts: its "
                 f"residual (RMS 300 um) is {np.sqrt(f):.3g} times what the design fit's scatter and the model's own "
                 f"uncertainty give for it (F-test p = {check['p_value']:.2g} < 0.01; 3 times the stated "
                 f"uncertainties, chi-square p = {check['p_stated']:.2g}): the model lacks something that shows on "
                 "data it was not fitted to. The model is not complete; no fix is claimed for it.")
    # the same rows against sigmas the user did not state (command-line defaults): the decision is the same, the
    # sentence does not call them stated
    stage.heldout["sigmas_stated"] = False
    check = heldout_check(stage, "measurement", 0.01)
    assert check["worse_than_stated"]
    v = verdict_text([stage], [], "", LoopSettings(), [], None, (), None, check)
    assert "3 times the default (not stated) uncertainties, chi-square p" in v and "the stated" not in v


def test_a_test_set_at_its_expected_scatter_leaves_the_verdict_as_it_was():
    """Held-out rows at what a complete model gives for the design fit's scatter (their mean square (93 / 111)
    (1 + 18/312) of it) while the stated u are 2.5 times too small (the loop estimated the noise; 1.2 times that
    estimate as the design fit's s0): far beyond the stated u, but not beyond the fit's scatter, so not worse
    (the design fit's rule says the stated u are off), and the verdict is word for word the one without the
    judgement. The other way round, the fit's noise estimate low by chance (s0 = 0.6) and the held-out rows at
    their stated u: not worse either."""
    s0, off = 1.2, 2.5
    rms = off * s0 * np.sqrt(93 / ROWS * (1 + 18 / 312))
    stage = _stage(rms, s0, fit_over_stated=off)
    check = heldout_check(stage, "measurement", 0.01)
    assert abs(check["ratio"] - 1.0) < 1e-12 and 0.4 < check["p_value"] < 0.6
    assert check["p_stated"] < 1e-30 and not check["worse_than_stated"]
    low = heldout_check(_stage(np.sqrt(93 / ROWS), 0.6), "measurement", 0.01)
    assert low["p_value"] < 1e-6 and low["p_stated"] > 0.3 and not low["worse_than_stated"]
    clean = verdict_text([stage], [], "", LoopSettings(), [], None)
    assert clean == ("no effect added. No structured residual remains (no regressor family is significant after "
                     "Bonferroni's correction).")
    assert verdict_text([stage], [], "", LoopSettings(), [], None, (), None, check) == clean
    # held-out poses (their features' centres fitted on the design poses): every row a degree of freedom, the
    # design rows' whole leverage (312 - 240) / 312
    pose = heldout_check(_stage(np.sqrt(1 + 72 / 312), nuisance=0), "pose", 0.01)
    assert pose["dof"] == ROWS and abs(pose["leverage"] - 72 / 312) < 1e-12 and abs(pose["ratio"] - 1) < 1e-12
    # the parameters' covariance at hand (a test set of whole measurements): its propagated variance, 0.2 per
    # degree of freedom here, is the leverage
    prop = _stage(1.0)
    prop.heldout["propagated"] = 0.2 * 93
    assert abs(heldout_check(prop, "measurement", 0.01)["leverage"] - 0.2) < 1e-12
    # nothing to judge: no degree of freedom left on the test set
    assert heldout_check(_stage(3.0, nuisance=ROWS), "measurement", 0.01) is None


def test_the_propagated_variance_is_what_the_parameters_move_the_held_out_rows_by(nominal):
    """``propagated`` (calibration.validation.heldout_residuals) is ``tr(P J C J^T P)``: checked against finite
    differences that re-solve the nuisance unknowns (the spheres' and seats' centres) at the parameters moved along
    each column of a Cholesky factor of ``C``, ``sum_k |r(p + L_k) - r(p)|^2`` (the re-solve is the projection)."""
    from arm_model.sim.quick import SynthSpec, make_campaign
    from calibration.data import Weights
    from calibration.validation import heldout_residuals
    model = ArmModel(nominal)
    camp = make_campaign(model, SynthSpec(ballbars=2, ballbar_points=5, seats=1, articulations=6, spheres=1,
                                          sphere_points=8, noise=0.0), seed=0)
    data = make_data(camp.points, camp.artefacts, model)
    w = Weights(probe=2e-6)
    names = ["j2.theta_offset", "j3.d", "j4.a", "probe.x"]
    rng = np.random.default_rng(1)
    a = rng.normal(0.0, 1.0, (4, 4)) * 1e-6
    c = a @ a.T + np.diag([1e-10, 1e-10, 1e-10, 1e-10])
    p0 = np.zeros(model.spec.size)
    h = heldout_residuals(model, p0, data, w, cov=(names, c))
    low = np.linalg.cholesky(c)
    fd = 0.0
    for k in range(4):
        p = p0.copy()
        for i, n in enumerate(names):
            p[model.spec.index(n)] += 1e-3 * low[i, k]
        fd += float(np.sum((heldout_residuals(model, p, data, w)["r"] - h["r"]) ** 2)) / 1e-6
    assert h["nuisance"] > 0 and h["propagated"] > 1.0
    assert abs(h["propagated"] - fd) < 1e-3 * fd


def _state(worse: bool, families=None):
    desc = load_description(NOMINAL)
    rng = np.random.default_rng(0)
    from arm_model.io import PointSet
    n = 24
    pts = PointSet("mem.csv", np.array([f"m{i % 3}" for i in range(n)]), np.array([""] * n),
                   rng.uniform(-2.0, 2.0, (n, desc.n_joints)), ref=rng.normal(0.0, 1.0, (n, 1, 3)),
                   lines=np.arange(2, n + 2))
    model = ArmModel(desc, ())
    said = []
    return SimpleNamespace(settings=LoopSettings(), stages=[_stage(3.0 if worse else 1.0)], test_by="measurement",
                           families=families, candidates=[], synthesised=[], remaining=[], model=model, desc=desc,
                           data=make_data(pts, None, model), escalated=None, say=said.append, said=said)


def test_the_opt_in_families_are_offered_once_when_the_test_set_is_worse():
    """Escalation: a test set worse than stated offers every family off by default that was not offered (on a
    measuring arm whose description gives masses: a gain per joint, the mount's tilt and a reading coupling per pair
    of joints), once;
    a test set at its scatter offers nothing, and a family already offered is not offered again."""
    state = _state(True)
    assert escalate(state)
    names = [c.name for c in state.remaining]
    jn = state.desc.joint_names
    assert names == ([f"gain {j}" for j in jn] + [f"coupling {j} by q{k + 1}" for j in jn for k in range(len(jn))
                                                   if jn[k] != j] + ["lateral compliance j1"])
    assert state.escalated["families"] == list(OPT_IN_FAMILIES) and state.escalated["candidates"] == names
    assert state.candidates == state.remaining
    assert "offering the opt-in families joint_gain, base_tilt, joint_coupling" in state.said[0]
    assert not escalate(state) and len(state.remaining) == len(names)          # once
    assert not escalate(_state(False)) and _state(False).escalated is None
    asked = _state(True, families=("eccentricity", "joint_gain"))
    assert escalate(asked) and asked.escalated["families"] == ["base_tilt", "joint_coupling"]
    assert [c.name for c in asked.remaining][-1] == "lateral compliance j1"
    stopped = _state(True)
    stopped.settings = LoopSettings(escalate=False)
    assert not escalate(stopped) and stopped.escalated is None


@pytest.mark.parametrize("added", [True, False])
def test_the_verdict_says_what_the_escalation_offered_and_added(added):
    from arm_model.effects import JointGain
    from calibration.candidates import Candidate
    gain = Candidate("gain j2", JointGain(joints=(1,)), "joint_gain", "j2")
    stages = [_stage(3.0)] + ([SimpleNamespace(added=gain, heldout={"rms_um": 100.0, "max_um": 290.0},
                                               result=SimpleNamespace(s0=1.0, **DESIGN), cv=[], tie=None)]
                              if added else [])
    esc = {"families": ["joint_gain", "base_tilt"], "candidates": ["gain j1", "gain j2"]}
    v = verdict_text(stages, [], "", LoopSettings(), [], None, (), None, None, esc)
    assert ("The outer test set was worse than stated after the default families, so the opt-in families "
            "joint_gain, base_tilt (2 candidates) were offered, kept by the same held-out rules: "
            + ("added gain j2" if added else "none was added")) in v


@pytest.mark.slow
def test_the_ur5_s_hidden_shoulder_gain_is_found_once_the_test_set_says_the_model_is_incomplete(tmp_path):
    """(slow: about 40 s on a loaded machine) scripts/robot_hidden_study.py's UR5 seat pairs with the shoulder's
    encoder gain 1e-3:
    the default families end at the shoulder's eccentricity, 297 um held out against the truth's 98 um, and the
    verdict said "No structured residual remains". Now the outer test set is found worse than stated, the opt-in
    families are offered, the gain passes the same held-out rules and the loop's model ends within 10 % of the
    truth on the held-out placements; with the families named (no escalation), the verdict says the model is not
    complete. The same judgement at loop seeds 0 and 1 (it draws nothing)."""
    import sys

    from conftest import ROOT
    sys.path.insert(0, str(ROOT / "scripts"))
    import robot_hidden_study as rhs
    from hidden_effects_study import cli_defaults

    from calibration.loop import close_loop

    path = rhs.Path(rhs.os.environ.get("XDG_CACHE_HOME", rhs.Path.home() / ".cache")) / "aacmm-toolkit" / \
        "example-robot-data-4.1.0" / "robots" / rhs.ROBOTS["ur5"][0]
    if not path.is_file():
        pytest.skip(f"{path} not cached: `pytest -m slow tests/test_robot_set.py -k quick` fetches it")
    row = rhs.run_one("ur5", "seats", "gain", 1, tmp_path)
    # the elbow's eccentricity passes its folds' test at p 0.0047 against 0.005 (0.0051 before keep_choice) with its
    # fourth fold 1.4 % worse: not added since every fold must be better (calibration.loop.settings.STABILITY_RULE)
    assert row["added"] == ["eccentricity shoulder_lift_joint", "gain shoulder_lift_joint"]
    assert row["escalated"] == list(OPT_IN_FAMILIES) and not row["heldout_check"]["worse_than_stated"]
    assert row["loop"] < 1.1 * row["floor"] and "No structured residual remains" in row["verdict"]
    case = rhs.make_case("ur5", "seats", "gain", 1)
    verdicts = []
    for seed in (0, 1):
        loop = close_loop(case.points, case.artefacts, case.desc, weights=case.weights, progress=lambda s: None,
                          seed=seed, escalate=False, **cli_defaults(case.desc))
        assert loop.heldout_check["worse_than_stated"] and loop.escalated is None
        assert "No structured residual remains" not in loop.verdict
        verdicts.append(loop.verdict)
    assert verdicts[0] == verdicts[1]
