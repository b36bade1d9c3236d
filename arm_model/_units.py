"""Units live in the names (docs/formats.md §1). Everything inside the code is SI."""
from __future__ import annotations

import math

__all__ = ["UNIT_FACTORS", "QUANTITY_OF_UNIT", "split_unit", "to_si"]

#: factor that converts a value in the suffix unit to SI (m, rad, N, N·m, m/N, °C, s)
UNIT_FACTORS: dict[str, float] = {
    "mm": 1e-3, "m": 1.0, "um": 1e-6,
    "deg": math.pi / 180.0, "rad": 1.0,
    "N": 1.0,
    "Nmm": 1e-3, "Nm": 1.0,
    "mm_per_N": 1e-3, "um_per_N": 1e-6, "m_per_N": 1.0,
    "C": 1.0,
    "s": 1.0,
    "kg": 1.0,  # project addition: link masses in the arm description
}

QUANTITY_OF_UNIT: dict[str, str] = {
    "mm": "length", "m": "length", "um": "length",
    "deg": "angle", "rad": "angle",
    "N": "force", "Nmm": "torque", "Nm": "torque",
    "mm_per_N": "compliance", "um_per_N": "compliance", "m_per_N": "compliance",
    "C": "temperature", "s": "time", "kg": "mass",
}

# longest suffixes first so that "_mm_per_N" wins over "_N"
_SUFFIXES = sorted(UNIT_FACTORS, key=len, reverse=True)


def split_unit(name: str) -> tuple[str, str] | None:
    """Split ``"d_mm"`` into ``("d", "mm")``; ``None`` if the name has no known unit suffix."""
    for unit in _SUFFIXES:
        suffix = "_" + unit
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)], unit
    return None


def to_si(value, unit: str):
    """Convert a value (scalar or array) given in ``unit`` to SI."""
    return value * UNIT_FACTORS[unit]
