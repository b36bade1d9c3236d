"""The held-out test of one candidate and the rules that turn the tests of a screening into the one effect to
add: the largest held-out drop, the harmonic order with the fewest parameters, a joint's compliance
replaced by every loaded joint's (:func:`whole_family`), joint compliance included as physics when no
candidate passes (:func:`physics_inclusion`), parsimony among candidates of the same signature, the tie rule
among candidates the held-out units cannot tell apart (:func:`resolve_tie`), and the candidates the data cannot
tell from the one added."""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np
from scipy import stats

from arm_model import NumericalError
from arm_model.model import ArmModel

from ..calibrate import CalibrationResult
from ..candidates import Candidate
from ..diagnostics import GroupTest, ResidualSpace, binned_estimates, candidate_family
from ..identifiability import prior_scales
from ..synthesis import RESIDUAL
from .crossval import CVResult, cross_validate, fold_fit, one_sided, warm_start
from .settings import PARSIMONY, PHYSICS, SAME_SIGNATURE
from .state import LoopState, Screening

__all__ = ["Decision", "heldout_test", "fit_on_design", "choose", "whole_family", "TIE_RULE", "paired_worse",
           "tie_rivals", "tie_order", "joinable", "joined", "resolve_tie", "PER_JOINT", "physics_inclusion",
           "resolved", "candidate_priors", "signature_overlap", "plot_family"]


@dataclass(frozen=True)
class Decision:
    """The candidate to add, its held-out evidence and the candidates whose signature lies within its own
    (``nested``) or that alone would explain the same (``alternatives``); ``tie``: the record of the tie it was
    chosen from (:func:`resolve_tie`), None when the held-out data told the candidates apart."""
    candidate: Candidate
    cv: CVResult
    nested: list
    alternatives: list
    tie: dict | None = None


def heldout_test(state: LoopState, scr: Screening, cand: Candidate) -> CVResult:
    """Cross-validate the current model plus ``cand`` against the current model (``state.base_folds``) on
    the folds of the decisions, at the level of this pass (``scr.threshold``); a candidate whose parameters
    were all held in some fold's training part (not separable there; held at a bound counts as estimated) does not
    pass."""
    t = scr.test_of(cand)
    model = state.model.with_effects(*cand.effects)
    cp = candidate_priors(model, cand)
    s = state.settings
    try:
        new = fold_fit(model, state.design, state.folds, partial(state.fit, extra_priors=cp), state.base_folds,
                       warm_start(state.result))
        cv = cross_validate(cand.name, state.base_folds, new, scr.threshold, s.min_improvement)
        names = cand.param_names(state.desc)
        held = [k for k, r in enumerate(new.results) if not set(names) & (set(r.free) | at_bound(r))]
        cv.held = bool(held)
        if held and cv.passed:
            cv.passed = False
            cv.reason = (f"its parameters were held (not resolved) in the training part of fold(s) "
                         f"{', '.join(str(k + 1) for k in held)}")
    except NumericalError as exc:
        cv = cross_validate(cand.name, state.base_folds, None, scr.threshold, s.min_improvement, str(exc))
    cv.score_p = t.p_value
    return cv


def at_bound(res: CalibrationResult) -> set[str]:
    """The parameters of ``res`` held at their lower bound: estimated (at the bound: a compliance the data put
    at zero), not left unresolved."""
    return {f.name for f in res.fixed if f.pulled is not None}


def fit_on_design(state: LoopState, scr: Screening, cand: Candidate) -> CalibrationResult:
    """The current model plus ``cand`` calibrated on the design set."""
    model = state.model.with_effects(*cand.effects)
    return state.fit(model, state.design, candidate_priors(model, cand))


def choose(state: LoopState, scr: Screening, passing: list) -> Decision:
    """Of the passing ``(candidate, CVResult)``: the largest held-out drop; for harmonics built from the
    residual the order with the fewest parameters within :data:`PARSIMONY` of it; a joint's compliance
    replaced by every loaded joint's (:func:`whole_family`); then a passing candidate of fewer identifiable
    directions inside the winner's signature and within :data:`PARSIMONY` of its drop replaces it; last, a tie with
    candidates the held-out units cannot tell from it is resolved by :data:`TIE_RULE` (:func:`resolve_tie`)."""
    desc, rank_tol = state.desc, state.settings.rank_tol
    rank = {c.name: t.rank for c, t in scr.gated}
    cand, cv = max(passing, key=lambda x: x[1].improvement)
    if cand.origin == RESIDUAL and cand.family == "joint_harmonics":
        # the harmonic order: the fewest parameters within the parsimony margin of the best held-out drop
        same = [(c, v) for c, v in passing if c.family == cand.family and c.joint == cand.joint
                and c.effect.source == cand.effect.source and cv.improvement - v.improvement <= PARSIMONY]
        cand, cv = min(same, key=lambda x: x[0].size(desc))
    if cand.family == "joint_compliance" and cand.joint is not None:
        cand, cv = whole_family(state, scr, cand, cv)
    wcols = _candidate_cols(scr, cand)
    # parsimony: a passing candidate inside the best one's signature, with fewer parameters and nearly the
    # same held-out improvement, explains as much with less
    for c2, cv2 in sorted(passing, key=lambda x: rank[x[0].name]):
        if c2 is cand or rank[c2.name] >= rank[cand.name] or cv.improvement - cv2.improvement > PARSIMONY:
            continue
        c2cols = _candidate_cols(scr, c2)
        if wcols is not None and c2cols is not None and \
                signature_overlap(scr.space, wcols, c2cols, rank_tol) >= SAME_SIGNATURE:
            cand, cv = c2, cv2
            break
    tie = None
    if not cv.reason.startswith(PHYSICS):
        cand, cv, tie = resolve_tie(state, scr, cand, cv)
    nested, alternatives = _same_signature(scr, cand, rank_tol)
    return Decision(cand, cv, nested, alternatives, tie)


#: how a tie is resolved (console, report and summary.json say it): the simpler first, then the evidence of every
#: design unit together, never the held-out split's noise
TIE_RULE = ("the fewest parameters (identifiable directions at the screening); of one effect on several joints, the "
            "effect on every tied joint at once if that lowers the held-out RMS by --min-improvement; else the "
            "strongest score test on the whole design set (the smallest p), then the name")

#: effect families with one library candidate a joint, whose tied candidates the tie rule joins into one
PER_JOINT = ("eccentricity", "joint_gain")


def paired_worse(cv_a: CVResult, cv_b: CVResult) -> float:
    """One-sided paired Wilcoxon p-value that ``cv_a``'s held-out errors are larger than ``cv_b``'s, unit by unit
    (mean squared weighted residual of each unit of the same folds; 1 when they are equal on every unit)."""
    units = sorted(cv_b.folds.sse)
    d = np.array([cv_a.folds.sse[u][0] / cv_a.folds.sse[u][1] - cv_b.folds.sse[u][0] / cv_b.folds.sse[u][1]
                  for u in units])
    return one_sided(d)


def tie_rivals(scr: Screening, cand: Candidate, cv: CVResult, level: float, min_improvement: float,
               desc, vetoed=()) -> list:
    """The candidates cross-validated in this pass that the held-out units do not tell from ``cand`` (the one the
    held-out drop chose): each lowers the held-out RMS by at least ``min_improvement`` itself, shares no parameter
    with ``cand`` (nested orders and a joint's compliance in the family's have their own rules), is no pair, was
    not vetoed by the outer test set, and ``cand`` is not significantly better on the units (one-sided paired
    Wilcoxon of the rival's minus ``cand``'s errors, p >= ``level``). Returns ``[(candidate, CVResult, p)]``."""
    if cand.parts or cv.folds is None:
        return []
    mine, units = set(cand.param_names(desc)), sorted(cv.folds.sse)
    out = []
    for c2, _ in scr.gated:
        cv2 = scr.cv_of(c2)
        if c2 is cand or c2.parts or cv2 is None or cv2.folds is None or cv2.held or c2.name in vetoed \
                or sorted(cv2.folds.sse) != units or set(c2.param_names(desc)) & mine \
                or not (np.isfinite(cv2.improvement) and cv2.improvement >= min_improvement):
            continue
        p = paired_worse(cv2, cv)
        if p >= level:
            out.append((c2, cv2, p))
    return out


def tie_order(scr: Screening, cand: Candidate) -> tuple:
    """The key of :data:`TIE_RULE`: (identifiable directions, score-test p-value, name); the smallest wins."""
    t = scr.test_of(cand)
    return (t.rank, t.p_value if np.isfinite(t.p_value) else 2.0, cand.name)


def joinable(tied: list[Candidate], scr: Screening) -> list[Candidate]:
    """Of the tied candidates, those with the fewest parameters when they are one library effect of
    :data:`PER_JOINT` on two or more joints (one joint each): the ones the tie rule joins; else []."""
    fewest = min(scr.test_of(c).rank for c in tied)
    best = [c for c in tied if scr.test_of(c).rank == fewest]
    if len(best) < 2 or len({c.family for c in best}) > 1 or best[0].family not in PER_JOINT or any(
            c.origin != "library" or c.joint is None or c.parts or len(c.effect.joints or ()) != 1 for c in best):
        return []
    return best


def joined(cands: list[Candidate], scr: Screening, desc) -> tuple[Candidate, GroupTest]:
    """One candidate of the effect of ``cands`` (one library effect of a :data:`PER_JOINT` family, one joint each) on
    all their joints (``"eccentricity j1+j3"``) and its score test assembled from theirs (the sum of their
    statistics' sizes, the smallest p, the one-step estimates of each joint's parameters)."""
    named = {j: str(c.joint) for c in cands for j in c.effect.joints}
    joints = tuple(sorted(named))
    first = cands[0]
    prefix = first.name[:-len(str(first.joint))].rstrip()            # "eccentricity", "gain"
    merged = Candidate(f"{prefix} {'+'.join(named[j] for j in joints)}", replace(first.effect, joints=joints),
                       first.family)
    tests = [scr.test_of(c) for c in cands]
    est = {n: (b, u) for t in tests for n, b, u in zip(t.names, t.estimate, t.u, strict=True)}
    pnames = merged.param_names(desc)
    nan = (float("nan"), float("nan"))
    test = replace(tests[0], name=merged.name, k=sum(t.k for t in tests), rank=sum(t.rank for t in tests),
                   absorbed=tuple(a for t in tests for a in t.absorbed), names=tuple(pnames),
                   estimate=np.array([est.get(n, nan)[0] for n in pnames]),
                   u=np.array([est.get(n, nan)[1] for n in pnames]), p_value=min(t.p_value for t in tests))
    return merged, test


def _join_tie(state: LoopState, scr: Screening, cands: list[Candidate]) -> tuple[Candidate, CVResult] | None:
    """The effect on every tied joint (:func:`joined`), held-out tested; returned when it lowers the held-out RMS by
    at least ``min_improvement`` and its parameters were resolved in every fold, else None."""
    merged, test = joined(cands, scr, state.desc)
    scr.candidates.append(merged)
    scr.tests.append(test)
    state.say(f"    cross-validating + {merged.name} (the effect on every tied joint)")
    got = heldout_test(state, scr, merged)
    state.say(f"      {got.reason}")
    scr.gated.append((merged, test))
    scr.cvs.append(got)
    if got.held or not (np.isfinite(got.improvement) and got.improvement >= state.settings.min_improvement):
        return None
    return merged, got


def resolve_tie(state: LoopState, scr: Screening, cand: Candidate, cv: CVResult
                ) -> tuple[Candidate, CVResult, dict | None]:
    """When the held-out units cannot tell the chosen ``cand`` from other candidates (:func:`tie_rivals`), which of
    them is added is no longer a matter of its held-out drop, a hair's difference another fit's tolerance can
    flip (the real Panda's eccentricities of joints 1 and 3 trained on ``right``: 0.04 u in the evidence's
    parameters moved the choice), but of the stated :data:`TIE_RULE`: the fewest parameters, then the strongest
    score test on the whole design set. The tie only says which of the tied candidates carries a signature the
    held-out folds support (``cand`` passed them); the one chosen lowers the held-out RMS by at least
    ``min_improvement`` itself, and the outer test set still vetoes it (:func:`calibration.loop.stages.decide`).
    A tie is declared when ``cand`` is not better than a rival at the screening's level (``screen_alpha``, one
    comparison each, no Bonferroni): at the decisions' own level (``alpha`` over the candidates tested) a winner 38 %
    lower than the current model was "tied" with a rival 27 % lower (paired p = 0.011, 15 units), and the rule
    took the rival (scripts/redteam_study.py, ``probe-aniso``).
    Returns the candidate, its held-out test (passed, its reason saying it was chosen by the rule) and the tie's
    record (None: no tie)."""
    s = state.settings
    vetoed = {v["name"] for v in state.vetoed}
    rivals = tie_rivals(scr, cand, cv, s.screen_alpha, s.min_improvement, state.desc, vetoed)
    if not rivals:
        return cand, cv, None
    tied = [(cand, cv, None)] + rivals
    state.say(f"  tie: {cand.name} (held-out {100 * cv.improvement:.1f} % lower, score p = "
              f"{scr.test_of(cand).p_value:.2g}) is not told from "
              + ", ".join(f"{c.name} ({100 * v.improvement:.1f} %, score p = {scr.test_of(c).p_value:.2g}, paired "
                          f"p = {p:.2g})" for c, v, p in rivals) + " on held-out data")
    members = joinable([c for c, _, _ in tied], scr)
    both = _join_tie(state, scr, members) if members else None
    chosen, ccv = both if both is not None else min(((c, v) for c, v, _ in tied),
                                                   key=lambda x: tie_order(scr, x[0]))

    def row(c, v, p):
        t = scr.test_of(c)
        return {"name": c.name, "parameters": int(t.rank), "score_p_value": float(t.p_value),
                "delta_chi2": float(t.delta_chi2), "relative_improvement": float(v.improvement),
                "wilcoxon_p_value": float(v.p_value), "paired_p_value": p}
    record = {"candidates": [row(*x) for x in tied], "heldout_best": cand.name, "chosen": chosen.name,
              "joined": [c.name for c in members] if both is not None else None,
              "rule": TIE_RULE, "level": float(s.screen_alpha)}
    state.say(f"  by the tie rule ({TIE_RULE}): {chosen.name}")
    if chosen is not cand:
        ccv.passed = True
        ccv.reason = (f"tied with {cand.name} on held-out data, chosen by the tie rule; its own held-out RMS "
                      f"{100 * ccv.improvement:.1f} % lower (Wilcoxon p = {ccv.p_value:.2g})")
    return chosen, ccv, record


def _same_signature(scr: Screening, cand: Candidate, rank_tol: float) -> tuple[list, list]:
    """The screened candidates whose signature lies within ``cand``'s (nested) and those whose signature
    holds ``cand``'s (alternatives), of the same screening batch."""
    nested, alternatives = [], []
    wi = scr.candidates.index(cand)
    wcols = _candidate_cols(scr, cand, wi)
    for i, other in enumerate(scr.candidates):
        if i == wi or not scr.tests[i].identifiable:
            continue
        ocols = _candidate_cols(scr, other, i)
        if wcols is None or ocols is None:
            continue
        if signature_overlap(scr.space, wcols, ocols, rank_tol) >= SAME_SIGNATURE:
            nested.append(other.name)
        if signature_overlap(scr.space, ocols, wcols, rank_tol) >= SAME_SIGNATURE:
            alternatives.append(other.name)
    return nested, alternatives


def whole_family(state: LoopState, scr: Screening, cand: Candidate, cv: CVResult) -> tuple[Candidate, CVResult]:
    """A joint compliance is a property of the arm, and under gravity the joints deflect together: when one
    loaded joint's compliance is supported on held-out data, the compliance of every loaded joint (one
    candidate) replaces it if (1) fitted on the design set it resolves the compliance of at least one
    other joint as non-zero (|c| > z u, z two-sided at ``alpha`` with Bonferroni over those joints) and
    (2) it does not predict the held-out data worse (positive relative improvement). Within one plate
    placement the gravity torques of the joints move together, so its held-out poses favour the one joint
    whose signature is plainest; the deflection of every compliant joint is what carries over to the rest
    of the workspace. A compliance of one joint alone (a measuring arm's shoulder) stays that joint's.
    Returns the (candidate, CV result) to add."""
    say = state.say
    every = next((c for c in scr.candidates if c.family == cand.family and c.joint is None), None)
    if every is None:
        return cand, cv
    res = fit_on_design(state, scr, every)
    own = set(cand.param_names(res.model.desc))
    others = [n for n in every.param_names(res.model.desc) if n not in own and (n in res.free or n in at_bound(res))]
    if not others:
        return cand, cv
    z, neg, pos = resolved(res, others, state.settings.alpha)
    named = [n for n in others if n in neg or n in pos]
    if not named:
        say(f"  {every.name}: no other joint's compliance resolved as non-zero (|c| > {z:.2f} u); "
            f"keeping {cand.name}")
        return cand, cv
    got = scr.cv_of(every)
    if got is None:
        say(f"  cross-validating + {every.name} (other joints resolved: {', '.join(named)})")
        got = heldout_test(state, scr, every)
        say(f"    {got.reason}")
        scr.cvs.append(got)
    if np.isfinite(got.improvement) and got.improvement > 0 and not got.held:
        say(f"  {cand.name} is supported and the design set resolves {', '.join(named)}: taking "
            f"{every.name} (held-out RMS {100 * got.improvement:.1f} % lower than the current model's)")
        return every, got
    return cand, cv


def resolved(res: CalibrationResult, names: list, level: float) -> tuple[float, list, list]:
    """``(z, negative, positive)``: the parameters ``names`` of ``res`` resolved below ``-z u`` and above
    ``z u``, z two-sided at ``level`` with Bonferroni over ``names``. A compliance every fit holds at its bound 0
    (:meth:`arm_model.model.ArmModel.lower_bounds`) counts as negative when the value the data pulled it to is
    below ``-z u`` of its own uncertainty (``FixedParameter.pulled``)."""
    z = float(stats.norm.isf(level / (2 * len(names))))
    pulled = {f.name: f.pulled for f in res.fixed if f.pulled is not None and f.name in names}
    free = [n for n in names if n in res.free]
    neg = [n for n in names if n in pulled and pulled[n][0] < -z * pulled[n][1]]
    return (z, neg + [n for n in free if res.value(n) < -z * res.uncertainty(n)],
            [n for n in free if res.value(n) > z * res.uncertainty(n)])


def physics_inclusion(state: LoopState, scr: Screening, level: float, tested: list = ()
                      ) -> tuple[Candidate, CVResult] | None:
    """Joint compliance under gravity (every loaded joint, the arm's masses) when no candidate improves the
    held-out poses significantly (neither the library's nor those built from the residual,
    :func:`calibration.loop.stages.physics`): every arm bends under its own weight, and held-out poses of the same
    plate placement cannot show what a compliance is worth elsewhere (their gravity torques differ little
    from the training poses', so the geometry absorbs most of its signature there; on the real Panda data,
    trained on one placement, the compliances make the held-out poses of that placement 6 % worse and the
    other placements' seat spread 27-44 % smaller). It is included, as physics and not as a held-out gain,
    when all of these hold:

    * its score test is significant (``p < scr.gate``, the screening's Bonferroni level);
    * fitted on the design set, at least one joint's compliance is resolved positive and none is
      significantly negative (``|c| > z u``, z two-sided at ``level`` with Bonferroni over the joints):
      a negative compliance is not a compliance, the signature would be something else's;
    * the held-out poses are not significantly worse (one-sided Wilcoxon ``p_worse >= level``) and its
      parameters were resolved in every fold (its held-out test at this stage, among ``tested``, or run now).

    Returns ``(candidate, CVResult)`` (passed, its reason saying why) or None."""
    say = state.say
    every = next((c for c in scr.candidates if c.family == "joint_compliance" and c.joint is None), None)
    if every is None:
        return None
    t = scr.test_of(every)
    support = _physics_support(state, scr, every, t)
    if support is None:
        return None
    res, why = support
    names = [n for n in every.param_names(res.model.desc) if n in res.free or n in at_bound(res)]
    if not names:
        return None
    z, neg, pos = resolved(res, names, level)
    say(f"  physics check of {every.name}: {why}; resolved positive: "
        f"{', '.join(pos) or 'none'}; significantly negative: {', '.join(neg) or 'none'} (z = {z:.2f})")
    # with the prior, the evidence has weighed the compliances (never negative) against their physical size
    if neg or not (pos or state.options.prior_scale is not None):
        return None
    got = scr.cv_of(every) or next((v for v in tested if v.candidate == every.name), None)
    if got is None:
        got = heldout_test(state, scr, every)
        scr.cvs.append(got)
    p_worse = 1.0 - got.p_value if np.isfinite(got.p_value) else 0.0
    if got.held or p_worse < level:
        say(f"    held-out poses significantly worse (p = {p_worse:.2g}) or parameters held: not included")
        return None
    got.passed = True
    got.reason = (f"{PHYSICS}: {why}, "
                  f"{'the compliances ' + ', '.join(pos) + ' are resolved positive and ' if pos else ''}none is "
                  f"negative; held-out poses of "
                  f"this placement {100 * got.improvement:+.1f} % (not significantly worse, p = {p_worse:.2g})")
    say(f"    {got.reason}")
    return every, got


def _physics_support(state: LoopState, scr: Screening, every: Candidate, t: GroupTest):
    """Whether the design set supports joint compliance at all, and its fit there: ``(result, why)`` or None.
    Without a prior its score test must pass the screening's gate; with the prior (its size the deflection
    under the data's gravity torques, never negative) the evidence must favour the model with it: its log
    evidence (each model at its own evidence-chosen scales, the same noise) above the current model's."""
    if state.options.prior_scale is None:
        if not (t.identifiable and t.p_value < scr.gate):
            return None
        return fit_on_design(state, scr, every), f"its gravity signature is significant (score p = {t.p_value:.2g})"
    res = fit_on_design(state, scr, every)
    base = state.fit(state.model, state.design)
    if res.log_evidence is None or base.log_evidence is None or not res.log_evidence > base.log_evidence:
        state.say(f"  physics check of {every.name}: the evidence does not favour it (log evidence "
                  f"{_num(res.log_evidence)} vs {_num(base.log_evidence)} without)")
        return None
    return res, (f"the evidence favours it (log evidence {res.log_evidence:.1f} vs {base.log_evidence:.1f} "
                 "without)")


def _num(v) -> str:
    return "n/a" if v is None else f"{v:.1f}"


def candidate_priors(model: ArmModel, cand: Candidate) -> dict[str, float]:
    """Plausible sizes of a candidate's parameters for ``calibrate``'s practical-identifiability check (fits without
    a prior; with one, the prior's own sizes apply): the physical sizes of
    :func:`~calibration.identifiability.prior_scales` (the effect's own plausible size, else its unit's scale at the
    data's noise), never the screening's estimate from the data being judged. (Until 2026-11-28 at least ten times
    that estimate: measured the same effects, held-out figures and verdicts on scripts/hidden_effects_study.py and
    tests/test_loop_effects.py, test_loop_synthesis.py; docs/studies/close-loop.md, "Stable decisions".)"""
    names = cand.param_names(model.desc)
    return {n: float(d) for n, d in zip(names, prior_scales(model, names), strict=True)}


def _candidate_cols(scr: Screening, cand: Candidate, i: int | None = None):
    """Raw columns of a screened candidate (``i``: its index in ``scr.candidates``, default the first equal
    to it) in the screening's residual space without those the screening found absorbed (None if it was
    screened in another batch)."""
    i = scr.candidates.index(cand) if i is None else i
    space, test = scr.space, scr.tests[i]
    extra = list(space.model.effects)[len(space.result.model.effects):]
    ks = [next((n for n, e in enumerate(extra) if e is mine), -1) for mine in scr.candidates[i].effects]
    if -1 in ks:
        return None
    keep = [j for j, n in enumerate(test.names) if n not in test.absorbed]
    cols: np.ndarray = np.hstack([space.jp[:, space.extra_slices[k]] for k in ks])
    return cols[:, keep]


def signature_overlap(space: ResidualSpace, a_cols: np.ndarray, b_cols: np.ndarray, rank_tol: float) -> float:
    """Share of b's projected signature (mean squared cosine of the principal angles) inside span(a)."""
    def basis(c):
        pc = space.project(c)
        norm = np.linalg.norm(c, axis=0)
        pc = pc / np.where(norm > 0, norm, 1.0)
        u, s, _ = np.linalg.svd(pc, full_matrices=False)
        return u[:, s > rank_tol]
    ua, ub = basis(a_cols), basis(b_cols)
    if ua.shape[1] == 0 or ub.shape[1] == 0:
        return 0.0
    return float(np.sum((ua.T @ ub) ** 2) / ub.shape[1])


def plot_family(space: ResidualSpace, cand: Candidate) -> tuple[str | None, dict | None]:
    """The generic family that shows ``cand``'s signature (:func:`~calibration.diagnostics.candidate_family`)
    and its binned estimates at ``space``'s fit (None, None: none)."""
    fam = candidate_family(space, cand)
    if fam is None:
        return None, None
    return fam.name, binned_estimates(space, fam)
