"""The propagation's plan is the state of a :class:`arm_model.uncertainty.Propagator` (a module-wide cache of the
last plan served a covariance changed in place with the plan of its old values), and the covariance's factor keeps
its precision when the parameters' scales differ by decades (m beside rad/(N m)): against exact rational arithmetic.
"""
from __future__ import annotations

import threading
from fractions import Fraction

import numpy as np
import pytest

from arm_model.effects import JointCompliance, ProbeCompliance, ThermalGrowth
from arm_model.model import ArmModel, AuxData
from arm_model.uncertainty import ParameterCovariance, Propagator, default_inputs, propagate


def _case(desc, effects, seed: int):
    """A model, its parameters, a covariance of its free parameters (every one but the probe's compliances), inputs
    and a few points with wrench and torques."""
    model = ArmModel(desc, effects)
    rng = np.random.default_rng(seed)
    spec = model.spec
    free = [i for i, nm in enumerate(spec.names) if not nm.startswith("probe.compliance")]
    scale = np.array([{"m": 1e-4, "rad": 1e-4, "m/N": 1e-6, "1/K": 1e-6, "rad/(N m)": 1e-7}.get(u, 1e-3)
                      for u in spec.units])[free]
    a = rng.normal(size=(len(free), len(free)))
    pc = ParameterCovariance(tuple(spec.names[i] for i in free), a @ a.T / len(free) * np.outer(scale, scale))
    inputs = default_inputs(desc, encoder=np.full(desc.n_joints, 2e-6), torque=0.002, probing=1e-6)
    n, j = 4, desc.n_joints
    q = rng.uniform(-2, 2, (n, j))
    w = np.column_stack([rng.normal(0, 3, (n, 3)), rng.normal(0, 0.05, (n, 3))])
    aux = AuxData(temperature=rng.uniform(18, 26, n), tau_gravity=rng.normal(0, 20, (n, j)),
                  tau_contact=rng.normal(0, 2, (n, j)))
    p = rng.normal(0, 1e-5, spec.size)
    return model, pc, inputs, (p, q, w, aux)


@pytest.fixture(scope="module")
def two(nominal):
    return (_case(nominal, (ProbeCompliance(anisotropic=True), JointCompliance(joints=(1, 2))), 1),
            _case(nominal.with_probe(rpy=(0.1, -0.2, 0.3)), (ThermalGrowth(), ProbeCompliance()), 2))


def _run(case, **kw):
    model, pc, inputs, (p, q, w, aux) = case
    return propagate(model, p, q, w, aux, parameters=pc, inputs=inputs, systematic=True, **kw)


def _same(a, b) -> None:
    np.testing.assert_array_equal(a.cov, b.cov)
    np.testing.assert_array_equal(a.systematic, b.systematic)
    np.testing.assert_array_equal(a.centres, b.centres)


def test_two_models_used_alternately_give_their_own_results(two):
    """Alternately, through ``propagate`` and each model's Propagator, and from four threads at once: every result is
    the one its model gives alone, bit for bit."""
    alone = [_run(c) for c in two]
    assert not np.allclose(alone[0].cov, alone[1].cov)
    own = [Propagator(m, pc, inputs) for m, pc, inputs, _ in two]
    for _ in range(3):
        for k in (0, 1):
            _same(_run(two[k]), alone[k])
            p, q, w, aux = two[k][3]
            _same(own[k](p, q, w, aux, systematic=True), alone[k])
    failures: list = []

    def worker(k: int) -> None:
        try:
            for _ in range(5):
                _same(_run(two[k], threads=1), alone[k])
                _same(own[k](*two[k][3], threads=1, systematic=True), alone[k])
        except AssertionError as exc:       # pragma: no cover - reported below
            failures.append(exc)
    threads = [threading.Thread(target=worker, args=(k % 2,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not failures, failures[0]


def test_a_covariance_changed_in_place_is_propagated_with_its_new_values(two):
    """The module-wide plan was found by the objects' identity: the same ParameterCovariance with its matrix changed
    in place got the factor of its old values (the covariance off by the change)."""
    model, pc, inputs, (p, q, w, aux) = two[0]
    cov = pc.cov.copy()
    before = propagate(model, p, q, w, aux, parameters=pc, inputs=inputs)
    try:
        pc.cov[...] = 4.0 * cov
        after = propagate(model, p, q, w, aux, parameters=pc, inputs=inputs)
    finally:
        pc.cov[...] = cov
    fresh = propagate(model, p, q, w, aux, parameters=ParameterCovariance(pc.names, 4.0 * cov), inputs=inputs)
    np.testing.assert_array_equal(after.cov, fresh.cov)
    ratio = after.contributions["parameters"] / before.contributions["parameters"]
    np.testing.assert_allclose(ratio, 4.0, rtol=1e-12)


def _exact_jcjt(j: np.ndarray, c: np.ndarray) -> np.ndarray:
    """J C J^T of float matrices in exact rational arithmetic, rounded once to float."""
    jf = [[Fraction(x) for x in row] for row in j.tolist()]
    cf = [[Fraction(x) for x in row] for row in c.tolist()]
    k = len(cf)
    jc = [[sum(r[m] * cf[m][b] for m in range(k)) for b in range(k)] for r in jf]
    return np.array([[float(sum(a[m] * b[m] for m in range(k))) for b in jf] for a in jc])


def test_the_factor_keeps_its_precision_over_nine_decades_of_scales():
    """Standard deviations from 1e-12 to 1e-3 (a rad/(N m) compliance beside a length in m), correlated, and a
    Jacobian that makes every parameter count: (J L)(J L)^T against the exact J C J^T, to 1e-13 relative to the
    variances (the raw covariance's eigen-decomposition: 2e-2 on these 30 draws; the scaled one 3e-15)."""
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(30):
        k = 8
        sd = 10.0 ** rng.uniform(-12, -3, k)
        a = rng.normal(size=(k, k + 2))
        r = a @ a.T
        r /= np.sqrt(np.outer(np.diag(r), np.diag(r)))
        c = r * np.outer(sd, sd)
        c = (c + c.T) / 2
        j = rng.normal(size=(3, k)) / sd * 1e-5
        a = j @ ParameterCovariance(tuple(f"p{i}" for i in range(k)), c).factor()
        ref = _exact_jcjt(j, c)
        worst = max(worst, np.abs((a @ a.T - ref) / np.sqrt(np.outer(np.diag(ref), np.diag(ref)))).max())
    assert worst < 1e-13, worst


def test_the_factor_of_a_singular_covariance_and_what_it_refuses():
    """A parameter held exactly (variance 0) and two parameters fully correlated: accepted, L L^T = C; a correlation
    beyond 1 (not positive semi-definite) and a negative variance are refused naming the parameters."""
    sd = np.array([1e-4, 0.0, 2e-9, 3e-9])
    r = np.eye(4)
    r[2, 3] = r[3, 2] = 1.0
    c = r * np.outer(sd, sd)
    lf = ParameterCovariance(("a", "b", "c", "d"), c).factor()
    assert lf.shape == (4, 2)
    assert np.all(np.abs(lf @ lf.T - c) <= 1e-15 * np.outer(sd, sd))
    r[2, 3] = r[3, 2] = 1.01
    with pytest.raises(ValueError, match=r"not positive semi-definite \(an eigenvalue of its correlations is -0.01"
                                         r"\d*, mostly along (c, d|d, c)"):
        ParameterCovariance(("a", "b", "c", "d"), r * np.outer(sd, sd)).factor()
    with pytest.raises(ValueError, match=r"negative variance \(b: -1e-12\)"):
        ParameterCovariance(("a", "b"), np.diag([1.0, -1e-12])).factor()
    # correlations that no covariance has (0.9, 0.9, -0.9) among small parameters beside a large one: the raw
    # eigenvalue, -8e-25, passed the raw check (-1e-9 of the largest, 1e-6); the correlations' -0.8 does not
    r = np.eye(4)
    for i, j, v in ((1, 2, 0.9), (1, 3, 0.9), (2, 3, -0.9)):
        r[i, j] = r[j, i] = v
    sd = np.array([1e-3, 1e-12, 1e-12, 1e-12])
    assert np.linalg.eigvalsh(r * np.outer(sd, sd)).min() > -1e-9 * 1e-6
    with pytest.raises(ValueError, match=r"correlations is -0.8, mostly along [bcd], [bcd], [bcd]\)"):
        ParameterCovariance(("a", "b", "c", "d"), r * np.outer(sd, sd)).factor()
