"""Uncertainty of the corrected ball centres: exact Jacobians (against CasADi), linear propagation
(against J Sigma J^T built from CasADi Jacobians and against Monte Carlo), defaults and their sources."""
from __future__ import annotations

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
from test_arm_model_urdf_chain import arm_urdf

from arm_model.effects import (
    ApproachOffset,
    EncoderEccentricity,
    ForceSensorError,
    JointBacklash,
    JointCompliance,
    JointGain,
    JointHarmonics,
    JointHysteresis,
    LateralCompliance,
    ProbeCompliance,
    ProbeComplianceMatrix,
    ProbeThermalGrowth,
    ThermalDrift,
    ThermalGrowth,
)
from arm_model.jacobian import chain_jacobian, direction_jacobian, joint_screws, point_jacobian
from arm_model.model import ArmModel, AuxData
from arm_model.params import split_params
from arm_model.uncertainty import (
    COMPLIANCE_U_RELATIVE,
    FORCE_SENSOR_U_N,
    ParameterCovariance,
    default_inputs,
    directional_ratio,
    monte_carlo,
    propagate,
)
from arm_model.urdf_import import load_arm
from conftest import assert_close, fd_jacobian


def _casadi_jacobians(model: ArmModel):
    f = model.casadi_function()
    j = model.desc.n_joints
    q, w = ca.SX.sym("q", j), ca.SX.sym("w", 6)
    aux, p = ca.SX.sym("aux", ArmModel.aux_width(j)), ca.SX.sym("p", model.spec.size)
    x = f(q, w, aux, p)
    return ca.Function("centre_jac", [q, w, aux, p], [x, ca.jacobian(x, p), ca.jacobian(x, q), ca.jacobian(x, w)])


def _arms(nominal, tmp_path):
    """The test arms by convention; each built when asked for (loading one takes up to seconds)."""
    from test_arm_model_evaluators import SLIDER, _dh_with_prismatic

    from arm_model.description import parse_description

    def urdf():
        path = tmp_path / "arm.urdf"
        path.write_text(arm_urdf(nominal).replace('<axis xyz="0.0 0.0 1.0"/>', '<axis xyz="0 0.6 0.8"/>', 1))
        return load_arm(path, "tip")
    return _Lazy({"dh": lambda: nominal, "mdh": lambda: replace(nominal, convention="mdh"), "urdf": urdf,
                  "mdh-prismatic": lambda: _dh_with_prismatic(nominal, "mdh"),
                  "urdf-prismatic-mimic": lambda: parse_description(SLIDER)})


class _Lazy(dict):
    def __getitem__(self, key):
        return super().__getitem__(key)()


CONVENTIONS = ["dh", "mdh", "urdf", "mdh-prismatic", "urdf-prismatic-mimic"]


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_chain_jacobian_is_the_casadi_jacobian(nominal, tmp_path, convention):
    desc = _arms(nominal, tmp_path)[convention]
    model = ArmModel(desc)
    rng = np.random.default_rng(3)
    n, j = 6, desc.n_joints
    q = rng.uniform(-2.5, 2.5, (n, j))
    w = np.column_stack([rng.normal(0, 3, (n, 3)), rng.normal(0, 0.1, (n, 3))])
    p = rng.normal(0, 1e-3, model.spec.size) * np.array([1e-3 if u == "m/N" else 1.0 for u in model.spec.units])
    rows, pl, c = split_params(desc, p)
    cen, g = chain_jacobian(desc.convention, rows, pl, c, list(q.T), list(w.T), desc.chain_joints,
                            desc.probe.rotation, desc.probe.lever)
    jac = _casadi_jacobians(model)
    size = model.spec.size
    for i in range(n):
        x, jp, jq, jw = (np.array(v) for v in jac(q[i], w[i], np.zeros(ArmModel.aux_width(j)), p))
        assert_close(cen[i], x.ravel(), atol=1e-14)
        ref = np.hstack([jp, jq, jw])
        assert_close(g[:, :, i].T, ref, atol=1e-12 * np.abs(ref).max(), msg=f"point {i}")
        # one point alone (a live session's) runs on Python floats: the batch's numbers, bit for bit
        one = [[v if np.ndim(v) == 0 else v[i: i + 1] for v in r] for r in rows]
        c1, g1 = chain_jacobian(desc.convention, one, pl, c, list(q[i: i + 1].T), list(w[i: i + 1].T),
                                desc.chain_joints, desc.probe.rotation, desc.probe.lever)
        np.testing.assert_array_equal(c1[0], cen[i])
        np.testing.assert_array_equal(g1[:, :, 0], g[:, :, i])
    assert g.shape[0] == size + j + 6


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_joint_screws_give_pinocchios_and_finite_difference_jacobians(nominal, tmp_path, convention):
    """The q-only Jacobian of the inverse kinematics: the last frame against the chain (a second
    implementation), the ball's Jacobian against Pinocchio's frame Jacobian and central differences, the
    frame axes' Jacobians against central differences, all to 1e-9 relative."""
    from arm_model import PinocchioArm
    from arm_model.chain import chain_point
    from arm_model.kinematics import rigid_centres

    desc = _arms(nominal, tmp_path)[convention].with_probe(rpy=(0.1, -0.2, 0.3))
    rng = np.random.default_rng(4)
    n, j = 6, desc.n_joints
    q = rng.uniform(-2.5, 2.5, (n, j))
    rows = desc.row_table()

    def frame(qq):
        qt = list(np.atleast_2d(qq).T)
        o = np.column_stack(chain_point(desc.convention, rows, qt, (0.0, 0.0, 0.0), joints=desc.chain_joints))
        return np.stack([np.column_stack(chain_point(desc.convention, rows, qt, tuple(e), joints=desc.chain_joints)) - o
                         for e in np.eye(3)], axis=2), o

    r, o, u, c = joint_screws(desc.convention, rows, q, desc.chain_joints)
    columns = joint_screws(desc.convention, [[np.full(n, v) for v in row] for row in rows], q, desc.chain_joints)
    for a, b in zip(columns, (r, o, u, c), strict=True):      # rows as columns (a geometry per point, e.g. thermal)
        assert_close(a, b, atol=1e-15)
    r_ref, o_ref = frame(q)
    assert_close(r, r_ref, atol=1e-14)
    assert_close(o, o_ref, atol=1e-14)
    ball = rigid_centres(desc, q)
    jn = desc.chain_joints
    jb = point_jacobian(u, c, ball, jn, j)
    arm = PinocchioArm(desc)
    for i in range(n):
        ref = arm.jacobians(q[i])[0]
        assert_close(jb[i], ref, atol=1e-9 * np.abs(ref).max(), msg=f"point {i}")
        fd = fd_jacobian(lambda x: rigid_centres(desc, x[None])[0], q[i])
        assert_close(jb[i], fd, atol=1e-9 * np.abs(fd).max(), msg=f"point {i}")
        for k in range(3):
            fd = fd_jacobian(lambda x: frame(x)[0][0, :, k], q[i])
            assert_close(direction_jacobian(u[i:i + 1], r[i:i + 1, :, k], jn, j)[0], fd, atol=1e-9, msg=f"axis {k}")


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
    # the shared rows give the covariance BETWEEN points: J_p(i) Sigma J_p(k)^T
    sy = propagate(model, p, q, w, aux, parameters=pc, inputs=inputs, chunk=3, systematic=True)
    assert_close(sy.cov, res.cov, atol=1e-12 * res.cov.max())
    jps = [np.array(jac(q[i], w[i], amat[i], p)[1])[:, free] for i in (0, 4)]
    ref = jps[0] @ cov @ jps[1].T
    assert_close(sy.systematic[0].T @ sy.systematic[4], ref, atol=1e-9 * np.abs(ref).max())


@pytest.mark.parametrize("convention", ["dh", "urdf"])
def test_one_point_propagation_is_the_batch_and_finite_differences_on_every_effect(nominal, tmp_path, convention):
    # a live session propagates each point alone (chain_jacobian on Python floats, the plan made once): the same
    # covariance as the points propagated together (relative 1e-15), every effect kind a model file holds
    desc = _arms(nominal, tmp_path)[convention]
    model = ArmModel(desc, (EncoderEccentricity(joints=(1, 3)), JointGain(joints=(2,)), ThermalGrowth(),
                            ThermalDrift(), ForceSensorError(), ProbeCompliance(anisotropic=True, axial=True),
                            JointCompliance(joints=(1, 2)), JointHarmonics(joints=(2,), source=1, harmonics=(1, 2)),
                            ProbeThermalGrowth(), ProbeComplianceMatrix(), ApproachOffset(),
                            LateralCompliance(joints=(1, 4)), JointBacklash(joints=(3,)), JointHysteresis(joints=(5,))))
    rng = np.random.default_rng(8)
    n, j = 3, desc.n_joints
    q = rng.uniform(-2, 2, (n, j))
    w = np.column_stack([rng.normal(0, 3, (n, 3)), rng.normal(0, 0.05, (n, 3))])
    aux = AuxData(temperature=rng.uniform(18, 26, n), tau_gravity=rng.normal(0, 20, (n, j)),
                  tau_contact=rng.normal(0, 2, (n, j)), time=rng.uniform(0, 3600, n),
                  motion=rng.choice([-1.0, 1.0], (n, j)))
    spec = model.spec
    scale = np.array([{"m": 1e-4, "rad": 1e-4, "m/N": 1e-6, "1": 1e-3, "N": 0.05, "1/K": 1e-6, "1/s": 1e-8,
                       "1/s^2": 1e-12, "rad/(N m)": 1e-6}[u] for u in spec.units])
    p = rng.normal(0, 1, spec.size) * scale
    free = [i for i, nm in enumerate(spec.names) if not nm.startswith("probe.compliance")]
    cov = _random_cov(rng, len(free), scale[free])
    pc = ParameterCovariance(tuple(spec.names[i] for i in free), cov)
    inputs = default_inputs(desc, encoder=np.linspace(1e-6, 7e-6, j), force=(0.07, 0.05, 0.04), torque=0.002)
    batch = propagate(model, p, q, w, aux, parameters=pc, inputs=inputs, systematic=True)
    u_w = np.concatenate([inputs.force, inputs.torque])
    ones = []
    for i in range(n):
        one = propagate(model, p, q[i: i + 1], w[i: i + 1], aux.select(slice(i, i + 1)), parameters=pc,
                        inputs=inputs, threads=1, systematic=True)
        assert_close(one.cov[0], batch.cov[i], atol=1e-15 * np.abs(batch.cov[i]).max(), msg=f"point {i}")
        assert_close(one.systematic[0], batch.systematic[i], atol=1e-15 * np.abs(batch.systematic[i]).max())
        ones.append(one.cov[0])

    # J by CasADi (exact; its own AD of the effects' code): the covariance to 1e-9 relative (through the factor
    # propagate uses: the covariance's own rounding in it is not the Jacobian's)
    jac = _casadi_jacobians(model)
    amat = ArmModel.aux_matrix(aux, n, j)
    lfac = pc.factor()
    for i in range(n):
        _, jp, jq, jw = (np.array(v) for v in jac(q[i], w[i], amat[i], p))
        a = jp[:, free] @ lfac
        ref = a @ a.T + jq @ np.diag(inputs.encoder ** 2) @ jq.T + jw @ np.diag(u_w ** 2) @ jw.T
        assert_close(ones[i], ref, atol=1e-9 * np.abs(ref).max(), msg=f"point {i} against CasADi")
    # the encoders' and the force sensor's parts by central differences of the model's centres (all points and steps
    # in one call; relative 1e-6: the differences' truncation and rounding)
    steps = np.concatenate([np.full(j, 1e-6), np.full(6, 0.1)])       # the centre is nearly linear in the wrench
    x0 = np.hstack([q, w])
    xs = np.concatenate([x0[:, None, :] + np.diag(steps) * sgn for sgn in (1.0, -1.0)], axis=1)   # (n, 2K, K)
    k2 = xs.shape[1]
    cen = model.ball_centres(xs[:, :, :j].reshape(-1, j), xs[:, :, j:].reshape(-1, 6), p,
                             AuxData(*(None if v is None else np.repeat(v, k2, axis=0) for v in (
                                 aux.temperature, aux.tau_gravity, aux.tau_contact, aux.time, aux.motion))))
    cen = cen.reshape(n, 2, len(steps), 3)
    dq = ((cen[:, 0] - cen[:, 1]) / (2 * steps[:, None])).transpose(0, 2, 1)     # (n, 3, K)
    no_p = default_inputs(desc, encoder=inputs.encoder, force=inputs.force, torque=inputs.torque, compliance=0.0)
    for i in range(n):
        jq, jw = dq[i, :, :j], dq[i, :, j:]
        want = jq @ np.diag(inputs.encoder ** 2) @ jq.T + jw @ np.diag(u_w ** 2) @ jw.T
        got = propagate(model, p, q[i: i + 1], w[i: i + 1], aux.select(slice(i, i + 1)), inputs=no_p, threads=1).cov[0]
        assert_close(got, want, atol=1e-6 * np.abs(want).max(), msg=f"point {i} against differences")


def test_shared_rows_of_a_singular_parameter_covariance(nominal):
    # a covariance file can carry a held parameter with variance from the free ones (rank below its names):
    # the shared rows are the factor's, fewer than the names, and still give J_p(i) Sigma J_p(k)^T
    model = ArmModel(nominal)
    rng = np.random.default_rng(11)
    q = rng.uniform(-2, 2, (5, nominal.n_joints))
    names = tuple(nm for nm in model.spec.names if not nm.startswith("probe.compliance"))[:6]
    b = rng.normal(size=(6, 4)) * 1e-5
    cov = b @ b.T                                     # rank 4 of 6
    pc = ParameterCovariance(names, cov)
    inputs = default_inputs(nominal, encoder=0.0, force=0.0)
    sy = propagate(model, None, q, parameters=pc, inputs=inputs, chunk=2, systematic=True)
    idx = [model.spec.index(nm) for nm in names]
    jac = _casadi_jacobians(model)
    amat = ArmModel.aux_matrix(None, len(q), nominal.n_joints)
    w0 = np.zeros(6)
    p0 = np.zeros(model.spec.size)
    jps = [np.array(jac(q[i], w0, amat[i], p0)[1])[:, idx] for i in (0, 3)]
    ref = jps[0] @ cov @ jps[1].T
    assert_close(sy.systematic[0].T @ sy.systematic[3], ref, atol=1e-9 * np.abs(ref).max())


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
    # the covariance terms: each off-diagonal term within 10 % of the scale sqrt(C_ii C_jj) (a term can be
    # near zero, so not relative to itself), i.e. the correlation coefficients agree within 0.1
    for i, j in ((0, 1), (0, 2), (1, 2)):
        scale_ij = lin.u[:, i] * lin.u[:, j]
        assert np.all(np.abs(mc.cov[:, i, j] - lin.cov[:, i, j]) < 0.10 * scale_ij), (i, j)
    # the whole covariance: the standard uncertainty along 2000 random directions within 10 % at every point
    v = rng.standard_normal((2000, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    along = np.sqrt(np.einsum("di,nij,dj->nd", v, mc.cov, v) / np.einsum("di,nij,dj->nd", v, lin.cov, v))
    assert np.all(np.abs(along - 1) < 0.10), (along.min(), along.max())
    # directional_ratio (generalized eigenvalues) bounds the sampled directions and nearly reaches them
    ext = directional_ratio(lin.cov, mc.cov)
    assert np.all(ext[:, 0] <= along.min(axis=1) + 1e-12) and np.all(along.max(axis=1) <= ext[:, 1] + 1e-12)
    assert_close(ext, np.column_stack([along.min(axis=1), along.max(axis=1)]), atol=0.01)
    assert np.all(np.abs(ext - 1) < 0.10), ext


# ---------------------------------------------------------------------------------------------
# aacmm tip

def test_tip_writes_uncertainty_columns_and_monte_carlo_agrees(tmp_path, nominal, capsys):
    import csv

    from arm_model.cli import main
    from conftest import NOMINAL

    rng = np.random.default_rng(4)
    q = rng.uniform(-90, 90, (30, 7))
    f = rng.normal(0, 2, (30, 3))
    pts = tmp_path / "p.csv"
    pts.write_text("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + ",fx_N,fy_N,fz_N\n"
                   + "\n".join(",".join(map(str, ["m1", "ring", *qi, *fi]))
                               for qi, fi in zip(q, f, strict=True)) + "\n")
    out = tmp_path / "tips.csv"
    assert main(["tip", str(pts), "--arm", str(NOMINAL), "-o", str(out), "--covariance", "--mc", "2000",
                 "--encoder-resolution-deg", "0.001", "--u-probing-um", "0.5"]) == 0
    text = capsys.readouterr().out
    assert "force sensor" in text and "Table 1" in text and "Monte Carlo (2000 samples" in text
    rows = list(csv.DictReader(out.open()))
    u = np.array([[float(r[f"u_{a}_mm"]) for a in "xyz"] for r in rows])
    cov = np.array([[float(r[f"cov_{a}{a}_um2"]) for a in "xyz"] for r in rows])
    umc = np.array([[float(r[f"u_{a}_mc_mm"]) for a in "xyz"] for r in rows])
    assert_close(u * 1e3, np.sqrt(cov), atol=2e-3)
    # the Monte Carlo's covariance terms beside the linear ones: its diagonal is u_mc, each off-diagonal
    # term within 10 % of sqrt(C_ii C_jj) of the linear result
    covmc = {t: np.array([float(r[f"cov_{t}_mc_um2"]) for r in rows]) for t in ("xx", "yy", "zz", "xy", "xz", "yz")}
    assert_close(umc * 1e3, np.sqrt(np.column_stack([covmc["xx"], covmc["yy"], covmc["zz"]])), atol=2e-3)
    for t in ("xy", "xz", "yz"):
        lin_t = np.array([float(r[f"cov_{t}_um2"]) for r in rows])
        scale_t = np.sqrt(np.array([float(r[f"cov_{t[0] * 2}_um2"]) * float(r[f"cov_{t[1] * 2}_um2"]) for r in rows]))
        assert np.all(np.abs(covmc[t] - lin_t) < 0.10 * scale_t), t
    assert "along any direction (the covariance terms included)" in text
    # by hand: the probing term alone is 0.5 um, the rest adds in quadrature
    assert np.all(u * 1e3 >= 0.5 - 1e-6)
    assert np.all(np.abs(umc / u - 1) < 0.10)
    # bad option: message, exit 2 (argparse), nothing written
    out2 = tmp_path / "t2.csv"
    with pytest.raises(SystemExit) as exc:
        main(["tip", str(pts), "--arm", str(NOMINAL), "-o", str(out2), "--u-probing-um", "-1"])
    assert exc.value.code == 2 and not out2.exists()
    # no covariance and no option: no uncertainty columns
    assert main(["tip", str(pts), "--arm", str(NOMINAL), "-o", str(out2)]) == 0
    assert "u_x_mm" not in out2.read_text().splitlines()[0]


def test_tip_with_a_model_file_and_its_covariance(tmp_path, nominal, capsys):
    """A model file naming a covariance file: tip writes the uncertainty columns without being asked,
    and the parameter contribution is J Sigma J^T of that covariance (CasADi Jacobian)."""
    import csv

    from arm_model.cli import main
    from arm_model.model_file import format_model, write_covariance

    model = ArmModel(nominal)
    spec = model.spec
    names = ["j2.d", "j3.a", "j4.alpha", "probe.z"]
    idx = [spec.index(n) for n in names]
    rng = np.random.default_rng(8)
    cov = _random_cov(rng, 4, np.array([2e-6, 3e-6, 5e-6, 1e-6]))
    write_covariance(tmp_path / "arm-covariance.csv", names, [spec.units[i] for i in idx], np.zeros(4), cov)
    (tmp_path / "arm.toml").write_text(format_model(nominal, covariance="arm-covariance.csv"))
    q = rng.uniform(-90, 90, (5, 7))
    pts = tmp_path / "p.csv"
    pts.write_text("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\n"
                   + "\n".join(",".join(map(str, ["m1", "", *qi])) for qi in q) + "\n")
    out = tmp_path / "t.csv"
    assert main(["tip", str(pts), "--arm", str(tmp_path / "arm.toml"), "-o", str(out)]) == 0
    assert "arm-covariance.csv" in capsys.readouterr().out
    rows = list(csv.DictReader(out.open()))
    u = np.array([[float(r[f"u_{a}_mm"]) for a in "xyz"] for r in rows]) * 1e-3
    jac = _casadi_jacobians(model)
    u_q = np.radians(0.0001) / np.sqrt(12)             # the encoder step the nominal arm's description gives
    for i in range(5):
        out = jac(np.radians(q[i]), np.zeros(6), np.zeros(ArmModel.aux_width(7)), np.zeros(spec.size))
        jp, jq = np.array(out[1])[:, idx], np.array(out[2])
        assert_close(u[i], np.sqrt(np.diag(jp @ cov @ jp.T + u_q ** 2 * jq @ jq.T)), atol=2e-9)


def test_encoder_resolution_from_the_description(nominal):
    from arm_model import InputError
    from arm_model.description import format_description, parse_description

    # the shipped arm gives 0.0001 deg on every joint (the step of the bundled data's readings)
    assert_close([j.encoder_resolution for j in nominal.joints], [np.radians(0.0001)] * 7, atol=1e-18)
    assert_close(default_inputs(nominal).encoder, [np.radians(0.0001) / np.sqrt(12)] * 7, atol=1e-18)
    bare = replace(nominal, joints=tuple(replace(j, encoder_resolution=None) for j in nominal.joints))
    text = format_description(bare).replace('name = "j2"\n', 'name = "j2"\nencoder_resolution_deg = 0.0005\n')
    desc = parse_description(text)
    assert_close(desc.joints[1].encoder_resolution, np.radians(0.0005), atol=1e-18)
    assert desc.joints[0].encoder_resolution is None
    d = default_inputs(desc)
    assert_close(d.encoder, [0, np.radians(0.0005) / np.sqrt(12)] + [0] * 5, atol=1e-18)
    assert "1 of 7 joints" in d.sources["encoders"]
    assert parse_description(format_description(desc)) == desc           # written back exactly
    with pytest.raises(InputError, match="encoder_resolution"):
        parse_description(text.replace("encoder_resolution_deg = 0.0005", "encoder_resolution_deg = 0"))


def test_tip_refuses_a_covariance_that_is_not_one(tmp_path, nominal, capsys):
    from arm_model.cli import main
    from arm_model.model_file import format_model

    pts = tmp_path / "p.csv"
    pts.write_text("measurement,feature," + ",".join(f"q{i}_deg" for i in range(1, 8)) + "\nm,," + "10," * 6 + "10\n")
    out = tmp_path / "t.csv"
    # a correlation of 2 (refused with its cell); correlations of 0.9, 0.9, -0.9 (each in [-1, 1], together
    # not positive semi-definite)
    for names, corr, words in ((["j2.d", "j3.a"], [[1, 2], [2, 1]], "line 2, column 'j3.a': a correlation "
                                "coefficient must be in [-1, 1]"),
                               (["j2.d", "j3.a", "j4.d"], [[1, .9, .9], [.9, 1, -.9], [.9, -.9, 1]],
                                "positive semi-definite")):
        # written by hand: the project's writer reads back what it writes and would refuse the first
        (tmp_path / "c.csv").write_text("parameter,unit,value,u," + ",".join(names) + "\n" + "".join(
            f"{n},um,0,1," + ",".join(map(str, row)) + "\n" for n, row in zip(names, corr, strict=True)))
        (tmp_path / "arm.toml").write_text(format_model(nominal, covariance="c.csv"))
        assert main(["tip", str(pts), "--arm", str(tmp_path / "arm.toml"), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert "c.csv" in err and words in err and not out.exists(), err


def test_propagation_with_prismatic_and_mimic_joints(nominal, tmp_path):
    """The encoder contribution of an arm with a prismatic lift (its resolution a length) and a mimic joint
    (no encoder of its own) is J_q diag(u^2) J_q^T with J_q CasADi's, by encoder column."""
    desc = _arms(nominal, tmp_path)["urdf-prismatic-mimic"]
    model = ArmModel(desc)
    inputs = default_inputs(desc, encoder=[1e-5, 2e-6, 1e-5, 1e-5, 5e-6])
    assert default_inputs(desc).encoder[1] == pytest.approx(1e-6 / np.sqrt(12))    # encoder_resolution_mm
    rng = np.random.default_rng(7)
    q = np.column_stack([rng.uniform(-1, 1, 5), rng.uniform(0, 0.3, 5), rng.uniform(-1, 1, (5, 2)),
                         rng.uniform(0, 0.04, 5)])
    w = np.column_stack([rng.normal(0, 2, (5, 3)), np.zeros((5, 3))])
    prop = propagate(model, None, q, w, inputs=inputs)
    jac = _casadi_jacobians(model)
    for i in range(5):
        jq = np.array(jac(q[i], w[i], np.zeros(ArmModel.aux_width(desc.n_joints)), np.zeros(model.spec.size))[2])
        ref = jq @ np.diag(inputs.encoder ** 2) @ jq.T
        assert_close(prop.contributions["encoders"][i], np.diag(ref), atol=1e-6 * np.abs(ref).max())
