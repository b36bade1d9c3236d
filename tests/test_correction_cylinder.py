"""Cylinder and circle fits: exact synthetic cylinders in any placement, noisy partial arcs against an
independent reference fit, known answers, and the failures that must raise."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from arm_model import NumericalError
from conftest import assert_close
from correction.cylinder import (fit_circle_2d, fit_cylinder, fit_row_circles, kasa_circle, ring_fit,
                                 split_rows)


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
    assert_close(np.sort(np.degrees(fit.angles[:72])), np.degrees(t), atol=1e-6)


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
