"""The model file: an arm description plus the effects a calibration found, with their parameters.

One TOML file (``aacmm calibrate`` and ``aacmm close-loop`` write it, every ``--arm`` reads it):

* the description (``name``, ``convention``, ``[[joint]]``, ``[probe]``) with the calibrated values
  folded in, exactly as :mod:`arm_model.description` reads it;
* one ``[[effect]]`` table an effect: ``kind`` (a key of :data:`arm_model.effects.EFFECTS`),
  ``joints`` (joint names; absent: all joints), the effect's other options (its dataclass fields,
  e.g. ``harmonics``, ``gravity``) and ``parameter``, one entry a parameter of the effect
  (``param_defs``): ``name``, ``value_<unit>``, ``u_<unit>`` (standard uncertainty; 0 when not
  estimated) and ``state`` ("free", "prior-dominated", "fixed" or "held") — units from :data:`PARAM_UNITS`;
* an optional ``[calibration]`` table: ``covariance`` (the covariance file, relative to the TOML),
  ``written_by`` and ``probing_scatter_um`` (the scatter of the contact itself per axis that the
  calibration's variance components estimated, net of the encoder and force-sensor noise:
  :meth:`calibration.CalibrationResult.probing_scatter`; ``aacmm tip``'s default probing uncertainty) and
  ``model_discrepancy_um`` (the error per axis beyond the fit's own prediction on poses away from those it was
  fitted on, by extrapolative cross-validation: :mod:`calibration.discrepancy`; ``aacmm tip`` adds it),
  ``model_discrepancy_growth_um_per_mm`` (how that error grows per mm the joint motions from the nearest
  training pose carry the ball, one number or a list of one a joint: :mod:`arm_model.discrepancy`) and
  ``training_poses`` (the points file of the poses the calibration was fitted on, relative to the TOML; read by
  :func:`training_poses_of`), all optional;
* optional ``[[reference_frame]]`` and ``[[marker]]`` tables: the reference instrument's frame of each
  session and the markers' offsets on the tip frame that a calibration on tracker data estimated
  (:mod:`arm_model.tracker`; ``aacmm tip --reference-frame`` predicts the instrument's coordinates).

The covariance file (:func:`write_covariance`, :func:`read_covariance`) is a CSV: one row a free
parameter of the fit, columns ``parameter``, ``unit``, ``value``, ``u`` (in that row's unit) and one
column per parameter holding the correlation coefficients, so that
``cov[i, k] = u[i] * u[k] * corr[i, k]``: the covariance of the parameters of the model read (its base errors
turn a URDF origin about the model file's own origin axes; the writer expresses the fit's covariance in them:
:func:`arm_model.params.folded_jacobian`).

The serialisation is generic over :class:`arm_model.effects.Effect`: an effect's options are its
dataclass fields and its parameters its ``param_defs``, so a new effect class needs no code here
(only, for a new SI unit, an entry of :data:`PARAM_UNITS`).
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .description import (
    MODEL_KEYS,
    ArmDescription,
    TomlReader,
    check_calibration_table,
    description_data,
    description_from_data,
    in_unit,
    toml_text,
)
from .discrepancy import GrowingDiscrepancy, TrainingPoses
from .effects import EFFECTS, Effect
from .errors import InputError, beside, did_you_mean, named_in, parse_toml, path_problem, read_text, resolved
from .model import ArmModel, AuxData, capture_columns, points_motion
from .tracker import Tracker, tracker_from_tables, tracker_tables
from .uncertainty import InputUncertainty, ParameterCovariance, default_inputs
from .units import implausible

__all__ = ["Arm", "PARAM_UNITS", "parse_model", "load_model", "format_model", "effect_tables", "training_poses_of",
           "effects_from_tables", "write_covariance", "read_covariance", "Covariance", "EFFECT_COLUMNS",
           "parameters_of", "read_model_file"]

#: SI unit of an effect parameter -> the unit suffixes a model file may use, (suffix, factor to SI); the
#: first is the one written. A new effect whose parameters have a new SI unit adds an entry here.
PARAM_UNITS: dict[str, tuple[tuple[str, float], ...]] = {
    "m": (("um", 1e-6), ("mm", 1e-3), ("m", 1.0)),
    "rad": (("urad", 1e-6), ("mrad", 1e-3), ("deg", math.pi / 180.0), ("rad", 1.0)),
    "m/N": (("um_per_N", 1e-6), ("mm_per_N", 1e-3), ("m_per_N", 1.0)),
    "rad/(N m)": (("urad_per_Nm", 1e-6), ("rad_per_Nm", 1.0)),
    "1/K": (("ppm_per_K", 1e-6), ("per_K", 1.0)),
    "1": (("ppm", 1e-6), ("pct", 1e-2), ("ratio", 1.0)),
    "N": (("N", 1.0),),
    "N m": (("Nm", 1.0), ("Nmm", 1e-3)),
    "K": (("K", 1.0),),
    "s": (("s", 1.0),),
    "kg": (("kg", 1.0),),
}
#: SI unit of an effect parameter -> its quantity, for the plausible range (arm_model.units.PLAUSIBLE_SI)
PARAM_QUANTITY: dict[str, str] = {
    "m": "length", "rad": "angle", "m/N": "compliance", "rad/(N m)": "angular compliance", "1/K": "expansion",
    "1": "ratio", "N": "force", "N m": "torque", "K": "temperature difference", "s": "time", "kg": "mass",
}

#: per-point input of an effect (``Effect.needs``) -> the points-file column it comes from (None:
#: computed from the description, e.g. gravity and contact torques)
EFFECT_COLUMNS: dict[str, str | None] = {"temperature": "temperature_C", "tau_gravity": None, "tau_contact": None,
                                         "time": "time_s"}

STATES = ("free", "prior-dominated", "fixed", "held")


def _unit_of(si: str) -> tuple[str, float]:
    try:
        return PARAM_UNITS[si][0]
    except KeyError:
        raise ValueError(f"no model-file unit for the SI unit {si!r}: add it to "
                         "arm_model.model_file.PARAM_UNITS") from None


# ---------------------------------------------------------------------------------------------
# the arm as --arm gives it

@dataclass(frozen=True)
class Arm:
    """An arm as every ``--arm`` option gives it: the description, its effects and their parameter
    values [SI] by name (``values``; the description's own values are folded in, so the base part
    of the parameter vector is zero), with standard uncertainties and states when a fit wrote them.
    ``covariance``: the covariance file named by the model file (resolved path) or None;
    ``probing_scatter``: the calibration's estimate of the scatter of one probed ball centre per axis [m]
    (``[calibration] probing_scatter_um``) or None; ``tracker``: the reference instrument's frames and the
    markers' offsets (``[[reference_frame]]``, ``[[marker]]``) or None; ``model_discrepancy``: the
    calibration's model discrepancy per axis [m] at its training poses (``[calibration] model_discrepancy_um``)
    or None; ``discrepancy_growth``: its growth [1] (m per m of ``d`` from the nearest training pose, one number or
    a tuple of one a joint: :class:`~arm_model.discrepancy.GrowingDiscrepancy`;
    ``model_discrepancy_growth_um_per_mm``) or None; ``training_poses``: the points file of the calibration's
    poses (resolved path; ``training_poses``) or None."""
    desc: ArmDescription
    effects: tuple[Effect, ...] = ()
    values: dict = field(default_factory=dict)
    uncertainties: dict = field(default_factory=dict)
    states: dict = field(default_factory=dict)
    covariance: Path | None = None
    probing_scatter: float | None = None
    tracker: Tracker | None = None
    model_discrepancy: float | None = None
    discrepancy_growth: float | tuple[float, ...] | None = None
    training_poses: Path | None = None

    def __post_init__(self):
        """A ValueError for what a model file's reader would refuse (:func:`check_calibration_table`): a scatter,
        discrepancy or growth not finite or out of its range, or a growth above 0 without the discrepancy it grows
        from and the training poses it grows away from (it would otherwise be silently ignored). A growth given as
        a list or an array is kept as a tuple."""
        if isinstance(self.discrepancy_growth, (list, np.ndarray)):
            object.__setattr__(self, "discrepancy_growth", tuple(np.asarray(self.discrepancy_growth).ravel().tolist()))
        cal = {k: [_scaled(x, f) for x in v] if isinstance(v, tuple) else _scaled(v, f)
               for k, v, f in (("probing_scatter_um", self.probing_scatter, 1e6),
                               ("model_discrepancy_um", self.model_discrepancy, 1e6),
                               ("model_discrepancy_growth_um_per_mm", self.discrepancy_growth, 1e3))
               if v is not None}
        if isinstance(self.discrepancy_growth, tuple) and len(self.discrepancy_growth) != self.desc.n_joints:
            raise ValueError(f"Arm: discrepancy_growth lists {len(self.discrepancy_growth)} growths, the arm has "
                             f"{self.desc.n_joints} joints")
        if self.training_poses is not None:
            cal["training_poses"] = Path(self.training_poses).name or "training_poses"
        try:
            check_calibration_table(cal, TomlReader("<Arm>", ""))
        except InputError as exc:
            raise ValueError(f"Arm: {exc.reason} (given in SI: probing_scatter and model_discrepancy in m, "
                             "discrepancy_growth in m/m, training_poses the path of a points file)") from None

    @functools.cached_property
    def discrepancy(self) -> GrowingDiscrepancy | float | None:
        """The model discrepancy as :func:`arm_model.uncertainty.default_inputs` takes it: a
        :class:`~arm_model.discrepancy.GrowingDiscrepancy` (its training poses read from their file, once:
        :func:`training_poses_of`) when the file gives a growth, else the constant ``model_discrepancy`` [m] or
        None."""
        g = self.discrepancy_growth
        if self.model_discrepancy is None or g is None or max(g if isinstance(g, tuple) else (g,)) == 0:
            return self.model_discrepancy
        return GrowingDiscrepancy(self.model_discrepancy, self.discrepancy_growth, training_poses_of(self))

    def input_uncertainty(self, has_force: bool = True, **given) -> InputUncertainty:
        """The input uncertainties of this arm's points: :func:`arm_model.uncertainty.default_inputs` with the
        model file's probing scatter and model discrepancy (growing away from its training poses when it says
        so) as their defaults, ``given`` overriding any of them (``default_inputs``' keywords). The one
        place every command that reports a point's uncertainty (``tip``, ``ring``, ``view``, ``live`` and the
        :class:`~arm_model.live.Session` of Python) takes them from, so that one model file gives one ``u``."""
        # a given discrepancy replaces the model file's, its growth too: the training poses are then not read
        model_disc = self.model_discrepancy if given.get("discrepancy") is not None else self.discrepancy
        return default_inputs(self.desc, has_force=has_force, model_probing=self.probing_scatter,
                              model_discrepancy=model_disc, **given)

    @functools.cached_property
    def model(self) -> ArmModel:
        """The :class:`~arm_model.model.ArmModel` of the description and the effects (made once: both are fixed)."""
        return ArmModel(self.desc, tuple(self.effects))

    @property
    def p(self) -> np.ndarray:
        """The parameter vector of :attr:`model`: zeros for the description, the effects' values."""
        return self.model.spec.vector(self.values)

    def needed_columns(self) -> list[tuple[Effect, str, str]]:
        """(effect, input, column) of every per-point input an effect reads from a column of the points (or of a live
        stream): ``temperature`` from ``temperature_C``, ``time`` from ``time_s`` (:data:`EFFECT_COLUMNS`)."""
        return [(e, need, column) for e in self.effects for need in e.needs()
                if (column := EFFECT_COLUMNS.get(need)) is not None]

    def missing_inputs(self, points) -> list[tuple[Effect, str]]:
        """(effect, column) of every points-file column an effect needs and ``points`` lack."""
        return [(e, column) for e, need, column in self.needed_columns()
                if (t := getattr(points, need)) is None or not np.all(np.isfinite(t))]

    def check_columns(self, columns, what: str, path, line: int) -> None:
        """An :class:`InputError` at ``path``, ``line`` naming the effect and the column when ``columns`` (the names
        a file or a stream gives: ``what``, "points" or "stream") lack one an effect needs: the one rule of
        :meth:`check_points`, for a header read before any row (``aacmm live``'s stream, before its folder exists)."""
        for e, _, column in self.needed_columns():
            if column not in columns:
                raise _missing_column(e, column, what, path, line)

    def check_points(self, points) -> None:
        """An :class:`InputError` naming the effect and the column when ``points`` lack a column an
        effect needs."""
        missing = self.missing_inputs(points)
        if missing:
            raise _missing_column(*missing[0], "points", points.path, 1, " (or hold a non-finite value in)")

    def aux(self, points, wrench=None, contact: bool = True, motion: np.ndarray | None = None) -> AuxData | None:
        """Per-point inputs of the effects for a :class:`~arm_model.io.PointSet` (temperature from its
        column; gravity and contact torques from this description by Pinocchio at the angles the joints take
        under them, the static equilibrium :meth:`~arm_model.model.ArmModel.equilibrium_aux`, and ``wrench``,
        default the points' own; each joint's last move: ``motion`` (N, J) [1] when given, else from the points,
        :func:`~arm_model.model.points_motion`; each point's place in its measurement's capture,
        :func:`~arm_model.model.capture_columns`). A column an effect needs and the points lack is an
        :class:`InputError` naming the effect and the column. ``contact=False``: contact torques zero."""
        self.check_points(points)
        needs = self.model.needs()
        if not needs:
            return None
        temperature = points.temperature if "temperature" in needs else None
        time = points.time if "time" in needs else None
        motion = points_motion(points, motion) if "motion" in needs else None
        capture = (capture_columns(self.model.capture_measurements, points.measurement, points.time)
                   if "capture" in needs else None)
        if needs & {"tau_gravity", "tau_contact"}:
            w = points.wrench if wrench is None else wrench
            return self.model.equilibrium_aux(points.q, w, self.p, temperature, contact=contact, time=time,
                                              motion=motion, capture=capture)
        return AuxData(temperature, time=time, motion=motion, capture=capture)

    def ball_centres(self, points, wrench=None, rigid: bool = False, motion: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) ball centres [m] of a :class:`~arm_model.io.PointSet` with every effect applied, from
        the points' wrench (or ``wrench``, e.g. forces found in signals). ``rigid``: at a zero force
        reading (no contact wrench, no contact torques), the other effects still applied. ``motion``: as
        :meth:`aux`."""
        w = points.wrench if wrench is None else np.asarray(wrench, dtype=float)
        if rigid:
            w = None
        aux = self.aux(points, wrench=w, contact=not rigid, motion=motion)
        return self.model.ball_centres(points.q, w, self.p, aux)


# ---------------------------------------------------------------------------------------------
# effects <-> TOML tables (generic over Effect subclasses)

def _options(effect: Effect) -> list[dataclasses.Field]:
    """The dataclass fields of an effect that a model file carries (all but ``key`` and ``joints``)."""
    return [f for f in dataclasses.fields(effect) if f.init and f.name not in ("key", "joints")]


def _plain(v):
    if isinstance(v, (bool, str)):
        return v
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, (tuple, list)):
        return [_plain(x) for x in v]
    raise ValueError(f"an effect option of type {type(v).__name__} cannot be written to a model file")


def effect_tables(desc: ArmDescription, effects, values: dict, uncertainties: dict | None = None,
                  states: dict | None = None) -> list[dict]:
    """The ``[[effect]]`` tables of ``effects`` (values and uncertainties [SI] by parameter name)."""
    out = []
    for e in effects:
        tbl: dict = {"kind": e.key}
        if e.joints is not None:
            tbl["joints"] = [desc.joint_names[i] for i in e.joints]
        for f in _options(e):
            if getattr(e, f.name) is not None:          # TOML has no null: an absent option takes its default
                tbl[f.name] = _plain(getattr(e, f.name))
        params = []
        for name, si in e.param_defs(desc):
            suffix, factor = _unit_of(si)
            row = {"name": name, f"value_{suffix}": in_unit(values.get(name, 0.0), factor),
                   f"u_{suffix}": in_unit((uncertainties or {}).get(name, 0.0), factor)}
            if states and name in states:
                row["state"] = states[name]
            params.append(row)
        tbl["parameter"] = params
        out.append(tbl)
    return out


def _option_value(value, default, r: TomlReader, where: tuple):
    """``value`` read as the type of the field's ``default``."""
    def bad(what):
        return r.error(f"must be {what}, got {value!r}", *where)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad("a whole number")
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise bad("a finite number")
        return float(value)
    if isinstance(default, str):
        if not isinstance(value, str):
            raise bad("a text")
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list):
            raise bad("a list")
        kinds = {type(x) for x in default}
        for x in value:
            if isinstance(x, bool) or (kinds and not any(isinstance(x, k) for k in kinds)):
                raise bad(f"a list of {' or '.join(sorted(k.__name__ for k in kinds))}")
        return tuple(value)
    if isinstance(value, list):
        return tuple(value)
    return value


def _joint_indices(value, jnames: list, r: TomlReader, where: tuple) -> tuple:
    """The indices of an effect's ``joints`` (a list of joint names, each once) among ``jnames``."""
    if not isinstance(value, list) or not value or not all(isinstance(x, str) for x in value):
        raise r.error("'joints' must be a list of joint names", *where)
    for x in value:
        if value.count(x) > 1:
            raise r.error(f"joint '{x}' is named twice: an effect acts once on each joint", *where)
        if x not in jnames:
            raise r.error(f"no joint named '{x}' (joints: {', '.join(jnames)}){did_you_mean(x, jnames)}", *where)
    return tuple(jnames.index(x) for x in value)


def effects_from_tables(desc: ArmDescription, tables, r: TomlReader):
    """Effects, values, uncertainties and states [SI] of the ``[[effect]]`` tables of a model file."""
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise r.error("'effect' must be an array of tables ([[effect]])", "effect")
    effects, values, uncertainties, states = [], {}, {}, {}
    jnames = list(desc.joint_names)
    for i, tbl in enumerate(tables):
        where = ("effect", i)
        kind = tbl.get("kind")
        if not isinstance(kind, str):
            if kind is None:
                raise r.error(f"missing 'kind' (one of: {', '.join(EFFECTS)})", *where)
            raise r.error(f"'kind' must be text, one of: {', '.join(EFFECTS)}; got {kind!r}", *where, "kind")
        if kind not in EFFECTS:
            raise r.error(f"unknown effect kind '{kind}' (known: {', '.join(EFFECTS)}){did_you_mean(kind, EFFECTS)}",
                          *where, "kind")
        cls = EFFECTS[kind]
        if cls.session:
            raise r.error(f"the effect kind '{kind}' is a drift of one session (its time and room), not of the arm: a "
                          "model file holds the geometry at the drift's reference time and no drift (docs/formats.md)",
                          *where, "kind")
        fields = {f.name: f for f in dataclasses.fields(cls) if f.init and f.name not in ("key", "joints")}
        known = ("kind", "joints", *fields, "parameter")
        kwargs = {}
        for key, value in tbl.items():
            if key in ("kind", "parameter"):
                continue
            if key == "joints":
                kwargs["joints"] = _joint_indices(value, jnames, r, where + (key,))
                continue
            if key not in fields:
                raise r.error(f"unknown key '{key}' of a '{kind}' effect (known: {', '.join(known)})"
                              f"{did_you_mean(key, known)}", *where, key)
            f = fields[key]
            default = f.default if f.default is not dataclasses.MISSING else None
            kwargs[key] = _option_value(value, default, r, where + (key,))
        try:
            effect = cls(**kwargs)
            defs = effect.param_defs(desc)
        except (TypeError, ValueError, IndexError) as exc:
            raise r.error(f"not a valid '{kind}' effect: {exc}", *where) from None
        effects.append(effect)
        expected = {n: si for n, si in defs}
        lowest = dict(zip(expected, effect.lower_bounds(desc), strict=True))
        rows = tbl.get("parameter", [])
        if not isinstance(rows, list) or not all(isinstance(x, dict) for x in rows):
            raise r.error("'parameter' must be a list of tables", *where, "parameter")
        seen = set()
        for k, row in enumerate(rows):
            pw = where + ("parameter", k)
            name = row.get("name")
            if not isinstance(name, str):
                raise r.error("a parameter needs a 'name'", *pw)
            if name not in expected:
                raise r.error(f"'{name}' is not a parameter of this '{kind}' effect (its parameters: "
                              f"{', '.join(expected)}){did_you_mean(name, expected)}", *pw, "name")
            if name in seen or name in values:
                raise r.error(f"parameter '{name}' is given twice", *pw, "name")
            seen.add(name)
            units = dict(PARAM_UNITS.get(expected[name], ()))
            got: dict = {}
            for key, v in row.items():
                if key == "name":
                    continue
                if key == "state":
                    if v not in STATES:
                        raise r.error(f"'state' must be one of {', '.join(STATES)}, got {v!r}", *pw, key)
                    states[name] = v
                    continue
                base, _, suffix = key.partition("_")
                if base not in ("value", "u") or suffix not in units:
                    allowed = [f"{b}_{s}" for b in ("value", "u") for s in units] + ["state"]
                    raise r.error(f"unknown key '{key}' (a '{expected[name]}' parameter takes "
                                  f"{', '.join(allowed)}){did_you_mean(key, allowed)}", *pw, key)
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise r.error(f"'{key}' must be a finite number, got {v!r}", *pw, key)
                if base in got:
                    raise r.error(f"'{base}' is given twice (with two units)", *pw, key)
                got[base] = float(v) * units[suffix]
                wrong = implausible(got[base], PARAM_QUANTITY.get(expected[name], ""))
                if wrong:
                    raise r.error(f"'{key}': {wrong[1]}", *pw, key)
            if "value" not in got:
                raise r.error(f"parameter '{name}' has no 'value_<unit>' (e.g. "
                              f"value_{PARAM_UNITS[expected[name]][0][0]})",
                              *pw)
            if got.get("u", 0.0) < 0:
                raise r.error("a standard uncertainty must not be negative", *pw)
            _check_bound(name, expected[name], got["value"], lowest[name], r,
                         pw + (next(k for k in row if k.startswith("value_")),))
            values[name] = got["value"]
            uncertainties[name] = got.get("u", 0.0)
        missing = [n for n in expected if n not in seen]
        if missing:
            raise r.error(f"the '{kind}' effect lacks parameter(s) {', '.join(missing)}", *where, "parameter")
    try:
        ArmModel(desc, tuple(effects))
    except ValueError as exc:
        raise r.error(f"the effects overlap: {exc}", "effect") from None
    return tuple(effects), values, uncertainties, states


def _check_bound(name: str, unit: str, value: float, low: float, r: TomlReader, where: tuple) -> None:
    """An error at ``where`` when ``value`` [SI, ``unit``] is below the parameter's physical lower bound ``low``
    (:meth:`arm_model.effects.Effect.lower_bounds`: a compliance cannot be negative in total, nor a backlash; every
    fit holds a parameter at its bound, so only a hand edit writes one below)."""
    if not value < low - 1e-9 * abs(low):
        return
    if low == 0.0:
        what = ("a joint's backlash cannot be negative (gravity carries the link to the side it pushes it)"
                if unit == "rad" else "a compliance cannot be negative (the joint or link would turn against its load)")
        raise r.error(f"'{name}' is {value:.6g} {unit}: {what}; calibrate and close-loop hold it at 0", *where)
    raise r.error(f"'{name}' is {value:.6g} {unit}: the probe's compliance would be negative in total (this "
                  f"increment is at least {low:.6g} {unit}, minus the description's)", *where)


# ---------------------------------------------------------------------------------------------
# whole files

def parse_model(text: str, path: str = "<string>") -> Arm:
    """A model file (or a plain description) from TOML text; errors name the file, line and key."""
    data = parse_toml(text, path)
    r = TomlReader(path, text)
    desc = description_from_data(data, r, MODEL_KEYS)
    covariance = scatter = discrepancy = growth = training = None
    if "calibration" in data:
        check_calibration_table(data["calibration"], r)
        cal = data["calibration"]
        covariance, training = (_beside(path, cal.get(k), r, k) for k in ("covariance", "training_poses"))
        if training is not None and covariance is not None and _same_file(training, covariance):
            raise r.error("'training_poses' names the covariance file: the training poses are a points file of "
                          "their own (measurement, feature and the joint columns)", "calibration", "training_poses")
        if "probing_scatter_um" in data["calibration"]:
            scatter = float(data["calibration"]["probing_scatter_um"]) * 1e-6
        if "model_discrepancy_um" in data["calibration"]:
            discrepancy = float(data["calibration"]["model_discrepancy_um"]) * 1e-6
        if "model_discrepancy_growth_um_per_mm" in data["calibration"]:
            growth = _growth_of(data["calibration"]["model_discrepancy_growth_um_per_mm"], desc, r)
    tracker = tracker_from_tables(data, r)
    if "effect" not in data:
        return Arm(desc, covariance=covariance, probing_scatter=scatter, tracker=tracker,
                   model_discrepancy=discrepancy, discrepancy_growth=growth, training_poses=training)
    effects, values, u, states = effects_from_tables(desc, data["effect"], r)
    return Arm(desc, effects, values, u, states, covariance, scatter, tracker, discrepancy, growth, training)


def _scaled(v, factor: float):
    """``v * factor`` for a number (not a bool), else ``v`` as given (for the checker to refuse by name)."""
    return v * factor if isinstance(v, (int, float)) and not isinstance(v, bool) else v


def _growth_of(value, desc: ArmDescription, r: TomlReader) -> float | tuple[float, ...]:
    """The model discrepancy's growth [1] of ``model_discrepancy_growth_um_per_mm`` (checked by
    :func:`~arm_model.description.check_calibration_table`): one number, or a list of one a joint of ``desc``."""
    if not isinstance(value, list):
        return float(value) * 1e-3
    if len(value) != desc.n_joints:
        raise r.error(f"'model_discrepancy_growth_um_per_mm' lists {len(value)} growths, the arm has {desc.n_joints} "
                      "joints (one a joint, in the order of its encoder columns)", "calibration",
                      "model_discrepancy_growth_um_per_mm")
    return tuple(float(v) * 1e-3 for v in value)


def _beside(model_path: str, name: str | None, r: TomlReader, key: str) -> Path | None:
    """A file a model file names (``covariance``, ``training_poses``; None: not named): relative to the folder of
    the model file itself, its symbolic links followed (a link to a model file is not a copy of its folder: the
    files written with it are beside the file, not beside the link); the model file itself is an InputError at
    ``key``."""
    if name is None:
        return None
    if "\0" in name:               # no system takes it in a file name (os.stat raised ValueError: exit 3)
        raise r.error(f"'{key}' holds a NUL character: not a file name", "calibration", key)
    why = path_problem(name, base=None if model_path == "<string>" else beside(model_path))
    if why:             # "c.csv/" read c.csv (Path drops the slash)
        raise r.error(f"'{key}': {why}", "calibration", key)
    out = named_in(model_path, name) if model_path != "<string>" else Path(name)
    if model_path != "<string>" and _same_file(out, Path(model_path)):
        raise r.error(f"'{key}' names the model file itself: it names the {key.replace('_', ' ')} file written "
                      "beside it", "calibration", key)
    return out


def _same_file(a: Path, b: Path) -> bool:
    """``a`` and ``b`` are one file (links followed; by name when either does not exist)."""
    try:
        return a.samefile(b)
    except OSError:
        return resolved(a) == resolved(b)


def training_poses_of(arm: Arm) -> TrainingPoses | None:
    """The training poses of an :class:`Arm` (its model file's ``training_poses`` points file, read by
    :func:`arm_model.io.read_points` with the arm's joints), or None when it names none; a file that is not
    such a points file is an InputError naming it. Angles that look like radians under its ``_deg`` columns are
    warned of as in every points file (:func:`arm_model.checks.radians_warning`)."""
    if arm.training_poses is None:
        return None
    from .io import read_points
    if not arm.training_poses.exists():
        raise InputError("no such file: the model file's [calibration] training_poses names it (the poses its model "
                         "discrepancy grows away from; keep it beside the model file)", arm.training_poses)
    try:                    # read_points opens it with open_input: a folder, a FIFO, a device said so, never waited on
        pts = read_points(arm.training_poses, arm.desc.joint_quantities)
    except InputError as exc:       # not on the command line: say whose file it is
        raise InputError(f"{exc.reason} (the training poses of the model file's [calibration] training_poses: a "
                         "points file of the arm's joints)", exc.path, exc.line, exc.column) from None
    if not len(pts.q):
        raise InputError("the training poses file holds no pose", arm.training_poses)
    from .checks import log_warnings, radians_warning
    # the rule of every points file (arm_model.checks): radians under the _deg columns put every pose near the
    # straight arm, and d(q) (the discrepancy's growth) is then measured from poses the arm never took
    log_warnings(w for w in [radians_warning(arm.desc, pts.q, pts.line_numbers, str(arm.training_poses),
                                             pts.q_units)] if w is not None)
    return TrainingPoses.of(arm.desc, pts.q)


def load_model(path, tip_frame: str | None = None, probe: dict | None = None, masses=None,
               base_frame: str | None = None, hold: dict | None = None) -> Arm:
    """The arm of an ``--arm`` option: a model file or description TOML (effects applied), or a URDF
    with ``tip_frame`` (no effects), optionally a masses file (:func:`arm_model.urdf_import.load_masses`) and
    the link its chain starts at (``base_frame``), or a shipped arm's name (``aacmm7``); ``hold``: {joint name:
    value (deg, or mm for a prismatic joint)} of the chain's joints held fixed (``--hold-joint``). An argument of
    the wrong type is a TypeError, a held value not finite a ValueError."""
    from .shipped import arm_path
    for name, frame in (("tip_frame", tip_frame), ("base_frame", base_frame)):
        if frame is not None and not isinstance(frame, str):
            raise TypeError(f"{name} must be a link name (str) or None, got {frame!r}")
    if hold is not None:
        if not isinstance(hold, dict) or not all(isinstance(k, str) for k in hold):
            raise TypeError(f"hold must be a dict {{joint name: value (deg, or mm)}}, got {hold!r}")
        bad = next((k for k, v in hold.items() if isinstance(v, bool) or not isinstance(v, (int, float, np.floating,
                                                                                             np.integer))), None)
        if bad is not None:
            raise TypeError(f"hold[{bad!r}] must be a number (deg, or mm), got {hold[bad]!r}")
        bad = next((k for k, v in hold.items() if not math.isfinite(v)), None)
        if bad is not None:
            raise ValueError(f"hold[{bad!r}] must be finite, got {hold[bad]!r}")
    from .urdf_import import is_urdf
    path = arm_path(path)
    if is_urdf(path) or masses is not None or base_frame is not None or hold:  # load_arm: why not
        from .urdf_import import load_arm
        return Arm(load_arm(path, tip_frame, probe, masses, base_frame, hold))
    if tip_frame:
        raise InputError("--tip-frame is for an arm given as a URDF; this arm is a TOML file", path)
    if not path.exists():
        from .shipped import SHIPPED_ARMS
        raise InputError("cannot read the arm model: no such file (a shipped arm is named without a path: "
                         f"{', '.join(f'--arm {n}' for n in SHIPPED_ARMS)})", path)
    return parse_model(read_text(path, "the arm model"), str(path))


def format_model(desc: ArmDescription, effects=(), values: dict | None = None, uncertainties: dict | None = None,
                 states: dict | None = None, *, covariance: str | None = None, written_by: str | None = None,
                 probing_scatter: float | None = None, tracker: Tracker | None = None,
                 comment: str | None = None, model_discrepancy: float | None = None,
                 discrepancy_growth: float | tuple[float, ...] | None = None,
                 training_poses: str | None = None) -> str:
    """TOML text of a model file that :func:`parse_model` reads back exactly (``probing_scatter`` and
    ``model_discrepancy`` [m]: written in um to 4 significant digits, ``discrepancy_growth`` [1] (one number, or a
    tuple of one a joint) in um/mm to 4 digits; ``training_poses``: the name of the training poses' points file;
    ``tracker``: the reference frames and marker offsets)."""
    data = description_data(desc)
    if effects:
        data["effect"] = effect_tables(desc, effects, values or {}, uncertainties, states)
    scatter, discrepancy = (None if v is None else float(f"{v * 1e6:.4g}")
                            for v in (probing_scatter, model_discrepancy))
    growth = None if discrepancy_growth is None else (
        [float(f"{g * 1e3:.4g}") for g in discrepancy_growth] if isinstance(discrepancy_growth, tuple)
        else float(f"{discrepancy_growth * 1e3:.4g}"))
    cal = {k: v for k, v in (("covariance", covariance), ("written_by", written_by), ("probing_scatter_um", scatter),
                             ("model_discrepancy_um", discrepancy), ("model_discrepancy_growth_um_per_mm", growth),
                             ("training_poses", training_poses))
           if v not in (None, "")}     # a 0 is kept
    if cal:
        try:                            # never a file parse_model refuses
            check_calibration_table(cal, TomlReader("<model file>", ""))
        except InputError as exc:
            raise ValueError(f"cannot write the model file's [calibration] table: {exc.reason}") from None
        data["calibration"] = cal
    if tracker is not None:
        data.update(tracker_tables(tracker))
    return toml_text(data, comment)


# ---------------------------------------------------------------------------------------------
# the covariance file

@dataclass(frozen=True)
class Covariance:
    """Covariance of the free parameters of a fit, SI: ``names``, SI ``units``, ``values`` (the
    estimates: errors of the nominal description for the base parameters, the values of the effect
    parameters), standard uncertainties ``u`` and correlations ``corr``; ``lines``: the line of each row
    of the file read (empty when not read from a file)."""
    names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray
    u: np.ndarray
    corr: np.ndarray
    lines: tuple[int, ...] = ()          # the file line of each parameter's row (as read)

    @property
    def matrix(self) -> np.ndarray:
        """(n, n) covariance [SI]."""
        return self.corr * np.outer(self.u, self.u)


def _display(si: str) -> tuple[str, float]:
    """Unit written for an SI unit in the covariance file (the model file's, e.g. um, urad)."""
    if si in PARAM_UNITS:
        return PARAM_UNITS[si][0]
    return si, 1.0


def write_covariance(path, names, units, values, cov, inputs=()) -> Path:
    """Write the covariance file: ``parameter, unit, value, u`` and one correlation column a parameter."""
    from .io import write_csv
    cov = np.asarray(cov, dtype=float)
    u = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(u, u)
    corr[~np.isfinite(corr)] = 0.0
    np.fill_diagonal(corr, 1.0)
    shown = [_display(si) for si in units]
    cols = {"parameter": np.array(list(names), dtype=object),
            "unit": np.array([s for s, _ in shown], dtype=object),
            "value": np.array([v / f for v, (_, f) in zip(values, shown, strict=True)]),
            "u": np.array([x / f for x, (_, f) in zip(u, shown, strict=True)])}
    for k, n in enumerate(names):
        cols[n] = corr[:, k]
    return write_csv(path, cols, inputs, fmt="%.17g")


#: the largest deviation of a correlation coefficient from [-1, 1], from 1 on the diagonal and from
#: symmetry that the covariance reader accepts (the writer's rounding is far below it)
CORRELATION_TOLERANCE = 1e-9


def read_covariance(path) -> Covariance:
    """Read a covariance file written by :func:`write_covariance` (SI inside). Every cell is checked
    (docs/formats.md, "The covariance file"): the unit one of :data:`PARAM_UNITS`; numbers plain
    decimals (no ``4_5``, ``nan`` or ``inf``); ``value`` and ``u`` in the plausible range of the unit's
    quantity, ``u`` not negative; correlations in [-1, 1], 1 on the diagonal, symmetric. A cell that is
    not is an InputError naming the file, the line and the column."""
    from .csv_io import SPACE, parse_number
    from .io import csv_records
    text = read_text(path, "the covariance file a model file names ([calibration] covariance)")
    recs = csv_records(text, str(path))
    if not recs:
        raise InputError("the covariance file is empty", path, 1)
    hl, header = recs[0]
    header = [h.strip() for h in header]
    head = ["parameter", "unit", "value", "u"]
    if header[:4] != head:
        raise InputError(f"the header must start with {', '.join(head)}", path, hl)
    names = tuple(header[4:])
    twice = next((n for k, n in enumerate(names) if n in names[:k]), None)
    if twice is not None:
        raise InputError(f"parameter '{twice}' has two columns", path, hl, twice)
    rows = recs[1:]
    if len(rows) != len(names):
        raise InputError(f"{len(rows)} rows for {len(names)} parameter columns", path, hl)
    si_of = {s: (si, f) for si, opts in PARAM_UNITS.items() for s, f in opts}
    units, values, u = [], np.empty(len(rows)), np.empty(len(rows))
    corr = np.empty((len(rows), len(rows)))
    for i, (no, r) in enumerate(rows):
        if len(r) != len(header):
            raise InputError(f"{len(r)} cells where the header has {len(header)}", path, no)
        if r[0].strip() != names[i]:
            raise InputError(f"row {i + 1} is '{r[0].strip()}', but column {i + 5} is '{names[i]}'", path, no,
                             "parameter")
        unit = r[1].strip()
        if unit not in si_of:
            raise InputError(f"unknown unit '{unit}' (known: {', '.join(si_of)}){did_you_mean(unit, si_of)}", path, no,
                             "unit")
        si, f = si_of[unit]
        units.append(si)
        nums = []
        for cell, column in zip(r[2:], header[2:], strict=True):
            v = parse_number(cell)
            if v is None or not math.isfinite(v):
                raise InputError(f"expected a finite number, got {cell.strip(SPACE)!r}", path, no, column)
            nums.append(v)
        values[i], u[i] = nums[0] * f, nums[1] * f
        for column, x in (("value", values[i]), ("u", u[i])):
            wrong = implausible(x, PARAM_QUANTITY.get(si, ""))
            if wrong:
                raise InputError(wrong[1], path, no, column)
        if u[i] < 0:
            raise InputError(f"a standard uncertainty must not be negative, got {nums[1]!r}", path, no, "u")
        corr[i] = nums[2:]
        bad = np.flatnonzero((np.abs(corr[i]) > 1 + CORRELATION_TOLERANCE)
                            | (np.arange(len(rows)) == i) & (np.abs(corr[i] - 1) > CORRELATION_TOLERANCE))
        if len(bad):
            k = int(bad[0])
            raise InputError(f"a correlation coefficient must be {'1 on the diagonal' if k == i else 'in [-1, 1]'}, "
                             f"got {float(corr[i, k])!r}", path, no, names[k])
    asym = np.argwhere(np.abs(corr - corr.T) > CORRELATION_TOLERANCE)
    if len(asym):
        i, k = (int(x) for x in asym[0])
        raise InputError(f"the correlations are not symmetric: {float(corr[i, k])!r} here, {float(corr[k, i])!r} in "
                         f"row '{names[k]}' (line {rows[k][0]}), column '{names[i]}'", path, rows[i][0], names[k])
    return Covariance(names, tuple(units), values, u, corr, tuple(no for no, _ in rows))


def parameters_of(arm) -> ParameterCovariance | None:
    """The parameter covariance of an :class:`~arm_model.model_file.Arm` (its model file's covariance
    file), or None when it names none. A parameter the model does not have is an InputError."""
    if getattr(arm, "covariance", None) is None:
        return None
    cov = read_covariance(arm.covariance)
    names = arm.model.spec.names
    spec = arm.model.spec
    for i, n in enumerate(cov.names):
        line = cov.lines[i] if cov.lines else None
        if n not in names:
            raise InputError(f"parameter '{n}' of the covariance file is not a parameter of the model "
                             f"(known: {', '.join(names)})", arm.covariance, line, "parameter")
        if cov.units[i] != spec.units[spec.index(n)]:
            raise InputError(f"parameter '{n}' is a '{spec.units[spec.index(n)]}' quantity, but the unit of this row "
                             f"is a '{cov.units[i]}' one: give the value and u in a unit of the parameter's quantity",
                             arm.covariance, line, "unit")
    _check_agrees(arm, cov)
    try:
        out = ParameterCovariance(tuple(cov.names), cov.matrix,
                                  source=f"the model's covariance file {arm.covariance.name}")
        out.factor()
    except ValueError as exc:
        raise InputError(f"not a usable covariance: {exc}", arm.covariance) from None
    return out


#: the relative difference up to which a value or uncertainty of the model file and of its covariance file agree
#: (both are written from one number: %.17g in the covariance file, the unit's factor applied in the model file)
AGREEMENT_RTOL = 1e-9


def _check_agrees(arm, cov: Covariance) -> None:
    """The model file's ``[[effect]]`` parameters and its covariance file are one fit's: a parameter with a row in
    the covariance file is estimated there (not ``fixed`` or ``held``), with the same value and uncertainty; an
    estimated one (``free``, ``prior-dominated``) has a row. A hand-edited file that breaks this would give
    points uncertainties of another model: an InputError naming the covariance file's line and column."""
    row = {n: i for i, n in enumerate(cov.names)}
    for name, i in row.items():
        if name not in arm.values:
            continue
        line = cov.lines[i] if cov.lines else None
        state = arm.states.get(name)
        if state in ("fixed", "held"):
            raise InputError(f"parameter '{name}' is '{state}' in the model file, but the covariance file gives it "
                             "an uncertainty: the two files are not of one fit", arm.covariance, line, "parameter")
        for column, ours, theirs in (("value", arm.values[name], cov.values[i]),
                                     ("u", arm.uncertainties.get(name), cov.u[i])):
            if ours is not None and abs(ours - theirs) > AGREEMENT_RTOL * max(abs(ours), abs(theirs)):
                unit, f = _display(cov.units[i])
                raise InputError(f"parameter '{name}': {float(theirs) / f:.10g} {unit} here, but {ours / f:.10g} "
                                 f"{unit} in the model file: the two files are not of one fit", arm.covariance,
                                 line, column)
    missing = next((n for n, st in arm.states.items() if st in ("free", "prior-dominated") and n not in row), None)
    if missing is not None:
        raise InputError(f"parameter '{missing}' is '{arm.states[missing]}' (estimated) in the model file, but the "
                         "covariance file has no row for it: the two files are not of one fit", arm.covariance)


def read_model_file(path: Path) -> Arm:
    """A model file as ``--arm`` reads it and, when it names one, its covariance file as ``tip`` reads it
    (the read-back of :mod:`arm_model.readback`)."""
    arm = load_model(path)
    parameters_of(arm)
    training_poses_of(arm)
    return arm


def _missing_column(effect: Effect, column: str, what: str, path, line: int, more: str = "") -> InputError:
    """The one message of a column an effect needs and a file or stream lacks."""
    return InputError(f"the model's effect '{effect.describe()}' needs the column '{column}', which the {what} "
                      f"lack{'s' if what == 'stream' else ''}{more}", path, line, column)
