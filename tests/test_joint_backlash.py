"""A joint's play closed by gravity (:class:`arm_model.effects.JointBacklash`, red team round 3,
docs/close-loop.md): its evaluators agree, it is the rigid arm at shifted readings (by hand), the structure
family that sees it exists only where the gravity torque changes sign, and the family builds it."""
from __future__ import annotations

import numpy as np

from arm_model import PinocchioArm, ball_centres
from arm_model.effects import EFFECTS, JointBacklash
from arm_model.model import ArmModel, AuxData
from calibration.synthesis import synthesise
from conftest import assert_close


def _inputs(desc, n=8, seed=4):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, (n, desc.n_joints))
    w = np.zeros((n, 6))
    w[:, :3] = rng.normal(0, 2, (n, 3))
    tg, tc = PinocchioArm(desc).torques(q, w)
    return q, w, AuxData(np.full(n, 20.0), tg, tc)


def test_three_evaluators_agree_and_the_play_is_a_shifted_reading(nominal):
    model = ArmModel(nominal, (JointBacklash(joints=(1, 3)),))
    q, w, aux = _inputs(nominal)
    assert np.any(aux.tau_gravity[:, 3] > 0) and np.any(aux.tau_gravity[:, 3] < 0)
    p = np.zeros(model.spec.size)
    p[-2:] = [3e-5, -2e-5]
    batch = model.ball_centres(q, w, p, aux)
    # by hand: the joint turns by b against its gravity torque's sign, the rest is the rigid arm
    shifted = q.copy()
    shifted[:, 1] -= 3e-5 * np.sign(aux.tau_gravity[:, 1])
    shifted[:, 3] += 2e-5 * np.sign(aux.tau_gravity[:, 3])
    assert_close(batch, ball_centres(nominal, shifted, w), atol=1e-12)
    f = model.casadi_function()
    a = ArmModel.aux_matrix(aux, len(q), nominal.n_joints)
    for i in range(len(q)):
        assert_close(np.array(f(q[i], w[i], a[i], p)).ravel(), batch[i], atol=1e-12)
        assert_close(model.pinocchio_ball_centre(q[i], w[i], p, dict(tau_gravity=aux.tau_gravity[i])), batch[i],
                     atol=1e-12)
    assert EFFECTS["joint_backlash"] is JointBacklash
    assert model.spec.names[-2:] == ("j2.backlash", "j4.backlash")


def test_the_sign_family_builds_the_play_once(nominal):
    cands = synthesise(["j4 gravity torque sign", "j4 gravity torque"], ArmModel(nominal, ()))
    assert [(c.name, c.effect) for c in cands] == [("backlash j4", JointBacklash(joints=(3,)))]
    assert synthesise(["j4 gravity torque sign"], ArmModel(nominal, (JointBacklash(joints=(3,)),))) == []
