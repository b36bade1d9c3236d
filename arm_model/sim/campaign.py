"""Campaign files: what to simulate (TOML, or the same structure as a Python dict).

Every numeric key carries its unit (``diameter_mm``, ``stiffness_Nm_per_rad``, ``drift_C_per_h``);
counts (``measurements``, ``points``), ratios (``gain``, ``friction_coefficient``) and directions
(``axis``, ``normal``) are plain numbers. A key without a known unit, an unknown key, or a value of
the wrong kind is one :class:`~arm_model.InputError` naming the file, the line and the key.
Inside, everything is SI. The full key reference is ``docs/simulator.md``.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..description import ArmDescription
from ..errors import MAX_ID_LENGTH, InputError, beside, did_you_mean, parse_toml, path_problem, read_text
from ..shipped import SHIPPED_ARMS, shipped_path
from ..toml_lines import key_path_text, toml_key_lines
from ..units import SMALLEST_ARTEFACT_M, implausible, split_unit
from ..urdf_import import is_urdf, load_arm

__all__ = ["Campaign", "Task", "load_campaign", "campaign_from_dict", "TASK_KINDS", "SENSORS",
           "DEFAULT_ARM"]

DEFAULT_ARM = shipped_path(SHIPPED_ARMS["aacmm7"])
TASK_KINDS = ("ring", "sphere", "plane", "seat", "ballbar", "tracker", "mocap")
SENSORS = ("xyz", "two-channel", "none")
#: a seat's articulations in random order, or in a sweep (by the stylus' azimuth about the seat's axis: each pose next
#: to the one before, as a robot program or an operator going round the seat takes them)
SEAT_ORDERS = ("random", "sweep")

# unit suffix -> (quantity, factor to SI); the longest suffix wins ("_Nm_per_rad" before "_rad")
_UNITS: dict[str, tuple[str, float]] = {
    "mm": ("length", 1e-3), "m": ("length", 1.0), "um": ("length", 1e-6),
    "deg": ("angle", math.pi / 180), "rad": ("angle", 1.0), "arcsec": ("angle", math.pi / 648000),
    "N": ("force", 1.0),
    "C": ("temperature", 1.0),
    "s": ("time", 1.0), "h": ("time", 3600.0),
    "mm_per_N": ("compliance", 1e-3), "um_per_N": ("compliance", 1e-6), "m_per_N": ("compliance", 1.0),
    "Nm_per_rad": ("stiffness", 1.0), "Nm_per_deg": ("stiffness", 180 / math.pi),
    "per_K": ("expansion", 1.0), "ppm_per_K": ("expansion", 1e-6),
    "C_per_h": ("temperature_rate", 1 / 3600),
    "mm_per_h": ("length_rate", 1e-3 / 3600), "um_per_h": ("length_rate", 1e-6 / 3600),
}
_SUFFIXES = sorted(_UNITS, key=len, reverse=True)
#: the finest encoder step the simulator quantises to [rad] (1e-9 deg; a step of 1e-320 deg made every reading
#: infinite, and simulate wrote a points file its own reader refused)
_FINEST_ENCODER_STEP = math.radians(1e-9)
#: the largest [noise] of a simulated instrument, in the unit shown (a probing noise of 1 km, a temperature noise
#: of 1000 C gave readings the toolkit's readers refuse: beyond every plausible angle, below absolute zero)
_NOISE_MAX = {"encoder_resolution": 10.0, "encoder_noise": 10.0, "probing_repeatability": 100.0, "force_noise": 1000.0,
              "temperature_noise": 10.0}
_NOISE_SHOWN = {"encoder_resolution": (180 / math.pi, "deg"), "encoder_noise": (180 / math.pi, "deg"),
                "probing_repeatability": (1e3, "mm"), "force_noise": (1.0, "N"), "temperature_noise": (1.0, "C")}
_UNITLESS = ("count", "ratio", "direction", "text", "bool", "names", "table", "matrix")


def _split(key: str) -> tuple[str, str] | None:
    for unit in _SUFFIXES:
        if key.endswith("_" + unit) and len(key) > len(unit) + 1:
            return key[: -len(unit) - 1], unit
    return None


# ---------------------------------------------------------------------------------------------
# schema: section -> {base key: (quantity, default, shape)}; shape None scalar, n a vector, -1 a list

_S = {
    "top": {"name": ("text", "campaign", None), "seed": ("count", 0, None), "arm": ("text", None, None),
            "tip_frame": ("text", None, None), "base_frame": ("text", None, None),
            "sensor": ("text", "xyz", None), "truth": ("table", None, None), "noise": ("table", None, None),
            "environment": ("table", None, None), "operator": ("table", None, None),
            "signals": ("table", None, None), "task": ("table", None, None),
            "description": ("text", "", None)},
    "truth": {"length_error": ("length", 20e-6, None), "angle_error": ("angle", math.radians(0.003), None),
              "probe_error": ("length", 20e-6, None), "errors": ("table", None, None),
              "eccentricity": ("table", None, None), "joint_compliance": ("table", None, None),
              "thermal": ("table", None, None), "probe_compliance": ("table", None, None),
              "force_sensor": ("table", None, None), "harmonics": ("table", None, None),
              "lateral_compliance": ("table", None, None), "approach_offset": ("table", None, None)},
    "lateral_compliance": {"joints": ("names", None, None), "stiffness_x": ("stiffness", None, -1),
                           "stiffness_y": ("stiffness", None, -1), "gravity": ("bool", True, None),
                           "contact": ("bool", True, None)},
    "approach_offset": {f"d{a}_u{b}": ("length", 0.0, None) for a in "xyz" for b in "xyz"},
    "harmonics": {"joint": ("text", None, None), "of": ("text", None, None), "harmonic": ("count", None, None),
                  "amplitude": ("angle", None, None), "phase": ("angle", 0.0, None)},
    "eccentricity": {"joint": ("text", None, None), "amplitude": ("angle", None, None),
                     "phase": ("angle", 0.0, None), "amplitude2": ("angle", 0.0, None),
                     "phase2": ("angle", 0.0, None)},
    "joint_compliance": {"joints": ("names", None, None), "stiffness": ("stiffness", None, -1),
                         "gravity": ("bool", True, None), "contact": ("bool", True, None)},
    "thermal": {"joints": ("names", None, None), "alpha": ("expansion", None, -1),
                "probe_alpha": ("expansion", 0.0, None)},
    "probe_compliance": {"bending": ("compliance", None, None), "bending_x": ("compliance", None, None),
                         "bending_y": ("compliance", None, None), "axial": ("compliance", None, None),
                         "coupling_xy": ("compliance", 0.0, None), "coupling_xz": ("compliance", 0.0, None),
                         "coupling_yz": ("compliance", 0.0, None)},
    "force_sensor": {"gain": ("ratio", (0.0, 0.0, 0.0), 3), "offset": ("force", (0.0, 0.0, 0.0), 3),
                     "cross_talk": ("matrix", None, None)},
    "noise": {"encoder_resolution": ("angle", 0.0, None), "encoder_noise": ("angle", 0.0, None),
              "probing_repeatability": ("length", 0.0, None), "force_noise": ("force", 0.0, None),
              "temperature_noise": ("temperature", 0.0, None)},
    "environment": {"temperature": ("temperature", 20.0, None), "drift": ("temperature_rate", 0.0, None),
                    "cycle_amplitude": ("temperature", 0.0, None), "cycle_period": ("time", 86400.0, None),
                    "artefact_drift": ("length_rate", (0.0, 0.0, 0.0), 3)},
    "operator": {"force_mean": ("force", 1.0, None), "level_log_sd": ("ratio", 0.35, None),
                 "point_cv": ("ratio", 0.35, None), "min_force": ("force", 0.15, None),
                 "max_force": ("force", 8.0, None), "spike_probability": ("ratio", 0.002, None),
                 "friction_coefficient": ("ratio", 0.1, None), "friction_torque": ("bool", False, None),
                 "point_period": ("time", 1.2, None), "measurement_gap": ("time", 60.0, None)},
    "signals": {"enabled": ("bool", True, None), "sample_period": ("time", 1e-3, None),
                "rise": ("time", 0.12, None), "decay": ("time", 0.2, None)},
}
_COMMON_TASK = {"kind": ("text", None, None), "id": ("text", None, None),
                "measurements": ("count", 1, None), "stylus_cone": ("angle", None, None)}
_TASKS = {
    "ring": {"diameter": ("length", 174.996e-3, None), "u_diameter": ("length", None, None),
             "form_error": ("length", None, None), "true_form_error": ("length", 0.0, None),
             "form_lobes": ("count", 3, None), "centre": ("length", (0.70, 0.0, 0.05), 3),
             "axis": ("direction", (0.0, 0.0, 1.0), 3), "depths": ("length", (5e-3, 12e-3, 19e-3), -1),
             "points_per_row": ("count", 24, None), "angle_jitter": ("angle", math.radians(3.0), None),
             "depth_jitter": ("length", 1e-3, None), "stylus_tilt": ("angle", 0.0, None),
             "roll": ("text", None, None), "roll_jitter": ("angle", math.radians(10.0), None)},
    "sphere": {"diameter": ("length", 25e-3, None), "centre": ("length", (0.55, 0.25, 0.1), 3),
               "points": ("count", 25, None), "polar_max": ("angle", math.radians(90.0), None)},
    "plane": {"point": ("length", (0.6, -0.2, 0.0), 3), "normal": ("direction", (0.0, 0.0, 1.0), 3),
              "size": ("length", (0.3, 0.3), 2), "points": ("count", 25, None)},
    "seat": {"position": ("length", (0.6, 0.2, 0.05), 3), "axis": ("direction", (0.0, 0.0, 1.0), 3),
             "articulations": ("count", 20, None), "force_cone": ("angle", math.radians(30.0), None),
             "order": ("text", "random", None)},
    "ballbar": {"positions": ("count", 20, None), "length": ("length", 0.6, None),
                "u_length": ("length", None, None), "true_length": ("length", None, None),
                "ends": ("text", "sphere", None), "sphere_diameter": ("length", 25e-3, None),
                "points_per_sphere": ("count", 5, None), "articulations": ("count", 3, None),
                "polar_max": ("angle", math.radians(70.0), None),
                "force_cone": ("angle", math.radians(30.0), None),
                "radius": ("length", (0.3, 0.8), 2), "height": ("length", (-0.2, 0.6), 2),
                "reach": ("length", 0.85, None)},
    "tracker": {"nests": ("count", 20, None), "articulations": ("count", 3, None),
                "noise": ("length", 10e-6, None), "radius": ("length", (0.3, 0.8), 2),
                "height": ("length", (-0.2, 0.6), 2), "reach": ("length", 0.85, None),
                "force_cone": ("angle", math.radians(30.0), None),
                "distance": ("length", 3.0, None)},
    "mocap": {"postures": ("count", 40, None), "markers": ("count", 1, None),
              "marker_distance": ("length", 0.05, None), "sessions": ("count", 1, None),
              "noise": ("length", 0.2e-3, None), "distance": ("length", 3.0, None),
              "limit_margin": ("angle", 0.05, None)},
}
_DEFAULT_CONE = {"ring": 0.0, "sphere": math.radians(30.0), "plane": math.radians(30.0),
                 "seat": math.radians(60.0), "ballbar": math.radians(45.0), "tracker": math.radians(45.0),
                 "mocap": 0.0}
_ID = {"ring": "ring", "sphere": "sphere", "plane": "plane", "seat": "seat", "ballbar": "bar",
       "tracker": "nest", "mocap": "pose"}
#: the longest suffix a measurement id adds to its task's id ("-pos-07", "-07-12"; counts up to 10^6 points)
_ID_SUFFIX = 32


@dataclass(frozen=True)
class Task:
    """One artefact task: ``kind`` (see :data:`TASK_KINDS`), its feature ``id``, how many
    ``measurements``, and its options in SI (``opts``: key base name -> value)."""
    kind: str
    id: str
    measurements: int
    opts: dict
    line: int | None = None


@dataclass(frozen=True)
class Campaign:
    """A parsed campaign (SI inside). ``sections`` holds truth/noise/environment/operator/signals
    options by key base name; ``source`` the file (None for a dict)."""
    name: str
    seed: int
    arm: ArmDescription
    arm_path: Path | None
    sensor: str
    truth: dict
    noise: dict
    environment: dict
    operator: dict
    signals: dict
    tasks: tuple[Task, ...]
    source: Path | None = None
    description: str = ""
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def inputs(self) -> tuple[Path, ...]:
        """The input files, which outputs must never overwrite."""
        return tuple(p for p in (self.source, self.arm_path) if p is not None)


def _harmonics(ctx, raw, desc) -> list[dict]:
    """``[[truth.harmonics]]``: joint-angle errors ``a sin(h q_of + phi)`` of ``joint`` (``of``: the joint
    whose angle drives it, the joint itself by default), harmonic h of 1..4."""
    if raw is None:
        return []
    if isinstance(raw, dict):
        raw = [raw]
    if not isinstance(raw, list):
        raise ctx.error("'harmonics' must be [[truth.harmonics]] tables", ("truth",), "harmonics")
    rows = []
    for i, t in enumerate(raw):
        tbl = ("truth", "harmonics", i)
        e = _section(ctx, t, _S["harmonics"], tbl)
        if e["joint"] is None or e["amplitude"] is None or e["harmonic"] is None:
            raise ctx.error("a harmonic needs 'joint', 'harmonic' and 'amplitude_<angle unit>'", tbl)
        if not 1 <= e["harmonic"] <= 4:
            raise ctx.error(f"'harmonic' must be 1 to 4, got {e['harmonic']}", tbl, "harmonic")
        e["index"] = _joint_index(ctx, desc, e["joint"], tbl, "joint", revolute=True)
        e["source"] = None if e["of"] is None else _joint_index(ctx, desc, e["of"], tbl, "of", revolute=True)
        if e["source"] == e["index"]:
            e["source"] = None
        if any((r["index"], r["source"], r["harmonic"]) == (e["index"], e["source"], e["harmonic"]) for r in rows):
            raise ctx.error(f"joint '{e['joint']}' has two tables of harmonic {e['harmonic']} of the same angle",
                            tbl, "harmonic")
        rows.append(e)
    return rows


def _given_key(raw: dict, base: str) -> str:
    """The key of ``raw`` (as written, with its unit suffix) whose base name is ``base``."""
    return next((k for k in raw if k == base or (_split(k) or ("",))[0] == base), base)


#: largest approach (lobing) offset per unit stylus component [m] a campaign may hide
APPROACH_MAX = 1e-3


def _check_compliance_matrix(ctx, e: dict, desc, tbl, raw: dict) -> None:
    """The true probe compliance as a symmetric 3x3 matrix (probe frame: the true bending x, y and axial
    compliance on the diagonal, declared where not given; the coupling terms off it) must be positive
    semi-definite: a probe does not move against the force."""
    declared = desc.probe.compliance
    cx = e["bending_x"] if e["bending_x"] is not None else e["bending"]
    cy = e["bending_y"] if e["bending_y"] is not None else e["bending"]
    diag = [declared[0] if cx is None else cx, declared[1] if cy is None else cy,
            declared[2] if e["axial"] is None else e["axial"]]
    c = np.diag(diag)
    for (a, b), key in (((0, 1), "coupling_xy"), ((0, 2), "coupling_xz"), ((1, 2), "coupling_yz")):
        c[a, b] = c[b, a] = e[key]
    low = float(np.linalg.eigvalsh(c)[0])
    if low < -1e-9 * max(float(np.abs(c).max()), 1e-12):
        bad = max(("coupling_xy", "coupling_xz", "coupling_yz"), key=lambda k: abs(e[k]))
        raise ctx.error(f"the true probe compliance matrix (diagonal {', '.join(f'{v * 1e6:.4g}' for v in diag)} "
                        f"um/N, the declared one where not given) with these coupling terms is not positive "
                        f"semi-definite (smallest eigenvalue {low * 1e6:.3g} um/N): a coupling term must be "
                        "smaller than the geometric mean of its two diagonal terms", tbl, _given_key(raw, bad))


class _Ctx:
    """Where a value came from: builds errors that name file, line and key (``lines``: the campaign
    text's :func:`~arm_model.toml_lines.toml_key_lines`)."""

    def __init__(self, path: str, lines: dict | None):
        self.path = path
        self.lines = lines or {}

    def error(self, msg: str, table: tuple, key: str | None = None) -> InputError:
        """The error at ``key`` of ``table``; a key named by its base (``stylus_cone``) is found with the unit
        the file gives it (``stylus_cone_deg``), and named so."""
        if key and table + (key,) not in self.lines:
            key = next((k[-1] for k in self.lines if len(k) == len(table) + 1 and k[:-1] == table
                        and isinstance(k[-1], str) and (split_unit(k[-1]) or ("",))[0] == key), key)
        line = self.lines.get(table + (key,)) if key else None
        if line is None:
            line = self.lines.get(table)
        return InputError(msg, self.path, line, f"key '{key_path_text(table + ((key,) if key else ()))}'")


def _number(ctx, v, table, key) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ctx.error(f"'{key}' must be a finite number, got {v!r}", table, key)
    return float(v) + 0.0       # -0.0 is 0 (numpy's random draws refuse a scale of -0.0: "scale < 0", exit 3)


def _section(ctx: _Ctx, data: Any, spec: dict, table: tuple) -> dict:
    """Read one table against its spec; returns base name -> SI value (defaults filled in)."""
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ctx.error("expected a table", table)
    out: dict[str, Any] = {}
    for key, v in data.items():
        base, unit = key, None
        if key not in spec or spec[key][0] not in _UNITLESS:
            parts = _split(key)
            if parts is not None and parts[0] in spec and spec[parts[0]][0] not in _UNITLESS:
                base, unit = parts
            elif key in spec:
                raise ctx.error(f"'{key}' needs a unit suffix for a {spec[key][0]} "
                                f"(e.g. {_example(spec[key][0])})", table, key)
            else:
                known = ", ".join(_display(b, q[0]) for b, q in spec.items())
                raise ctx.error(f"unknown key '{key}'{did_you_mean(key, spec)} (known: {known})", table, key)
        quantity, _, shape = spec[base]
        if base in out:
            raise ctx.error(f"'{base}' is given twice (with two units)", table, key)
        if unit is not None:
            if _UNITS[unit][0] != quantity:
                raise ctx.error(f"'{key}' is a {quantity}, but '_{unit}' is a unit of {_UNITS[unit][0]} "
                                f"(e.g. {_example(quantity)})", table, key)
            out[base] = _scaled(ctx, v, _UNITS[unit][1], shape, table, key, quantity)
        else:
            out[base] = _unitless(ctx, v, quantity, shape, table, key)
    for base, (quantity, default, _shape) in spec.items():
        if base not in out and quantity != "table":
            out[base] = default
    return out


def _example(quantity: str) -> str:
    return ", ".join("_" + u for u, (q, _) in _UNITS.items() if q == quantity)


def _display(base: str, quantity: str) -> str:
    if quantity in _UNITLESS:
        return base
    return f"{base}_<{quantity} unit>"


def _scaled(ctx, v, factor, shape, table, key, quantity=None):
    """A number (or a list of ``shape`` numbers) in SI, each within the plausible range of ``quantity``."""
    def one(x):
        x = _number(ctx, x, table, key) * factor
        wrong = implausible(x, quantity) if quantity else None
        if wrong:
            raise ctx.error(f"'{key}': {wrong[1]}", table, key)
        return x
    if shape is None:
        return one(v)
    values = v if isinstance(v, list) else ([v] if shape == -1 else None)
    if values is None or (shape != -1 and len(values) != shape) or not values:
        want = "a list" if shape == -1 else f"a list of {shape} numbers"
        raise ctx.error(f"'{key}' must be {want}, got {v!r}", table, key)
    return tuple(one(x) for x in values)


def _unitless(ctx, v, quantity, shape, table, key):
    if quantity == "table":
        if not isinstance(v, (dict, list)):
            raise ctx.error(f"'{key}' must be a table", table, key)
        return v
    if quantity == "text":
        if not isinstance(v, str) or not v.strip():
            raise ctx.error(f"'{key}' must be a non-empty text", table, key)
        return v.strip()
    if quantity == "bool":
        if not isinstance(v, bool):
            raise ctx.error(f"'{key}' must be true or false", table, key)
        return v
    if quantity == "count":
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise ctx.error(f"'{key}' must be a whole number >= 0, got {v!r}", table, key)
        return int(v)
    if quantity == "names":
        if not isinstance(v, list) or not v or not all(isinstance(x, str) for x in v):
            raise ctx.error(f"'{key}' must be a list of joint names", table, key)
        return tuple(v)
    if quantity == "matrix":
        if (not isinstance(v, list) or len(v) != 3
                or not all(isinstance(r, list) and len(r) == 3 for r in v)):
            raise ctx.error(f"'{key}' must be a 3x3 list of lists", table, key)
        return np.array([[_number(ctx, x, table, key) for x in r] for r in v])
    if quantity == "direction":
        vec = _scaled(ctx, v, 1.0, shape, table, key)
        norm = math.sqrt(sum(x * x for x in vec))
        if norm < 1e-9:
            raise ctx.error(f"'{key}' must be a non-zero direction", table, key)
        return tuple(x / norm for x in vec)
    # ratio
    return _scaled(ctx, v, 1.0, shape, table, key, "ratio")


# ---------------------------------------------------------------------------------------------

def _joint_index(ctx, desc: ArmDescription, name: str, table, key, revolute: bool = False) -> int:
    """The encoder column of joint ``name``; ``revolute``: for an effect on a joint's angle, which a
    prismatic joint has not."""
    if name not in desc.joint_names:
        raise ctx.error(f"unknown joint '{name}'{did_you_mean(name, desc.joint_names)} (the arm has: "
                        f"{', '.join(desc.joint_names)})", table, key)
    i = desc.joint_names.index(name)
    if revolute and desc.encoders[i].prismatic:
        raise ctx.error(f"joint '{name}' is prismatic: '{table[1]}' acts on a joint's angle (revolute joints: "
                        f"{', '.join(desc.joint_names[k] for k in desc.revolute_columns)})", table, key)
    return i


def _joint_indices(ctx, desc: ArmDescription, names, table, revolute: bool) -> tuple[int, ...]:
    """The encoder columns of ``names``; none given: every joint (every revolute one for an effect on a
    joint's angle)."""
    if not names:
        return desc.revolute_columns if revolute else tuple(range(desc.n_joints))
    out = tuple(_joint_index(ctx, desc, n, table, "joints", revolute) for n in names)
    if len(set(out)) != len(out):       # (joint_compliance and thermal: an internal error of their effect's check)
        raise ctx.error("a joint is named twice", table, "joints")
    return out


def _load_arm(ctx, arm_path: Path, tip_frame: str | None, base_frame: str | None) -> ArmDescription:
    """The campaign's arm; a tip or base frame the URDF refuses is the campaign's ``tip_frame`` or
    ``base_frame`` key's error (the command-line option a command would name does not exist here)."""
    try:
        return load_arm(arm_path, tip_frame, base_frame=base_frame)
    except InputError as exc:
        keys = {"key '--tip-frame'": "tip_frame", "key '--base-frame'": "base_frame"}
        if exc.column not in keys:
            raise
        reason = exc.reason.replace("--base-frame", "base_frame")
        raise ctx.error(f"{reason} (in the URDF {arm_path})", (), keys[exc.column]) from None


def _campaign_arm(ctx, top: dict, base_dir: Path | None, arm) -> tuple[ArmDescription, Path | None]:
    """The campaign's arm (``arm``: a description, a path given by the caller, or None: the campaign's
    'arm' key, a shipped arm's name or a path relative to the campaign, default the nominal arm) and the
    path it was read from."""
    arm_path = None
    if isinstance(arm, ArmDescription):
        return arm, arm_path
    arm_path = Path(arm) if arm is not None else None
    if arm_path is None and top["arm"] is not None:
        why = path_problem(top["arm"], base=base_dir)
        if why:         # "arm.toml/" read arm.toml (Path drops the slash)
            raise ctx.error(f"'arm': {why}", (), "arm")
        arm_path = Path(top["arm"])
        if not arm_path.is_absolute() and base_dir is not None:
            arm_path = base_dir / arm_path
        if top["arm"] in SHIPPED_ARMS and not arm_path.exists():     # a shipped arm by name
            arm_path = shipped_path(SHIPPED_ARMS[top["arm"]])
    if arm_path is None:
        arm_path = DEFAULT_ARM
    if not arm_path.exists():
        raise ctx.error(f"arm description not found: {arm_path}", (), "arm")
    urdf = is_urdf(arm_path)
    if urdf and not top["tip_frame"]:
        raise ctx.error("an arm given as a URDF needs 'tip_frame' (the link at the ball centre)", (), "arm")
    for key in ("tip_frame", "base_frame"):       # load_arm refuses the options; the keys were ignored
        if not urdf and top[key] is not None:
            raise ctx.error(f"'{key}' is for an arm given as a URDF; this campaign's arm {arm_path.name} is a "
                            "description TOML (its chain is its [[joint]] rows, its tip the [probe])", (), key)
    return _load_arm(ctx, arm_path, top["tip_frame"], top["base_frame"]), arm_path


def _eccentricities(ctx, ecc, desc) -> list[dict]:
    """The [[truth.eccentricity]] tables (one a revolute joint)."""
    if isinstance(ecc, dict):
        ecc = [ecc]
    if not isinstance(ecc, list):
        raise ctx.error("'eccentricity' must be [[truth.eccentricity]] tables", ("truth",), "eccentricity")
    rows = []
    for i, t in enumerate(ecc):
        tbl = ("truth", "eccentricity", i)
        e = _section(ctx, t, _S["eccentricity"], tbl)
        if e["joint"] is None or e["amplitude"] is None:
            raise ctx.error("an eccentricity needs 'joint' and 'amplitude_<angle unit>'", tbl)
        e["index"] = _joint_index(ctx, desc, e["joint"], tbl, "joint", revolute=True)
        if any(r["index"] == e["index"] for r in rows):
            raise ctx.error(f"joint '{e['joint']}' has two eccentricity tables", tbl, "joint")
        rows.append(e)
    return rows


def _joint_values(ctx, e: dict, name: str, desc, tbl) -> None:
    """joint_compliance / thermal: the joints and one stiffness (alpha) for all or one a joint."""
    e["indices"] = _joint_indices(ctx, desc, e["joints"], tbl, name == "joint_compliance")
    key = "stiffness" if name == "joint_compliance" else "alpha"
    vals = e[key]
    if vals is None:
        raise ctx.error(f"'{name}' needs '{key}_<unit>'", tbl)
    if len(vals) not in (1, len(e["indices"])):
        raise ctx.error(f"'{key}' has {len(vals)} values for {len(e['indices'])} joints", tbl, key)
    if name == "joint_compliance" and min(vals) <= 0:
        raise ctx.error("stiffness must be > 0", tbl, key)
    e[key] = tuple(vals) * (len(e["indices"]) if len(vals) == 1 else 1)


def _lateral_compliance(ctx, e: dict, desc, tbl, raw: dict) -> None:
    e["indices"] = _joint_indices(ctx, desc, e["joints"], tbl, True)
    if e["stiffness_x"] is None and e["stiffness_y"] is None:
        raise ctx.error("'lateral_compliance' needs 'stiffness_x_<unit>' and/or 'stiffness_y_<unit>' "
                        "(about the joint frame's x and y axes)", tbl)
    if not (e["gravity"] or e["contact"]):
        raise ctx.error("'gravity' and 'contact' are both false: the compliance would carry no load", tbl)
    for key in ("stiffness_x", "stiffness_y"):
        vals = e[key]
        if vals is None:
            e[key] = (None,) * len(e["indices"])
            continue
        if len(vals) not in (1, len(e["indices"])):
            raise ctx.error(f"'{key}' has {len(vals)} values for {len(e['indices'])} joints", tbl,
                            _given_key(raw, key))
        if min(vals) <= 0:
            raise ctx.error(f"'{key}' must be > 0", tbl, _given_key(raw, key))
        e[key] = tuple(vals) * (len(e["indices"]) if len(vals) == 1 else 1)


def _approach_offset(ctx, e: dict, tbl, raw: dict) -> None:
    for key, v in e.items():
        if abs(v) > APPROACH_MAX:
            raise ctx.error(f"'{key}' is {v * 1e3:g} mm: an approach (lobing) offset must be within "
                            f"+-{APPROACH_MAX * 1e3:g} mm", tbl, _given_key(raw, key))


def _probe_compliance(ctx, e: dict, desc, tbl, raw: dict) -> None:
    if e["bending"] is not None and (e["bending_x"] is not None or e["bending_y"] is not None):
        raise ctx.error("give 'bending' or 'bending_x'/'bending_y', not both", tbl)
    if all(e[k] is None for k in ("bending", "bending_x", "bending_y", "axial")) and \
            not any(e[f"coupling_{a}"] for a in ("xy", "xz", "yz")):
        raise ctx.error("probe_compliance needs the true 'bending_<unit>' (or bending_x/_y), "
                        "'axial_<unit>' and/or a coupling term 'coupling_xy_<unit>' (xz, yz)", tbl)
    for k in ("bending", "bending_x", "bending_y", "axial"):
        if e[k] is not None and e[k] < 0:
            raise ctx.error(f"'{k}' must not be negative", tbl, k)
    _check_compliance_matrix(ctx, e, desc, tbl, raw)


def _force_sensor(ctx, e: dict, tbl, sensor: str) -> None:
    if e["cross_talk"] is None:
        e["cross_talk"] = np.zeros((3, 3))
    if np.any(np.diag(e["cross_talk"]) != 0):
        raise ctx.error("the diagonal of 'cross_talk' must be 0 (gains are 'gain')", tbl, "cross_talk")
    if min(e["gain"]) <= -1:
        raise ctx.error("'gain' must be > -1 (reading = (1 + gain) force)", tbl, "gain")
    if sensor == "two-channel" and (e["gain"][1] or e["offset"][1] or np.any(e["cross_talk"][1])):
        raise ctx.error("the two-channel sensor does not measure probe y: its gain, offset and "
                        "cross-talk row must be 0", tbl)


def _truth_effect(ctx, name: str, raw: dict, desc, sensor: str) -> dict:
    """One effect table of [truth] (joint_compliance, thermal, probe_compliance, force_sensor,
    lateral_compliance, approach_offset), read and checked."""
    tbl = ("truth", name)
    e = _section(ctx, raw, _S[name], tbl)
    if name in ("joint_compliance", "thermal"):
        _joint_values(ctx, e, name, desc, tbl)
    if name == "lateral_compliance":
        _lateral_compliance(ctx, e, desc, tbl, raw)
    if name == "approach_offset":
        _approach_offset(ctx, e, tbl, raw)
    if name == "probe_compliance":
        _probe_compliance(ctx, e, desc, tbl, raw)
    if name == "force_sensor":
        _force_sensor(ctx, e, tbl, sensor)
    return e


def _truth(ctx, data: dict, desc, sensor: str) -> dict:
    """The [truth] table: random error sizes, given errors and every effect of the true arm."""
    truth = _section(ctx, data.get("truth"), _S["truth"], ("truth",))
    for k in ("length_error", "angle_error", "probe_error"):
        if truth[k] < 0:
            raise ctx.error(f"'{k}' (the size of the random errors, 1 sigma) must not be negative", ("truth",),
                            _given_key(data.get("truth") or {}, k))
    raw_truth = data.get("truth") or {}
    truth["errors"] = _errors(ctx, raw_truth.get("errors"), desc)
    ecc = raw_truth.get("eccentricity")
    if ecc is not None:
        truth["eccentricity"] = _eccentricities(ctx, ecc, desc)
    truth["harmonics"] = _harmonics(ctx, raw_truth.get("harmonics"), desc)
    for name in ("joint_compliance", "thermal", "probe_compliance", "force_sensor", "lateral_compliance",
                 "approach_offset"):
        truth[name] = None if raw_truth.get(name) is None else _truth_effect(ctx, name, raw_truth[name], desc,
                                                                              sensor)
    if ecc is None:
        truth["eccentricity"] = []
    return truth


#: the shortest temperature cycle [s] and signal sample period [s] a campaign may ask for (0 s or 1e-320 s made every
#: temperature or time stamp NaN: an internal error; 1e9 s put every time stamp at 0)
_SHORTEST_CYCLE_S, _SHORTEST_SAMPLE_S = 1.0, 1e-6


def _sections(ctx, data: dict) -> dict:
    """The [noise], [environment], [operator] and [signals] tables, checked."""
    sections = {}
    for name in ("noise", "environment", "operator", "signals"):
        sections[name] = _section(ctx, data.get(name), _S[name], (name,))
    for k, v in sections["noise"].items():
        if v < 0:
            raise ctx.error(f"'{k}' must not be negative", ("noise",), k)
    for k, bound in _NOISE_MAX.items():
        if sections["noise"][k] * _NOISE_SHOWN[k][0] > bound:
            raise ctx.error(f"'{k}' must be at most {bound:g} {_NOISE_SHOWN[k][1]} (1 sigma; beyond, the readings "
                            "are none an instrument gives)", ("noise",), k)
    if 0 < sections["noise"]["encoder_resolution"] < _FINEST_ENCODER_STEP:
        raise ctx.error(f"'encoder_resolution' must be 0 (no quantisation) or at least "
                        f"{math.degrees(_FINEST_ENCODER_STEP):g} deg (finer than any encoder; the readings are "
                        "quantised to its steps)", ("noise",), "encoder_resolution")
    op = sections["operator"]
    if not 0 < op["min_force"] < op["max_force"]:
        raise ctx.error(f"need 0 < min_force < max_force, got {op['min_force']:g} N and {op['max_force']:g} N",
                        ("operator",), "min_force")
    if not op["min_force"] <= op["force_mean"] <= op["max_force"]:
        raise ctx.error(f"force_mean must lie between min_force and max_force ({op['min_force']:g} to "
                        f"{op['max_force']:g} N), got {op['force_mean']:g} N", ("operator",), "force_mean")
    for k in ("level_log_sd", "point_cv", "friction_coefficient"):
        if op[k] < 0:
            raise ctx.error(f"'{k}' must not be negative", ("operator",), k)
    if not 0 <= op["spike_probability"] <= 1:
        raise ctx.error("'spike_probability' must lie in [0, 1]", ("operator",), "spike_probability")
    if op["measurement_gap"] < 0:
        raise ctx.error("'measurement_gap' must not be negative", ("operator",), "measurement_gap")
    env = sections["environment"]
    if env["cycle_period"] < _SHORTEST_CYCLE_S:
        raise ctx.error(f"'cycle_period' must be at least {_SHORTEST_CYCLE_S:g} s (a room's temperature cycle), got "
                        f"{env['cycle_period']:g} s", ("environment",), "cycle_period")
    sg = sections["signals"]
    if sg["sample_period"] <= 0 or sg["rise"] <= 0 or sg["decay"] <= 0:
        raise ctx.error("sample period, rise and decay must be > 0", ("signals",))
    if not _SHORTEST_SAMPLE_S <= sg["sample_period"] <= min(sg["rise"], sg["decay"]):
        raise ctx.error(f"'sample_period' must be from {_SHORTEST_SAMPLE_S:g} s to the shorter of rise and decay "
                        f"({min(sg['rise'], sg['decay']):g} s: a pulse sampled at least once), got "
                        f"{sg['sample_period']:g} s (every time stamp is a multiple of it)", ("signals",),
                        "sample_period")
    if op["point_period"] < 1.5 * (sg["rise"] + sg["decay"]):
        raise ctx.error(f"'point_period' must be at least 1.5 x (rise + decay) = "
                        f"{1.5 * (sg['rise'] + sg['decay']):.3g} s so that pulses do not overlap",
                        ("operator",), "point_period_s")
    return sections


def _task(ctx, t, i: int, ids: dict[str, str], sensor: str) -> Task:
    """One [[task]] table (number ``i``); ``ids``: the task ids so far (this one is added)."""
    tbl = ("task", i)
    if not isinstance(t, dict):
        raise ctx.error("expected a table", tbl)
    kind = t.get("kind")
    if kind not in TASK_KINDS:
        raise ctx.error(f"'kind' must be one of {', '.join(TASK_KINDS)}, got {kind!r}", tbl, "kind")
    spec = dict(_COMMON_TASK)
    spec.update(_TASKS[kind])  # type: ignore[call-overload]
    o = _section(ctx, t, spec, tbl)
    tid = o.pop("id") or _ID[kind]
    if not re.fullmatch(r"[A-Za-z0-9_.\-]+", tid):
        raise ctx.error(f"'id' {tid!r} may hold letters, digits, '_', '.', '-' only", tbl, "id")
    if len(tid) > MAX_ID_LENGTH - _ID_SUFFIX:      # its measurements' ids ("<id>-pos-07") are ids the reader takes
        raise ctx.error(f"'id' must be at most {MAX_ID_LENGTH - _ID_SUFFIX} characters long (a measurement id adds "
                        f"its number to it, and an id is at most {MAX_ID_LENGTH}), got {len(tid)}", tbl, "id")
    if tid in ids:
        raise ctx.error(f"task id '{tid}' is used twice", tbl, "id")
    ids[tid] = kind
    o.pop("kind")
    n_meas = o.pop("measurements")
    if kind == "ballbar" and "measurements" in t:
        raise ctx.error("a ball bar makes one measurement a position: give 'positions'", tbl, "measurements")
    if kind == "mocap" and ("measurements" in t or any(k.startswith("stylus_cone") for k in t)):
        raise ctx.error("a motion-capture task makes one measurement a posture, without contact: give "
                        "'postures'", tbl, "measurements" if "measurements" in t else
                        next(k for k in t if k.startswith("stylus_cone")))
    if kind == "ring" and any(k.startswith("stylus_cone") for k in t):
        raise ctx.error("a ring's stylus is parallel to its axis: tilt it with 'stylus_tilt_<angle unit>'",
                        tbl, next(k for k in t if k.startswith("stylus_cone")))
    if kind in ("ballbar", "tracker"):      # without a region of its own, the chain's workspace holds what it cannot
        o["region_given"] = any(re.fullmatch(r"(radius|height|reach)_.+", str(k)) for k in t)
    if kind == "ballbar":
        n_meas = o["positions"]
    if kind == "mocap":
        n_meas = o["postures"]
    if o["stylus_cone"] is None:
        o["stylus_cone"] = _DEFAULT_CONE[kind]
    _check_task(ctx, kind, o, tbl, sensor)
    if n_meas < 1:
        raise ctx.error("need at least one measurement", tbl, "measurements")
    return Task(kind, tid, n_meas, o, ctx.lines.get(tbl))


def _tasks(ctx, data: dict, sensor: str) -> list[Task]:
    """The [[task]] tables (at least one)."""
    raw_tasks = data.get("task")
    if raw_tasks is None:
        raw_tasks = []
    if not isinstance(raw_tasks, list):
        raise ctx.error("'task' must be [[task]] tables", (), "task")
    if not raw_tasks:
        raise ctx.error("no [[task]] tables: nothing to simulate", ())
    ids: dict[str, str] = {}
    return [_task(ctx, t, i, ids, sensor) for i, t in enumerate(raw_tasks)]


def _parse(data: dict, path: str, lines: dict | None, base_dir: Path | None, arm=None) -> Campaign:
    """A campaign from its TOML ``data``: the top table, the arm, the truth, the sections, the tasks."""
    ctx = _Ctx(path, lines)
    top = _section(ctx, data, _S["top"], ())
    if top["sensor"] not in SENSORS:
        raise ctx.error(f"'sensor' must be one of {', '.join(SENSORS)}, got {top['sensor']!r}", (), "sensor")
    desc, arm_path = _campaign_arm(ctx, top, base_dir, arm)
    truth = _truth(ctx, data, desc, top["sensor"])
    sections = _sections(ctx, data)
    op, sg = sections["operator"], sections["signals"]
    tasks = _tasks(ctx, data, top["sensor"])
    _check_mocap(ctx, tasks)
    _check_size(ctx, tasks, op, sg)
    return Campaign(name=top["name"], seed=top["seed"], arm=desc, arm_path=arm_path, sensor=top["sensor"],
                    truth=truth, noise=sections["noise"], environment=sections["environment"],
                    operator=op, signals=sg, tasks=tuple(tasks),
                    source=None if path.startswith("<") else Path(path), description=top["description"],
                    raw=data)


#: the most points a campaign may ask for (the simulator makes ~500 points/s with their force signals)
MAX_POINTS = 1_000_000


def points_per_measurement(kind: str, o: dict) -> int:
    """Captured points of one measurement of a task (tracker tasks: points of the arm, not the tracker)."""
    if kind == "ring":
        return len(o["depths"]) * int(o["points_per_row"])
    if kind in ("sphere", "plane"):
        return int(o["points"])
    if kind == "mocap":
        return 1
    if kind == "seat":
        return int(o["articulations"])
    if kind == "ballbar":
        return 2 * int(o["points_per_sphere"] if o["ends"] == "sphere" else o["articulations"])
    return int(o["nests"]) * int(o["articulations"])        # tracker


def _check_size(ctx, tasks, op, sg) -> None:
    """Refuse a campaign too large to simulate, with an estimate, before anything is allocated."""
    n = sum(t.measurements * points_per_measurement(t.kind, t.opts) for t in tasks)
    if n <= MAX_POINTS:
        return
    big = max(tasks, key=lambda t: t.measurements * points_per_measurement(t.kind, t.opts))
    samples = n * op["point_period"] / sg["sample_period"] if sg["enabled"] else 0.0
    raise ctx.error(f"the campaign asks for {n:.3g} points (about {n / 500 / 3600:.3g} h at ~500 points/s"
                    + (f", {samples * 30 / 1e9:.3g} GB of force signals" if samples else "")
                    + f"); at most {MAX_POINTS:,} points a campaign: fewer measurements or points (task "
                      f"'{big.id}' asks for {big.measurements} x {points_per_measurement(big.kind, big.opts)})",
                    ("task", tasks.index(big)))


#: a task's half-angles of cones (a direction within that angle of an axis): from 0 to 180 deg; its random angle
#: spreads (1 sigma): not negative
_CONE_KEYS = ("stylus_cone", "stylus_tilt", "polar_max", "force_cone")
_SPREAD_KEYS = ("angle_jitter", "roll_jitter")
#: a task's sizes that cannot be negative (uncertainties, form errors, spreads, noise, offsets, a ring's depths
#: below its top face; -1 mm was an internal error or a silent ring probed above itself) and those that must be
#: above 0 (an instrument's distance, a plane's extent; a bar's true length: at least an artefact's; 0 or -1 mm
#: were simulated as given)
_NON_NEGATIVE_KEYS = ("u_diameter", "form_error", "true_form_error", "depth_jitter", "depths", "noise",
                      "marker_distance", "limit_margin")
_POSITIVE_KEYS = ("distance", "size")
#: the most markers a motion-capture task carries on the arm (10^7 ran for minutes on 4 postures)
MAX_MARKERS = 100


def _check_task(ctx, kind, o, tbl, sensor):
    for k in _CONE_KEYS:
        if k in o and not 0.0 <= o[k] <= math.pi:
            raise ctx.error(f"'{k}' is a cone's half-angle: from 0 to 180 deg, got {math.degrees(o[k]):.6g} deg",
                            tbl, k)
    for k in _SPREAD_KEYS:
        if k in o and o[k] < 0:
            raise ctx.error(f"'{k}' (a spread, 1 sigma) must not be negative", tbl, k)
    for k in _NON_NEGATIVE_KEYS:
        if o.get(k) is not None and min(np.atleast_1d(o[k])) < 0:
            raise ctx.error(f"'{k}' must not be negative", tbl, k)
    for k in _POSITIVE_KEYS:
        if o.get(k) is not None and min(np.atleast_1d(o[k])) <= 0:
            raise ctx.error(f"'{k}' must be > 0", tbl, k)
    if kind == "ballbar" and o["true_length"] is not None and o["true_length"] < SMALLEST_ARTEFACT_M:
        raise ctx.error(f"'true_length' must be at least {SMALLEST_ARTEFACT_M * 1e3:g} mm (as a certified length)", tbl,
                        "true_length")
    if kind == "ring" and o["form_lobes"] < 2:
        raise ctx.error("'form_lobes' must be at least 2 (one lobe is a shifted circle, none a size error: no form "
                        "error either way)", tbl, "form_lobes")
    if kind == "mocap" and not 1 <= o["markers"] <= MAX_MARKERS:
        raise ctx.error(f"'markers' must be from 1 to {MAX_MARKERS}", tbl, "markers")
    positive = {"ring": ("diameter", "points_per_row"), "sphere": ("diameter", "points"),
                "plane": ("points",), "seat": ("articulations",),
                "ballbar": ("length", "positions", "sphere_diameter", "reach"),
                "tracker": ("nests", "articulations", "reach"),
                "mocap": ("postures", "sessions")}[kind]
    for k in positive:
        if o[k] <= 0:
            raise ctx.error(f"'{k}' must be > 0", tbl, k)
    if kind == "mocap":
        if o["sessions"] > o["postures"]:
            raise ctx.error(f"{o['sessions']} sessions for {o['postures']} postures: each session needs postures",
                            tbl, "sessions")
    if kind == "ring":
        if o["roll"] is None:   # the paper's sensor sees one bending axis: its operator keeps it on the force
            o["roll"] = "bend-along-force" if sensor == "two-channel" else "random"
        if o["roll"] not in ("random", "bend-along-force"):
            raise ctx.error("'roll' must be \"random\" or \"bend-along-force\"", tbl, "roll")
    if kind == "seat" and o["order"] not in SEAT_ORDERS:
        raise ctx.error(f"'order' must be one of {', '.join(map(repr, SEAT_ORDERS))}", tbl, "order")
    if kind == "ballbar":
        if o["ends"] not in ("sphere", "seat"):
            raise ctx.error("'ends' must be \"sphere\" or \"seat\"", tbl, "ends")
        if o["ends"] == "sphere" and o["points_per_sphere"] < 1:
            raise ctx.error("'points_per_sphere' must be > 0", tbl, "points_per_sphere")
        if o["ends"] == "seat" and o["articulations"] < 1:
            raise ctx.error("'articulations' must be > 0", tbl, "articulations")
    if kind in ("ballbar", "tracker"):
        for k in ("radius", "height"):
            if o[k][0] >= o[k][1]:
                raise ctx.error(f"'{k}' must be [low, high] with low < high", tbl, k)


def _check_mocap(ctx, tasks) -> None:
    """One motion-capture task a campaign (its markers are the points file's markers); several markers
    cannot share the reference columns with tracker nests, which the instrument sees at the ball centre."""
    mocap = [k for k, t in enumerate(tasks) if t.kind == "mocap"]
    if len(mocap) > 1:
        raise ctx.error("one motion-capture task a campaign (its markers are the points file's markers); for "
                        "several placements of the instrument give 'sessions'", ("task", mocap[1]), "kind")
    if mocap and tasks[mocap[0]].opts["markers"] > 1 and any(t.kind == "tracker" for t in tasks):
        raise ctx.error("several markers cannot share the reference columns with tracker nests (a nest is seen "
                        "at the ball centre, one marker): give 'markers = 1' or simulate them apart",
                        ("task", mocap[0]), "markers")


_PARAM_QUANTITY = {"m": "length", "rad": "angle", "m/N": "compliance"}


def _errors(ctx, tbl, desc) -> dict[str, float]:
    """Explicit true parameter errors ``"j2.d_um" = 25.0`` -> {"j2.d": 2.5e-5}."""
    from ..params import param_spec

    if tbl is None:
        return {}
    where = ("truth", "errors")
    if not isinstance(tbl, dict):
        raise ctx.error("expected a table of parameter errors", where)
    spec = param_spec(desc)
    out = {}
    for key, v in tbl.items():
        parts = _split(key)
        if parts is None or parts[0] not in spec.names:
            raise ctx.error(f"unknown parameter key '{key}'{did_you_mean(key, spec.names)} (expected a parameter name "
                            f"with a unit, e.g. \"{spec.names[1]}_um\"; names: {', '.join(spec.names)})", where, key)
        base, unit = parts
        quantity = _PARAM_QUANTITY[spec.units[spec.index(base)]]
        if _UNITS[unit][0] != quantity:
            raise ctx.error(f"'{base}' is a {quantity}, '_{unit}' is not (e.g. {_example(quantity)})", where, key)
        out[base] = _number(ctx, v, where, key) * _UNITS[unit][1]
    return out


def load_campaign(path: str | Path) -> Campaign:
    """Read a campaign TOML file; the arm path in it is relative to the file (:func:`arm_model.errors.beside`: the
    real file's folder, its links followed)."""
    path = Path(path)
    text = read_text(path, "the campaign file")
    data = parse_toml(text, str(path))
    return _parse(data, str(path), toml_key_lines(text), beside(path))


def campaign_from_dict(data: dict, arm: str | Path | ArmDescription | None = None,
                       base_dir: str | Path | None = None) -> Campaign:
    """A campaign from a dict with the structure of the TOML file (e.g. ``{"seed": 1, "task":
    [{"kind": "sphere", "points": 5}]}``). ``arm``: a description or its path (default: the
    dict's ``arm`` or the nominal arm ``urdf/aacmm7.dh.toml``)."""
    if not isinstance(data, dict):
        raise InputError("a campaign must be a dict", "<dict>")
    return _parse(data, "<dict>", None, None if base_dir is None else Path(base_dir), arm)
