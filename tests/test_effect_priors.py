"""The effects' physical priors (calibration/prior.py, docs/calibration.md "Priors of the effects"): a joint's play
is sized by physics and its group's scale is not the evidence's; a backlash is non-negative; a play whose points lie
nearly all on one side is the joint's offset in the data and stays at its prior (prior-dominated), the offset taking
the error; a play the data see on both sides is still recovered."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from arm_model.effects import EFFECTS, PLAY, JointBacklash, JointHysteresis
from arm_model.model import ArmModel
from calibration import prior
from calibration.calibrate import FitOptions, calibrate
from calibration.data import Weights, make_data

#: the joint whose offset and play the tests look at (j4 of the nominal arm: its gravity torque takes either sign)
JOINT = 3
OFFSET = 3e-3          # [rad] the true offset error of that joint


@functools.cache
def _tracker_data(nominal, backlash: float):
    """Tracker points (the ball seen directly, 160 random poses, 5 um noise) of the nominal arm with joint 4's offset
    off by :data:`OFFSET` and a backlash ``backlash`` [rad] on it, and the gravity torque of each pose."""
    from arm_model import PinocchioArm
    from arm_model.io import PointSet
    from arm_model.model import AuxData
    from arm_model.sim.ik import random_q
    from calibration.candidates import needs_model

    truth = ArmModel(nominal, (JointBacklash(joints=(JOINT,)),))
    p = np.zeros(truth.spec.size)
    p[truth.spec.index(f"{nominal.joint_names[JOINT]}.theta_offset")] = OFFSET
    p[truth.spec.index(f"{nominal.joint_names[JOINT]}.backlash")] = backlash
    rng = np.random.default_rng(3)
    q = random_q(nominal, 160, rng)
    x = truth.ball_centres(q, None, p, AuxData(tau_gravity=PinocchioArm(nominal).torques(q)[0]))
    pts = PointSet(path="<tracker>", measurement=np.array(["tracker"] * len(q), dtype=object),
                   feature=np.array([""] * len(q), dtype=object), q=q,
                   ref=(x + rng.normal(0, 5e-6, x.shape))[:, None, :], lines=np.arange(2, len(q) + 2))
    data = make_data(pts, None, needs_model(nominal, [JointBacklash()]))
    return data, data.aux.tau_gravity[:, JOINT]


def _fit(nominal, data, prior_scale="evidence"):
    name = nominal.joint_names[JOINT]
    model = ArmModel(nominal, (JointBacklash(joints=(JOINT,)),))
    free = [f"{n}.theta_offset" for n in nominal.joint_names[1:]] + [f"{name}.backlash"]
    return calibrate(model, data, FitOptions(free=free, weights=Weights(reference=5e-6, probe=5e-6),
                                             prior_scale=prior_scale)), name


@pytest.mark.parametrize("minority", [0, 3])
def test_a_play_with_one_side_nearly_empty_stays_at_its_prior(nominal, minority):
    """Training poses whose joint-4 gravity torque keeps one sign (but for ``minority`` of 80): the play's sign is
    a constant there, the joint's offset. Before, the rank test held the offset and the play took the 3 mrad offset
    error as a well-determined "play" (the real Panda's elbow: 17 mrad at u 1 mrad); now the play is prior-only:
    prior-dominated at 0 with its prior's 1 mrad, and the offset takes the error."""
    data, tau = _tracker_data(nominal, 0.0)
    pos, neg = np.flatnonzero(tau > 0), np.flatnonzero(tau < 0)
    assert len(pos) >= 80 and len(neg) >= minority
    res, name = _fit(nominal, data.select(np.r_[pos[:80 - minority], neg[:minority]]))
    assert res.state(f"{name}.backlash") == "prior-dominated", res.parameter_rows()
    assert res.value(f"{name}.backlash") == pytest.approx(0.0, abs=1e-9)
    assert res.uncertainty(f"{name}.backlash") == pytest.approx(PLAY, rel=1e-6)
    assert "one side of its play" in res.prior_only[f"{name}.backlash"]
    from calibration.report import prior_html
    page = "".join(prior_html(res))
    assert "Left to the prior" in page and f"{name}.backlash" in page and "(at most 1)" in page
    assert res.to_dict()["prior"]["prior_only"] == res.prior_only
    assert res.value(f"{name}.theta_offset") == pytest.approx(OFFSET, abs=5e-5)
    # without a prior: held at its given value, with the reason
    res0, _ = _fit(nominal, data.select(np.r_[pos[:80 - minority], neg[:minority]]), prior_scale=None)
    held = {f.name: f.reason for f in res0.fixed}
    assert "one side of its play" in held[f"{name}.backlash"] and res0.value(f"{name}.backlash") == 0.0


def test_a_play_seen_on_both_sides_is_recovered_within_its_uncertainty(nominal):
    """The same arm with a real 0.2 mrad backlash and poses on both sides: the physical prior (1 mrad) does not bias
    it: free, within 3 u of the truth."""
    data, tau = _tracker_data(nominal, 2e-4)
    assert prior.both_sides(tau)
    res, name = _fit(nominal, data)
    assert res.state(f"{name}.backlash") == "free"
    assert abs(res.value(f"{name}.backlash") - 2e-4) <= 3 * res.uncertainty(f"{name}.backlash")
    assert res.uncertainty(f"{name}.backlash") < 0.1 * PLAY
    assert abs(res.value(f"{name}.theta_offset") - OFFSET) <= 3 * res.uncertainty(f"{name}.theta_offset")


def test_the_plays_priors(nominal):
    """Each play's prior: physical size :data:`PLAY`, a maximum (its group's scale at most 1), a backlash >= 0, a
    hysteresis signed (which side lags is the encoder's side); a joint whose gravity torque is nil (j1, a vertical
    axis: rounding-level torques, :data:`calibration.prior.NIL_LOAD`) has no side: prior-only."""
    from calibration.candidates import needs_model

    data, _ = _tracker_data(nominal, 0.0)
    tau = data.aux.tau_gravity
    assert np.max(np.abs(tau[:, 0])) < 1e-9 * np.max(np.abs(tau)) and np.sum(tau[:, 0] > 0) > 10
    data = make_data(data.points, None, needs_model(nominal, [JointBacklash(), JointHysteresis()]))
    model = ArmModel(nominal, (JointBacklash(joints=(0, 1, JOINT)), JointHysteresis(joints=(2,))))
    spec = prior.prior_spec(model, data)
    names = model.spec.names
    for k in range(model.base_size, model.spec.size):
        assert spec.size[k] == PLAY and spec.group[k] in spec.capped and spec.group[k] not in spec.physical, names[k]
    lower = dict(zip(names, spec.lower, strict=True))
    assert lower["j2.backlash"] == lower["j4.backlash"] == 0.0 and lower["j3.hysteresis"] == -np.inf
    only = prior.prior_only(model, data)
    assert list(only) == [names.index("j1.backlash")], only
    assert "nil on all 160 points" in only[names.index("j1.backlash")]
    assert {EFFECTS[k].physical_size for k in EFFECTS} == {True, False}


def test_side_visits_by_hand():
    """Runs of each side in the capture order of each measurement (time order where every point has a time); a 0
    neither breaks nor starts a run."""
    side = np.array([1, 1, 0, 1, -1, -1, 1, -1, 1, 1])
    assert prior.side_visits(side) == (3, 2)
    meas = np.array(["a"] * 5 + ["b"] * 5, dtype=object)
    assert prior.side_visits(side, meas) == (3, 3)             # a: +, -; b: -, +, -, +
    assert prior.side_visits(np.r_[1, -1, 1, -1], np.array(["a", "a", "b", "b"], dtype=object)) == (2, 2)
    time = np.array([0.0, 2.0, 1.0, 3.0])                         # in time order: 1, 1, -1, -1
    assert prior.side_visits(np.r_[1, -1, 1, -1], None, time) == (1, 1)
    assert prior.side_visits(np.r_[1, -1, 1, -1], None, np.r_[0.0, np.nan, 1, 2]) == (2, 2)   # a time missing: rows


def test_a_drifts_prior_is_a_strain_over_the_datas_time_span(nominal):
    """A drift of the links in time: its prior's size is :data:`arm_model.effects.DRIFT_STRAIN` over the data's
    largest time from the reference (to the drift's power), not a size by unit (1 /s, a link doubling each second)."""
    from arm_model.effects import DRIFT_STRAIN, ThermalDrift
    from arm_model.io import PointSet
    from arm_model.model import AuxData
    from calibration.data import CalibrationData

    q = np.zeros((3, nominal.n_joints))
    pts = PointSet(path="<p>", measurement=np.array(["m"] * 3, dtype=object), feature=np.array([""] * 3, dtype=object),
                   q=q, time=np.array([100.0, 700.0, 2500.0]))
    data = CalibrationData(points=pts, artefacts=None, aux=AuxData(time=pts.time))
    model = ArmModel(nominal, (ThermalDrift(reference_time_s=1000.0), ThermalDrift(power=2, reference_time_s=1000.0)))
    spec = prior.prior_spec(model, data)
    assert spec.size[-2] == pytest.approx(DRIFT_STRAIN / 1500.0) and spec.size[-1] == pytest.approx(
        DRIFT_STRAIN / 1500.0 ** 2)
    assert "over the data's 1500 s" in spec.source[-1]


def test_a_capped_group_shrinks_with_the_evidence_but_never_grows_past_its_physical_size():
    """MacKay's fixed point on a capped group (a play's: its size a physical maximum) and an ordinary one, each of
    two fully determined parameters (rho = 0): at 3 sizes from the centre the ordinary scale goes to 3 (hand-derived:
    sqrt((9 + 9) / 2)), the capped one stops at 1; at 0.3 sizes both go to 0.3."""
    from calibration.prior import PriorSpec, update_scales

    spec = PriorSpec(("lengths", "lengths", "effect b", "effect b"), np.array([1e-3, 1e-3, PLAY, PLAY]),
                     np.array([-np.inf, -np.inf, 0.0, 0.0]), ("a",) * 4, capped=frozenset({"effect b"}))
    for z, want in ((3.0, 1.0), (0.3, 0.3)):
        delta = z * np.array([1e-3, -1e-3, PLAY, PLAY])
        new, _ = update_scales({"lengths": 1.0, "effect b": 1.0}, spec, [0, 1, 2, 3], delta, np.zeros(4))
        assert new["lengths"] == pytest.approx(z, rel=1e-12) and new["effect b"] == pytest.approx(want, rel=1e-12)
