"""The arm description (docs/formats.md §2): the single source of every evaluator.

Inside, everything is SI: lengths [m], angles [rad], forces [N], compliances [m/N], masses [kg].
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ._errors import InputError, parse_toml, read_text
from ._units import QUANTITY_OF_UNIT, UNIT_FACTORS, split_unit

__all__ = ["JointRow", "Probe", "ArmDescription", "load_description", "parse_description",
           "format_description", "GRAVITY", "DH_ROW_FIELDS", "URDF_ROW_FIELDS"]

DH_ROW_FIELDS = ("theta_offset", "d", "a", "alpha")
URDF_ROW_FIELDS = ("origin_x", "origin_y", "origin_z", "origin_roll", "origin_pitch", "origin_yaw")

#: gravity in the base frame [m/s^2] (docs/formats.md §2: -z of the base frame)
GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass(frozen=True)
class JointRow:
    """One joint row.

    DH and modified DH: ``theta_offset`` [rad], ``d`` [m], ``a`` [m], ``alpha`` [rad].
    URDF chains (convention "urdf"): ``origin`` = (x, y, z [m], roll, pitch, yaw [rad]) of the joint in
    its parent's frame (URDF ``<origin>``) and ``axis`` (unit vector, joint frame); the DH fields are 0.

    ``lower``/``upper`` [rad] are the joint limits (None if not given), ``mass`` [kg] the mass of the
    link this joint moves, ``com`` [m] its centre of mass in the row's end frame (after Rx(alpha) for
    DH; the joint's child frame for MDH and URDF).
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


@dataclass(frozen=True)
class Probe:
    """The probe: ball centre ``p_last`` [m] in the last joint frame, ball diameter [m],
    calibrated force range [N], and compliances [m/N] of the ball along probe x, y (bending)
    and z (axial)."""
    p_last: tuple[float, float, float]
    ball_diameter: float
    max_force: float
    bending_compliance_x: float
    bending_compliance_y: float
    axial_compliance: float

    @property
    def stylus_length(self) -> float:
        """Distance [m] from the flange plane (z = 0 of the last joint frame) to the ball centre,
        the lever of the virtual bending joints."""
        return self.p_last[2]

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

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def row_fields(self) -> tuple[str, ...]:
        """Names of the geometric values of one row, in :meth:`row_table` order (SI)."""
        return URDF_ROW_FIELDS if self.convention == "urdf" else DH_ROW_FIELDS

    def row_table(self) -> np.ndarray:
        """(J, 4) (theta_offset, d, a, alpha) for DH/MDH, (J, 6) (x, y, z, roll, pitch, yaw) for URDF."""
        if self.convention == "urdf":
            return np.array([j.origin for j in self.joints], dtype=float)
        return np.array([[j.theta_offset, j.d, j.a, j.alpha] for j in self.joints], dtype=float)

    def with_row_table(self, table: np.ndarray) -> "ArmDescription":
        table = np.asarray(table, dtype=float)
        if self.convention == "urdf":
            joints = tuple(replace(j, origin=tuple(float(v) for v in r)) for j, r in zip(self.joints, table))
        else:
            joints = tuple(replace(j, theta_offset=float(r[0]), d=float(r[1]), a=float(r[2]), alpha=float(r[3]))
                           for j, r in zip(self.joints, table))
        return replace(self, joints=joints)

    @property
    def axes(self) -> tuple | None:
        """Joint axes (URDF chains), None for DH/MDH (z)."""
        return tuple(j.axis for j in self.joints) if self.convention == "urdf" else None

    @property
    def length_indices(self) -> tuple[int, ...]:
        """Indices of the row values that are lengths (thermal growth scales them)."""
        return (0, 1, 2) if self.convention == "urdf" else (1, 2)

    def with_probe(self, **changes) -> "ArmDescription":
        return replace(self, probe=replace(self.probe, **changes))


# ---------------------------------------------------------------------------------------------
# reading

_JOINT_KEYS = {  # base name -> (quantity, required)
    "theta_offset": ("angle", True), "d": ("length", True), "a": ("length", True),
    "alpha": ("angle", True), "lower": ("angle", False), "upper": ("angle", False),
    "mass": ("mass", False), "com_x": ("length", False), "com_y": ("length", False),
    "com_z": ("length", False),
}
_URDF_JOINT_KEYS = {
    "origin_x": ("length", True), "origin_y": ("length", True), "origin_z": ("length", True),
    "origin_roll": ("angle", True), "origin_pitch": ("angle", True), "origin_yaw": ("angle", True),
    "lower": ("angle", False), "upper": ("angle", False),
    "mass": ("mass", False), "com_x": ("length", False), "com_y": ("length", False),
    "com_z": ("length", False),
}
_PROBE_KEYS = {
    "x": ("length", True), "y": ("length", True), "z": ("length", True),
    "ball_diameter": ("length", True), "max_force": ("force", True),
    "bending_compliance": ("compliance", True), "axial_compliance": ("compliance", True),
    "bending_compliance_x": ("compliance", False), "bending_compliance_y": ("compliance", False),
}


def _key_lines(text: str) -> dict[tuple[str, int, str], int]:
    """Map (table, index, key) to its 1-based line, for messages. Tables: "", "joint", "probe"."""
    lines: dict[tuple[str, int, str], int] = {}
    table, counts = "", {}
    for no, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        m = re.match(r"^\[\[\s*([\w.-]+)\s*\]\]$", line)
        if m:
            table = m.group(1)
            counts[table] = counts.get(table, -1) + 1
            lines[(table, counts[table], "")] = no
            continue
        m = re.match(r"^\[\s*([\w.-]+)\s*\]$", line)
        if m:
            table = m.group(1)
            counts[table] = 0
            lines[(table, 0, "")] = no
            continue
        m = re.match(r"^([\w-]+)\s*=", line)
        if m:
            lines[(table, counts.get(table, 0), m.group(1))] = no
    return lines


class _Reader:
    def __init__(self, path: str, text: str):
        self.path = path
        self.lines = _key_lines(text)

    def error(self, msg: str, table: str, index: int, key: str | None) -> InputError:
        line = self.lines.get((table, index, key or ""), self.lines.get((table, index, "")))
        where = table if table else "top level"
        if table == "joint":
            where = f"joint[{index + 1}]"
        col = f"key '{where}.{key}'" if key else f"key '{where}'"
        return InputError(msg, self.path, line, col)

    def values(self, tbl: dict, spec: dict, table: str, index: int,
               text_keys: tuple[str, ...] = ()) -> dict[str, float]:
        out: dict[str, float] = {}
        for key, value in tbl.items():
            if key in text_keys:
                if not isinstance(value, str) or not value.strip():
                    raise self.error(f"'{key}' must be a non-empty text", table, index, key)
                continue
            parts = split_unit(key)
            if parts is None:
                raise self.error(f"'{key}' has no known unit suffix (a numeric key carries its unit: "
                                 f"_mm, _m, _um, _deg, _rad, _N, _mm_per_N, _kg ...)", table, index, key)
            base, unit = parts
            if base not in spec:
                raise self.error(f"unknown key '{key}' (known: {', '.join(sorted(spec))})", table, index, key)
            quantity = spec[base][0]
            if QUANTITY_OF_UNIT[unit] != quantity:
                raise self.error(f"'{key}' is a {quantity}, but '_{unit}' is a unit of "
                                 f"{QUANTITY_OF_UNIT[unit]}", table, index, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise self.error(f"'{key}' must be a number, got {value!r}", table, index, key)
            if not math.isfinite(value):
                raise self.error(f"'{key}' must be finite, got {value!r}", table, index, key)
            if base in out:
                raise self.error(f"'{base}' is given twice (with two units)", table, index, key)
            out[base] = float(value) * UNIT_FACTORS[unit]
        for base, (quantity, required) in spec.items():
            if required and base not in out:
                raise self.error(f"missing key '{base}_<unit>' ({quantity})", table, index, None)
        return out


def parse_description(text: str, path: str = "<string>") -> ArmDescription:
    """Parse an arm description from TOML text; raise :class:`InputError` naming line and key."""
    data = parse_toml(text, path)
    r = _Reader(path, text)
    for key in data:
        if key not in ("name", "convention", "joint", "probe"):
            raise r.error(f"unknown top-level key '{key}' (known: name, convention, joint, probe)", "", 0, key)
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise r.error("missing or empty 'name'", "", 0, "name")
    convention = data.get("convention")
    if convention not in ("dh", "mdh", "urdf"):
        raise r.error(f"'convention' must be \"dh\", \"mdh\" or \"urdf\", got {convention!r}", "", 0,
                      "convention")
    rows = data.get("joint")
    if not isinstance(rows, list) or not rows:
        raise r.error("no [[joint]] rows", "", 0, "joint")
    joints = []
    seen = set()
    for i, row in enumerate(rows):
        if convention == "urdf":
            row = dict(row)
            axis = row.pop("axis", None)
            if (not isinstance(axis, list) or len(axis) != 3
                    or not all(isinstance(a, (int, float)) and not isinstance(a, bool) for a in axis)
                    or not math.isfinite(sum(axis)) or math.hypot(*axis) < 1e-9):
                raise r.error("a URDF row needs 'axis = [x, y, z]', a non-zero direction (no unit)",
                              "joint", i, "axis")
            norm = math.hypot(*axis)
            axis = tuple(float(a) / norm for a in axis)
        v = r.values(row, _URDF_JOINT_KEYS if convention == "urdf" else _JOINT_KEYS, "joint", i,
                     text_keys=("name",))
        jname = row.get("name", f"j{i + 1}")
        if jname in seen:
            raise r.error(f"joint name '{jname}' is used twice", "joint", i, "name")
        seen.add(jname)
        if "lower" in v and "upper" in v and v["lower"] >= v["upper"]:
            raise r.error("lower limit is not below upper limit", "joint", i, "lower_deg")
        if v.get("mass", 0.0) < 0:
            raise r.error("mass must not be negative", "joint", i, "mass_kg")
        common = dict(name=jname, lower=v.get("lower"), upper=v.get("upper"), mass=v.get("mass", 0.0),
                      com=(v.get("com_x", 0.0), v.get("com_y", 0.0), v.get("com_z", 0.0)))
        if convention == "urdf":
            joints.append(JointRow(origin=tuple(v[k] for k in URDF_ROW_FIELDS), axis=axis, **common))
        else:
            joints.append(JointRow(theta_offset=v["theta_offset"], d=v["d"], a=v["a"], alpha=v["alpha"],
                                   **common))
    ptab = data.get("probe")
    if not isinstance(ptab, dict):
        raise r.error("missing [probe] table", "", 0, "probe")
    pv = r.values(ptab, _PROBE_KEYS, "probe", 0)
    if pv["z"] <= 0:
        raise r.error("the ball must lie beyond the flange: z of the probe must be > 0 "
                      "(the probe z axis points along the stylus towards the ball)", "probe", 0, "z_mm")
    for key in ("ball_diameter", "max_force"):
        if pv[key] <= 0:
            raise r.error(f"'{key}' must be > 0", "probe", 0, key)
    for key in ("bending_compliance", "axial_compliance", "bending_compliance_x", "bending_compliance_y"):
        if pv.get(key, 0.0) < 0:
            raise r.error(f"'{key}' must not be negative", "probe", 0, key)
    probe = Probe(
        p_last=(pv["x"], pv["y"], pv["z"]), ball_diameter=pv["ball_diameter"], max_force=pv["max_force"],
        bending_compliance_x=pv.get("bending_compliance_x", pv["bending_compliance"]),
        bending_compliance_y=pv.get("bending_compliance_y", pv["bending_compliance"]),
        axial_compliance=pv["axial_compliance"])
    return ArmDescription(name=name, convention=convention, joints=tuple(joints), probe=probe, source=path)


def load_description(path: str | Path) -> ArmDescription:
    """Read an arm description TOML file (docs/formats.md §2)."""
    return parse_description(read_text(path, "the arm description"), str(path))


# ---------------------------------------------------------------------------------------------
# writing

def _num(x: float) -> str:
    return repr(float(x))


def format_description(desc: ArmDescription, comment: str | None = None) -> str:
    """TOML text of a description, in mm and degrees, that :func:`parse_description` reads back exactly."""
    deg = 180.0 / math.pi
    out = []
    if comment:
        out += [f"# {line}" for line in comment.splitlines()]
    out += [f'name = "{desc.name}"', f'convention = "{desc.convention}"', ""]
    for j in desc.joints:
        out += ["[[joint]]", f'name = "{j.name}"']
        if desc.convention == "urdf":
            out += [f"origin_{k}_mm = {_num(v * 1e3)}" for k, v in zip("xyz", j.origin[:3])]
            out += [f"origin_{k}_deg = {_num(v * deg)}" for k, v in zip(("roll", "pitch", "yaw"), j.origin[3:])]
            out.append(f"axis = [{', '.join(_num(a) for a in j.axis)}]")
        else:
            out += [f"theta_offset_deg = {_num(j.theta_offset * deg)}",
                    f"d_mm = {_num(j.d * 1e3)}", f"a_mm = {_num(j.a * 1e3)}",
                    f"alpha_deg = {_num(j.alpha * deg)}"]
        if j.lower is not None:
            out.append(f"lower_deg = {_num(j.lower * deg)}")
        if j.upper is not None:
            out.append(f"upper_deg = {_num(j.upper * deg)}")
        if j.mass:
            out.append(f"mass_kg = {_num(j.mass)}")
        if any(j.com):
            out += [f"com_x_mm = {_num(j.com[0] * 1e3)}", f"com_y_mm = {_num(j.com[1] * 1e3)}",
                    f"com_z_mm = {_num(j.com[2] * 1e3)}"]
        out.append("")
    p = desc.probe
    out += ["[probe]", f"x_mm = {_num(p.p_last[0] * 1e3)}", f"y_mm = {_num(p.p_last[1] * 1e3)}",
            f"z_mm = {_num(p.p_last[2] * 1e3)}", f"ball_diameter_mm = {_num(p.ball_diameter * 1e3)}",
            f"max_force_N = {_num(p.max_force)}",
            f"bending_compliance_mm_per_N = {_num(p.bending_compliance_x * 1e3)}"]
    if p.bending_compliance_y != p.bending_compliance_x:
        out += [f"bending_compliance_x_mm_per_N = {_num(p.bending_compliance_x * 1e3)}",
                f"bending_compliance_y_mm_per_N = {_num(p.bending_compliance_y * 1e3)}"]
    out.append(f"axial_compliance_mm_per_N = {_num(p.axial_compliance * 1e3)}")
    return "\n".join(out) + "\n"
