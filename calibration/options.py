"""``FitOptions``: every option of :func:`calibration.calibrate.calibrate` in one frozen, validated object.

A variant of a fit (a refit with other weights, the evidence's fits at each prior scale, a fit with one
parameter held) is ``dataclasses.replace(options, ...)``, never a call with re-spelt keywords.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .data import Weights
from .identifiability import DEFAULT_RANK_TOL
from .prior import PRIOR_GROUPS

__all__ = ["FitOptions", "UNIDENTIFIABLE", "COVARIANCE", "REFERENCE", "ARM_SCALE", "PRIOR_FACTOR_LIMITS",
           "PRIOR_LENGTH_RANGE"]

#: what :func:`~calibration.calibrate.calibrate` does with parameters the data cannot identify
UNIDENTIFIABLE = ("fix", "stop")
#: how the covariance is scaled
COVARIANCE = ("residual", "stated")
#: how reference coordinates enter the fit
REFERENCE = ("fit", "identity", "off")
#: FitOptions.arm_scale choices
ARM_SCALE = ("prior", "data")

#: standardized residual [robust standard deviations] from which a point is a gross error, left out by default:
#: above Baarda's data-snooping critical value of a Gaussian campaign of up to 10^5 rows at a family-wise level
#: of 0.001 (Bonferroni: 4.3 for 66 rows, 5.7 for 10^5), with a margin for the heavier tails an effect the
#: model lacks gives real residuals. A point's rows are tested together (their group-deletion residual's
#: chi-square, :func:`calibration.calibrate.point_tests`) at the false-alarm rate this value has row by row:
#: one row exactly at 6, three rows at chi-square 41.2 (docs/studies/calibration.md, Gross errors)
GROSS_THRESHOLD = 6.0


#: the prior scale factors a fit takes: beyond, the prior's weights overflow (a factor of 1e-300 made the normal
#: matrix "exactly singular", 5e-324 stalled the fit on NaN, 1e300 overflowed the prior ratios); the command line's
#: --prior-scale takes the narrower range of sensible factors (:data:`calibration.cli.PRIOR_FACTOR_RANGE`)
PRIOR_FACTOR_LIMITS = (1e-12, 1e12)
#: the range of the plausible size of a length error [m] (``--plausible-length-mm`` 1e-6 to 1e6)
PRIOR_LENGTH_RANGE = (1e-9, 1e3)


def _positive(name: str, v: object, allow_none: bool = False) -> None:
    if v is None and allow_none:
        return
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v) \
            or v <= 0:
        raise ValueError(f"{name} must be a positive finite number{' or None' if allow_none else ''}, got {v!r}")


def _in_range(name: str, v: object, low: float, high: float) -> None:
    """``v`` a finite number in [low, high] (as the command line's option of the same meaning takes it)."""
    _positive(name, v)
    if not low <= v <= high:  # type: ignore[operator]
        raise ValueError(f"{name} must be in [{low:g}, {high:g}], got {v!r}")


def _finite_values(name: str, v: dict[str, Any], positive: bool = False) -> dict[str, float]:
    """A {name: number} mapping with finite values (and > 0 for ``positive``), by str names, as floats."""
    out = {}
    for k, x in dict(v).items():
        try:
            f = float(x) if not isinstance(x, (bool, str, bytes)) and np.ndim(x) == 0 else math.nan
        except (TypeError, ValueError):
            f = math.nan
        if not math.isfinite(f) or (positive and f <= 0):
            raise ValueError(f"{name}[{k!r}] must be a {'positive ' if positive else ''}finite number, got {x!r}")
        out[str(k)] = f
    return out


def _flag(name: str, v: object) -> None:
    if not isinstance(v, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {v!r}")


def _choice(name: str, v: object, choices: tuple[str, ...]) -> None:
    if v not in choices:
        raise ValueError(f"{name} must be one of {', '.join(repr(c) for c in choices)}, got {v!r}")


@dataclass(frozen=True)
class FitOptions:
    """How :func:`~calibration.calibrate.calibrate` fits (all SI).

    Attributes:
        free: parameter names or glob patterns to identify (``("j*.d", "probe.*")``); None:
            :func:`~calibration.calibrate.default_free`.
        values: values [SI] of the parameters that are not free, by name (default 0).
        start: starting values [SI] of free parameters, by name (default their ``values`` or 0).
        weights: standard uncertainties of the residuals (:class:`~calibration.data.Weights`).
        on_unidentifiable: "fix" (hold and list the parameters the data cannot identify) or "stop" (raise
            with the list).
        rank_tol: relative singular value below which a direction is not identifiable.
        outlier_threshold: standardized residual beyond which a point is an outlier.
        drop_outliers: drop the points and certified lengths whose gross-error test (``gross_threshold``'s) reaches
            ``outlier_threshold`` and refit, in rounds (the worst first) until none is left.
        gross_threshold: without ``drop_outliers``, the standardized residual from which a point or a certified
            length (a point's rows tested together by their deletion residual, as the standardized residual of the
            same false-alarm rate; beyond ``outlier_threshold`` too: a gross error is an outlier) is a gross error,
            left out and the fit redone (one at a time, the largest first, at most 5 % of the points); None keeps
            every point.
        outlier_lengths: False: ``drop_outliers`` and the gross errors (``gross_threshold``) leave certified lengths
            in (only points are left out): the closed loop's, whose base model may lack the very effect a length
            measures (thermal growth, a scale error).
        outlier_limit: with ``drop_outliers``, at most this many points are dropped; past it (or after the last
            round) the misfit is the model's, not gross errors: the rest is kept and said (``gross_kept``) instead
            of a numerical failure. None (default): drop until none is left (``gross_threshold``'s: 5 % of the
            points). The closed loop sets it (5 % of its campaign's points: an effect its base model lacks makes
            its largest errors look like outliers).
        covariance: "residual" (scaled by the residual variance factor) or "stated".
        reference: "fit" (``T_ref_base`` unknown), "identity" (reference coordinates are base
            coordinates) or "off" (reference columns ignored).
        max_iter: iterations of each Levenberg-Marquardt solve.
        min_resolution: without a prior, hold parameters the data would resolve only to worse than this
            fraction of a plausible error size (the practical-resolution rule); None (default) keeps every
            linearly independent parameter.
        priors: plausible error sizes [SI] by parameter name or glob pattern (overrides).
        prior_length: plausible size [m] of a length error (angles: 10 rad/m times it).
        weights_from_data: estimate the noise of each row group from the fit (variance components) and
            refit until the factors settle.
        prior_scale: "evidence" (default: a Gaussian prior on every free parameter, one scale a parameter
            group chosen by the evidence, :mod:`calibration.prior`), a positive factor (every group's
            scale), a dict {group: scale} (e.g. the ``prior_scales`` of an earlier fit), or None (no prior).
        prior_groups: with the evidence's scales, "separate" (each group its own scale) or "pooled" (the
            geometric groups, lengths, joint offsets, axis angles and the tip offset, one scale by one fixed point;
            :func:`calibration.prior.update_scales`).
        prior_centre: the prior's centre (full parameter vector [SI]); None: ``values``.
        blas: BLAS threads during the fit (None: unchanged).
        discrepancy: estimate the model discrepancy (:mod:`calibration.discrepancy`); False leaves the result's
            ``discrepancy`` None (a fit that only predicts held-out data, as a cross-validation fold's).
        arm_scale: "prior" (default): the lengths' prior shrinks the arm's uniform scale with the other length
            errors; "data": a flat prior on it (the prior's centre the description scaled by the factor the data give,
            :func:`calibration.prior.scale_step`), where the data set it to within
            :data:`calibration.prior.MAX_SCALE_U` (a certified length does), with a prior only. Not the default:
            measured in docs/studies/calibration.md ("The arm's scale left to the data"), it lowers the real Panda
            seats' held-out distance error but takes up the signature of effects the model lacks on simulated robots.
        region_effect: also estimate the parameters' random effect between regions of the joint space
            (:mod:`calibration.region`) and add it to the covariance file; off by default (measured on the real and
            simulated seat robots with calibrate and close-loop in docs/studies/calibration.md: it does not reach the
            worst real pair and widens pairs covered already).
    """
    free: tuple[str, ...] | None = None
    values: dict[str, float] | None = None
    start: dict[str, float] | None = None
    weights: Weights = field(default_factory=Weights)
    on_unidentifiable: str = "fix"
    rank_tol: float = DEFAULT_RANK_TOL
    outlier_threshold: float = 4.0
    drop_outliers: bool = False
    gross_threshold: float | None = GROSS_THRESHOLD
    outlier_lengths: bool = True
    outlier_limit: int | None = None
    covariance: str = "residual"
    reference: str = "fit"
    max_iter: int = 200
    min_resolution: float | None = None
    priors: dict[str, float] | None = None
    prior_length: float | None = None
    weights_from_data: bool = False
    prior_scale: float | str | dict[str, float] | None = "evidence"
    prior_groups: str = "separate"
    prior_centre: np.ndarray | None = field(default=None, compare=False)
    blas: int | None = 1
    discrepancy: bool = True
    region_effect: bool = False
    arm_scale: str = "prior"

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        if self.free is not None:
            if isinstance(self.free, str):
                raise ValueError(f"free must be a sequence of names or patterns, got the string {self.free!r}")
            bad = next((n for n in self.free if not isinstance(n, str) or not n.strip()), None)
            if bad is not None or not isinstance(self.free, (tuple, list)):
                raise ValueError(f"free must be a sequence of parameter names or patterns (non-empty str), got "
                                 f"{bad if bad is not None else self.free!r}")
            set_(self, "free", tuple(self.free))
        for name in ("values", "start", "priors"):
            v = getattr(self, name)
            if v is not None:
                set_(self, name, _finite_values(name, v, positive=name == "priors"))
        if self.weights is None:
            set_(self, "weights", Weights())
        elif not isinstance(self.weights, Weights):
            raise ValueError(f"weights must be a calibration.Weights, got {type(self.weights).__name__}")
        _choice("on_unidentifiable", self.on_unidentifiable, UNIDENTIFIABLE)
        _choice("covariance", self.covariance, COVARIANCE)
        _choice("reference", self.reference, REFERENCE)
        _choice("arm_scale", self.arm_scale, ARM_SCALE)
        _choice("prior_groups", self.prior_groups, PRIOR_GROUPS)
        _positive("rank_tol", self.rank_tol)
        if not self.rank_tol < 1:
            raise ValueError(f"rank_tol must be below 1, got {self.rank_tol!r}")
        _positive("outlier_threshold", self.outlier_threshold)
        _positive("gross_threshold", self.gross_threshold, allow_none=True)
        if isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer)) or self.max_iter < 1:
            raise ValueError(f"max_iter must be a positive integer, got {self.max_iter!r}")
        _positive("min_resolution", self.min_resolution, allow_none=True)
        if self.prior_length is not None:
            _in_range("prior_length", self.prior_length, *PRIOR_LENGTH_RANGE)
        _flag("drop_outliers", self.drop_outliers)
        _flag("outlier_lengths", self.outlier_lengths)
        if self.outlier_limit is not None and (isinstance(self.outlier_limit, bool) or not isinstance(
                self.outlier_limit, (int, np.integer)) or self.outlier_limit < 0):
            raise ValueError(f"outlier_limit must be a non-negative integer or None, got {self.outlier_limit!r}")
        _flag("weights_from_data", self.weights_from_data)
        if isinstance(self.prior_scale, dict):
            for g, v in self.prior_scale.items():
                _in_range(f"prior_scale[{g!r}]", v, *PRIOR_FACTOR_LIMITS)
            set_(self, "prior_scale", {str(g): float(v) for g, v in self.prior_scale.items()})
        elif self.prior_scale is not None and self.prior_scale != "evidence":
            _in_range("prior_scale", self.prior_scale, *PRIOR_FACTOR_LIMITS)
        if self.prior_centre is not None:
            set_(self, "prior_centre", np.array(self.prior_centre, dtype=float))
            if not np.isfinite(self.prior_centre).all():
                raise ValueError("prior_centre must be finite")
        if self.blas is not None and (isinstance(self.blas, bool) or not isinstance(self.blas, (int, np.integer))
                                      or self.blas < 1):
            raise ValueError(f"blas must be a positive integer or None, got {self.blas!r}")
