"""Reports of the ring-gauge pipeline: PNG figures (matplotlib, Agg), an HTML page, CSV tables and a
``summary.json`` with the same figures for machines.

* :func:`ring_report` (``aacmm ring``): a ring-gauge campaign, every model side by side.
* :func:`paper_report` (``aacmm paper``): the seed paper's Tables 1-3 reproduced from its own data and
  budgets, with the loop closed on its Table 2.

Everything is computed before anything is written; each file is written atomically and never over an
input. Lengths are reported in mm (and µm in the point-error figure), forces in N.
"""
from __future__ import annotations

import html
import io
import json
import math
from pathlib import Path

import numpy as np

from arm_model import reports
from arm_model.checks import warnings_html
from arm_model.io import atomic_write_bytes, atomic_write_text, guard_output
from arm_model.shipped import provenance

from . import paper as P
from .correlation import FORCE_VALUES, campaign_correlations
from .gum import BudgetResult, ring_budget
from .models import MODEL_LABELS, RingCampaign, campaign_summary, table2

__all__ = ["ring_budgets", "ring_report", "paper_report", "ring_summary", "paper_summary",
           "DEFAULT_U_FORCE", "roundness_data", "roundness_models"]

#: standard uncertainty of a measured force [N] when none is given: the paper's bending sensor, its
#: Table 1 terms combined (0.0723 N; the table misprints 0.00723)
DEFAULT_U_FORCE = 0.0723

_COLOURS = {"initial": "#444444", "point": "#1f77b4", "mean": "#17becf", "max": "#d62728", "max10": "#ff7f0e",
            "wrench": "#2ca02c", "point_force": "#1f77b4", "mean_force": "#17becf", "max_force": "#d62728",
            "max10_force": "#ff7f0e"}
_T2_LABELS = {"point_force": "point force", "mean_force": "mean force", "max_force": "max force",
              "max10_force": "10Max force"}


def _num(x):
    if x is None:
        return None
    if isinstance(x, (np.floating, float)):
        x = float(x)
        return x if math.isfinite(x) else ("inf" if x > 0 else ("-inf" if x < 0 else None))
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.ndarray):
        return [_num(v) for v in x.tolist()]
    if isinstance(x, (list, tuple)):
        return [_num(v) for v in x]
    if isinstance(x, dict):
        return {k: _num(v) for k, v in x.items()}
    return x


# ---------------------------------------------------------------------------------------------
# ring campaigns

def ring_budgets(campaign: RingCampaign, u_force: float = DEFAULT_U_FORCE, u_ring_form: float | None = None,
                 delta_t: float = 0.5, u_alpha: float = 1e-6, resolution: float = 1e-7,
                 probability: float = 95.0, u_ring: float | None = None) -> list[BudgetResult]:
    """The paper's Table 3 for every model of a campaign: diameter and form error budgets.

    Args:
        u_force: standard uncertainty of a measured force [N]; u_cor = 2 c u_force [m].
        u_ring_form: standard uncertainty of the ring's form [m]; None: its certified form error as the
            half-width of a rectangular distribution (the paper used CMM repetitions instead), or no term
            when the artefacts file gives no form error.
        u_ring: the ring diameter's standard uncertainty [m]; None takes ``u_diameter`` of the artefact (no
            term when it has none).
        delta_t [C], u_alpha [1/C], resolution [m], probability [%]: see :func:`correction.gum.ring_budget`.
    """
    out = []
    u_cor = 2 * campaign.compliance * u_force
    if u_ring is None:
        u_ring, ring_src = campaign.u_diameter, "certificate (artefacts file u_diameter)"
    else:
        ring_src = "given"
    form_half = None            # the ring's certified form error, taken as a rectangular half-width
    if u_ring_form is None and campaign.reference_form_error is not None:
        form_half = campaign.reference_form_error
        form_src = (f"ring form error {form_half * 1e3:g} mm as a rectangular half-width a, a/sqrt(3)")
    else:
        form_src = "given"
    for m in campaign.models:
        cor = None if m == "initial" else u_cor
        d = campaign.column(m, "diameter")
        f = campaign.column(m, "form_error")
        out.append(ring_budget(f"diameter, {MODEL_LABELS[m]}", d, float(np.mean(d)), u_ring, cor,
                               delta_t=delta_t, u_alpha=u_alpha, resolution=resolution, probability=probability,
                               u_ring_source=ring_src).evaluate())
        out.append(ring_budget(f"form error, {MODEL_LABELS[m]}", f, float(np.mean(f)), u_ring_form, cor,
                               delta_t=delta_t, u_alpha=u_alpha, resolution=resolution, probability=probability,
                               u_ring_source=form_src, ring_half_width=form_half).evaluate())
    return out


def ring_summary(campaign: RingCampaign, budgets: list[BudgetResult], inputs: dict) -> dict:
    """The machine-readable summary of a ring campaign (what ``summary.json`` holds), lengths in mm."""
    meas = []
    for r in campaign.measurements:
        meas.append({
            "measurement": r.id, "n_points": r.n_points,
            "forces_N": {"mean": r.summary.mean, "max10": r.summary.max10, "max": r.summary.max},
            "models": {m: {"diameter_mm": f.diameter * 1e3, "diameter_error_mm": f.diameter_error * 1e3,
                           "form_error_mm": f.form_error * 1e3,
                           "rows": [{"height_mm": row["height"] * 1e3, "diameter_mm": row["diameter"] * 1e3,
                                     "form_error_mm": row["form_error"] * 1e3} for row in f.rows()]}
                       for m, f in r.fits.items()},
        })
    corr = [c.as_dict() for c in campaign_correlations(campaign, "initial")]
    return _num({
        "inputs": inputs, "feature": campaign.feature,
        "reference_diameter_mm": None if campaign.reference_diameter is None else campaign.reference_diameter * 1e3,
        "ball_diameter_mm": campaign.ball_diameter * 1e3, "paper_compliance_mm_per_N": campaign.compliance * 1e3,
        "force_kind": campaign.force_kind, "models": {m: MODEL_LABELS[m] for m in campaign.models},
        "summary": campaign_summary(campaign), "measurements": meas, "correlations": corr,
        "budgets": [b.as_dict() for b in budgets], "notes": list(campaign.notes)})


def roundness_models(c: RingCampaign) -> tuple:
    """The models of the polar roundness plots: the initial one and the corrected one (the full wrench
    when evaluated, else the paper's point-force model)."""
    corrected = next((m for m in ("wrench", "point") if m in c.models), None)
    return ("initial",) if corrected is None else ("initial", corrected)


def roundness_data(c: RingCampaign) -> dict:
    """What the polar roundness plots draw: ``{measurement: {model: (angle_deg, deviation_um)}}`` for
    the models of :func:`roundness_models`, each point's angular position about the fitted axis [deg] and
    its radial deviation from the fitted cylinder [µm] (outward positive: the fit's own residuals,
    ``arm_model.geometry.CylinderFit``; max - min is the form error), sorted by angle."""
    out = {}
    for r in c.measurements:
        out[r.id] = {}
        for m in roundness_models(c):
            cyl = r.fits[m].cylinder
            o = np.argsort(cyl.angles, kind="stable")
            out[r.id][m] = (np.degrees(cyl.angles[o]), cyl.residuals[o] * 1e6)
    return out


def roundness_csv(data: dict) -> dict:
    """Columns of ``roundness.csv``: one row a point and model of :func:`roundness_data`."""
    rows = [(mid, m, a, d) for mid, per in data.items() for m, (ang, dev) in per.items()
            for a, d in zip(ang, dev, strict=True)]
    return {"measurement": np.array([r[0] for r in rows], dtype=object),
            "model": np.array([r[1] for r in rows], dtype=object),
            "angle_deg": np.array([r[2] for r in rows], float),
            "radial_deviation_um": np.array([r[3] for r in rows], float)}


def _roundness_figure(c: RingCampaign, data: dict) -> bytes:
    """A grid of polar plots, one a measurement: the radial deviations of :func:`roundness_data` against
    angle, the fitted cylinder the dashed circle (deviation 0), one radial scale for all."""
    plt = reports.pyplot()
    models = roundness_models(c)
    n = len(data)
    cols = min(n, 4)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.3 * cols, 3.4 * rows + 0.4),
                             subplot_kw={"projection": "polar"}, squeeze=False)
    big = max((float(np.max(np.abs(dev))) for per in data.values() for _, dev in per.values()), default=0.0) or 1.0
    lo, hi = -1.5 * big, 1.15 * big
    ring = np.linspace(0, 2 * np.pi, 181)
    # the grid has up to cols - 1 cells more than measurements (hidden below): strict=False
    for ax, (mid, per) in zip(axes.flat, data.items(), strict=False):
        ax.plot(ring, np.zeros_like(ring), "--", lw=0.7, color="k")
        for m in models:
            ang, dev = per[m]
            ax.plot(np.radians(np.r_[ang, ang[:1]]), np.r_[dev, dev[:1]], ".-", ms=3, lw=0.8, color=_COLOURS[m],
                    label=f"{MODEL_LABELS[m]} (form {np.ptp(dev):.1f} µm)")
        ax.set_ylim(lo, hi)
        ax.set_rticks([round(v, 1) for v in (-big, 0.0, big)])
        ax.tick_params(labelsize=6)
        ax.set_title(mid, fontsize=9)
        ax.legend(fontsize=6, loc="lower center", bbox_to_anchor=(0.5, -0.32))
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.suptitle("Radial deviation from the fitted cylinder [µm] against angle (dashed: the fitted cylinder)",
                 fontsize=10)
    # a fixed layout in inches (each cell: the title and the 90 deg label above the plot, the 270 deg label and the
    # legend below it): laying out and cropping 17 polar plots from their drawn extents cost twice the drawing
    w, h = fig.get_figwidth(), fig.get_figheight()
    top, bottom, left, right, gap_h, gap_w = 1.0, 0.85, 0.4, 0.45, 1.2, 0.85      # [in]
    cell_h = (h - top - bottom - (rows - 1) * gap_h) / rows
    cell_w = (w - left - right - (cols - 1) * gap_w) / cols
    fig.subplots_adjust(left=left / w, right=1 - right / w, top=1 - top / h, bottom=bottom / h, wspace=gap_w / cell_w,
                        hspace=gap_h / cell_h)
    return reports.png(fig, crop=False)


def _ring_figures(c: RingCampaign, budgets) -> dict:
    plt = reports.pyplot()
    figs = {}
    ids = [r.id for r in c.measurements]
    x = np.arange(len(ids))
    models = c.models
    # 1. contact point errors vs angle (Figures 6 and 12) for the measurement with the largest initial error
    worst = max(c.measurements, key=lambda r: abs(r.fits["initial"].diameter_error))
    fig, ax = plt.subplots(figsize=(8, 4))
    for m in [mm for mm in ("initial", "point", "wrench") if mm in worst.fits]:
        f = worst.fits[m]
        o = np.argsort(f.angles_deg)
        style = {"initial": dict(marker="o", ms=3), "point": dict(marker="o", ms=6, mfc="none"),
                 "wrench": dict(marker="o", ms=2.5)}[m]
        ax.plot(f.angles_deg[o], f.point_errors[o] * 1e6, ls="none", color=_COLOURS[m], **style,
                label=f"{MODEL_LABELS[m]} (diameter error {f.diameter_error * 1e3:+.4f} mm)")
    ax.axhline(0, color="k", lw=0.6)
    ax.set(xlabel="angular position of the point [deg]", ylabel="contact point radial error [µm]",
           title=f"Contact point errors, measurement {worst.id} (0 = certified radius)", xlim=(0, 360))
    ax.legend(fontsize=8)
    figs["point_errors.png"] = reports.png(fig)
    # 2-3. diameter and form error per measurement (Figures 7, 8, 13, 14)
    for what, fname, title in (("diameter_error", "diameters.png", "Diameter error, initial and corrected"),
                               ("form_error", "form_errors.png", "Form error, initial and corrected")):
        fig, ax = plt.subplots(figsize=(9, 4))
        w = 0.8 / len(models)
        for k, m in enumerate(models):
            ax.bar(x + (k - (len(models) - 1) / 2) * w, c.column(m, what) * 1e3, w, color=_COLOURS[m],
                   label=MODEL_LABELS[m])
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks(x, ids, rotation=60 if len(ids) > 10 else 0, fontsize=7)
        ax.set(xlabel="measurement", ylabel=f"{what.replace('_', ' ')} [mm]", title=title)
        ax.legend(fontsize=8, ncol=3)
        figs[fname] = reports.png(fig)
    # 4. force values per measurement (Figure 9)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    for fv, mk in zip(FORCE_VALUES, ("o", "s", "^"), strict=True):
        ax.plot(x, c.force_values(fv), mk + "-", label={"mean": "mean", "max10": "10Max", "max": "max"}[fv])
    ax.set_xticks(x, ids, rotation=60 if len(ids) > 10 else 0, fontsize=7)
    ax.set(xlabel="measurement", ylabel="bending force [N]", title="Contact force values per measurement")
    ax.legend(fontsize=8)
    figs["forces.png"] = reports.png(fig)
    # 5-6. correlations (Figures 10, 11), with the (0, 0) reference point
    for what, fname in (("diameter_error", "correlation_diameter.png"), ("form_error", "correlation_form.png")):
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        y = c.column("initial", what) * 1e3
        corr = {k.x_name: k for k in campaign_correlations(c) if k.y_name == f"{what}_mm" and k.with_reference}
        for fv, mk in zip(FORCE_VALUES, ("o", "s", "^"), strict=True):
            xv = c.force_values(fv)
            cr = corr[f"{fv}_force_N"]
            line = ax.plot(np.r_[0, xv], np.r_[0, y], mk, ms=5,
                           label=f"{fv}: r = {cr.r:.3f}, R² = {cr.r2:.2f}")[0]
            xs = np.linspace(0, xv.max() * 1.05, 10)
            ax.plot(xs, cr.intercept + cr.slope * xs, "-", lw=0.8, color=line.get_color())
        ax.set(xlabel="force value [N]", ylabel=f"initial {what.replace('_', ' ')} [mm]",
               title=f"{what.replace('_', ' ').capitalize()} against force (with the 0 N, 0 mm point)")
        ax.legend(fontsize=8)
        figs[fname] = reports.png(fig)
    # 7. budgets: expanded uncertainty per model
    fig, ax = plt.subplots(figsize=(8, 3.5))
    names = [b.name for b in budgets]
    ax.barh(np.arange(len(names)), [b.U for b in budgets],
            color=["#1f77b4" if n.startswith("diameter") else "#ff7f0e" for n in names])
    ax.set_yticks(np.arange(len(names)), names, fontsize=7)
    ax.invert_yaxis()
    ax.set(xlabel=f"expanded uncertainty U ({budgets[0].probability:g} %) [mm]", title="Uncertainty budgets")
    figs["budgets.png"] = reports.png(fig)
    # 8. polar roundness plots, one a measurement
    figs["roundness.png"] = _roundness_figure(c, roundness_data(c))
    return figs


def _budget_html(b: BudgetResult) -> str:
    rows = [(t.name, t.type, t.distribution, "inf" if t.dof == math.inf else f"{t.dof:.0f}",
             t.sensitivity_label or f"{t.sensitivity:g}", f"{t.contribution:.3g}", t.source) for t in b.terms]
    rows += [("combined standard uncertainty", "", "", "", "", f"{b.u_c:.4g}", ""),
             ("effective degrees of freedom (Welch-Satterthwaite)", "", "", "", "",
              "inf" if b.dof == math.inf else f"{b.dof:.1f}", ""),
             (f"coverage factor k (Student t, {b.probability:g} %)", "", "", "", "", f"{b.k:.3f}", ""),
             ("expanded uncertainty U", "", "", "", "", f"{b.U:.4g}", "")]
    return (f"<h4>{html.escape(b.name)} [{html.escape(b.unit)}]</h4>"
            + reports.html_table(("term", "type", "distribution", "dof", "sensitivity", f"u [{b.unit}]", "from"), rows))


_CSS = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.85em}"
        "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}th{background:#eee}"
        "td:first-child{text-align:left}img{max-width:100%;margin:0.5em 0}.bad{color:#b00}.ok{color:#070}")


def _page(title: str, parts: list[str]) -> str:
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_CSS}</style></head><body><h1>{html.escape(title)}</h1>" + "\n".join(parts)
            + "</body></html>\n")


def _budget_csv(budgets) -> dict:
    rows = []
    for b in budgets:
        for t in b.terms:
            rows.append((b.name, t.name, t.type, t.distribution, t.u, t.sensitivity, t.dof, t.contribution, ""))
        rows.append((b.name, "combined", "", "", b.u_c, "", b.dof, b.u_c, ""))
        rows.append((b.name, "expanded", "", "", b.U, b.k, b.dof, b.U, f"k at {b.probability:g} %"))
    names = ("budget", "term", "type", "distribution", "u_mm", "sensitivity", "dof", "contribution_mm", "note")
    return {n: np.array([r[i] for r in rows], dtype=object) for i, n in enumerate(names)}


def _write_outputs(out: Path, files: dict, inputs) -> list[Path]:
    """Write {relative name: bytes | str} under ``out`` atomically; nothing over an input."""
    targets = [guard_output(out / name, inputs) for name in files]
    written = []
    for name, target in zip(files, targets, strict=True):
        data = files[name]
        if isinstance(data, str):
            atomic_write_text(target, data, inputs)
        else:
            atomic_write_bytes(target, data, inputs)
        written.append(target)
    return written


def _csv_text(columns: dict, fmt: str = "%.6f") -> str:
    """CSV text of {column: array} as ``write_csv`` formats it (floats with ``fmt``)."""
    import csv as _csv
    buf = io.StringIO()
    w = _csv.writer(buf, lineterminator="\n")
    names = list(columns)
    w.writerow(names)

    def cell(v):
        if isinstance(v, (float, np.floating)):
            return "inf" if v == math.inf else (fmt % v)
        return str(v)
    for i in range(len(next(iter(columns.values())))):
        w.writerow([cell(columns[n][i]) for n in names])
    return buf.getvalue()


def _ring_summary(campaign: RingCampaign, inputs: dict, budgets, warnings, point_uncertainty,
                  parameters_source) -> dict:
    """``summary.json`` of :func:`ring_report` (without its provenance)."""
    summary = ring_summary(campaign, budgets, {k: None if v is None else str(v) for k, v in inputs.items()})
    summary["warnings"] = [w.as_dict() for w in warnings]
    if point_uncertainty is not None:
        summary["diameter_uncertainty_from_points"] = {
            "method": "linear propagation of each corrected ball centre's covariance through the cylinder fit; "
                      "errors shared by the points (parameters, compliance) propagated jointly; k = 1",
            "parameters": parameters_source or "none (parameters taken as exact)",
            "measurements": [dict(measurement=r.id, **d.as_dict())
                             for r, (d, _) in zip(campaign.measurements, point_uncertainty, strict=True)]}
        summary["form_uncertainty_from_points"] = {
            "method": "the point errors sampled from the same covariances (shared errors once per sample), mapped "
                      "to the residuals through the refit to first order, max - min of each sample; u_form_mm: "
                      "their standard deviation (k = 1), inflation_mm: their mean minus the measured form error",
            "model": "wrench" if campaign.measurements and "wrench" in campaign.measurements[0].fits else "initial",
            "measurements": [dict(measurement=r.id, **f.as_dict())
                             for r, (_, f) in zip(campaign.measurements, point_uncertainty, strict=True)]}
    return summary


def _ring_tables_html(campaign: RingCampaign, summary: dict, t2: dict) -> list[str]:
    """The report's tables per model and per measurement."""
    s = summary["summary"]
    models = campaign.models
    parts = ["<h2>Summary per model</h2>" + reports.html_table(
        ("model", "mean |diameter error| [mm]", "reduction [%]", "mean form error [mm]", "form change [%]",
         "largest form increase [mm]"),
        [(MODEL_LABELS[m], f"{s[m]['mean_abs_diameter_error_mm']:.4f}", f"{s[m]['diameter_error_reduction_pct']:.1f}",
          f"{s[m]['mean_form_error_mm']:.4f}", f"{s[m]['form_error_change_pct']:+.1f}",
          f"{s[m]['max_form_error_increase_mm']:+.4f}") for m in models])]
    rows = []
    for i, r in enumerate(campaign.measurements):
        row = [r.id]
        for m in models:
            v = t2[f"diameter_error_{m}_mm"][i]
            row.append(f"{v:.4f}" if m == "initial" else f"{v:.4f} ({t2[f'improvement_{m}_pct'][i]:.0f})")
        rows.append(row)
    parts.append("<h2>Diameter error per measurement [mm] (improvement %)</h2>"
                 + reports.html_table(["measurement"] + [MODEL_LABELS[m] for m in models], rows))
    rows = [[r.id] + [f"{t2[f'form_error_{m}_mm'][i]:.4f}" for m in models] +
            [f"{r.summary.mean:.3f}", f"{r.summary.max10:.3f}", f"{r.summary.max:.3f}"]
            for i, r in enumerate(campaign.measurements)]
    parts.append("<h2>Form error [mm] and force values [N] per measurement</h2>"
                 + reports.html_table(["measurement"] + [MODEL_LABELS[m] for m in models]
                                      + ["mean F", "10Max F", "max F"], rows))
    return parts


def _ring_figures_html(campaign: RingCampaign, corr, plots: bool = True) -> list[str]:
    """The report's figures (none when not ``plots``), the correlations with the force and their table."""
    parts = []
    for name, cap in (("point_errors.png", "Contact point errors against angular position (paper Fig. 6, 12)"),
                      ("diameters.png", "Initial and corrected diameter errors (paper Fig. 13)"),
                      ("form_errors.png", "Initial and corrected form errors (paper Fig. 8, 14)"),
                      ("forces.png", "Force values (paper Fig. 9)")):
        if plots:
            parts.append(f"<h3>{html.escape(cap)}</h3><img src='figures/{name}' alt='{html.escape(cap)}'>")
    rm = roundness_models(campaign)
    parts.append("<h3>Roundness: radial deviations against angle, per measurement</h3>"
                 f"<p>Each point's radial deviation from the fitted cylinder (the fit's residual, outward positive; "
                 f"max - min is the form error) against its angle about the fitted axis, "
                 f"{' and '.join(MODEL_LABELS[m] for m in rm)}; the data are in roundness.csv.</p>"
                 + ("<img src='figures/roundness.png' alt='polar roundness plots'>" if plots else ""))
    parts.append("<h2>Correlation with the force (initial errors)</h2>" + reports.html_table(
        ("error", "force value", "with (0, 0)", "n", "Pearson r", "R²", "p", "slope [mm/N]"),
        [(k.y_name, k.x_name, "yes" if k.with_reference else "no", k.n, f"{k.r:.3f}", f"{k.r2:.3f}",
          f"{k.p_value:.2g}", f"{k.slope:.4f}") for k in corr]))
    if plots:
        parts.append("<img src='figures/correlation_diameter.png' alt='diameter error against force'>"
                     "<img src='figures/correlation_form.png' alt='form error against force'>")
    return parts


def _point_uncertainty_html(campaign: RingCampaign, point_uncertainty, parameters_source) -> str:
    """The diameter and form uncertainty from the points' covariances, as a section of the report."""
    return ("<h2>Diameter and form uncertainty from the points' covariances (k = 1, beside the GUM budgets)</h2>"
            f"<p>Parameters: {html.escape(parameters_source or 'none (taken as exact)')}. Each corrected "
            "ball centre's covariance is propagated through the cylinder fit; errors the points share "
            "(parameters, compliance) do not average out. 'if independent' is what the naive sum of "
            "independent point variances would give. The form error (max - min of the residuals) is sampled: its "
            "standard deviation is u(form), and the mean of the samples minus the measured form is how much the "
            "point errors alone add to a form error. See docs/ring-pipeline.md.</p>" + reports.html_table(
                ("measurement", "u(D) [mm]", "point-alone errors [mm]", "parameters [mm]",
                 "compliance [mm]", "if independent [mm]", "form error [mm]", "u(form) [mm]",
                 "inflation by the errors [mm]"),
                [(r.id, f"{u.u * 1e3:.4f}", f"{u.independent * 1e3:.4f}", f"{u.parameters * 1e3:.4f}",
                  f"{u.compliance * 1e3:.4f}", f"{u.if_independent * 1e3:.4f}", f"{f.form * 1e3:.4f}",
                  f"{f.u * 1e3:.4f}", f"{f.inflation * 1e3:.4f}")
                 for r, (u, f) in zip(campaign.measurements, point_uncertainty, strict=True)]))


def ring_report(campaign: RingCampaign, out: str | Path, inputs: dict, budgets: list[BudgetResult],
                warnings=(), point_uncertainty=None, parameters_source=None, plots: bool = True) -> list[Path]:
    """Write the report of an analysed ring campaign into folder ``out``: ``report.html``,
    ``summary.json``, ``table2.csv``, ``correlations.csv``, ``budgets.csv``, ``roundness.csv`` and
    ``figures/*.png`` (not when ``plots`` is False: the report then shows no figure).

    Args:
        campaign: :func:`correction.models.analyse_ring_campaign`'s result.
        inputs: {role: path} of the input files (never written over, listed in the summary).
        budgets: :func:`ring_budgets`'s result.
    Returns: the files written.
    """
    out = Path(out)
    in_paths = [p for p in inputs.values() if p is not None]
    guard_output(out, in_paths)
    summary = _ring_summary(campaign, inputs, budgets, warnings, point_uncertainty, parameters_source)
    summary.update(provenance(in_paths))
    t2 = table2(campaign)
    corr = campaign_correlations(campaign)
    figs = _ring_figures(campaign, budgets) if plots else {}
    parts = [f"<p>Ring <b>{html.escape(campaign.feature)}</b>, certified diameter "
             f"{campaign.reference_diameter * 1e3:.4f} mm, ball {campaign.ball_diameter * 1e3:g} mm, "  # type: ignore[operator]
             f"{len(campaign.measurements)} measurements, force sensor: {html.escape(campaign.force_kind)}. "
             f"The paper's models move each point by f x {campaign.compliance * 1e3:.4f} mm/N towards the axis; "
             "the full-wrench model evaluates the ball centres again through the probe's elastic joint with "
             "each point's force vector.</p>"]
    parts += [f"<p class='bad'>{html.escape(n)}</p>" for n in campaign.notes]
    parts.append(warnings_html(warnings))
    parts += _ring_tables_html(campaign, summary, t2)
    parts += _ring_figures_html(campaign, corr, plots)
    parts.append("<h2>Uncertainty budgets (GUM, paper Table 3)</h2>"
                 + ("<img src='figures/budgets.png' alt='budgets'>" if plots else ""))
    parts += [_budget_html(b) for b in budgets]
    if point_uncertainty is not None:
        parts.append(_point_uncertainty_html(campaign, point_uncertainty, parameters_source))
    files = {"report.html": _page("Ring-gauge campaign: force correction", parts),
             "summary.json": json.dumps(summary, indent=1, allow_nan=False) + "\n",
             "table2.csv": _csv_text(t2),
             "correlations.csv": _csv_text({k: np.array([getattr(c, k) for c in corr], dtype=object)
                                            for k in ("y_name", "x_name", "with_reference", "n", "r", "r2",
                                                      "p_value", "slope", "intercept")}),
             "budgets.csv": _csv_text(_budget_csv(budgets), "%.6g"),
             "roundness.csv": _csv_text(roundness_csv(roundness_data(campaign)), "%.6f")}
    files.update({f"figures/{k}": v for k, v in figs.items()})
    return _write_outputs(out, files, in_paths)


# ---------------------------------------------------------------------------------------------
# the paper

def paper_summary(table: P.PaperTable2 | None = None) -> dict:
    """Every reproduced figure of the paper, the findings and the loop (what ``summary.json`` holds)."""
    table = P.load_paper_table2() if table is None else table
    forces = P.implied_forces(table)
    corr = P.paper_correlations(table)
    imp = P.improvements(table)
    t1, t3 = P.table1_reproduction(), P.table3_reproduction(table)
    loops = {fm: P.close_loop(table, force_model=fm) for fm in ("mean_force", "max10_force", "max_force")}
    main = loops["mean_force"]
    per = [{"measurement": str(mid), "initial_mm": table.initial[i] * 1e3,
            "after_fem_mean_force_mm": main.residual[i] * 1e3,
            "after_fem_plus_series_compliance_loo_mm": main.origin["after"][i] * 1e3,
            "after_fem_plus_series_compliance_and_offset_loo_mm": main.after[i] * 1e3,
            "implied_forces_N": {m: forces[m][i] for m in P.TABLE2_MODELS}}
           for i, mid in enumerate(table.measurement)]

    def loop_dict(L):
        return {"force": L.force_model, "residual_of": L.residual_model,
                "series_compliance_mm_per_N": L.origin["extra_compliance"] * 1e3,
                "series_compliance_ci95_mm_per_N": [v * 1e3 for v in L.origin["extra_compliance_ci"]],
                "with_offset": {"extra_compliance_mm_per_N": L.extra_compliance * 1e3,
                                "extra_compliance_ci95_mm_per_N": [v * 1e3 for v in L.extra_compliance_ci],
                                "intercept_mm": L.intercept * 1e3, "intercept_se_mm": L.intercept_se * 1e3,
                                "loo_rms_after_mm": L.rms_after * 1e3},
                "r_residual_force": L.r, "p_value": L.p_value,
                "rms_before_mm": L.rms_before * 1e3, "loo_rms_after_mm": L.origin["rms_after"] * 1e3,
                "mean_abs_before_mm": L.mean_abs_before * 1e3,
                "loo_mean_abs_after_mm": L.origin["mean_abs_after"] * 1e3}
    return _num({
        "source": "Gonzalez-Madruga et al., Sensors 2013, 13, 10430-10448, Tables 1-3",
        "table2_file": table.source,
        "implied_forces_N": {m: forces[m] for m in P.TABLE2_MODELS},
        "implied_force_rounding_half_width_N": P.IMPLIED_FORCE_HALF_WIDTH,
        "pearson": [{"force": c.x_name, "with_reference": c.with_reference, "r": c.r, "r2": c.r2,
                     "p_value": c.p_value} for c in corr],
        "pearson_printed": P.PAPER_PEARSON,
        "improvement": {m: {k: v for k, v in d.items()} for m, d in imp.items()},
        "improvement_printed_pct": P.PAPER_IMPROVEMENT,
        "table1": {col: b.as_dict() for col, b in t1["budgets"].items()},
        "table3": {col: b.as_dict() for col, b in t3["budgets"].items()},
        "table3_recomputed": {col: b.as_dict() for col, b in t3["recomputed"].items()},
        "findings": [f.as_dict() for f in t1["findings"] + t3["findings"]],
        "loop": loop_dict(main), "loop_other_forces": {k: loop_dict(v) for k, v in loops.items() if k != "mean_force"},
        "per_measurement": per,
    })


def _paper_figures(table: P.PaperTable2, summary: dict) -> dict:
    plt = reports.pyplot()
    figs = {}
    ids = [str(i) for i in table.measurement]
    x = np.arange(len(ids))
    fig, ax = plt.subplots(figsize=(9, 4))
    ax.plot(x, table.initial * 1e3, "o-", color=_COLOURS["initial"], label="initial")
    for m in P.TABLE2_MODELS:
        ax.plot(x, table.columns[m] * 1e3, ".-", color=_COLOURS[m], label=_T2_LABELS[m])
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xticks(x, ids)
    ax.set(xlabel="measurement", ylabel="diameter error [mm]",
           title="Paper Table 2: initial and corrected diameter errors (real arm)")
    ax.legend(fontsize=8, ncol=3)
    figs["paper_table2.png"] = reports.png(fig)
    forces = P.implied_forces(table)
    fig, ax = plt.subplots(figsize=(9, 3.5))
    for m, mk in (("mean_force", "o"), ("max10_force", "s"), ("max_force", "^")):
        ax.errorbar(x, forces[m], yerr=P.IMPLIED_FORCE_HALF_WIDTH, fmt=mk + "-", ms=4, capsize=2,
                    color=_COLOURS[m], label=_T2_LABELS[m])
    ax.set_xticks(x, ids)
    ax.set(xlabel="measurement", ylabel="implied force [N]",
           title="Forces implied by Table 2: (initial - corrected) / (2 x 0.0142 mm/N), rounding bars")
    ax.legend(fontsize=8)
    figs["paper_implied_forces.png"] = reports.png(fig)
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    corr = {(c["force"], c["with_reference"]): c for c in summary["pearson"]}
    for m, key, mk in (("mean_force", "mean", "o"), ("max10_force", "max10", "s"), ("max_force", "max", "^")):
        c = corr[(f"{key}_force_N", True)]
        ax.plot(np.r_[0, forces[m]], np.r_[0, table.initial * 1e3], mk, color=_COLOURS[m],
                label=f"{_T2_LABELS[m]}: r = {c['r']:.3f} (paper {P.PAPER_PEARSON[key]:.2f})")
        fit = np.polyfit(np.r_[0, forces[m]], np.r_[0, table.initial * 1e3], 1)
        xs = np.linspace(0, forces[m].max() * 1.05, 10)
        ax.plot(xs, np.polyval(fit, xs), "-", lw=0.8, color=_COLOURS[m])
    ax.set(xlabel="implied force [N]", ylabel="initial diameter error [mm]",
           title="Paper Fig. 10 reproduced from Table 2 (with the 0 N, 0 mm point)")
    ax.legend(fontsize=8)
    figs["paper_correlation.png"] = reports.png(fig)
    L = P.close_loop(table)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.2))
    a1.plot(L.force, L.residual * 1e3, "o", color=_COLOURS["mean_force"], label="after the FEM (stylus) correction")
    xs = np.linspace(0, L.force.max() * 1.05, 10)
    a1.plot(xs, L.origin["slope"] * xs * 1e3, "-", color="k",
            label=f"series compliance {L.origin['extra_compliance'] * 1e3:.4f} mm/N (through 0)")
    a1.plot(xs, (L.intercept + L.slope * xs) * 1e3, "--", color="grey",
            label=f"with offset: {L.extra_compliance * 1e3:.4f} mm/N, {L.intercept * 1e3:+.3f} mm")
    a1.axhline(0, color="k", lw=0.5)
    a1.set(xlabel="mean force implied by Table 2 [N]", ylabel="residual diameter error [mm]",
           title="The residual still depends on the force")
    a1.legend(fontsize=8)
    w = 0.28
    a2.bar(x - w, table.initial * 1e3, w, color=_COLOURS["initial"], label="initial")
    a2.bar(x, L.residual * 1e3, w, color=_COLOURS["mean_force"], label="FEM stylus model (mean force)")
    a2.bar(x + w, L.origin["after"] * 1e3, w, color=_COLOURS["wrench"], label="+ series compliance (leave-one-out)")
    a2.axhline(0, color="k", lw=0.5)
    a2.set_xticks(x, ids)
    a2.set(xlabel="measurement", ylabel="diameter error [mm]",
           title=f"RMS {L.rms_before * 1e3:.4f} -> {L.origin['rms_after'] * 1e3:.4f} mm (cross-validated)")
    a2.legend(fontsize=8)
    figs["paper_loop.png"] = reports.png(fig)
    return figs


def paper_report(out: str | Path, table_path: str | Path | None = None) -> list[Path]:
    """Write the reproduction of the paper's Tables 1-3 and the closed loop into folder ``out``:
    ``report.html``, ``summary.json``, ``table2_implied.csv``, ``findings.csv``, ``figures/*.png``."""
    out = Path(out)
    table = P.load_paper_table2(table_path)
    inputs = [table.source]
    guard_output(out, inputs)
    s = paper_summary(table)
    figs = _paper_figures(table, s)
    forces = P.implied_forces(table)
    imp = P.improvements(table)
    loop = s["loop"]
    t2cols = {"measurement": table.measurement, "initial_mm": table.initial * 1e3}
    for m in P.TABLE2_MODELS:
        t2cols[f"{m}_mm"] = table.columns[m] * 1e3
    for m in P.TABLE2_MODELS:
        t2cols[f"{m}_improvement_pct"] = imp[m]["per_measurement_pct"]
    for m in P.TABLE2_MODELS:
        t2cols[f"{m}_improvement_paper_formula_pct"] = imp[m]["paper_formula_pct"]
    for m in P.TABLE2_MODELS:
        t2cols[f"{m}_implied_N"] = forces[m]
    t2cols["after_series_compliance_loo_mm"] = np.array([p["after_fem_plus_series_compliance_loo_mm"]
                                                         for p in s["per_measurement"]])
    findings = s["findings"]
    parts = ["<p>Source: González-Madruga, Cuesta, Barreiro, Fernández-Abia, <i>Application of a Force Sensor to "
             "Improve the Reliability of Measurement with Articulated Arm Coordinate Measuring Machines</i>, "
             "Sensors 2013, 13, 10430-10448 (CC BY 3.0). Table 2 is measured data of a real arm, bundled as "
             f"<code>{html.escape(Path(table.source).name)}</code>.</p>"]
    parts.append("<h2>Table 2: forces implied, correlations, improvements</h2>"
                 f"<p>Each model's correction implies a force F = (initial - corrected) / (2 x 0.0142 mm/N); the "
                 f"table's 3 decimals make it uncertain by ±{P.IMPLIED_FORCE_HALF_WIDTH:.3f} N (worst case).</p>")
    rows = [(str(table.measurement[i]), f"{table.initial[i] * 1e3:.3f}")
            + tuple(f"{forces[m][i]:.2f}" for m in ("point_force", "mean_force", "max10_force", "max_force"))
            for i in range(len(table.initial))]
    parts.append(reports.html_table(("measurement", "initial [mm]", "point F [N]", "mean F [N]", "10Max F [N]",
                              "max F [N]"), rows))
    parts.append("<img src='figures/paper_table2.png' alt='Table 2'><img src='figures/paper_implied_forces.png' "
                 "alt='implied forces'>")
    rows = [(c["force"], "yes" if c["with_reference"] else "no", f"{c['r']:.3f}", f"{c['r2']:.3f}",
             f"{P.PAPER_PEARSON[c['force'].replace('_force_N', '')]:.2f}" if c["with_reference"] else "")
            for c in s["pearson"]]
    parts.append("<h3>Pearson r of the diameter error with the force</h3>"
                 + reports.html_table(("force", "with (0, 0)", "r", "R²", "paper"), rows)
                 + "<img src='figures/paper_correlation.png' alt='correlation'>")
    rows = [(_T2_LABELS[m], f"{d['mean_abs_reduction_pct']:.1f}", f"{d['mean_pct']:.1f}", f"{d['median_pct']:.1f}",
             f"{P.PAPER_IMPROVEMENT[m]:.0f}") for m, d in imp.items()]
    parts.append("<h3>Improvement of the diameter error [%]</h3>" + reports.html_table(
        ("model", "reduction of mean |error|", "mean of per-measurement", "median", "paper's conclusion"), rows)
        + "<p>The table supports max &gt; 10Max (as the paper's §4.2 says: the max-force model achieved the "
          "largest reduction); the conclusion's '60 % and 55 %' for 10Max and max assigns the two figures the "
          "other way round.</p>")
    # findings
    rows = [(f["table"], f["item"], str(f["printed"]), (f"{f['computed']:.5g}" if isinstance(f["computed"], float)
                                                        else str(f["computed"])),
             "yes" if f["consistent"] else "NO", f["note"]) for f in findings]
    parts.append("<h2>Tables 1 and 3: every printed figure recomputed (GTC)</h2>"
                 + reports.html_table(("table", "figure", "printed", "recomputed", "consistent", "what follows"), rows))
    t1, t3 = P.table1_reproduction(), P.table3_reproduction(table)
    parts.append("<h3>Table 1 evaluated from its terms</h3>" + "".join(_budget_html(b) for b in t1["budgets"].values()))
    parts.append("<h3>Table 3 evaluated from its terms</h3>" + "".join(_budget_html(b) for b in t3["budgets"].values()))
    parts.append("<h3>Table 3 recomputed (u_r from Table 2, u_cor from the bending sensor)</h3>"
                 + "".join(_budget_html(b) for b in t3["recomputed"].values()))
    # loop
    parts.append(
        "<h2>Closing the loop on Table 2</h2>"
        f"<p>After the FEM probe correction (mean force x 0.0142 mm/N), the residual diameter error still grows "
        f"with the force: Pearson r = {loop['r_residual_force']:.3f} (p = {loop['p_value']:.1g}, 17 measurements). "
        f"A compliance in series with the stylus explains it: fitted through the origin, "
        f"{loop['series_compliance_mm_per_N']:.4f} mm/N radial (95 % interval "
        f"{loop['series_compliance_ci95_mm_per_N'][0]:.4f} to {loop['series_compliance_ci95_mm_per_N'][1]:.4f}), "
        f"that is {(loop['series_compliance_mm_per_N'] + 0.0142) / 0.0142:.1f} times the FEM stylus value in "
        f"total. With a free offset: {loop['with_offset']['extra_compliance_mm_per_N']:.4f} mm/N and "
        f"{loop['with_offset']['intercept_mm']:+.4f} ± {loop['with_offset']['intercept_se_mm']:.4f} mm, an offset "
        f"not distinguishable from zero. Leave-one-out (each measurement predicted by the other 16): RMS "
        f"diameter error {loop['rms_before_mm']:.4f} mm after the FEM correction, "
        f"{loop['loo_rms_after_mm']:.4f} mm with the series compliance (mean |error| "
        f"{loop['mean_abs_before_mm']:.4f} -> {loop['loo_mean_abs_after_mm']:.4f} mm).</p>"
        "<p>The effect the FEM probe model lacks: it models the stylus alone, clamped at its root; the force the "
        "operator and the ring exchange also deflects what carries the stylus (the probe mount and the wrist, "
        "the arm's links and joints), a compliance in series that the arm's calibration does not remove. "
        "What 17 measurements cannot tell apart: that series compliance from an under-read force (one bending "
        "channel sees only the component along probe x, so a force at an angle reads low by cos of it, which "
        "scales the apparent compliance the same way); which force statistic drives it ("
        + ", ".join(f"{k.replace('_force', '')}: LOO RMS {v['loo_rms_after_mm']:.4f} mm"
                    for k, v in [("mean_force", loop)] + list(s["loop_other_forces"].items()))
        + "); and a non-linear force-deflection law from a linear one.</p>"
        "<img src='figures/paper_loop.png' alt='closing the loop'>")
    rows = [(p["measurement"], f"{p['initial_mm']:.3f}", f"{p['after_fem_mean_force_mm']:.3f}",
             f"{p['after_fem_plus_series_compliance_loo_mm']:+.4f}") for p in s["per_measurement"]]
    parts.append("<h3>Diameter error per measurement [mm]</h3>" + reports.html_table(
        ("measurement", "initial", "after FEM (mean force)", "after FEM + series compliance (LOO)"), rows))
    files = {"report.html": _page("The seed paper reproduced and the loop closed", parts),
             "summary.json": json.dumps({**s, **provenance([P.TABLE2_PATH if table_path is None else table_path])},
                                        indent=1, allow_nan=False) + "\n",
             "table2_implied.csv": _csv_text(t2cols),
             "findings.csv": _csv_text({k: np.array([str(f[k]) for f in findings], dtype=object)
                                        for k in ("table", "item", "printed", "computed", "consistent", "note")})}
    files.update({f"figures/{k}": v for k, v in figs.items()})
    return _write_outputs(out, files, inputs)
