"""An arm with effects: numpy, CasADi and Pinocchio evaluations agree; each effect does its physics."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from arm_model import PinocchioArm, ball_centres, load_description
from arm_model.effects import (
    EncoderEccentricity,
    ForceSensorError,
    JointCompliance,
    JointGain,
    JointHarmonics,
    ProbeCompliance,
    ThermalGrowth,
)
from arm_model.model import ArmModel, AuxData
from conftest import NOMINAL, assert_close

ALL = (EncoderEccentricity(), JointGain(), JointCompliance(), ThermalGrowth(), ForceSensorError(),
       ProbeCompliance(anisotropic=True, axial=True))


def _data(nominal, n, seed):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, (n, 7))
    w = np.zeros((n, 6))
    w[:, :3] = rng.normal(0, 2, (n, 3))
    w[:, 3:] = rng.normal(0, 0.02, (n, 3))
    tg, tc = PinocchioArm(nominal).torques(q, w)
    return rng, q, w, AuxData(rng.uniform(15, 30, n), tg, tc)


def _casadi_and_pinocchio_agree(model, q, w, aux, p, batch):
    """CasADi and Pinocchio give the batch ball centres ``batch`` to 1e-12 m at every row."""
    f = model.casadi_function()
    A = ArmModel.aux_matrix(aux, len(q), 7)
    for i in range(len(q)):
        assert_close(np.array(f(q[i], w[i], A[i], p)).ravel(), batch[i], atol=1e-12)
        row = dict(temperature=aux.temperature[i], tau_gravity=aux.tau_gravity[i], tau_contact=aux.tau_contact[i])
        assert_close(model.pinocchio_ball_centre(q[i], w[i], p, row), batch[i], atol=1e-12)


def test_effect_model_three_evaluators_agree(nominal):
    model = ArmModel(nominal, ALL)
    rng, q, w, aux = _data(nominal, 8, 1)
    p = rng.normal(0, 1e-5, model.spec.size)
    batch = model.ball_centres(q, w, p, aux)
    _casadi_and_pinocchio_agree(model, q, w, aux, p, batch)


def test_zero_effect_parameters_give_the_base_model(nominal):
    model = ArmModel(nominal, ALL)
    rng, q, w, aux = _data(nominal, 50, 2)
    assert_close(model.ball_centres(q, w, None, aux), ball_centres(nominal, q, w), atol=1e-15)


def test_eccentricity_is_a_reading_error_of_its_joint(nominal):
    model = ArmModel(nominal, (EncoderEccentricity(joints=(1,), harmonics=(1,)),))
    assert model.spec.names[-2:] == ("j2.ecc1_cos", "j2.ecc1_sin")
    a, phi = 5e-5, 0.7
    p = model.spec.vector({"j2.ecc1_cos": a * math.sin(phi), "j2.ecc1_sin": a * math.cos(phi)})
    rng = np.random.default_rng(3)
    q = rng.uniform(-3, 3, (20, 7))
    q_true = q.copy()
    q_true[:, 1] += a * np.sin(q[:, 1] + phi)          # a sin(q + phi), by hand
    assert_close(model.ball_centres(q, None, p), ball_centres(nominal, q_true), atol=1e-15)


def test_joint_gain_scales_its_joint_reading(nominal):
    model = ArmModel(nominal, (JointGain(joints=(3,)),))
    assert model.spec.names[-1:] == ("j4.gain",) and model.spec.units[-1] == "1"
    p = model.spec.vector({"j4.gain": 3e-3})
    q = np.random.default_rng(4).uniform(-3, 3, (20, 7))
    q_true = q.copy()
    q_true[:, 3] *= 1.003                               # (1 + g) q, by hand
    assert_close(model.ball_centres(q, None, p), ball_centres(nominal, q_true), atol=1e-15)


def test_thermal_growth_scales_lengths(nominal):
    model = ArmModel(nominal, (ThermalGrowth(),))
    alpha, temp = 2.3e-5, 30.0
    p = model.spec.vector({"links.thermal_alpha": alpha})
    q = np.zeros((1, 7))
    grown = model.ball_centres(q, None, p, AuxData(temperature=np.array([temp])))
    # at q = 0: x = a2 + a4 = 90 mm grows; z = d1 + d3 + d5 + d7 grows; the probe (85 mm) does not
    s = 1 + alpha * (temp - 20.0)
    assert_close(grown[0], [0.090 * s, 0.0, 1.095 * s + 0.085], atol=1e-15)
    with pytest.raises(ValueError, match="temperature"):
        model.ball_centres(q, None, p)


def test_joint_compliance_turns_joint_by_load(nominal, pin_arm):
    model = ArmModel(nominal, (JointCompliance(joints=(1,)),))
    c = 2e-6  # rad/(N m)
    p = model.spec.vector({"j2.compliance": c})
    q = np.zeros((1, 7))
    q[0, 1] = 1.0
    w = np.array([[0.0, 0.0, -3.0]])
    tg, tc = pin_arm.torques(q, w)
    got = model.ball_centres(q, w, p, AuxData(tau_gravity=tg, tau_contact=tc))
    q_true = q.copy()
    q_true[0, 1] += c * (tc[0, 1] - tg[0, 1])
    assert_close(got, ball_centres(nominal, q_true, w), atol=1e-15)
    assert abs(c * (tc[0, 1] - tg[0, 1])) > 1e-6      # a real turn, not a no-op


def test_force_sensor_error_maps_reading_back(nominal):
    model = ArmModel(nominal, (ForceSensorError(axes=(0,)),))
    p = model.spec.vector({"force.gain_x": 0.1, "force.offset_x": 0.2})
    q = np.zeros((1, 7))
    f_true = np.array([[2.0, 0.0, 0.0]])
    f_meas = f_true * 1.1 + [0.2, 0, 0]
    assert_close(model.ball_centres(q, f_meas, p), ball_centres(nominal, q, f_true), atol=1e-15)


def test_an_effect_names_its_joints_by_the_arm_s_names():
    """Console lines name a URDF robot's joints as its file does (``arm_left_7_joint``), not by column."""
    desc = load_description(NOMINAL)
    renamed = replace(desc, joints=tuple(replace(j, name=f"arm_{k}") for k, j in enumerate(desc.joints)))
    assert EncoderEccentricity(joints=(1, 6)).describe() == "eccentricity(j2, j7)"
    assert EncoderEccentricity(joints=(1, 6)).describe(renamed) == "eccentricity(arm_1, arm_6)"
    assert JointHarmonics(joints=(2,), source=0, harmonics=(1,)).describe(renamed) == \
        "joint_harmonics(arm_2; h 1 of arm_0)"


def test_the_effects_seat_pairs_build_agree_across_the_three_evaluators(nominal):
    """A reading coupling (j6 reads a fraction of q5, ``JointGain(source=4)``) and a shoulder's lateral compliance
    (``LateralCompliance`` of j2), the effects the loop builds on simulated robot seat pairs
    (docs/studies/close-loop.md, Hidden effects on robots): batch, CasADi and Pinocchio to 1e-12 m, and each moves
    the ball."""
    from arm_model.effects import LateralCompliance
    model = ArmModel(nominal, (JointGain(joints=(5,), source=4), LateralCompliance(joints=(1,))))
    rng, q, w, aux = _data(nominal, 6, 3)
    p = np.r_[rng.normal(0, 1e-5, model.base_size), 2e-3, 4e-6, -3e-6]
    batch = model.ball_centres(q, w, p, aux)
    for k in range(model.base_size, model.spec.size):
        pk = p.copy()
        pk[k] = 0.0
        assert np.max(np.linalg.norm(batch - model.ball_centres(q, w, pk, aux), axis=1)) > 1e-6
    _casadi_and_pinocchio_agree(model, q, w, aux, p, batch)
