"""The sample stream of a live session (docs/formats.md §8): one CSV line a sample, a header line first.

A sample is the arm's encoder angles and the force sensor's wrench at one instant::

    time_s,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,q7_deg,fx_N,fy_N,fz_N,trigger
    12.001,10.5,-30.25,0.125,85.0,-1.5,30.0,0.0,0.012,-0.031,0.004,0

Columns (units in the names, as in the points format): ``time_s`` (or ``t_s``), the joints ``q1_deg`` ...
(or ``_rad``), optional force (``fx_N, fy_N, fz_N``, or the two-channel ``f_bend_N, f_axial_N``), optional
torque (``mx_Nm, my_Nm, mz_Nm`` or ``_Nmm``), optional ``temperature_C`` and an optional ``trigger``
(the arm's button: 0 released, any other number pressed). Anything else is an error of the header.

:class:`SampleLayout` reads the header once and then each line (:meth:`SampleLayout.parse`) into SI
values with the points reader's rules: the same unit factors (so a value reads to the same float as the
points reader gives it), plain decimal or exponent numbers only (no ``nan``, ``inf``, ``4_5``), every
value in its plausible range; a bad line is one :class:`~arm_model.InputError` naming the stream, the
line and the column.
"""
from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from itertools import repeat
from typing import NamedTuple

import numpy as np

from ..csv_io import SPACE, blank_record, parse_number
from ..errors import InputError, did_you_mean, read_text, text_lines
from ..units import ABSOLUTE_ZERO_C, PLAUSIBLE_SI, QUANTITY_OF_UNIT, UNIT_FACTORS, implausible, split_unit

__all__ = ["Sample", "SampleBlock", "SampleLayout", "TIME_COLUMNS", "sample_header", "read_samples", "sample_bounds",
           "checked_value"]

#: the names the time column may have (one of them, once)
TIME_COLUMNS = ("time_s", "t_s")
_GROUPS = {"force": ("fx", "fy", "fz"), "two-channel": ("f_bend", "f_axial"), "torque": ("mx", "my", "mz")}
_QUANTITY = {"fx": "force", "fy": "force", "fz": "force", "f_bend": "force", "f_axial": "force",
             "mx": "torque", "my": "torque", "mz": "torque", "temperature": "temperature"}
# characters of a line that the fast path reads with float(); any other takes the checked path
_PLAIN = str.maketrans("", "", "0123456789.eE+-, ")


def sample_bounds(quantity: str) -> tuple[float, float]:
    """The lowest and highest value [SI] a sample's ``quantity`` ("time", "angle", "length", "force", "torque",
    "temperature") takes: its plausible range, a temperature not below absolute zero."""
    hi = PLAUSIBLE_SI[quantity]
    return (ABSOLUTE_ZERO_C if quantity == "temperature" else -hi), hi


def checked_value(value, quantity: str, what: str) -> float:
    """``value`` as a float within :func:`sample_bounds` of ``quantity`` [SI], or a TypeError / ValueError naming
    ``what`` (a sample given in Python is held to the stream reader's rule)."""
    if isinstance(value, (str, bytes, bool)) or value is None:
        raise TypeError(f"{what} must be a number, got {value!r}")
    v = float(value)
    lo, hi = sample_bounds(quantity)
    if not lo <= v <= hi:           # nan too
        raise ValueError(f"{what} must be a finite {quantity} in [{lo:g}, {hi:g}] (SI), got {value!r}")
    return v


class Sample(NamedTuple):
    """One sample, SI: ``t`` [s]; ``q`` (J,) [rad] as a tuple; ``wrench`` (6,) force [N] and torque
    [N m] of the part on the ball, probe frame, or None without a force sensor; ``trigger`` True while
    the button is pressed (None without a trigger column); ``temperature`` [°C] or None."""
    t: float
    q: tuple
    wrench: tuple | None = None
    trigger: bool | None = None
    temperature: float | None = None


class SampleBlock:
    """Samples that came together (lines of a stream read at once, :meth:`SampleLayout.parse_block`), SI.

    Attributes:
        n: their count; texts, lines: each line as received and its number in the stream.
        t_arr (n,) [s], q (n, J) [rad], wrench (n, 6) [N, N m] or None, pressed (n,) bool or None (the trigger),
        temperature (n,) [°C] or None, mags_arr (n,) |F| [N] (0 without a force sensor): arrays;
        t, fx, fy, fz, mags: the same as lists of floats, for the loops that must go sample by sample.
    """

    def __init__(self, layout: SampleLayout, values: np.ndarray, texts: list[str], lines: list[int]):
        cols = layout.columns(values)
        self.n, self.texts, self.lines = len(values), texts, lines
        self.t_arr, self.q, self.wrench = cols["t"], cols["q"], cols["wrench"]
        self.pressed, self.temperature = cols["pressed"], cols["temperature"]
        self.t = self.t_arr.tolist()
        w = self.wrench
        if w is None:
            self.mags_arr = np.zeros(self.n)
            self.fx = self.fy = self.fz = None
        else:
            fx, fy, fz = w[:, 0], w[:, 1], w[:, 2]
            self.mags_arr = np.sqrt(fx * fx + fy * fy + fz * fz)   # as the one-sample path: the same operations
            self.fx, self.fy, self.fz = fx.tolist(), fy.tolist(), fz.tolist()
        self.mags = self.mags_arr.tolist()
        self._wrench_rows: list | None = None
        #: what a session that takes this block keeps of it (its masks of the rows it may take at once)
        self.masks: object = None

    def __len__(self) -> int:
        return self.n

    def sample(self, k: int) -> Sample:
        """Row ``k`` as the :class:`Sample` :meth:`SampleLayout.parse` gives for its line."""
        w = None if self.wrench is None else tuple(self.wrench[k].tolist())
        return Sample(self.t[k], tuple(self.q[k].tolist()), w,
                      None if self.pressed is None else bool(self.pressed[k]),
                      None if self.temperature is None else float(self.temperature[k]))

    def wrench_rows(self, a: int, b: int) -> list:
        """Rows ``a`` to ``b - 1`` of the wrench, each a list of 6 floats."""
        if self._wrench_rows is None:
            assert self.wrench is not None
            self._wrench_rows = self.wrench.tolist()
        return self._wrench_rows[a:b]


def sample_header(n_joints: int, force: str | None = "xyz", torque: bool = False, trigger: bool = False,
                  temperature: bool = False) -> list[str]:
    """The header of a sample stream in SI units (what :class:`~arm_model.live.Session` records for
    samples pushed from Python): ``time_s``, ``q1_rad`` ..., the force, torque, temperature and trigger
    columns asked for."""
    cols = ["time_s"] + [f"q{i}_rad" for i in range(1, n_joints + 1)]
    if force == "xyz":
        cols += ["fx_N", "fy_N", "fz_N"]
    elif force == "two-channel":
        cols += ["f_bend_N", "f_axial_N"]
    if torque:
        cols += ["mx_Nm", "my_Nm", "mz_Nm"]
    if temperature:
        cols.append("temperature_C")
    if trigger:
        cols.append("trigger")
    return cols


class SampleLayout:
    """What the header of a sample stream says, and the reader of its lines.

    Args:
        header: the header's cells.
        n_joints: the arm's joint count (the stream must have exactly as many joint columns).
        path: the stream's name, for messages (a file, ``<stdin>``, ``tcp://host:port``).
        line: the header's line number.

    Attributes:
        header: the cells; n_cells: their count; force_kind: "xyz", "two-channel" or None;
        has_torque, has_trigger, has_temperature: which optional columns are present.
    """

    def __init__(self, header: list[str], n_joints: int, path: str, line: int = 1):
        self.header = [h.strip() for h in header]
        self.path, self.header_line = path, line
        self.n_cells = len(self.header)
        cols = self._columns(n_joints)
        self.force_kind = "xyz" if "fx" in cols else ("two-channel" if "f_bend" in cols else None)
        self.has_torque = "mx" in cols
        self.has_trigger = "trigger" in cols
        self.has_temperature = "temperature" in cols
        self._time = cols["time"][0]
        self._joints = [cols[f"q{i}"] for i in range(1, n_joints + 1)]
        force = [cols[b] for b in _GROUPS.get({"xyz": "force"}.get(self.force_kind, self.force_kind), ())]
        self._force = force[:1] + [None] + force[1:] if self.force_kind == "two-channel" else force
        self._torque = [cols[b] for b in _GROUPS["torque"]] if self.has_torque else []
        self._trigger = cols["trigger"][0] if self.has_trigger else None
        self._temperature = cols["temperature"][0] if self.has_temperature else None
        # (column, unit factor, lowest, highest [SI]) of every numeric cell, for the range check
        self._checks = [(k, cols_f, *sample_bounds(q), q) for k, (q, cols_f) in self._quantities(cols).items()]
        # the same bounds per cell in the file's units, narrowed by 1e-9 so that a value within them is within
        # the SI bounds whatever the rounding (one outside them is checked exactly); the trigger: any number
        self._lows, self._highs = [-math.inf] * self.n_cells, [math.inf] * self.n_cells
        for k, f, lo, hi, _ in self._checks:
            self._lows[k], self._highs[k] = lo / f * (1 - 1e-9), hi / f * (1 - 1e-9)
        self._low_row, self._high_row = np.array(self._lows), np.array(self._highs)
        self._q_slice = self._joint_slice()
        f = self._force
        self._f_slice = (f[0][0] if self.force_kind == "xyz" and not self._torque and [c[1] for c in f] == [1.0] * 3
                         and [c[0] for c in f] == [f[0][0] + k for k in range(3)] else None)

    def _columns(self, n_joints: int) -> dict:
        """base name -> (index, unit factor) of every column; every header error here."""
        path, line = self.path, self.header_line
        cols: dict[str, tuple[int, float]] = {}
        known = ("time_s, q1_deg ... (or _rad), fx_N, fy_N, fz_N (or f_bend_N, f_axial_N), mx_Nm ..., temperature_C, "
                 "trigger")
        for k, h in enumerate(self.header):
            if not h:
                raise InputError("empty column name in the header", path, line)
            if h in TIME_COLUMNS or h == "trigger":
                base, factor = ("time" if h != "trigger" else "trigger"), 1.0
            else:
                parts = split_unit(h)
                base = None if parts is None else parts[0]
                if parts is None or not (re.fullmatch(r"q[1-9][0-9]*", base) or base in _QUANTITY):
                    names = [*TIME_COLUMNS, "trigger", "temperature_C", "fx_N", "fy_N", "fz_N", "f_bend_N",
                             "f_axial_N", "mx_Nm", "my_Nm", "mz_Nm"] + [f"q{i}_deg" for i in range(1, n_joints + 1)]
                    raise InputError(f"unknown column '{h}'{did_you_mean(h, names)}; the columns of a sample "
                                     f"stream are {known}", path, line, h)
                want = "angle" if base.startswith("q") and base[1:].isdigit() else _QUANTITY[base]
                if QUANTITY_OF_UNIT[parts[1]] != want:
                    raise InputError(f"'{base}' must be a{'n' if want[0] in 'aeiou' else ''} {want}, got unit "
                                     f"'_{parts[1]}'", path, line, h)
                factor = UNIT_FACTORS[parts[1]]
            if base in cols:
                raise InputError(f"'{h}' and '{self.header[cols[base][0]]}' give the same quantity: keep one",
                                 path, line, h)
            cols[base] = (k, factor)
        if "time" not in cols:
            raise InputError("missing the time column 'time_s' (or 't_s')", path, line)
        joints = sorted(int(b[1:]) for b in cols if b.startswith("q") and b[1:].isdigit())
        if joints != list(range(1, len(joints) + 1)) or len(joints) != n_joints:
            raise InputError(f"the joint columns must be q1 ... q{n_joints} (the arm has {n_joints} joints), got "
                             f"{', '.join(f'q{i}' for i in joints) or 'none'}", path, line)
        for group in _GROUPS.values():
            present = [b for b in group if b in cols]
            if present and len(present) != len(group):
                raise InputError(f"columns {', '.join(b for b in group if b not in cols)} missing beside "
                                 f"{', '.join(present)}", path, line, self.header[cols[present[0]][0]])
        if "fx" in cols and "f_bend" in cols:
            raise InputError("both three-axis (fx, fy, fz) and two-channel (f_bend, f_axial) force columns; "
                             "give one sensor", path, line, self.header[cols["f_bend"][0]])
        return cols

    @staticmethod
    def _quantities(cols: dict) -> dict:
        """column index -> (quantity, unit factor) of every numeric column."""
        out = {cols["time"][0]: ("time", 1.0)}
        for base, (k, factor) in cols.items():
            if base.startswith("q") and base[1:].isdigit():
                out[k] = ("angle", factor)
            elif base in _QUANTITY:
                out[k] = (_QUANTITY[base], factor)
        return out

    def parse(self, text: str, line: int) -> Sample:
        """The sample of one line (its text without the line end) [SI]; an :class:`InputError` naming
        the stream, the line and the column for anything that is not a sample of this layout."""
        return self._sample(self._values(text, line))

    def parse_block(self, texts: Sequence[str], lines: Sequence[int]) -> list[SampleBlock | InputError]:
        """Lines that came together (their texts without the line ends, none blank, and their numbers): their
        samples as :class:`SampleBlock` runs, each line that is not a sample as its :class:`InputError` (the one
        :meth:`parse` gives), in the stream's order. Plain lines are read at once (one split, ``float`` on each
        cell, the range check on the array): the same numbers as :meth:`parse`."""
        n = len(texts)
        if not n:
            return []
        joined = ",".join(texts)
        values = None
        if not joined.translate(_PLAIN) and set(map(str.count, texts, repeat(",", n))) == {self.n_cells - 1}:
            try:
                values = np.array(list(map(float, joined.split(","))), float).reshape(n, self.n_cells)
            except ValueError:                  # a cell float() refuses: the line's own error, below
                values = None
        bad = np.ones(n, bool)                  # the lines each read alone
        if values is not None:
            bad = np.asarray(((values < self._low_row) | (values > self._high_row)).any(axis=1))
            if not bad.any():
                return [SampleBlock(self, values, list(texts), list(lines))]
        out: list[SampleBlock | InputError] = []
        rows: list = []
        first = 0
        for k, (text, line) in enumerate(zip(texts, lines, strict=True)):
            try:
                row = self._values(text, line) if values is None or bad[k] else values[k]
            except InputError as exc:
                if rows:
                    out.append(SampleBlock(self, np.array(rows, float), list(texts[first:k]), list(lines[first:k])))
                out.append(exc)
                rows, first = [], k + 1
                continue
            rows.append(row)
        if rows:
            out.append(SampleBlock(self, np.array(rows, float), list(texts[first:]), list(lines[first:])))
        return out

    def _values(self, text: str, line: int) -> list[float]:
        """The numbers of one line in the file's units, checked (see :meth:`parse`)."""
        cells = text.split(",") if '"' not in text else self._quoted(text, line)
        if len(cells) != self.n_cells:
            raise InputError(f"expected {self.n_cells} cells (as the header), got {len(cells)}", self.path, line)
        if text.translate(_PLAIN):
            values = self._checked(cells, line)
        else:
            try:
                values = [float(c) for c in cells]
            except ValueError:
                values = self._checked(cells, line)
        # plain numbers are finite; far ones are typos
        for v, lo, hi in zip(values, self._lows, self._highs, strict=True):
            if not lo <= v <= hi:
                self._range_error(values, line)
        return values

    def _quoted(self, text: str, line: int) -> list[str]:
        """The cells of a line with quotes, as the file readers take them (``"12.5"`` is 12.5)."""
        try:
            return next(csv.reader([text], strict=True))
        except csv.Error as exc:
            raise InputError(f"not valid CSV: {exc}", self.path, line) from None

    def columns(self, values: np.ndarray) -> dict:
        """The SI columns of samples ``values`` (n, cells) in the file's units, as :meth:`parse` makes each sample
        (the same products by the same unit factors): ``t`` (n,), ``q`` (n, J), ``wrench`` (n, 6) or None,
        ``pressed`` (n,) bool or None, ``temperature`` (n,) or None."""
        n = len(values)
        qs = self._q_slice
        if qs is None:
            q = np.stack([values[:, k] * f for k, f in self._joints], axis=1)
        else:
            q = values[:, qs[0]:qs[1]] * qs[2]
        wrench = None
        if self.force_kind is not None:
            wrench = np.zeros((n, 6))
            for i, c in enumerate(self._force):
                if c is not None:
                    wrench[:, i] = values[:, c[0]] * c[1]
            for i, (k, f) in enumerate(self._torque):
                wrench[:, 3 + i] = values[:, k] * f
        return {"t": values[:, self._time], "q": q, "wrench": wrench,
                "pressed": None if self._trigger is None else values[:, self._trigger] != 0.0,
                "temperature": None if self._temperature is None else values[:, self._temperature]}

    def _range_error(self, values: list[float], line: int) -> None:
        for k, f, lo, hi, quantity in self._checks:
            if not lo <= values[k] * f <= hi:
                wrong = implausible(values[k] * f, quantity)
                raise InputError(wrong[1] if wrong else f"value out of range: {values[k]!r}", self.path, line,
                                 self.header[k])

    def _checked(self, cells: list[str], line: int) -> list[float]:
        """Every cell read with the points reader's number rule; the first bad one is the error."""
        values = []
        for k, cell in enumerate(cells):
            v = parse_number(cell)
            if v is None:
                what = "empty cell" if not cell.strip() else f"not a number: {cell.strip(SPACE)[:40]!r}"
                raise InputError(f"{what} (numbers are plain decimals or exponent notation)", self.path, line,
                                 self.header[k])
            if not math.isfinite(v):
                raise InputError(f"value must be finite, got {cell.strip()!r}", self.path, line, self.header[k])
            values.append(v)
        return values

    def _joint_slice(self) -> tuple[int, int, float] | None:
        """(first, last + 1, factor) when the joints are consecutive columns of one unit, else None."""
        ks = [k for k, _ in self._joints]
        fs = {f for _, f in self._joints}
        if len(fs) == 1 and ks == list(range(ks[0], ks[0] + len(ks))):
            return ks[0], ks[-1] + 1, fs.pop()
        return None

    def _sample(self, v: list[float]) -> Sample:
        qs = self._q_slice
        if qs is None:
            q = tuple(v[k] * f for k, f in self._joints)
        elif qs[2] == 1.0:
            q = tuple(v[qs[0]:qs[1]])                 # in rad: the values themselves (x 1.0 is exact)
        else:
            f = qs[2]
            q = tuple([x * f for x in v[qs[0]:qs[1]]])
        wrench = None
        fx = self._f_slice
        if fx is not None:                            # fx, fy, fz in N in three columns, no torque
            wrench = (v[fx], v[fx + 1], v[fx + 2], 0.0, 0.0, 0.0)
        elif self.force_kind is not None:
            f = [0.0 if c is None else v[c[0]] * c[1] for c in self._force]
            m = [v[k] * f_ for k, f_ in self._torque] if self._torque else [0.0, 0.0, 0.0]
            wrench = (*f, *m)  # type: ignore[misc]
        trigger = None if self._trigger is None else v[self._trigger] != 0.0
        temperature = None if self._temperature is None else v[self._temperature]
        return Sample(v[self._time], q, wrench, trigger, temperature)


def read_samples(path) -> int:
    """A sample stream file (docs/formats.md §8) as ``aacmm live`` reads it, line by line; the number of samples
    (the read-back of :mod:`arm_model.readback`)."""
    lines = text_lines(read_text(path, "the sample stream"))
    first = next((k for k, text in enumerate(lines) if not blank_record(text)), len(lines))
    header = [c.strip() for c in lines[first].split(",")] if first < len(lines) else []
    layout = SampleLayout(header, len({m.group(1) for h in header if (m := re.fullmatch(r"q(\d+)_\w+", h))}),
                          str(path), first + 1)
    n = 0
    for no, text in enumerate(lines[first + 1:], start=first + 2):
        if not blank_record(text):
            layout.parse(text, no)
            n += 1
    return n
