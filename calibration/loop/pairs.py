"""The pair step of the closed loop: two effects that help only together.

The loop adds one effect a stage, each tested alone against the current model; two effects whose signatures
overlap so that each alone is half absorbed by the fit (two joints' plays seen through the same postures) can each
fail the held-out folds, or each make the outer test set worse, while the model with both predicts better than
either. When no single candidate is added at a stage (:func:`calibration.loop.stages.run_stage`), the pairs of the
candidates held-out tested at that stage (the best few the screening sent on, so at most ``C(2 cv_top, 2)`` pairs,
never every pair of the library) are screened by the score test of both together at the current fit, and a pair
goes on only when **each member is significant given the other** (:func:`conditional_p`, Bonferroni over the pairs
screened): the residual's evidence that both are needed. The best ``LoopSettings.pairs`` of them, by the weaker
member's conditional p-value, are cross-validated like any candidate (the Wilcoxon level counting every candidate
tested at the stage), must be better on the held-out folds than each member alone by ``min_improvement``
(:func:`beats_parts`), and are vetoed by the outer test set like any other.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np

from ..candidates import Candidate, pair_of
from ..diagnostics import GroupTest, f_upper_tail
from .crossval import CVResult

__all__ = ["pair_pool", "candidate_pairs", "conditional_p", "rank_pairs", "beats_parts"]


def pair_pool(ranked: list, tested: list[CVResult]) -> list[Candidate]:
    """The candidates of a screening (``ranked``: ``(candidate, test)`` by score p-value) that were held-out tested
    at the stage (``tested``, by name) with their fold fits at hand and an identifiable signature, no pair among
    them; in the screening's order."""
    cvs = {cv.candidate: cv for cv in tested}
    return [c for c, t in ranked if c.name in cvs and cvs[c.name].folds is not None and not cvs[c.name].held
            and t.identifiable and not c.parts]


def candidate_pairs(pool: list[Candidate], desc) -> list[Candidate]:
    """Every pair of ``pool`` whose members share no parameter (a harmonic order and another of the same joint,
    a joint's compliance and every loaded joint's, are alternatives, not a pair), as one candidate each
    (:func:`~calibration.candidates.pair_of`, the better-screened member first)."""
    return [pair_of(a, b) for a, b in combinations(pool, 2)
            if not set(a.param_names(desc)) & set(b.param_names(desc))]


def conditional_p(pair: GroupTest, member: GroupTest, chi2: float, dof: int) -> float:
    """P-value of the score test of the pair's other member given ``member`` (both tests at the same fit, whose
    weighted residual has ``chi2`` on ``dof`` degrees of freedom): ``F = ((d_pair - d_member) / (k_pair - k_member))
    / ((chi2 - d_pair) / (dof - k_pair))``, ``d`` the score statistics and ``k`` the identifiable directions. 1 when
    the other member adds no direction."""
    extra = pair.rank - member.rank
    rest, dof2 = chi2 - pair.delta_chi2, dof - pair.rank
    if extra <= 0 or dof2 <= 0 or not rest > 0:
        return 1.0
    return f_upper_tail(max(pair.delta_chi2 - member.delta_chi2, 0.0) / extra / (rest / dof2), extra, dof2)


def rank_pairs(pairs: list[Candidate], tests: list[GroupTest], single: dict, chi2: float, dof: int, alpha: float
               ) -> list[tuple[Candidate, GroupTest, float]]:
    """The pairs whose each member is significant given the other at ``alpha / len(pairs)`` (``single``: each
    member's own score test at the same fit, by name), as ``(pair, test, p)`` with ``p`` the larger of the two
    conditional p-values (the weaker member's), best first (then the larger joint statistic, then the name)."""
    gate = alpha / max(len(pairs), 1)
    out = []
    for pc, t in zip(pairs, tests, strict=True):
        if not t.identifiable:
            continue
        p = max(conditional_p(t, single[c.name], chi2, dof) for c in pc.parts)
        if p < gate:
            out.append((pc, t, p))
    return sorted(out, key=lambda x: (x[2], -x[1].delta_chi2, x[0].name))


def beats_parts(cv: CVResult, tested: list[CVResult], pair: Candidate, min_improvement: float) -> str | None:
    """None when the pair's pooled held-out RMS is below each member's alone (on the same folds, ``tested`` by
    name) by at least ``min_improvement``: each member earns its place on held-out data; else why not."""
    cvs = {v.candidate: v for v in tested}
    for c in pair.parts:
        alone = cvs.get(c.name)
        if alone is None or not np.isfinite(alone.rms_new):
            continue
        if not cv.rms_new <= (1.0 - min_improvement) * alone.rms_new:
            return (f"not better than {c.name} alone on the held-out folds by {100 * min_improvement:g} % (weighted "
                    f"RMS {cv.rms_new:.4g} against {alone.rms_new:.4g})")
    return None
