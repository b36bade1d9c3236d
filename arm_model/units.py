"""Units live in the names (docs/formats.md §1). Everything inside the code is SI."""
from __future__ import annotations

import math

__all__ = ["UNIT_FACTORS", "QUANTITY_OF_UNIT", "PLAUSIBLE_SI", "STATED_SIGMA_M", "split_unit", "unit_of", "to_si",
           "implausible"]

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


def unit_of(name: str) -> str:
    """The unit suffix of a column name already checked to carry one (``"d_mm"`` -> ``"mm"``); a ValueError
    (a bug of the caller, not bad input) if it has none."""
    parts = split_unit(name)
    if parts is None:
        raise ValueError(f"'{name}' has no unit suffix")
    return parts[1]


def to_si(value, unit: str):
    """Convert a value (scalar or array) given in ``unit`` to SI."""
    return value * UNIT_FACTORS[unit]


#: the largest magnitude, in SI, that an input number of each quantity may have: far beyond any arm,
#: artefact, probe or campaign (1 km, 10 000 degrees, 100 kN, 100 kN·m, 1 m/N, 10 000 °C, 10^10 s, 10 t: a
#: link of the largest robots weighs a few t).
#: A larger number is a typo or garbage, and would overflow the arithmetic; a temperature is also at or
#: above absolute zero (docs/formats.md §1).
PLAUSIBLE_SI: dict[str, float] = {
    "length": 1e3, "angle": math.radians(1e4), "force": 1e5, "torque": 1e5, "compliance": 1.0,
    "temperature": 1e4, "time": 1e10, "mass": 1e4,
    "inertia": 1e10,            # a moment of inertia [kg m^2]: 10 t at 1 km
    # effect parameters of a model file (arm_model.model_file.PARAM_UNITS)
    "angular compliance": 1.0, "expansion": 1.0, "ratio": 1e3, "temperature difference": 1e4,
    # campaign files of the simulator
    "stiffness": 1e12, "temperature_rate": 1e3, "length_rate": 1.0,
}
ABSOLUTE_ZERO_C = -273.15
#: the range [m] of a stated standard uncertainty of a length that weights a fit (a certified distance's
#: ``u_length_mm``, ``--sigma-*-um``): from 1 pm, whose square is still a normal number in m^2 (1e-300 m gave a
#: weight of 1e600: overflow, and LAPACK's SVD failed), to 100 mm
STATED_SIGMA_M = (1e-12, 0.1)

#: the smallest artefact size [m] (a diameter, a certified distance): below 1 um no artefact is probed by a ball;
#: such a value is a unit slip (1e-320 mm ran the fit 800 iterations to exit 4 instead of a refusal at its key)
SMALLEST_ARTEFACT_M = 1e-6


def implausible(value_si, quantity: str):
    """Where ``value_si`` (a number or an array, SI) is out of the plausible range of ``quantity``
    (:data:`PLAUSIBLE_SI`): None if nowhere, else ``(index, message)`` for the first bad element
    (index None for a scalar). Non-finite values are the caller's (they are refused before)."""
    import numpy as np
    bound = PLAUSIBLE_SI.get(quantity)
    if bound is None:
        return None
    v = np.asarray(value_si, dtype=float)
    bad = np.abs(v) > bound
    if quantity == "temperature":
        bad |= v < ABSOLUTE_ZERO_C
    if not bad.any():
        return None
    idx = None if v.ndim == 0 else tuple(int(i) for i in np.argwhere(bad)[0])
    x = float(v if idx is None else v[idx])
    if quantity == "temperature" and x < ABSOLUTE_ZERO_C:
        return idx, f"a temperature below absolute zero ({x:g} C)"
    f, unit = {"length": (1e3, "mm"), "angle": (180 / math.pi, "deg"), "force": (1.0, "N"),
               "torque": (1.0, "N m"), "compliance": (1e3, "mm/N"), "temperature": (1.0, "C"),
               "time": (1.0, "s"), "mass": (1.0, "kg"), "inertia": (1.0, "kg m^2"),
               "angular compliance": (1.0, "rad/(N m)"),
               "expansion": (1.0, "1/K"), "ratio": (1.0, ""), "temperature difference": (1.0, "K"),
               "stiffness": (1.0, "N m/rad"), "temperature_rate": (1.0, "C/s"),
               "length_rate": (3.6e6, "mm/h")}[quantity]
    si = {"length": "m", "angle": "rad", "compliance": "m/N"}.get(quantity, unit)
    sep, sep_si = (" " if unit else ""), (" " if si else "")    # a ratio has no unit: no blank before none
    shown = f"{x * f:g}{sep}{unit}" if math.isfinite(x * f) else f"{x:g}{sep_si}{si}"     # 1e308 m is no "inf mm"
    return idx, (f"{shown} is not a plausible {quantity} (|value| at most {bound * f:g}{sep}{unit}); "
                 + ("check the number and its unit" if unit else "check the number"))
