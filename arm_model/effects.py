"""The effect library: physics the base kinematic model lacks, each with named parameters.

An effect transforms the model's per-point inputs (encoder angles, wrench, temperature, joint
torques) and/or its geometry (DH rows, probe point, compliance) before the chain is evaluated.
It is written once with the ``ops`` namespace, like :mod:`arm_model.chain`, so the same code runs
on numpy columns (batch path, simulator truth) and on CasADi SX (calibration). A new effect is one
subclass of :class:`Effect`.

Sign conventions:

* ``tau_gravity``: the torque each joint holds against gravity, RNEA(q, 0, 0) [N m] (Pinocchio's
  sign); the generalized force of gravity on the joint is ``-tau_gravity``.
* ``tau_contact``: the generalized force ``J_local^T w`` [N m] that the contact wrench exerts on
  the joints.
* A joint of compliance ``c`` [rad/(N m)] turns by ``c * (tau_contact - tau_gravity)`` beyond its
  encoder reading.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .description import ArmDescription

__all__ = ["ModelInputs", "Geometry", "Effect", "EncoderEccentricity", "JointCompliance",
           "ThermalGrowth", "ForceSensorError", "ProbeCompliance", "EFFECTS", "effect_from_name",
           "REFERENCE_TEMPERATURE_C"]

REFERENCE_TEMPERATURE_C = 20.0


@dataclass
class ModelInputs:
    """Per-point inputs; each entry a column (numpy array), a scalar or an SX."""
    q: list                       # J encoder angles [rad]
    wrench: list                  # 6: force [N], torque [N m], probe frame
    temperature: Any = None       # [°C]
    tau_gravity: list | None = None   # J [N m]
    tau_contact: list | None = None   # J [N m]


@dataclass
class Geometry:
    rows: list                    # J x (theta_offset [rad], d [m], a [m], alpha [rad])
    p_last: list                  # 3 [m]
    compliance: list              # 3 [m/N]


@dataclass(frozen=True)
class Effect:
    """Base class. Subclasses set ``key``, implement :meth:`param_defs` and :meth:`apply`.

    ``joints``: 0-based indices of the joints the effect acts on (None: all joints).
    """
    joints: tuple[int, ...] | None = None
    key: str = field(default="effect", init=False, repr=False)

    def needs(self) -> tuple[str, ...]:
        """Per-point inputs the effect needs beyond q and the wrench."""
        return ()

    def joint_indices(self, desc: ArmDescription) -> tuple[int, ...]:
        return tuple(range(desc.n_joints)) if self.joints is None else tuple(self.joints)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        """(name, SI unit) of each parameter, in the order :meth:`apply` reads them."""
        raise NotImplementedError

    def apply(self, desc: ArmDescription, params: list, inputs: ModelInputs, geom: Geometry, ops) -> None:
        """Modify ``inputs`` and ``geom`` in place (lists of columns/expressions)."""
        raise NotImplementedError

    def describe(self) -> str:
        return self.key if self.joints is None else f"{self.key}({', '.join(f'j{i + 1}' for i in self.joints)})"


@dataclass(frozen=True)
class EncoderEccentricity(Effect):
    """Encoder reading error: ``q_true = q_enc + sum_h c_h cos(h q_enc) + s_h sin(h q_enc)``
    (amplitude ``hypot(c, s)``, phase ``atan2(c, s)`` of ``a sin(h q + phi)``) for harmonics ``harmonics``."""
    harmonics: tuple[int, ...] = (1, 2)
    key: str = field(default="eccentricity", init=False, repr=False)

    def param_defs(self, desc):
        out = []
        for i in self.joint_indices(desc):
            for h in self.harmonics:
                out += [(f"{desc.joints[i].name}.ecc{h}_cos", "rad"), (f"{desc.joints[i].name}.ecc{h}_sin", "rad")]
        return out

    def apply(self, desc, params, inputs, geom, ops):
        k = 0
        q = list(inputs.q)
        for i in self.joint_indices(desc):
            for h in self.harmonics:
                c, s = params[k], params[k + 1]
                k += 2
                q[i] = q[i] + c * ops.cos(h * inputs.q[i]) + s * ops.sin(h * inputs.q[i])
        inputs.q = q


@dataclass(frozen=True)
class JointCompliance(Effect):
    """Joint i turns by ``c_i (tau_contact_i - tau_gravity_i)`` beyond its encoder. With
    ``gravity=False`` or ``contact=False`` that part is left out."""
    gravity: bool = True
    contact: bool = True
    key: str = field(default="joint_compliance", init=False, repr=False)

    def needs(self):
        return tuple(n for n, on in (("tau_gravity", self.gravity), ("tau_contact", self.contact)) if on)

    def param_defs(self, desc):
        return [(f"{desc.joints[i].name}.compliance", "rad/(N m)") for i in self.joint_indices(desc)]

    def apply(self, desc, params, inputs, geom, ops):
        q = list(inputs.q)
        for k, i in enumerate(self.joint_indices(desc)):
            load = 0.0
            if self.contact:
                load = load + inputs.tau_contact[i]
            if self.gravity:
                load = load - inputs.tau_gravity[i]
            q[i] = q[i] + params[k] * load
        inputs.q = q


@dataclass(frozen=True)
class ThermalGrowth(Effect):
    """Link lengths (d and a; a URDF origin's xyz) grow by ``(1 + alpha (T - 20 °C))``; one alpha [1/K] for the links of
    ``joints`` (all by default), or one per joint with ``per_joint=True``."""
    per_joint: bool = False
    key: str = field(default="thermal", init=False, repr=False)

    def needs(self):
        return ("temperature",)

    def param_defs(self, desc):
        if self.per_joint:
            return [(f"{desc.joints[i].name}.thermal_alpha", "1/K") for i in self.joint_indices(desc)]
        return [("links.thermal_alpha", "1/K")]

    def apply(self, desc, params, inputs, geom, ops):
        dt = inputs.temperature - REFERENCE_TEMPERATURE_C
        rows = [list(r) for r in geom.rows]
        for k, i in enumerate(self.joint_indices(desc)):
            scale = 1.0 + params[k if self.per_joint else 0] * dt
            for m in desc.length_indices:
                rows[i][m] = rows[i][m] * scale
        geom.rows = rows


@dataclass(frozen=True)
class ForceSensorError(Effect):
    """The sensor reads ``f_meas = (1 + g) f_true + o`` per probe axis (``cross_talk`` adds
    ``f_meas_x += k_xy f_true_y`` etc. in the simulator's truth only); the model maps the reading
    back: ``f_true = (f_meas - o) / (1 + g)``. ``axes``: which of x, y, z (0, 1, 2)."""
    axes: tuple[int, ...] = (0, 1, 2)
    offsets: bool = True
    key: str = field(default="force_sensor", init=False, repr=False)

    def param_defs(self, desc):
        out = [(f"force.gain_{'xyz'[a]}", "1") for a in self.axes]
        if self.offsets:
            out += [(f"force.offset_{'xyz'[a]}", "N") for a in self.axes]
        return out

    def apply(self, desc, params, inputs, geom, ops):
        w = list(inputs.wrench)
        n = len(self.axes)
        for k, a in enumerate(self.axes):
            off = params[n + k] if self.offsets else 0.0
            w[a] = (w[a] - off) / (1.0 + params[k])
        inputs.wrench = w


@dataclass(frozen=True)
class ProbeCompliance(Effect):
    """Bending compliance of the probe beyond the declared one: one increment [m/N] for both
    bending axes (``anisotropic=False``) or one per axis; ``axial=True`` adds one along z."""
    anisotropic: bool = False
    axial: bool = False
    key: str = field(default="probe_compliance", init=False, repr=False)

    def param_defs(self, desc):
        out = ([("probe.dcompliance_x", "m/N"), ("probe.dcompliance_y", "m/N")] if self.anisotropic
               else [("probe.dcompliance_bend", "m/N")])
        if self.axial:
            out.append(("probe.dcompliance_z", "m/N"))
        return out

    def apply(self, desc, params, inputs, geom, ops):
        c = list(geom.compliance)
        if self.anisotropic:
            c[0], c[1] = c[0] + params[0], c[1] + params[1]
        else:
            c[0], c[1] = c[0] + params[0], c[1] + params[0]
        if self.axial:
            c[2] = c[2] + params[-1]
        geom.compliance = c


EFFECTS = {cls.__dataclass_fields__["key"].default: cls for cls in
           (EncoderEccentricity, JointCompliance, ThermalGrowth, ForceSensorError, ProbeCompliance)}


def effect_from_name(key: str, **kwargs) -> Effect:
    """An effect by its key (``"eccentricity"``, ``"joint_compliance"``, ``"thermal"``,
    ``"force_sensor"``, ``"probe_compliance"``)."""
    try:
        return EFFECTS[key](**kwargs)
    except KeyError:
        raise KeyError(f"unknown effect {key!r}; known: {', '.join(EFFECTS)}") from None
