"""Readers and writers of the interchange formats (docs/formats.md §3-5). I/O lives here only.

Readers stop at the first problem with one :class:`~arm_model.InputError` that names the file, the
line (or key) and the column. Writers are atomic (temporary file, then rename) and refuse to write
over an input.
"""
from __future__ import annotations

import json
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .csv_io import BLOCK_BYTES, csv_records, format_csv, iter_csv_blocks, label_rows
from .errors import InputError, id_problem, parse_toml, read_text, unknown_key
from .output import atomic_write_bytes, guard_output
from .readback import UnreadableOutput, read_back
from .toml_lines import toml_key_lines, top_key_line
from .units import (
    PLAUSIBLE_SI,
    QUANTITY_OF_UNIT,
    SMALLEST_ARTEFACT_M,
    STATED_SIGMA_M,
    UNIT_FACTORS,
    implausible,
    split_unit,
    unit_of,
)

log = logging.getLogger(__name__)

__all__ = ["PointSet", "Feature", "Distance", "Artefacts", "ForceSignal", "read_points",
           "read_artefacts", "read_force_signal", "check_features", "atomic_write_text",
           "atomic_write_bytes", "write_csv", "guard_output", "csv_records", "FEATURE_KINDS", "CENTRE_KINDS",
           "id_problem", "iter_points",
           "concat_points", "POINT_COLUMNS", "format_artefacts", "read_back", "UnreadableOutput", "json_text",
           "MOVE_SUFFIX", "move_columns"]

FEATURE_KINDS = ("ring", "cylinder", "sphere", "seat", "plane", "point")
#: the kinds whose centre is one point a fit determines: the only ends a certified [[distance]] can join (a ring's or
#: cylinder's axis is a line, a plane has no centre, a free point is no artefact's)
CENTRE_KINDS = ("seat", "sphere")
_TEXT_COLUMNS = ("measurement", "feature")
#: optional text column: rows of one session share one reference-instrument frame (docs/formats.md §3)
SESSION_COLUMN = "session"
#: the suffix of the optional per-joint last-move columns ``q1_move_sign`` ... ``qJ_move_sign`` (docs/formats.md §3):
#: the sign (-1, 0, 1) of each joint's last move onto the point, a number without a unit, named by its kind
MOVE_SUFFIX = "_move_sign"
_MOVE_COLUMN = re.compile(r"q([1-9][0-9]*)" + MOVE_SUFFIX)


def move_columns(n_joints: int) -> list[str]:
    """The last-move columns of a points file for ``n_joints`` joint columns, in the joints' order."""
    return [f"q{j + 1}{MOVE_SUFFIX}" for j in range(n_joints)]


# ---------------------------------------------------------------------------------------------
# points

@dataclass(frozen=True)
class PointSet:
    """Captured points (docs/formats.md §3), SI inside.

    Attributes:
        path: the file read.
        measurement: (N,) measurement ids.
        feature: (N,) feature ids ("" for a free point).
        q: (N, J) encoder readings: joint angles [rad], prismatic joints' positions [m].
        force: (N, 3) force of the part on the ball, probe frame [N], or None. With the paper's
            two-channel sensor, column 1 (probe y) is zero: see ``force_kind``.
        torque: (N, 3) torque at the ball, probe frame [N m], or None (project columns mx, my, mz).
        force_kind: "xyz", "two-channel" or None.
        temperature: (N,) [°C] or None; time: (N,) [s] or None.
        ref: (N, K, 3) the reference instrument's coordinates of K markers [m] (columns ``x_ref_mm`` ...
            for one marker, ``x1_ref_mm`` ... ``xK_ref_mm`` ... for K), in the instrument's frame, or None.
            NaN where a row has no reference (a row of another file, :func:`calibration.data.merge_points`).
        session: (N,) the session of each row (column ``session``: rows of one session share one frame of
            the reference instrument), or None (one session).
        lines: (N,) 1-based line of each row in the file, for messages.
        q_units: the unit each joint column was written in (``("deg", ...)``), or None (not read from a file).
        motion: (N, J) the sign (-1, 0, 1) of each joint's last move onto each point [1], as measured (columns
            ``q1_move_sign`` ...: a live session's, read from its samples), or None: the points' own rule
            (:func:`arm_model.model.points_motion`).
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
    session: np.ndarray | None = None
    q_units: tuple | None = None
    motion: np.ndarray | None = None

    def __post_init__(self) -> None:
        # the readers refuse these with file, line and column; a PointSet built in Python is held to the same
        # (a NaN or an absurd joint value would otherwise reach a fit and come back as a number)
        q = np.asarray(self.q)
        if q.ndim != 2:
            raise ValueError(f"points '{self.path}': q must be (N, joints), got the shape {q.shape}")
        bad = ~np.isfinite(q) | (np.abs(q) > PLAUSIBLE_SI["length"])
        if bad.any():
            i, k = (int(v) for v in np.argwhere(bad)[0])
            raise ValueError(f"points '{self.path}': joint {k + 1} of row {i + 1}{self._at(i)} is {float(q[i, k])!r}: "
                             f"a joint value must be finite and within +-{PLAUSIBLE_SI['length']:g} (rad, or m for a "
                             "prismatic joint)")
        if self.motion is not None:
            m = np.asarray(self.motion)
            if m.shape != q.shape:
                raise ValueError(f"points '{self.path}': motion must be (N, joints) like q {q.shape}, got the shape "
                                 f"{m.shape}")
            bad = ~np.isin(m, (-1.0, 0.0, 1.0))
            if bad.any():
                i, k = (int(v) for v in np.argwhere(bad)[0])
                raise ValueError(f"points '{self.path}': the last move of joint {k + 1} of row {i + 1}"
                                 f"{self._at(i)} is {float(m[i, k])!r}: it is -1, 0 or 1")

    def _at(self, i: int) -> str:
        return "" if self.lines is None or len(self.lines) <= i else f", line {int(self.lines[i])}"

    def __len__(self) -> int:
        return self.q.shape[0]

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def line_numbers(self) -> np.ndarray:
        """(N,) ``lines``, or each row's 1-based position for points not read from a file."""
        return np.arange(1, len(self) + 1) if self.lines is None else self.lines

    @property
    def n_markers(self) -> int:
        """How many markers the reference columns give (0 without reference columns)."""
        return 0 if self.ref is None else self.ref.shape[1]

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

    def measurement_rows(self) -> dict[str, np.ndarray]:
        """``{measurement id: its rows (file order)}`` in order of first appearance (:func:`label_rows`)."""
        return label_rows(self.measurement)

    def select(self, mask) -> PointSet:
        """The rows where ``mask`` (bool array or index array) holds, file order kept."""
        def take(a):
            return None if a is None else a[mask]
        return PointSet(self.path, self.measurement[mask], self.feature[mask], self.q[mask],
                        take(self.force), take(self.torque), self.force_kind, take(self.temperature),
                        take(self.time), take(self.ref), take(self.lines), take(self.session), self.q_units,
                        take(self.motion))

    def over_force(self, max_force: float) -> np.ndarray:
        """(N,) True where the force magnitude exceeds ``max_force`` [N] (rows are flagged, not dropped)."""
        if self.force is None:
            return np.zeros(len(self), bool)
        return np.linalg.norm(self.force, axis=1) > max_force


#: base names of the numeric columns of a points file -> quantity (joints ``q<i>`` are angles)
POINT_COLUMNS = {"fx": "force", "fy": "force", "fz": "force", "f_bend": "force", "f_axial": "force",
                 "mx": "torque", "my": "torque", "mz": "torque", "temperature": "temperature", "time": "time",
                 "x_ref": "length", "y_ref": "length", "z_ref": "length"}
_GROUPS = (("fx", "fy", "fz"), ("f_bend", "f_axial"), ("mx", "my", "mz"), ("x_ref", "y_ref", "z_ref"))
#: a numbered marker's reference column (``x2_ref``), or the one marker's (``x_ref``)
_MARKER_COLUMN = re.compile(r"([xyz])([1-9][0-9]*)?_ref")


@dataclass(frozen=True)
class _PointsLayout:
    """What the header of a points file says: column index and unit of each base name."""
    header: tuple
    line: int
    cols: dict              # base -> (index, unit)
    joints: tuple           # column indices of q1..qJ
    num_idx: list
    txt_idx: list
    markers: tuple = ()     # base names (x, y, z) of each marker's reference columns
    moves: tuple = ()       # column indices of q1_move_sign .. qJ_move_sign (none: no last moves given), read as
    #                         text (the last cells of txt_idx): exactly -1, 0 or 1 as written


def _joint_count_and_kinds(joints) -> tuple[int | None, tuple | None]:
    """``joints`` of the readers: None, a count, or each column's quantity ("angle", "length")."""
    if joints is None or isinstance(joints, int):
        return joints, None
    return len(joints), tuple(joints)


def _points_layout(header: list[str], line: int, path: str, joints) -> _PointsLayout:
    n_joints, kinds = _joint_count_and_kinds(joints)
    seen = set()
    for h in header:
        if not h:
            raise InputError("empty column name in the header", path, line)
        if h in seen:
            raise InputError(f"column '{h}' appears twice", path, line, h)
        seen.add(h)
    for req in _TEXT_COLUMNS:
        if req not in header:
            sep = next((f"{name}-separated" for c, name in (("\t", "tab"), (";", "semicolon")) if c in header[0]), None)
            if len(header) == 1 and sep:
                raise InputError(f"the header is {sep}: a points file's columns are separated by commas",
                                 path, line)
            raise InputError(f"missing required column '{req}'", path, line, req)
    known = ("measurement, feature, session, q1_deg ..., " + ", ".join(f"{b}_<unit>" for b in POINT_COLUMNS)
             + f", x1_ref_mm ... (markers 1 to K), q1{MOVE_SUFFIX} ... (each joint's last move)")
    cols: dict[str, tuple[int, str]] = {}
    moves: dict[int, int] = {}
    for k, h in enumerate(header):
        if h in _TEXT_COLUMNS or h == SESSION_COLUMN:
            continue
        if mv := _MOVE_COLUMN.fullmatch(h):
            moves[int(mv.group(1))] = k
            continue
        parts = split_unit(h)
        if parts is None:
            raise InputError(f"unknown column '{h}': a numeric column carries its unit suffix (e.g. '_mm', "
                             f"'_deg', '_N', '_C', '_s'); the columns of a points file are {known}", path, line, h)
        base, unit = parts
        if re.fullmatch(r"q[1-9][0-9]*", base):
            if QUANTITY_OF_UNIT[unit] not in ("angle", "length"):
                raise InputError(f"a joint column is an angle (_deg or _rad) or, for a prismatic joint, a length "
                                 f"(_mm, _m or _um), got '_{unit}'", path, line, h)
        elif base in POINT_COLUMNS or _MARKER_COLUMN.fullmatch(base):
            quantity = POINT_COLUMNS.get(base, "length")
            if QUANTITY_OF_UNIT[unit] != quantity:
                raise InputError(f"'{base}' must be a {quantity}, got unit '_{unit}'", path, line, h)
        else:
            raise InputError(f"unknown column '{h}' (the columns of a points file are {known})", path, line, h)
        if base in cols:
            raise InputError(f"'{h}' and '{header[cols[base][0]]}' give the same quantity: keep one", path, line, h)
        cols[base] = (k, unit)
    idx = sorted(int(b[1:]) for b in cols if b.startswith("q") and b[1:].isdigit())
    if not idx:
        raise InputError("no joint columns (q1_deg ... or q1_rad ...; a prismatic joint's q<i>_mm or q<i>_m)",
                         path, line)
    if idx != list(range(1, len(idx) + 1)):
        missing = sorted(set(range(1, max(idx) + 1)) - set(idx))
        raise InputError(f"joint columns are not q1..q{max(idx)}: missing "
                         f"{', '.join(f'q{i}' for i in missing)}", path, line)
    if n_joints is not None and len(idx) != n_joints:
        raise InputError(f"{len(idx)} joint columns, but the arm has {n_joints} joints"
                         + (" (a URDF chain holding joints the points do not give, a mobile base's or a torso's: "
                            "start it after them with --base-frame LINK, or give each one's value with "
                            "--hold-joint JOINT=VALUE)" if len(idx) < n_joints else ""),
                         path, line, header[cols[f"q{idx[-1]}"][0]])
    for i, want in enumerate(kinds or (), 1):        # each column in its joint's quantity (the count checked first)
        h = header[cols[f"q{i}"][0]]
        if QUANTITY_OF_UNIT[cols[f"q{i}"][1]] != want:
            raise InputError(f"'{h}': joint {i} of the arm is "
                             + ("prismatic: its column is a length (_mm, _m or _um)" if want == "length" else
                                "revolute: its column is an angle (_deg or _rad)") + f", got '_{cols[f'q{i}'][1]}'",
                             path, line, h)
    for group in _GROUPS:
        present = [b for b in group if b in cols]
        if present and len(present) != len(group):
            missing = [b for b in group if b not in cols]  # type: ignore[misc]
            raise InputError(f"columns {', '.join(missing)} missing beside {', '.join(present)}", path, line,
                             header[cols[present[0]][0]])
    if "fx" in cols and "f_bend" in cols:
        raise InputError("both three-axis (fx, fy, fz) and two-channel (f_bend, f_axial) force columns; "
                         "give one sensor", path, line, header[cols["f_bend"][0]])
    move_idx = _move_layout(moves, len(idx), header, path, line)
    num_idx = sorted(k for k, _ in cols.values())
    txt_idx = [header.index(t) for t in _TEXT_COLUMNS] + ([header.index(SESSION_COLUMN)]
                                                          if SESSION_COLUMN in header else []) + list(move_idx)
    return _PointsLayout(tuple(header), line, cols, tuple(cols[f"q{i}"][0] for i in idx), num_idx, txt_idx,
                         _marker_groups(cols, header, path, line), move_idx)


def _move_layout(moves: dict[int, int], n_joints: int, header, path: str, line: int) -> tuple:
    """The column indices of ``q1_move_sign`` ... ``qJ_move_sign`` (``moves``: joint number -> column), one a joint
    column in the joints' order, all or none: a last move for a joint the points do not have, or a joint without
    its last move beside the others', is an error of the header."""
    if not moves:
        return ()
    if beyond := [i for i in sorted(moves) if i > n_joints]:
        h = header[moves[beyond[0]]]
        raise InputError(f"a last move for joint {beyond[0]}, but the points have {n_joints} joint columns "
                         f"(one q<i>{MOVE_SUFFIX} a joint column)", path, line, h)
    if missing := [i for i in range(1, n_joints + 1) if i not in moves]:
        raise InputError(f"columns {', '.join(f'q{i}{MOVE_SUFFIX}' for i in missing)} missing beside "
                         f"{', '.join(header[moves[i]] for i in sorted(moves))}: the last moves come for every joint "
                         "or for none", path, line, header[moves[min(moves)]])
    return tuple(moves[i] for i in range(1, n_joints + 1))


def _marker_groups(cols: dict, header, path: str, line: int) -> tuple:
    """The base names ``(x, y, z)`` of each marker's reference columns, marker 1 first: ``x_ref`` ... for
    one marker, or ``x1_ref`` ... ``xK_ref`` ... for K (numbered from 1 without a gap; the two namings
    are not mixed; each marker's three columns come together)."""
    numbered = sorted({int(m.group(2)) for b in cols if (m := _MARKER_COLUMN.fullmatch(b)) and m.group(2)})
    if not numbered:
        return (("x_ref", "y_ref", "z_ref"),) if "x_ref" in cols else ()
    if "x_ref" in cols:
        raise InputError("both unnumbered (x_ref_mm ...) and numbered (x1_ref_mm ...) reference columns: give "
                         "one marker as x_ref_mm, y_ref_mm, z_ref_mm or every marker numbered", path, line,
                         header[cols["x_ref"][0]])
    if numbered != list(range(1, len(numbered) + 1)):
        gap = min(set(range(1, numbered[-1] + 1)) - set(numbered))
        last = next(header[i] for b, (i, _) in cols.items() if (m := _MARKER_COLUMN.fullmatch(b))
                    and m.group(2) == str(numbered[-1]))
        raise InputError(f"marker columns are numbered up to {numbered[-1]} but marker {gap} is missing (markers "
                         "are numbered from 1 without a gap)", path, line, last)
    groups = tuple(tuple(f"{a}{k}_ref" for a in "xyz") for k in numbered)
    for group in groups:
        present = [b for b in group if b in cols]
        if len(present) != 3:
            missing = [b for b in group if b not in cols]
            raise InputError(f"columns {', '.join(missing)} missing beside {', '.join(present)}", path, line,
                             header[cols[present[0]][0]])
    return groups


def _check_ids(blk, lay: _PointsLayout, path: str) -> None:
    """The text cells of a block (measurement, feature, session ids) hold no control character (a NUL, an
    escape, DEL, a line or paragraph separator, a tab), the rule of :func:`id_problem` for every id the toolkit
    writes back: a located InputError at the first one. Each distinct id is checked once."""
    for j, c in enumerate(lay.txt_idx[:len(lay.txt_idx) - len(lay.moves)]):
        column = blk.texts[:, j]
        bad = [t for t in set(column.tolist()) if t and id_problem(t)]
        if bad:
            i = int(np.flatnonzero(np.isin(column, bad))[0])
            raise InputError(f"the {lay.header[c]} id {id_problem(column[i])}", path, int(blk.lines[i]),
                             lay.header[c])


def _points_from_block(lay: _PointsLayout, blk, path: str) -> PointSet:
    nums = blk.numbers
    bad = ~np.isfinite(nums)
    if bad.any():
        i, k = np.argwhere(bad)[0]
        raise InputError(f"value must be finite, got {float(nums[i, k])!r}", path, int(blk.lines[i]),
                         lay.header[lay.num_idx[k]])
    pos = {c: k for k, c in enumerate(lay.num_idx)}

    def col(base: str) -> np.ndarray | None:
        if base not in lay.cols:
            return None
        c, unit = lay.cols[base]
        values = nums[:, pos[c]] * UNIT_FACTORS[unit]
        wrong = implausible(values, QUANTITY_OF_UNIT[unit])
        if wrong:
            raise InputError(wrong[1], path, int(blk.lines[wrong[0][0]]), lay.header[c])
        return values

    def group(bases) -> np.ndarray | None:
        return None if bases[0] not in lay.cols else np.column_stack([col(b) for b in bases])  # type: ignore[misc]

    measurement = blk.texts[:, 0]
    empty = np.flatnonzero(measurement == "")
    if len(empty):
        raise InputError("empty measurement id", path, int(blk.lines[empty[0]]), "measurement")
    _check_ids(blk, lay, path)
    units = [unit_of(lay.header[c]) for c in lay.joints]
    q = nums[:, [pos[c] for c in lay.joints]] * np.array([UNIT_FACTORS[u] for u in units])
    for k, unit in enumerate(units):
        wrong = implausible(q[:, k], QUANTITY_OF_UNIT[unit])
        if wrong:
            raise InputError(wrong[1], path, int(blk.lines[wrong[0][0]]), lay.header[lay.joints[k]])
    motion = _moves_from_texts(blk.texts[:, len(lay.txt_idx) - len(lay.moves):], lay, blk.lines, path)
    force, force_kind = group(("fx", "fy", "fz")), None
    if force is not None:
        force_kind = "xyz"
    elif "f_bend" in lay.cols:
        force_kind = "two-channel"
        force = np.column_stack([col("f_bend"), np.zeros(len(q)), col("f_axial")])  # type: ignore[list-item]
    ref = np.stack([group(m) for m in lay.markers], axis=1) if lay.markers else None  # type: ignore[misc]
    session = blk.texts[:, 2] if SESSION_COLUMN in lay.header else None
    if session is not None and (empty := np.flatnonzero(session == "")).size:
        raise InputError("empty session id (a session column names the session of every row)", path,
                         int(blk.lines[empty[0]]), SESSION_COLUMN)
    return PointSet(path=path, measurement=measurement, feature=blk.texts[:, 1], q=q, force=force,
                    torque=group(("mx", "my", "mz")), force_kind=force_kind, temperature=col("temperature"),
                    time=col("time"), ref=ref, lines=blk.lines, session=session,
                    q_units=tuple(unit_of(lay.header[c]) for c in lay.joints), motion=motion)


#: a cell of a last-move column: -1, 0 or 1 exactly, in decimal (``+1``, ``-0``, ``1.0`` too; no exponent, so that no
#: text rounds onto a sign: ``1e-400`` or ``0.99999999999999999`` is refused, not read as 0 or 1)
_MOVE_CELL = re.compile(r"([+-]?)([01])(?:\.0*)?")


def _moves_from_texts(cells: np.ndarray, lay: _PointsLayout, lines: np.ndarray, path: str) -> np.ndarray | None:
    """(n, J) the last moves of a block's move cells (n, J) of text, or None without move columns; a cell that is not
    exactly -1, 0 or 1 is an InputError at its line and column. Each distinct text is parsed once."""
    if not lay.moves:
        return None
    flat = cells.ravel().tolist()
    values = {}
    for t in set(flat):
        m = _MOVE_CELL.fullmatch(t)
        values[t] = np.nan if m is None else (-1.0 if m.group(1) == "-" else 1.0) * float(m.group(2)) + 0.0
    out = np.fromiter(map(values.__getitem__, flat), float, len(flat)).reshape(cells.shape)
    if (bad := np.argwhere(np.isnan(out))).size:
        i, k = bad[0]
        raise InputError(f"a joint's last move is -1, 0 or 1 (the sign of its move onto the point), got "
                         f"{cells[i, k]!r}", path, int(lines[i]), lay.header[lay.moves[k]])
    return out


def iter_points(path: str | Path, joints=None, data: bytes | None = None,
                block_bytes: int = BLOCK_BYTES, span: tuple[int, int] | None = None,
                known_header: tuple[int, list[str]] | None = None):
    """The points of a points CSV (docs/formats.md §3) as :class:`PointSet` blocks of whole lines, file
    order, so that a file of millions of rows is processed in bounded memory. Same checks and
    errors as :func:`read_points` (an error in a later block comes after earlier blocks were yielded).
    ``data``: the file's bytes instead of reading ``path``. ``span``, ``known_header``: one part of
    the file (see :func:`arm_model.csv_io.csv_spans`); a part may hold no rows (the caller checks the
    whole file's count)."""
    path = str(path)
    layout = []

    def check(header, line):
        layout.append(_points_layout(header, line, path, joints))
        return layout[0].num_idx, layout[0].txt_idx
    count, blocks = 0, 0
    for _, _, blk in iter_csv_blocks(path, "the points file", check, block_bytes, data, span, known_header):
        if len(blk.lines):
            count += len(blk.lines)
            blocks += 1
            yield _points_from_block(layout[0], blk, path)
    if not count and span is None:
        raise InputError("no points after the header line", path, layout[0].line + 1)
    log.debug(f"{path}: {count} point row(s) read in {blocks} block(s); columns {', '.join(layout[0].header)}")


def concat_points(sets) -> PointSet:
    """One :class:`PointSet` of blocks of the same file (same columns)."""
    sets = list(sets)
    if len(sets) == 1:
        return sets[0]

    def cat(attr):
        v = [getattr(s, attr) for s in sets]
        return None if v[0] is None else np.concatenate(v)
    return PointSet(path=sets[0].path, measurement=cat("measurement"), feature=cat("feature"), q=cat("q"),
                    force=cat("force"), torque=cat("torque"), force_kind=sets[0].force_kind,
                    temperature=cat("temperature"), time=cat("time"), ref=cat("ref"), lines=cat("lines"),
                    session=cat("session"), q_units=sets[0].q_units, motion=cat("motion"))


def read_points(path: str | Path, joints=None) -> PointSet:
    """Read a points CSV (docs/formats.md §3): every column with its unit, SI inside. Unknown columns,
    two columns for one quantity, an empty or non-numeric cell, ``nan``/``inf``, ``4_5`` are errors
    naming the file, the line and the column.

    Args:
        path: the CSV file (UTF-8; a byte-order mark is accepted).
        joints: the arm's joint columns: their number, or each one's quantity ("angle" for a revolute
            joint, "length" for a prismatic one: :attr:`arm_model.ArmDescription.joint_quantities`); a
            different count, or a column in the other quantity, is an error. None: any count, each column
            an angle or a length by its unit.
    """
    return concat_points(iter_points(path, joints))


def parse_points(text: str, path: str = "<string>", joints=None) -> PointSet:
    """Parse points CSV text; see :func:`read_points`."""
    return concat_points(iter_points(path, joints, data=text.encode("utf-8", "surrogatepass")))


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

    def __post_init__(self):
        """A Feature built in Python is held to the artefacts reader's rule (a ValueError naming the field): a
        non-empty id, a known kind, a diameter > 0 and an uncertainty and form error >= 0, each finite and a
        plausible length."""
        if id_problem(self.id):
            raise ValueError(f"Feature: id {id_problem(self.id)}")
        if self.kind not in FEATURE_KINDS:
            raise ValueError(f"Feature: kind must be one of {', '.join(FEATURE_KINDS)}, got {self.kind!r}")
        for name in _FEATURE_LENGTHS:
            v = getattr(self, name)
            if v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v) \
                    or implausible(float(v), "length") or v < 0 or (name == "diameter" and v == 0):
                least = "> 0" if name == "diameter" else ">= 0"
                raise ValueError(f"Feature: {name} must be a finite length [m] {least} and plausible, got {v!r}")


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


#: the numeric keys of a feature (lengths; each with its unit suffix), which only the kinds of a certified diameter take
_FEATURE_LENGTHS = ("diameter", "u_diameter", "form_error")
_DIAMETER_KINDS = ("ring", "cylinder", "sphere")


def read_artefacts(path: str | Path) -> Artefacts:
    """Read an artefacts TOML file (docs/formats.md §4)."""
    art = parse_artefacts(read_text(path, "the artefacts file"), str(path))
    kinds = sorted({f.kind for f in art.features.values()})
    log.debug(f"{path}: {len(art.features)} feature(s) ({', '.join(kinds) or 'none'}), "
              f"{len(art.distances)} certified distance(s)")
    return art


def _artefacts_error(lines: dict, path: str):
    """``err(msg, table, index, key=None)``: the InputError at the line of ``[[table]]`` number ``index``
    (and its ``key``) of the artefacts text (``lines``: its :func:`~arm_model.toml_lines.toml_key_lines`)."""
    def err(msg, table, index, key=None):
        col = f"key '{table}[{index + 1}].{key}'" if key else f"key '{table}[{index + 1}]'"
        return InputError(msg, path, lines.get((table, index, key) if key else (table, index)), col)
    return err


def _artefact_feature(err, t, i: int, features: dict, extra_feature_keys: tuple) -> Feature:
    """[[feature]] table number ``i`` (``features``: the ones before it)."""
    if not isinstance(t, dict):
        raise err("expected a [[feature]] table", "feature", i)
    fid = t.get("id")
    if fid is None or fid == "":
        raise err("missing or empty 'id'", "feature", i, "id")
    if id_problem(fid):
        raise err(f"'id' {id_problem(fid)}", "feature", i, "id")
    if fid in features:
        raise err(f"feature id '{fid}' is used twice", "feature", i, "id")
    kind = t.get("kind")
    if kind not in FEATURE_KINDS:
        raise err(f"unknown kind {kind!r} (known: {', '.join(FEATURE_KINDS)})", "feature", i, "kind")
    values = {}
    for key, v in t.items():
        if key in ("id", "kind") or key in extra_feature_keys:
            continue
        parts = split_unit(key)
        if parts is None or parts[0] not in _FEATURE_LENGTHS:
            raise err(unknown_key(key, ("id", "kind") + _FEATURE_LENGTHS + tuple(extra_feature_keys),
                                  ["id", "kind"] + [f"{b}_<length unit>" for b in _FEATURE_LENGTHS]
                                  + list(extra_feature_keys)),
                      "feature", i, key)
        if QUANTITY_OF_UNIT[parts[1]] != "length":
            raise err(f"'{key}' must be a length (_mm, _m, _um)", "feature", i, key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise err(f"'{key}' must be a finite number, got {v!r}", "feature", i, key)
        if parts[0] in values:
            raise err(f"'{parts[0]}' is given twice (with two units)", "feature", i, key)
        values[parts[0]] = float(v) * UNIT_FACTORS[parts[1]]
        wrong = implausible(values[parts[0]], "length")
        if wrong:
            raise err(f"'{key}': {wrong[1]}", "feature", i, key)
        if parts[0] != "diameter" and values[parts[0]] < 0:
            raise err(f"'{key}' must not be negative, got {v!r}", "feature", i, key)
    if values and kind not in _DIAMETER_KINDS:      # a certificate the kind has not: a key of another kind
        key = next(k for k in t if (parts := split_unit(k)) is not None and parts[0] in _FEATURE_LENGTHS)
        raise err(f"'{key}' is not a key of a {kind}: diameter_mm, u_diameter_mm and form_error_mm certify a "
                  f"{', '.join(_DIAMETER_KINDS[:-1])} or {_DIAMETER_KINDS[-1]}", "feature", i, key)
    if kind in _DIAMETER_KINDS and "diameter" not in values:
        raise err(f"a {kind} needs 'diameter_mm'", "feature", i)
    if "diameter" in values and values["diameter"] <= 0:
        raise err("diameter must be > 0", "feature", i, "diameter_mm")
    if "diameter" in values and values["diameter"] < SMALLEST_ARTEFACT_M:
        raise err(f"diameter {values['diameter'] * 1e3:g} mm is below {SMALLEST_ARTEFACT_M * 1e3:g} mm: no artefact "
                  "a ball probes (a unit slip?)", "feature", i, "diameter_mm")
    return Feature(fid, kind, values.get("diameter"), values.get("u_diameter"),
                   values.get("form_error"), values)


def _artefact_distance(err, t, i: int, features: dict) -> Distance:
    """[[distance]] table number ``i`` between two of ``features``."""
    if not isinstance(t, dict):
        raise err("expected a [[distance]] table", "distance", i)
    between = t.get("between")
    if (not isinstance(between, list) or len(between) != 2
            or not all(isinstance(b, str) for b in between)):
        raise err("'between' must name two features", "distance", i, "between")
    for b in between:
        if b not in features:
            raise err(f"unknown feature '{b}' (known: {', '.join(features)})", "distance", i, "between")
    if between[0] == between[1]:
        raise err(f"'between' names '{between[0]}' twice; a distance joins two features", "distance", i,
                  "between")
    other = next((b for b in between if features[b].kind not in CENTRE_KINDS), None)
    if other is not None:
        kind = features[other].kind
        why = {"plane": "a plane has none", "point": "a free point is no artefact's centre"}.get(
            kind, f"a {kind}'s axis is a line, not a point")
        raise err(f"'{other}' is a {kind}: a distance joins two features' centres (seats or spheres), and {why}",
                  "distance", i, "between")
    length = u = None
    for key, v in t.items():
        if key == "between":
            continue
        parts = split_unit(key)
        if parts is None or parts[0] not in ("length", "u_length"):
            raise err(unknown_key(key, ("between", "length", "u_length"),
                                  ["between", "length_<length unit>", "u_length_<length unit>"]),
                      "distance", i, key)
        if QUANTITY_OF_UNIT[parts[1]] != "length":
            raise err(f"'{key}' must be a length (_mm, _m, _um)", "distance", i, key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise err(f"'{key}' must be a finite number, got {v!r}", "distance", i, key)
        if (length if parts[0] == "length" else u) is not None:
            raise err(f"'{parts[0]}' is given twice (with two units)", "distance", i, key)
        wrong = implausible(float(v) * UNIT_FACTORS[parts[1]], "length")
        if wrong:
            raise err(f"'{key}': {wrong[1]}", "distance", i, key)
        if parts[0] == "length":
            length = float(v) * UNIT_FACTORS[parts[1]]
            if not length > 0:
                raise err(f"'{key}' must be > 0, got {v!r}", "distance", i, key)
            if length < SMALLEST_ARTEFACT_M:
                raise err(f"'{key}' = {v!r} is below {SMALLEST_ARTEFACT_M * 1e3:g} mm: no distance two probed "
                          "centres have (a unit slip?)", "distance", i, key)
        else:
            u = float(v) * UNIT_FACTORS[parts[1]]
            if not u > 0:
                raise err(f"'{key}' must be > 0 (a certified length has an uncertainty; leave the key "
                          f"out to use --sigma-length-um), got {v!r}", "distance", i, key)
            if not STATED_SIGMA_M[0] <= u <= STATED_SIGMA_M[1]:
                f = UNIT_FACTORS[parts[1]]
                raise err(f"'{key}' must be in [{STATED_SIGMA_M[0] / f:g}, {STATED_SIGMA_M[1] / f:g}] {parts[1]} "
                          f"(a stated uncertainty, the fit's weight), got {v!r}", "distance", i, key)
    if length is None:
        raise err("missing 'length_mm'", "distance", i)
    return Distance((between[0], between[1]), length, u)


def parse_artefacts(text: str, path: str = "<string>", *, extra_keys: tuple = (),
                    extra_feature_keys: tuple = ()) -> Artefacts:
    """Parse artefacts TOML text (docs/formats.md §4). ``extra_keys`` (top level) and
    ``extra_feature_keys`` (in a ``[[feature]]``) are left to a caller whose file extends the format
    (a live session's plan); every other unknown key is an error."""
    data = parse_toml(text, path)
    lines = toml_key_lines(text)
    err = _artefacts_error(lines, path)
    for key in data:
        if key not in ("feature", "distance") + tuple(extra_keys):
            raise InputError(unknown_key(key, ("feature", "distance") + tuple(extra_keys)), path,
                             top_key_line(lines, key), f"key '{key}'")
    if not isinstance(data.get("distance", []), list):
        raise InputError("'distance' must be [[distance]] tables", path, top_key_line(lines, "distance"),
                         "key 'distance'")
    feats = data.get("feature", [])
    if not isinstance(feats, list) or not feats:
        raise InputError("no [[feature]] tables", path, 1)
    features: dict[str, Feature] = {}
    for i, t in enumerate(feats):
        feature = _artefact_feature(err, t, i, features, extra_feature_keys)
        features[feature.id] = feature
    distances = [_artefact_distance(err, t, i, features) for i, t in enumerate(data.get("distance", []))]
    for i, d in enumerate(distances):
        first = next((k for k in range(i) if set(distances[k].between) == set(d.between)), None)
        if first is not None:
            raise err(f"the distance between '{d.between[0]}' and '{d.between[1]}' is given twice (first in "
                      f"[[distance]] {first + 1}, line {lines.get(('distance', first, 'between'), '?')}): one "
                      "certified length a pair", "distance", i, "between")
    return Artefacts(path, features, tuple(distances))


def check_features(points: PointSet, artefacts: Artefacts | None) -> None:
    """Every non-empty feature id of the points must exist in the artefacts file (``artefacts`` None: no
    artefacts file, every row a free point)."""
    for i, fid in enumerate(points.feature):
        if fid and (artefacts is None or fid not in artefacts.features):
            line = None if points.lines is None else int(points.lines[i])
            if artefacts is None:
                raise InputError(f"feature '{fid}' but no artefacts file was given (without one, every row is a "
                                 "free point with reference coordinates and its feature cell is empty)",
                                 points.path, line, "feature")
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
    found = []

    def check(header, hline):
        if "time_s" not in header:
            raise InputError("missing column 'time_s'", path, hline)
        if {"fx_N", "fy_N", "fz_N"} <= set(header):
            found.append(("xyz", ("fx_N", "fy_N", "fz_N"), hline))
        elif {"f_bend_N", "f_axial_N"} <= set(header):
            found.append(("two-channel", ("f_bend_N", "f_axial_N"), hline))
        else:
            raise InputError("expected force columns fx_N, fy_N, fz_N or f_bend_N, f_axial_N", path, hline)
        known = ("time_s",) + found[-1][1]
        for h in header:
            if h not in known or header.count(h) > 1:
                what = "repeated column" if h in known else "unknown column"
                raise InputError(f"{what} '{h}' (the columns of this force signal are {', '.join(known)}; "
                                 "docs/formats.md §5)", path, hline, h)
        return list(range(len(header))), []
    blocks = [(h, b) for _, h, b in iter_csv_blocks(path, "the force signal", check)]
    if not blocks or not sum(len(b.lines) for _, b in blocks):
        raise InputError("the file is empty (expected a header and samples)", path, 1 if not found else found[0][2] + 1)
    header = blocks[0][0]
    arr = np.concatenate([b.numbers for _, b in blocks])
    lines = np.concatenate([b.lines for _, b in blocks])
    bad = ~np.isfinite(arr)
    if bad.any():
        i, k = np.argwhere(bad)[0]
        raise InputError(f"expected a finite number, got {float(arr[i, k])!r}", path, int(lines[i]), header[k])
    for k, h in enumerate(header):
        wrong = implausible(arr[:, k], QUANTITY_OF_UNIT[unit_of(h)])
        if wrong:
            raise InputError(wrong[1], path, int(lines[wrong[0][0]]), h)
    kind, cols, _ = found[0]
    t = arr[:, header.index("time_s")]
    if np.any(np.diff(t) <= 0):
        bad_i = int(np.argmax(np.diff(t) <= 0)) + 1
        raise InputError("time must increase", path, int(lines[bad_i]), "time_s")
    f = np.column_stack([arr[:, header.index(c)] for c in cols])
    if kind == "two-channel":
        f = np.column_stack([f[:, 0], np.zeros(len(t)), f[:, 1]])
    return ForceSignal(str(path), t, f, kind)


# ---------------------------------------------------------------------------------------------
# writing

def atomic_write_text(path: str | Path, text: str, inputs=()) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"), inputs)


def format_artefacts(features, distances=(), comment: str | None = None) -> str:
    """Text of an artefacts file (docs/formats.md §4) that :func:`parse_artefacts` reads back: the
    :class:`Feature` s and :class:`Distance` s, lengths in mm, written by ``tomli_w`` with ``comment``
    as a header."""
    from .description import toml_text
    mm = {"diameter": "diameter_mm", "u_diameter": "u_diameter_mm", "form_error": "form_error_mm"}
    doc = {"feature": [{"id": f.id, "kind": f.kind, **{key: getattr(f, name) * 1e3 for name, key in mm.items()
                                                         if getattr(f, name) is not None}}
                       for f in features],
           "distance": [{"between": list(d.between), "length_mm": d.length * 1e3,
                         **({} if d.u_length is None else {"u_length_mm": d.u_length * 1e3})}
                        for d in distances]}
    return toml_text({k: v for k, v in doc.items() if v}, comment)


def _json_plain(o):
    """``o`` with numpy scalars and arrays as Python numbers and lists, tuples as lists, and every non-finite
    number as None."""
    if isinstance(o, np.ndarray):
        o = o.tolist()
    elif isinstance(o, np.generic):
        o = o.item()
    if isinstance(o, float):
        return o if math.isfinite(o) else None
    if isinstance(o, dict):
        return {k: _json_plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_json_plain(v) for v in o]
    return o


def json_text(obj, indent: int = 1) -> str:
    """Standard JSON text of ``obj`` with a final newline (the one writer of the toolkit's JSON files): numpy
    numbers and arrays as numbers and lists; a number that is not finite (a value nobody resolved) as
    ``null``, never ``NaN`` or ``Infinity``, which Python's json writes and other tools refuse."""
    return json.dumps(_json_plain(obj), indent=indent, allow_nan=False) + "\n"


def write_csv(path: str | Path, columns: dict, inputs=(), fmt="%.9g") -> Path:
    """Write a CSV atomically from ``{name: 1-D array}`` (names carry their unit suffix). ``fmt``: the
    ``%`` format of the float columns, or ``{name: format}`` (others ``%.9g``); fixed formats such as
    ``%.6f`` are formatted by vectorised code (millions of rows a second)."""
    return atomic_write_bytes(path, format_csv(columns, fmt), inputs)
