"""Named model parameters: the vector ``p`` that calibration identifies.

``p`` holds *errors* added to the description's values, so ``p = 0`` is the description itself.
Order, stated once and kept everywhere: for each joint of the chain (revolute or prismatic, a mimicking
joint too: its geometry is its own), base first,
``theta_offset [rad], d [m], a [m], alpha [rad]`` (DH and MDH) or ``origin_x, origin_y, origin_z [m],
origin_roll, origin_pitch, origin_yaw [rad]`` (URDF chains: the angles turn the origin about its own x, y, z axes,
``R(rpy) Rz(yaw err) Ry(pitch err) Rx(roll err)``, :func:`arm_model.chain.row_motions`); then
``probe.x, probe.y, probe.z [m]``; then ``probe.compliance_x, probe.compliance_y, probe.compliance_z [m/N]``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .description import ArmDescription

__all__ = ["ParamSpec", "param_spec", "split_params", "apply_params", "folded_jacobian", "chain_floats"]

#: parameter vectors whose :func:`chain_floats` a description keeps
_CHAIN_FLOATS_KEPT = 8
#: (rows, p_last, compliance, rotation) of :func:`chain_floats`
ChainFloats = tuple[tuple[tuple[float, ...], ...], tuple[float, ...], tuple[float, ...],
                    "tuple[tuple[float, ...], ...] | None"]

_UNITS = {"theta_offset": "rad", "d": "m", "a": "m", "alpha": "rad", "origin_x": "m", "origin_y": "m",
          "origin_z": "m", "origin_roll": "rad", "origin_pitch": "rad", "origin_yaw": "rad"}
_PROBE_FIELDS = (("probe.x", "m"), ("probe.y", "m"), ("probe.z", "m"),
                 ("probe.compliance_x", "m/N"), ("probe.compliance_y", "m/N"),
                 ("probe.compliance_z", "m/N"))


@dataclass(frozen=True)
class ParamSpec:
    """Names and SI units of the parameter vector of one arm."""
    names: tuple[str, ...]
    units: tuple[str, ...]
    n_joints: int

    @property
    def size(self) -> int:
        return len(self.names)

    @property
    def labels(self) -> tuple[str, ...]:
        """``"j3.d [m]"`` style labels for reports."""
        return tuple(f"{n} [{u}]" for n, u in zip(self.names, self.units, strict=True))

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"unknown parameter {name!r}; known: {', '.join(self.names)}") from None

    def vector(self, values: dict[str, float] | None = None) -> np.ndarray:
        """A parameter vector, zero except for the named ``values`` (SI)."""
        p = np.zeros(self.size)
        for name, value in (values or {}).items():
            p[self.index(name)] = value
        return p


def param_spec(desc: ArmDescription) -> ParamSpec:
    names, units = [], []
    for j in desc.joints:
        for field in desc.row_fields:
            names.append(f"{j.name}.{field}")
            units.append(_UNITS[field])
    for field, unit in _PROBE_FIELDS:
        names.append(field)
        units.append(unit)
    return ParamSpec(tuple(names), tuple(units), desc.n_joints)


def split_params(desc: ArmDescription, p: Any = None) -> tuple[list[list[Any]], list[Any], list[Any]]:
    """(rows, p_last, compliance) of ``desc`` plus the errors ``p``.

    ``p`` may be None (the description itself), a numpy vector or a CasADi SX/MX column; the
    entries returned are floats or symbolic expressions accordingly.
    """
    table = desc.row_table()
    probe = desc.probe
    p_last: list[Any] = list(probe.p_last)
    compliance: list[Any] = list(probe.compliance)
    rows: list[list[Any]] = [[float(v) for v in r] for r in table]
    if p is None:
        return rows, p_last, compliance
    n, m = len(desc.joints), len(desc.row_fields)
    rows = [[rows[i][k] + p[m * i + k] for k in range(m)] for i in range(n)]
    p_last = [p_last[k] + p[m * n + k] for k in range(3)]
    compliance = [compliance[k] + p[m * n + 3 + k] for k in range(3)]
    return rows, p_last, compliance


def apply_params(desc: ArmDescription, p: ArrayLike) -> ArmDescription:
    """A new description with the errors ``p`` (numeric) folded into its values."""
    p = np.asarray(p, dtype=float)
    spec = param_spec(desc)
    if p.shape != (spec.size,):
        raise ValueError(f"parameter vector has shape {p.shape}, expected ({spec.size},)")
    rows, p_last, compliance = split_params(desc, p)
    out = desc.with_row_table(np.array(rows, dtype=float))
    return out.with_probe(p_last=tuple(float(v) for v in p_last),
                          bending_compliance_x=float(compliance[0]),
                          bending_compliance_y=float(compliance[1]),
                          axial_compliance=float(compliance[2]))


def folded_jacobian(desc: ArmDescription, p: ArrayLike) -> np.ndarray:
    """(n, n) ``d p' / d p`` [1] (n the base parameters of ``desc``): how a small change of the errors ``p`` of
    ``desc`` moves the errors ``p'`` of the folded description ``apply_params(desc, p)``, at ``p' = 0``; so a
    covariance ``C`` of ``p`` is ``T C T^T`` for ``p'`` (what a model file's covariance is read as, since its
    description holds ``p`` folded in), to first order exactly: the chain of ``desc`` at ``p + dp`` is that of the
    folded description at ``T dp`` to second order in ``dp``.

    The identity but for a URDF origin's angle errors: they turn the origin about its own axes (``R(rpy0)
    E(roll, pitch, yaw)``, ``E = Rz(yaw) Ry(pitch) Rx(roll)``, :func:`arm_model.chain.row_motions`), the folded
    origin is ``R(rpy0) E(p)``, and ``E(p)^T E(p + dp)`` is the turn ``(dp'_roll, dp'_pitch, dp'_yaw)`` about
    the folded origin's axes, the body angular velocity of ``E`` at ``p``: columns ``e_x``, ``Rx(roll)^T e_y``,
    ``(Ry(pitch) Rx(roll))^T e_z`` (at ``p = 0`` the identity)."""
    from .geometry import rotation_xyz
    spec = param_spec(desc)
    p = np.asarray(p, dtype=float)[: spec.size]
    out = np.eye(spec.size)
    if desc.convention != "urdf":
        return out
    m = len(desc.row_fields)
    for i in range(len(desc.joints)):
        roll, pitch, _ = p[m * i + 3: m * i + 6]
        rx = rotation_xyz((roll, 0.0, 0.0))
        out[m * i + 3: m * i + 6, m * i + 3: m * i + 6] = np.column_stack(
            [(1.0, 0.0, 0.0), rx.T[:, 1], (rotation_xyz((0.0, pitch, 0.0)) @ rx).T[:, 2]])
    return out


def chain_floats(desc: ArmDescription, p: ArrayLike | None = None) -> ChainFloats:
    """``(rows, p_last, compliance, rotation)`` of the description plus the errors ``p`` (None: none) as Python
    floats (:func:`split_params`, and :attr:`~arm_model.description.Probe.rotation`): what one point's evaluation
    on floats reads (:data:`arm_model.chain.FLOAT_OPS`), made once for the same ``p`` (the last few kept on the
    description), not per point."""
    key = None if p is None else np.asarray(p, dtype=float).tobytes()
    cache: dict[bytes | None, ChainFloats] = desc.__dict__.setdefault("_chain_floats", {})
    if key not in cache:
        rows, p_last, compliance = split_params(desc, None if p is None else np.asarray(p, dtype=float).tolist())
        if len(cache) >= _CHAIN_FLOATS_KEPT:
            cache.clear()
        cache[key] = (tuple(tuple(float(v) for v in r) for r in rows), tuple(float(v) for v in p_last),
                      tuple(float(v) for v in compliance), desc.probe.rotation)
    return cache[key]
