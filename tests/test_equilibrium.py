"""The static equilibrium under gravity: a compliant joint turns under the torque of the configuration the arm
sits in (sagged), not of its readings. A planar three-joint arm with heavy links, its torques derived by hand;
the simulator's truth (which solves the sagged pose and inverts for the readings) against the model."""
from __future__ import annotations

import numpy as np
import pytest
from urdf_fixtures import serial_urdf

from arm_model import NumericalError
from arm_model.description import GRAVITY
from arm_model.effects import JointCompliance
from arm_model.kinematics import ball_centres
from arm_model.model import ArmModel, AuxData
from arm_model.sim import campaign_from_dict, simulate
from arm_model.urdf_import import description_from_urdf
from conftest import assert_close

L, M, C = 0.5, 40.0, 2e-4     # link length [m], link mass [kg] at its middle, joint compliance [rad/(N m)]

#: three joints about y in a row, each link L long with M at its middle, the tip at the end of the third
PLANAR_URDF = serial_urdf(
    "heavy3", "base", [((0, 0, 0), (0, 0, 0), (0, 1, 0), -1.2, 0.3), ((L, 0, 0), (0, 0, 0), (0, 1, 0), -0.8, 0.8),
                       ((L, 0, 0), (0, 0, 0), (0, 1, 0), -0.8, 0.8)],
    "tip", (L, 0, 0), masses=[(M, (L / 2, 0, 0))] * 3, effort=1000.0)


def _hand_gravity_torques(theta: np.ndarray) -> np.ndarray:
    """(N, 3) torque [N m] each joint holds against gravity (RNEA's sign), by hand: a turn about +y by phi
    puts a link's x axis at (cos phi, 0, -sin phi); gravity -g z on a mass at horizontal distance x from a
    joint pulls it about +y by m g x, which the joint holds with -m g x."""
    g = -float(GRAVITY[2])
    phi = np.cumsum(theta, axis=1)                               # each link's absolute angle
    joints = np.concatenate([np.zeros((len(theta), 1)), np.cumsum(L * np.cos(phi), axis=1)], axis=1)
    com = joints[:, :3] + 0.5 * L * np.cos(phi)                 # horizontal positions of the masses
    return np.stack([-M * g * (com[:, i:] - joints[:, i:i + 1]).sum(axis=1) for i in range(3)], axis=1)


@pytest.fixture(scope="module")
def heavy(tmp_path_factory):
    path = tmp_path_factory.mktemp("heavy3") / "heavy3.urdf"
    path.write_text(PLANAR_URDF)
    desc = description_from_urdf(path, "tip")
    model = ArmModel(desc, (JointCompliance(gravity=True, contact=False),))
    p = model.spec.vector({f"j{k}.compliance": C for k in (1, 2, 3)})
    theta = np.random.default_rng(7).uniform([-1.0, -0.6, -0.6], [0.2, 0.6, 0.6], (12, 3))
    q = theta + C * _hand_gravity_torques(theta)                # readings: theta = q - C tau_g(theta)
    return path, desc, model, p, theta, q


def test_the_equilibrium_is_the_sagged_pose(heavy):
    """From the readings, the model finds the angles the joints sit at (by hand) to 1e-12 rad, and the ball
    there; the torques at the readings miss it by millimetres (the sag here: up to 60 mrad a joint)."""
    _, desc, model, p, theta, q = heavy
    assert np.max(np.abs(q - theta)) > 0.04
    aux = model.equilibrium_aux(q, None, p)
    assert_close(aux.tau_gravity, _hand_gravity_torques(theta), atol=1e-9)
    assert_close(model.joint_angles(q, None, p, aux), theta, atol=1e-12)
    truth = ball_centres(desc, theta)
    assert_close(model.ball_centres(q, None, p, aux), truth, atol=1e-12)
    at_readings = AuxData(None, _hand_gravity_torques(q), np.zeros_like(q))
    assert np.max(np.linalg.norm(model.ball_centres(q, None, p, at_readings) - truth, axis=1)) > 1e-3


def test_three_evaluators_agree_at_the_sagged_equilibrium(heavy):
    """Batch, CasADi and Pinocchio give one ball centre at the equilibrium's torques, to 1e-12 m."""
    _, desc, model, p, _, q = heavy
    aux = model.equilibrium_aux(q, None, p)
    batch = model.ball_centres(q, None, p, aux)
    f = model.casadi_function()
    a = ArmModel.aux_matrix(aux, len(q), 3)
    for i in range(len(q)):
        assert_close(np.array(f(q[i], np.zeros(6), a[i], p)).ravel(), batch[i], atol=1e-12)
        row = {"tau_gravity": aux.tau_gravity[i], "tau_contact": aux.tau_contact[i]}
        assert_close(model.pinocchio_ball_centre(q[i], None, p, row), batch[i], atol=1e-12)


def test_without_compliance_the_torques_are_the_readings(heavy):
    """A nominal model (no compliance): one pass, the torques at the readings as before."""
    _, _, model, _, _, q = heavy
    assert_close(model.equilibrium_aux(q).tau_gravity, _hand_gravity_torques(q), atol=1e-9)


def test_an_arm_that_buckles_is_said(heavy):
    """A compliance at which gravity's own stiffness wins (C dtau/dtheta > 1) has no equilibrium to find."""
    _, _, model, _, _, q = heavy
    soft = model.spec.vector({f"j{k}.compliance": 5e-2 for k in (1, 2, 3)})
    with pytest.raises(NumericalError, match="buckles under its own weight"):
        model.equilibrium_aux(q, None, soft)


def test_the_model_reproduces_the_simulator_s_truth(heavy):
    """The simulator solves the pose the arm sags into and inverts for the readings; the truth's model, from
    those readings (the points file's, 19 digits), finds the same angles and puts the tip where the simulator
    did, to 1e-12 m."""
    path = heavy[0]
    camp = {"name": "heavy3", "seed": 2, "arm": path.name, "tip_frame": "tip", "sensor": "none",
            "truth": {"length_error_mm": 0.5, "angle_error_deg": 0.05,
                      "joint_compliance": {"stiffness_Nm_per_rad": 1 / C, "gravity": True, "contact": False}},
            "task": [{"kind": "mocap", "postures": 10, "noise_mm": 0.0}]}
    sim = simulate(campaign_from_dict(camp, base_dir=path.parent))
    model, p, q = sim.truth["model"], sim.truth["p_vector"], sim.points.q
    assert np.max(np.abs(q - sim.true_q)) > 0.02                          # the sag is large
    aux = model.equilibrium_aux(q, None, p)
    assert_close(model.joint_angles(q, None, p, aux), sim.true_q, atol=1e-12)
    assert_close(model.ball_centres(q, None, p, aux), sim.true_centres, atol=1e-12)
