"""Each effect changes the simulated data the way its physics says, and noise has the requested size."""
from __future__ import annotations

import math

import numpy as np
import pytest

from arm_model import PinocchioArm, ball_centres
from arm_model.model import ArmModel, AuxData
from arm_model.sim import campaign_from_dict, simulate
from conftest import assert_close

TASKS = [{"kind": "seat", "articulations": 40, "stylus_cone_deg": 70.0},
         {"kind": "sphere", "points": 20, "centre_mm": [450.0, -300.0, 150.0]}]


def run(truth=None, seed=11, sensor="xyz", noise=None, tasks=TASKS, environment=None, **extra):
    data = {"seed": seed, "sensor": sensor, "truth": truth or {}, "noise": noise or {},
            "signals": {"enabled": False}, "operator": {"point_period_s": 0.5}, "task": tasks}
    if environment:
        data["environment"] = environment
    data.update(extra)
    return simulate(campaign_from_dict(data))


def _true_minus_read(result):
    return result.true_q - result.points.q


def test_eccentricity_is_periodic_in_its_joint_with_the_right_amplitude():
    a1, p1, a2, p2 = math.radians(0.004), math.radians(35.0), math.radians(0.001), math.radians(-50.0)
    r = run({"eccentricity": [{"joint": "j4", "amplitude_deg": 0.004, "phase_deg": 35.0,
                               "amplitude2_deg": 0.001, "phase2_deg": -50.0}]})
    d = _true_minus_read(r)
    assert np.all(np.abs(np.delete(d, 3, axis=1)) < 1e-13), "only j4 is affected"
    q = r.points.q[:, 3]
    # fit a1 sin(q + p1) + a2 sin(2q + p2) by linear least squares on (sin, cos) of q and 2q
    A = np.column_stack([np.sin(q), np.cos(q), np.sin(2 * q), np.cos(2 * q)])
    c, *_ = np.linalg.lstsq(A, d[:, 3], rcond=None)
    assert math.hypot(c[0], c[1]) == pytest.approx(a1, rel=1e-9)
    assert math.atan2(c[1], c[0]) == pytest.approx(p1, abs=1e-8)
    assert math.hypot(c[2], c[3]) == pytest.approx(a2, rel=1e-8)
    assert math.atan2(c[3], c[2]) == pytest.approx(p2, abs=1e-7)
    assert np.abs(A @ c - d[:, 3]).max() < 1e-13        # nothing else: a pure periodic reading error
    # periodic: readings a whole turn apart would carry the same error
    assert_close(a1 * np.sin(q + 2 * np.pi + p1) + a2 * np.sin(2 * (q + 2 * np.pi) + p2), d[:, 3], atol=1e-13)


def test_joint_compliance_follows_the_gravity_torque():
    k = 3.0e4   # N m / rad
    r = run({"joint_compliance": {"joints": ["j2"], "stiffness_Nm_per_rad": k, "contact": False}})
    d = _true_minus_read(r)
    arm = PinocchioArm(r.truth["description"])
    tau_g = np.array([arm.gravity_torques(q)[1] for q in r.true_q])
    assert np.std(tau_g) > 0.5, "the articulations load the shoulder differently"
    assert_close(d[:, 1], -tau_g / k, atol=1e-13)     # the joint sags by tau / k, against gravity
    assert np.all(np.abs(np.delete(d, 1, axis=1)) < 1e-13)


def test_joint_compliance_contact_part_is_j_transpose_w():
    k = 1.0e4
    r = run({"joint_compliance": {"joints": ["j6"], "stiffness_Nm_per_rad": k, "gravity": False}})
    arm = PinocchioArm(r.truth["description"])
    tau_c = np.array([arm.contact_torques(q, w)[5] for q, w in zip(r.true_q, r.true_wrench, strict=True)])
    assert np.abs(tau_c).max() > 0.05
    assert_close(_true_minus_read(r)[:, 5], tau_c / k, atol=1e-13)


def test_thermal_growth_scales_the_link_lengths_with_temperature():
    alpha = 1.2e-5
    env = {"temperature_C": 26.0, "drift_C_per_h": 40.0}
    r = run({"thermal": {"alpha_per_K": alpha}}, environment=env)
    temps = r.points.temperature
    assert temps.max() - temps.min() > 0.5, "the drift spreads the temperatures"
    base = r.truth["description"]
    # links scaled by hand: d and a grow by (1 + alpha (T - 20)); the readings are the true angles
    for q, w, t, c in zip(r.points.q, r.true_wrench, temps, r.true_centres, strict=True):
        table = base.row_table().copy()
        table[:, 1:3] *= 1 + alpha * (t - 20.0)
        assert_close(ball_centres(base.with_row_table(table), q[None], w[None, :3])[0], c, atol=1e-11)
    # and the growth is what the data carry: without it the centres move by about alpha dT L
    shift = np.linalg.norm(ball_centres(base, r.points.q, r.true_wrench[:, :3]) - r.true_centres, axis=1)
    lever = np.linalg.norm(r.true_centres - np.array([0, 0, 0.2]), axis=1) + 0.2
    assert np.all(shift < alpha * (temps - 20) * lever * 1.5)
    assert np.all(shift > alpha * (temps - 20) * 0.1)


def test_probe_compliance_of_the_truth_is_the_true_one():
    cx, cy, cz = 0.02e-3, 0.011e-3, 0.0003e-3
    r = run({"probe_compliance": {"bending_x_mm_per_N": cx * 1e3, "bending_y_mm_per_N": cy * 1e3,
                                  "axial_mm_per_N": cz * 1e3}})
    base = r.truth["description"]
    rigid = ball_centres(base, r.true_q)
    R = r.truth["truth"].rotation(r.true_q, np.full(len(r.true_q), 20.0))   # R_base_probe
    defl_probe = np.einsum("nji,nj->ni", R, r.true_centres - rigid)
    f = r.true_wrench[:, :3]
    # small-force statics: the ball moves by diag(c) F in the probe frame (to second order)
    assert_close(defl_probe, f * np.array([cx, cy, cz]), atol=2e-8)
    assert np.abs(defl_probe[:, :2]).max() > 1e-5


def test_force_sensor_gain_offset_and_cross_talk_scale_the_force_columns():
    plain = run()
    g, o = np.array([0.05, -0.04, 0.02]), np.array([0.03, 0.0, -0.02])
    k = [[0.0, 0.02, 0.0], [0.0, 0.0, 0.0], [0.01, 0.0, 0.0]]
    err = run({"force_sensor": {"gain": g.tolist(), "offset_N": o.tolist(), "cross_talk": k}})
    # the sensor does not change the physics: same articulations, same true forces
    assert_close(err.true_q, plain.true_q, atol=0)
    f = plain.true_wrench[:, :3]
    expected = f * (1 + g) + o + f @ np.array(k).T
    assert_close(err.points.force, expected, atol=6e-7)        # the file's 1e-6 N resolution
    assert_close(plain.points.force, f, atol=6e-7)


def test_two_channel_sensor_writes_bend_and_axial():
    r = run(sensor="two-channel")
    assert r.points.force_kind == "two-channel"
    assert_close(r.points.force[:, 0], r.true_wrench[:, 0], atol=6e-7)
    assert_close(r.points.force[:, 2], r.true_wrench[:, 2], atol=6e-7)
    assert np.all(r.points.force[:, 1] == 0)


def test_noise_has_the_requested_standard_deviations():
    sig = {"probing_repeatability_um": 4.0, "force_noise_N": 0.02, "temperature_noise_C": 0.05,
           "encoder_resolution_deg": 0.0002}
    tasks = [{"kind": "seat", "articulations": 300, "stylus_cone_deg": 70.0}]
    r = run(noise=sig, tasks=tasks, seed=3)
    t = r.truth
    truth = t["truth"]
    n = len(r.points)
    # probing repeatability: the true model at the written readings scatters around the truth
    aux = truth.aux(t["temperature"], t["tau_gravity"], t["tau_contact"])
    got = truth.model.ball_centres(r.points.q, r.true_wrench, truth.p, aux)
    dx = got - r.true_centres
    res = math.radians(0.0002)
    sd_expected = math.sqrt(4e-6 ** 2 + (res * 0.8) ** 2 / 12 * 3)   # plus quantisation of ~3 joints a lever ~0.8 m
    for k in range(3):
        assert np.std(dx[:, k]) == pytest.approx(4e-6, rel=0.15), k
    assert np.std(dx) < sd_expected * 1.2
    # encoder resolution: readings are whole multiples of it
    steps = r.points.q / res
    assert np.abs(steps - np.round(steps)).max() < 1e-6
    # force and temperature noise
    df = r.points.force - r.true_wrench[:, :3]
    assert np.std(df) == pytest.approx(0.02, rel=0.1)
    assert abs(np.mean(df)) < 3 * 0.02 / math.sqrt(df.size)
    dt = r.points.temperature - t["temperature"]
    assert np.std(dt) == pytest.approx(0.05, rel=0.15)
    assert n == 300


def test_core_model_without_the_effect_leaves_a_periodic_residual():
    """The close-the-loop premise: data with an undeclared j2 eccentricity, evaluated by a model that
    knows every other true parameter, misses by a residual periodic in q2."""
    r = run({"eccentricity": [{"joint": "j2", "amplitude_deg": 0.003, "phase_deg": 10.0}]},
            tasks=[{"kind": "seat", "articulations": 60, "stylus_cone_deg": 70.0}])
    t = r.truth
    base_model = ArmModel(r.campaign.arm)
    p_base = t["p_vector"][: base_model.spec.size]
    aux = AuxData(r.points.temperature)
    miss = base_model.ball_centres(r.points.q, r.points.force, p_base, aux) - r.true_centres
    assert np.linalg.norm(miss, axis=1).max() > 5e-6
    # the miss is the ball's motion under the eccentricity: J_q2 * (-a sin(q2 + phi))
    a, phi = math.radians(0.003), math.radians(10.0)
    arm = PinocchioArm(t["description"])
    for q, w, m in zip(r.true_q, r.true_wrench, miss, strict=True):
        jq, _ = arm.jacobians(q, w[:3])
        e = a * math.sin(q[1] - a * math.sin(q[1] + phi) + phi)   # reading q2 = q_true - e(reading)
        assert_close(m, -jq[:, 1] * e, atol=2e-9)
