"""Calibration residuals: the CasADi model against Pinocchio, residual kinds by hand, exact Jacobians
against finite differences, state updates that stay on their manifolds."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from arm_model.effects import EncoderEccentricity, ProbeCompliance, ThermalGrowth
from arm_model.geometry import perpendicular_basis, rotation_xyz
from arm_model.model import ArmModel
from arm_model.sim.quick import SynthSpec, make_campaign
from calibration import Problem, Weights, kinds as geo, make_data
from conftest import assert_close


@pytest.fixture(scope="module")
def campaign(nominal):
    model = ArmModel(nominal)
    spec = SynthSpec(ballbars=3, ballbar_points=5, seats=1, articulations=6, spheres=1, sphere_points=8, rings=1,
                     ring_points=9, planes=1, plane_points=6, reference_points=12, force=1.5, noise=3e-6)
    return model, make_campaign(model, spec, seed=11)


def test_casadi_centres_match_pinocchio(nominal):
    """The Problem's CasADi ball centres (with effects and a wrench) equal the Pinocchio evaluation of the
    same description to 1e-12 m."""
    model = ArmModel(nominal, (EncoderEccentricity(joints=(1,), harmonics=(1,)), ThermalGrowth(),
                               ProbeCompliance(anisotropic=True)))
    rng = np.random.default_rng(3)
    n = 6
    c = make_campaign(ArmModel(nominal), SynthSpec(ballbars=0, seats=1, articulations=n, spheres=0), seed=2)
    pts = c.points
    pts = replace(pts, force=rng.normal(0, 2, (n, 3)), force_kind="xyz", temperature=rng.uniform(15, 25, n))
    data = make_data(pts, c.artefacts, model)
    prob = Problem(model, data, Weights(), [])
    p = np.array([rng.normal(0, {"m": 1e-4, "rad": 1e-3, "m/N": 1e-6, "1/K": 1e-5}[u]) for u in model.spec.units])
    x, _ = prob.centres(p)
    for i in range(n):
        ref = model.pinocchio_ball_centre(pts.q[i], pts.wrench[i], p, {"temperature": pts.temperature[i]})
        assert_close(x[i], ref, atol=1e-12)


def test_residual_kinds_by_hand():
    x = np.array([0.3, -0.2, 0.5])
    z = np.zeros
    # seat: x - c
    r, _, _ = geo.kind_function("seat")(x, z(3), [0.1, 0.1, 0.1], z(3))
    assert_close(np.array(r).ravel(), [0.2, -0.3, 0.4], atol=1e-15)
    # sphere: |x - c| - R, here |(3, 4, 0) mm| = 5 mm
    r, drdx, _ = geo.kind_function("sphere")([0.003, 0.004, 0.0], z(3), [0, 0, 0, 0.0045], z(3))
    assert_close(float(r), 0.0005, atol=1e-15)
    assert_close(np.array(drdx).ravel(), [0.6, 0.8, 0.0], atol=1e-15)
    # ring: axis through (1, 0, 0) along z; point at distance 3 from the axis, R = 2
    e1, e2 = perpendicular_basis(np.array([0, 0, 1.0]))
    k = np.concatenate([[1, 0, 0], [0, 0, 1], e1, e2, [2.0]])
    r, _, _ = geo.kind_function("ring")([1, 3, 7.0], z(4), k, z(3))
    assert_close(float(r), 1.0, atol=1e-15)
    # plane z = 0.25 (h absorbs the ball radius): signed distance
    e1, e2 = perpendicular_basis(np.array([0, 0, 1.0]))
    r, _, _ = geo.kind_function("plane")([5, 6, 0.75], z(3), np.concatenate([[0, 0, 1], e1, e2, [0.25]]), z(3))
    assert_close(float(r), 0.5, atol=1e-15)
    # reference: R x + t - x_ref with R a quarter turn about z
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    k = np.concatenate([rot.reshape(-1, order="F"), [1, 2, 3]])
    r, _, _ = geo.kind_function("reference")([1, 0, 0], z(6), k, [1, 3, 3])
    assert_close(np.array(r).ravel(), [0, 0, 0], atol=1e-15)
    # distance: |a - b| - L
    r, _, _ = geo.distance_function()([0, 0, 0], [0.3, 0.4, 0], 0.49)
    assert_close(float(r), 0.01, atol=1e-15)


def _numpy_residuals(prob: Problem, p, states) -> np.ndarray:
    """A second implementation of the weighted residuals: numpy, ball centres from
    ``ArmModel.ball_centres`` (not CasADi), kinds written out by hand."""
    data, model = prob.data, prob.model
    x_all = model.ball_centres(data.points.q, data.wrench, p, data.aux)
    out = []
    for g in prob.groups:
        for k, (pi, ii) in enumerate(zip(g["points"], g["inst"], strict=True)):
            s, x = states[ii], x_all[pi]
            kind = g["kind"]
            if kind == "seat":
                out.append(x - s[:3])
            elif kind == "sphere":
                out.append([np.linalg.norm(x - s[:3]) - s[3]])
            elif kind in ("ring", "cylinder"):
                v = x - s[0:3]
                out.append([np.linalg.norm(v - (v @ s[3:6]) * s[3:6]) - s[12]])
            elif kind == "plane":
                out.append([s[0:3] @ x - s[9]])
            else:
                a = g["anchor"][k]
                xx = states[a][:3] if a >= 0 else x
                out.append(s[0:9].reshape(3, 3, order="F") @ xx + s[9:12] - data.points.ref[pi, 0])
    for d in prob.distance_items:
        out.append([np.linalg.norm(states[d.a][:3] - states[d.b][:3]) - d.length])
    return np.concatenate([np.ravel(o) for o in out]) / prob.sigma


def test_residuals_match_a_numpy_implementation(campaign):
    model, c = campaign
    data = make_data(c.points, c.artefacts, model, reference=c.reference_points)
    prob = Problem(model, data, Weights(probe=3e-6), np.arange(model.spec.size))
    states = prob.initial_states(c.p_true)
    ev = prob.evaluate(c.p_true, states)
    assert {g["kind"] for g in prob.groups} == {"seat", "sphere", "ring", "plane", "reference"}
    assert len(prob.distance_items) == 3
    assert_close(ev.r, _numpy_residuals(prob, c.p_true, states), atol=1e-7)   # weighted: 1e-7 sigma


def test_jacobians_match_finite_differences(campaign, nominal):
    """d r / d p and d r / d theta (all kinds, a reference tied to a seat included) against central
    differences of the numpy residuals."""
    model, c = campaign
    ref = c.reference_points
    # tie three reference rows to the seat (a tracker nest): same measurement and feature
    seat_rows = np.flatnonzero(c.points.feature == "seat")[:3]
    pts = c.points
    nest = pts.select(seat_rows)
    nest = replace(nest, ref=1.0 + np.arange(9.0).reshape(3, 1, 3) * 1e-6)
    data = make_data(pts, c.artefacts, model, reference=_concat_ref(ref, nest))
    free = np.arange(model.spec.size)
    prob = Problem(model, data, Weights(probe=3e-6), free)
    p0 = c.p_true + 1e-6
    states = prob.initial_states(p0)
    assert sum((g["anchor"] >= 0).sum() for g in prob.groups if g["kind"] == "reference") == 3
    ev = prob.evaluate(p0, states)
    for k in range(0, model.spec.size, 3):
        e = np.zeros(model.spec.size)
        e[k] = 1e-7 if model.spec.units[k] != "m/N" else 1e-9
        fd = (_numpy_residuals(prob, p0 + e, states) - _numpy_residuals(prob, p0 - e, states)) / (2 * e[k])
        scale = max(np.abs(fd).max(), 1.0)
        assert np.abs(fd - ev.jp[:, k]).max() <= 2e-5 * scale, model.spec.names[k]
    jt = ev.jt.toarray()
    for k in range(0, prob.n_nuisance, 2):
        e = np.zeros(prob.n_nuisance)
        e[k] = 1e-7
        fd = (_numpy_residuals(prob, p0, prob.retract(states, e))
              - _numpy_residuals(prob, p0, prob.retract(states, -e))) / 2e-7
        scale = max(np.abs(fd).max(), 1.0)
        assert np.abs(fd - jt[:, k]).max() <= 2e-5 * scale, k


def _concat_ref(a, b):
    from calibration.data import merge_points
    m, _ = merge_points(a, b)
    return m


@settings(max_examples=30, deadline=None)
@given(theta=st.lists(st.floats(-0.5, 0.5), min_size=6, max_size=6),
       axis=st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 0.1))
def test_retract_stays_on_the_manifold(theta, axis):
    """Axes stay unit vectors with an orthonormal complement; rotations stay proper rotations."""
    u = np.array(axis) / np.linalg.norm(axis)
    e1, e2 = perpendicular_basis(u)
    ring = np.concatenate([[0.1, 0.2, 0.3], u, e1, e2, [0.05]])
    new = geo.retract("ring", ring, np.array(theta[:4]))
    b = np.column_stack([new[3:6], new[6:9], new[9:12]])
    assert_close(b.T @ b, np.eye(3), atol=1e-12)
    assert_close(np.linalg.det(b), 1.0, atol=1e-12)
    rot = rotation_xyz(theta[3:])
    ref = np.concatenate([rot.reshape(-1, order="F"), [0, 0, 0]])
    new = geo.retract("reference", ref, np.array(theta))
    r = new[0:9].reshape(3, 3, order="F")
    assert_close(r.T @ r, np.eye(3), atol=1e-13)
    assert_close(np.linalg.det(r), 1.0, atol=1e-13)


def test_starting_states_find_the_features():
    """Starting states on exact data (the fits are tested in test_geometry): a sphere at its known radius,
    a ring, a plane and a rigid transform."""
    rng = np.random.default_rng(5)
    c = np.array([0.4, -0.1, 0.2])
    d = rng.normal(size=(30, 3))
    d[:, 2] = np.abs(d[:, 2])
    x = c + 0.015 * d / np.linalg.norm(d, axis=1)[:, None]
    assert_close(geo.initial_state("sphere", x, 0.015), np.r_[c, 0.015], atol=1e-12)
    u = np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0])
    e1, e2 = perpendicular_basis(u)
    a = rng.uniform(0, 2 * np.pi, 40)
    x = c + 0.08 * (np.outer(np.cos(a), e1) + np.outer(np.sin(a), e2)) + np.outer(rng.uniform(-0.01, 0.01, 40), u)
    s = geo.initial_state("ring", x, 0.08)
    assert abs(abs(s[3:6] @ u) - 1) < 1e-12 and s[12] == 0.08
    b = np.column_stack([s[3:6], s[6:9], s[9:12]])
    assert_close(b.T @ b, np.eye(3), atol=1e-12)
    plane = c + np.outer(rng.uniform(-1, 1, 10), e1) + np.outer(rng.uniform(-1, 1, 10), e2)
    s = geo.initial_state("plane", plane)
    assert abs(abs(s[0:3] @ u) - 1) < 1e-12 and abs(abs(s[9]) - abs(u @ c)) < 1e-12
    rot = rotation_xyz([0.3, -1.0, 2.0])
    xb = rng.normal(size=(10, 3))
    s = geo.initial_state("reference", xb, None, xb @ rot.T + [1, 2, 3])
    assert_close(s[0:9].reshape(3, 3, order="F"), rot, atol=1e-12)
    assert_close(s[9:12], [1, 2, 3], atol=1e-12)
    # too few points for the fits: a start anyway (the solver and the readers judge the data)
    assert np.all(np.isfinite(geo.initial_state("ring", x[:2], 0.08)))
    assert np.all(np.isfinite(geo.initial_state("sphere", x[:2], 0.015)))


def test_initial_state_is_fitted_once_for_the_same_centres_and_given_as_a_new_array(monkeypatch):
    """The starting state of a sphere from the same centres is the fit's, computed once (the loop starts its many
    fits of one campaign from the same centres); changing the array returned changes nothing kept."""
    from arm_model import geometry
    rng = np.random.default_rng(3)
    u = rng.normal(size=(10, 3))
    x = np.array([0.3, 0.1, 0.2]) + 0.0125 * u / np.linalg.norm(u, axis=1)[:, None]
    fits = []
    real = geometry.fit_sphere
    monkeypatch.setattr(geometry, "fit_sphere", lambda *a: fits.append(1) or real(*a))
    first = geo.initial_state("sphere", x.copy(), 0.0125)
    first[:] = 0.0
    second = geo.initial_state("sphere", x.copy(), 0.0125)
    assert len(fits) == 1
    np.testing.assert_array_equal(second, np.r_[real(x, 0.0125).centre, 0.0125])
    geo.initial_state("sphere", x + 1e-9, 0.0125)
    assert len(fits) == 2
