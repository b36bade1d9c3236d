"""The arm description (docs/formats.md §2): the single source of every evaluator.

Inside, everything is SI: lengths [m], angles [rad], forces [N], compliances [m/N], masses [kg].
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError, did_you_mean, id_problem, parse_toml, read_text
from .toml_lines import key_path_text, toml_key_lines
from .units import QUANTITY_OF_UNIT, UNIT_FACTORS, implausible, split_unit

if TYPE_CHECKING:
    from .chain import Joint

__all__ = ["JointRow", "Mimic", "Probe", "Visual", "ArmDescription", "load_description", "parse_description",
           "format_description", "GRAVITY", "MIN_STYLUS", "default_lever", "DH_ROW_FIELDS", "URDF_ROW_FIELDS",
           "check_calibration_table", "MAX_PROBING_SCATTER_UM", "MAX_DISCREPANCY_GROWTH_UM_PER_MM"]

DH_ROW_FIELDS = ("theta_offset", "d", "a", "alpha")
URDF_ROW_FIELDS = ("origin_x", "origin_y", "origin_z", "origin_roll", "origin_pitch", "origin_yaw")

#: gravity in the base frame [m/s^2] (docs/formats.md §2: -z of the base frame)
GRAVITY = np.array([0.0, 0.0, -9.81])


JOINT_KINDS = ("revolute", "prismatic")
#: the shortest stylus [m] a compliant probe may have (from its bending hinge to the ball)
MIN_STYLUS = 1e-6


@dataclass(frozen=True)
class Mimic:
    """A URDF ``<mimic>``: the joint's value is ``multiplier * value of joint`` + ``offset`` ([rad] or [m],
    the joint's own unit). ``joint`` names the master: another joint of the chain (then the mimicking
    joint takes no encoder column) or a joint off the chain (then the column holds the master's value)."""
    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class JointRow:
    """One joint row.

    DH and modified DH: ``theta_offset`` [rad], ``d`` [m], ``a`` [m], ``alpha`` [rad].
    URDF chains (convention "urdf"): ``origin`` = (x, y, z [m], roll, pitch, yaw [rad]) of the joint in
    its parent's frame (URDF ``<origin>``) and ``axis`` (unit vector, joint frame); the DH fields are 0.

    ``lower``/``upper`` [rad] are the joint limits (None if not given), ``mass`` [kg] the mass of the
    link this joint moves, ``com`` [m] its centre of mass in the row's end frame (after Rx(alpha) for
    DH; the joint's child frame for MDH and URDF). ``encoder_resolution`` [rad] is the step of the
    joint's encoder (optional key ``encoder_resolution_deg``; None if not given): the uncertainty of
    the corrected ball centres takes ``resolution / sqrt(12)`` per reading (docs/uncertainty.md).

    ``kind``: "revolute" (q an angle [rad]) or "prismatic" (q a length [m]: it adds to ``d`` for DH/MDH,
    it moves along ``axis`` for URDF; its limits and resolution are then lengths [m]). ``mimic``: the
    joint follows another (:class:`Mimic`), None for a joint read by its own encoder.
    """
    name: str
    theta_offset: float = 0.0
    d: float = 0.0
    a: float = 0.0
    alpha: float = 0.0
    lower: float | None = None
    upper: float | None = None
    mass: float = 0.0
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    origin: tuple[float, float, float, float, float, float] | None = None
    axis: tuple[float, float, float] | None = None
    encoder_resolution: float | None = None
    kind: str = "revolute"
    mimic: Mimic | None = None

    @property
    def prismatic(self) -> bool:
        return self.kind == "prismatic"


def _folded_origin(own: ArrayLike, row: ArrayLike) -> tuple[float, float, float, float, float, float]:
    """The URDF origin (x, y, z, roll, pitch, yaw) of ``row``: its xyz, and the origin ``own`` turned about its
    own axes by the angles' differences, ``R(own) Rz(dyaw) Ry(dpitch) Rx(droll)``, as roll, pitch, yaw (``own``'s
    angles kept where the differences are zero)."""
    row, own = np.asarray(row, dtype=float), np.asarray(own, dtype=float)
    d = row[3:6] - own[3:6]
    if not np.any(d):
        return _six(row)
    from .geometry import rotation_xyz, rpy_from_matrix
    rot = rotation_xyz(own[3:6]) @ rotation_xyz((0.0, 0.0, d[2])) @ rotation_xyz((0.0, d[1], 0.0)) \
        @ rotation_xyz((d[0], 0.0, 0.0))
    return _six([*row[:3], *rpy_from_matrix(rot)])


def _six(values: ArrayLike) -> tuple[float, float, float, float, float, float]:
    """A URDF joint origin (x, y, z [m], roll, pitch, yaw [rad]) as six floats."""
    x, y, z, roll, pitch, yaw = (float(v) for v in np.asarray(values, dtype=float))
    return x, y, z, roll, pitch, yaw


def _origin(j: JointRow) -> tuple[float, float, float, float, float, float]:
    """The origin of a URDF row (every row of a URDF chain has one)."""
    if j.origin is None:
        raise ValueError(f"joint '{j.name}' of a URDF chain has no origin")
    return j.origin


def _axis(j: JointRow) -> tuple[float, float, float]:
    """The axis of a URDF row (every row of a URDF chain has one)."""
    if j.axis is None:
        raise ValueError(f"joint '{j.name}' of a URDF chain has no axis")
    return j.axis


@dataclass(frozen=True)
class Visual:
    """One visual of a URDF the arm was read from, for the viewer only: ``row`` the chain row whose moving
    link carries it (-1: the base, before the first moving joint), ``pose`` its 4x4 pose in that link's
    frame (nested tuples [m]), ``geometry`` the ``<geometry>`` element's XML (mesh file names absolute),
    ``rgba`` its colour or None."""
    row: int
    pose: tuple[float, ...]
    geometry: str
    rgba: tuple[float, ...] | None = None


@dataclass(frozen=True)
class Probe:
    """The probe: ball centre ``p_last`` [m] in the last joint frame, ball diameter [m],
    calibrated force range [N], and compliances [m/N] of the ball along probe x, y (bending)
    and z (axial).

    ``rpy`` (roll, pitch, yaw) [rad] orients the probe frame in the last joint frame
    (R = Rz(yaw) Ry(pitch) Rx(roll), as a URDF origin); its z axis runs along the stylus towards the
    ball. ``lever`` [m] is the stylus length from the bending hinge to the ball; None puts the hinge
    where the stylus line passes closest to the last joint origin (lever = the ball's coordinate along
    probe z, seen from the last joint origin; z of ``p_last`` for an unrotated probe).
    """
    p_last: tuple[float, float, float]
    ball_diameter: float
    max_force: float
    bending_compliance_x: float
    bending_compliance_y: float
    axial_compliance: float
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lever: float | None = None

    @property
    def rotation(self) -> tuple[tuple[float, ...], ...] | None:
        """R_last_probe as a 3x3 nested tuple, None for an unrotated probe."""
        from .geometry import rotation_xyz
        return None if not any(self.rpy) else tuple(map(tuple, rotation_xyz(self.rpy).tolist()))

    @property
    def stylus_length(self) -> float:
        """Distance [m] from the bending hinge to the ball centre along probe z, the lever of the
        virtual bending joints."""
        from .chain import probe_lever
        return float(probe_lever(self.p_last, self.rotation, self.lever))

    @property
    def compliance(self) -> np.ndarray:
        """Diagonal compliance (cx, cy, cz) [m/N] of the ball under a force at the ball."""
        return np.array([self.bending_compliance_x, self.bending_compliance_y, self.axial_compliance])


@dataclass(frozen=True)
class ArmDescription:
    """A serial arm: joint rows from the base out and a probe. ``convention`` is "dh", "mdh" or
    "urdf" (rows are URDF joint origins and axes)."""
    name: str
    convention: str
    joints: tuple[JointRow, ...]
    probe: Probe
    source: str | None = field(default=None, compare=False)
    #: the URDF link at the ball centre when the arm was read from a URDF (``source``)
    tip_frame: str | None = field(default=None, compare=False)
    #: the URDF link the chain starts at, when not the root (``--base-frame``)
    base_frame: str | None = field(default=None, compare=False)
    #: the URDF's moving joints held at a value (``--hold-joint``): (name, deg or mm) pairs
    held_joints: tuple[tuple[str, float], ...] = field(default=(), compare=False)
    #: the user's visuals when the arm was read from a URDF, for the viewer (:class:`Visual`); never written
    #: to a description TOML
    visuals: tuple[Visual, ...] = field(default=(), compare=False, repr=False)
    #: the mesh files of the URDF's visuals on the chain that were not found (``package://`` beside or above the
    #: URDF, relative to it, absolute): the viewer draws without them and says so; the kinematics never use them
    missing_meshes: tuple[str, ...] = field(default=(), compare=False, repr=False)
    #: the joints' masses are not the arm's but assumed from its geometry
    #: (:func:`calibration.calibrate.with_assumed_masses`): a written model file says so in its comment
    masses_assumed: bool = field(default=False, compare=False, repr=False)

    @cached_property
    def exact_key(self) -> str:
        """Every field of the description, each number exactly (``repr``: 0.0 and -0.0 differ, as they may in a
        written file), as one text: the key of a cache of what is derived from it (``==`` compares the kinematic
        fields only, and equal numbers)."""
        return repr(tuple(getattr(self, f.name) for f in fields(self)))

    @cached_property
    def encoders(self) -> tuple[JointRow, ...]:
        """The joints whose values are the encoder columns q1..qJ, in column order: every joint of the
        chain but those mimicking another joint of the chain, and for a joint mimicking one off the chain,
        that master (named after it, its limits mapped back through the mimic). Without ``<mimic>``
        joints: :attr:`joints` itself."""
        if not any(j.mimic for j in self.joints):
            return self.joints
        rows = {j.name: j for j in self.joints}
        out: dict[str, JointRow] = {}
        for j in self.joints:
            source = j.name if j.mimic is None else j.mimic.joint
            if source in out:
                continue
            if source in rows:
                out[source] = rows[source]
                continue
            m = j.mimic
            assert m is not None              # a joint without <mimic> is its own source
            lims = None if j.lower is None or j.upper is None else sorted(((j.lower - m.offset) / m.multiplier,
                                                                          (j.upper - m.offset) / m.multiplier))
            out[source] = JointRow(name=source, kind=j.kind, lower=None if lims is None else lims[0],
                                   upper=None if lims is None else lims[1])
        return tuple(out.values())

    @cached_property
    def chain_joints(self) -> tuple[Joint, ...]:
        """How each row moves (:class:`arm_model.chain.Joint`): axis, revolute or prismatic, and the
        encoder column it reads (with a mimic's multiplier and offset)."""
        from .chain import Joint
        column = {e.name: k for k, e in enumerate(self.encoders)}
        out = []
        for j in self.joints:
            m = j.mimic
            urdf = self.convention == "urdf"
            out.append(Joint(column=column[j.name if m is None else m.joint],
                             axis=j.axis if urdf else None, prismatic=j.prismatic,
                             multiplier=1.0 if m is None else m.multiplier, offset=0.0 if m is None else m.offset,
                             rpy=(float(j.origin[3]), float(j.origin[4]), float(j.origin[5]))
                             if urdf and j.origin is not None else (0.0, 0.0, 0.0)))
        return tuple(out)

    @property
    def coupled(self) -> bool:
        """True when some joint follows another joint of the chain (rows and encoder columns differ)."""
        return len(self.encoders) != len(self.joints)

    @property
    def n_joints(self) -> int:
        """The number of encoder columns (joints read by an encoder; see :attr:`encoders`)."""
        return len(self.encoders)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The names of the encoder columns q1..qJ (:attr:`encoders`)."""
        return tuple(j.name for j in self.encoders)

    @property
    def joint_quantities(self) -> tuple[str, ...]:
        """Per encoder column: "angle" (revolute) or "length" (prismatic), the unit a points file gives it in."""
        return tuple("length" if j.prismatic else "angle" for j in self.encoders)

    @property
    def joint_column_units(self) -> tuple[tuple[str, float], ...]:
        """Per encoder column: the unit suffix its column is written in and the factor from SI, ("deg",
        180/pi) for a revolute joint, ("mm", 1000) for a prismatic one (``q3_mm``)."""
        return tuple(("mm", 1e3) if j.prismatic else ("deg", 180.0 / math.pi) for j in self.encoders)

    @property
    def revolute_columns(self) -> tuple[int, ...]:
        """Indices of the encoder columns of revolute joints."""
        return tuple(k for k, j in enumerate(self.encoders) if not j.prismatic)

    @property
    def row_fields(self) -> tuple[str, ...]:
        """Names of the geometric values of one row, in :meth:`row_table` order (SI)."""
        return URDF_ROW_FIELDS if self.convention == "urdf" else DH_ROW_FIELDS

    def row_table(self) -> np.ndarray:
        """(J, 4) (theta_offset, d, a, alpha) for DH/MDH, (J, 6) (x, y, z, roll, pitch, yaw) for URDF."""
        if self.convention == "urdf":
            return np.array([j.origin for j in self.joints], dtype=float)
        return np.array([[j.theta_offset, j.d, j.a, j.alpha] for j in self.joints], dtype=float)

    def with_row_table(self, table: np.ndarray) -> ArmDescription:
        """The description with the row values ``table`` (this description's own plus errors): for a URDF chain
        the angles' differences from the origin's own turn the origin about its own axes (:func:`~arm_model.
        chain.row_motions`), folded here into the origin's new roll, pitch and yaw."""
        table = np.asarray(table, dtype=float)
        if self.convention == "urdf":
            joints = tuple(replace(j, origin=_folded_origin(_origin(j), r)) for j, r in zip(self.joints, table,
                                                                                            strict=True))
        else:
            joints = tuple(replace(j, theta_offset=float(r[0]), d=float(r[1]), a=float(r[2]), alpha=float(r[3]))
                           for j, r in zip(self.joints, table, strict=True))
        return replace(self, joints=joints)

    @property
    def axes(self) -> tuple[tuple[float, float, float] | None, ...] | None:
        """Joint axes (URDF chains), None for DH/MDH (z)."""
        return tuple(j.axis for j in self.joints) if self.convention == "urdf" else None

    @property
    def chain_length(self) -> float:
        """The length [m] of the chain: the sum of its joint rows' translations (DH/MDH ``hypot(d, a)``, a URDF
        origin's ``|(x, y, z)|``) and the tip's distance from the last joint's origin: the arm's size, at least its
        reach."""
        rows = sum(math.hypot(j.d, j.a) if j.origin is None else float(np.linalg.norm(j.origin[:3]))
                   for j in self.joints)
        return float(rows + np.linalg.norm(self.probe.p_last))

    @property
    def length_indices(self) -> tuple[int, ...]:
        """Indices of the row values that are lengths (thermal growth scales them)."""
        return (0, 1, 2) if self.convention == "urdf" else (1, 2)

    def with_probe(self, **changes: Any) -> ArmDescription:
        return replace(self, probe=replace(self.probe, **changes))


# ---------------------------------------------------------------------------------------------
# reading

_JOINT_KEYS = {  # base name -> (quantity, required)
    "theta_offset": ("angle", True), "d": ("length", True), "a": ("length", True),
    "alpha": ("angle", True), "lower": ("angle", False), "upper": ("angle", False),
    "mass": ("mass", False), "com_x": ("length", False), "com_y": ("length", False),
    "com_z": ("length", False), "encoder_resolution": ("angle", False),
}
_URDF_JOINT_KEYS = {
    "origin_x": ("length", True), "origin_y": ("length", True), "origin_z": ("length", True),
    "origin_roll": ("angle", True), "origin_pitch": ("angle", True), "origin_yaw": ("angle", True),
    "lower": ("angle", False), "upper": ("angle", False),
    "mass": ("mass", False), "com_x": ("length", False), "com_y": ("length", False),
    "com_z": ("length", False), "encoder_resolution": ("angle", False),
}
_PROBE_KEYS = {
    "x": ("length", True), "y": ("length", True), "z": ("length", True),
    "ball_diameter": ("length", True), "max_force": ("force", True),
    "bending_compliance": ("compliance", True), "axial_compliance": ("compliance", True),
    "bending_compliance_x": ("compliance", False), "bending_compliance_y": ("compliance", False),
    "roll": ("angle", False), "pitch": ("angle", False), "yaw": ("angle", False),
    "stylus_length": ("length", False),
}


class TomlReader:
    """Messages naming the file, the line and the key path of a parsed TOML text."""

    def __init__(self, path: str, text: str):
        self.path = path
        self._text = text

    @cached_property
    def lines(self) -> dict[tuple[Any, ...], int]:
        """The line of each key path (:func:`~arm_model.toml_lines.toml_key_lines`), worked out when a message
        first needs one: a text without a mistake never pays for it."""
        return toml_key_lines(self._text)

    def error(self, msg: str, *path: Any) -> InputError:
        """An InputError at ``path`` (the key path; its line, else its table's, else none)."""
        line = None
        for k in range(len(path), -1, -1):
            line = self.lines.get(tuple(path[:k]))
            if line is not None:
                break
        return InputError(msg, self.path, line, f"key '{key_path_text(path)}'")

    def values(self, tbl: dict[str, Any], spec: dict[str, Any], where: tuple[Any, ...],
               text_keys: tuple[str, ...] = ()) -> dict[str, float]:
        """Numeric keys with unit suffixes of ``tbl`` (at key path ``where``) in SI by base name;
        ``spec``: base name -> (quantity, required)."""
        out: dict[str, float] = {}
        for key, value in tbl.items():
            if key in text_keys:
                if not isinstance(value, str) or not value.strip():
                    raise self.error(f"'{key}' must be a non-empty text", *where, key)
                continue
            parts = split_unit(key)
            if parts is None:
                near = did_you_mean(key, [f"{b}_<unit>" for b in spec] + list(text_keys))
                raise self.error(f"'{key}' has no known unit suffix (a numeric key carries its unit: "
                                 f"_mm, _m, _um, _deg, _rad, _N, _mm_per_N, _kg ...){near}", *where, key)
            base, unit = parts
            if base not in spec:
                raise self.error(f"unknown key '{key}' (known: {', '.join(sorted(spec))})"
                                 f"{did_you_mean(base, list(spec))}", *where, key)
            quantity = spec[base][0]
            if QUANTITY_OF_UNIT[unit] != quantity:
                raise self.error(f"'{key}' is a {quantity}, but '_{unit}' is a unit of "
                                 f"{QUANTITY_OF_UNIT[unit]}", *where, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise self.error(f"'{key}' must be a number, got {value!r}", *where, key)
            if not math.isfinite(value):
                raise self.error(f"'{key}' must be finite, got {value!r}", *where, key)
            if base in out:
                raise self.error(f"'{base}' is given twice (with two units)", *where, key)
            out[base] = float(value) * UNIT_FACTORS[unit]
            wrong = implausible(out[base], quantity)
            if wrong:
                raise self.error(f"'{key}': {wrong[1]}", *where, key)
        for base, (quantity, required) in spec.items():
            if required and base not in out:
                raise self.error(f"missing key '{base}_<unit>' ({quantity})", *where)
        return out


#: top-level keys of a description; a model file (arm_model.model_file) adds its effects and calibration tables
DESCRIPTION_KEYS = ("name", "convention", "joint", "probe")
MODEL_KEYS = ("effect", "calibration", "reference_frame", "marker")


#: the largest probing scatter a model file may give [um]: 100 mm is a unit mistake, while a poor fit of a
#: robot can estimate more than a millimetre, and every model file calibrate writes must read back
MAX_PROBING_SCATTER_UM = 1.0e5
#: the largest growth of the model discrepancy a model file may give [um per mm of ball travel beyond the
#: nearest training pose]: 100 times the travel itself is a unit mistake, not an estimate
MAX_DISCREPANCY_GROWTH_UM_PER_MM = 1.0e5
#: the keys of ``[calibration]`` that name a file, relative to the model file's folder
FILE_KEYS = ("covariance", "training_poses")


def check_calibration_table(tbl: Any, r: TomlReader) -> None:
    """The ``[calibration]`` table of a model file: text keys ``covariance`` and ``written_by``, the
    numbers ``probing_scatter_um`` (>= 0: a calibration whose encoder and force-sensor noise alone account for
    its residual scatter writes 0; at most :data:`MAX_PROBING_SCATTER_UM`) and ``model_discrepancy_um`` (the
    same range), ``model_discrepancy_growth_um_per_mm`` (in [0, :data:`MAX_DISCREPANCY_GROWTH_UM_PER_MM`], or a list
    of one such number a joint, whose length :func:`arm_model.model_file.parse_model` checks; above 0
    it needs ``model_discrepancy_um`` and ``training_poses``, the text naming the training poses' points file); the
    files (:data:`FILE_KEYS`) relative to the model file's folder, never an absolute path."""
    if not isinstance(tbl, dict):
        raise r.error("'calibration' must be a table", "calibration")
    known = ("covariance", "written_by", "probing_scatter_um", "model_discrepancy_um",
             "model_discrepancy_growth_um_per_mm", "training_poses")
    top = {"probing_scatter_um": MAX_PROBING_SCATTER_UM, "model_discrepancy_um": MAX_PROBING_SCATTER_UM,
           "model_discrepancy_growth_um_per_mm": MAX_DISCREPANCY_GROWTH_UM_PER_MM}
    for key, value in tbl.items():
        if key not in known:
            raise r.error(f"unknown key '{key}' (known: {', '.join(known)}){did_you_mean(key, known)}",
                          "calibration", key)
        if key in top:
            per_joint = key == "model_discrepancy_growth_um_per_mm" and isinstance(value, list)
            for v in value if per_joint else [value]:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                        or not 0 <= v <= top[key]:
                    unit = key.rsplit("_", 1)[-1] if not key.endswith("per_mm") else "um/mm"
                    what = "a number or a non-empty list of one number a joint" if key.endswith("per_mm") \
                        else "a number"
                    raise r.error(f"'{key}' must be {what} in [0, {top[key]:g}] {unit}, got {value!r}",
                                  "calibration", key)
            if per_joint and not value:
                raise r.error(f"'{key}' must be a number or a non-empty list of one number a joint, got []",
                              "calibration", key)
        elif not isinstance(value, str) or not value.strip():
            raise r.error(f"'{key}' must be a non-empty text", "calibration", key)
        elif key in FILE_KEYS and Path(value).is_absolute():
            raise r.error(f"'{key}' must name a file relative to the model file's folder (the model file and the "
                          f"files it names move together), got the absolute path {value!r}", "calibration", key)
    lacking = [k for k in ("model_discrepancy_um", "training_poses") if k not in tbl]
    growth = tbl.get("model_discrepancy_growth_um_per_mm", 0)
    if max(growth if isinstance(growth, list) else [growth]) > 0 and lacking:
        raise r.error(f"'model_discrepancy_growth_um_per_mm' needs '{lacking[0]}' (the discrepancy at the training "
                      "poses, and the points file of those poses it grows away from)", "calibration",
                      "model_discrepancy_growth_um_per_mm")


def parse_description(text: str, path: str = "<string>") -> ArmDescription:
    """Parse an arm description from TOML text; raise :class:`InputError` naming line and key.

    A model file's ``[calibration]`` table is accepted (and checked); its ``[[effect]]`` tables are
    refused here: a model with effects is read by :func:`arm_model.model_file.parse_model` (every
    ``--arm`` option does), which applies them."""
    data = parse_toml(text, path)
    r = TomlReader(path, text)
    if data.get("effect"):
        raise r.error("this model file holds effects ([[effect]] tables), which a plain description cannot "
                      "carry: give it to an --arm option (tip, ring, view, calibrate, close-loop apply them; in "
                      "Python arm_model.model_file.load_model)", "effect", 0)
    if "calibration" in data:
        check_calibration_table(data["calibration"], r)
    return description_from_data({k: v for k, v in data.items() if k not in MODEL_KEYS}, r)


def _joint_kind_keys(convention: str, kind: str) -> dict[str, Any]:
    """The numeric keys of a [[joint]] row: limits, resolution and mimic offset are angles for a revolute
    joint, lengths for a prismatic one."""
    spec = dict(_URDF_JOINT_KEYS if convention == "urdf" else _JOINT_KEYS)
    quantity = "length" if kind == "prismatic" else "angle"
    for key in ("lower", "upper", "encoder_resolution", "mimic_offset"):
        spec[key] = (quantity, False)
    return spec


def _joint_row(r: TomlReader, convention: str, i: int, row: dict[str, Any]) -> JointRow:
    """One [[joint]] table (number ``i``) as a :class:`JointRow`."""
    row = dict(row)
    kind = row.pop("type", "revolute")
    if kind not in JOINT_KINDS:
        raise r.error(f"'type' must be \"revolute\" or \"prismatic\", got {kind!r}", "joint", i, "type")
    axis = None
    if convention == "urdf":
        axis = row.pop("axis", None)
        if (not isinstance(axis, list) or len(axis) != 3
                or not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in axis)
                or not math.isfinite(sum(axis)) or math.hypot(*axis) < 1e-9):
            raise r.error("a URDF row needs 'axis = [x, y, z]', a non-zero direction (no unit)",
                          "joint", i, "axis")
        norm = math.hypot(*axis)
        axis = tuple(float(a) / norm for a in axis)
    master, multiplier = row.pop("mimic_joint", None), row.pop("mimic_multiplier", 1.0)
    if master is not None and (not isinstance(master, str) or not master.strip()):
        raise r.error("'mimic_joint' must be the name of the joint this one follows", "joint", i, "mimic_joint")
    if (isinstance(multiplier, bool) or not isinstance(multiplier, (int, float)) or not math.isfinite(multiplier)
            or multiplier == 0 or abs(multiplier) > 1e3):
        raise r.error(f"'mimic_multiplier' (no unit) must be a non-zero number of at most 1000 in size, got "
                      f"{multiplier!r}", "joint", i, "mimic_multiplier")
    unit = "mm" if kind == "prismatic" else "deg"
    v = r.values(row, _joint_kind_keys(convention, kind), ("joint", i), text_keys=("name",))
    if "name" in row and id_problem(row["name"]):       # it names parameters in every CSV table and the URDF
        raise r.error(f"'name' {id_problem(row['name'])}", "joint", i, "name")
    if master is None and ("mimic_offset" in v or multiplier != 1.0):
        raise r.error("'mimic_multiplier' and 'mimic_offset' need 'mimic_joint'", "joint", i)
    if "lower" in v and "upper" in v and v["lower"] >= v["upper"]:
        raise r.error("lower limit is not below upper limit", "joint", i, f"lower_{unit}")
    if v.get("mass", 0.0) < 0:
        raise r.error("mass must not be negative", "joint", i, "mass_kg")
    if v.get("encoder_resolution", 1.0) <= 0:
        raise r.error("encoder_resolution must be > 0", "joint", i, f"encoder_resolution_{unit}")
    common = dict(name=row.get("name", f"j{i + 1}"), lower=v.get("lower"), upper=v.get("upper"),
                  mass=v.get("mass", 0.0), com=(v.get("com_x", 0.0), v.get("com_y", 0.0), v.get("com_z", 0.0)),
                  encoder_resolution=v.get("encoder_resolution"), kind=kind,
                  mimic=None if master is None else Mimic(master, float(multiplier), v.get("mimic_offset", 0.0)))
    if convention == "urdf":
        return JointRow(origin=_six([v[k] for k in URDF_ROW_FIELDS]), axis=axis, **common)
    return JointRow(theta_offset=v["theta_offset"], d=v["d"], a=v["a"], alpha=v["alpha"], **common)


def _check_mimics(r: TomlReader, joints: list[JointRow]) -> None:
    """A mimicking joint follows a joint of its own kind that is itself read by an encoder (or one off the
    chain), never itself."""
    by_name = {j.name: j for j in joints}
    for i, j in enumerate(joints):
        if j.mimic is None:
            continue
        master = by_name.get(j.mimic.joint)
        if master is j:
            raise r.error(f"joint '{j.name}' cannot mimic itself", "joint", i, "mimic_joint")
        if master is not None and master.mimic is not None:
            raise r.error(f"joint '{j.name}' mimics '{master.name}', which mimics '{master.mimic.joint}': name the "
                          "joint read by the encoder (multiply the multipliers)", "joint", i, "mimic_joint")
        if master is not None and master.kind != j.kind:
            raise r.error(f"joint '{j.name}' ({j.kind}) mimics '{master.name}' ({master.kind}): a mimic follows a "
                          "joint of its own kind", "joint", i, "mimic_joint")


def default_lever(p_last: ArrayLike, rotation: ArrayLike | None = None) -> float | None:
    """The stylus length a probe gets when none is given, one rule for every route (a description TOML, a
    URDF's tip frame): None (the lever is the ball's coordinate along probe z, ``z_probe . p``) when that is
    a length, at least :data:`MIN_STYLUS` and 1/1000 of the ball's distance from the last joint origin;
    else ``|p|`` (the probe z points back past or across that origin: the hinge hangs |p| behind the ball);
    0 for a ball at that origin (no stylus)."""
    p = np.asarray(p_last, dtype=float)
    z = np.array([0.0, 0.0, 1.0]) if rotation is None else np.asarray(rotation, dtype=float)[:, 2]
    dist = float(np.linalg.norm(p))
    if float(z @ p) >= max(1e-3 * dist, MIN_STYLUS):
        return None
    return dist if dist >= MIN_STYLUS else 0.0


def _probe(r: TomlReader, ptab: Any) -> Probe:
    """The [probe] table. What the probe model needs, and nothing a measuring arm merely suggests: a
    compliant stylus needs a length (its bending hinge lies that far behind the ball along probe z,
    wherever the ball is: default :func:`default_lever`); ``stylus_length_mm = 0`` is a tip without a
    stylus (a flange point, a tracker marker), rigid, its compliances 0."""
    if not isinstance(ptab, dict):
        raise r.error("missing [probe] table", "probe")
    pv = r.values(ptab, _PROBE_KEYS, ("probe",))
    rpy = (pv.get("roll", 0.0), pv.get("pitch", 0.0), pv.get("yaw", 0.0))
    if pv.get("stylus_length", 0.0) < 0:
        raise r.error("'stylus_length' must not be negative (0: a tip without a stylus)", "probe", "stylus_length_mm")
    def written(key: str) -> str:      # the key as the file spells it, with its unit (ball_diameter_mm): its line
        return next((k for k in ptab if k.startswith(key + "_") and k[len(key) + 1:] in UNIT_FACTORS), key)
    for key in ("ball_diameter", "max_force"):
        if pv[key] <= 0:
            raise r.error(f"'{written(key)}' must be > 0", "probe", written(key))
    for key in ("bending_compliance", "axial_compliance", "bending_compliance_x", "bending_compliance_y"):
        if pv.get(key, 0.0) < 0:
            raise r.error(f"'{written(key)}' must not be negative", "probe", written(key))
    probe = Probe(
        p_last=(pv["x"], pv["y"], pv["z"]), ball_diameter=pv["ball_diameter"], max_force=pv["max_force"],
        bending_compliance_x=pv.get("bending_compliance_x", pv["bending_compliance"]),
        bending_compliance_y=pv.get("bending_compliance_y", pv["bending_compliance"]),
        axial_compliance=pv["axial_compliance"], rpy=rpy, lever=pv.get("stylus_length"))
    if probe.lever is None:
        probe = replace(probe, lever=default_lever(probe.p_last, probe.rotation))
    if probe.lever == 0.0 and probe.compliance.any():
        given = "stylus_length" in pv
        raise r.error(("a tip without a stylus (stylus_length_mm = 0)" if given else
                       f"the ball lies {float(np.linalg.norm(probe.p_last)) * 1e3:.3g} mm from the last joint origin, "
                       "a tip without a stylus") + " bends under no force: its compliances must be 0 (a compliant "
                      "stylus is at least 0.001 mm long: give its length, stylus_length_mm)", "probe",
                      "stylus_length_mm" if given else "z_mm")
    if 0 < probe.stylus_length < MIN_STYLUS:
        raise r.error(f"the stylus, from its bending hinge to the ball, is {probe.stylus_length * 1e3:.3g} mm long: "
                      "at least 0.001 mm (0: a tip without a stylus)", "probe", "stylus_length_mm")
    return probe


def description_from_data(data: dict[str, Any], r: TomlReader, extra_keys: tuple[str, ...] = ()) -> ArmDescription:
    """The description of parsed TOML ``data``; keys of ``extra_keys`` are left to the caller."""
    path = r.path
    known = DESCRIPTION_KEYS + tuple(extra_keys)
    for key in data:
        if key not in known:
            raise r.error(f"unknown top-level key '{key}' (known: {', '.join(known)}){did_you_mean(key, known)}", key)
    name = data.get("name")
    if not isinstance(name, str) or not name.strip():
        raise r.error("missing or empty 'name'" if name is None or name == "" else
                      f"'name' must be a non-empty text, got {name!r}", "name")
    if id_problem(name):            # it names files and is written into every model file, URDF and report
        raise r.error(f"'name' {id_problem(name)}", "name")
    convention = data.get("convention")
    if convention not in ("dh", "mdh", "urdf"):
        raise r.error(f"'convention' must be \"dh\", \"mdh\" or \"urdf\", got {convention!r}", "convention")
    rows = data.get("joint")
    if not isinstance(rows, list) or not rows or not all(isinstance(x, dict) for x in rows):
        raise r.error("no [[joint]] rows", "joint")
    joints = []
    for i, row in enumerate(rows):
        joints.append(_joint_row(r, convention, i, row))
        if joints[-1].name in [j.name for j in joints[:-1]]:
            raise r.error(f"joint name '{joints[-1].name}' is used twice", "joint", i, "name")
    _check_mimics(r, joints)
    probe = _probe(r, data.get("probe"))
    return ArmDescription(name=name, convention=convention, joints=tuple(joints), probe=probe, source=path)


def load_description(path: str | Path) -> ArmDescription:
    """Read an arm description TOML file (docs/formats.md §2); a shipped arm's name (``"aacmm7"``) that is
    not an existing file reads the shipped description, as ``--arm`` does."""
    from .shipped import arm_path
    path = arm_path(path)
    return parse_description(read_text(path, "the arm description"), str(path))


# ---------------------------------------------------------------------------------------------
# writing

def in_unit(value_si: float, factor: float) -> float:
    """``value_si`` in a unit of ``factor`` (to SI), chosen among the nearest floats so that reading it
    back (``x * factor``) gives ``value_si`` exactly whenever such a float exists."""
    value_si = float(value_si)
    x = value_si / factor
    if x * factor == value_si or not math.isfinite(x):
        return x
    lo = hi = x
    for _ in range(8):
        lo, hi = math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf)
        for c in (lo, hi):
            if c * factor == value_si:
                return c
    return x


def _check_writable(desc: ArmDescription) -> None:
    """The description obeys the reader's rules on numbers (:func:`arm_model.units.implausible`), so that
    what is written reads back: a value beyond them (a joint origin of more than 1 km, say, from a fit
    that ran away along a direction the data do not see) is a :class:`NumericalError` naming it, never a
    file its reader refuses."""
    from .errors import NumericalError
    for j in desc.joints:
        length = "length" if j.prismatic else "angle"
        values = ([("origin", v, "length") for v in _origin(j)[:3]] + [("origin", v, "angle") for v in _origin(j)[3:]]
                  if desc.convention == "urdf" else
                  [("theta_offset", j.theta_offset, "angle"), ("d", j.d, "length"), ("a", j.a, "length"),
                   ("alpha", j.alpha, "angle")])
        values += [("com", v, "length") for v in j.com] + [("limit", v, length) for v in (j.lower, j.upper)
                                                             if v is not None]
        for key, v, quantity in values:
            wrong = implausible(v, quantity) if math.isfinite(v) else (None, f"{v!r} is not a finite number")
            if wrong:
                raise NumericalError(f"joint '{j.name}' of the arm '{desc.name}': its {key} value {wrong[1]}: "
                                     "this arm cannot be written (a fit that ran away along a direction the data "
                                     "do not see?)")
    p = desc.probe
    for key, v in (("x", p.p_last[0]), ("y", p.p_last[1]), ("z", p.p_last[2]), ("stylus_length", p.lever or 0.0)):
        wrong = implausible(v, "length") if math.isfinite(v) else (None, f"{v!r} is not a finite number")
        if wrong:
            raise NumericalError(f"the probe of the arm '{desc.name}': its {key} {wrong[1]}: this arm cannot be "
                                 "written")
    if p.lever == 0.0 and p.compliance.any():
        raise NumericalError(f"the probe of the arm '{desc.name}' has no stylus but compliances "
                             f"{p.compliance.tolist()} m/N: a tip without a stylus bends under no force")
    if p.lever is None and default_lever(p.p_last, p.rotation) is not None:
        # the stylus length is the ball's coordinate along probe z; read back, a ball at or behind the last joint
        # origin along probe z gets a hinge behind the ball (|p|): the file would not be this arm
        raise NumericalError(f"the probe of the arm '{desc.name}': its ball lies "
                             f"{p.stylus_length * 1e3:.6g} mm along probe z from the last "
                             "joint origin, at or behind it: this arm cannot be written (a fit that ran away along a "
                             "direction the data do not see?)")


def description_data(desc: ArmDescription) -> dict[str, Any]:
    """The TOML tables of a description (mm and degrees) as plain data for ``tomli_w``; read back,
    every value is the same float. A description its reader would refuse is a :class:`NumericalError`
    (:func:`_check_writable`)."""
    _check_writable(desc)
    mm, deg = UNIT_FACTORS["mm"], UNIT_FACTORS["deg"]
    joints = []
    for j in desc.joints:
        row: dict[str, Any] = {"name": j.name}
        if j.prismatic:
            row["type"] = "prismatic"
        if desc.convention == "urdf":
            row.update({f"origin_{k}_mm": in_unit(v, mm) for k, v in zip("xyz", _origin(j)[:3], strict=True)})
            row.update({f"origin_{k}_deg": in_unit(v, deg)
                        for k, v in zip(("roll", "pitch", "yaw"), _origin(j)[3:], strict=True)})
            row["axis"] = [float(a) for a in _axis(j)]
        else:
            row.update({"theta_offset_deg": in_unit(j.theta_offset, deg), "d_mm": in_unit(j.d, mm),
                        "a_mm": in_unit(j.a, mm), "alpha_deg": in_unit(j.alpha, deg)})
        unit, factor = ("mm", mm) if j.prismatic else ("deg", deg)
        if j.lower is not None:
            row[f"lower_{unit}"] = in_unit(j.lower, factor)
        if j.upper is not None:
            row[f"upper_{unit}"] = in_unit(j.upper, factor)
        if j.mass:
            row["mass_kg"] = float(j.mass)
        if any(j.com):
            row.update({f"com_{k}_mm": in_unit(v, mm) for k, v in zip("xyz", j.com, strict=True)})
        if j.encoder_resolution is not None:
            row[f"encoder_resolution_{unit}"] = in_unit(j.encoder_resolution, factor)
        if j.mimic is not None:
            row.update({"mimic_joint": j.mimic.joint, "mimic_multiplier": float(j.mimic.multiplier)})
            if j.mimic.offset:
                row[f"mimic_offset_{unit}"] = in_unit(j.mimic.offset, factor)
        joints.append(row)
    p = desc.probe
    mpn = UNIT_FACTORS["mm_per_N"]
    probe = {"x_mm": in_unit(p.p_last[0], mm), "y_mm": in_unit(p.p_last[1], mm), "z_mm": in_unit(p.p_last[2], mm),
             "ball_diameter_mm": in_unit(p.ball_diameter, mm), "max_force_N": float(p.max_force),
             "bending_compliance_mm_per_N": in_unit(p.bending_compliance_x, mpn)}
    if p.bending_compliance_y != p.bending_compliance_x:
        probe.update({"bending_compliance_x_mm_per_N": in_unit(p.bending_compliance_x, mpn),
                      "bending_compliance_y_mm_per_N": in_unit(p.bending_compliance_y, mpn)})
    probe["axial_compliance_mm_per_N"] = in_unit(p.axial_compliance, mpn)
    if any(p.rpy):
        probe.update({f"{k}_deg": in_unit(v, deg) for k, v in zip(("roll", "pitch", "yaw"), p.rpy, strict=True)})
    if p.lever is not None:
        probe["stylus_length_mm"] = in_unit(p.lever, mm)
    return {"name": desc.name, "convention": desc.convention, "joint": joints, "probe": probe}


def comment_block(comment: str | None) -> str:
    """``comment`` as TOML comment lines (every line, whatever it holds, stays a comment)."""
    if not comment:
        return ""
    clean = "".join(c if c == "\n" or c == "\t" or (ord(c) >= 32 and ord(c) != 127) else "?" for c in comment)
    return "".join(f"# {line}".rstrip() + "\n" for line in clean.split("\n"))


def toml_text(data: dict[str, Any], comment: str | None = None) -> str:
    """TOML text of ``data`` written by ``tomli_w`` (every name and text quoted as TOML needs), with
    ``comment`` as a header."""
    import tomli_w
    return comment_block(comment) + tomli_w.dumps(data)


def format_description(desc: ArmDescription, comment: str | None = None) -> str:
    """TOML text of a description, in mm and degrees, that :func:`parse_description` reads back exactly."""
    return toml_text(description_data(desc), comment)
