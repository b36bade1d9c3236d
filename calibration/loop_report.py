"""Outputs of the closed loop: the model file (description, effects, covariance, URDF), ``summary.json`` (for machines),
``report.html`` with PNG plots (for people; the model discrepancy's section and plot are calibrate's:
:func:`calibration.report.discrepancy_html`) and the before/after table printed by ``aacmm close-loop``. Every file is
written atomically and refused if it would overwrite an input."""
from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from arm_model import reports
from arm_model.checks import warnings_html
from arm_model.io import atomic_write_bytes, atomic_write_text, guard_output, json_text
from arm_model.shipped import provenance

from .loop import LoopResult, Stage, effect_summary
from .model_output import (
    calibrated_name,
    drift_text,
    model_check,
    model_paths,
    session_drift,
    without_session_effects,
    write_model,
)
from .report import (
    conformance_html,
    conformance_pngs,
    discrepancy_html,
    discrepancy_pngs,
    write_conformance_pngs,
    write_discrepancy_png,
)
from .validation import with_u

__all__ = ["summary_dict", "before_after_text", "write_loop_report", "write_loop_model", "loop_model_name",
           "plot_signature", "plot_screening", "plot_before_after"]

#: columns of the before/after table: key, header, unit
TABLE = (("rms_um", "RMS", "um"), ("max_um", "max", "um"), ("length_error_max", "length max", "um"),
         ("length_error_rms", "length RMS", "um"), ("articulation_2rms", "artic. 2RMS", "um"),
         ("sphere_diameter_error_max", "sphere diam.", "um"), ("ring_diameter_error_max", "ring diam.", "um"),
         ("flatness_max", "flatness", "um"), ("reference_rms_predicted", "ref. RMS", "um"),
         ("pose_rms", "pose RMS", "um"))


#: the held-out figures of a stage that the summary repeats per added effect
HELDOUT_KEYS = ("rms_um", "u_rms_um", "max_um", "u_max_um", "standard", "u_standard", "flagged_points",
                "rms_um_unflagged", "max_um_unflagged")


def _num(v):
    if v is None:
        return None
    if isinstance(v, (np.floating, np.integer)):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _clean(o):
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    if isinstance(o, (float, np.floating, np.integer)):
        return _num(o)
    return o


def _counts(data) -> dict:
    """``points`` (the distinct readings a fit counts, a repeated one once) and ``rows`` (the points files' rows) of
    ``data`` (:meth:`~calibration.data.CalibrationData.counts`)."""
    c = data.counts()
    return {"points": c["n_points"], "rows": c["n_rows"]}


def _stage_dict(s: Stage) -> dict:
    r = s.result
    out = {"stage": s.index, "model_effects": [e.describe() for e in s.model.effects],
           "fit": {"s0": r.s0, "dof": r.dof, **_counts(r.data), "status": r.status, "noise": r.weights_dict(),
                   "fixed": [f.to_dict() for f in r.fixed]},
           "heldout_test": s.heldout}
    if s.added is not None:
        out["added"] = {"name": s.added.name, "family": s.added.family, "joint": s.added.joint,
                        "origin": s.added.origin, "effect": "; ".join(e.describe() for e in s.added.effects),
                        "pair_of": [c.name for c in s.added.parts] or None,
                        "parameters": effect_summary(r, s.added),
                        "indistinguishable_nested": s.nested, "indistinguishable_alternatives": s.alternatives,
                        "tie": s.tie}
        out["screening"] = [t.to_dict() for t in s.screening]
        out["cross_validation"] = [c.to_dict() for c in s.cv]
    return out


def summary_dict(loop: LoopResult, inputs: dict | None = None) -> dict:
    """Everything of the report for machines (SI values, display values where named so)."""
    base = loop.stages[0].heldout
    effects = []
    prev = base
    for s in loop.stages[1:]:
        effects.append({"name": s.added.name, "family": s.added.family, "joint": s.added.joint,
                        "origin": s.added.origin,
                        "found_from_the_residual": s.added.origin == "residual",
                        "parameters": effect_summary(s.result, s.added),
                        "heldout_before": {k: prev[k] for k in HELDOUT_KEYS},
                        "heldout_after": {k: s.heldout[k] for k in HELDOUT_KEYS},
                        "indistinguishable_from": s.nested + [a for a in s.alternatives if a not in s.nested],
                        "pair_of": [c.name for c in s.added.parts] or None, "tie": s.tie})
        prev = s.heldout
    return _clean({
        "inputs": inputs or {},
        "arm": loop.desc.name,
        "settings": loop.settings.to_dict(),
        "base_effects": [e.describe() for e in loop.stages[0].model.effects],
        "estimation": {"prior_scale": _prior_used(loop.stages[0].result)},
        "measurements": {"design": loop.design, "test": loop.test, "test_by": loop.test_by},
        "decision_power": loop.power,
        "candidates": [{"name": c.name, "family": c.family, "joint": c.joint, "effect": c.effect.describe(),
                        "origin": c.origin} for c in loop.candidates],
        "skipped_candidates": [{"name": s.name, "reason": s.reason} for s in loop.skipped],
        "effects_added": effects,
        "before_after": loop.before_after(),
        "stages": [_stage_dict(s) for s in loop.stages],
        "final_screening": [t.to_dict() for t in loop.final_screening],
        "final_cross_validation": [c.to_dict() for c in loop.final_cv],
        "stop_reason": loop.stop_reason,
        "outliers_dropped": loop.dropped,
        "test_outliers_flagged": loop.flagged,
        "structure_tests": [{**t.to_dict(), "family": f.name, "description": f.what, "p_value_holm": a}
                            for f, t, a in loop.structure],
        "structure_remains": bool(loop.remaining),
        "residual_over_stated": loop.residual_over_stated,
        "heldout_check": loop.heldout_check,
        "heldout_worse_than_stated": None if loop.heldout_check is None else loop.heldout_check["worse_than_stated"],
        "escalation": None if loop.escalated is None else {
            "families": loop.escalated["families"], "candidates": loop.escalated["candidates"],
            "added": [c.name for c in loop.added if c.name in loop.escalated["candidates"]],
            "check": loop.escalated["check"]},
        "remaining_structure": [{"family": f.name, "best_regressor": t.best, "p_value_holm": a,
                                 "explained_heldout": t.explained_cv} for f, t, a in loop.remaining],
        "built_from_residual": loop.built,
        "vetoed_by_outer_test": loop.vetoed,
        "verdict": loop.verdict,
    })


def _heldout_html(check: dict | None) -> str:
    """The report's paragraph on the outer test set's judgement (:func:`calibration.loop.verdict.heldout_check`)."""
    if check is None:
        return "<p>Outer test set: too few degrees of freedom to judge it against the fit's scatter.</p>"
    stated = ("" if check["rms_over_stated"] is None else
              f", {check['rms_over_stated']:.3g} times the {check.get('stated_word', 'stated')} uncertainties")
    word = ("<b>worse than a complete model predicts</b>" if check["worse_than_stated"]
            else "as a complete model predicts")
    return (f"<p>Outer test set of the final model: {word}: its residual (RMS {check['rms_um']:.4g} um{stated}) is "
            f"{check['ratio']:.3g} times what the design fit's scatter and the model's own uncertainty give for it "
            f"({check['dof']} degrees of freedom, F-test p = {check['p_value']:.2g}"
            + ("" if check["p_stated"] is None else f"; against the {check.get('stated_word', 'stated')} "
               "uncertainties chi-square p = "
               f"{check['p_stated']:.2g}") + f", level {check['alpha']:g}).</p>")


def before_after_text(loop: LoopResult) -> str:
    """The before/after table on the outer test set (fixed-width text)."""
    rows = loop.before_after()
    cols = [(k, h, u) for k, h, u in TABLE if any(k in r for r in rows)]
    name_w = max(len("model"), *(len(r["model"]) for r in rows))
    w = 16
    head = f"{'model':<{name_w}}  " + "  ".join(f"{h:>{w}}" for _, h, _ in cols)
    units = f"{'':<{name_w}}  " + "  ".join(f"{'[' + u + ']':>{w}}" for _, _, u in cols)
    what = (f"{len(loop.test)} measurements no model of this table was fitted to" if loop.test_by == "measurement"
            else "poses of each feature no model of this table was fitted to, each predicted against its "
            "feature's centre fitted on the design poses")
    what += "; an effect that makes it worse is not added"
    lines = [f"held-out test set: {what} (rows: {loop.stages[0].heldout.get('headline_rows', '')}); "
             "± the standard uncertainty of each figure (bootstrap over the test measurements)", head, units]
    for r in rows:
        lines.append(f"{r['model']:<{name_w}}  " + "  ".join(
            f"{with_u(r[k], r.get('u', {}).get(k)):>{w}}" if k in r and r[k] is not None else f"{'-':>{w}}"
            for k, _, _ in cols))
    if len(rows) > 1:
        lines.append(f"RMS ratio base / final: {rows[0]['rms_um'] / rows[-1]['rms_um']:.2f}")
    if loop.flagged and rows[0].get("rms_um_unflagged") is not None:
        ids = ", ".join(dict.fromkeys(str(e["measurement"]) for e in loop.flagged))
        lines.append(f"{len(loop.flagged)} test point(s) flagged by the point test under the base model ({ids}) are in "
                     "every figure above; without them, RMS " + " -> ".join(
                         f"{r['rms_um_unflagged']:.2f}" for r in rows) + " um, max " + " -> ".join(
                         f"{r['max_um_unflagged']:.2f}" for r in rows) + " um")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------
# plots

#: the close-loop report's figures are drawn at a lower resolution than the other reports' (reports.DPI)
_DPI = 100


def _plot_unit(unit: str) -> tuple[str, float]:
    return {"rad": ("arcsec", 180 / math.pi * 3600), "m": ("um", 1e6), "1": ("ppm", 1e6)}.get(unit, (unit, 1.0))


def plot_signature(before: dict | None, after: dict | None, title: str) -> bytes:
    """PNG: binned estimates of a family (error bars 2u) and its fitted curve, at the previous fit and after
    the effect was added (field families: one panel per direction; groups: one bar per group)."""
    data = [(lab, d) for lab, d in (("before", before), ("after", after)) if d is not None]
    first = data[0][1]
    if first["kind"] == "groups":
        fig, axs = reports.figure(10, 3.2, cols=1)
        ax = axs[0, 0]
        for k, (lab, d) in enumerate(data):
            x = np.arange(len(d["names"])) + (k - 0.5 * (len(data) - 1)) * 0.35
            ax.errorbar(x, np.asarray(d["value"]) * 1e6, yerr=2 * np.asarray(d["u"]) * 1e6, fmt="o", ms=3,
                        label=lab, capsize=2)
        names = first["names"]
        step = max(1, len(names) // 40)
        ax.set_xticks(np.arange(len(names))[::step])
        ax.set_xticklabels(names[::step], rotation=90, fontsize=7)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel("offset [um] (2u bars)")
        ax.legend(fontsize=8)
        ax.set_title(title, fontsize=10)
        return reports.png(fig, _DPI)
    nd = len(first["directions"])
    fig, axs = reports.figure(4.2 * nd, 3.2, cols=nd)
    colours = {"before": "tab:red", "after": "tab:blue"}
    for j, (dname, dunit) in enumerate(first["directions"]):
        ax = axs[0, j]
        pu, pf = _plot_unit(dunit)
        for lab, d in data:
            x = np.asarray(d["centres"]) * d["factor"]
            v, u = np.asarray(d["value"][j]) * pf, np.asarray(d["u"][j]) * pf
            ok = np.isfinite(v)
            ax.errorbar(x[ok], v[ok], yerr=2 * u[ok], fmt="o", ms=4, capsize=2, color=colours[lab],
                        label=f"{lab}: binned estimate")
            xs = np.asarray(d["variable"]) * d["factor"]
            order = np.argsort(xs)
            curve = np.asarray(d["curve"])[:, j] * pf
            ax.plot(xs[order], curve[order], "-", lw=1, color=colours[lab], alpha=0.7, label=f"{lab}: fitted")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(f"{first['label']} [{first['unit']}]")
        ax.set_ylabel(f"{dname} error [{pu}]")
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return reports.png(fig, _DPI)


def plot_screening(tests, title: str, gate: float | None = None) -> bytes:
    """PNG: -log10(p) of each candidate's score test (absorbed candidates grey at 0)."""
    tests = list(tests)[:30]
    fig, axs = reports.figure(7, 0.25 * len(tests) + 1.2, cols=1)
    ax = axs[0, 0]
    y = np.arange(len(tests))[::-1]
    vals = [-math.log10(max(t.p_value, 1e-300)) if t.identifiable and math.isfinite(t.p_value) else 0.0
            for t in tests]
    ax.barh(y, vals, color=["tab:orange" if t.identifiable else "0.7" for t in tests])
    ax.set_yticks(y)
    ax.set_yticklabels([t.name + ("" if t.identifiable else " (absorbed)") for t in tests], fontsize=7)
    if gate:
        ax.axvline(-math.log10(gate), color="k", ls="--", lw=0.8, label=f"screening gate p = {gate:.2g}")
        ax.legend(fontsize=7)
    ax.set_xlabel("-log10(p) of the score test")
    ax.set_title(title, fontsize=10)
    return reports.png(fig, _DPI)


def plot_before_after(loop: LoopResult) -> bytes:
    """PNG: held-out test-set figures of every stage."""
    rows = loop.before_after()
    keys = [(k, h) for k, h, _ in TABLE if all(k in r and r[k] is not None for r in rows)]
    fig, axs = reports.figure(1.4 * len(keys) * max(len(rows), 2) / 2 + 2, 3.2, cols=1)
    ax = axs[0, 0]
    w = 0.8 / len(rows)
    for i, r in enumerate(rows):
        ax.bar(np.arange(len(keys)) + i * w, [r[k] for k, _ in keys], w, label=r["model"])
    ax.set_xticks(np.arange(len(keys)) + 0.4 - w / 2)
    ax.set_xticklabels([h for _, h in keys], fontsize=8)
    ax.set_ylabel("um")
    ax.set_title("held-out test set, stage by stage", fontsize=10)
    ax.legend(fontsize=7)
    return reports.png(fig, _DPI)


# ---------------------------------------------------------------------------------------------------
# HTML

def _g(v, fmt=".3g"):
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def _screening_rows(tests):
    return [(t.name, t.k, t.rank, _g(t.delta_chi2, ".1f"), _g(t.p_value, ".2g"), _g(t.delta_bic, ".1f"),
             _g(t.explained_cv, ".3f"), ", ".join(t.absorbed) or "") for t in tests]


_SCREEN_HEAD = ("candidate", "k", "rank", "delta chi2", "p (score F)", "delta BIC", "explained (held-out)",
                "absorbed parameters")
_CV_HEAD = ("candidate", "weighted RMS before", "after", "improvement", "Wilcoxon p", "threshold",
            "folds better", "measurements improved", "passed", "reason")


def _cv_rows(cvs):
    return [(c.candidate, _g(c.rms_base, ".4g"), _g(c.rms_new, ".4g"), _g(100 * c.improvement, ".1f") + " %",
             _g(c.p_value, ".2g"), _g(c.threshold, ".2g"), _stability_cell(c), f"{c.wins} / {c.n_measurements}",
             "yes" if c.passed else "no", c.reason) for c in cvs]


def _stability_cell(c) -> str:
    """The stability rule's figure of a held-out test: the folds whose held-out RMS it lowers, of all."""
    if not c.fold_change:
        return "-"
    return f"{sum(1 for v in c.fold_change if v > 0)} / {len(c.fold_change)}"


def loop_model_name(loop: LoopResult) -> str:
    """Name of the loop's model file (without ``.toml``): ``<arm>-calibrated``."""
    return calibrated_name(loop.desc.name)


def write_loop_model(loop: LoopResult, out_dir, inputs=()) -> dict:
    """The final model of the loop (every effect added, calibrated on every point: ``loop.model_fit``, or
    the last fit on the design set if absent) as a model file, covariance file and URDF
    (:mod:`calibration.model_output`)."""
    res = loop.model_fit or loop.final.result
    added = [s.added.name for s in loop.stages[1:] if not any(e.session for e in s.added.effects)]
    comment = (f"Model of '{loop.desc.name}' found by aacmm close-loop: the description with the final fit's values "
               f"folded in and the effects " + (f"added ({', '.join(added)})" if added else "of the base model")
               + f" with their parameters.\nFitted on {len(res.data)} points ({_fitted_on(loop)}); s0 = "
               f"{res.s0:.4g}. Read by every --arm option; format: docs/formats.md, "
               "'The model file'.")
    return write_model(res, out_dir, loop_model_name(loop), inputs=inputs, written_by="aacmm close-loop",
                       comment=comment)


def _fitted_on(loop: LoopResult) -> str:
    """What the model written was fitted on, in words."""
    if loop.model_fit is None:
        return "the design set"
    return ("every point, design and test" if loop.settings.test_in_model else
            "every point but the held-out test set's (--holdout)")


def _pair_tie_html(s) -> str:
    """The report's lines on a stage's pair (added together) and tie (chosen by the tie rule)."""
    parts = []
    if s.added.parts:
        parts.append("<p>A pair, added together: " + html.escape(", ".join(c.name for c in s.added.parts))
                     + " (each significant given the other, better on the held-out folds than either alone).</p>")
    if s.tie:
        parts.append(f"<p>A tie: the held-out units did not tell these candidates apart; chosen "
                     f"{html.escape(s.tie['chosen'])} by the tie rule ({html.escape(s.tie['rule'])}).</p>"
                     + reports.html_table(("candidate", "parameters", "score p", "held-out RMS lower [%]",
                                           "Wilcoxon p", "paired p (worse than the held-out best)"),
                                          [(t["name"], t["parameters"], _g(t["score_p_value"], ".2g"),
                                            _g(100 * t["relative_improvement"], ".1f"),
                                            _g(t["wilcoxon_p_value"], ".2g"),
                                            "-" if t["paired_p_value"] is None else _g(t["paired_p_value"], ".2g"))
                                           for t in s.tie["candidates"]]))
    return "".join(parts)


def write_loop_report(loop: LoopResult, out_dir, inputs=(), input_names: dict | None = None,
                      warnings=(), conformance: dict | None = None, plots: bool = True) -> list[Path]:
    """Write the model file (:func:`write_loop_model`), ``summary.json``, ``report.html``,
    ``before-after.txt`` and the PNGs into ``out_dir`` (atomically, never over ``inputs``); returns the
    paths written. ``conformance``: the standard tests (:func:`calibration.cli.conformance_entry`), written
    as ``calibrate`` writes them (summary key ``conformance``, ``conformance_*.png``, a report section).
    ``plots``: False (``--no-plots``), no PNG is drawn and the report holds the tables alone."""
    out = Path(out_dir)
    inputs = [Path(p) for p in inputs]
    conf_files = conformance_pngs(conformance, out) if conformance and plots else {}
    fit = loop.model_fit or loop.final.result
    final = without_session_effects(fit)                   # the fit the model file is written from
    drift = session_drift(fit)
    disc_files = discrepancy_pngs(final, out) if plots else {}
    for name in ("summary.json", "report.html", "before-after.txt", *model_paths(out, loop_model_name(loop)).values(),
                 *(f.name for f in conf_files.values()), *(f.name for f in disc_files.values())):
        guard_output(out / name, inputs)
    model_files = write_loop_model(loop, out, inputs)
    written = list(model_files.values())

    def img(name, draw, *args) -> str:
        """``<img>`` of the plot ``draw(*args)`` written as ``name`` ("" without plots: nothing drawn)."""
        if not plots:
            return ""
        written.append(atomic_write_bytes(out / name, draw(*args), inputs))
        return f"<img src='{name}'>"

    sections = []
    table = before_after_text(loop)
    sections.append(f"<h2>Verdict</h2><p>{html.escape(loop.verdict)}</p><p>Stopped: "
                    f"{html.escape(loop.stop_reason)}.</p>{_heldout_html(loop.heldout_check)}"
                    "<h2>Before and after (held-out test set)</h2>"
                    f"<pre>{html.escape(table)}</pre>" + img("before-after.png", plot_before_after, loop))
    if loop.built:
        sections.append("<h2>Effects built from the residual</h2>" + reports.html_table(
            ("effect", "family", "added", "why not"),
            [(b["name"], b["family"], "yes" if b["added"] else "no", b["why_not_added"] or "") for b in loop.built]))
    for s in loop.stages[1:]:
        gate = loop.settings.screen_alpha / max(sum(t.identifiable for t in s.screening), 1)
        found = " (found from the residual)" if s.added.origin == "residual" else ""
        parts = [f"<h2>Stage {s.index}: + {html.escape(s.added.name)}{found}</h2>"]
        prm = effect_summary(s.result, s.added)
        parts.append(reports.html_table(("parameter", "value", "u (1 sigma)", "unit", "state"),
                            [(r["name"], _g(r["display_value"], ".5g"), _g(r["display_u"], ".2g"), r["display_unit"],
                              r["state"] + (f", phase {r['phase_deg']:.1f} deg" if "phase_deg" in r else ""))
                             for r in prm]))
        parts.append(_pair_tie_html(s))
        if s.nested or s.alternatives:
            parts.append("<p>The data cannot tell it from: "
                         + html.escape(", ".join(dict.fromkeys(s.nested + s.alternatives)))
                         + " (same residual signature).</p>")
        parts.append("<h3>Screening at the previous fit</h3>"
                     + reports.html_table(_SCREEN_HEAD, _screening_rows(s.screening)))
        parts.append(img(f"stage-{s.index}-screening.png", plot_screening, s.screening, f"stage {s.index}: screening",
                         gate))
        parts.append("<h3>Cross-validation (held-out folds of the design set)</h3>"
                     + reports.html_table(_CV_HEAD, _cv_rows(s.cv)))
        if s.plot_before is not None and plots:
            parts.append("<h3>The residual that led to it</h3>" + img(
                f"stage-{s.index}-signature.png", plot_signature, s.plot_before, s.plot_after,
                f"{s.plot_family}: before and after + {s.added.name}"))
        sections.append("".join(parts))
    if drift:
        sections.append("<h2>The session's drift (not in the model file)</h2><p>" + html.escape(drift_text(drift))
                        + "</p>")
    sections.append(_final_html(loop, img))
    if conformance:
        written += write_conformance_pngs(conformance, conf_files, inputs) if plots else []
        sections.append("".join(conformance_html(conformance, conf_files)))
    written += write_discrepancy_png(final, disc_files, inputs)
    sections.append("".join(discrepancy_html(final, disc_files)))
    page = ("<!doctype html><html><head><meta charset='utf-8'><title>close-loop report</title><style>"
            "body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse;font-size:12px}"
            "td,th{border:1px solid #ccc;padding:2px 6px}pre{background:#f6f6f6;padding:6px}</style></head><body>"
            f"<h1>Closing the loop: {html.escape(loop.desc.name)}</h1>" + warnings_html(warnings)
            + "".join(sections) + "</body></html>")
    summary = summary_dict(loop, input_names)
    summary["warnings"] = [w.as_dict() for w in warnings]
    poses = model_files.get("training_poses")
    summary["model"] = {"file": model_files["model"].name, "covariance": model_files["covariance"].name,
                        "urdf": model_files["urdf"].name, "check": model_check(final),
                        "training_poses": None if poses is None else poses.name,
                        "model_discrepancy": None if final.discrepancy is None else final.discrepancy.to_dict(),
                        "region_effect": None if final.region is None else final.region.to_dict(),
                        "fitted_on": _fitted_on(loop), **_counts(final.data), "session_drift": drift}
    summary["reference_frame"] = final.reference_frame()
    if conformance:
        summary["conformance"] = conformance
    summary.update(provenance(inputs))
    written.append(atomic_write_text(out / "summary.json", json_text(summary), inputs))
    written.append(atomic_write_text(out / "before-after.txt", table + "\n", inputs))
    written.append(atomic_write_text(out / "report.html", page, inputs))
    return written


def _final_html(loop: LoopResult, img) -> str:
    """The report's section on the final fit (its screening, cross-validation, structure tests and the candidates
    not offered); ``img(name, draw, *args)`` writes the plot ``draw(*args)`` and returns its ``<img>`` ("" without
    plots)."""
    parts = ["<h2>Final screening</h2>"]
    if loop.final_screening:
        parts.append(reports.html_table(_SCREEN_HEAD, _screening_rows(loop.final_screening)))
        gate = loop.settings.screen_alpha / max(sum(t.identifiable for t in loop.final_screening), 1)
        parts.append(img("final-screening.png", plot_screening, loop.final_screening, "final screening", gate))
    if loop.final_cv:
        parts.append("<h3>Cross-validation</h3>" + reports.html_table(_CV_HEAD, _cv_rows(loop.final_cv)))
    parts.append("<h2>Structure tests on the final fit</h2>")
    parts.append(reports.html_table(("family", "columns", "rank", "delta chi2", "p", "p (Holm)", "explained (held-out)",
                         "best regressor", "what"),
                        [(f.name, t.k, t.rank, _g(t.delta_chi2, ".1f"), _g(t.p_value, ".2g"), _g(a, ".2g"),
                          _g(t.explained_cv, ".3f"), t.best, f.what) for f, t, a in loop.structure]))
    for name, d in loop.structure_plots.items():
        parts.append(img(f"structure-{_slug(name)}.png", plot_signature, d, None, f"remaining structure: {name}"))
    if loop.skipped:
        parts.append("<h3>Candidates not offered</h3>" + reports.html_table(("candidate", "why"),
                                                               [(s.name, s.reason) for s in loop.skipped]))
    return "".join(parts)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in name).strip("-").lower()


def _prior_used(res) -> str | float | None:
    """The prior scale the loop's fits used (``--prior-scale auto`` resolved): "evidence", a factor or None."""
    return None if res.options is None else res.options.prior_scale
