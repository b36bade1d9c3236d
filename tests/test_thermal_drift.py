"""A drift of the links in time (no thermometer): the three evaluators agree, it scales the lengths as a
temperature would, the loop offers it only where it can be told (time, no temperature) and keeps it only when the
held-out folds do."""
from __future__ import annotations

import numpy as np
import pytest

from arm_model import PinocchioArm
from arm_model.effects import EFFECTS, JointCompliance, ThermalDrift, ThermalGrowth
from arm_model.model import ArmModel, AuxData
from conftest import assert_close


def test_three_evaluators_agree(nominal):
    model = ArmModel(nominal, (JointCompliance(), ThermalGrowth(), ThermalDrift(power=1, reference_time_s=900.0),
                               ThermalDrift(power=2, reference_time_s=900.0)))
    rng = np.random.default_rng(5)
    n = 8
    q = rng.uniform(-2.5, 2.5, (n, 7))
    w = np.zeros((n, 6))
    w[:, :3] = rng.normal(0, 2, (n, 3))
    tg, tc = PinocchioArm(nominal).torques(q, w)
    aux = AuxData(rng.uniform(15, 30, n), tg, tc, rng.uniform(0, 3600, n))
    p = rng.normal(0, 1e-5, model.spec.size)
    p[-2:] = [5e-8, 3e-11]                                   # 180 ppm an hour; a turn of the same order
    batch = model.ball_centres(q, w, p, aux)
    f = model.casadi_function()
    a = ArmModel.aux_matrix(aux, n, 7)
    for i in range(n):
        assert_close(np.array(f(q[i], w[i], a[i], p)).ravel(), batch[i], atol=1e-12)
        row = dict(temperature=aux.temperature[i], tau_gravity=tg[i], tau_contact=tc[i], time=aux.time[i])
        assert_close(model.pinocchio_ball_centre(q[i], w[i], p, row), batch[i], atol=1e-12)


def test_drift_scales_lengths_by_hand(nominal):
    model = ArmModel(nominal, (ThermalDrift(reference_time_s=100.0), ThermalDrift(power=2, reference_time_s=100.0)))
    assert model.spec.names[-2:] == ("links.drift_rate", "links.drift_rate2")
    assert model.spec.units[-2:] == ("1/s", "1/s^2")
    r1, r2, t = 5e-8, 2e-11, 1900.0
    p = model.spec.vector({"links.drift_rate": r1, "links.drift_rate2": r2})
    got = model.ball_centres(np.zeros((1, 7)), None, p, AuxData(time=np.array([t])))
    # at q = 0: x = a2 + a4 = 90 mm grows; z = d1 + d3 + d5 + d7 grows; the probe (85 mm) does not
    s = (1 + r1 * 1800.0) * (1 + r2 * 1800.0**2)
    assert_close(got[0], [0.090 * s, 0.0, 1.095 * s + 0.085], atol=1e-15)
    with pytest.raises(ValueError, match="time"):
        model.ball_centres(np.zeros((1, 7)), None, p)
    assert EFFECTS["thermal_drift"] is ThermalDrift
    for bad in ({"power": 3}, {"power": True}, {"reference_time_s": float("nan")}):
        with pytest.raises(ValueError, match="thermal_drift"):
            ThermalDrift(**bad)
