"""The one geometry module (arm_model.geometry): cylinder, circle, sphere and plane fits on exact synthetic
shapes in any placement, noisy partial arcs against an independent reference fit, known answers, the
standard uncertainties against Monte Carlo, ball compensation, rotations against hand-written matrices,
and the failures that must raise."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from arm_model import NumericalError
from arm_model.geometry import (
    ball_centre_radius,
    feature_diameter,
    fit_circle_2d,
    fit_cylinder,
    fit_plane,
    fit_ring_axis,
    fit_row_circles,
    fit_sphere,
    frame_along,
    kabsch,
    kasa_circle,
    perpendicular_basis,
    random_rotation,
    ring_fit,
    rotation_xyz,
    rpy_from_matrix,
    smallest_enclosing_sphere,
    split_rows,
)
from conftest import assert_close


def cylinder_points(radius, heights, per_row, arc=2 * np.pi, start=0.0, jitter=None, rng=None):
    """Points on a cylinder of axis z through the origin (local frame), rows at ``heights``."""
    pts = []
    for h in heights:
        t = start + np.linspace(0, arc, per_row, endpoint=arc < 2 * np.pi - 1e-12)
        if jitter is not None:
            t = t + rng.uniform(-jitter, jitter, per_row)
        pts.append(np.column_stack([radius * np.cos(t), radius * np.sin(t), np.full(per_row, h)]))
    return np.vstack(pts)


def place(p, rot, shift):
    return p @ rot.T + shift


def reference_fit(p):
    """Independent reference: another parameterisation (axis by spherical angles, axis point by its two
    coordinates in the plane normal to the axis through the centroid, radius), finite-difference Jacobian,
    trust-region reflective solver; each principal direction tried as the start, the best kept."""
    c0 = p.mean(axis=0)
    q = p - c0
    _, _, vt = np.linalg.svd(q, full_matrices=False)

    def frame(th, ph):
        a = np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])
        e1 = np.array([math.cos(th) * math.cos(ph), math.cos(th) * math.sin(ph), -math.sin(th)])
        return a, e1, np.cross(a, e1)

    def res(x):
        a, e1, e2 = frame(x[0], x[1])
        d = q - (x[2] * e1 + x[3] * e2)
        return np.linalg.norm(np.cross(d, a), axis=1) - x[4]

    best = None
    for a0 in vt:
        th, ph = math.acos(np.clip(a0[2], -1, 1)), math.atan2(a0[1], a0[0])
        r0 = float(np.mean(np.linalg.norm(np.cross(q, a0), axis=1)))
        sol = least_squares(res, [th, ph, 0.0, 0.0, r0], method="trf", x_scale="jac",
                            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=5000)
        if best is None or sol.cost < best.cost:
            best = sol
    a, _, _ = frame(best.x[0], best.x[1])
    return abs(best.x[4]), a

@settings(max_examples=25, deadline=None)
@given(rotvec=st.lists(st.floats(-3.1, 3.1), min_size=3, max_size=3),
       shift=st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3),
       radius=st.floats(0.005, 0.5), spacing=st.floats(0.002, 0.05))
def test_exact_cylinder_any_axis_any_placement(rotvec, shift, radius, spacing):
    local = cylinder_points(radius, [-spacing, 0.0, spacing], 12, start=0.3)
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    p = place(local, rot, np.array(shift))
    fit = fit_cylinder(p)
    assert_close(fit.radius, radius, atol=1e-12 + 1e-10 * radius)
    assert_close(abs(fit.axis @ rot[:, 2]), 1.0, atol=1e-10)
    assert np.max(np.abs(fit.residuals)) < 1e-12 + 1e-10 * radius
    # the axis passes through the placed origin of the local frame
    d = np.array(shift) - fit.point
    assert np.linalg.norm(d - (d @ fit.axis) * fit.axis) < 1e-12 + 1e-9 * radius
    # residuals sum to zero (radius is a free parameter of the least squares)
    assert abs(fit.residuals.sum()) < 1e-12


@settings(max_examples=15, deadline=None)
@given(rotvec=st.lists(st.floats(-3.1, 3.1), min_size=3, max_size=3),
       shift=st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3), seed=st.integers(0, 10_000))
def test_noisy_fit_does_not_depend_on_placement(rotvec, shift, seed):
    rng = np.random.default_rng(seed)
    local = cylinder_points(0.0855, [-0.01, 0.0, 0.01], 24, jitter=0.05, rng=rng)
    local = local + rng.normal(0, 5e-6, local.shape)
    a = fit_cylinder(local)
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    b = fit_cylinder(place(local, rot, np.array(shift)))
    assert abs(a.radius - b.radius) < 1e-11
    assert abs(a.form_error - b.form_error) < 1e-11
    assert_close(b.residuals, a.residuals, atol=1e-11)
    assert_close(abs(b.axis @ (rot @ a.axis)), 1.0, atol=1e-10)


@pytest.mark.parametrize("arc_deg,rows", [(360, 3), (200, 3), (120, 2), (90, 4)])
def test_noisy_partial_arcs_match_independent_reference(arc_deg, rows):
    rng = np.random.default_rng(arc_deg + rows)
    local = cylinder_points(0.05, np.linspace(-0.03, 0.03, rows), 15, arc=np.radians(arc_deg), start=0.7,
                            jitter=0.02, rng=rng)
    local = local + rng.normal(0, 2e-5, local.shape)
    rot = Rotation.from_rotvec([0.3, -1.1, 0.4]).as_matrix()
    p = place(local, rot, np.array([0.4, -0.2, 0.9]))
    fit = fit_cylinder(p)
    r_ref, a_ref = reference_fit(p)
    assert abs(fit.radius - r_ref) < 1e-8, (fit.radius, r_ref)        # 10 nm on a 50 mm radius
    assert abs(abs(fit.axis @ a_ref) - 1) < 1e-10
    # and both lie close to the truth within what the noise allows
    assert abs(fit.radius - 0.05) < 2e-3 * (360 / arc_deg) ** 2


def test_ring_known_answer_ball_compensation_and_point_errors():
    ball = 0.004
    D = 0.174996
    local = cylinder_points((D - ball) / 2 + 10e-6, [-0.008, 0.0, 0.008], 24)      # 20 um too large
    rot = Rotation.from_rotvec([0.2, 0.1, 0.0]).as_matrix()
    ring = ring_fit(place(local, rot, np.array([0.5, 0.1, 0.05])), ball, D)
    assert_close(ring.diameter, D + 20e-6, atol=1e-12)
    assert_close(ring.diameter_error, 20e-6, atol=1e-12)
    assert_close(ring.point_errors, np.full(72, 10e-6), atol=1e-12)
    assert ring.form_error < 1e-12
    assert np.all((ring.angles_deg >= 0) & (ring.angles_deg < 360))
    # without a reference the point errors are the residuals
    free = ring_fit(place(local, rot, np.zeros(3)), ball)
    assert free.diameter_error is None
    assert_close(free.point_errors, free.cylinder.residuals, atol=1e-15)


def test_form_error_and_angles_of_a_known_lobe():
    # a 3-lobed radius r(t) = R + e cos(3t): form error 2e (max - min) to first order of a LS fit
    R, e = 0.08, 5e-6
    t = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    rows = [np.column_stack([(R + e * np.cos(3 * t)) * np.cos(t), (R + e * np.cos(3 * t)) * np.sin(t),
                             np.full(72, h)]) for h in (-0.01, 0.01)]
    fit = fit_cylinder(np.vstack(rows))
    assert_close(fit.form_error, 2 * e, atol=1e-9)
    assert_close(fit.radius, R, atol=1e-10)
    # angles compared on the circle: a point at 0 may come out at 2 pi - 1e-16 (the [0, 2 pi) wrap)
    assert np.abs(np.angle(np.exp(1j * (fit.angles[:72] - t)))).max() < np.radians(1e-6)


def test_circles_per_row():
    local = cylinder_points(0.06, [-0.01, 0.0, 0.01], 20, start=0.1)
    local[20:40, :2] *= (0.06 + 3e-6) / 0.06                    # middle row 6 um larger in diameter
    rot = Rotation.from_rotvec([1.0, 0.5, -0.3]).as_matrix()
    p = place(local, rot, np.array([1.0, 2.0, 3.0]))
    cyl = fit_cylinder(p)
    circles = fit_row_circles(p, cyl)
    assert len(circles) == 3
    assert_close([c.radius for c in circles], [0.06, 0.06 + 3e-6, 0.06], atol=1e-10)
    assert_close([c.height for c in circles], [-0.01, 0.0, 0.01], atol=1e-9)   # lowest row first
    for c in circles:
        assert c.form_error < 1e-11
        assert_close(c.centre_3d - np.array([1.0, 2.0, 3.0]), c.height * cyl.axis, atol=1e-9)
    # explicit labels and an explicit count give the same rows
    assert [c.radius for c in fit_row_circles(p, cyl, rows=3)] == [c.radius for c in circles]
    labels = np.repeat([2, 0, 1], 20)
    assert_close(sorted(c.radius for c in fit_row_circles(p, cyl, rows=labels)), sorted(c.radius for c in circles),
                 atol=1e-14)


def test_split_rows():
    h = np.r_[np.random.default_rng(0).uniform(-1e-3, 1e-3, 10), 0.015 + np.zeros(5), 0.03 + np.zeros(5)]
    assert len(set(split_rows(h).tolist())) == 3
    assert set(split_rows(np.zeros(10)).tolist()) == {0}
    two = split_rows(np.r_[0.0, 0.1, 0.2, 0.9, 1.0, 1.05], rows=2)
    assert two.tolist() == [0, 0, 0, 1, 1, 1]
    # rows of fewer than 3 points are not rows: one row
    assert set(split_rows(np.r_[0.0, 0.001, 1.0]).tolist()) == {0}


def test_circle_2d_known_answer_and_kasa():
    t = np.linspace(0.3, 1.5, 9)
    xy = np.column_stack([2 + 0.5 * np.cos(t), -1 + 0.5 * np.sin(t)])
    fit = fit_circle_2d(xy)
    assert_close(fit.centre, [2, -1], atol=1e-12)
    assert_close(fit.radius, 0.5, atol=1e-12)
    c, r = kasa_circle(xy)
    assert_close(c, [2, -1], atol=1e-9)
    assert_close(r, 0.5, atol=1e-9)


def test_failures_raise():
    # one plane of points: the axis is not determined
    flat = cylinder_points(0.05, [0.0], 30)
    with pytest.raises(NumericalError, match="rank|not determine"):
        fit_cylinder(flat)
    with pytest.raises(NumericalError):
        fit_cylinder(np.zeros((10, 3)))
    with pytest.raises(NumericalError, match="at least 5"):
        fit_cylinder(np.random.default_rng(0).normal(size=(4, 3)))
    line = np.column_stack([np.linspace(0, 1, 10), np.zeros(10), np.zeros(10)])
    with pytest.raises(NumericalError):
        fit_cylinder(line)
    with pytest.raises(NumericalError, match="collinear"):
        fit_circle_2d(np.column_stack([np.linspace(0, 1, 5), np.zeros(5)]))


def test_ring_rows_are_ball_compensated():
    ball = 0.004
    local = cylinder_points(0.0855, [-0.008, 0.0, 0.008], 24)
    ring = ring_fit(local, ball, 0.175)
    rows = ring.rows()
    assert len(rows) == 3
    assert_close([r["diameter"] for r in rows], [0.175] * 3, atol=1e-12)
    assert_close([r["height"] for r in rows], [-0.008, 0.0, 0.008], atol=1e-12)


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@settings(max_examples=30, deadline=None)
@given(w=st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3))
def test_rotation_xyz_is_rz_ry_rx(w):
    """Against the elementary rotations written out by hand."""
    assert_close(rotation_xyz(w), _rz(w[2]) @ _ry(w[1]) @ _rx(w[0]), atol=1e-15)


def test_rpy_from_matrix_inverts_rotation_xyz_including_gimbal_lock():
    """Random rotations and pitch +-90 degrees (yaw then 0), back through the hand-written Rz Ry Rx."""
    rng = np.random.default_rng(2)
    mats = list(Rotation.random(200, random_state=3).as_matrix())
    mats += [_rz(y) @ _ry(s * np.pi / 2) @ _rx(r)
             for r, s, y in zip(rng.uniform(-3, 3, 20), rng.choice([-1, 1], 20), rng.uniform(-3, 3, 20), strict=True)]
    for R in mats:
        r, p, y = rpy_from_matrix(R)
        assert_close(_rz(y) @ _ry(p) @ _rx(r), R, atol=1e-12)
        assert abs(p) <= np.pi / 2 + 1e-12
    assert rpy_from_matrix(_ry(np.pi / 2) @ _rx(0.3))[2] == 0.0


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("v", [(1.0, 2.0, 3.0), (1.0, 0.0, 0.0), (0.0, 0.0, -2.0), (0.0, 1e-3, 1.0), (0.0, 0.0, 0.0)])
def test_frame_along_puts_the_axis_along_the_vector(axis, v):
    r = frame_along(v, axis)
    assert_close(r.T @ r, np.eye(3), atol=1e-15)
    assert_close(np.linalg.det(r), 1.0, atol=1e-15)
    want = np.eye(3)[axis] if not any(v) else np.array(v) / np.linalg.norm(v)
    assert_close(r[:, axis], want, atol=1e-15)


def test_random_rotation_is_the_quaternion_of_four_normals():
    """The same draws as the hand-written unit quaternion (w, x, y, z) it replaced, so simulated
    campaigns keep their seeds; and a proper rotation."""
    for seed in range(5):
        w, x, y, z = (q := np.random.default_rng(seed).normal(size=4)) / np.linalg.norm(q)
        hand = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        rot = random_rotation(np.random.default_rng(seed))
        assert_close(rot, hand, atol=1e-15)
        assert_close(rot.T @ rot, np.eye(3), atol=1e-15)


@settings(max_examples=30, deadline=None)
@given(u=st.lists(st.floats(-1, 1), min_size=3, max_size=3).filter(lambda v: np.linalg.norm(v) > 0.1))
def test_perpendicular_basis_is_right_handed(u):
    u = np.array(u) / np.linalg.norm(u)
    e1, e2 = perpendicular_basis(u)
    b = np.column_stack([e1, e2, u])
    assert_close(b.T @ b, np.eye(3), atol=1e-15)
    assert_close(np.linalg.det(b), 1.0, atol=1e-15)


def test_kabsch_recovers_a_rigid_transform():
    rng = np.random.default_rng(5)
    rot = _rz(2.0) @ _ry(-1.0) @ _rx(0.3)
    xb = rng.normal(size=(10, 3))
    r, t = kabsch(xb, xb @ rot.T + [1, 2, 3])
    assert_close(r, rot, atol=1e-12)
    assert_close(t, [1, 2, 3], atol=1e-12)


def _cap(rng, n, centre, radius):
    d = rng.normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2])
    return centre + radius * d / np.linalg.norm(d, axis=1)[:, None]


def test_sphere_exact_free_and_known_radius():
    rng = np.random.default_rng(5)
    c = np.array([0.4, -0.1, 0.2])
    x = _cap(rng, 30, c, 0.015)
    for radius in (None, 0.015):
        fit = fit_sphere(x, radius)
        assert_close(fit.centre, c, atol=1e-12)
        assert_close(fit.radius, 0.015, atol=1e-12)
        assert np.abs(fit.residuals).max() < 1e-12
    # a small cap (10 degrees) with 1 um noise: the known radius keeps the centre within its uncertainty,
    # which is far smaller than the free fit's
    d = np.column_stack([np.zeros(40), np.zeros(40), np.ones(40)]) + rng.uniform(-0.17, 0.17, (40, 3)) * [1, 1, 0]
    x = c + 0.0125 * d / np.linalg.norm(d, axis=1)[:, None] + rng.normal(0, 1e-6, (40, 3))
    known, free = fit_sphere(x, 0.0125), fit_sphere(x)
    assert np.linalg.norm(known.centre - c) < 4 * np.linalg.norm(known.u_centre)
    assert np.linalg.norm(known.u_centre) < 0.2 * np.linalg.norm(free.u_centre)


def test_sphere_uncertainty_matches_monte_carlo():
    """u_radius and u_centre from one fit agree with the spread of the fits of 300 noisy repeats
    (to the 15 % a 300-sample standard deviation allows, with margin)."""
    rng = np.random.default_rng(8)
    c, r, sigma = np.array([0.1, 0.2, 0.3]), 0.0125, 2e-6
    base = _cap(rng, 25, c, r)
    fits = [fit_sphere(base + rng.normal(0, sigma, base.shape)) for _ in range(300)]
    mc_r = np.std([f.radius for f in fits], ddof=1)
    mc_c = np.std([f.centre for f in fits], axis=0, ddof=1)
    u_r = np.median([f.u_radius for f in fits])
    u_c = np.median([f.u_centre for f in fits], axis=0)
    assert abs(u_r / mc_r - 1) < 0.15
    assert np.all(np.abs(u_c / mc_c - 1) < 0.15)


def test_cylinder_and_circle_uncertainty_matches_monte_carlo():
    rng = np.random.default_rng(9)
    local = cylinder_points(0.0855, [-0.01, 0.0, 0.01], 8)
    sigma = 3e-6
    fits = [fit_cylinder(local + rng.normal(0, sigma, local.shape)) for _ in range(200)]
    mc = np.std([f.radius for f in fits], ddof=1)
    assert abs(np.median([f.u_radius for f in fits]) / mc - 1) < 0.2
    xy = local[:8, :2]
    circles = [fit_circle_2d(xy + rng.normal(0, sigma, xy.shape)) for _ in range(300)]
    mc = np.std([f.radius for f in circles], ddof=1)
    assert abs(np.median([f.u_radius for f in circles]) / mc - 1) < 0.2
    # sqrt(2 / N) sigma / ... : the closed form for a full circle of N equally spaced points is sigma / sqrt(N)
    assert abs(np.median([f.u_radius for f in circles]) / (sigma / math.sqrt(8)) - 1) < 0.2


def test_plane_fit_and_flatness():
    n = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    e1, e2 = perpendicular_basis(n)
    g = np.linspace(-0.1, 0.1, 5)
    uv = np.array([(u, v) for u in g for v in g])
    # a bow orthogonal to 1, u and v on this symmetric grid: the least-squares plane is the true one
    h = 1e-4 * (uv[:, 0] ** 2 - np.mean(uv[:, 0] ** 2))
    p = np.array([0.3, 0.1, 0.2]) + uv[:, :1] * e1 + uv[:, 1:] * e2 + h[:, None] * n
    fit = fit_plane(p)
    assert abs(abs(fit.normal @ n) - 1) < 1e-12
    assert_close(np.sign(fit.normal @ n) * fit.residuals, h, atol=1e-15)
    assert_close(fit.form_error, np.ptp(h), atol=1e-15)
    assert_close(fit.offset, fit.normal @ p.mean(axis=0), atol=1e-15)
    with pytest.raises(NumericalError, match="collinear"):
        fit_plane(np.outer(np.linspace(0, 1, 5), n))
    with pytest.raises(NumericalError, match="need at least 3"):
        fit_plane(p[:2])


def test_sphere_failures_raise():
    with pytest.raises(NumericalError, match="one plane"):
        fit_sphere(cylinder_points(0.05, [0.0], 12))
    with pytest.raises(NumericalError, match="need at least 4"):
        fit_sphere(np.eye(3))


def test_ring_axis_short_long_and_one_row():
    """A short ring and a long cylinder (the axis either way of the spread), and a ring probed in one plane
    (no tilt information: the plane's normal)."""
    rng = np.random.default_rng(5)
    c = np.array([0.4, -0.1, 0.2])
    u = np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0])
    e1, e2 = perpendicular_basis(u)
    for height in (0.01, 0.5, 0.0):
        a = rng.uniform(0, 2 * np.pi, 40)
        h = rng.uniform(-height, height, 40)
        x = c + 0.08 * (np.outer(np.cos(a), e1) + np.outer(np.sin(a), e2)) + np.outer(h, u)
        p0, u0, r = fit_ring_axis(x)
        assert abs(abs(u0 @ u) - 1) < 1e-12
        v = p0 - c
        assert np.linalg.norm(v - (v @ u) * u) < 1e-9
        assert_close(r, 0.08, atol=1e-12)


def test_ball_compensation_round_trip():
    assert_close(ball_centre_radius("sphere", 0.025, 0.004), 0.0145, atol=1e-15)
    assert_close(ball_centre_radius("ring", 0.175, 0.004), 0.0855, atol=1e-15)
    for kind in ("sphere", "ring", "cylinder"):
        assert_close(feature_diameter(kind, ball_centre_radius(kind, 0.05, 0.003), 0.003), 0.05, atol=1e-15)
    with pytest.raises(ValueError):
        ball_centre_radius("plane", 0.05, 0.003)


def test_smallest_enclosing_sphere_by_hand():
    rng = np.random.default_rng(5)
    # a regular tetrahedron's vertices plus points inside: the circumsphere, radius a sqrt(6) / 4
    a = 2.0
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) * a / (2 * math.sqrt(2))
    inside = rng.uniform(-0.2, 0.2, (20, 3))
    pts = np.vstack([inside[:10], tet, inside[10:]]) * 1e-5 + [0.4, -0.1, 0.3]
    c, r = smallest_enclosing_sphere(pts)
    assert_close(r, a * math.sqrt(6) / 4 * 1e-5, atol=1e-15)          # rounding of the 0.4 m offset: 1e-16
    assert_close(c, [0.4, -0.1, 0.3], atol=1e-15)
    # every point inside, and no smaller sphere: a check of a second kind, the smallest radius t by a general
    # constrained solver (SLSQP: minimise t subject to |p_i - x| <= t, in units of 10 um; 12 iterations, to 1e-12;
    # the Nelder-Mead search it replaces ran out of its 20000 iterations 1.6e-7 above the optimum, 1.8 s of CPU)
    assert np.all(np.linalg.norm(pts - c, axis=1) <= r * (1 + 1e-9))
    from scipy.optimize import minimize
    scaled = pts * 1e5
    start = np.append(scaled.mean(axis=0), np.max(np.linalg.norm(scaled - scaled.mean(axis=0), axis=1)))
    sol = minimize(lambda z: z[3], start, method="SLSQP", options={"ftol": 1e-14, "maxiter": 500},
                   constraints=[{"type": "ineq", "fun": lambda z: z[3] ** 2 - np.sum((scaled - z[:3]) ** 2, axis=1)}])
    assert abs(r * 1e5 - sol.fun) < 1e-9, (r * 1e5, sol.fun, sol.message)
    assert_close(sol.x[:3] * 1e-5, c, atol=1e-12)
