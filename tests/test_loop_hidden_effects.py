"""What the red-team study of hidden effects (scripts/hidden_effects_study.py, docs/studies/close-loop.md "Hidden
effects nobody told the loop of") found and fixed, each checked on its own:

* a joint's angle error linear in another joint's reading (a differential wrist's coupling ratio) is an effect
  (``JointGain(source=K)``) that the loop builds from the ``qK harmonics on jN`` family;
* the structure tests hold a joint's fourth harmonic (the effects built from the residual went to 4 already,
  the tests stopped at 3, so a hidden fourth harmonic was never seen);
* a fold's fit of a larger model that stops above the nested model's cost is restarted from the nested
  solution, and the folds start from the design set's solution.

The verdict judged against the stated uncertainties: tests/test_loop_verdict.py."""
from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from arm_model import load_description
from arm_model.effects import JointGain, JointHarmonics
from arm_model.model import ArmModel
from arm_model.model_file import format_model, parse_model
from arm_model.sim.quick import SynthSpec, make_campaign, random_truth
from calibration import FitOptions, calibrate
from calibration.data import Weights, make_data
from calibration.diagnostics import remaining_structure, residual_space
from calibration.loop.crossval import _not_worse_than_nested, warm_start
from conftest import NOMINAL, assert_close

ROOT = Path(__file__).resolve().parents[1]


def test_a_joint_gain_of_another_joints_reading_is_a_linear_coupling():
    """``JointGain(joints=(5,), source=4)``: the ball where the plain model puts it with j6's reading moved by
    g q5 (an independent evaluation: the nominal model at edited readings); its parameter is named after both
    joints, and the model file writes and reads it back (the option ``source`` included)."""
    desc = load_description(NOMINAL)
    eff = JointGain(joints=(5,), source=4)
    assert eff.param_defs(desc) == [("j6.gain_by_j5", "1")]
    assert JointGain(joints=(5,)).param_defs(desc) == [("j6.gain", "1")]
    model, plain = ArmModel(desc, (eff,)), ArmModel(desc)
    q = np.random.default_rng(0).uniform(-3, 3, (20, 7))
    w = np.zeros((20, 6))
    p = np.zeros(model.spec.size)
    p[model.spec.index("j6.gain_by_j5")] = 3e-4
    edited = q.copy()
    edited[:, 5] += 3e-4 * q[:, 4]
    assert_close(model.ball_centres(q, w, p), plain.ball_centres(edited, w, np.zeros(plain.spec.size)), atol=1e-12)
    text = format_model(desc, (eff,), {"j6.gain_by_j5": 3e-4})
    arm = parse_model(text)
    assert arm.effects == (eff,)
    assert_close(arm.model.ball_centres(q, w, arm.p), model.ball_centres(q, w, p), atol=1e-12)
    with pytest.raises(TypeError, match="source"):
        JointGain(joints=(5,), source=-1)


def test_the_structure_tests_see_a_fourth_harmonic():
    """A fourth harmonic of j1's encoder (0.004 deg) hidden in a small campaign: after the base calibration the
    forward selection keeps ``q1 harmonics`` and names cos/sin(4 q1) as its best regressor (with harmonics 1-3
    only, nothing is kept: the eccentricity's harmonics absorb a part and the rest looked like noise)."""
    nominal = load_description(NOMINAL)
    truth = ArmModel(nominal, (JointHarmonics(joints=(0,), harmonics=(4,)),))
    p = random_truth(truth, np.random.default_rng(2), length=30e-6, angle=5e-5, probe=30e-6)
    p[truth.base_size:] = np.radians(0.004) * np.array([np.sin(0.3), np.cos(0.3)])
    camp = make_campaign(truth, SynthSpec(ballbars=8, ballbar_points=4, seats=3, articulations=8, spheres=3,
                                          sphere_points=8, noise=2e-6), seed=2, p_true=p)
    base = ArmModel(nominal)
    res = calibrate(base, make_data(camp.points, camp.artefacts, base),
                    FitOptions(weights=Weights(probe=2e-6), prior_scale=None, discrepancy=False))
    kept = remaining_structure(residual_space(res), None, 0.01)
    assert kept and kept[0][0].name == "q1 harmonics", [f.name for f, _ in kept]
    assert kept[0][1].best == "cos/sin(4 q1)"


def _fit_result(cost, free=("a",), p=(1.0,)):
    return SimpleNamespace(cost=cost, free=free, p=np.array(p), model=SimpleNamespace(spec=SimpleNamespace(
        names=("a",))))


def test_a_fold_fit_above_its_nested_models_cost_starts_again_from_the_nested_solution():
    """A larger model's optimum cannot cost more than the nested model's on the same data: a fit that stops above
    it is redone from the nested solution (its free parameters by name), and the lower of the two kept; a fit at
    or below it is kept as it is, without a second fit."""
    calls = []

    def fit(model, data, discrepancy=False, start=None):
        calls.append(start)
        return _fit_result(5.0)

    nested = _fit_result(10.0, p=(0.25,))
    kept = _fit_result(9.0)
    assert _not_worse_than_nested(kept, nested, None, None, fit) is kept and calls == []
    assert _not_worse_than_nested(kept, None, None, None, fit) is kept and calls == []
    stuck = _fit_result(600.0)
    assert _not_worse_than_nested(stuck, nested, None, None, fit).cost == 5.0
    assert calls == [{"a": 0.25}] == [warm_start(nested)]

    def worse(model, data, discrepancy=False, start=None):
        return _fit_result(700.0)
    assert _not_worse_than_nested(stuck, nested, None, None, worse) is stuck


@pytest.mark.slow
@pytest.mark.parametrize("case, added", [("coupling", ["coupling j6 by q5"]),
                                         ("harmonic4", ["eccentricity j1", "harmonics j1 (h 3,4)"])])
def test_the_default_loop_finds_the_hidden_coupling_and_fourth_harmonic(case, added):
    """The study's two cases the loop missed before its fixes (docs/studies/close-loop.md: held-out RMS 25.99 and
    10.45 um, the truth 1.65 and 1.41 um): the default loop now adds the effect from the residual, leaves no
    structure, and its held-out RMS is within 1.3 times the truth's (about 40 s of CPU for both)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    import hidden_effects_study as study
    c = study.CASES[case]()
    from calibration.loop import close_loop
    loop = close_loop(c.points, c.artefacts, c.desc, weights=c.weights, progress=lambda s: None)
    fig = study.figures(c, loop)
    assert [a.name for a in loop.added] == added, loop.verdict
    assert not loop.remaining and "No structured residual remains" in loop.verdict
    assert fig["loop"] <= 1.3 * fig["floor"], fig
