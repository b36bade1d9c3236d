"""The one explicit state the stages of the loop read and write (:class:`LoopState`), and the fit every stage
calls through it (:meth:`LoopState.fit`)."""
from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from arm_model.description import ArmDescription
from arm_model.model import ArmModel

from ..calibrate import CalibrationResult, calibrate, default_free, resolve_parameters
from ..candidates import Candidate
from ..data import CalibrationData, Weights, concat
from ..diagnostics import GroupTest, ResidualSpace
from ..model_output import at_equilibrium
from ..options import GROSS_THRESHOLD, FitOptions
from .crossval import CVResult, FoldFit
from .folds import Folds
from .heldout import heldout_figures
from .outliers import outlier_budget
from .settings import LoopSettings

__all__ = ["LoopState", "Screening", "fitted_names"]

#: the loop's logger (progress lines, and the warning that the held-out test cannot reach its level)
log = logging.getLogger("calibration.loop")


def fitted_names(model: ArmModel, free, hold, base_size: int, held=(), data: CalibrationData | None = None
                 ) -> list[str] | None:
    """The parameters of ``model`` a loop fit frees, as ``aacmm calibrate --free/--hold`` would, plus the
    parameters of every effect the loop added (those after the base model's ``base_size``): ``free`` patterns
    (None: :func:`~calibration.calibrate.default_free` on ``data``) less the ``hold`` patterns and the names
    ``held``. None: calibrate's default set unchanged."""
    names = None
    if free is not None:
        names = [model.spec.names[i] for i in resolve_parameters(model.spec, free)]
        names += [n for n in model.spec.names[base_size:] if n not in names]
    out = set(held)
    if hold:
        out |= {model.spec.names[i] for i in resolve_parameters(model.spec, hold)}
    if out:
        names = [n for n in (names or default_free(model, data)) if n not in out]
    return names


@dataclass
class LoopState:
    """Everything the loop knows between its stages; each stage (:mod:`calibration.loop.stages`) takes it and
    updates it, none keeps anything of its own.

    Fixed once the data are split (:func:`~calibration.loop.stages.prepare`):
        settings, desc, say: the options, the nominal arm, the progress printer.
        data: every point; design, test: the design set and the outer test set (outliers dropped);
        test_by: the test set holds whole "measurement"s or the "pose"s of every feature; test_rows: the rows
            of ``data`` in the outer test set (outliers included).
        options: the fit's options common to every fit of the loop (values, prior scale ...);
        free, hold: the user's patterns of the parameters to free (None:
            :func:`~calibration.calibrate.default_free`) and to hold; base_size: the size of the base model's
            parameter vector (the parameters after it are those of the effects the loop added).
        stated: the user's stated uncertainties; candidates, skipped: the library's candidate set.
        folds, power: the folds of the decisions and whether their test can reach its level.
        dropped: outlier points left out ("design"; the test set's are never left out).
        flagged: (len(test),) bool, the test points the base model's point test flags (kept in every figure;
            also left out in the figures labelled so); flagged_entries: their descriptions.

    Changed by the stages:
        weights: the uncertainties every fit starts from: the noise estimated from the data by the current model's
            fit on the design set (the stated ones with ``settings.weights_from_data`` False).
        priors: plausible sizes of the added effects' parameters (at least ten times their screening estimate).
        model, result: the current model and its fit on the design set; stages: one per model.
        remaining: the candidates not added; synthesised: every candidate built from the residual;
        fate: why each built candidate was (not) added.
        base_folds: the current model's fold fits (None: not computed at the current weights).
        cv_here: held-out tests run at the current stage (its candidates are not tested again there).
        last_tests, last_cv: the last screening and held-out tests; stop: why the loop stopped.
        vetoed: candidates that passed the held-out folds but would have made the outer test set worse (not
            added; the loop stops there).
        families: the candidate families of the first pass (None: the library's defaults); escalated: the opt-in
            families offered when the outer test set was worse than stated (``families``, ``candidates``, the
            judgement ``check`` that led to it), None if not.
    """
    settings: LoopSettings
    desc: ArmDescription
    say: Callable[[str], None]
    data: CalibrationData
    design: CalibrationData
    test: CalibrationData
    test_by: str
    test_rows: np.ndarray
    options: FitOptions
    free: tuple | None
    hold: tuple
    base_size: int
    stated: Weights
    candidates: list
    skipped: list
    model: ArmModel
    weights: Weights
    folds: Folds | None = None
    power: dict = field(default_factory=dict)
    dropped: dict = field(default_factory=lambda: {"design": []})
    flagged: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    flagged_entries: list = field(default_factory=list)
    priors: dict = field(default_factory=dict)
    result: CalibrationResult | None = None
    stages: list = field(default_factory=list)
    remaining: list = field(default_factory=list)
    synthesised: list[Candidate] = field(default_factory=list)
    fate: dict = field(default_factory=dict)
    base_folds: FoldFit | None = None
    cv_here: list[CVResult] = field(default_factory=list)
    last_tests: list = field(default_factory=list)
    last_cv: list = field(default_factory=list)
    stop: str = ""
    vetoed: list = field(default_factory=list)
    families: tuple | None = None
    escalated: dict | None = None

    def fit(self, model: ArmModel, data: CalibrationData, extra_priors: dict | None = None, reweight: bool = False,
            hold: tuple = (), weights: Weights | None = None, discrepancy: bool = True,
            start: dict | None = None, gross: bool = False, region: bool = False) -> CalibrationResult:
        """``calibrate`` of ``model`` on ``data`` with the loop's options, the current ``weights`` (or those
        given) and ``priors`` (and ``extra_priors``): the parameters ``free`` and those of every effect the loop
        added, less the user's ``hold`` and the names ``hold``; the noise re-estimated from the data only with
        ``reweight``; ``discrepancy`` False: no model discrepancy (a fold's fit, which only predicts its held-out
        units); ``start``: starting values of free parameters by name (a warm start; the prior's centre and the
        held parameters' values stay the given ones); ``gross``: calibrate's default gross-error rule
        (:data:`~calibration.options.GROSS_THRESHOLD`; points only, at most the loop's budget): the base fit's,
        :func:`~calibration.loop.outliers.drop_design_outliers` (every other fit keeps every point); ``region``: the
        parameters' random effect between regions of the joint space too
        (:mod:`calibration.region`; the final model's)."""
        names = fitted_names(model, self.free, self.hold, self.base_size, hold, data)
        # the added effects' plausible sizes serve the practical-resolution rule without a prior; with one,
        # the prior's own sizes (calibration.prior.prior_spec) and the evidence's scales apply
        priors = {**self.priors, **(extra_priors or {})} if self.options.prior_scale is None else None
        return calibrate(model, data, replace(
            self.options, free=names, weights=self.weights if weights is None else weights, priors=priors, start=start,
            weights_from_data=reweight and self.settings.weights_from_data, discrepancy=discrepancy,
            gross_threshold=GROSS_THRESHOLD if gross else None, outlier_lengths=False,
            outlier_limit=outlier_budget(len(self.data)) if gross else None, region_effect=region))

    def tested_here(self, scr: Screening) -> list[CVResult]:
        """The held-out tests run at the current stage: its earlier passes' (``cv_here``), then those of the pass
        ``scr`` not among them, in order (the physics and pair steps' "tested at this stage", before their own
        tests and after)."""
        return self.cv_here + [cv for cv in scr.cvs if cv not in self.cv_here]

    def test_figures(self, model: ArmModel, result: CalibrationResult, weights: Weights | None = None) -> dict:
        """Figures of ``(model, result.p)`` on the outer test set (:func:`~calibration.loop.heldout.heldout_figures`),
        each a prediction as ``calibrate``'s held-out figures are: the test measurements' own centres solved on
        them, the instrument's frames and marker offsets those of the design fit (``result.tracker``; a session
        the design set lacks solved on the test points), or each test pose against its feature's design poses;
        every test point in them (without those the point test flags, ``flagged``, also: ``unflagged``, and
        ``rms_um_unflagged``, ``max_um_unflagged``; their nuisance solved without them), weighted
        by ``weights`` (default the current ones); the bootstrap of their uncertainties seeded by
        ``settings.seed``. A model with joint torques takes them at its own static equilibrium, as ``aacmm tip``
        applies its model file (:func:`calibration.model_output.at_equilibrium`; with the torques of the base
        fit's equilibrium, a simulated UR5 with a hidden shoulder gain showed 299 -> 180 um where the model files
        give 425 -> 303 um, scripts/robot_hidden_study.py). The variance the fit's parameter covariance adds to the
        held-out rows (``propagated``) is computed for a test set of whole measurements."""
        seed, weights = self.settings.seed, self.weights if weights is None else weights
        p, reference, cov = result.p, result.reference_mode, (result.free, result.cov)

        def figures(test):
            if self.test_by == "measurement":
                return heldout_figures(model, p, at_equilibrium(model, p, test), weights, reference, seed=seed,
                                       stated=self.stated, cov=cov, tracker=result.tracker)
            n = len(self.design)
            return heldout_figures(model, p, at_equilibrium(model, p, concat(self.design, test)), weights, reference,
                                   np.arange(n + len(test)) < n, seed, self.stated)
        out = figures(self.test)
        out["flagged_points"] = int(self.flagged.sum())
        out["unflagged"] = (figures(self.test.select(~self.flagged)) if self.flagged.any() and not self.flagged.all()
                            else None)
        for k in ("rms_um", "max_um"):
            out[f"{k}_unflagged"] = None if out["unflagged"] is None else out["unflagged"][k]
        return out


@dataclass
class Screening:
    """One pass of a stage: the score tests of the candidates then remaining at the current fit, and the
    held-out tests run on those that passed the screening.

    Attributes:
        candidates: the candidates screened (``LoopState.remaining`` then); tests: the score test of each.
        space: the residual space of the screening (its first batch), for the signature overlaps.
        ranked: ``(candidate, test)`` by p-value; gate: the screening's Bonferroni level.
        gated: ``(candidate, test)`` to cross-validate (the best ``cv_top`` below the gate not tested at this
            stage yet); cvs: their held-out tests (and those the decision adds), in the same order.
        threshold: the Wilcoxon level of this pass (``alpha`` over every candidate tested at the stage).
    """
    candidates: list
    tests: list[GroupTest]
    space: ResidualSpace
    ranked: list
    gate: float
    gated: list
    cvs: list[CVResult] = field(default_factory=list)
    threshold: float = float("nan")

    def test_of(self, cand) -> GroupTest:
        """The score test of a screened candidate."""
        return self.tests[self.candidates.index(cand)]

    def cv_of(self, cand) -> CVResult | None:
        """The held-out test of a gated candidate, None if it has none."""
        # cvs may be shorter (tests still running) or longer (the decision's tests follow the gated ones)
        return next((v for (c, _), v in zip(self.gated, self.cvs, strict=False) if c is cand), None)

