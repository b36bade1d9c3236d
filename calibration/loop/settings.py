"""The options of the closed loop (:class:`LoopSettings`) and the constants its decisions use."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..identifiability import DEFAULT_RANK_TOL
from ..prior import PRIOR_GROUPS

__all__ = ["LoopSettings", "wilcoxon_units_needed", "STABILITY_RULE", "STABLE_MARGIN", "SAME_SIGNATURE", "PHYSICS",
           "PARSIMONY", "NOISE_OFF", "FOLD_BY", "POSE_FOLDS", "LEGACY_RESOLUTION", "MAX_COUNT"]

#: the practical-resolution rule the loop's fits without a prior keep (calibrate's default before its prior)
LEGACY_RESOLUTION = 0.1
#: share of a candidate's signature inside another's above which the data cannot tell them apart
SAME_SIGNATURE = 0.99
#: the start of the reason of a candidate included as physics (:func:`calibration.loop.decide.physics_inclusion`)
PHYSICS = "included as physics"
#: held-out improvement (fraction) within which a smaller nested candidate is preferred
PARSIMONY = 0.01
#: the verdict says a default sigma (one the user did not state) was replaced by the noise estimated from the data
#: when they differ by more than this factor (every fit of the loop weighs the rows by the estimate, as calibrate's
#: default fit does; within the factor the default would have done as well)
NOISE_OFF = 2.0
#: how the decisions' folds are made: by whole measurement, by pose inside each feature, or the first
#: that can reach the significance level
FOLD_BY = ("auto", "measurement", "pose")
#: how folds by pose are made (:func:`calibration.diagnostics.pose_folds`): each instance's poses dealt in turn along
#: their main direction (every held-out pose between training ones: interpolative), or blocks of the joint space
#: (each fold predicted from poses away from it: extrapolative)
POSE_FOLDS = ("dealt", "blocked")
#: the most effects to add, candidates to cross-validate a stage or pairs to try (``max_effects``, ``cv_top``,
#: ``pairs``): more than any arm's library offers (every family of a J-joint chain: J^2 + 2 J + 10 candidates, 970 at
#: 30 joints); beyond it a count is a typo (``--cv-top 1e300`` was taken, and written to summary.json as a 301-digit
#: integer that JSON readers of other tools round)
MAX_COUNT = 1000


#: a candidate whose Wilcoxon p lies within this factor of its level (``level / STABLE_MARGIN <= p < level``) must
#: also be better in every fold; one far below its level passes on the pooled test (a true drift extrapolated into
#: one fold of a short campaign can make that fold worse while every other unit says it is there)
STABLE_MARGIN = 10.0

#: the stability rule of the held-out decisions (:func:`calibration.loop.crossval.cross_validate`), as the console,
#: report and summary.json state it
STABILITY_RULE = (f"every fold better near the level: a candidate whose one-sided Wilcoxon p over every held-out unit "
                  f"lies within a factor {STABLE_MARGIN:g} of its level must also lower the held-out RMS of each "
                  "fold's units (each fold's training fit predicting them) by at least --min-improvement, as it must "
                  "the pooled RMS, so that no verdict near the level rests on the units of a few folds; one further "
                  "below passes on the pooled test; computed from the held-out residuals at hand, no refit")


def wilcoxon_units_needed(alpha: float, tests: int) -> int:
    """Fewest paired units for which a one-sided Wilcoxon signed-rank test can reach ``p < alpha / tests``:
    its smallest p-value over n units is ``1 / 2^n`` (every difference positive)."""
    return int(math.floor(math.log2(tests / alpha))) + 1


@dataclass(frozen=True)
class LoopSettings:
    """Options of :func:`close_loop` (see its docstring). ``seed``: the seed of the bootstrap of the held-out
    figures' uncertainties only (the test set and the folds are functions of the data, drawn from no seed).
    ``test_in_model``: the final model is fitted on every point, design and test (default); False (``aacmm
    close-loop --holdout``), the outer test set's rows are kept out of it, as ``calibrate --holdout`` keeps its
    held-out measurements out of its model. ``prior_scale``: "auto" (default: the prior with the evidence's scales,
    "evidence", when the base model holds a joint compliance, whose prior is physical, else None: no prior, the
    practical-resolution rule), "evidence", a factor, or None. ``arm_scale``, ``prior_groups``: every fit's
    :attr:`calibration.options.FitOptions.arm_scale` and :attr:`~calibration.options.FitOptions.prior_groups`.
    ``escalate``: when the outer test set is worse than
    stated once the default families are exhausted (:func:`~calibration.loop.verdict.heldout_check`), the
    families off by default (:data:`~calibration.candidates.OPT_IN_FAMILIES`) not offered yet are offered, once,
    under the same rules (``aacmm close-loop`` turns it off when ``--candidates`` names the families).
    ``synthesise``: build effects from the residual's structure when the library is exhausted, with an outer test
    set of whole measurements only (:func:`~calibration.loop.verdict.builds_from_residual`). ``pairs``: when no single
    candidate is added at a stage, at most this many pairs of the candidates tested there are cross-validated as one
    candidate each (:mod:`calibration.loop.pairs`; 0: no pair step). ``region_effect``: the final model's fit also
    estimates the parameters' random effect between regions of the joint space (:mod:`calibration.region`), which the
    covariance file adds, as ``calibrate --region-effect`` does (the loop's decisions and folds never use it)."""
    folds: int = 4
    test_fraction: float = 0.25
    alpha: float = 0.01
    screen_alpha: float = 0.05
    min_improvement: float = 0.02
    max_effects: int = 4
    cv_top: int = 3
    seed: int = 0
    rank_tol: float = DEFAULT_RANK_TOL
    drop_outliers: bool = True
    holdout: tuple = ()
    fold_by: str = "auto"
    pose_folds: str = "dealt"
    weights_from_data: bool = True
    synthesise: bool = True
    physics: bool = True
    prior_scale: float | str | None = "auto"
    arm_scale: str = "prior"
    prior_groups: str = "separate"
    test_in_model: bool = True
    escalate: bool = True
    pairs: int = 2
    region_effect: bool = False

    def __post_init__(self):
        object.__setattr__(self, "holdout", tuple(self.holdout or ()))
        if self.fold_by not in FOLD_BY:
            raise ValueError(f"fold_by must be one of {', '.join(FOLD_BY)}, got {self.fold_by!r}")
        if self.pose_folds not in POSE_FOLDS:
            raise ValueError(f"pose_folds must be one of {', '.join(POSE_FOLDS)}, got {self.pose_folds!r}")
        if self.prior_groups not in PRIOR_GROUPS:
            raise ValueError(f"prior_groups must be one of {', '.join(PRIOR_GROUPS)}, got {self.prior_groups!r}")
        if self.folds < 2:
            raise ValueError(f"folds must be at least 2, got {self.folds}")
        if not 0.0 < self.test_fraction < 1.0:
            raise ValueError(f"test_fraction must be in (0, 1), got {self.test_fraction}")
        for name in ("alpha", "screen_alpha"):
            v = getattr(self, name)
            if not 0.0 < v < 1.0:
                raise ValueError(f"{name} must be in (0, 1), got {v}")
        if not (self.prior_scale in (None, "auto", "evidence") or isinstance(self.prior_scale, (int, float))
                and not isinstance(self.prior_scale, bool) and 0 < self.prior_scale < math.inf):
            raise ValueError(f"prior_scale must be 'auto', 'evidence', a positive factor or None, got "
                             f"{self.prior_scale!r}")
        if self.min_improvement < 0 or self.max_effects < 0 or self.cv_top < 1 or self.pairs < 0:
            raise ValueError("min_improvement, max_effects and pairs must be >= 0 and cv_top >= 1")
        for name in ("max_effects", "cv_top", "pairs"):
            if getattr(self, name) > MAX_COUNT:
                raise ValueError(f"{name} must be at most {MAX_COUNT}, got {getattr(self, name)}")

    def to_dict(self) -> dict:
        return dict(self.__dict__)

