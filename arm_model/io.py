"""Readers and writers of the interchange formats (docs/formats.md §3-5). I/O lives here only.

Readers stop at the first problem with one :class:`~arm_model.InputError` that names the file, the
line (or key) and the column. Writers are atomic (temporary file, then rename) and refuse to write
over an input.
"""
from __future__ import annotations

import csv
import io
import math
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._errors import InputError, parse_toml, read_text
from ._units import QUANTITY_OF_UNIT, UNIT_FACTORS, split_unit

__all__ = ["PointSet", "Feature", "Distance", "Artefacts", "ForceSignal", "read_points",
           "read_artefacts", "read_force_signal", "check_features", "atomic_write_text",
           "atomic_write_bytes", "write_csv", "guard_output", "csv_records", "FEATURE_KINDS"]

FEATURE_KINDS = ("ring", "cylinder", "sphere", "seat", "plane", "point")
_TEXT_COLUMNS = ("measurement", "feature")


# ---------------------------------------------------------------------------------------------
# points

@dataclass(frozen=True)
class PointSet:
    """Captured points (docs/formats.md §3), SI inside.

    Attributes:
        path: the file read.
        measurement: (N,) measurement ids.
        feature: (N,) feature ids ("" for a free point).
        q: (N, J) encoder angles [rad].
        force: (N, 3) force of the part on the ball, probe frame [N], or None. With the paper's
            two-channel sensor, column 1 (probe y) is zero: see ``force_kind``.
        torque: (N, 3) torque at the ball, probe frame [N m], or None (project columns mx, my, mz).
        force_kind: "xyz", "two-channel" or None.
        temperature: (N,) [°C] or None; time: (N,) [s] or None.
        ref: (N, 3) reference-instrument ball centres [m] or None.
        lines: (N,) 1-based line of each row in the file, for messages.
        extra: other numeric columns, SI, by base name (e.g. "x_ref" is not here, it is ``ref``).
        text: other text columns by name.
        flagged: (N,) True where |force| exceeds the probe's calibrated range (set by
            :func:`flag_forces`); never used to drop a row.
    """
    path: str
    measurement: np.ndarray
    feature: np.ndarray
    q: np.ndarray
    force: np.ndarray | None = None
    torque: np.ndarray | None = None
    force_kind: str | None = None
    temperature: np.ndarray | None = None
    time: np.ndarray | None = None
    ref: np.ndarray | None = None
    lines: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    text: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return self.q.shape[0]

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def wrench(self) -> np.ndarray | None:
        """(N, 6) wrench (force [N], torque [N m]) at the ball in the probe frame, or None."""
        if self.force is None and self.torque is None:
            return None
        w = np.zeros((len(self), 6))
        if self.force is not None:
            w[:, :3] = self.force
        if self.torque is not None:
            w[:, 3:] = self.torque
        return w

    def measurements(self) -> list[str]:
        """Measurement ids in order of first appearance."""
        return list(dict.fromkeys(self.measurement.tolist()))

    def select(self, mask) -> "PointSet":
        """The rows where ``mask`` (bool array or index array) holds, file order kept."""
        def take(a):
            return None if a is None else a[mask]
        return PointSet(self.path, self.measurement[mask], self.feature[mask], self.q[mask],
                        take(self.force), take(self.torque), self.force_kind, take(self.temperature),
                        take(self.time), take(self.ref), take(self.lines),
                        {k: v[mask] for k, v in self.extra.items()},
                        {k: v[mask] for k, v in self.text.items()})

    def over_force(self, max_force: float) -> np.ndarray:
        """(N,) True where the force magnitude exceeds ``max_force`` [N] (rows are flagged, not dropped)."""
        if self.force is None:
            return np.zeros(len(self), bool)
        return np.linalg.norm(self.force, axis=1) > max_force


def _parse_float(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None


def csv_records(text: str, path: str) -> list[tuple[int, list[str]]]:
    """Non-blank CSV records with their physical line; a record may not span lines."""
    out = []
    for no, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        try:
            rec = next(csv.reader([line], strict=True))
        except csv.Error as exc:
            raise InputError(f"not valid CSV: {exc}", path, no) from None
        if any(c.strip() for c in rec):
            out.append((no, rec))
    return out


def read_points(path: str | Path, n_joints: int | None = None) -> PointSet:
    """Read a points CSV (docs/formats.md §3).

    Args:
        path: the CSV file.
        n_joints: number of joint columns the arm has; a different count is an error.
    """
    text = read_text(path, "the points file")
    return parse_points(text, str(path), n_joints)


def parse_points(text: str, path: str = "<string>", n_joints: int | None = None) -> PointSet:
    """Parse points CSV text; see :func:`read_points`."""
    records = csv_records(text, path)
    if not records:
        raise InputError("the file is empty (expected a header line and at least one point)", path, 1)
    header_line, header = records[0]
    header = [h.strip() for h in header]
    if len(records) == 1:
        raise InputError("no points after the header line", path, header_line + 1)
    seen = set()
    for h in header:
        if not h:
            raise InputError("empty column name in the header", path, header_line)
        if h in seen:
            raise InputError(f"column '{h}' appears twice", path, header_line, h)
        seen.add(h)
    for req in _TEXT_COLUMNS:
        if req not in header:
            raise InputError(f"missing required column '{req}'", path, header_line, req)
    # classify columns
    numeric: dict[str, tuple[str, str]] = {}
    text_cols: list[str] = []
    for h in header:
        if h in _TEXT_COLUMNS:
            continue
        parts = split_unit(h)
        if parts is None:
            text_cols.append(h)
        else:
            numeric[h] = parts
    data = records[1:]
    for no, r in data:
        if len(r) != len(header):
            raise InputError(f"{len(r)} cells where the header has {len(header)} columns", path, no)
    # a column with no unit suffix whose cells are all numbers is a numeric column without a unit
    for h in text_cols:
        k = header.index(h)
        cells = [r[k].strip() for _, r in data]
        if cells and all(c and _parse_float(c) is not None for c in cells):
            raise InputError("numeric column without a unit suffix (expected e.g. '_mm', '_deg', "
                             "'_N', '_C', '_s')", path, header_line, h)
    # joints
    joint_cols = {}
    for h, (base, unit) in numeric.items():
        m = re.fullmatch(r"q(\d+)", base)
        if m:
            if QUANTITY_OF_UNIT[unit] != "angle":
                raise InputError(f"joint column must be an angle (_deg or _rad), got '_{unit}'",
                                 path, header_line, h)
            joint_cols[int(m.group(1))] = h
    if not joint_cols:
        raise InputError("no joint columns (q1_deg ... or q1_rad ...)", path, header_line)
    idx = sorted(joint_cols)
    if idx != list(range(1, len(idx) + 1)):
        missing = sorted(set(range(1, max(idx) + 1)) - set(idx))
        raise InputError(f"joint columns are not q1..q{max(idx)}: missing "
                         f"{', '.join('q%d' % i for i in missing)}", path, header_line)
    if n_joints is not None and len(idx) != n_joints:
        raise InputError(f"{len(idx)} joint columns, but the arm has {n_joints} joints", path,
                         header_line, joint_cols[idx[-1]])

    def column(h: str) -> np.ndarray:
        k = header.index(h)
        out = np.empty(len(data))
        for i, (no, r) in enumerate(data):
            cell = r[k].strip()
            v = _parse_float(cell)
            if v is None:
                raise InputError(f"expected a number, got {cell!r}" if cell else "empty cell where a number "
                                 "is expected", path, no, h)
            if not math.isfinite(v):
                raise InputError(f"value must be finite, got {cell!r}", path, no, h)
            out[i] = v
        return out * UNIT_FACTORS[numeric[h][1]]

    def text_col(h: str) -> np.ndarray:
        k = header.index(h)
        return np.array([r[k].strip() for _, r in data], dtype=object)

    measurement = text_col("measurement")
    for i, (no, _) in enumerate(data):
        if not measurement[i]:
            raise InputError("empty measurement id", path, no, "measurement")
    q = np.column_stack([column(joint_cols[i]) for i in idx])
    by_base = {base: h for h, (base, _) in numeric.items()}

    def expect(base: str, quantity: str) -> np.ndarray | None:
        h = by_base.get(base)
        if h is None:
            return None
        if QUANTITY_OF_UNIT[numeric[h][1]] != quantity:
            raise InputError(f"'{base}' must be a {quantity}, got unit '_{numeric[h][1]}'", path, header_line, h)
        return column(h)

    def group(bases, quantity) -> np.ndarray | None:
        present = [b for b in bases if b in by_base]
        if not present:
            return None
        if len(present) != len(bases):
            missing = [b for b in bases if b not in by_base]
            raise InputError(f"columns {', '.join(missing)} missing beside {', '.join(present)}", path,
                             header_line, by_base[present[0]])
        return np.column_stack([expect(b, quantity) for b in bases])

    force = group(("fx", "fy", "fz"), "force")
    two = group(("f_bend", "f_axial"), "force")
    force_kind = None
    if force is not None:
        force_kind = "xyz"
        if two is not None:
            raise InputError("both three-axis (fx, fy, fz) and two-channel (f_bend, f_axial) force columns; "
                             "give one sensor", path, header_line, by_base["f_bend"])
    elif two is not None:
        force_kind = "two-channel"
        force = np.column_stack([two[:, 0], np.zeros(len(data)), two[:, 1]])
    torque = group(("mx", "my", "mz"), "torque")
    temperature = expect("temperature", "temperature")
    time = expect("time", "time")
    ref = group(("x_ref", "y_ref", "z_ref"), "length")
    used = {"fx", "fy", "fz", "f_bend", "f_axial", "mx", "my", "mz", "temperature", "time",
            "x_ref", "y_ref", "z_ref"} | {f"q{i}" for i in idx}
    extra = {base: column(h) for h, (base, _) in numeric.items() if base not in used}
    return PointSet(path=path, measurement=measurement, feature=text_col("feature"), q=q, force=force,
                    torque=torque, force_kind=force_kind, temperature=temperature, time=time, ref=ref,
                    lines=np.array([no for no, _ in data]), extra=extra,
                    text={h: text_col(h) for h in text_cols})


# ---------------------------------------------------------------------------------------------
# artefacts

@dataclass(frozen=True)
class Feature:
    """One artefact feature. ``diameter``, ``u_diameter``, ``form_error`` [m] where they apply;
    ``values`` holds every numeric key in SI by base name."""
    id: str
    kind: str
    diameter: float | None = None
    u_diameter: float | None = None
    form_error: float | None = None
    values: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Distance:
    """A certified centre-to-centre length [m] between two features."""
    between: tuple[str, str]
    length: float
    u_length: float | None = None


@dataclass(frozen=True)
class Artefacts:
    path: str
    features: dict          # id -> Feature, file order
    distances: tuple = ()

    def of_kind(self, *kinds: str) -> list[Feature]:
        return [f for f in self.features.values() if f.kind in kinds]


def _toml_key_line(text: str, table: str, index: int, key: str | None) -> int | None:
    count, inside = -1, False
    for no, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if re.fullmatch(r"\[\[\s*" + re.escape(table) + r"\s*\]\]", line):
            count += 1
            inside = count == index
            if inside and key is None:
                return no
            continue
        if line.startswith("["):
            inside = False
            continue
        if inside and key is not None and re.match(re.escape(key) + r"\s*=", line):
            return no
    return None


def read_artefacts(path: str | Path) -> Artefacts:
    """Read an artefacts TOML file (docs/formats.md §4)."""
    return parse_artefacts(read_text(path, "the artefacts file"), str(path))


def parse_artefacts(text: str, path: str = "<string>") -> Artefacts:
    data = parse_toml(text, path)

    def err(msg, table, index, key=None):
        col = f"key '{table}[{index + 1}].{key}'" if key else f"key '{table}[{index + 1}]'"
        return InputError(msg, path, _toml_key_line(text, table, index, key), col)

    for key in data:
        if key not in ("feature", "distance"):
            raise InputError(f"unknown top-level key '{key}' (known: feature, distance)", path, None, f"key '{key}'")
    feats = data.get("feature", [])
    if not isinstance(feats, list) or not feats:
        raise InputError("no [[feature]] tables", path, 1)
    features: dict[str, Feature] = {}
    for i, t in enumerate(feats):
        fid = t.get("id")
        if not isinstance(fid, str) or not fid.strip():
            raise err("missing or empty 'id'", "feature", i, "id")
        if fid in features:
            raise err(f"feature id '{fid}' is used twice", "feature", i, "id")
        kind = t.get("kind")
        if kind not in FEATURE_KINDS:
            raise err(f"unknown kind {kind!r} (known: {', '.join(FEATURE_KINDS)})", "feature", i, "kind")
        values = {}
        for key, v in t.items():
            if key in ("id", "kind"):
                continue
            parts = split_unit(key)
            if parts is None:
                if isinstance(v, (int, float)) and not isinstance(v, bool):
                    raise err(f"numeric key '{key}' has no unit suffix", "feature", i, key)
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise err(f"'{key}' must be a finite number, got {v!r}", "feature", i, key)
            values[parts[0]] = float(v) * UNIT_FACTORS[parts[1]]
            if parts[0] in ("diameter", "u_diameter", "form_error") and QUANTITY_OF_UNIT[parts[1]] != "length":
                raise err(f"'{key}' must be a length", "feature", i, key)
        if kind in ("ring", "cylinder", "sphere") and "diameter" not in values:
            raise err(f"a {kind} needs 'diameter_mm'", "feature", i)
        if "diameter" in values and values["diameter"] <= 0:
            raise err("diameter must be > 0", "feature", i, "diameter_mm")
        features[fid] = Feature(fid, kind, values.get("diameter"), values.get("u_diameter"),
                                values.get("form_error"), values)
    distances = []
    for i, t in enumerate(data.get("distance", [])):
        between = t.get("between")
        if (not isinstance(between, list) or len(between) != 2
                or not all(isinstance(b, str) for b in between)):
            raise err("'between' must name two features", "distance", i, "between")
        for b in between:
            if b not in features:
                raise err(f"unknown feature '{b}' (known: {', '.join(features)})", "distance", i, "between")
        length = u = None
        for key, v in t.items():
            if key == "between":
                continue
            parts = split_unit(key)
            if parts is None or QUANTITY_OF_UNIT[parts[1]] != "length" or parts[0] not in ("length", "u_length"):
                raise err(f"unknown key '{key}' (expected length_mm, u_length_mm)", "distance", i, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise err(f"'{key}' must be a finite number", "distance", i, key)
            if parts[0] == "length":
                length = float(v) * UNIT_FACTORS[parts[1]]
            else:
                u = float(v) * UNIT_FACTORS[parts[1]]
        if length is None or length <= 0:
            raise err("missing or non-positive 'length_mm'", "distance", i)
        distances.append(Distance((between[0], between[1]), length, u))
    return Artefacts(path, features, tuple(distances))


def check_features(points: PointSet, artefacts: Artefacts) -> None:
    """Every non-empty feature id of the points must exist in the artefacts file."""
    for i, fid in enumerate(points.feature):
        if fid and fid not in artefacts.features:
            line = None if points.lines is None else int(points.lines[i])
            raise InputError(f"unknown feature '{fid}' (the artefacts file {artefacts.path} has: "
                             f"{', '.join(artefacts.features)})", points.path, line, "feature")


# ---------------------------------------------------------------------------------------------
# force signals

@dataclass(frozen=True)
class ForceSignal:
    """A force signal (docs/formats.md §5): ``time`` (M,) [s], ``force`` (M, 3) [N] in the probe frame
    (probe y zero for the two-channel sensor), ``kind`` "xyz" or "two-channel"."""
    path: str
    time: np.ndarray
    force: np.ndarray
    kind: str


def read_force_signal(path: str | Path) -> ForceSignal:
    """Read one force-signal CSV (``time_s`` and either f_bend/f_axial or fx/fy/fz)."""
    text = read_text(path, "the force signal")
    rows = csv_records(text, str(path))
    if len(rows) < 2:
        raise InputError("the file is empty (expected a header and samples)", path, 1)
    hline, header = rows[0]
    header = [h.strip() for h in header]
    for h in header:
        if split_unit(h) is None:
            raise InputError("column without a unit suffix", path, hline, h)
    if "time_s" not in header:
        raise InputError("missing column 'time_s'", path, hline)
    if {"fx_N", "fy_N", "fz_N"} <= set(header):
        kind, cols = "xyz", ("fx_N", "fy_N", "fz_N")
    elif {"f_bend_N", "f_axial_N"} <= set(header):
        kind, cols = "two-channel", ("f_bend_N", "f_axial_N")
    else:
        raise InputError("expected force columns fx_N, fy_N, fz_N or f_bend_N, f_axial_N", path, hline)
    arr = np.empty((len(rows) - 1, len(header)))
    for i, (no, r) in enumerate(rows[1:]):
        if len(r) != len(header):
            raise InputError(f"{len(r)} cells where the header has {len(header)} columns", path, no)
        for k, cell in enumerate(r):
            v = _parse_float(cell.strip())
            if v is None or not math.isfinite(v):
                raise InputError(f"expected a finite number, got {cell.strip()!r}", path, no, header[k])
            arr[i, k] = v
    t = arr[:, header.index("time_s")]
    if np.any(np.diff(t) <= 0):
        bad = int(np.argmax(np.diff(t) <= 0)) + 1
        raise InputError("time must increase", path, rows[bad + 1][0], "time_s")
    f = np.column_stack([arr[:, header.index(c)] for c in cols])
    if kind == "two-channel":
        f = np.column_stack([f[:, 0], np.zeros(len(t)), f[:, 1]])
    return ForceSignal(str(path), t, f, kind)


# ---------------------------------------------------------------------------------------------
# writing

def guard_output(out: str | Path, inputs=()) -> Path:
    """Refuse an output path that is one of the inputs (by resolved path)."""
    out = Path(out)
    ro = out.resolve()
    for p in inputs:
        if p is not None and Path(p).resolve() == ro:
            raise InputError("refusing to write the output over an input file", out)
    return out


def atomic_write_bytes(path: str | Path, data: bytes, inputs=()) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = guard_output(path, inputs)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)          # mkstemp makes 0600; outputs get the usual mode
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path: str | Path, text: str, inputs=()) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"), inputs)


def write_csv(path: str | Path, columns: dict, inputs=(), fmt: str = "%.9g") -> Path:
    """Write a CSV atomically from ``{name: 1-D array}`` (names carry their unit suffix)."""
    names = list(columns)
    n = {len(v) for v in columns.values()}
    if len(n) > 1:
        raise ValueError(f"columns of different lengths: {n}")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(names)
    def cells(c: np.ndarray) -> list[str]:
        if c.dtype.kind in "iub":
            return [str(int(v)) for v in c]
        if c.dtype.kind == "f":
            return [fmt % v for v in c]
        return [str(v) for v in c]
    w.writerows(zip(*(cells(np.asarray(columns[k])) for k in names)))
    return atomic_write_text(path, buf.getvalue(), inputs)
