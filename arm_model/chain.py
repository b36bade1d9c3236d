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
  A prismatic joint translates instead: ``q`` [m] is added to ``d`` (DH, MDH) or moves along the
  URDF axis.
* ``joints``: how each row moves (:class:`Joint`: its URDF axis, revolute or prismatic, and the
  encoder column it reads, ``value = multiplier q[column] + offset``, a URDF ``<mimic>``); None for
  revolute DH/MDH rows reading one column each.
* ``p_last``: the probe ball centre (x, y, z) [m] in the last joint frame with a rigid stylus.
* ``rotation``: R_last_probe, the probe frame's orientation in the last joint frame (3x3 constants),
  None for a probe frame parallel to the last joint frame; the probe z axis runs along the stylus.
* ``lever``: the stylus length L [m] from the bending hinge to the ball, or None for the ball's
  coordinate along probe z seen from the last joint origin (``z`` of ``p_last`` when unrotated).
* ``compliance``: (c_x, c_y, c_z) [m/N], the ball's compliance along probe x, y, z.

The probe's compliance is a virtual elastic joint in the chain: the stylus hangs from a hinge at
``p_last - L z_probe`` (for an unrotated probe with the default lever: ``(x, y, 0)`` of the last joint
frame, the flange plane). Two revolute DOF bend it (``theta_y`` about probe y, then ``theta_x`` about
probe x) and one prismatic DOF ``s`` shortens it along probe z. A wrench ``w = (F, M)`` at the ball (probe frame, force
first [N], then torque [N m])
sets the joint displacement by statics, ``q_e = K^-1 J_e^T w`` with ``J_e`` the ball's Jacobian with
respect to ``q_e`` at ``q_e = 0`` (probe frame) and ``K = diag(L^2/c_x, L^2/c_y, 1/c_z)``:

    theta_y = c_x (L F_x + M_y) / L^2,   theta_x = c_y (M_x - L F_y) / L^2,   s = c_z F_z

and the ball centre is the forward kinematics of ``(q, q_e)``: for small forces it moves by about
``diag(c) F``, for every direction of F.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = ["NUMPY_OPS", "FLOAT_OPS", "Joint", "joint_value", "elastic_displacement", "ball_in_last_frame",
           "row_motions", "chain_point", "ball_centre_expr", "probe_lever", "has_stylus", "cross"]

NUMPY_OPS = SimpleNamespace(sin=np.sin, cos=np.cos, sign=np.sign)
#: One point on Python floats (a live point: tens of times cheaper than numpy columns of one value): numpy's own
#: ``sin``, ``cos`` and ``sign`` as Python floats, and every angle that depends on the inputs (a joint value, the
#: stylus's bending) taken through them, never skipped when 0, as the batch takes its columns: the batch's numbers
#: bit for bit (the same IEEE operations in the same order; tests/test_arm_model_evaluators.py).
FLOAT_OPS = SimpleNamespace(sin=lambda x: float(np.sin(x)), cos=lambda x: float(np.cos(x)),
                            sign=lambda x: float(np.sign(x)), floats=True)


def cross(a: Any, b: Any) -> np.ndarray:
    """``np.cross(a, b)`` of 3-vectors along the last axis (broadcast): the same products and differences, so
    the same numbers, without np.cross's axis handling (two to three times its speed on the small stacks of the
    Jacobians and the frames, called hundreds of thousands of times)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out

#: A number of the chain: a float, a numpy array (one entry a point) or a CasADi SX/MX expression.
Scalar = Any
#: A short vector of them: a sequence, or a numpy array whose first axis is the component.
Vector = Sequence[Scalar] | np.ndarray
#: One elementary motion of a row (:func:`row_motions`): kind, axis, amount, row indices, is_joint.
Motion = tuple[str, "int | tuple[float, ...]", Scalar, tuple[int, ...], bool]


@dataclass(frozen=True)
class Joint:
    """How one row of the chain moves (constants, not calibrated).

    ``axis``: the joint's constant unit axis in its own frame (URDF rows), None for DH/MDH (local z);
    ``prismatic``: a translation along the axis [m] instead of a rotation about it [rad]; the row's
    joint value is ``multiplier * q[column] + offset`` (``column``: the encoder column it reads; a URDF
    ``<mimic>`` joint reads its master's column with the URDF's multiplier and offset [rad] or [m]).
    """
    column: int
    axis: tuple[float, float, float] | None = None
    prismatic: bool = False
    multiplier: float = 1.0
    offset: float = 0.0
    #: URDF rows: the origin's own (roll, pitch, yaw) [rad]; the row's angles turn the origin about its own
    #: axes by their difference from these (never singular, unlike roll/pitch/yaw at pitch +-90 deg)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


def joint_value(joints: Sequence[Joint] | None, i: int, q: Vector) -> Scalar:
    """The joint value of row ``i`` from the encoder columns ``q`` (``joints`` None: ``q[i]``)."""
    if joints is None:
        return q[i]
    j = joints[i]
    v = q[j.column]
    if j.multiplier != 1.0:
        v = j.multiplier * v
    if j.offset != 0.0:
        v = v + j.offset
    return v


def _is_const(x: object) -> bool:
    return isinstance(x, (int, float))


def _cos_sin(angle: Scalar, ops: Any) -> tuple[Scalar, Scalar]:
    """cos and sin of an angle that depends on the inputs (:data:`FLOAT_OPS`: always by ``ops``)."""
    if _is_const(angle) and not getattr(ops, "floats", False):
        return math.cos(angle), math.sin(angle)
    return ops.cos(angle), ops.sin(angle)


def probe_lever(p_last: Vector, rotation: Sequence[Sequence[float]] | None = None,
                lever: Scalar | None = None) -> Scalar:
    """The stylus length L [m]: ``lever`` if given, else the ball's coordinate along probe z seen
    from the last joint origin (``z_probe . p_last``)."""
    if lever is not None:
        return lever
    if rotation is None:
        return p_last[2]
    return rotation[0][2] * p_last[0] + rotation[1][2] * p_last[1] + rotation[2][2] * p_last[2]


def elastic_displacement(p_last: Vector, compliance: Vector, wrench: Vector,
                         lever: Scalar | None = None) -> tuple[Scalar, Scalar, Scalar]:
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


def ball_in_last_frame(p_last: Vector, q_e: Vector, ops: Any = NUMPY_OPS,
                       rotation: Sequence[Sequence[float]] | None = None,
                       lever: Scalar | None = None) -> tuple[Scalar, Scalar, Scalar]:
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
    x, y, z = (p_last[k] + rotation[k][0] * u[0] + rotation[k][1] * u[1] + rotation[k][2] * u[2] for k in range(3))
    return x, y, z


def row_motions(convention: str, row: Vector, q: Scalar, joint: Joint | None = None) -> list[Motion]:
    """The one description of each joint convention: the elementary motions of one row of the chain,
    in application order from its parent frame (the chain is their product).

    Each motion is ``(kind, axis, amount, row indices, is_joint)``: kind ``"R"`` (rotation [rad]) or
    ``"T"`` (translation [m]) along a local axis (0, 1, 2 for x, y, z, or a constant unit 3-vector), the
    amount (a value of ``row``, the joint value ``q``, or their sum), the indices of the row values it
    depends on, and whether it depends on ``q``. :func:`chain_point` applies them to a point;
    :mod:`arm_model.jacobian` differentiates them and multiplies them as homogeneous matrices.

    * ``"dh"``:   ``Rz(theta_offset + q) Tz(d) Tx(a) Rx(alpha)``, ``row`` = (theta_offset, d, a, alpha);
      prismatic: ``Rz(theta_offset) Tz(d + q) Tx(a) Rx(alpha)``;
    * ``"mdh"``:  ``Rx(alpha) Tx(a) Rz(theta_offset + q) Tz(d)``, same ``row``; prismatic:
      ``Rx(alpha) Tx(a) Rz(theta_offset) Tz(d + q)``;
    * ``"urdf"``: ``T(x, y, z) Rz(yaw0) Ry(pitch0) Rx(roll0) Rz(yaw - yaw0) Ry(pitch - pitch0) Rx(roll - roll0)
      R(axis, q)`` (prismatic: ``T(axis q)``), ``row`` = (x, y, z, roll, pitch, yaw) of the joint origin,
      ``joint.rpy`` = (roll0, pitch0, yaw0) the origin's own angles (the description's), ``joint.axis`` its
      constant unit axis: an angle error turns the origin about its own axes, three independent directions at
      every orientation (roll, pitch and yaw added to the origin's own turn about one axis at pitch +-90 deg).
      At the description's own angles this is URDF's ``T(x, y, z) Rz(yaw) Ry(pitch) Rx(roll) R(axis, q)``.
    """
    prismatic = joint is not None and joint.prismatic
    if convention in ("dh", "mdh"):
        turn: Motion
        slide: Motion
        if prismatic:
            turn, slide = ("R", 2, row[0], (0,), False), ("T", 2, row[1] + q, (1,), True)
        else:
            turn, slide = ("R", 2, row[0] + q, (0,), True), ("T", 2, row[1], (1,), False)
        if convention == "dh":
            return [turn, slide, ("T", 0, row[2], (2,), False), ("R", 0, row[3], (3,), False)]
        return [("R", 0, row[3], (3,), False), ("T", 0, row[2], (2,), False), turn, slide]
    if convention == "urdf":
        if joint is None or joint.axis is None:
            raise ValueError("a URDF row needs its joint's axis")
        ax = tuple(float(a) for a in joint.axis)
        local: int | tuple[float, ...] = (2 if ax == (0.0, 0.0, 1.0) else 0 if ax == (1.0, 0.0, 0.0)
                                          else 1 if ax == (0.0, 1.0, 0.0) else ax)
        r0, p0, y0 = joint.rpy
        return [("T", 0, row[0], (0,), False), ("T", 1, row[1], (1,), False), ("T", 2, row[2], (2,), False),
                ("R", 2, y0, (), False), ("R", 1, p0, (), False), ("R", 0, r0, (), False),
                ("R", 2, row[5] - y0, (5,), False), ("R", 1, row[4] - p0, (4,), False),
                ("R", 0, row[3] - r0, (3,), False), ("T" if prismatic else "R", local, q, (), True)]
    raise ValueError(f"unknown convention {convention!r}")


def chain_point(convention: str, rows: Sequence[Vector] | np.ndarray, q: Vector, point: Vector,
                ops: Any = NUMPY_OPS, joints: Sequence[Joint] | None = None) -> tuple[Scalar, Scalar, Scalar]:
    """Map ``point`` (x, y, z) given in the last joint frame to the base frame.

    ``rows[i]`` = (theta_offset, d, a, alpha) of joint i for DH/MDH, or (x, y, z, roll, pitch, yaw)
    of its URDF origin; ``joints[i]`` how it moves (:class:`Joint`; None: revolute DH/MDH rows);
    ``q`` the encoder columns [rad] or [m] (:func:`joint_value`). Applies the motions of
    :func:`row_motions` from the last joint inwards, carrying only the point (three numbers a point),
    never a matrix; a constant zero motion is skipped (exact).
    """
    x, y, z = point
    floats = getattr(ops, "floats", False)       # FLOAT_OPS: a joint's amount is an input, as the batch's columns
    for i in range(len(rows) - 1, -1, -1):
        for kind, axis, amount, _, moves in reversed(row_motions(convention, rows[i], joint_value(joints, i, q),
                                                                 None if joints is None else joints[i])):
            const = _is_const(amount) and not (floats and moves)
            if const and amount == 0.0:
                continue
            if kind == "T":
                if axis == 0:
                    x = x + amount
                elif axis == 1:
                    y = y + amount
                elif axis == 2:
                    z = z + amount
                elif isinstance(axis, tuple):
                    x, y, z = x + amount * axis[0], y + amount * axis[1], z + amount * axis[2]
                continue
            c, s = (math.cos(amount), math.sin(amount)) if const else (ops.cos(amount), ops.sin(amount))
            if axis == 2:
                x, y = c * x - s * y, s * x + c * y
            elif axis == 0:
                y, z = c * y - s * z, s * y + c * z
            elif axis == 1:
                x, z = c * x + s * z, c * z - s * x
            elif isinstance(axis, tuple):         # Rodrigues about a constant unit axis
                kx, ky, kz = axis
                dot = (kx * x + ky * y + kz * z) * (1 - c)
                x, y, z = (x * c + (ky * z - kz * y) * s + kx * dot,
                           y * c + (kz * x - kx * z) * s + ky * dot,
                           z * c + (kx * y - ky * x) * s + kz * dot)
    return x, y, z


def ball_centre_expr(convention: str, rows: Sequence[Vector] | np.ndarray, p_last: Vector,
                     compliance: Vector, q: Vector, wrench: Vector | None = None,
                     ops: Any = NUMPY_OPS, joints: Sequence[Joint] | None = None,
                     rotation: Sequence[Sequence[float]] | None = None,
                     lever: Scalar | None = None) -> tuple[Scalar, Scalar, Scalar]:
    """Deflection-aware ball centre (x, y, z) [m] in the base frame: FK of (q, q_e(wrench)).

    ``rotation``, ``lever``: the probe frame (see :class:`arm_model.description.Probe`); a ``lever`` of
    0 is a tip without a stylus (a flange point, a tracker marker): rigid, the wrench moves nothing."""
    if wrench is None or not has_stylus(lever):
        return chain_point(convention, rows, q, tuple(p_last), ops, joints)
    q_e = elastic_displacement(p_last, compliance, wrench, probe_lever(p_last, rotation, lever))
    return chain_point(convention, rows, q, ball_in_last_frame(p_last, q_e, ops, rotation, lever), ops, joints)


def has_stylus(lever: Scalar | None) -> bool:
    """False for a tip without a stylus (a stylus length ``lever`` of exactly 0): no elastic joint."""
    return lever is None or lever != 0.0
