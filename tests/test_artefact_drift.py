"""The artefact's drift along each measurement's capture (:class:`arm_model.effects.ArtefactDrift`,
:func:`arm_model.model.capture_columns`, docs/calibration.md "Priors of the effects"): the evaluators agree and the
ball moves by the drift's translation (by hand); the capture's time base; a simulated seat campaign whose plate creeps
gives the creep back within its u, one that does not gives it near nil under its prior; a model file never holds it."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import PinocchioArm
from arm_model.effects import DRIFT_STRAIN, EFFECTS, ArtefactDrift, JointCompliance
from arm_model.model import ArmModel, AuxData, capture_columns, capture_position
from conftest import assert_close, assert_evaluators_agree


def test_the_evaluators_agree_and_the_ball_moves_by_the_drift(nominal):
    model = ArmModel(nominal, (JointCompliance(), ArtefactDrift(measurements=("a", "b"))))
    assert EFFECTS["artefact_drift"] is ArtefactDrift
    assert model.spec.names[-6:] == ("a.drift_x", "a.drift_y", "a.drift_z", "b.drift_x", "b.drift_y", "b.drift_z")
    rng = np.random.default_rng(3)
    n = 9
    q = rng.uniform(-2.5, 2.5, (n, nominal.n_joints))
    w = np.zeros((n, 6))
    w[:, :3] = rng.normal(0, 2, (n, 3))
    meas = np.array(["a"] * 5 + ["b"] * 4, dtype=object)
    tg, tc = PinocchioArm(nominal).torques(q, w)
    aux = AuxData(None, tg, tc, capture=capture_columns(model.capture_measurements, meas))
    p = np.zeros(model.spec.size)
    p[model.base_size:model.base_size + nominal.n_joints] = 2e-6          # compliances
    drift = np.array([3e-4, -1e-4, 2e-4, -5e-4, 0.0, 1e-4])
    p[-6:] = drift
    assert_evaluators_agree(model, q, w, p, aux)
    # by hand: each point is the arm without the drift, moved by minus its measurement's displacement times its
    # place in the capture (-1/2 ... +1/2 by the rows' order); without a force (the probe's bending hinge sees the
    # ball's shift: 8e-12 m under these forces)
    still = p.copy()
    still[-6:] = 0.0
    place = np.r_[np.linspace(-0.5, 0.5, 5), np.linspace(-0.5, 0.5, 4)]
    shift = -np.where((meas == "a")[:, None], drift[:3], drift[3:]) * place[:, None]
    assert_close(model.ball_centres(q, None, p, aux), model.ball_centres(q, None, still, aux) + shift, atol=1e-12)


def test_the_capture_place_is_the_time_where_given_else_the_rows_order():
    meas = np.array(["x", "y", "x", "x", "y", "z"], dtype=object)
    assert_close(capture_position(meas), [-0.5, -0.5, 0.0, 0.5, 0.5, 0.0], atol=0)
    t = np.array([10.0, 0.0, 30.0, 14.0, 5.0, 7.0])      # x by its stamps, y by its own; z one point
    assert_close(capture_position(meas, t), [-0.5, -0.5, 0.5, -0.3, 0.5, 0.0], atol=1e-15)
    t[0] = np.nan                                         # a measurement missing a stamp: its rows' order
    assert_close(capture_position(meas, t)[[0, 2, 3]], [-0.5, 0.0, 0.5], atol=0)
    cols = capture_columns(("y", "x"), meas)
    assert cols.shape == (6, 2) and cols[1, 0] == -0.5 and cols[1, 1] == 0.0 and cols[3, 1] == 0.5
    with pytest.raises(ValueError, match="distinct"):
        ArtefactDrift(measurements=("a", "a"))
    with pytest.raises(ValueError, match="no joints"):
        ArtefactDrift(joints=(1,), measurements=("a",))


def _campaign(drift_mm_per_h, seed=5):
    """Two seats 30 articulations each, in random order, on the shipped 7-joint arm (probing scatter 20 um), the plate
    creeping at ``drift_mm_per_h``: (calibration data, model with the drift, its displacement over the measurement)."""
    from arm_model.sim import campaign_from_dict, simulate
    from calibration.data import make_data
    tasks = [{"kind": "seat", "id": f"s{k}", "articulations": 30, "position_mm": pos, "axis": [0, 0, 1],
              "stylus_cone_deg": 40.0} for k, pos in enumerate(([600.0, 150.0, 50.0], [600.0, -150.0, 50.0]))]
    sim = simulate(campaign_from_dict({
        "seed": seed, "sensor": "none", "signals": {"enabled": False}, "task": tasks,
        "truth": {"length_error_um": 0.0, "angle_error_deg": 0.0, "probe_error_um": 0.0,
                  "probe_compliance": {"bending_um_per_N": 0.0, "axial_um_per_N": 0.0}},
        "noise": {"probing_repeatability_um": 20.0},
        "operator": {"force_mean_N": 0.3, "max_force_N": 1.0, "point_period_s": 1.2, "measurement_gap_s": 1.2},
        "environment": {"artefact_drift_mm_per_h": list(drift_mm_per_h)}}), progress=lambda s: None)
    pts = sim.points
    pts = pts.select(np.arange(len(pts)))
    pts.measurement[:] = "plate"                    # one measurement: the plate, both seats in turn
    t = sim.points.time
    shown = np.asarray(drift_mm_per_h) * 1e-3 / 3600 * (t.max() - t.min())
    model = ArmModel(sim.campaign.arm, (ArtefactDrift(measurements=("plate",)),))
    return make_data(pts, sim.artefacts, model), model, shown


@pytest.mark.parametrize("drift", [(30.0, -20.0, 10.0), (0.0, 0.0, 0.0)])
def test_a_creeping_plate_is_given_back_within_its_u_and_a_still_one_near_nil(drift):
    """The plate creeps by (0.61, -0.40, 0.20) mm over the 73 s of its capture (the time stamps its time base), or not
    at all; the fit frees the tip offset and the drift under the evidence's prior: the drift within 3 u of the truth
    (596 +- 18 um along x), and nil drift within 3 u of 0 (the evidence's scale 0.10)."""
    from calibration import FitOptions, calibrate
    data, model, truth = _campaign(drift)
    res = calibrate(model, data, FitOptions(free=("probe.*", "plate.drift_*"), discrepancy=False,
                                            gross_threshold=None))
    names = ("plate.drift_x", "plate.drift_y", "plate.drift_z")
    got = np.array([res.value(n) for n in names])
    u = np.array([res.uncertainty(n) for n in names])
    assert np.all(np.abs(got - truth) <= 3 * u), (got, truth, u)
    if any(drift):
        assert np.all(u < 0.05e-3) and abs(got[0]) > 10 * u[0], (got, u)        # resolved: 20 um scatter, 60 points
    else:
        assert np.all(np.abs(got) < 0.05e-3), got
    size = DRIFT_STRAIN * model.desc.chain_length
    assert 0.5e-4 < size < 1e-3                       # a strain of 1e-4 over a metre-long arm


def test_the_model_written_holds_no_drift_and_says_it():
    """What a model file holds (:func:`calibration.model_output.without_session_effects`) has no drift; its comment
    (:func:`~calibration.model_output.drift_text`) gives the measurement's."""
    from calibration import FitOptions, calibrate
    from calibration.model_output import drift_text, session_drift, without_session_effects
    data, model, _ = _campaign((30.0, 0.0, 0.0), seed=6)
    res = calibrate(model, data, FitOptions(free=("probe.*", "plate.drift_*"), discrepancy=False,
                                            gross_threshold=None))
    kept = without_session_effects(res)
    assert not any(isinstance(e, ArtefactDrift) for e in kept.model.effects)
    assert not any(n.startswith("plate.") for n in kept.model.spec.names + kept.free)
    text = drift_text(session_drift(res))
    assert "artefact_drift(1 measurement)" in text and "plate.drift_x = " in text and "no drift" in text
