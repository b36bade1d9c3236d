"""Diameter uncertainty of a fitted cylinder from point covariances: hand-derived cases and a Monte Carlo
of the fit itself (independent of the linearisation)."""
import numpy as np
import pytest

from arm_model.feature_uncertainty import diameter_sensitivity, diameter_uncertainty
from arm_model.geometry import fit_cylinder


def ring_points(n_per_row=8, rows=(-0.01, 0.01), r=0.025, rot=None):
    a = np.arange(n_per_row) * 2 * np.pi / n_per_row
    p = np.concatenate([np.column_stack([r * np.cos(a), r * np.sin(a), np.full(n_per_row, h)]) for h in rows])
    if rot is not None:
        p = p @ rot.T
    return p + np.array([0.3, -0.2, 0.1])


def test_isotropic_independent_noise_gives_2_sigma_over_sqrt_n():
    # hand-derived: points symmetric in angle and height, isotropic independent noise sigma per axis:
    # the radius is the mean radial distance to first order, var(R) = sigma^2 / N, u(D) = 2 sigma / sqrt(N)
    p = ring_points(8, (-0.01, 0.01))
    cyl = fit_cylinder(p)
    sigma = 3e-6
    cov = np.broadcast_to(np.eye(3) * sigma ** 2, (len(p), 3, 3))
    u = diameter_uncertainty(diameter_sensitivity(p, cyl), cov)
    assert u.u == pytest.approx(2 * sigma / np.sqrt(len(p)), rel=1e-9)


def test_shared_radial_error_does_not_average_out():
    # every point moved radially outward by the same error delta: D changes by 2 delta exactly,
    # while the naive sum of independent variances gives 2 delta / sqrt(N)
    p = ring_points(6, (-0.01, 0.0, 0.01))
    cyl = fit_cylinder(p)
    delta = 5e-6
    radial = cyl.radial  # (N, 3) unit, outward
    sysr = (delta * radial)[:, None, :]
    cov = np.einsum("nri,nrj->nij", sysr, sysr)
    u = diameter_uncertainty(diameter_sensitivity(p, cyl), cov, sysr)
    assert u.u == pytest.approx(2 * delta, rel=1e-9)
    assert u.parameters == pytest.approx(2 * delta, rel=1e-9) and u.independent == pytest.approx(0, abs=1e-12)
    assert u.if_independent == pytest.approx(2 * delta / np.sqrt(len(p)), rel=1e-9)


def test_against_monte_carlo_of_the_fit():
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    p = ring_points(7, (-0.012, 0.004, 0.011), rot=q)
    p = p + rng.normal(0, 2e-6, p.shape)   # an imperfect ring, points at uneven angles after noise
    n = len(p)
    cyl = fit_cylinder(p)
    # per point: a random independent covariance; shared: 4 random factor rows (N, 4, 3)
    m = rng.standard_normal((n, 3, 3)) * 2e-6
    indep = np.einsum("nij,nkj->nik", m, m)
    sysr = rng.standard_normal((n, 4, 3)) * 1e-6 + rng.standard_normal((1, 4, 3)) * 2e-6
    cov = indep + np.einsum("nri,nrj->nij", sysr, sysr)
    u = diameter_uncertainty(diameter_sensitivity(p, cyl), cov, sysr, n_parameters=2)
    d = []
    for _ in range(3000):
        e = np.einsum("nij,nj->ni", m, rng.standard_normal((n, 3)))
        e += np.einsum("nri,r->ni", sysr, rng.standard_normal(4))
        d.append(fit_cylinder(p + e, cyl.axis).diameter)
    u_mc = float(np.std(d, ddof=1))
    print(f"linear {u.u * 1e6:.3f} um, Monte Carlo {u_mc * 1e6:.3f} um, naive {u.if_independent * 1e6:.3f} um")
    assert u.u == pytest.approx(u_mc, rel=0.1)
    assert u.u ** 2 == pytest.approx(u.independent ** 2 + u.parameters ** 2 + u.compliance ** 2, rel=1e-12)
