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
* ``rotation``: R_last_probe, the probe frame's orientation in the last joint frame (3x3 constants),
  None for a probe frame parallel to the last joint frame; the probe z axis runs along the stylus.
* ``lever``: the stylus length L [m] from the bending hinge to the ball, or None for the ball's
  coordinate along probe z seen from the last joint origin (``z`` of ``p_last`` when unrotated).
* ``compliance``: (c_x, c_y, c_z) [m/N], the ball's compliance along probe x, y, z.

The probe's compliance is a virtual elastic joint in the chain: the stylus hangs from a hinge at
``p_last - L z_probe`` (for an unrotated probe with the default lever: ``(x, y, 0)`` of the last joint
frame, the flange plane). Two revolute DOF bend it (``theta_y`` about probe y, then ``theta_x`` about
probe x) and one prismatic DOF ``s`` shortens it along probe z. A wrench ``w = (F, M)`` at the ball (probe frame, force first [N], then torque [N m])
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
           "ball_centre_expr", "probe_lever"]

NUMPY_OPS = SimpleNamespace(sin=np.sin, cos=np.cos)


def _is_const(x) -> bool:
    return isinstance(x, (int, float))


def _cos_sin(angle, ops):
    if _is_const(angle):
        return math.cos(angle), math.sin(angle)
    return ops.cos(angle), ops.sin(angle)


def probe_lever(p_last, rotation=None, lever=None):
    """The stylus length L [m]: ``lever`` if given, else the ball's coordinate along probe z seen
    from the last joint origin (``z_probe . p_last``)."""
    if lever is not None:
        return lever
    if rotation is None:
        return p_last[2]
    return rotation[0][2] * p_last[0] + rotation[1][2] * p_last[1] + rotation[2][2] * p_last[2]


def elastic_displacement(p_last, compliance, wrench, lever=None):
    """Virtual elastic joint displacement ``(theta_y [rad], theta_x [rad], s [m])`` under ``wrench``.

    ``wrench`` is a sequence of 3 (force) or 6 (force, torque) components in the probe frame, each a
    scalar, an array or an SX; a missing torque is zero. ``lever``: the stylus length L (default z of
    ``p_last``, see :func:`probe_lever`).
    """
    lever = p_last[2] if lever is None else lever
    fx, fy, fz = wrench[0], wrench[1], wrench[2]
    mx, my = (wrench[3], wrench[4]) if len(wrench) >= 6 else (0.0, 0.0)
    cx, cy, cz = compliance
    theta_y = cx * (lever * fx + my) / (lever * lever)
    theta_x = cy * (mx - lever * fy) / (lever * lever)
    s = cz * fz
    return theta_y, theta_x, s


def ball_in_last_frame(p_last, q_e, ops=NUMPY_OPS, rotation=None, lever=None):
    """Ball centre (x, y, z) [m] in the last joint frame for elastic displacement ``q_e``.

    Forward kinematics of the virtual joints: the hinge at ``p_last - L z_probe`` with the probe's
    orientation ``rotation``, then Ry(theta_y) Rx(theta_x) Tz(L + s), L from :func:`probe_lever`.
    """
    theta_y, theta_x, s = q_e
    cy_, sy_ = _cos_sin(theta_y, ops)
    cx_, sx_ = _cos_sin(theta_x, ops)
    if rotation is None and lever is None:
        length = p_last[2] + s
        return (p_last[0] + length * cx_ * sy_,
                p_last[1] - length * sx_,
                length * cx_ * cy_)
    big_l = probe_lever(p_last, rotation, lever)
    length = big_l + s
    u = (length * cx_ * sy_, -length * sx_, length * cx_ * cy_ - big_l)   # ball - p_last, probe frame
    if rotation is None:
        return p_last[0] + u[0], p_last[1] + u[1], p_last[2] + u[2]
    return tuple(p_last[k] + rotation[k][0] * u[0] + rotation[k][1] * u[1] + rotation[k][2] * u[2]
                 for k in range(3))


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


def ball_centre_expr(convention: str, rows, p_last, compliance, q, wrench=None, ops=NUMPY_OPS, axes=None,
                     rotation=None, lever=None):
    """Deflection-aware ball centre (x, y, z) [m] in the base frame: FK of (q, q_e(wrench)).

    ``rotation``, ``lever``: the probe frame (see :class:`arm_model.description.Probe`)."""
    if wrench is None:
        return chain_point(convention, rows, q, tuple(p_last), ops, axes)
    q_e = elastic_displacement(p_last, compliance, wrench, probe_lever(p_last, rotation, lever))
    return chain_point(convention, rows, q, ball_in_last_frame(p_last, q_e, ops, rotation, lever), ops, axes)
