"""The residuals file the viewer draws (``aacmm view --residuals``).

One row a residual vector, units in the column names (DATA-FORMATS §1)::

    measurement,feature,x_mm,y_mm,z_mm,rx_um,ry_um,rz_um
    ring-01,ring,512.113,-20.410,118.025,1.8,-0.6,0.2

* ``x, y, z`` (required, any length unit): where the vector starts, the ball centre in the base frame.
* ``rx, ry, rz`` (required, any length unit): the residual vector, base frame: measured minus model
  (e.g. the ball centre minus its nearest point on the fitted feature's ball-centre surface).
* ``measurement``, ``feature`` (optional text). Other columns are allowed and ignored; a column of
  numbers without a unit suffix is an error, as in every file of the project.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arm_model import InputError
from arm_model._errors import read_text
from arm_model._units import QUANTITY_OF_UNIT, UNIT_FACTORS, split_unit
from arm_model.io import _csv_records

__all__ = ["Residuals", "read_residuals", "parse_residuals"]

_POINT = ("x", "y", "z")
_VECTOR = ("rx", "ry", "rz")


@dataclass(frozen=True)
class Residuals:
    """Residual vectors: ``points`` (N, 3) [m] and ``vectors`` (N, 3) [m], base frame; ``measurement``
    and ``feature`` (N,) text ("" when absent); ``lines`` (N,) file line of each row."""
    path: str
    points: np.ndarray
    vectors: np.ndarray
    measurement: np.ndarray
    feature: np.ndarray
    lines: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


def read_residuals(path: str | Path) -> Residuals:
    """Read a residuals CSV (see the module documentation)."""
    return parse_residuals(read_text(path, "the residuals file"), str(path))


def parse_residuals(text: str, path: str = "<string>") -> Residuals:
    """Parse residuals CSV text; see :func:`read_residuals`."""
    records = _csv_records(text, path)
    if not records:
        raise InputError("the file is empty (expected a header line and at least one residual)", path, 1)
    hline, header = records[0]
    header = [h.strip() for h in header]
    data = records[1:]
    if not data:
        raise InputError("no residuals after the header line", path, hline + 1)
    by_base: dict[str, tuple[int, str]] = {}
    for k, h in enumerate(header):
        if header.count(h) > 1:
            raise InputError(f"column '{h}' appears twice", path, hline, h)
        parts = split_unit(h)
        if parts is not None:
            by_base[parts[0]] = (k, h)
    for base in _POINT + _VECTOR:
        if base not in by_base:
            raise InputError(f"missing column '{base}_mm' (or _m, _um): expected x, y, z and rx, ry, rz "
                             "lengths", path, hline)
        h = by_base[base][1]
        if QUANTITY_OF_UNIT[split_unit(h)[1]] != "length":
            raise InputError(f"'{base}' must be a length (_mm, _m or _um)", path, hline, h)
    for no, r in data:
        if len(r) != len(header):
            raise InputError(f"{len(r)} cells where the header has {len(header)} columns", path, no)
    for k, h in enumerate(header):
        if split_unit(h) is None and h not in ("measurement", "feature"):
            cells = [r[k].strip() for _, r in data]
            if all(c and _number(c) is not None for c in cells):
                raise InputError("numeric column without a unit suffix (expected e.g. '_mm', '_um')",
                                 path, hline, h)

    def column(base: str) -> np.ndarray:
        k, h = by_base[base]
        out = np.empty(len(data))
        for i, (no, r) in enumerate(data):
            v = _number(r[k].strip())
            if v is None or not math.isfinite(v):
                raise InputError(f"expected a finite number, got {r[k].strip()!r}", path, no, h)
            out[i] = v
        return out * UNIT_FACTORS[split_unit(h)[1]]

    def text(name: str) -> np.ndarray:
        if name not in header:
            return np.full(len(data), "", dtype=object)
        k = header.index(name)
        return np.array([r[k].strip() for _, r in data], dtype=object)

    return Residuals(path, np.column_stack([column(b) for b in _POINT]),
                     np.column_stack([column(b) for b in _VECTOR]), text("measurement"), text("feature"),
                     np.array([no for no, _ in data]))


def _number(cell: str) -> float | None:
    try:
        return float(cell)
    except ValueError:
        return None
