"""The loop's verdict: a sentence saying what was added, what was built from the residual and not added (and
why), and what structure remains unexplained."""
from __future__ import annotations

import math

from scipy import stats

from arm_model.model import ArmModel

from ..diagnostics import f_upper_tail
from ..synthesis import RESIDUAL, synthesise
from .settings import NOISE_OFF, PHYSICS

__all__ = ["judged", "verdict_text", "residual_over_stated", "estimated_words", "heldout_check", "builds_from_residual",
           "NOT_BUILT_ON_POSES", "S0_LIMIT", "ADDED"]


#: residual standard deviation factor above which the residual is not noise at the stated level
S0_LIMIT = 3.0
#: the fate of a synthesised candidate that was added
ADDED = "added"


def residual_over_stated(result, stated=None) -> tuple[float, str]:
    """By how much the final fit's residual exceeds the *stated* uncertainties ``stated``
    (:class:`~calibration.data.Weights`), and the groups' figures as words.

    The fit's own ``s0`` is no measure of it when the loop estimated the noise from the data (its default): its
    weights then are the residual's own scatter and ``s0`` is near 1 whatever the residual holds. So each row group
    whose noise the fit estimated gives its scatter against its stated sigma (``estimate_um / stated``), and the
    groups are pooled by their redundancy, as ``s0`` pools the rows; without a stated sigma or an estimated
    group, ``s0``. A sigma the user did not state (a default, :meth:`~calibration.data.Weights.stated_sigma_of`)
    is no statement: its group is judged against its estimate (``s0``) and said by :func:`estimated_words`."""
    variance = _estimated(result)
    groups = [v for v in variance if stated is not None and stated.stated_sigma_of(v["group"])]
    if not groups:
        return float(result.s0), ""
    ratios = [v["estimate_um"] / (stated.stated_sigma_of(v["group"]) * 1e6) for v in groups]
    ratios += [float(result.s0)] * (len(variance) - len(groups))
    red = [v["redundancy"] for v in groups] + [v["redundancy"] for v in variance if v not in groups]
    pooled = math.sqrt(sum(r * x * x for r, x in zip(red, ratios, strict=True)) / sum(red))
    words = ", ".join(f"{v['group']} {v['estimate_um']:.3g} um against the stated "
                      f"{stated.stated_sigma_of(v['group']) * 1e6:.3g}" for v in groups)
    return pooled, words


def _estimated(result) -> list[dict]:
    """The row groups whose noise the fit estimated from the data (variance components with a redundancy)."""
    return [v for v in getattr(result, "variance", None) or ()
            if v.get("estimated") and v.get("estimate_um") is not None and v.get("redundancy", 0) > 0]


def estimated_words(result, stated=None) -> str:
    """The verdict's sentence on the groups whose noise was estimated from the data although the user stated no
    uncertainty for them and the estimate is off the default by more than the loop's factor
    (:data:`~calibration.loop.settings.NOISE_OFF`: the default is replaced by it, a default within it would
    have done as well): "" when there is none."""
    if stated is None:
        return ""
    groups = [v for v in _estimated(result) if stated.sigma_of(v["group"]) and not stated.stated_sigma_of(v["group"])
              and not 1 / NOISE_OFF < v["estimate_um"] / (stated.sigma_of(v["group"]) * 1e6) < NOISE_OFF]
    if not groups:
        return ""
    return ("Noise estimated from the data, no uncertainty stated for it: " + ", ".join(
        f"{v['group']} {v['estimate_um']:.3g} um (the default {stated.sigma_of(v['group']) * 1e6:.3g} um replaced by "
        "the estimate)" for v in groups) + f"; the final residual is {result.s0:.3g} times the estimate")


def judged(stage) -> dict:
    """The outer test set's figures of ``stage`` the loop's decisions read (the veto,
    :func:`~calibration.loop.stages.outer_test_worse`; the judgement against a complete model, :func:`heldout_check`):
    without the points the point test flags when it flags some (``stage.heldout["unflagged"]``: a gross point's
    error drowns the difference between two models; four points 1 mm off on a sphere of the test set, 70.53 ->
    70.59 um with them, and the hidden cross-coupling was vetoed), else those printed (every test point)."""
    return stage.heldout.get("unflagged") or stage.heldout


def heldout_check(stage, test_by: str, alpha: float) -> dict | None:
    """Whether the outer test set is worse than stated: worse than a complete model predicts for it, judged on data
    the fit never saw, beside the structure tests of the design fit's residual.

    A complete model predicts a held-out row with the noise and, in addition, its own propagated uncertainty, on
    average ``1 + lev`` times the noise's variance. A test set of whole measurements solves its own ``k_t``
    nuisance unknowns (centres, frames) on its ``n_t`` rows, which leaves ``dof_t = n_t - k_t`` degrees of freedom,
    and the fitted parameters' covariance adds ``propagated`` (:func:`~calibration.validation.heldout_residuals`:
    ``tr(P J C J^T P)``) to their sum of squares: ``lev = propagated / (dof_t s0^2)``. Held-out poses are predicted
    against their features as fitted on the design poses (``dof_t = n_t``), whose uncertainty adds too: ``lev`` is
    then the design rows' mean leverage ``(n - red) / n`` (``n`` design rows, ``red`` their redundancy, the prior's
    shrinkage included), the average prediction variance of a new row like them (also used, with the parameters'
    share ``(n - red - k) / n``, ``k`` the design's nuisance unknowns, when the covariance is not at hand). The
    instrument's frames and marker offsets a test set of whole measurements is predicted with (the design fit's,
    ``held`` unknowns, not solved on its rows) add their share of the design rows' leverage, ``held / n`` (their
    correlation with the parameters neglected). The
    test set is *worse than stated* when both

    * against the stated uncertainties, its sum of squares ``chi2_s`` over the rows that have one (not the lengths)
      is beyond a complete model's: ``chi2_s / (1 + lev)`` about chi-square with ``dof_s`` degrees of freedom, upper
      tail ``p_stated < alpha``;
    * against the design fit's own scatter (``s0`` times its weights: the stated uncertainties, or the noise the
      loop estimated from the data when they were off): ``F = chi2_t / (dof_t (1 + lev) s0^2)`` about
      ``F(dof_t, red)``, upper tail ``p_value < alpha``. This guards against stated uncertainties that are wrong
      (10 um stated on a robot with 0.2 mm scatter: every test set is "worse" than them), which the design fit's
      rule (:data:`S0_LIMIT`) reports; the first guards against a noise estimate low by chance.

    Without a stated uncertainty on any row, the second alone. Without the figures it needs (no redundancy, no
    degree of freedom left on the test set): None. The figures judged: :func:`judged`."""
    h, res = judged(stage), stage.result
    chi2, rows, nuis = h.get("chi2"), h.get("rows"), h.get("nuisance")
    red = getattr(res, "redundancy", None)
    red = float(res.dof if red is None else red)
    n = getattr(res, "n_residuals", None)
    if chi2 is None or rows is None or nuis is None or n is None or red <= 0 or not res.s0 > 0:
        return None
    by_meas = test_by == "measurement"
    dof_t = rows - nuis if by_meas else rows
    if dof_t <= 0:
        return None
    prop = h.get("propagated") if by_meas else None
    lev = (prop / (dof_t * res.s0 ** 2) if prop is not None else
           max(0.0, n - red - (res.n_nuisance if by_meas else 0)) / n) + (h.get("held", 0) / n if by_meas else 0.0)
    f = chi2 / (dof_t * (1.0 + lev) * res.s0 ** 2)
    p = f_upper_tail(f, dof_t, red)
    dof_s = (h.get("rows_stated") or 0) - (nuis if by_meas else 0)
    p_s = (float(stats.chi2.sf(h["chi2_stated"] / (1.0 + lev), dof_s))
           if h.get("chi2_stated") is not None and dof_s > 0 else None)
    return {"rows": int(rows), "dof": int(dof_t), "leverage": lev, "design_redundancy": red, "design_s0": float(res.s0),
            "rms_weighted": h.get("rms_weighted"), "ratio": math.sqrt(f), "p_value": p, "alpha": alpha,
            "rms_um": h.get("rms_um"), "rms_over_stated": h.get("rms_over_stated"),
            "ratio_stated": None if p_s is None else math.sqrt(h["chi2_stated"] / (dof_s * (1.0 + lev))),
            "p_stated": p_s, "worse_than_stated": p < alpha and (p_s is None or p_s < alpha),
            "stated_word": "stated" if h.get("sigmas_stated", True) else "default (not stated)"}


def _p(p: float) -> str:
    """A p-value as the verdict writes it (one below the smallest double written as such)."""
    return f"= {p:.2g}" if p > 0 else "< 1e-300"


def heldout_sentence(check: dict | None) -> str:
    """The verdict's sentence on an outer test set worse than stated (:func:`heldout_check`), else ""."""
    if not check or not check["worse_than_stated"]:
        return ""
    stated = ("" if check["p_stated"] is None else
              f"; {check['rms_over_stated']:.3g} times the {check.get('stated_word', 'stated')} uncertainties, "
              f"chi-square p {_p(check['p_stated'])}")
    return (f"The outer test set is worse than a complete model predicts: its residual (RMS {check['rms_um']:.4g} "
            f"um) is {check['ratio']:.3g} times what the design fit's scatter and the model's own uncertainty give "
            f"for it (F-test p {_p(check['p_value'])} < {check['alpha']:g}{stated}): the model lacks something that "
            "shows on data it was not fitted to. The model is not complete; no fix is claimed for it.")


def escalation_sentence(escalated: dict | None, added: list) -> str:
    """What the escalation offered (the opt-in families, when the outer test set was worse than stated after the
    default ones) and what of it was added; "" without escalation."""
    if not escalated:
        return ""
    mine = [n for n in added if n in escalated["candidates"]]
    return (f". The outer test set was worse than stated after the default families, so the opt-in famil"
            f"{'y' if len(escalated['families']) == 1 else 'ies'} {', '.join(escalated['families'])} "
            f"({len(escalated['candidates'])} candidates) were offered, kept by the same held-out rules: "
            + ("added " + ", ".join(mine) if mine else "none was added"))


#: why no effect is built from the residual when the outer test set is poses of the design's own measurements
NOT_BUILT_ON_POSES = ("effects are not built from the residual when the outer test set is poses of the measurements "
                      "the model is fitted to: no decision would see whether one carries over to other placements")


def builds_from_residual(settings, test_by: str) -> bool:
    """Whether the loop builds effects from the residual's structure: on (``settings.synthesise``) and an outer test
    set of whole measurements (placements, sessions), whose veto judges an effect where no decision looked. An effect
    built from one placement's residual is fitted to that placement's structure, and its held-out poses cannot show
    whether it carries over: on the real Panda seats trained on ``back-high`` (scripts/real_seats_study.py)
    ``harmonics panda_joint1 of q2 (h 1,2)`` passed that placement's held-out poses and the test poses and spread
    the ``front`` placement's seats from 1.44 / 1.97 to 3.04 / 2.77 mm (2 sigma, holes 0 / 1). The library's
    effects, physical hypotheses given before the data, are still tested there."""
    return bool(settings.synthesise) and test_by == "measurement"


def verdict_text(stages, significant, stop, settings, built=(), model: ArmModel | None = None, vetoed=(),
                 stated=None, heldout: dict | None = None, escalated: dict | None = None, test_by: str = "measurement"
                 ) -> str:
    """What was added (and how much the held-out error dropped), what passed the held-out folds but was not
    added because the outer test set got worse, what was built from the residual and not added (and why), and
    what structure remains unexplained. ``stated``: the user's stated uncertainties, against which the final
    residual is judged (:func:`residual_over_stated`); None: the final fit's own weights. ``heldout``: the judgement
    of the outer test set (:func:`heldout_check`): when it is worse than stated the verdict says so, and never
    "No structured residual remains". ``escalated``: the opt-in families offered (``families``, ``candidates``).
    ``test_by``: how the outer test set was held out (effects are built from the residual only with whole
    measurements, :func:`builds_from_residual`)."""
    def label(s):
        if any(cv.candidate == s.added.name and cv.reason.startswith(PHYSICS) for cv in s.cv):
            return " (included as physics, not for a held-out gain)"
        out = " (found from the residual)" if s.added.origin == RESIDUAL else ""
        if s.added.parts:
            out += " (a pair: each helps only with the other)"
        if s.tie:
            others = [t["name"] for t in s.tie["candidates"] if t["name"] != s.added.name]
            out += f" (tied on held-out data with {', '.join(others)}; chosen by the tie rule)"
        return out

    added = [s.added.name + label(s) for s in stages[1:]]
    s0, words = residual_over_stated(stages[-1].result, stated)
    out = ("effects added: " + ", ".join(added) if added else "no effect added")
    base, last = stages[0].heldout, stages[-1].heldout
    if added:
        out += (f"; held-out test RMS {base['rms_um']:.2f} -> {last['rms_um']:.2f} um, "
                f"max {base['max_um']:.2f} -> {last['max_um']:.2f} um")
    out += escalation_sentence(escalated, [s.added.name for s in stages[1:]])
    noise = estimated_words(stages[-1].result, stated)
    out += f". {noise}" if noise else ""
    tail = heldout_sentence(heldout)
    for v in vetoed:
        out += (f". Not added, the outer test set got worse with it: {v['name']} (RMS "
                f"{v['heldout_rms_before_um']:.2f} -> {v['heldout_rms_after_um']:.2f} um)")
    not_added = [b for b in built if not b["added"] and b["name"] not in {v["name"] for v in vetoed}]
    if not_added:
        out += (". Built from the residual, not supported, not added: "
                + "; ".join(f"{b['name']} ({b['why_not_added']})" for b in not_added))
    if not significant and s0 > S0_LIMIT:
        return out + (f". The final residual is {s0:.3g} times the stated uncertainties"
                      + (f" ({words})" if words else "") + ": it is not noise at the stated level, but no tested "
                      "regressor family explains it (wrong stated uncertainties, or structure beyond the tests). No "
                      "fix is claimed." + (" " + tail if tail else ""))
    if not significant and tail:
        return out + (". No regressor family is significant on the design fit's residual (after Bonferroni's "
                      "correction), but: " + tail[0].lower() + tail[1:])
    if not significant:
        return out + (". No structured residual remains (no regressor family is significant after Bonferroni's "
                      "correction).")
    fams = "; ".join(f"{f.name} ({t.best})" if t.best else f.name for f, t, _ in significant)
    nothing = []
    builds = builds_from_residual(settings, test_by)
    if builds and model is not None:
        nothing = [f.name for f, _, _ in significant if not synthesise([f.name], model)]
    why = (" (effects are not built from the residual: library only)" if not settings.synthesise else
           f" ({NOT_BUILT_ON_POSES})" if not builds else
           f" (no further effect is built for {', '.join(nothing)})" if nothing else "")
    built_by = " nor by the effects built from it" if not_added else ""
    return (out + f". Structured residual remains, not explained by the effect library{built_by}{why}: it "
            f"correlates with {fams}. No fix is claimed for it." + (" " + tail if tail else ""))
