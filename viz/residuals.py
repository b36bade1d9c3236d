"""The residuals file the viewer draws (``aacmm view --residuals``).

One row a residual vector, units in the column names (docs/formats.md §1). Either the start point is
given::

    measurement,feature,x_mm,y_mm,z_mm,rx_um,ry_um,rz_um
    ring-01,ring,512.113,-20.410,118.025,1.8,-0.6,0.2

or, as ``aacmm calibrate`` writes its ``residuals.csv``, the point's file and line::

    measurement,feature,kind,file,line,residual_um,dx_um,dy_um,dz_um,standardized
    ring-01,ring,ring,sim/points.csv,2,1.93,1.8,-0.6,0.2,0.4

* ``x, y, z`` (any length unit): where the vector starts, the ball centre in the base frame; or
  ``line``: the file line of the point in the points file the viewer shows (the vector then starts at
  that point's deflection-corrected ball centre; a row of another file, or whose measurement or feature
  differs from that line's, is not drawn and is counted). ``file`` (optional, with ``line``): the points file
  of the row as the calibration was given it; a point is its file and line (a reference file's points share
  line numbers with the points file's). A row is of the file shown when its ``file`` is that file's path or
  names the same file; failing any such row (the files moved), when its ``file`` has the shown file's name and
  no other file of the residuals has that name (:func:`shown_file`).
* ``rx, ry, rz`` or ``dx, dy, dz`` (any length unit): the residual vector, base frame: measured minus
  model (e.g. the ball centre minus its nearest point on the fitted feature's ball-centre surface).
* ``measurement``, ``feature``, ``file`` (optional text); ``kind`` (a feature kind, ``reference`` or ``marker``: a
  reference residual starts at its marker); ``residual`` (a length), ``standardized`` (read and not used: the
  columns ``aacmm calibrate`` writes). Any other column is an error naming the
  file, line 1 (the header) and the column, as in every file of the project.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arm_model import QUANTITY_OF_UNIT, UNIT_FACTORS, InputError, csv_records, read_text, split_unit
from arm_model.csv_io import SPACE, parse_number
from arm_model.errors import id_problem, unknown_key
from arm_model.io import FEATURE_KINDS
from arm_model.units import implausible, unit_of

__all__ = ["Residuals", "read_residuals", "parse_residuals", "residual_origins", "shown_file"]

_POINT = ("x", "y", "z")
_VECTORS = (("rx", "ry", "rz"), ("dx", "dy", "dz"))
#: the kinds of a residual (calibrate's residuals.csv): a feature's, a reference point's (a tracker's target) or a
#: motion-capture marker's (calibration.problem's instances)
_KINDS = (*FEATURE_KINDS, "reference", "marker")
_TEXT = ("measurement", "feature", "kind", "file", "line", "standardized")     # no unit: text, line number, ratio
_LENGTHS = _POINT + _VECTORS[0] + _VECTORS[1] + ("residual",)           # a length unit each

@dataclass(frozen=True)
class Residuals:
    """Residual vectors ``vectors`` (N, 3) [m], base frame, starting at ``points`` (N, 3) [m] or, when
    the file gives none, at the points-file lines ``point_lines`` (N,); ``measurement``, ``feature`` and
    ``kind`` (N,) text ("" when absent); ``lines`` (N,) the file line of each row; ``file`` (N,) the points file
    of each ``point_lines`` entry ("" when absent)."""
    path: str
    points: np.ndarray | None
    vectors: np.ndarray
    measurement: np.ndarray
    feature: np.ndarray
    lines: np.ndarray
    point_lines: np.ndarray | None = None
    kind: np.ndarray | None = None
    file: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.vectors)

    def select(self, mask) -> Residuals:
        """The rows where ``mask`` holds."""
        def take(a):
            return None if a is None else a[mask]
        return Residuals(self.path, take(self.points), self.vectors[mask], self.measurement[mask],
                         self.feature[mask], self.lines[mask], take(self.point_lines), take(self.kind),
                         take(self.file))

def read_residuals(path: str | Path) -> Residuals:
    """Read a residuals CSV (see the module documentation)."""
    return parse_residuals(read_text(path, "the residuals file"), str(path))

def parse_residuals(text: str, path: str = "<string>") -> Residuals:
    """Parse residuals CSV text; see :func:`read_residuals`."""
    records = csv_records(text, path)
    if not records:
        raise InputError("the file is empty (expected a header line and at least one residual)", path, 1)
    hline, header = records[0]
    header = [h.strip() for h in header]
    data = records[1:]
    by_base: dict[str, tuple[int, str]] = {}
    for k, h in enumerate(header):
        if header.count(h) > 1:
            raise InputError(f"column '{h}' appears twice", path, hline, h)
        parts = split_unit(h)
        if h not in _TEXT and (parts is None or parts[0] not in _LENGTHS):
            raise InputError(unknown_key(h, _TEXT + _LENGTHS, _TEXT + tuple(f"{b}_<length unit>" for b in _LENGTHS),
                                         what="column"), path, hline, h)
        if parts is not None:
            if parts[0] in by_base:
                raise InputError(f"'{h}' and '{by_base[parts[0]][1]}' give the same quantity: keep one",
                                 path, hline, h)
            by_base[parts[0]] = (k, h)
    if not data:
        raise InputError("no residuals after the header line", path, hline + 1)
    vector = next((v for v in _VECTORS if all(b in by_base for b in v)), None)
    if vector is None:
        raise InputError("missing residual columns: expected rx, ry, rz (or dx, dy, dz) with a length unit, "
                         "e.g. rx_um", path, hline)
    has_xyz = all(b in by_base for b in _POINT)
    if not has_xyz and "line" not in header:
        raise InputError("missing columns x_mm, y_mm, z_mm (where each vector starts) or 'line' (its line in "
                         "the points file)", path, hline)
    for base, (_, h) in by_base.items():
        if QUANTITY_OF_UNIT[unit_of(h)] != "length":
            raise InputError(f"'{base}' must be a length (_mm, _m or _um)", path, hline, h)
    for no, r in data:
        if len(r) != len(header):
            raise InputError(f"{len(r)} cells where the header has {len(header)} columns", path, no)

    def column(base: str) -> np.ndarray:
        k, h = by_base[base]
        out = np.empty(len(data))
        for i, (no, r) in enumerate(data):
            v = parse_number(r[k])      # the toolkit's one number grammar (no '1_0', no '１', no NBSP)
            if v is None or not math.isfinite(v):
                raise InputError(f"expected a finite number, got {r[k].strip(SPACE)!r}", path, no, h)
            wrong = implausible(v * UNIT_FACTORS[unit_of(h)], "length")    # 1e308 overflowed the drawing
            if wrong:
                raise InputError(wrong[1], path, no, h)
            out[i] = v
        return out * UNIT_FACTORS[unit_of(h)]

    def text_column(name: str) -> np.ndarray:
        if name not in header:
            return np.full(len(data), "", dtype=object)
        k = header.index(name)
        for no, r in data:              # the ids of the points file: one line of text (empty: not given)
            if r[k].strip() and id_problem(r[k].strip()):
                raise InputError(f"{name!r} {id_problem(r[k].strip())}", path, no, name)
        return np.array([r[k].strip() for _, r in data], dtype=object)

    if "residual" in by_base:
        column("residual")              # read and not used, but a number in range as every cell of the project
    if "standardized" in header:
        k = header.index("standardized")
        for no, r in data:
            v = parse_number(r[k])
            if v is None or not math.isfinite(v) or abs(v) > 1e12:
                raise InputError(f"expected a finite number (a residual over its standard uncertainty), got "
                                 f"{r[k].strip(SPACE)!r}", path, no, "standardized")

    point_lines = None
    if not has_xyz:
        k = header.index("line")
        point_lines = np.empty(len(data), dtype=int)
        for i, (no, r) in enumerate(data):
            cell = r[k].strip()
            if not (cell.isascii() and cell.isdigit()) or len(cell) > 12 or int(cell) < 1:  # '²' is a digit to isdigit
                raise InputError(f"expected a line number (1, 2, ...), got {cell!r}", path, no, "line")
            point_lines[i] = int(cell)
    kinds = text_column("kind")
    for (no, _), kind in zip(data, kinds, strict=True):    # "reference" starts at a marker: a typo would not
        if kind and kind not in _KINDS:
            raise InputError(f"unknown kind {kind!r} (known: {', '.join(_KINDS)})", path, no, "kind")
    files = text_column("file")
    if point_lines is not None:         # one residual a point (a reference point or a mocap marker: one a marker)
        first: dict[tuple, int] = {}
        for (no, _), line, kind, file in zip(data, point_lines, kinds, files, strict=True):
            if kind not in ("reference", "marker"):
                seen = first.setdefault((file, int(line), kind), no)
                if seen != no:
                    where = f" of {file}" if file else ""
                    raise InputError(f"point line {line}{where} (kind {kind or 'not given'}) is given twice (first on "
                                     f"line {seen}): one residual a point", path, no, "line")
    return Residuals(path, np.column_stack([column(b) for b in _POINT]) if has_xyz else None,
                     np.column_stack([column(b) for b in vector]), text_column("measurement"), text_column("feature"),
                     np.array([no for no, _ in data]), point_lines, kinds, files)

def residual_origins(res: Residuals, points, centres: np.ndarray,
                     markers: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Start points and vectors [m] of the residuals that can be drawn.

    Args:
        res: the residuals read.
        points: the :class:`~arm_model.PointSet` shown (for residuals given by ``line``).
        centres: (N, 3) its deflection-corrected ball centres [m].
        markers: (N, K, 3) [m] the markers of a tracker where the model puts them (base frame), or None: a
            ``reference`` residual of a line then starts at its marker (the k-th row of that line at marker
            k), not at the tip point.

    Returns:
        (origins (M, 3), vectors (M, 3), skipped): ``skipped`` counts rows given by a line that is not a
        point of ``points`` (a row of another ``file``, :func:`shown_file`) with the same measurement and feature.

    A point of ``points`` given twice (the same kind; its file spelt two ways, ``calpts.csv`` and ``./calpts.csv``,
    or left empty on one row, which the reader cannot tell apart) is an InputError naming the second row's line.
    """
    if res.points is not None:
        return res.points, res.vectors, 0
    row_of = {int(line): i for i, line in enumerate(points.lines)}
    mine = shown_file(() if res.file is None else res.file, points.path)
    keep, origins, seen, drawn = [], [], {}, {}
    for k, line in enumerate(res.point_lines):
        i = row_of.get(int(line))
        if i is None or (res.file is not None and res.file[k] and res.file[k] not in mine) \
                or (res.measurement[k] and res.measurement[k] != points.measurement[i]) \
                or (res.feature[k] and res.feature[k] != points.feature[i]):
            continue
        kind = "" if res.kind is None else res.kind[k]
        if kind not in ("reference", "marker"):     # one residual a point, however its file is spelt ("", ./x)
            first = drawn.setdefault((i, kind), k)
            if first != k:
                raise InputError(f"point line {int(line)} of {points.path} (kind {kind or 'not given'}) is given twice "
                                 f"(first on line {res.lines[first]}, file {_named(res, first)}; here file "
                                 f"{_named(res, k)}): one residual a point", res.path, int(res.lines[k]), "line")
        keep.append(k)
        if markers is not None and res.kind is not None and res.kind[k] == "reference":
            m = seen.get(i, 0)
            seen[i] = m + 1
            origins.append(markers[i, m % markers.shape[1]])
        else:
            origins.append(centres[i])
    return np.reshape(origins, (-1, 3)), res.vectors[keep], len(res.vectors) - len(keep)



def _named(res: Residuals, k: int) -> str:
    """The ``file`` cell of row ``k`` for a message: quoted, or "not given"."""
    f = "" if res.file is None else res.file[k]
    return repr(f) if f else "not given"


def shown_file(files, shown: str | Path) -> set[str]:
    """The entries of a residuals file's ``file`` column (``files``; "" not given) that are the points file
    ``shown``: those equal to its path or naming the same file on disk; failing any (the files moved since the
    calibration), the entry with its file name when no other entry has that name; else none."""
    names = {str(f) for f in files if f}
    same = {f for f in names if f == str(shown) or _same_file(f, shown)}
    if same:
        return same
    named = {f for f in names if Path(f).name == Path(shown).name}
    return named if len(named) == 1 else set()


def _same_file(a: str | Path, b: str | Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):        # a file that is not there (moved), a name the system refuses
        return False
