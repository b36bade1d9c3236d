"""The Pinocchio evaluator: one point at a time, with Jacobians, gravity and contact torques.

Built from the URDF text generated from the description, so it shares no kinematic code with the
batch and CasADi evaluators: the tests use it as an independent reference. The elastic joint
displacement is computed here by statics from Pinocchio's own Jacobian of the ball frame,
``q_e = K^-1 J_e^T w``.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .description import GRAVITY, ArmDescription
from .urdf import BALL_FRAME, ELASTIC_JOINTS, urdf_text

__all__ = ["PinocchioArm"]


class PinocchioArm:
    """Pinocchio model of an arm with its probe's virtual elastic joints.

    Args:
        desc: the arm description.
    """

    def __init__(self, desc: ArmDescription):
        import pinocchio as pin  # heavy backend: imported only here

        self._pin = pin
        self.desc = desc
        self.urdf = urdf_text(desc)
        self.model = pin.buildModelFromXML(self.urdf)
        self.model.gravity.linear = GRAVITY.copy()
        self.data = self.model.createData()
        self.ball_id = self.model.getFrameId(BALL_FRAME)
        # every row of the chain is its own joint here (a mimic's too): ``coupling`` maps the encoder
        # columns to them, row value = coupling @ q + offsets (the URDF's <mimic>)
        self.arm_idx = np.array([self.model.joints[self.model.getJointId(j.name)].idx_q
                                 for j in desc.joints])
        cj = desc.chain_joints
        self.coupling = np.zeros((len(cj), desc.n_joints))
        self.coupling[np.arange(len(cj)), [j.column for j in cj]] = [j.multiplier for j in cj]
        self.offsets = np.array([j.offset for j in cj])
        self.elastic_idx = np.array([self.model.joints[self.model.getJointId(name)].idx_q
                                     for name in ELASTIC_JOINTS])
        p = desc.probe
        lever = p.stylus_length
        # compliance of the elastic joints, K^-1 = diag(c_x / L^2, c_y / L^2, c_z); none without a stylus
        self.joint_compliance = np.zeros(3) if lever == 0.0 else np.array(
            [p.bending_compliance_x / lever**2, p.bending_compliance_y / lever**2, p.axial_compliance])

    # -- configuration ------------------------------------------------------------------------
    def full_q(self, q: ArrayLike, q_e: ArrayLike | None = None) -> np.ndarray:
        """Pinocchio configuration from the encoder readings ``q`` [rad] or [m] and elastic displacement ``q_e``."""
        x = np.zeros(self.model.nq)
        x[self.arm_idx] = self.coupling @ np.asarray(q, dtype=float) + self.offsets
        if q_e is not None:
            x[self.elastic_idx] = q_e
        return x

    def _ball_jacobian(self, x: np.ndarray, frame: Any) -> np.ndarray:
        pin = self._pin
        pin.computeJointJacobians(self.model, self.data, x)
        pin.updateFramePlacements(self.model, self.data)
        jac: np.ndarray = pin.getFrameJacobian(self.model, self.data, self.ball_id, frame)
        return jac

    def elastic_q(self, q: ArrayLike, wrench: ArrayLike) -> np.ndarray:
        """Elastic joint displacement (theta_y [rad], theta_x [rad], s [m]) by statics.

        ``wrench``: (3,) force [N] or (6,) force [N] and torque [N m] at the ball, probe frame.
        """
        w = _six(wrench)
        j_local = self._ball_jacobian(self.full_q(q), self._pin.ReferenceFrame.LOCAL)
        j_e = j_local[:, self.elastic_idx]
        q_e: np.ndarray = self.joint_compliance * (j_e.T @ w)
        return q_e

    # -- evaluation ---------------------------------------------------------------------------
    def ball_centre(self, q: ArrayLike, wrench: ArrayLike | None = None) -> np.ndarray:
        """Deflection-aware ball centre [m] in the base frame for one point."""
        pin = self._pin
        q_e = None if wrench is None else self.elastic_q(q, wrench)
        pin.framesForwardKinematics(self.model, self.data, self.full_q(q, q_e))
        centre: np.ndarray = self.data.oMf[self.ball_id].translation.copy()
        return centre

    def T_base_ball(self, q: ArrayLike, wrench: ArrayLike | None = None) -> np.ndarray:
        """4x4 pose of the (deflected) ball frame in the base frame."""
        pin = self._pin
        q_e = None if wrench is None else self.elastic_q(q, wrench)
        pin.framesForwardKinematics(self.model, self.data, self.full_q(q, q_e))
        T_base_ball: np.ndarray = self.data.oMf[self.ball_id].homogeneous.copy()
        return T_base_ball

    def jacobians(self, q: ArrayLike, wrench: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(d ball / d q  (3, J) [m/rad] ([m/m] for a prismatic joint), d ball / d w  (3, 6) [m/N, m/(N m)]),
        base frame axes, by encoder column."""
        pin = self._pin
        w = _six(wrench)
        x = self.full_q(q, self.elastic_q(q, w))
        j = self._ball_jacobian(x, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        j_e0 = self._ball_jacobian(self.full_q(q), pin.ReferenceFrame.LOCAL)[:, self.elastic_idx]
        dqe_dw = self.joint_compliance[:, None] * j_e0.T
        return j[:, self.arm_idx] @ self.coupling, j[:, self.elastic_idx] @ dqe_dw

    def gravity_torques(self, q: ArrayLike) -> np.ndarray:
        """Torque [N m] (force [N] for a prismatic joint) each encoder column's joint holds against gravity,
        RNEA(q, 0, 0) (Pinocchio's sign): the generalized force gravity exerts on the joints is its negative
        (a mimicking joint's share carried to its master by the multiplier)."""
        g = self._pin.computeGeneralizedGravity(self.model, self.data, self.full_q(q))
        tau: np.ndarray = self.coupling.T @ g[self.arm_idx]
        return tau

    def contact_torques(self, q: ArrayLike, wrench: ArrayLike) -> np.ndarray:
        """Generalized force [N m] a wrench at the ball (probe frame) exerts on the arm joints,
        ``J_local^T w``."""
        w = _six(wrench)
        j_local = self._ball_jacobian(self.full_q(q), self._pin.ReferenceFrame.LOCAL)
        tau: np.ndarray = self.coupling.T @ (j_local.T @ w)[self.arm_idx]
        return tau

    def torques(self, q: ArrayLike, wrench: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
        """For (N, J) angles and (N, 3|6) wrenches: (tau_gravity (N, J), tau_contact (N, J)) [N m]
        (see :mod:`arm_model.effects` for the signs); tau_contact is zero without a wrench."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        n, j = q.shape
        tg, tc = np.empty((n, j)), np.zeros((n, j))
        w = None if wrench is None else np.atleast_2d(np.asarray(wrench, dtype=float))
        for i in range(n):
            tg[i] = self.gravity_torques(q[i])
            if w is not None:
                tc[i] = self.contact_torques(q[i], w[i])
        return tg, tc


def _six(wrench: ArrayLike | None) -> np.ndarray:
    """A wrench of 3 (force [N]) or 6 (force, torque [N m]) components as 6, the torque zero if absent."""
    w = np.zeros(6)
    if wrench is not None:
        v = np.asarray(wrench, dtype=float).reshape(-1)
        w[: len(v)] = v
    return w
