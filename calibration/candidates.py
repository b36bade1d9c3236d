"""Candidate missing effects: the effect library (:mod:`arm_model.effects`) instantiated for one arm
and one data set, each with a readable name.

A candidate is an :class:`~arm_model.effects.Effect` instance that the closed loop may add to the
model (``ArmModel.with_effects``). The library gives, per arm and data:

* ``eccentricity jN``: encoder eccentricity of joint N, harmonics 1 and 2 (4 parameters);
* ``gain jN``: encoder scale (gain) error of joint N, ``q_true = (1 + g) q_enc`` (1 parameter; the
  joint's offset stays the description's, so the gain is told from it only by the spread of the joint's
  angle over the data: a gain the data cannot resolve is shown as absorbed by the screening); offered
  only on request (not in :data:`DEFAULT_FAMILIES`);
* ``joint compliance jN``: joint N turns by ``c (tau_contact - tau_gravity)`` (1 parameter); offered
  only where the joint's gravity or contact torque is not zero throughout the data (none at all for an
  arm without masses measured without force: one "joint compliance" entry says so); and
  ``joint compliance (every loaded joint)``: one such parameter for each of those joints at once;
* ``thermal growth``: one expansion coefficient of every link length; offered only when the
  temperature column varies by at least :data:`MIN_TEMPERATURE_SPAN`;
* ``thermal drift (time)`` (family ``thermal`` too): the links grow with the time instead of a temperature
  (:class:`~arm_model.effects.ThermalDrift`, one rate about the middle of the session's time span), and once it is
  added ``thermal drift (time^2)`` (a second term in the square of the time); offered only when the points have no
  temperature and their ``time_s`` spans at least :data:`MIN_DRIFT_SPAN_S`. A session's drift, never the arm's:
  the written model holds the geometry at the reference time and no drift (:mod:`calibration.model_output`);
* ``force sensor x|y|z``: gain and offset of one sensor axis; only with force data on that axis
  (a constant offset deflects the probe by a constant vector, which the probe offset ``probe.x/y/z``
  absorbs: the screening shows it as not identifiable);
* ``probe compliance (isotropic)`` / ``(anisotropic)``: bending compliance beyond the declared one;
  only with force data;
* ``coupling jN by qK`` (family ``joint_coupling``): joint N's reading carries a fraction ``g`` of joint K's,
  ``q_N += g q_K`` (:class:`~arm_model.effects.JointGain` with ``source``, 1 parameter: a differential wrist's or a
  belt's coupling ratio, an encoder read through another joint's transmission), for every ordered pair of revolute
  joints whose source angle varies over the data; offered only on request or by the escalation (not in
  :data:`DEFAULT_FAMILIES`: J (J - 1) candidates, the effect :mod:`calibration.synthesis` builds from a
  ``qK harmonics on jN`` family, under the same name);
* ``lateral compliance jN`` of the first joint N (family ``base_tilt``): the mount tilts about the two axes across
  the first joint under the moment of the arm's weight and of the contact wrench
  (:class:`~arm_model.effects.LateralCompliance`, 2 parameters [rad/(N m)]): a tripod, a magnetic base, a robot's
  pedestal or table; offered where a torque loads the arm (masses or force) and the chain has no joint
  mimicking another (an effect on the chain's rows).

A new candidate is one :class:`~arm_model.effects.Effect` subclass (parameters zero = no change,
as every library effect) wrapped in a :class:`Candidate`, passed to the loop as an extra candidate.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from arm_model.description import ArmDescription
from arm_model.effects import (
    Effect,
    EncoderEccentricity,
    ForceSensorError,
    JointCompliance,
    JointGain,
    LateralCompliance,
    ProbeCompliance,
    ThermalDrift,
    ThermalGrowth,
)
from arm_model.model import ArmModel

from .data import CalibrationData

__all__ = ["Candidate", "pair_of", "Skipped", "FAMILIES", "DEFAULT_FAMILIES", "MIN_TEMPERATURE_SPAN",
           "library_candidates", "needs_model", "torques_of", "no_torque_reason", "has_force", "MIN_DRIFT_SPAN_S",
           "drift_offer"]

#: candidate families of the library, by effect key (the CLI's ``--candidates`` names)
FAMILIES = ("eccentricity", "joint_gain", "joint_compliance", "thermal", "force_sensor", "probe_compliance",
            "base_tilt", "joint_coupling")

#: the families offered when none are named: every one but ``joint_gain`` and ``base_tilt``, which are offered on
#: request (``--candidates``). On the real robot data of examples/ each passed the held-out test of the poses of
#: one plate placement and made the other placements worse. A joint gain: within one seat the poses of a redundant
#: arm move its joints together (self-motion), and a gain of one joint fits there what another error of the same
#: self-motion leaves (docs/studies/close-loop.md, "Joint gains"). The mount's tilt: trained on ``back-high`` (no joint
#: compliance in the base model) it took that placement's own test set from 287 to 245 um and spread the two
#: other placements' seats from 2.81 to 4.01 mm (tests/test_loop_real_physics.py); the joint compliance it
#: displaced takes them to 2.07 mm. The reading couplings: one a pair of joints (42 on a 7-joint arm), the effect
#: built from the residual when a ``qK harmonics on jN`` family is significant; offered whole only on evidence.
OPT_IN_FAMILIES = ("joint_gain", "base_tilt", "joint_coupling")
DEFAULT_FAMILIES = tuple(f for f in FAMILIES if f not in OPT_IN_FAMILIES)

#: smallest temperature range [K] over the data for which thermal growth is a candidate
MIN_TEMPERATURE_SPAN = 0.2

#: smallest time span [s] of points without a temperature for which a drift of the links in time is a candidate
#: (ten minutes: a room's drift of a few K an hour grows an aluminium arm's links by a few ppm)
MIN_DRIFT_SPAN_S = 600.0

#: torque [N m] below which a joint's torque counts as zero throughout the data
_ZERO_TORQUE = 1e-6
#: force [N] below which a sensor axis counts as unused
_ZERO_FORCE = 1e-6


@dataclass(frozen=True)
class Candidate:
    """A missing effect the loop may add.

    Attributes:
        name: readable name, e.g. ``"eccentricity j2"`` (unique within a candidate set).
        effect: the effect instance added to the model.
        family: the effect family (the effect's key for library effects).
        joint: the joint it acts on (name), or None.
        origin: "library", "user" (an extra candidate) or "residual" (built from a structure family that
            stayed significant, :mod:`calibration.synthesis`).
        then: candidates offered only once this one is added (a higher term of the same effect: the loop
            screens and tests it at the next stage, never before its first term is in).
        parts: for a pair (:func:`pair_of`), the two candidates added together as one; ``effect`` is then the
            first part's, and :attr:`effects` holds both.
    """
    name: str
    effect: Effect
    family: str
    joint: str | None = None
    origin: str = "library"
    then: tuple[Candidate, ...] = ()
    parts: tuple[Candidate, ...] = ()

    @property
    def effects(self) -> tuple[Effect, ...]:
        """The effects this candidate adds to the model: its own, or its parts' (a pair)."""
        return tuple(c.effect for c in self.parts) if self.parts else (self.effect,)

    def param_names(self, desc: ArmDescription) -> list[str]:
        return [n for e in self.effects for n, _ in e.param_defs(desc)]

    def size(self, desc: ArmDescription) -> int:
        return len(self.param_names(desc))


def pair_of(a: Candidate, b: Candidate) -> Candidate:
    """Two candidates offered as one (``"a + b"``, :attr:`Candidate.parts`): the loop's pair step, for effects that
    help only together (:mod:`calibration.loop.pairs`). Its family is the parts' when they share it, else both
    joined by ``+``; its origin "residual" when a part was built from the residual, "user" when a part is the
    user's, else "library"."""
    fam = a.family if a.family == b.family else f"{a.family}+{b.family}"
    origins = {a.origin, b.origin}
    origin = "residual" if "residual" in origins else "user" if "user" in origins else "library"
    return Candidate(f"{a.name} + {b.name}", a.effect, fam, None, origin, parts=(a, b))


@dataclass(frozen=True)
class Skipped:
    """A library candidate left out for these data, and why."""
    name: str
    reason: str


def needs_model(desc: ArmDescription, effects=()) -> ArmModel:
    """A model that needs every per-point input ``effects`` need (for ``make_data``): one effect per need."""
    picked, seen = [], set()
    for e in effects:
        new = set(e.needs()) - seen
        if new:
            picked.append(e)
            seen |= set(e.needs())
    names: set[str] = set()
    out = []
    for e in picked:                  # parameter names must not collide in one model
        pn = {n for n, _ in e.param_defs(desc)}
        if pn & names:
            continue
        names |= pn
        out.append(e)
    return ArmModel(desc, tuple(out))


def torques_of(desc: ArmDescription, data: CalibrationData) -> tuple[np.ndarray, np.ndarray]:
    """(tau_gravity, tau_contact) (N, J) [N m] of the data: its aux inputs, else Pinocchio at the
    measured angles and wrenches (nominal description)."""
    aux = data.aux
    if aux is not None and aux.tau_gravity is not None and aux.tau_contact is not None:
        return aux.tau_gravity, aux.tau_contact
    from arm_model import PinocchioArm
    return PinocchioArm(desc).torques(data.points.q, data.points.wrench)


def has_force(points) -> bool:
    """Whether the points (a :class:`~arm_model.io.PointSet`) carry a measured contact force: force columns, not zero
    throughout."""
    return points.force is not None and np.max(np.abs(points.force), initial=0.0) > _ZERO_FORCE


def no_torque_reason(desc: ArmDescription, data: CalibrationData) -> str | None:
    """Why no joint carries a torque in these data (no masses and no force), or None."""
    if has_force(data.points) or any(j.mass > 0 for j in desc.joints):
        return None
    return ("the arm has no masses (no <inertial> in its URDF, no mass_kg in its description) and the data no "
            "force, so no joint carries a torque; give the link masses with --masses (or mass_kg in the "
            "description)")


_MIMIC_GROWTH = "the chain has a joint mimicking another: link growth acts on the chain's rows"


def drift_offer(desc: ArmDescription, points) -> list[Candidate] | Skipped:
    """The candidate of a drift of the links in time (:class:`~arm_model.effects.ThermalDrift` about the middle of
    the points' time span; its second term, power 2, offered once it is added), or why it is not offered: a chain
    with a joint mimicking another (link growth acts on the chain's rows), a temperature column (thermal growth
    is offered instead), no or empty ``time_s``, or a span shorter than :data:`MIN_DRIFT_SPAN_S`. The one
    decision: the loop asks it both for the per-point inputs it must read and for its candidates."""
    if desc.coupled:
        return Skipped("thermal drift (time)", _MIMIC_GROWTH)
    temp, time = points.temperature, points.time
    if temp is not None and np.all(np.isfinite(temp)):
        return Skipped("thermal drift (time)", "the points have a temperature_C column: thermal growth instead")
    if time is None or len(time) == 0 or not np.all(np.isfinite(time)):
        return Skipped("thermal drift (time)", "no temperature_C column and no time_s column (or empty cells)")
    span = float(np.ptp(time))
    if span < MIN_DRIFT_SPAN_S:
        return Skipped("thermal drift (time)", f"the points span {span:.3g} s only (at least {MIN_DRIFT_SPAN_S:g} s "
                                               "needed)")
    t_ref = ThermalDrift.reference_of(time)
    second = Candidate("thermal drift (time^2)", ThermalDrift(power=2, reference_time_s=t_ref), "thermal")
    return [Candidate("thermal drift (time)", ThermalDrift(power=1, reference_time_s=t_ref), "thermal",
                      then=(second,))]


def _per_joint_columns(desc: ArmDescription, skipped: list) -> dict[int, str]:
    """{encoder column: joint name} of the joints a per-joint effect of the library (an angle's error or
    compliance, each an error of a reading: on an arm whose chain has a joint following another it acts on the
    master's column) may act on: the revolute ones. What is left out goes to ``skipped``."""
    for j in desc.encoders:
        if j.prismatic:
            skipped.append(Skipped(f"per-joint effects {j.name}", "a prismatic joint: the library's per-joint "
                                                                 "effects model a joint angle (but its gain)"))
    return {i: desc.encoders[i].name for i in desc.revolute_columns}


def _couplings(names: dict[int, str], q: np.ndarray) -> list[Candidate]:
    """``coupling jN by qK`` for every ordered pair of revolute joints (``names``: column -> name) whose source
    angle ``q[:, K]`` varies over the data (a constant one is an offset of jN)."""
    return [Candidate(f"coupling {n} by q{k + 1}", JointGain(joints=(i,), source=k), "joint_coupling", n)
            for i, n in names.items() for k in names if k != i and np.ptp(q[:, k]) > 0]


def _base_tilt(desc: ArmDescription, data: CalibrationData) -> Candidate | Skipped:
    """The mount's tilt under the arm's moment: the first joint's lateral compliance (the links it moves, i.e. the
    whole arm, tilt about its frame's x and y axes through its origin by ``c M``), or why it is not offered. Its
    name is the one :mod:`calibration.synthesis` gives the same effect built from a ``j1 lateral load`` family."""
    name = desc.joint_names[0]
    reason = no_torque_reason(desc, data)
    if reason is None and desc.coupled:
        reason = "the chain has a joint mimicking another: a lateral compliance acts on the chain's rows"
    if reason is not None:
        return Skipped(f"lateral compliance {name} (base tilt)", reason)
    return Candidate(f"lateral compliance {name}", LateralCompliance(joints=(0,)), "lateral_compliance", name)


def library_candidates(desc: ArmDescription, data: CalibrationData, families=None,
                       extra=()) -> tuple[list[Candidate], list[Skipped]]:
    """The library's candidates for ``desc`` and ``data``, and those left out with the reason.

    Args:
        families: keys of :data:`FAMILIES` to offer (default :data:`DEFAULT_FAMILIES`).
        extra: user candidates (:class:`Candidate`), appended after the library's.
    """
    families = DEFAULT_FAMILIES if families is None else tuple(families)
    unknown = set(families) - set(FAMILIES)
    if unknown:
        raise ValueError(f"unknown candidate famil{'y' if len(unknown) == 1 else 'ies'} "
                         f"{', '.join(sorted(unknown))}; known: {', '.join(FAMILIES)}")
    pts = data.points
    out: list[Candidate] = []
    skipped: list[Skipped] = []
    names = _per_joint_columns(desc, skipped)
    force = pts.force if pts.force is not None else np.zeros((len(pts), 3))
    axes_used = [a for a in range(3) if np.max(np.abs(force[:, a]), initial=0.0) > _ZERO_FORCE]
    if "eccentricity" in families:
        for i, n in names.items():
            out.append(Candidate(f"eccentricity {n}", EncoderEccentricity(joints=(i,), harmonics=(1, 2)),
                                 "eccentricity", n))
    if "joint_gain" in families:
        # a scale error of any joint's reading, a slide's (a lift's screw pitch) as a gear ratio's
        for i, j in enumerate(desc.encoders):
            out.append(Candidate(f"gain {j.name}", JointGain(joints=(i,)), "joint_gain", j.name))
    if "joint_coupling" in families:
        out += _couplings(names, pts.q)
    no_torque = no_torque_reason(desc, data) if "joint_compliance" in families else None
    if no_torque:
        skipped.append(Skipped("joint compliance", no_torque))
    elif "joint_compliance" in families:
        tau_g, tau_c = torques_of(desc, data)
        loaded = []
        for i, n in names.items():
            g = np.max(np.abs(tau_g[:, i]), initial=0.0)
            c = np.max(np.abs(tau_c[:, i]), initial=0.0)
            if g <= _ZERO_TORQUE and c <= _ZERO_TORQUE:
                skipped.append(Skipped(f"joint compliance {n}", "neither gravity nor the contact loads this joint "
                                                                 "in these data (torques zero)"))
                continue
            out.append(Candidate(f"joint compliance {n}", JointCompliance(joints=(i,), gravity=True, contact=True),
                                 "joint_compliance", n))
            loaded.append(i)
        if len(loaded) > 1:
            # every loaded joint at once: under gravity the joints deflect together, and one joint's share of
            # the signature may be too small to pass alone when the sum is plain
            out.append(Candidate("joint compliance (every loaded joint)",
                                 JointCompliance(joints=tuple(loaded), gravity=True, contact=True), "joint_compliance"))
    if "thermal" in families:
        t = pts.temperature
        has_t = t is not None and bool(np.all(np.isfinite(t)))
        if desc.coupled:
            skipped.append(Skipped("thermal growth", _MIMIC_GROWTH))
        elif not has_t:
            skipped.append(Skipped("thermal growth", "no temperature_C column (or empty cells)"))
        elif np.ptp(t) < MIN_TEMPERATURE_SPAN:
            skipped.append(Skipped("thermal growth", f"the temperature varies by {np.ptp(t):.3g} K only "
                                                     f"(at least {MIN_TEMPERATURE_SPAN:g} K needed)"))
        else:
            out.append(Candidate("thermal growth", ThermalGrowth(), "thermal"))
        if not has_t:
            drift = drift_offer(desc, pts)
            (out.extend if isinstance(drift, list) else skipped.append)(drift)
    if "force_sensor" in families:
        if not axes_used:
            skipped.append(Skipped("force sensor", "no force data"))
        for a in range(3):
            if a in axes_used:
                out.append(Candidate(f"force sensor {'xyz'[a]}", ForceSensorError(axes=(a,), offsets=True),
                                     "force_sensor"))
            elif axes_used:
                skipped.append(Skipped(f"force sensor {'xyz'[a]}", f"no force along probe {'xyz'[a]} in these data"))
    if "probe_compliance" in families:
        if not axes_used:
            skipped.append(Skipped("probe compliance", "no force data"))
        else:
            out.append(Candidate("probe compliance (isotropic)", ProbeCompliance(anisotropic=False),
                                 "probe_compliance"))
            out.append(Candidate("probe compliance (anisotropic)", ProbeCompliance(anisotropic=True),
                                 "probe_compliance"))
    if "base_tilt" in families:
        tilt = _base_tilt(desc, data)
        (out if isinstance(tilt, Candidate) else skipped).append(tilt)
    for c in extra:
        if not isinstance(c, Candidate):
            raise TypeError(f"an extra candidate must be a Candidate, got {type(c).__name__}")
        out.append(c)
    seen = set()
    for c in out:
        if c.name in seen:
            raise ValueError(f"two candidates are named {c.name!r}")
        seen.add(c.name)
    return out, skipped
