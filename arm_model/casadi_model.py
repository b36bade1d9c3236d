"""The CasADi evaluator: ``f(q, w, p)`` as SX expressions from the same chain code.

``p`` is the named parameter vector of :mod:`arm_model.params` (errors added to the description),
which calibration identifies. Inputs and outputs of the Function are named.
"""
from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from .chain import ball_centre_expr
from .description import ArmDescription
from .params import param_spec, split_params

__all__ = ["casadi_ball_centre"]


def _ops() -> SimpleNamespace:
    import casadi as ca
    return SimpleNamespace(sin=ca.sin, cos=ca.cos)


def casadi_ball_centre(desc: ArmDescription, name: str = "ball_centre") -> Any:
    """CasADi Function ``ball_centre(q[J], w[6], p[P]) -> (p_base[3])`` [m].

    ``w`` is the wrench at the ball in the probe frame (force [N], then torque [N m]).
    """
    import casadi as ca

    spec = param_spec(desc)
    q = ca.SX.sym("q", desc.n_joints)
    w = ca.SX.sym("w", 6)
    p = ca.SX.sym("p", spec.size)
    rows, p_last, compliance = split_params(desc, p)
    x, y, z = ball_centre_expr(desc.convention, rows, p_last, compliance,
                               [q[i] for i in range(desc.n_joints)], [w[i] for i in range(6)], _ops(),
                               desc.chain_joints, desc.probe.rotation, desc.probe.lever)
    return ca.Function(name, [q, w, p], [ca.vertcat(x, y, z)], ["q", "w", "p"], ["p_base"])
