"""The kinematic chain, written once for every backend.

The functions here take scalars, numpy arrays (one entry a point, for the batch path) or CasADi SX
(for calibration) alike: they only use ``+ - * /`` and the ``sin``/``cos`` of the ``ops`` namespace
given to them. The batch evaluator (:mod:`arm_model.kinematics`) and the CasADi evaluator
(:mod:`arm_model.casadi_model`) both call them; Pinocchio (:mod:`arm_model.pinocchio_model`) is an
independent third evaluator built from the URDF, and the tests hold all three to 1e-12 m.

Geometry (all SI):

* ``rows``: one (theta_offset [rad], d [m], a [m], alpha [rad]) per joint, base first (for URDF
  chains: the joint origin (x, y, z [m], roll, pitch, yaw [rad]) and a constant unit axis).
  Standard DH: ``T_{i-1,i} = Rz(theta_offset + q) Tz(d) Tx(a) Rx(alpha)``;
  modified DH: ``T_{i-1,i} = Rx(alpha) Tx(a) Rz(theta_offset + q) Tz(d)``.
* ``p_last``: the probe ball centre (x, y, z) [m] in the last joint frame with a rigid stylus.
* ``compliance``: (c_x, c_y, c_z) [m/N], the ball's compliance along probe x, y, z.

The probe's compliance is a virtual elastic joint in the chain: the stylus hangs from a hinge at
``(x, y, 0)`` of the last joint frame (the flange plane), of lever ``L = z``. Two revolute DOF bend it
(``theta_y`` about probe y, then ``theta_x`` about probe x) and one prismatic DOF ``s`` shortens it
along probe z. A wrench ``w = (F, M)`` at the ball (probe frame, force first [N], then torque [N m])
sets the joint displacement by statics, ``q_e = K^-1 J_e^T w`` with ``J_e`` the ball's Jacobian with
respect to ``q_e`` at ``q_e = 0`` (probe frame) and ``K = diag(L^2/c_x, L^2/c_y, 1/c_z)``:

    theta_y = c_x (L F_x + M_y) / L^2,   theta_x = c_y (M_x - L F_y) / L^2,   s = c_z F_z

and the ball centre is the forward kinematics of ``(q, q_e)``: for small forces it moves by about
``diag(c) F``, for every direction of F.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

__all__ = ["NUMPY_OPS", "elastic_displacement", "ball_in_last_frame", "chain_point",
           "ball_centre_expr"]

NUMPY_OPS = SimpleNamespace(sin=np.sin, cos=np.cos)


def _is_const(x) -> bool:
    return isinstance(x, (int, float))


def _cos_sin(angle, ops):
    if _is_const(angle):
        return math.cos(angle), math.sin(angle)
    return ops.cos(angle), ops.sin(angle)


def elastic_displacement(p_last, compliance, wrench):
    """Virtual elastic joint displacement ``(theta_y [rad], theta_x [rad], s [m])`` under ``wrench``.

    ``wrench`` is a sequence of 3 (force) or 6 (force, torque) components, each a scalar, an array
    or an SX; a missing torque is zero.
    """
    lever = p_last[2]
    fx, fy, fz = wrench[0], wrench[1], wrench[2]
    mx, my = (wrench[3], wrench[4]) if len(wrench) >= 6 else (0.0, 0.0)
    cx, cy, cz = compliance
    theta_y = cx * (lever * fx + my) / (lever * lever)
    theta_x = cy * (mx - lever * fy) / (lever * lever)
    s = cz * fz
    return theta_y, theta_x, s


def ball_in_last_frame(p_last, q_e, ops=NUMPY_OPS):
    """Ball centre (x, y, z) [m] in the last joint frame for elastic displacement ``q_e``.

    Forward kinematics of the virtual joints: hinge at (x, y, 0), then Ry(theta_y) Rx(theta_x)
    Tz(L + s) with L = z of ``p_last``.
    """
    theta_y, theta_x, s = q_e
    cy_, sy_ = _cos_sin(theta_y, ops)
    cx_, sx_ = _cos_sin(theta_x, ops)
    length = p_last[2] + s
    return (p_last[0] + length * cx_ * sy_,
            p_last[1] - length * sx_,
            length * cx_ * cy_)


def _rotate_axis(axis, c, s, x, y, z):
    """Rodrigues: rotate (x, y, z) by the angle (cos c, sin s) about the constant unit ``axis``."""
    kx, ky, kz = axis
    if (kx, ky, kz) == (0.0, 0.0, 1.0):
        return c * x - s * y, s * x + c * y, z
    dot = (kx * x + ky * y + kz * z) * (1 - c)
    return (x * c + (ky * z - kz * y) * s + kx * dot,
            y * c + (kz * x - kx * z) * s + ky * dot,
            z * c + (kx * y - ky * x) * s + kz * dot)


def chain_point(convention: str, rows, q, point, ops=NUMPY_OPS, axes=None):
    """Map ``point`` (x, y, z) given in the last joint frame to the base frame.

    ``rows[i]`` = (theta_offset, d, a, alpha) of joint i for DH/MDH, or (x, y, z, roll, pitch, yaw)
    of its URDF origin (then ``axes[i]`` is its unit axis); ``q[i]`` its angle [rad]. Works from the
    last joint inwards, carrying only the point (three numbers a point), never a matrix.
    """
    x, y, z = point
    for i in range(len(rows) - 1, -1, -1):
        if convention == "urdf":    # T_origin(xyz, Rz(yaw) Ry(pitch) Rx(roll)) R(axis, q) p
            ox, oy, oz, roll, pitch, yaw = rows[i]
            cq, sq = _cos_sin(q[i], ops)
            x, y, z = _rotate_axis(axes[i], cq, sq, x, y, z)
            cr, sr = _cos_sin(roll, ops)
            y, z = cr * y - sr * z, sr * y + cr * z
            cp, sp = _cos_sin(pitch, ops)
            x, z = cp * x + sp * z, -sp * x + cp * z
            cw, sw = _cos_sin(yaw, ops)
            x, y = cw * x - sw * y, sw * x + cw * y
            x, y, z = x + ox, y + oy, z + oz
            continue
        theta_offset, d, a, alpha = rows[i]
        ca, sa = _cos_sin(alpha, ops)
        ct, st = _cos_sin(theta_offset + q[i], ops)
        if convention == "dh":     # Rz(theta) Tz(d) Tx(a) Rx(alpha) p
            y, z = ca * y - sa * z, sa * y + ca * z
            x = x + a
            z = z + d
            x, y = ct * x - st * y, st * x + ct * y
        elif convention == "mdh":  # Rx(alpha) Tx(a) Rz(theta) Tz(d) p
            z = z + d
            x, y = ct * x - st * y, st * x + ct * y
            x = x + a
            y, z = ca * y - sa * z, sa * y + ca * z
        else:
            raise ValueError(f"unknown convention {convention!r}")
    return x, y, z


def ball_centre_expr(convention: str, rows, p_last, compliance, q, wrench=None, ops=NUMPY_OPS, axes=None):
    """Deflection-aware ball centre (x, y, z) [m] in the base frame: FK of (q, q_e(wrench))."""
    if wrench is None:
        q_e = (0.0, 0.0, 0.0)
    else:
        q_e = elastic_displacement(p_last, compliance, wrench)
    return chain_point(convention, rows, q, ball_in_last_frame(p_last, q_e, ops), ops, axes)
