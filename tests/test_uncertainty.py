"""Uncertainty of the corrected ball centres: exact Jacobians (against CasADi), linear propagation
(against J Sigma J^T built from CasADi Jacobians and against Monte Carlo), defaults and their sources."""
from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from arm_model.effects import (ApproachOffset, EncoderEccentricity, ForceSensorError, JointCompliance, JointHarmonics,
                               LateralCompliance, ProbeCompliance, ProbeComplianceMatrix, ProbeThermalGrowth, ThermalGrowth)
from arm_model.jacobian import chain_jacobian
from arm_model.model import ArmModel, AuxData
from arm_model.params import split_params
from arm_model.uncertainty import (FORCE_SENSOR_U_N, COMPLIANCE_U_RELATIVE, ParameterCovariance, default_inputs,
                                   monte_carlo, propagate)
from arm_model.urdf_import import load_arm
from conftest import assert_close
from test_arm_model_urdf_chain import arm_urdf


def _casadi_jacobians(model: ArmModel):
    f = model.casadi_function()
    j = model.desc.n_joints
    q, w = ca.SX.sym("q", j), ca.SX.sym("w", 6)
    aux, p = ca.SX.sym("aux", 1 + 2 * j), ca.SX.sym("p", model.spec.size)
    x = f(q, w, aux, p)
    return ca.Function("centre_jac", [q, w, aux, p], [x, ca.jacobian(x, p), ca.jacobian(x, q), ca.jacobian(x, w)])


def _arms(nominal, tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(arm_urdf(nominal).replace('<axis xyz="0.0 0.0 1.0"/>', '<axis xyz="0 0.6 0.8"/>', 1))
    return {"dh": nominal, "mdh": replace(nominal, convention="mdh"), "urdf": load_arm(path, "tip")}


@pytest.mark.parametrize("convention", ["dh", "mdh", "urdf"])
def test_chain_jacobian_is_the_casadi_jacobian(nominal, tmp_path, convention):
    desc = _arms(nominal, tmp_path)[convention]
    model = ArmModel(desc)
    rng = np.random.default_rng(3)
    n, j = 6, desc.n_joints
    q = rng.uniform(-2.5, 2.5, (n, j))
    w = np.column_stack([rng.normal(0, 3, (n, 3)), rng.normal(0, 0.1, (n, 3))])
    p = rng.normal(0, 1e-3, model.spec.size) * np.array([1e-3 if u == "m/N" else 1.0 for u in model.spec.units])
    rows, pl, c = split_params(desc, p)
    cen, g = chain_jacobian(desc.convention, rows, pl, c, list(q.T), list(w.T), desc.axes)
    jac = _casadi_jacobians(model)
    size = model.spec.size
    for i in range(n):
        x, jp, jq, jw = (np.array(v) for v in jac(q[i], w[i], np.zeros(1 + 2 * j), p))
        assert_close(cen[i], x.ravel(), atol=1e-14)
        ref = np.hstack([jp, jq, jw])
        assert_close(g[:, :, i].T, ref, atol=1e-12 * np.abs(ref).max(), msg=f"point {i}")
    assert g.shape[0] == size + j + 6


def _effect_model(nominal):
    return ArmModel(nominal, (EncoderEccentricity(joints=(1, 3)), ThermalGrowth(), ForceSensorError(),
                              ProbeCompliance(anisotropic=True, axial=True), JointCompliance(joints=(1, 2)),
                              JointHarmonics(joints=(2,), source=1, harmonics=(1, 2)), ProbeThermalGrowth(),
                              ProbeComplianceMatrix(), ApproachOffset(), LateralCompliance(joints=(1, 4))))


def _random_cov(rng, k, scale):
    a = rng.normal(size=(k, k))
    return (a @ a.T / k) * np.outer(scale, scale)


def test_linear_propagation_is_j_sigma_jt_through_every_effect(nominal):
    model = _effect_model(nominal)
    rng = np.random.default_rng(5)
    n, j = 7, nominal.n_joints
    q = rng.uniform(-2, 2, (n, j))
    w = np.column_stack([rng.normal(0, 3, (n, 3)), np.zeros((n, 3))])
    aux = AuxData(temperature=rng.uniform(18, 26, n), tau_gravity=rng.normal(0, 20, (n, j)),
                  tau_contact=rng.normal(0, 2, (n, j)))
    spec = model.spec
    scale = np.array([{"m": 1e-4, "rad": 1e-4, "m/N": 1e-6, "1": 1e-3, "N": 0.05, "1/K": 1e-6,
                   "rad/(N m)": 1e-6}[u] for u in spec.units])
    p = rng.normal(0, 1, spec.size) * scale
    free = [i for i, nm in enumerate(spec.names) if not nm.startswith("probe.compliance")]
    cov = _random_cov(rng, len(free), scale[free])
    pc = ParameterCovariance(tuple(spec.names[i] for i in free), cov)
    inputs = default_inputs(nominal, encoder=np.linspace(1e-6, 7e-6, j), force=(0.07, 0.05, 0.04),
                            torque=0.002, probing=1.5e-6)
    res = propagate(model, p, q, w, aux, parameters=pc, inputs=inputs, chunk=3)
    jac = _casadi_jacobians(model)
    amat = ArmModel.aux_matrix(aux, n, j)
    u_w = np.concatenate([inputs.force, inputs.torque])
    for i in range(n):
        x, jp, jq, jw = (np.array(v) for v in jac(q[i], w[i], amat[i], p))
        assert_close(res.centres[i], x.ravel(), atol=1e-14)
        ref = (jp[:, free] @ cov @ jp[:, free].T + jq @ np.diag(inputs.encoder ** 2) @ jq.T
               + jw @ np.diag(u_w ** 2) @ jw.T + inputs.probing ** 2 * np.eye(3))
        assert_close(res.cov[i], ref, atol=1e-9 * np.abs(ref).max(), msg=f"point {i}")
    # compliance is in the covariance (probe.dcompliance_*): no separate contribution
    assert not res.contributions["compliance"].any()
    parts = sum(res.contributions.values())
    assert_close(parts, np.einsum("nii->ni", res.cov), atol=1e-9 * res.cov.max())


def test_compliance_contribution_by_hand(nominal):
    # one point, a pure bending force along probe x: the ball moves by c_x F_x along probe x
    model = ArmModel(nominal)
    q = np.array([[0.3, -0.4, 0.2, 1.0, -0.5, 0.7, 0.1]])
    f = np.array([[2.0, 0.0, 0.0]])
    inputs = default_inputs(nominal, encoder=0.0, force=0.0, compliance=(1e-6, 0.0, 0.0))
    res = propagate(model, None, q, f, parameters=None, inputs=inputs)
    assert_close(np.sqrt(np.trace(res.cov[0])), 2.0 * 1e-6, atol=1e-11)   # |dx| = F u_c (to 1st order)


def test_defaults_and_their_sources(nominal):
    from correction.paper import close_loop, load_paper_table2, table1_reproduction

    t1 = table1_reproduction()["budgets"]
    assert_close(FORCE_SENSOR_U_N, [t1["bending"].u_c, t1["bending"].u_c, t1["axial"].u_c], atol=5e-5)
    fit = close_loop(load_paper_table2()).origin
    assert_close(COMPLIANCE_U_RELATIVE, fit["slope_se"] / 2 / 0.0142e-3, atol=0.01)
    d = default_inputs(nominal)
    assert "Table 1" in d.sources["force sensor"] and "Table 2" in d.sources["compliance"]
    assert_close(d.compliance, 0.2 * nominal.probe.compliance, atol=1e-15)
    with pytest.raises(ValueError, match="finite"):
        default_inputs(nominal, force=-1.0)


def test_monte_carlo_agrees_with_linear_on_the_nominal_arm(nominal):
    model = ArmModel(nominal)
    rng = np.random.default_rng(11)
    n = 40
    q = rng.uniform(-2, 2, (n, nominal.n_joints))
    w = rng.normal(0, 2.0, (n, 3))
    spec = model.spec
    free = [i for i, nm in enumerate(spec.names) if not nm.startswith("probe.")]
    scale = np.array([1e-5 if spec.units[i] == "m" else 2e-5 for i in free])
    pc = ParameterCovariance(tuple(spec.names[i] for i in free), _random_cov(rng, len(free), scale))
    inputs = default_inputs(nominal, encoder=2e-5, probing=1e-6)
    lin = propagate(model, None, q, w, parameters=pc, inputs=inputs)
    mc = monte_carlo(model, None, q, w, parameters=pc, inputs=inputs, samples=3000, seed=2)
    ratio = mc.u / lin.u
    assert np.all(np.abs(ratio - 1) < 0.10), ratio
    assert abs(np.median(ratio) - 1) < 0.03
