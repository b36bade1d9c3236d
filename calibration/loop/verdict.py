"""The loop's verdict: a sentence saying what was added, what was built from the residual and not added (and
why), and what structure remains unexplained."""
from __future__ import annotations

import math

from arm_model.model import ArmModel

from ..synthesis import RESIDUAL, synthesise
from .settings import PHYSICS

__all__ = ["verdict_text", "residual_over_stated", "S0_LIMIT", "ADDED"]


#: residual standard deviation factor above which the residual is not noise at the stated level
S0_LIMIT = 3.0
#: the fate of a synthesised candidate that was added
ADDED = "added"


def residual_over_stated(result, stated=None) -> tuple[float, str]:
    """By how much the final fit's residual exceeds the *stated* uncertainties ``stated``
    (:class:`~calibration.data.Weights`), and the groups' figures as words.

    The fit's own ``s0`` is no measure of it when the loop re-estimated the noise from the data (a group's
    residual off its stated sigma by more than :data:`~calibration.loop.settings.NOISE_OFF`): its weights then
    are the residual's own scatter and ``s0`` is near 1 whatever the residual holds. So each row group whose
    noise the fit estimated gives its scatter against its stated sigma (``estimate_um / stated``), and the
    groups are pooled by their redundancy, as ``s0`` pools the rows; without a stated sigma or an estimated
    group, ``s0``."""
    groups = [v for v in getattr(result, "variance", None) or ()
              if v.get("estimated") and v.get("estimate_um") is not None and v.get("redundancy", 0) > 0
              and stated is not None and stated.sigma_of(v["group"])]
    if not groups:
        return float(result.s0), ""
    ratios = [v["estimate_um"] / (stated.sigma_of(v["group"]) * 1e6) for v in groups]
    red = [v["redundancy"] for v in groups]
    pooled = math.sqrt(sum(r * x * x for r, x in zip(red, ratios, strict=True)) / sum(red))
    words = ", ".join(f"{v['group']} {v['estimate_um']:.3g} um against the stated "
                      f"{stated.sigma_of(v['group']) * 1e6:.3g}" for v in groups)
    return pooled, words


def verdict_text(stages, significant, stop, settings, built=(), model: ArmModel | None = None, vetoed=(),
                 stated=None) -> str:
    """What was added (and how much the held-out error dropped), what passed the held-out folds but was not
    added because the outer test set got worse, what was built from the residual and not added (and why), and
    what structure remains unexplained. ``stated``: the user's stated uncertainties, against which the final
    residual is judged (:func:`residual_over_stated`); None: the final fit's own weights."""
    def label(s):
        if any(cv.candidate == s.added.name and cv.reason.startswith(PHYSICS) for cv in s.cv):
            return " (included as physics, not for a held-out gain)"
        return " (found from the residual)" if s.added.origin == RESIDUAL else ""

    added = [s.added.name + label(s) for s in stages[1:]]
    s0, words = residual_over_stated(stages[-1].result, stated)
    out = ("effects added: " + ", ".join(added) if added else "no effect added")
    base, last = stages[0].heldout, stages[-1].heldout
    if added:
        out += (f"; held-out test RMS {base['rms_um']:.2f} -> {last['rms_um']:.2f} um, "
                f"max {base['max_um']:.2f} -> {last['max_um']:.2f} um")
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
                      "fix is claimed.")
    if not significant:
        return out + (". No structured residual remains (no regressor family is significant after Bonferroni's "
                      "correction).")
    fams = "; ".join(f"{f.name} ({t.best})" if t.best else f.name for f, t, _ in significant)
    nothing = []
    if settings.synthesise and model is not None:
        nothing = [f.name for f, _, _ in significant if not synthesise([f.name], model)]
    why = (" (effects are not built from the residual: library only)" if not settings.synthesise else
           f" (no further effect is built for {', '.join(nothing)})" if nothing else "")
    built_by = " nor by the effects built from it" if not_added else ""
    return (out + f". Structured residual remains, not explained by the effect library{built_by}{why}: it "
            f"correlates with {fams}. No fix is claimed for it.")
