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

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, ClassVar

from .description import ArmDescription

__all__ = ["ModelInputs", "Geometry", "Effect", "EncoderEccentricity", "JointCompliance",
           "ThermalGrowth", "ForceSensorError", "JointGain", "ProbeCompliance", "EFFECTS", "effect_from_name",
           "REFERENCE_TEMPERATURE_C", "JointHarmonics", "ProbeThermalGrowth", "ProbeComplianceMatrix",
           "ApproachOffset", "LateralCompliance", "ThermalDrift", "JointBacklash", "JointHysteresis", "joint_frame",
           "last_frame", "gravity_moment", "contact_moment", "PLAY", "DRIFT_STRAIN", "ArtefactDrift", "PAPER_STYLUS",
           "PAPER_STYLUS_COMPLIANCE", "stylus_compliance"]

REFERENCE_TEMPERATURE_C = 20.0


@dataclass
class ModelInputs:
    """Per-point inputs; each entry a column (numpy array), a scalar or an SX."""
    q: list[Any]                  # J encoder angles [rad]
    wrench: list[Any]             # 6: force [N], torque [N m], probe frame
    temperature: Any = None       # [°C]
    tau_gravity: list[Any] | None = None   # J [N m]
    tau_contact: list[Any] | None = None   # J [N m]
    #: optional provider of joint moments, ``f(geom, q, i, origin) -> (M_gravity, M_contact)`` (base frame,
    #: about ``origin``, [N m]); :class:`LateralCompliance` computes them itself when None
    moments: Any = None
    time: Any = None              # [s] the points' time stamps (``time_s``)
    #: K columns [1]: each point's place in the capture of its measurement, -1/2 (first) to +1/2 (last), in the
    #: column of its measurement (0 in the others; :func:`arm_model.model.capture_columns`)
    capture: list[Any] | None = None
    motion: list[Any] | None = None   # J [1] the sign of each reading's last move (model.reading_motion)


@dataclass
class Geometry:
    rows: list[list[Any]]         # J x (theta_offset [rad], d [m], a [m], alpha [rad])
    p_last: list[Any]             # 3 [m]
    compliance: list[Any]         # 3 [m/N]


def _torques(tau: list[Any] | None, name: str) -> list[Any]:
    """The per-joint torques of ``inputs`` an effect reads (an evaluator supplies what :meth:`Effect.needs`)."""
    if tau is None:
        raise ValueError(f"the effect needs the per-point joint torques '{name}'")
    return tau


def _joint(desc: ArmDescription | None, i: int, prefix: str = "j") -> str:
    """Encoder column ``i`` (0-based) as a person reads it: the joint's name in ``desc``, else ``j<i+1>``."""
    names = getattr(desc, "joint_names", ())
    return names[i] if 0 <= i < len(names) else f"{prefix}{i + 1}"


def _source_index(value: object, what: str) -> int | None:
    """An effect's ``source`` joint (a 0-based index) as an int, or None; else a TypeError naming ``what``."""
    if value is None:
        return None
    if not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < 0:
        raise TypeError(f"{what}: source must be a 0-based joint index or None, got {value!r}")
    return int(value)


def _check_source(key: str, source: int | None, desc: ArmDescription) -> None:
    """A ValueError when the effect ``key``'s source joint is not a joint of ``desc``."""
    if source is not None and source >= desc.n_joints:
        raise ValueError(f"the effect '{key}' takes joint index {source} (0-based) as its source, but "
                         f"the arm has {desc.n_joints} joints")


def _indices(values: object, what: str, *, low: int = 0, high: int | None = None) -> tuple[int, ...]:
    """``values`` as a non-empty tuple of distinct whole numbers in [low, high] (an effect's joints, harmonics), or a
    TypeError/ValueError naming ``what``."""
    if not isinstance(values, (tuple, list)) or not all(isinstance(v, numbers.Integral) and not isinstance(v, bool)
                                                         for v in values):
        raise TypeError(f"{what} must be a tuple of whole numbers, got {values!r}")
    out = tuple(int(v) for v in values)
    if not out or len(set(out)) != len(out) or min(out) < low or (high is not None and max(out) > high):
        raise ValueError(f"{what} must be distinct whole numbers >= {low}{'' if high is None else f' and <= {high}'}"
                         f" (at least one), got {values!r}")
    return out


#: the highest harmonic an effect takes (of a joint angle: a period of 0.36 deg, below any drive's)
MAX_HARMONIC = 1000
#: the largest plausible thermal strain of the links over one session [1] (aluminium's 23e-6 /K over 4 K): the size of a
#: drift's prior over the data's time span (:class:`ThermalDrift`)
DRIFT_STRAIN = 1e-4
#: the seed paper's stylus [m] (hinge to ball) and its FEM compliances [m/N] (bending x, y; axial): the stylus a probe
#: compliance's prior is scaled from (:func:`stylus_compliance`)
PAPER_STYLUS = 0.085
PAPER_STYLUS_COMPLIANCE = (1.42e-5, 1.42e-5, 8.76e-8)
#: the largest plausible play of a joint [rad] (half the band): a robot's gear play is typically 0.01-1 mrad (harmonic
#: drives the least), a measuring arm's bearings far less; the size of a play's physical prior (:class:`JointBacklash`,
#: :class:`JointHysteresis`)
PLAY = 1e-3


@dataclass(frozen=True)
class Effect:
    """Base class. Subclasses set ``key``, implement :meth:`param_defs` and :meth:`apply`.

    ``joints``: 0-based indices of the joints the effect acts on (None: all joints).
    """
    joints: tuple[int, ...] | None = None
    key: str = field(default="effect", init=False, repr=False)
    #: plausible size of an error of each parameter [SI] (None: by unit,
    #: :data:`calibration.identifiability.PRIOR_SCALES`)
    plausible_size: ClassVar[float | None] = None
    #: a calibration parameter of the geometry kind: held, like the description's own parameters, when the
    #: data resolve it only to worse than ``--min-resolution`` of its plausible size (other effects'
    #: parameters are estimated whenever linearly identifiable)
    held_when_weak: ClassVar[bool] = False
    #: the effect models a joint angle's error (its unit rad, its physics a rotation): it acts on the
    #: revolute joints only (by default all of them; a prismatic joint named in ``joints`` is an error)
    revolute_only: ClassVar[bool] = False
    #: the effect changes encoder readings only (``inputs.q``, one value an encoder column), never a row of the
    #: chain: on an arm with a joint mimicking another of its chain, it acts on the master's reading and the
    #: mimicking joint follows it through the ``<mimic>`` formula (the torques are per encoder column already)
    acts_on_readings: ClassVar[bool] = False
    #: the effect belongs to the session it was fitted on, not to the arm (a drift in that session's time): a model
    #: file never holds it (the geometry it writes is the one at the effect's reference; the session's value is
    #: reported beside it), so that applying the model to other data applies no drift it cannot know
    session: ClassVar[bool] = False
    #: :attr:`plausible_size` is a physical maximum (a joint's play), not a guess the data may revise upwards: the
    #: evidence may shrink its prior group's scale below 1, never raise it above (:attr:`calibration.prior.PriorSpec.
    #: capped`)
    physical_size: ClassVar[bool] = False

    def __post_init__(self) -> None:
        """``joints``: None or distinct 0-based joint indices (a TypeError or ValueError here, not deep in a fit)."""
        if self.joints is not None:
            object.__setattr__(self, "joints", _indices(self.joints, f"{self.key}: joints"))

    def needs(self) -> tuple[str, ...]:
        """Per-point inputs the effect needs beyond q and the wrench."""
        return ()

    def joint_indices(self, desc: ArmDescription) -> tuple[int, ...]:
        """The encoder columns the effect acts on (0-based): ``joints``, or by default every joint (every
        revolute joint for :attr:`revolute_only` effects). A ``ValueError`` names a prismatic joint given
        to a revolute-only effect, or, for an effect on the chain's rows (not :attr:`acts_on_readings`), an arm
        with a joint mimicking another joint of its chain (its rows and encoder columns differ)."""
        if desc.coupled and not self.acts_on_readings:
            raise ValueError(f"the effect '{self.key}' acts per joint, and the arm has a joint that mimics another "
                             "joint of its chain: per-joint effects on the chain's rows are not supported there")
        if self.joints is None:
            return desc.revolute_columns if self.revolute_only else tuple(range(desc.n_joints))
        for i in self.joints:
            if i >= desc.n_joints:
                raise ValueError(f"the effect '{self.key}' acts on joint index {i} (0-based), but the arm has "
                                 f"{desc.n_joints} joints")
            if self.revolute_only and desc.encoders[i].prismatic:
                raise ValueError(f"the effect '{self.key}' models a joint angle's error; joint "
                                 f"'{desc.encoders[i].name}' is prismatic")
        return tuple(self.joints)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        """(name, SI unit) of each parameter, in the order :meth:`apply` reads them."""
        raise NotImplementedError

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        """Modify ``inputs`` and ``geom`` in place (lists of columns/expressions)."""
        raise NotImplementedError

    def lower_bounds(self, desc: ArmDescription) -> list[float]:
        """The smallest physical value [SI] of each parameter (:meth:`param_defs` order): ``-inf`` (none) by
        default; a compliance cannot be negative in total (:meth:`ArmModel.lower_bounds` gathers them; every fit
        holds a parameter at its bound, the model-file reader refuses a value below it)."""
        return [-math.inf] * len(self.param_defs(desc))

    def prior_sizes(self, desc: ArmDescription, inputs: ModelInputs) -> list[tuple[float, str]] | None:
        """The size [SI] of each parameter's prior (:meth:`param_defs` order) and whence, from the data's per-point
        ``inputs`` (numpy columns) where the effect's scale lies in them (a drift's, in the data's time span); None:
        :attr:`plausible_size`, or a size by unit (:mod:`calibration.prior`)."""
        return None

    def sides(self, desc: ArmDescription, inputs: ModelInputs, ops: Any) -> list[Any] | None:
        """For an effect each of whose parameters acts through a per-point sign only (a joint's play): that sign
        (-1, 0, +1; one column a parameter, :meth:`param_defs` order), the side of the play each point rests on; None
        for the others. A parameter whose points lie nearly all on one side is the joint's offset in the data
        (:func:`calibration.prior.prior_only`)."""
        return None

    def describe(self, desc: ArmDescription | None = None) -> str:
        """The effect and its joints: ``j3`` by encoder column, or by name with the arm's description ``desc``."""
        return self.key if self.joints is None else f"{self.key}({', '.join(_joint(desc, i) for i in self.joints)})"


@dataclass(frozen=True)
class EncoderEccentricity(Effect):
    """Encoder reading error: ``q_true = q_enc + sum_h c_h cos(h q_enc) + s_h sin(h q_enc)``
    (amplitude ``hypot(c, s)``, phase ``atan2(c, s)`` of ``a sin(h q + phi)``) for harmonics ``harmonics``.
    The cos/sin pair is linear in the reading's error, so an amplitude near zero is no singularity. An angle
    error of the joint's reading, like the description's ``theta_offset``: a harmonic the data resolve only
    to worse than ``--min-resolution`` of the plausible size of an angle error is held at its value (e.g. the
    last joint's, when the ball is near that joint's axis), as the description's own parameters are."""
    harmonics: tuple[int, ...] = (1, 2)
    key: str = field(default="eccentricity", init=False, repr=False)
    acts_on_readings: ClassVar[bool] = True
    revolute_only: ClassVar[bool] = True
    held_when_weak: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "harmonics", _indices(self.harmonics, "eccentricity: harmonics", low=1,
                                                       high=MAX_HARMONIC))

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        out = []
        for i in self.joint_indices(desc):
            for h in self.harmonics:
                out += [(f"{desc.joint_names[i]}.ecc{h}_cos", "rad"), (f"{desc.joint_names[i]}.ecc{h}_sin", "rad")]
        return out

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        k = 0
        q = list(inputs.q)
        for i in self.joint_indices(desc):
            for h in self.harmonics:
                c, s = params[k], params[k + 1]
                k += 2
                q[i] = q[i] + c * ops.cos(h * inputs.q[i]) + s * ops.sin(h * inputs.q[i])
        inputs.q = q


@dataclass(frozen=True)
class JointGain(Effect):
    """Encoder scale (gain) error: ``q_true = (1 + g) q_enc`` for each joint of ``joints`` (all by
    default), one gain ``g`` [1] a joint (a wrong gear ratio or encoder line count, a standard parameter of
    robot calibration). The joint's zero offset stays the description's ``theta_offset``: a gain about
    another zero differs from this one by an offset only. Over a small range of the joint's angle the gain
    and the offset (or the first harmonic of an eccentricity) are nearly the same signature; the fit's
    covariance says how well the data tell them apart. A gain the data resolve only to worse than
    ``--min-resolution`` of :attr:`plausible_size` is held at its value (e.g. the last joint's, when the
    ball is near that joint's axis), as the description's own parameters are.

    ``source`` (0-based; None: the joint's own reading): the reading of another joint instead, ``q_i += g
    q_enc_source``, a linear cross-coupling (the coupling ratio of a differential wrist, a cable or a belt
    wound by another joint: parameter ``jN.gain_by_jK``), the linear counterpart of
    :class:`JointHarmonics`' ``source``."""
    source: int | None = None
    key: str = field(default="joint_gain", init=False, repr=False)
    acts_on_readings: ClassVar[bool] = True
    plausible_size: ClassVar[float] = 1e-2     # a 1 % scale error of an encoder is already large
    held_when_weak: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "source", _source_index(self.source, "joint_gain"))

    def _source(self, desc: ArmDescription, i: int) -> int:
        _check_source(self.key, self.source, desc)
        return i if self.source is None else self.source

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        out = []
        for i in self.joint_indices(desc):
            k = self._source(desc, i)
            out.append((f"{desc.joint_names[i]}.gain" + ("" if k == i else f"_by_{desc.joint_names[k]}"), "1"))
        return out

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        q0 = list(inputs.q)
        q = list(inputs.q)
        for k, i in enumerate(self.joint_indices(desc)):
            q[i] = q[i] + params[k] * q0[self._source(desc, i)]
        inputs.q = q

    def describe(self, desc: ArmDescription | None = None) -> str:
        base = super().describe(desc)
        if self.source is None:
            return base
        src = f" of {_joint(desc, self.source, 'q')}"
        return base[:-1] + src + ")" if base.endswith(")") else base + f"({src.strip()})"


@dataclass(frozen=True)
class JointCompliance(Effect):
    """Joint i turns by ``c_i (tau_contact_i - tau_gravity_i)`` beyond its encoder. With
    ``gravity=False`` or ``contact=False`` that part is left out."""
    gravity: bool = True
    contact: bool = True
    key: str = field(default="joint_compliance", init=False, repr=False)
    acts_on_readings: ClassVar[bool] = True
    revolute_only: ClassVar[bool] = True

    def needs(self) -> tuple[str, ...]:
        return tuple(n for n, on in (("tau_gravity", self.gravity), ("tau_contact", self.contact)) if on)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        return [(f"{desc.joint_names[i]}.compliance", "rad/(N m)") for i in self.joint_indices(desc)]

    def lower_bounds(self, desc: ArmDescription) -> list[float]:
        """0: a joint turning against its load is no compliance."""
        return [0.0] * len(self.param_defs(desc))

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        q = list(inputs.q)
        for k, i in enumerate(self.joint_indices(desc)):
            load = 0.0
            if self.contact:
                load = load + _torques(inputs.tau_contact, "tau_contact")[i]
            if self.gravity:
                load = load - _torques(inputs.tau_gravity, "tau_gravity")[i]
            q[i] = q[i] + params[k] * load
        inputs.q = q


@dataclass(frozen=True)
class ThermalGrowth(Effect):
    """Link lengths (d and a; a URDF origin's xyz) grow by ``(1 + alpha (T - 20 °C))``; one alpha [1/K] for the links of
    ``joints`` (all by default), or one per joint with ``per_joint=True``."""
    per_joint: bool = False
    key: str = field(default="thermal", init=False, repr=False)

    def needs(self) -> tuple[str, ...]:
        return ("temperature",)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        if self.per_joint:
            return [(f"{desc.joint_names[i]}.thermal_alpha", "1/K") for i in self.joint_indices(desc)]
        return [("links.thermal_alpha", "1/K")]

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        dt = inputs.temperature - REFERENCE_TEMPERATURE_C
        _grow_links(desc, geom, self.joint_indices(desc),
                    [p * dt for p in params] if self.per_joint else [params[0] * dt])


def _grow_links(desc: ArmDescription, geom: Geometry, joints: tuple[int, ...], growth: list[Any]) -> None:
    """Scale the link lengths (d and a; a URDF origin's xyz) of ``joints`` by ``1 + growth`` (one growth [1] for
    all of them, or one per joint): the thermal growth of the links, whatever drives it."""
    rows = [list(r) for r in geom.rows]
    for k, i in enumerate(joints):
        scale = 1.0 + growth[k if len(growth) > 1 else 0]
        for m in desc.length_indices:
            rows[i][m] = rows[i][m] * scale
    geom.rows = rows


@dataclass(frozen=True)
class ThermalDrift(Effect):
    """The links grow with the time instead of a measured temperature: every link length scaled by
    ``1 + r (t - t_ref)^power``, ``t`` the points' time stamps [s], ``t_ref`` = ``reference_time_s``; ``power`` 1
    (``links.drift_rate`` [1/s]) or 2 (``links.drift_rate2`` [1/s^2], a drift that speeds up or turns; added on
    top of the first, each term scales the lengths). For a session whose room drifts while the arm logs no
    temperature: the drift is this session's (its time origin and its room's), not the arm's, and the fitted
    geometry is the one at ``t_ref``. The growth itself is :class:`ThermalGrowth`'s (one code for both)."""
    power: int = 1
    reference_time_s: float = 0.0
    key: str = field(default="thermal_drift", init=False, repr=False)
    session: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        if isinstance(self.power, bool) or self.power not in (1, 2):
            raise ValueError(f"thermal_drift: power must be 1 or 2, got {self.power!r}")
        if (isinstance(self.reference_time_s, bool) or not isinstance(self.reference_time_s, numbers.Real)
                or not math.isfinite(self.reference_time_s)):
            raise ValueError(f"thermal_drift: reference_time_s must be a finite time [s], got "
                             f"{self.reference_time_s!r}")

    def prior_sizes(self, desc: ArmDescription, inputs: ModelInputs) -> list[tuple[float, str]] | None:
        """:data:`DRIFT_STRAIN` over the data's largest time from ``reference_time_s`` (to the power ``power``)."""
        if inputs.time is None or not len(inputs.time):
            return None
        span = float(max(abs(float(min(inputs.time)) - self.reference_time_s),
                         abs(float(max(inputs.time)) - self.reference_time_s)))
        if not math.isfinite(span) or span <= 0:
            return None
        return [(DRIFT_STRAIN / span ** self.power, f"a link strain of {DRIFT_STRAIN:g} over the data's {span:.4g} s "
                                                    "from the reference time")]

    @staticmethod
    def reference_of(time: Any) -> float:
        """The time origin a session's drift is taken about: the middle of its time stamps' span [s], to 1 ms."""
        return float(round(0.5 * (float(min(time)) + float(max(time))), 3))

    def needs(self) -> tuple[str, ...]:
        return ("time",)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        return [("links.drift_rate", "1/s")] if self.power == 1 else [("links.drift_rate2", "1/s^2")]

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        if inputs.time is None:
            raise ValueError("the effect 'thermal_drift' needs the per-point time 'time'")
        dt = inputs.time - self.reference_time_s
        _grow_links(desc, geom, self.joint_indices(desc), [params[0] * (dt if self.power == 1 else dt * dt)])


@dataclass(frozen=True)
class ForceSensorError(Effect):
    """The sensor reads ``f_meas = (1 + g) f_true + o`` per probe axis (``cross_talk`` adds
    ``f_meas_x += k_xy f_true_y`` etc. in the simulator's truth only); the model maps the reading
    back: ``f_true = (f_meas - o) / (1 + g)``. ``axes``: which of x, y, z (0, 1, 2)."""
    axes: tuple[int, ...] = (0, 1, 2)
    offsets: bool = True
    key: str = field(default="force_sensor", init=False, repr=False)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        out = [(f"force.gain_{'xyz'[a]}", "1") for a in self.axes]
        if self.offsets:
            out += [(f"force.offset_{'xyz'[a]}", "N") for a in self.axes]
        return out

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        w = list(inputs.wrench)
        n = len(self.axes)
        for k, a in enumerate(self.axes):
            off = params[n + k] if self.offsets else 0.0
            w[a] = (w[a] - off) / (1.0 + params[k])
        inputs.wrench = w


def stylus_compliance(length: float) -> tuple[float, float, float]:
    """The compliances [m/N] (bending x, y; axial) of a stylus ``length`` [m] long made as the seed paper's 85 mm
    one (:data:`PAPER_STYLUS_COMPLIANCE`): a cantilever's bending compliance grows with the cube of its length
    (``L^3 / (3 E I)``), a rod's axial one with the length (``L / (E A)``)."""
    r = length / PAPER_STYLUS
    bx, by, ax = PAPER_STYLUS_COMPLIANCE
    return bx * r ** 3, by * r ** 3, ax * r


def _stylus_sizes(desc: ArmDescription, terms: list[str]) -> list[tuple[float, str]] | None:
    """The prior size [m/N] of each compliance term ("xx", "yy", "zz", "xy", "xz", "yz") of the probe: the compliance
    of the description's stylus made as the seed paper's (:func:`stylus_compliance`), an off-diagonal term the
    geometric mean of its two diagonal ones (the largest a positive compliance matrix allows); None for a tip without
    a stylus (a size by unit)."""
    length = desc.probe.stylus_length
    if not length > 0:
        return None
    c = dict(zip(("xx", "yy", "zz"), stylus_compliance(length), strict=True))
    c.update(xy=math.sqrt(c["xx"] * c["yy"]), xz=math.sqrt(c["xx"] * c["zz"]), yz=math.sqrt(c["yy"] * c["zz"]))
    how = (f"the compliance of a {length * 1e3:.4g} mm stylus made as the seed paper's {PAPER_STYLUS * 1e3:g} mm one "
           f"(bending {PAPER_STYLUS_COMPLIANCE[0] * 1e6:g} um/N x (L / {PAPER_STYLUS * 1e3:g} mm)^3, axial "
           f"{PAPER_STYLUS_COMPLIANCE[2] * 1e6:g} um/N x L / {PAPER_STYLUS * 1e3:g} mm)")
    return [(c[t], f"{c[t] * 1e6:.3g} um/N: {how}") for t in terms]


@dataclass(frozen=True)
class ProbeCompliance(Effect):
    """Bending compliance of the probe beyond the declared one: one increment [m/N] for both
    bending axes (``anisotropic=False``) or one per axis; ``axial=True`` adds one along z."""
    anisotropic: bool = False
    axial: bool = False
    key: str = field(default="probe_compliance", init=False, repr=False)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        out = ([("probe.dcompliance_x", "m/N"), ("probe.dcompliance_y", "m/N")] if self.anisotropic
               else [("probe.dcompliance_bend", "m/N")])
        if self.axial:
            out.append(("probe.dcompliance_z", "m/N"))
        return out

    def lower_bounds(self, desc: ArmDescription) -> list[float]:
        """Minus the description's compliance each increment adds to (the total cannot be negative; one
        increment of both bending axes: the smaller of theirs)."""
        p = desc.probe
        low = {"probe.dcompliance_x": -p.bending_compliance_x, "probe.dcompliance_y": -p.bending_compliance_y,
               "probe.dcompliance_bend": -min(p.bending_compliance_x, p.bending_compliance_y),
               "probe.dcompliance_z": -p.axial_compliance}
        return [low[n] for n, _ in self.param_defs(desc)]

    def prior_sizes(self, desc: ArmDescription, inputs: ModelInputs) -> list[tuple[float, str]] | None:
        """The compliance of the description's stylus made as the seed paper's (:func:`stylus_compliance`)."""
        terms = {"probe.dcompliance_x": "xx", "probe.dcompliance_y": "yy", "probe.dcompliance_bend": "xx",
                 "probe.dcompliance_z": "zz"}
        return _stylus_sizes(desc, [terms[n] for n, _ in self.param_defs(desc)])

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        c = list(geom.compliance)
        if self.anisotropic:
            c[0], c[1] = c[0] + params[0], c[1] + params[1]
        else:
            c[0], c[1] = c[0] + params[0], c[1] + params[0]
        if self.axial:
            c[2] = c[2] + params[-1]
        geom.compliance = c


EFFECTS: dict[str, type[Effect]] = {
    str(cls.__dataclass_fields__["key"].default): cls
    for cls in (EncoderEccentricity, JointGain, JointCompliance, ThermalGrowth, ForceSensorError, ProbeCompliance)}


def effect_from_name(key: str, **kwargs: Any) -> Effect:
    """An effect by its key (``"eccentricity"``, ``"joint_compliance"``, ``"thermal"``,
    ``"force_sensor"``, ``"probe_compliance"``)."""
    try:
        return EFFECTS[key](**kwargs)
    except KeyError:
        raise KeyError(f"unknown effect {key!r}; known: {', '.join(EFFECTS)}") from None


# ---------------------------------------------------------------------------------------------
# effects the closed loop synthesises from the residual's structure (beyond the library above)

def _chain(desc: ArmDescription, geom: Geometry, q: Any, upto: int, point: Any, ops: Any) -> list[Any]:
    """``point`` given in frame ``upto - 1`` (the end of row ``upto - 1``) in base coordinates."""
    from .chain import chain_point
    return list(chain_point(desc.convention, geom.rows[:upto], q, point, ops, desc.chain_joints[:upto]))


def _perpendicular(axis: Any) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """Two constant unit vectors (u, v) with (u, v, axis) right-handed and orthonormal."""
    import numpy as np
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    e = np.array([0.0, 1.0, 0.0]) if abs(a[0]) > 0.9 else np.array([1.0, 0.0, 0.0])
    u = e - (e @ a) * a
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    return (float(u[0]), float(u[1]), float(u[2])), (float(v[0]), float(v[1]), float(v[2]))


def _sub(a: Any, b: Any) -> list[Any]:
    return [a[k] - b[k] for k in range(3)]


def _cross(a: Any, b: Any) -> list[Any]:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a: Any, b: Any) -> Any:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


#: an origin and the axes (x, y, z) of a frame, in the base frame
Frame = tuple[list[Any], list[list[Any]]]


def joint_frame(desc: ArmDescription, geom: Geometry, q: Any, i: int, ops: Any) -> Frame:
    """Origin and axes (x, y, z) [m, unit] in the base frame of joint ``i``'s frame, the frame that turns
    with the joint: for standard DH the frame ``i - 1`` turned by ``Rz(theta_offset + q)`` (x along the
    common normal); for modified DH and URDF the joint's child frame (for URDF x, y are a fixed pair of
    unit vectors perpendicular to the joint's axis, see :func:`_perpendicular`)."""
    if desc.convention == "dh":
        o = _chain(desc, geom, q, i, (0.0, 0.0, 0.0), ops)
        theta = geom.rows[i][0] + q[i]
        c, s = ops.cos(theta), ops.sin(theta)
        ex, ey, ez = (c, s, 0.0), (-s, c, 0.0), (0.0, 0.0, 1.0)
        return o, [_sub(_chain(desc, geom, q, i, e, ops), o) for e in (ex, ey, ez)]
    o = _chain(desc, geom, q, i + 1, (0.0, 0.0, 0.0), ops)
    if desc.convention == "urdf":
        axes = desc.axes
        axis = None if axes is None else axes[i]
        if axis is None:
            raise ValueError(f"joint {i} of a URDF chain has no axis")
        u, v = _perpendicular(axis)
        vecs: tuple[tuple[float, float, float], ...] = (u, v, axis)
    else:
        vecs = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    return o, [_sub(_chain(desc, geom, q, i + 1, e, ops), o) for e in vecs]


def last_frame(desc: ArmDescription, geom: Geometry, q: Any, ops: Any) -> Frame:
    """Origin and axes (x, y, z) of the last joint frame in the base frame (the probe frame's axes:
    :func:`probe_axes`)."""
    n = len(desc.joints)
    o = _chain(desc, geom, q, n, (0.0, 0.0, 0.0), ops)
    return o, [_sub(_chain(desc, geom, q, n, e, ops), o) for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                                                                    (0.0, 0.0, 1.0))]


def probe_axes(desc: ArmDescription, axes: list[list[Any]]) -> list[list[Any]]:
    """The probe frame's axes (x, y, z) in the base frame from the last joint frame's ``axes``
    (the probe's rotation R_last_probe of the description; the same axes for an unrotated probe)."""
    r = desc.probe.rotation
    if r is None:
        return axes
    return [[sum(axes[m][a] * r[m][k] for m in range(3)) for a in range(3)] for k in range(3)]


def _shift_ball(desc: ArmDescription, geom: Geometry, q: Any, d_base: list[Any], ops: Any,
                frame: Frame | None = None) -> None:
    """Move the ball by ``d_base`` (base frame) at this pose: ``p_last += R^T d``."""
    _, axes = last_frame(desc, geom, q, ops) if frame is None else frame
    geom.p_last = [geom.p_last[k] + _dot(axes[k], d_base) for k in range(3)]


@dataclass(frozen=True)
class _JointPlay(Effect):
    """A joint's play: joint i sits ``b_i s_i`` beyond its encoder, ``s_i`` a per-point sign (-1, 0, +1) that says
    which side of the play the joint rests on (:meth:`signs`); ``b`` [rad], half the band, linear in the model.

    Its prior (:mod:`calibration.prior`): :attr:`plausible_size` :data:`PLAY` (1 mrad, the largest plausible half
    band of a joint's play), a physical maximum the evidence may shrink, never exceed; a play whose points lie nearly
    all on one side (or whose sign is nil: no gravity torque, no motion; or whose sides come in too few runs of the
    capture order) is the joint's offset, or a drift, in the data, and the prior alone holds it."""
    acts_on_readings: ClassVar[bool] = True
    revolute_only: ClassVar[bool] = True
    plausible_size: ClassVar[float] = PLAY
    physical_size: ClassVar[bool] = True
    #: the parameter's name after the joint's (``j4.backlash``)
    parameter: ClassVar[str] = "play"

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        return [(f"{desc.joint_names[i]}.{self.parameter}", "rad") for i in self.joint_indices(desc)]

    def signs(self, inputs: ModelInputs, ops: Any) -> list[Any]:
        """The side of the play of every joint (one column or expression a joint)."""
        raise NotImplementedError

    def sides(self, desc: ArmDescription, inputs: ModelInputs, ops: Any) -> list[Any]:
        side = self.signs(inputs, ops)
        return [side[i] for i in self.joint_indices(desc)]

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        side = self.signs(inputs, ops)
        q = list(inputs.q)
        for k, i in enumerate(self.joint_indices(desc)):
            q[i] = q[i] + params[k] * side[i]
        inputs.q = q


@dataclass(frozen=True)
class JointBacklash(_JointPlay):
    """Play of joint i closed by gravity: the joint sits ``b_i sign(-tau_gravity_i)`` beyond its encoder, ``b_i``
    to the side its gravity load pushes it (the sign convention of :class:`JointCompliance`'s gravity part), whatever
    the load's size: a gear's or a bearing's play, closed one way or the other as the torque the joint holds against
    the links' weight changes sign. Piecewise constant in the torque; where the torque changes sign within the play
    itself, the joint floats in its middle (sign 0, :meth:`arm_model.model.ArmModel.equilibrium_aux`)."""
    key: str = field(default="joint_backlash", init=False, repr=False)
    parameter: ClassVar[str] = "backlash"

    def needs(self) -> tuple[str, ...]:
        return ("tau_gravity",)

    def lower_bounds(self, desc: ArmDescription) -> list[float]:
        """0: gravity carries the links through the play to the side it pushes them, beyond a reading taken on the
        drive's side of the play (a reading on the link's side sees no play at all): never against the load."""
        return [0.0] * len(self.param_defs(desc))

    def signs(self, inputs: ModelInputs, ops: Any) -> list[Any]:
        return [-ops.sign(t) for t in _torques(inputs.tau_gravity, "tau_gravity")]


@dataclass(frozen=True)
class JointHysteresis(_JointPlay):
    """Hysteresis of joint i by the direction it last turned: the joint sits ``h_i m_i`` beyond its encoder, ``m_i``
    the sign of its last move onto the point (``ModelInputs.motion``, :func:`arm_model.model.points_motion`: as
    measured, a points file's ``q1_move_sign`` ..., else its reading's move from the point captured before it): a
    play or an encoder's hysteresis that the last motion closes, a robot's backlash when it drives from posture to
    posture.

    Signed, unlike :class:`JointBacklash` (no lower bound; its width is ``|h|``): ``h > 0`` when the reading lags the
    joint (an encoder's hysteresis, a measuring arm's joint moved by hand), ``h < 0`` when the joint lags the reading
    (a link dragged through its play by a drive whose encoder sits on the motor)."""
    key: str = field(default="joint_hysteresis", init=False, repr=False)
    parameter: ClassVar[str] = "hysteresis"

    def needs(self) -> tuple[str, ...]:
        return ("motion",)

    def signs(self, inputs: ModelInputs, ops: Any) -> list[Any]:
        if inputs.motion is None:
            raise ValueError("the effect 'joint_hysteresis' needs the per-point 'motion' (model.reading_motion)")
        return list(inputs.motion)


@dataclass(frozen=True)
class JointHarmonics(Effect):
    """Joint-angle error periodic in an angle: ``q_i += sum_h c_h cos(h q_s) + s_h sin(h q_s)`` for the
    harmonics ``harmonics`` of the reading of joint ``source`` (0-based; None: the joint's own angle, a
    cross-coupling otherwise, e.g. a cable or a counterbalance). ``joints``: the joint(s) i it acts on."""
    source: int | None = None
    harmonics: tuple[int, ...] = (1, 2, 3)
    key: str = field(default="joint_harmonics", init=False, repr=False)
    acts_on_readings: ClassVar[bool] = True
    revolute_only: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "harmonics", _indices(self.harmonics, "joint_harmonics: harmonics", low=1,
                                                       high=MAX_HARMONIC))
        object.__setattr__(self, "source", _source_index(self.source, "joint_harmonics"))

    def _suffix(self, desc: ArmDescription, i: int) -> str:
        _check_source(self.key, self.source, desc)
        return "" if self.source is None or self.source == i else f"_by_{desc.joint_names[self.source]}"

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        out = []
        for i in self.joint_indices(desc):
            sfx = self._suffix(desc, i)
            for h in self.harmonics:
                out += [(f"{desc.joint_names[i]}.harm{h}_cos{sfx}", "rad"),
                        (f"{desc.joint_names[i]}.harm{h}_sin{sfx}", "rad")]
        return out

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        q0 = list(inputs.q)
        q = list(inputs.q)
        k = 0
        for i in self.joint_indices(desc):
            src = q0[i if self.source is None else self.source]
            for h in self.harmonics:
                q[i] = q[i] + params[k] * ops.cos(h * src) + params[k + 1] * ops.sin(h * src)
                k += 2
        inputs.q = q

    def describe(self, desc: ArmDescription | None = None) -> str:
        src = "" if self.source is None else f" of {_joint(desc, self.source, 'q')}"
        js = "" if self.joints is None else ", ".join(_joint(desc, i) for i in self.joints)
        return f"{self.key}({js}; h {','.join(map(str, self.harmonics))}{src})"


@dataclass(frozen=True)
class ProbeThermalGrowth(Effect):
    """The probe (ball centre ``p_last`` in the last joint frame) grows by ``(1 + alpha (T - 20 °C))``."""
    key: str = field(default="probe_thermal", init=False, repr=False)

    def needs(self) -> tuple[str, ...]:
        return ("temperature",)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        return [("probe.thermal_alpha", "1/K")]

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        scale = 1.0 + params[0] * (inputs.temperature - REFERENCE_TEMPERATURE_C)
        geom.p_last = [v * scale for v in geom.p_last]


#: parameter order of the symmetric compliance increment of :class:`ProbeComplianceMatrix`
_MATRIX_TERMS = ("xx", "yy", "zz", "xy", "xz", "yz")


@dataclass(frozen=True)
class ProbeComplianceMatrix(Effect):
    """The probe's compliance as a full symmetric 3x3 matrix in the probe frame: an increment ``dC`` of
    the declared (diagonal) one, so the ball moves by about ``(diag(c) + dC) f`` under the force ``f``
    (probe frame). The diagonal adds to the declared compliance (the elastic joints), the off-diagonal
    terms move the ball by ``dC_off f``. ``terms``: which of xx, yy, zz, xy, xz, yz are parameters (the
    others zero), e.g. only the off-diagonal ones beside a diagonal :class:`ProbeCompliance`."""
    terms: tuple[str, ...] = _MATRIX_TERMS
    key: str = field(default="probe_compliance_matrix", init=False, repr=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        bad = set(self.terms) - set(_MATRIX_TERMS)
        if bad or len(set(self.terms)) != len(self.terms) or not self.terms:
            raise ValueError(f"terms must be distinct entries of {_MATRIX_TERMS}, got {self.terms}")

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        return [(f"probe.dcompliance_{t}", "m/N") for t in _MATRIX_TERMS if t in self.terms]

    def lower_bounds(self, desc: ArmDescription) -> list[float]:
        """A diagonal term: minus the description's compliance on its axis (a compliance matrix's diagonal is not
        negative); an off-diagonal term: none."""
        p = desc.probe
        low = {"xx": -p.bending_compliance_x, "yy": -p.bending_compliance_y, "zz": -p.axial_compliance}
        return [low.get(t, -math.inf) for t in _MATRIX_TERMS if t in self.terms]

    def prior_sizes(self, desc: ArmDescription, inputs: ModelInputs) -> list[tuple[float, str]] | None:
        """The compliance of the description's stylus made as the seed paper's (:func:`stylus_compliance`), an
        off-diagonal term the geometric mean of its diagonal ones."""
        return _stylus_sizes(desc, [t for t in _MATRIX_TERMS if t in self.terms])

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        it = iter(params)
        cxx, cyy, czz, cxy, cxz, cyz = (next(it) if t in self.terms else 0.0 for t in _MATRIX_TERMS)
        fx, fy, fz = inputs.wrench[0], inputs.wrench[1], inputs.wrench[2]
        geom.compliance = [geom.compliance[0] + cxx, geom.compliance[1] + cyy, geom.compliance[2] + czz]
        d = [cxy * fy + cxz * fz, cxy * fx + cyz * fz, cxz * fx + cyz * fy]     # probe frame
        r = desc.probe.rotation
        if r is not None:                                                       # into the last joint frame
            d = [r[k][0] * d[0] + r[k][1] * d[1] + r[k][2] * d[2] for k in range(3)]
        geom.p_last = [geom.p_last[k] + d[k] for k in range(3)]


@dataclass(frozen=True)
class ApproachOffset(Effect):
    """Approach-direction (probe lobing) offset: the ball moves by ``B u`` (base frame), ``u`` the stylus
    direction (probe z) in the base frame, which is the part's frame up to a constant rotation (the
    parts do not move during a campaign). ``B`` is 3x3: parameter ``approach.d<a>_u<b>`` [m] is the
    offset along base axis a per unit stylus component b. Its part ``b I`` is a probe-length error
    (the probe offset absorbs it)."""
    key: str = field(default="approach_offset", init=False, repr=False)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        return [(f"approach.d{a}_u{b}", "m") for a in "xyz" for b in "xyz"]

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        frame = last_frame(desc, geom, inputs.q, ops)
        u = probe_axes(desc, frame[1])[2]
        d = [params[3 * a] * u[0] + params[3 * a + 1] * u[1] + params[3 * a + 2] * u[2] for a in range(3)]
        _shift_ball(desc, geom, inputs.q, d, ops, frame)


def gravity_moment(desc: ArmDescription, geom: Geometry, q: Any, i: int, origin: Any, ops: Any) -> list[Any]:
    """Moment [N m] (base frame) of gravity on the links joint ``i`` moves, about ``origin``."""
    from .description import GRAVITY
    g = [float(v) for v in GRAVITY]
    m = [0.0, 0.0, 0.0]
    for k in range(i, len(desc.joints)):
        jr = desc.joints[k]
        if jr.mass <= 0:
            continue
        c = _chain(desc, geom, q, k + 1, jr.com, ops)
        t = _cross(_sub(c, origin), [jr.mass * gk for gk in g])
        m = [m[a] + t[a] for a in range(3)]
    return m


def contact_moment(desc: ArmDescription, geom: Geometry, q: Any, wrench: Any, origin: Any, ops: Any,
                   frame: Frame | None = None) -> list[Any]:
    """Moment [N m] (base frame) about ``origin`` of the contact wrench at the ball (probe frame)."""
    o_last, axes = last_frame(desc, geom, q, ops) if frame is None else frame
    ball = [o_last[a] + sum(axes[k][a] * geom.p_last[k] for k in range(3)) for a in range(3)]
    pa = probe_axes(desc, axes)
    f = [sum(pa[k][a] * wrench[k] for k in range(3)) for a in range(3)]
    mt = [sum(pa[k][a] * wrench[3 + k] for k in range(3)) for a in range(3)]
    t = _cross(_sub(ball, origin), f)
    return [t[a] + mt[a] for a in range(3)]


@dataclass(frozen=True)
class LateralCompliance(Effect):
    """Off-axis (lateral) compliance of joint i: the links it moves tilt about the joint frame's x and y
    axes (:func:`joint_frame`) through its origin by ``c_x M_x`` and ``c_y M_y`` [rad], ``M`` the moment
    [N m] there of gravity on those links and of the contact wrench (``gravity``/``contact`` select);
    the ball moves by ``e x (ball - origin)`` (small rotation ``e``). The moments come from the masses
    and centres of mass of the description (the axial part of ``M`` is ``tau_contact - tau_gravity``).
    An evaluator may supply them through ``ModelInputs.moments`` (Pinocchio does, by RNEA). A prismatic
    joint has it too: its carriage (the joint's child frame, where the slide has put it) tilts under the
    moment of what it carries, as a lift column or a linear axis' carriage does."""
    gravity: bool = True
    contact: bool = True
    key: str = field(default="lateral_compliance", init=False, repr=False)

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        out = []
        for i in self.joint_indices(desc):
            out += [(f"{desc.joint_names[i]}.lateral_compliance_x", "rad/(N m)"),
                    (f"{desc.joint_names[i]}.lateral_compliance_y", "rad/(N m)")]
        return out

    def lower_bounds(self, desc: ArmDescription) -> list[float]:
        """0: the tilt about an axis under the moment about it is a diagonal term of the joint's (positive
        semi-definite) compliance; a link tilting against the moment is no compliance."""
        return [0.0] * len(self.param_defs(desc))

    def gravity_loads(self, desc: ArmDescription, q: Any) -> list[Any]:
        """The load each parameter multiplies at the description's own geometry: per joint of the effect,
        the moment [N m] of gravity on the links it moves about its frame's x and about its y axis, one
        array (N,) a parameter, for angles ``q`` (N, J) [rad] (the size of a compliance's prior:
        :mod:`calibration.prior`)."""
        import numpy as np

        from .chain import NUMPY_OPS
        from .params import split_params
        rows, p_last, compliance = split_params(desc, None)
        geom = Geometry([list(r) for r in rows], list(p_last), list(compliance))
        cols = list(np.asarray(q, dtype=float).T)
        out = []
        for i in self.joint_indices(desc):
            o, (ux, uy, _) = joint_frame(desc, geom, cols, i, NUMPY_OPS)
            m = gravity_moment(desc, geom, cols, i, o, NUMPY_OPS)
            out += [np.asarray(_dot(m, ux), dtype=float) * np.ones(len(cols[0])),
                    np.asarray(_dot(m, uy), dtype=float) * np.ones(len(cols[0]))]
        return out

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        q = inputs.q
        last = last_frame(desc, geom, q, ops)
        ball = [last[0][a] + sum(last[1][k][a] * geom.p_last[k] for k in range(3)) for a in range(3)]
        shift = [0.0, 0.0, 0.0]
        for k, i in enumerate(self.joint_indices(desc)):
            o, (ux, uy, _) = joint_frame(desc, geom, q, i, ops)
            if inputs.moments is not None:
                mg, mc = inputs.moments(geom, q, i, o)
            else:
                mg = gravity_moment(desc, geom, q, i, o, ops) if self.gravity else None
                mc = contact_moment(desc, geom, q, inputs.wrench, o, ops, last) if self.contact else None
            m = [0.0, 0.0, 0.0]
            for part, on in ((mg, self.gravity), (mc, self.contact)):
                if on:
                    m = [m[a] + part[a] for a in range(3)]
            ex, ey = params[2 * k] * _dot(m, ux), params[2 * k + 1] * _dot(m, uy)
            e = [ex * ux[a] + ey * uy[a] for a in range(3)]
            t = _cross(e, _sub(ball, o))
            shift = [shift[a] + t[a] for a in range(3)]
        _shift_ball(desc, geom, q, shift, ops, last)


@dataclass(frozen=True)
class ArtefactDrift(Effect):
    """The artefact (or the arm's base under it) creeping while one measurement is captured: the artefact of
    measurement ``m`` sits at ``c + D_m s`` when a point is taken, ``c`` its place at the middle of the capture and
    ``s`` the point's place in the capture, -1/2 at the first point to +1/2 at the last (``ModelInputs.capture``:
    the time stamps where the measurement has them, else its rows' order, :func:`arm_model.model.capture_columns`).
    ``D_m`` [m] (base frame; parameters ``<m>.drift_x/y/z``) is the artefact's whole displacement over the capture,
    one per measurement of ``measurements``: the ball, seen from the artefact, is moved by ``-D_m s``, so every
    feature's fitted place (a seat's centre, a sphere's, a plane) is the one at the middle of its measurement's
    capture. A rigid translation of the whole artefact, linear along the capture; a rotation of it is not modelled.

    A nuisance of the measurement, as the artefact's place is (:attr:`Effect.session`): a model file never holds it,
    and applying the model (``tip``) to other data applies no drift (each measurement has its own, unknown). The
    shift is along the base axes at the joint angles the effects listed before it leave: list it after them (the
    command line puts it after the effects given with it; one the loop adds later turns the shift by that effect's
    own small angle only, a micrometre for a millimetre's drift and a milliradian)."""
    measurements: tuple[str, ...] = ()
    key: str = field(default="artefact_drift", init=False, repr=False)
    session: ClassVar[bool] = True

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.joints is not None:
            raise ValueError("artefact_drift moves the artefact, not a joint: it takes no joints")
        ids = self.measurements
        if (not isinstance(ids, (tuple, list)) or not all(isinstance(m, str) and m for m in ids)
                or len(set(ids)) != len(ids)):
            raise ValueError(f"artefact_drift: measurements must be distinct measurement ids, got {ids!r}")
        object.__setattr__(self, "measurements", tuple(ids))

    def needs(self) -> tuple[str, ...]:
        """The capture places, once bound to measurements (an unbound one, ``--effect artefact_drift`` before the
        data are read, has no parameter and needs nothing)."""
        return ("capture",) if self.measurements else ()

    def param_defs(self, desc: ArmDescription) -> list[tuple[str, str]]:
        return [(f"{m}.drift_{a}", "m") for m in self.measurements for a in "xyz"]

    def prior_sizes(self, desc: ArmDescription, inputs: ModelInputs) -> list[tuple[float, str]] | None:
        """:data:`DRIFT_STRAIN` of the arm's size (:meth:`ArmDescription.chain_length`): the distance from the
        base to an artefact in its reach changing by a thermal strain of the structures between them."""
        size = DRIFT_STRAIN * desc.chain_length
        return [(size, f"a strain of {DRIFT_STRAIN:g} over the arm's size ({desc.chain_length:.3g} m)")] * (
            3 * len(self.measurements))

    def apply(self, desc: ArmDescription, params: list[Any], inputs: ModelInputs, geom: Geometry, ops: Any) -> None:
        if not self.measurements:
            return
        if inputs.capture is None or len(inputs.capture) != len(self.measurements):
            raise ValueError(f"the effect 'artefact_drift' needs one 'capture' column a measurement "
                             f"({len(self.measurements)})")
        d = [0.0, 0.0, 0.0]
        for k, s in enumerate(inputs.capture):
            d = [d[a] - params[3 * k + a] * s for a in range(3)]
        _shift_ball(desc, geom, inputs.q, d, ops)

    def describe(self, desc: ArmDescription | None = None) -> str:
        return f"{self.key}({len(self.measurements)} measurement{'' if len(self.measurements) == 1 else 's'})"


EFFECTS.update({str(cls.__dataclass_fields__["key"].default): cls for cls in
                (JointHarmonics, ProbeThermalGrowth, ProbeComplianceMatrix, ApproachOffset, LateralCompliance,
                 ThermalDrift, JointBacklash, JointHysteresis, ArtefactDrift)})
