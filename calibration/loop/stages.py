"""The stages of the closed loop, each a function of the one :class:`~calibration.loop.state.LoopState`:

* :func:`prepare`: the data, the outer test set, the base fit on the design set, outliers, the noise, the
  folds of the decisions;
* one stage per effect added (:func:`run_stage`), in at most two passes (the library's candidates, then,
  if nothing passes, those built from the residual as well):

  - :func:`screen`: the score test of every remaining candidate at the current fit, the gate;
  - :func:`test`: the held-out test of the gated candidates;
  - :func:`synthesise`: effects built from the structure still in the residual, offered as candidates;
  - :func:`physics`: joint compliance as physics, when nothing passed (library or built from the residual);
  - :func:`pairs`: two of the candidates tested at the stage together, when nothing else was added
    (:mod:`calibration.loop.pairs`);
  - :func:`~calibration.loop.decide.choose`: the one candidate to add;
  - :func:`add`: the model with it, recalibrated on the design set;

* :func:`report`: the structure tests on the final fit, the verdict, the final model on every point.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from arm_model import NumericalError
from arm_model.description import ArmDescription
from arm_model.effects import JointCompliance, JointHysteresis, ThermalGrowth
from arm_model.io import Artefacts, PointSet
from arm_model.log import counted
from arm_model.model import ArmModel

from ..calibrate import CalibrationResult
from ..candidates import DEFAULT_FAMILIES, OPT_IN_FAMILIES, drift_offer, library_candidates, needs_model
from ..data import Weights, make_data
from ..diagnostics import (
    binned_estimates,
    candidate_family,
    families,
    holm,
    remaining_structure,
    residual_space,
    screen_candidates,
    structure_tests,
)
from ..model_output import refine_torques, with_fitted_torques
from ..options import GROSS_THRESHOLD, FitOptions
from ..synthesis import RESIDUAL, synthesise as build_effects
from .crossval import fold_fit, warm_start
from .decide import (
    Decision,
    candidate_priors,
    choose,
    heldout_test,
    physics_inclusion,
    plot_family,
)
from .folds import check_fold_by, choose_folds, outer_split
from .outliers import drop_design_outliers, flag_test_outliers, outlier_budget
from .pairs import beats_parts, candidate_pairs, pair_pool, rank_pairs
from .result import LoopResult, Stage
from .settings import LEGACY_RESOLUTION, LoopSettings
from .state import LoopState, Screening, log
from .verdict import ADDED, builds_from_residual, heldout_check, judged, residual_over_stated, verdict_text

__all__ = ["Campaign", "Stop", "prepare", "at_current_torques", "screen", "test", "physics", "pairs", "synthesise",
           "decide",
           "fit_stage", "escalate",
           "outer_test_worse", "add", "run_stage", "run", "report"]


@dataclass(frozen=True)
class Campaign:
    """What :func:`~calibration.loop.close_loop` is given: the points, artefacts and nominal arm, the reference
    points, the effects already in the base model, starting values, the base parameters to free (names or
    globs), the stated uncertainties, the candidate families and user candidates."""
    points: PointSet
    artefacts: Artefacts
    desc: ArmDescription
    reference: PointSet | None = None
    effects: tuple = ()
    values: dict | None = None
    free: tuple | None = None
    hold: tuple = ()
    weights: Weights | None = None
    families: tuple | None = None
    extra: tuple = ()


@dataclass(frozen=True)
class Stop:
    """Why a stage added nothing: the loop stops."""
    reason: str


def prepare(camp: Campaign, settings: LoopSettings, say) -> LoopState:
    """The data and their split, the base model calibrated on the design set (outliers dropped, the noise
    estimated), the test set's outliers, the folds of the decisions
    (and whether their test can reach its level), and the base stage."""
    points, desc = camp.points, camp.desc
    has_t = points.temperature is not None and np.all(np.isfinite(points.temperature))
    drift = drift_offer(desc, points)
    need = ([JointCompliance(), JointHysteresis()] + ([ThermalGrowth()] if has_t else []) + list(camp.effects)
            + [c.effect for c in camp.extra] + ([c.effect for c in drift] if isinstance(drift, list) else []))
    data = make_data(points, camp.artefacts, needs_model(desc, need), reference=camp.reference)
    cands, skipped = library_candidates(desc, data, camp.families, camp.extra)
    design, test, test_by, test_rows = outer_split(data, settings)
    check_fold_by(design, settings)             # before any fit
    _say_split(say, data, design, test, test_by, len(cands), settings)
    stated = camp.weights or Weights()
    model = ArmModel(desc, tuple(camp.effects))
    scale = _prior_scale(model, design, camp, stated, settings, say)
    # the loop drops its outliers itself, once, on the base model (``settings.drop_outliers``): every model it
    # compares is fitted on the same points (no gross errors left out fit by fit)
    options = FitOptions(values=camp.values, rank_tol=settings.rank_tol, prior_scale=scale,
                         arm_scale=settings.arm_scale, prior_groups=settings.prior_groups,
                         min_resolution=LEGACY_RESOLUTION if scale is None else None, gross_threshold=None)
    state = LoopState(settings, desc, say, data, design, test, test_by, test_rows, options, camp.free, camp.hold,
                      model.spec.size, stated, cands, skipped, model, stated, remaining=list(cands),
                      families=camp.families)
    say("calibrating the base model on the design set")
    # the base fit is calibrate's default fit of the design set: the noise estimated jointly with the prior's
    # scales in the evidence's rounds (from the stated sigmas), the gross points left out by calibrate's own rule
    # at the noise it estimates (points only, at most the loop's budget: step 2 of docs/close-loop.md), the torques
    # then refined as calibrate refines them (:func:`torques_at_equilibrium`)
    if settings.drop_outliers:
        result, state.design, state.dropped["design"] = drop_design_outliers(
            state.design, partial(state.fit, model, reweight=True))
        if state.dropped["design"]:
            say(f"  {len(state.dropped['design'])} outlier(s) of the design set dropped (base fit, calibrate's "
                f"gross-error test at {GROSS_THRESHOLD:g}); they stay out of every later fit")
        if result.gross_kept:
            say(f"  outliers of the design set kept: {result.gross_kept}")
    else:
        result = state.fit(model, state.design, reweight=True)
    # every decision and later fit weighs the rows by the noise this fit estimated (re-estimated at each model
    # added, fit_stage), as calibrate's default fit does: nothing is judged against the stated sigmas
    if settings.weights_from_data:
        state.weights = result.weights
        if _noise(result):
            say("  " + _noise(result)[2:] + " (the stated uncertainties are starting values)")
    result = torques_at_equilibrium(state, model, result)
    state.flagged = np.zeros(len(state.test), bool)
    if settings.drop_outliers:
        _flag_test(state, model, result)
    state.folds, state.power = choose_folds(state.design, settings)
    if state.power["note"].startswith("WARNING: "):        # shown with --quiet too
        log.warning(state.power["note"][len("WARNING: "):])
    else:
        say(state.power["note"])
    state.result = result
    state.stages = [Stage(0, model, result, heldout=state.test_figures(model, result))]
    say(f"  base model: s0 {result.s0:.3g}, held-out test RMS {state.stages[0].heldout['rms_um']:.2f} um")
    return state


def _flag_test(state: LoopState, model: ArmModel, result: CalibrationResult) -> None:
    """The test points the base model's point test flags (:func:`~calibration.loop.outliers.flag_test_outliers`):
    reported, never left out of a held-out figure (each figure is also given without them, labelled)."""
    say = state.say
    try:
        state.flagged, state.flagged_entries = flag_test_outliers(
            model, result.p, state.test, state.weights, result.reference_mode,
            None if state.test_by == "measurement" else state.design,
            max(0, outlier_budget(len(state.data)) - len(state.dropped["design"])))
    except NumericalError:        # e.g. two tracker poses: a frame and the markers' offsets undetermined
        say("  the test set alone does not determine its own unknowns (centres, frames, offsets) for the point "
            "test: its points are not tested for outliers")
    if state.flagged_entries:
        ids = ", ".join(dict.fromkeys(str(e["measurement"]) for e in state.flagged_entries))
        say(f"  {int(state.flagged.sum())} point(s) of the test set flagged by the point test (base model; {ids}): "
            "kept in every held-out figure, which is also given without them")


def torques_at_equilibrium(state: LoopState, model: ArmModel, result: CalibrationResult) -> CalibrationResult:
    """When the base model needs the joint torques (a joint compliance): the base fit refined as ``calibrate``
    refines its own (:func:`calibration.model_output.refine_torques`: its prior scales and weights kept, the torques
    on its calibrated description), and the torques of every row (design and test) taken at the static equilibrium
    of that fit, as the model file and ``calibrate``'s held-out figures take them
    (:func:`calibration.model_output.with_fitted_torques`); every later fit, fold and figure of the loop uses them.
    Without it they stay at the readings on the nominal description, a model error of about ``C dtau/dtheta``
    times the sag: on a simulated Panda whose shoulder sagged 20 mrad under its RMS gravity torque, the base
    model's held-out RMS in the loop's table was 169 um where ``tip`` gave 141 um with its model file, and the
    structure tests claimed joint 4's harmonics (scripts/robot_hidden_study.py, ``stiff2x``). Other models:
    ``result`` unchanged."""
    if not ({"tau_gravity", "tau_contact"} & model.needs()):
        return result
    result = refine_torques(result)
    state.data, state.design, state.test = (with_fitted_torques(d, result)
                                            for d in (state.data, state.design, state.test))
    return result


def _say_split(say, data, design, test, test_by: str, n_cands: int, settings: LoopSettings) -> None:
    if test_by == "measurement":
        say(f"{counted(len(data), 'point')}, {counted(len(data.measurements()), 'measurement')}: "
            f"{len(design.measurements())} for design, {len(test.measurements())} held out for the test "
            f"({', '.join(test.measurements())}); {counted(n_cands, 'candidate')}")
    else:
        say(f"{len(data)} points in {len(data.measurements())} measurement(s): too few to hold whole measurements "
            f"out, so the test set is {len(test)} poses ({100 * settings.test_fraction:g} % of each feature's), "
            f"each predicted against its feature's centre fitted on the design poses; {n_cands} candidates")


def _prior_scale(model: ArmModel, design, camp: Campaign, stated: Weights, settings: LoopSettings, say):
    """The prior scale of every fit: "evidence" (every fit chooses its groups' scales by its own evidence, as
    ``calibrate`` does, on the data it is given: a fold's training part chooses them without the fold), a
    factor, or None (no prior: the practical-resolution rule holds weak parameters). "auto": "evidence" when the
    base model holds a joint compliance, else None. A compliance needs its physical prior (non-negative, at most
    a plausible deflection under the data's torques): without it nothing bounds a compliance the data see
    weakly (on the real Panda seats, trained on one placement, joint 7's reached 1.75 rad/(N m), a model file
    ``tip`` refuses), and the evidence's scales for the geometry come with it (docs/close-loop.md)."""
    scale = settings.prior_scale
    if scale == "auto":
        scale = "evidence" if any(isinstance(e, JointCompliance) for e in model.effects) else None
    if scale == "evidence":
        say("estimation: a Gaussian prior on every free parameter, its groups' scales chosen by the evidence of "
            "each fit's own data (prior-dominated parameters are shrunk, not held; compliances >= 0)")
    return scale


def _noise(res: CalibrationResult) -> str:
    parts = [f"{v['group']} {v['sigma_um']:.3g} um" for v in res.variance
             if v["estimated"] and v["sigma_um"] is not None]
    return "; noise from the data: " + ", ".join(parts) if parts and res.weights_history else ""


def at_current_torques(result: CalibrationResult) -> CalibrationResult:
    """``result`` with its data's gravity and contact torques those of its own model at the static equilibrium
    its compliances give (:meth:`~arm_model.model.ArmModel.equilibrium_aux`, as the model file evaluates them),
    not the nominal description's at the readings the fits use (``calibration.data.make_data``; the final model
    is refined to them, :func:`calibration.model_output.refine_torques`): what the screening projects a
    candidate's torque columns on. Measured on the real Panda trained on back-high (44 points): the torques move
    by up to 0.51 N m (of 26.7), the equilibrium costs 0.024 s against 0.19 s for the screening, the candidates'
    score p-values move in their third digit."""
    d = result.data
    if d.aux is None or (d.aux.tau_gravity is None and d.aux.tau_contact is None):
        return result
    aux = result.model.equilibrium_aux(d.points.q, d.wrench, result.p, d.aux.temperature,
                                       contact=d.aux.tau_contact is not None, time=d.aux.time,
                                       motion=d.aux.motion, capture=d.aux.capture)
    return replace(result, data=replace(d, aux=aux))


def screen(state: LoopState) -> Screening:
    """The score test of every remaining candidate at the current fit; the gate is ``screen_alpha`` over the
    identifiable ones (Bonferroni) and the best ``cv_top`` below it, not yet tested at this stage, go on.
    Records why each candidate built from the residual is not (yet) added."""
    s = state.settings
    state.say(f"screening {len(state.remaining)} candidate(s) at stage {len(state.stages) - 1}")
    tests, space = screen_candidates(at_current_torques(state.result), state.remaining, state.folds.assign,
                                     s.rank_tol)
    ranked = sorted(zip(state.remaining, tests, strict=True),
                    key=lambda ct: (ct[1].p_value if np.isfinite(ct[1].p_value) else 2, -ct[1].delta_chi2))
    state.last_tests, state.last_cv = [t for _, t in ranked], list(state.cv_here)
    ident = [(c, t) for c, t in ranked if t.identifiable]
    gate = s.screen_alpha / max(len(ident), 1)
    tried = {cv.candidate for cv in state.cv_here}
    gated = [(c, t) for c, t in ident if t.p_value < gate and c.name not in tried][: s.cv_top]
    for c, t in ranked:               # why each effect built from the residual is not (yet) added
        if c.origin == RESIDUAL:
            state.fate[c.name] = ("absorbed by the fit (the data cannot tell it from what is fitted)"
                                  if not t.identifiable else
                                  f"not significant at the screening (score p = {t.p_value:.2g} >= {gate:.2g})"
                                  if not t.p_value < gate else
                                  f"significant at the screening but not among the --cv-top {s.cv_top} best")
    return Screening(list(state.remaining), tests, space, ranked, gate, gated)


def test(state: LoopState, scr: Screening) -> list:
    """The held-out test of every gated candidate (the current model's fold fits first, if not at hand), at
    ``alpha`` over every candidate tested at the stage. Returns the passing ``(candidate, CVResult)``."""
    s = state.settings
    _current_folds(state)
    scr.threshold = s.alpha / (len(state.cv_here) + len(scr.gated))
    for c, t in scr.gated:
        state.say(f"  cross-validating + {c.name} (score p = {t.p_value:.2g})")
        cv = heldout_test(state, scr, c)
        state.say(f"    {cv.reason}")
        scr.cvs.append(cv)
        if c.origin == RESIDUAL:
            state.fate[c.name] = cv.reason if not cv.passed else "passed, but another candidate was added"
    state.last_cv = state.cv_here + scr.cvs
    return [(c, cv) for (c, _), cv in zip(scr.gated, scr.cvs, strict=True) if cv.passed]


def _current_folds(state: LoopState) -> None:
    """The current model's fold fits, computed if not at hand (``state.base_folds``)."""
    if state.base_folds is None:
        state.say(f"  cross-validating the current model ({state.folds.k} folds by {state.folds.by})")
        state.base_folds = fold_fit(state.model, state.design, state.folds, state.fit, start=warm_start(state.result))


def physics(state: LoopState, scr: Screening) -> list:
    """Joint compliance as physics (:func:`~calibration.loop.decide.physics_inclusion`), weighed once a stage
    and only when no candidate passed the held-out test, neither the library's nor those built from the
    residual: a compliance would otherwise absorb part of the signature of an effect the library lacks.
    Returns ``[(candidate, CVResult)]`` or ``[]``."""
    _current_folds(state)
    tested = state.tested_here(scr)
    got = physics_inclusion(state, scr, state.settings.alpha / max(len(tested), 1), tested)
    if got is None:
        return []
    if all(c is not got[0] for c, _ in scr.gated):
        scr.gated.append((got[0], scr.test_of(got[0])))
    if got[1] not in scr.cvs:
        scr.cvs.append(got[1])
    state.last_cv = state.tested_here(scr)
    return [got]


def pairs(state: LoopState, scr: Screening) -> tuple[Decision, Stage] | None:
    """The pair step (:mod:`calibration.loop.pairs`), when nothing else was added at the stage: the pairs of the
    candidates held-out tested at the stage, each member significant given the other at the current fit, the best
    ``settings.pairs`` of them cross-validated (at ``alpha`` over every candidate tested at the stage), kept only
    when better on the held-out folds than each member alone, then :func:`decide` (the outer test set's veto).
    Counts as two effects against ``max_effects``. Returns the decision and its stage, or None."""
    s, say = state.settings, state.say
    if not s.pairs or sum(len(st.added.effects) for st in state.stages[1:]) + 2 > s.max_effects \
            or not state.power["can_reach"]:
        return None
    tested = state.tested_here(scr)
    pool = pair_pool(scr.ranked, tested)
    offered = candidate_pairs(pool, state.desc)
    if not offered:
        return None
    tests, space = screen_candidates(at_current_torques(state.result), offered, state.folds.assign, s.rank_tol)
    single = {c.name: t for c, t in scr.ranked}
    ranked = rank_pairs(offered, tests, single, space.chi2, space.dof, s.screen_alpha)
    say(f"  pairs of the {len(pool)} candidates tested at this stage: {len(ranked)} of {len(offered)} with each "
        f"member significant given the other (score test, p < {s.screen_alpha / len(offered):.2g})")
    todo = ranked[: s.pairs]
    if not todo:
        return None
    _current_folds(state)
    scr.threshold = s.alpha / (len(tested) + len(todo))
    passing = []
    for pc, t, p in todo:
        scr.candidates.append(pc)
        scr.tests.append(t)
        scr.gated.append((pc, t))
        say(f"  cross-validating the pair + {pc.name} (score p = {t.p_value:.2g}; each member given the other "
            f"p <= {p:.2g})")
        cv = heldout_test(state, scr, pc)
        why = beats_parts(cv, tested, pc, s.min_improvement) if cv.passed else None
        if why:
            cv.passed, cv.reason = False, f"{cv.reason}; but {why}"
        say(f"    {cv.reason}")
        scr.cvs.append(cv)
        if cv.passed:
            passing.append((pc, cv))
    state.last_cv = state.tested_here(scr)
    return decide(state, scr, passing) if passing else None


def synthesise(state: LoopState) -> bool:
    """When the library is exhausted: the structure families still significant at the current fit (forward
    selection, Bonferroni, held-out explained variance > 0) become candidate effects
    (:func:`calibration.synthesis.synthesise`), appended to ``remaining`` (and ``synthesised``) to be
    screened and cross-validated like any candidate. Returns whether any new candidate was offered."""
    s = state.settings
    if not builds_from_residual(s, state.test_by):
        return False
    kept = remaining_structure(residual_space(state.result), state.folds.assign, s.alpha, s.rank_tol)
    if not kept:
        return False
    known = {c.name for c in state.remaining} | {c.name for c in state.synthesised}
    new = [c for c in build_effects([f.name for f, _ in kept], state.model) if c.name not in known]
    if not new:
        return False
    state.say(f"  structure remains ({', '.join(f.name for f, _ in kept)}): offering "
              f"{', '.join(c.name for c in new)} (built from the residual)")
    state.remaining.extend(new)
    state.synthesised.extend(new)
    return True


def run_stage(state: LoopState) -> tuple[Decision, Stage, Screening] | Stop:
    """One stage: screen and test the library's candidates; if none passes (or every one that passes makes the
    outer test set worse), once, the effects built from the residual join them and they are screened and
    tested again (those already tested at the stage are not). Returns the decision, the stage it makes and
    the screening it came from, or why nothing is added."""
    weigh_physics = state.settings.physics and state.power["can_reach"]
    for built in (False, True):
        scr = screen(state)
        if scr.gated and len(state.stages) - 1 >= state.settings.max_effects:
            stop = Stop(f"the maximum number of effects ({state.settings.max_effects}) was added")
            for c, _ in scr.gated:
                if c.origin == RESIDUAL:
                    state.fate[c.name] = f"not cross-validated: {stop.reason}"
            return stop
        passing = test(state, scr) if scr.gated else []
        staged = decide(state, scr, passing)
        if staged is not None:
            return (*staged, scr)
        if scr.gated:
            stop = Stop("every candidate that passed the held-out folds made the outer test set worse" if passing
                        else "no screened candidate improves the held-out data significantly")
            state.cv_here = state.last_cv
        else:
            stop = Stop("no screened candidate improves the held-out data significantly" if state.cv_here else
                        f"no candidate passes the screening (score-test p < {scr.gate:.2g}): nothing significant "
                        "remains that the library or an effect built from the residual explains")
        if not built and synthesise(state):
            continue
        staged = decide(state, scr, physics(state, scr)) if weigh_physics else None
        if staged is None:
            staged = pairs(state, scr)
        if staged is not None:
            return (*staged, scr)
        state.cv_here = state.last_cv if weigh_physics or state.settings.pairs else state.cv_here
        return stop
    raise AssertionError("unreachable")


def fit_stage(state: LoopState, decision: Decision, scr: Screening) -> Stage:
    """The model with the decision's candidate, recalibrated on the design set (the noise re-estimated at it, as
    the base fit estimates it, if the loop estimates the noise; the candidate's parameters with their plausible
    sizes), as a new stage with its figures
    on the outer test set and the plots of its signature before and after. The state is not changed."""
    cand = decision.candidate
    fam_name, before = plot_family(scr.space, cand)
    model = state.model.with_effects(*cand.effects)
    state.say(f"adding {cand.name}; recalibrating")
    result = state.fit(model, state.design, candidate_priors(model, cand), reweight=True)
    after = None
    if fam_name is not None:
        sp2 = residual_space(result)
        fam2 = next((f for f in families(sp2) if f.name == fam_name), None) or candidate_family(sp2, cand)
        after = binned_estimates(sp2, fam2) if fam2 is not None else None
    heldout = state.test_figures(model, result, result.weights)
    return Stage(len(state.stages), model, result, cand, state.last_tests, state.cv_here + scr.cvs, decision.nested,
                 decision.alternatives, heldout, fam_name, before, after, decision.tie)


def decide(state: LoopState, scr: Screening, passing: list) -> tuple[Decision, Stage] | None:
    """The candidate to add among the passing ones (:func:`~calibration.loop.decide.choose`) and its stage
    (:func:`fit_stage`); an effect is never added when the outer test set gets worse with it
    (:func:`outer_test_worse`): then the next choice among the passing candidates left (without it, and
    without the candidate it stood in for). None: none is left."""
    passing = list(passing)
    while passing:
        decision = choose(state, scr, passing)
        stage = fit_stage(state, decision, scr)
        if not outer_test_worse(state, stage, decision.cv):
            return decision, stage
        top = max(passing, key=lambda x: x[1].improvement)[0]
        passing = [(c, v) for c, v in passing if c is not decision.candidate and c is not top]
    return None


def outer_test_worse(state: LoopState, stage: Stage, cv) -> bool:
    """Whether the stage's RMS on the outer test set is above the current model's (an effect is never added
    when the outer test gets worse, so the before/after table never shows a step up); if so its candidate's
    held-out test no longer passes (its reason says why), and it is recorded in ``state.vetoed``."""
    now, new = judged(state.stages[-1])["rms_um"], judged(stage)["rms_um"]
    if not new > now:
        return False
    name = stage.added.name
    flagged = stage.heldout.get("flagged_points") or 0
    why = f"the outer test set got worse with it (RMS {now:.4g} -> {new:.4g} um" + (
        f", without its {flagged} point(s) the point test flags)" if flagged else ")")
    state.say(f"  {name} passed the held-out folds, but {why}: not added")
    state.vetoed.append({"name": name, "origin": stage.added.origin, "heldout_rms_before_um": now,
                         "heldout_rms_after_um": new, "cross_validation": cv.reason})
    cv.passed, cv.reason = False, f"{cv.reason}; but {why}"
    if stage.added.origin == RESIDUAL:
        state.fate[name] = f"passed the held-out folds, but {why}"
    return True


def add(state: LoopState, decision: Decision, stage: Stage, scr: Screening) -> None:
    """The stage's model becomes the current one (its effect's parameters keep their plausible sizes in every
    later fit); the candidates that share its parameters leave the remaining ones, the candidates it opens
    (``Candidate.then``, its higher terms) join them."""
    cand, cv = decision.candidate, decision.cv
    model, result = stage.model, stage.result
    state.priors.update(candidate_priors(model, cand))
    old_weights = state.weights
    state.model, state.result, state.weights = model, result, result.weights
    state.stages.append(stage)
    state.say(f"  + {cand.name}: held-out test RMS {stage.heldout['rms_um']:.2f} um "
              f"(base {state.stages[0].heldout['rms_um']:.2f} um)")
    state.base_folds = cv.folds if state.weights == old_weights else None      # compared at the same weights
    state.cv_here = []
    have = set(model.spec.names)      # e.g. the other harmonic orders of a joint once one is in
    state.fate[cand.name] = ADDED
    for c in state.remaining:
        if c is not cand and c.origin == RESIDUAL and set(c.param_names(state.desc)) & have:
            state.fate[c.name] = f"shares parameters with {cand.name}, which was added"
    for c in cand.parts:              # a pair: each part was added
        state.fate[c.name] = ADDED
    state.remaining = [c for c in state.remaining if c is not cand and not set(c.param_names(state.desc)) & have]
    state.remaining.extend(c for c in cand.then if not set(c.param_names(state.desc)) & have)


def run(state: LoopState) -> None:
    """Stages until one adds nothing or every candidate was added; sets ``state.stop``. Then, once, when the
    outer test set is still worse than stated (:func:`escalate`), the opt-in families join the candidates left and
    the stages go on."""
    while True:
        outcome = run_stage(state)
        if isinstance(outcome, Stop):
            state.stop = outcome.reason
        else:
            add(state, *outcome)
            if state.remaining:
                continue
            state.stop = "every candidate was added"
            state.last_tests, state.last_cv = [], []
        if not escalate(state):
            return


def escalate(state: LoopState) -> bool:
    """Offer the families off by default (:data:`~calibration.candidates.OPT_IN_FAMILIES`, those not offered
    yet), once, when the outer test set of the current model is worse than stated
    (:func:`~calibration.loop.verdict.heldout_check`) and an effect may still be added: what the default families
    and the effects built from the residual could not explain shows on data the fit never saw, so the effects a
    user must otherwise ask for are tested too, each kept only by the held-out folds and the outer test set like
    any other. The judgement is a function of the data (no seed). Returns whether new candidates were offered."""
    s = state.settings
    if not s.escalate or state.escalated is not None or len(state.stages) - 1 >= s.max_effects:
        return False
    check = heldout_check(state.stages[-1], state.test_by, s.alpha)
    if not check or not check["worse_than_stated"]:
        return False
    first = DEFAULT_FAMILIES if state.families is None else state.families
    fams = tuple(f for f in OPT_IN_FAMILIES if f not in first)
    known = {c.name for c in state.candidates} | {c.name for c in state.synthesised}
    have = set(state.model.spec.names)
    new = [c for c in library_candidates(state.desc, state.data, fams)[0]
           if c.name not in known and not set(c.param_names(state.desc)) & have] if fams else []
    state.escalated = {"families": list(fams), "candidates": [c.name for c in new], "check": check}
    if not new:
        return False
    state.say(f"the outer test set is worse than stated (RMS {check['rms_um']:.4g} um, {check['ratio']:.3g} times "
              f"what the fit predicts, p = {check['p_value']:.2g}): offering the opt-in famil"
              f"{'y' if len(fams) == 1 else 'ies'} {', '.join(fams)} ({', '.join(c.name for c in new)})")
    state.candidates.extend(new)
    state.remaining.extend(new)
    return True


def report(state: LoopState) -> LoopResult:
    """The structure tests on the final fit (Holm-adjusted, and the forward selection of what remains), the
    effects built from the residual and their fate, the verdict, and the final model calibrated on every
    point from the stated uncertainties."""
    s, say = state.settings, state.say
    say("structure tests on the final fit")
    space = residual_space(state.result, prior=True)       # what the fit made leaves (the score test of its prior)
    st = structure_tests(space, state.folds.assign, s.rank_tol)
    adj = holm([t.p_value for _, t in st])
    structure = [(f, t, float(a)) for (f, t), a in zip(st, adj, strict=True)]
    significant = [(f, t, min(1.0, t.p_value * len(structure)))
                   for f, t in remaining_structure(space, state.folds.assign, s.alpha, s.rank_tol)]
    plots = {f.name: binned_estimates(space, f) for f, _, _ in significant[:4]}
    fate = state.fate
    built = [{"name": c.name, "family": c.family, "joint": c.joint, "effect": c.effect.describe(),
              "added": fate.get(c.name) == ADDED, "why_not_added": None if fate.get(c.name) == ADDED else
              fate.get(c.name, "not screened")} for c in state.synthesised]
    check = heldout_check(state.stages[-1], state.test_by, s.alpha)
    verdict = verdict_text(state.stages, significant, state.stop, s, built, state.model, state.vetoed, state.stated,
                           check, state.escalated if state.escalated and state.escalated["candidates"] else None,
                           state.test_by)
    say(verdict)
    data = state.data if s.test_in_model else state.data.select(~state.test_rows)
    say("calibrating the final model on every point (" + ("design and test" if s.test_in_model else
        "but the held-out test set's") + "; outliers kept, as calibrate does)")
    # no compliance of it is negative: every fit holds a parameter at its lower bound (calibrate, _at_bounds)
    model_fit = state.fit(state.model, data, reweight=True, weights=state.stated, region=s.region_effect)
    return LoopResult(state.stages, state.last_tests, state.last_cv, state.stop, structure, significant, verdict,
                      state.candidates + state.synthesised, state.skipped, state.design.measurements(),
                      state.test.measurements(), s, state.desc, plots, state.dropped, state.test_by, state.power,
                      model_fit, built, state.vetoed, state.data,
                      residual_over_stated(state.result, state.stated)[0], check, state.escalated,
                      state.flagged_entries)
