"""Close the loop: calibrate, find the residual's structure, add the effect it points to, repeat.

:func:`close_loop` runs, on points and artefacts of any campaign:

1. An outer **test set** is put aside: the measurements ``holdout`` or a share ``test_fraction`` of them
   (seeded, stratified by feature kind), or, with too few measurements, that share of every feature's
   poses (each predicted against its feature's centre fitted on the design poses). It takes part in no
   decision and gives the before/after figures of the report.
2. The base model is calibrated on the rest (the **design set**).
3. **Screening** (:func:`calibration.diagnostics.screen_candidates`): the score test of every candidate
   effect at the current fit. It only filters: candidates whose p-value is below
   ``screen_alpha / (number of identifiable candidates)`` (Bonferroni), at most ``cv_top`` of them, go on.
4. **Decision on held-out data**: K-fold cross-validation on the design set, by measurement or, when the
   measurements are too few for the test to reach its level (``fold_by="auto"``), by pose inside each
   feature. In each fold the current model and the model plus the candidate are calibrated on the other
   folds and predict the fold's units: whole measurements, whose nuisance unknowns (centres, axes, planes,
   ``T_ref_base``) are solved on the held-out points only, or poses, predicted against their feature's
   centre fitted on its other poses. Whether the test can reach its level (smallest p over n units is
   1/2^n) is reported before it runs. Per held-out unit, the mean squared weighted residual of the two
   models is compared by a one-sided Wilcoxon signed-rank test; a candidate passes with ``p < alpha / (number of
   candidates tested)`` and a relative drop of the pooled held-out RMS of at least ``min_improvement``.
   The passing candidate with the largest drop is added; ties in signature are reported (``nested``,
   ``alternatives``: candidates the data cannot tell from it).
5. Recalibrate on the design set with the new effect; repeat from 3 until no candidate passes, none is
   left, or ``max_effects`` were added.
   **Beyond the library**: when no candidate passes at a stage, the generic structure families still
   significant at the current fit (the forward selection of step 6) become candidate effects
   (:mod:`calibration.synthesis`: a joint's harmonics of order k = 1..4, per-link and probe thermal growth,
   a full probe compliance matrix, an approach-direction offset, a joint's lateral compliance), screened
   and cross-validated in steps 3-4 exactly like the library's, against a Bonferroni level over every
   candidate then offered (screening) and every candidate held-out tested at the stage (Wilcoxon): the
   candidates that already failed the held-out test at this stage are not tested again, so the built
   effects reach it even when failed library candidates rank above them. One that passes is added and reported as found
   from the residual; one that does not is reported with its held-out evidence and not added.
6. The generic structure tests (:func:`calibration.diagnostics.structure_tests`) on the final fit, and a
   forward selection among them (:func:`calibration.diagnostics.remaining_structure`): a family
   significant after Bonferroni's correction (``alpha``), given the families kept before it, with a
   positive held-out explained variance means that **structured residual remains**; the verdict names
   its regressors and claims no fix.

The package: :mod:`~calibration.loop.settings` (:class:`LoopSettings`), :mod:`~calibration.loop.state` (the one
:class:`~calibration.loop.state.LoopState` every stage reads and writes), :mod:`~calibration.loop.stages` (the
named stages: prepare, screen, test, synthesise, add, report), :mod:`~calibration.loop.decide` (the held-out
test of a candidate and the rules that choose the effect to add), :mod:`~calibration.loop.folds`,
:mod:`~calibration.loop.crossval`, :mod:`~calibration.loop.heldout`, :mod:`~calibration.loop.outliers`,
:mod:`~calibration.loop.result` and :mod:`~calibration.loop.verdict`.
"""
from __future__ import annotations

from arm_model.description import ArmDescription
from arm_model.io import Artefacts, PointSet
from arm_model.log import progress_line

from ..data import Weights
from .crossval import CVResult, cross_validate
from .decide import resolved
from .heldout import bootstrap_rows, heldout_figures, heldout_residuals
from .outliers import flag_test_outliers
from .result import LoopResult, Stage, display, effect_summary
from .settings import LEGACY_RESOLUTION, PHYSICS, LoopSettings, wilcoxon_units_needed
from .stages import Campaign, prepare, report, run
from .state import log
from .verdict import verdict_text

__all__ = ["LoopSettings", "CVResult", "Stage", "LoopResult", "close_loop", "heldout_residuals",
           "heldout_figures", "cross_validate", "display", "effect_summary", "wilcoxon_units_needed", "PHYSICS",
           "bootstrap_rows", "flag_test_outliers", "resolved", "verdict_text", "LEGACY_RESOLUTION"]


def close_loop(points: PointSet, artefacts: Artefacts, desc: ArmDescription, *, reference: PointSet | None = None,
               effects=(), values: dict | None = None, free=None, hold=None, weights: Weights | None = None,
               settings: LoopSettings | None = None, families_: tuple | None = None, extra=(), progress=None,
               **kw) -> LoopResult:
    """Calibrate, diagnose, add the best-supported effect, recalibrate ... until nothing passes.

    Args:
        points, artefacts: the campaign (``arm_model.read_points`` / ``read_artefacts``).
        desc: the arm description (nominal).
        reference: a second points file with reference (tracker) coordinates.
        effects: effects already in the base model (not candidates).
        values: starting values [SI] of parameters by name (e.g. the effect parameters of a model file);
            parameters held fixed keep them.
        free: parameters to calibrate (names or globs, as ``aacmm calibrate --free``; default
            ``calibration.calibrate.default_free``: every joint-row error, the probe offset and the parameters of
            ``effects``); the parameters of every effect the loop adds are free as well.
        hold: parameters to hold at ``values`` (names or globs), removed from the free set.
        weights: standard uncertainties of the residuals.
        settings: :class:`LoopSettings`; keyword arguments (``folds=5`` ...) override its fields.
        families_: candidate families to offer (default :data:`calibration.candidates.DEFAULT_FAMILIES`: every
            family of :data:`~calibration.candidates.FAMILIES` but ``joint_gain``).
        extra: user candidates (:class:`calibration.candidates.Candidate`).
        progress: ``callable(str)`` for progress lines.

    Raises:
        NumericalError: the base model cannot be calibrated on the design set or a training fold.
    """
    from arm_model.parallel import blas_threads

    settings = settings or LoopSettings()
    if kw:
        settings = LoopSettings(**{**settings.to_dict(), **kw})
    camp = Campaign(points, artefacts, desc, reference, tuple(effects), values, _patterns(free), _patterns(hold) or (),
                    weights, families_, tuple(extra))
    # many small dense solves: threaded BLAS only adds contention (8x slower on a loaded 2-core machine)
    with blas_threads(1):
        state = prepare(camp, settings, progress or progress_line(log))
        run(state)
        return report(state)


def _patterns(names) -> tuple | None:
    """Names or globs as a tuple (one string is one pattern); None stays None."""
    if names is None:
        return None
    return (names,) if isinstance(names, str) else tuple(names)
