"""Correlation of ring errors with the contact force (the seed paper's §4.1, Figures 10-11).

Pearson r, R^2 = r^2, the least-squares line and the two-sided p-value of r = 0, with or without the
paper's reference point (0 N, 0 mm): the reference values were taken by a CMM at (nominally) zero force.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = ["Correlation", "correlate", "campaign_correlations", "FORCE_VALUES"]

#: the paper's significant force values of a measurement
FORCE_VALUES = ("mean", "max10", "max")


@dataclass(frozen=True)
class Correlation:
    """Pearson correlation of y with x (in the units of the arrays given): ``r``, ``r2``, ``p_value``,
    the line ``y = intercept + slope x``, ``n`` pairs, and whether the (0, 0) point was added."""
    x_name: str
    y_name: str
    with_reference: bool
    n: int
    r: float
    r2: float
    p_value: float
    slope: float
    intercept: float

    def as_dict(self) -> dict:
        return {k: (v.item() if isinstance(v, np.generic) else v) for k, v in self.__dict__.items()}


def correlate(x, y, with_reference: bool = False, x_name: str = "x", y_name: str = "y") -> Correlation:
    """Pearson r of ``y`` with ``x`` (M,), optionally with the point (0, 0) added. A ValueError for fewer than 3
    pairs, a constant ``x`` or ``y``, a value that is not finite or arrays of two lengths."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if x.ndim != 1 or x.shape != y.shape:
        raise ValueError(f"{x_name} and {y_name} must be two 1-D arrays of one length, got shapes {x.shape}, {y.shape}")
    for name, v in ((x_name, x), (y_name, y)):
        bad = np.flatnonzero(~np.isfinite(v))
        if len(bad):
            raise ValueError(f"{name}: value {int(bad[0])} is {float(v[bad[0]])!r}, not finite: no correlation (a NaN "
                             "would make r, p and the slope NaN)")
    if with_reference:
        x, y = np.r_[0.0, x], np.r_[0.0, y]
    if len(x) < 3:
        raise ValueError("need at least 3 pairs for a correlation")
    if np.ptp(x) == 0 or np.ptp(y) == 0:
        raise ValueError(f"{x_name if np.ptp(x) == 0 else y_name} is constant: no correlation")
    fit = stats.linregress(x, y)
    return Correlation(x_name, y_name, with_reference, len(x), float(fit.rvalue), float(fit.rvalue**2),
                       float(fit.pvalue), float(fit.slope), float(fit.intercept))


def campaign_correlations(campaign, model: str = "initial") -> list[Correlation]:
    """Diameter error and form error [mm] of ``model`` against each force value [N] of a
    :class:`~correction.models.RingCampaign`, without and with the (0 N, 0 mm) point."""
    out = []
    for what in ("diameter_error", "form_error"):
        y = campaign.column(model, what) * 1e3
        for fv in FORCE_VALUES:
            x = campaign.force_values(fv)
            for ref in (False, True):
                out.append(correlate(x, y, ref, f"{fv}_force_N", f"{what}_mm"))
    return out
