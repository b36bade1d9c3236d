"""Outputs of a calibration: the calibrated description (TOML and URDF, new files, never over the
nominal), ``summary.json``, CSV tables and an HTML report with plots. Every file is written
atomically and refused if it would overwrite an input."""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from arm_model import InputError, reports
from arm_model.checks import warnings_html
from arm_model.discrepancy import growth_text
from arm_model.io import atomic_write_bytes, atomic_write_text, guard_output, json_text, write_csv
from arm_model.log import counted
from arm_model.shipped import provenance

from .calibrate import CalibrationResult, display_unit
from .model_output import calibrated_name, model_check, model_paths, write_model
from .validation import with_u

__all__ = ["write_outputs", "plot_residuals", "plot_parameters", "plot_correlation", "plot_conformance",
           "conformance_lines", "conformance_pngs", "write_conformance_pngs", "conformance_html", "CONFORMANCE_SETS",
           "plot_discrepancy", "discrepancy_pngs", "write_discrepancy_png", "discrepancy_html"]


def plot_residuals(result: CalibrationResult) -> bytes:
    """PNG: residuals [um] of every point, grouped by artefact instance, coloured by kind; certified
    distances as their own group."""
    t = result.residuals
    fig, ax = reports.figure(max(6.0, 0.12 * len(result.instances) + 4), 4.0)
    colours = {"seat": "C0", "sphere": "C1", "ring": "C2", "cylinder": "C2", "plane": "C3", "reference": "C4"}
    labels = []
    for i, inst in enumerate(result.instances):
        v = t["value"][t["instance"] == i] * 1e6
        ax.plot(np.full(len(v), i), v, ".", color=colours.get(inst["kind"], "k"), ms=3)
        labels.append(f"{inst['measurement']}:{inst['feature'] or 'ref'}")
    if len(t["distance"]):
        x0 = len(result.instances)
        ax.plot(np.arange(x0, x0 + len(t["distance"])), t["distance"] * 1e6, "s", color="C5", ms=4)
        labels += [f"{d['measurement']}:length" for d in result.distances]
    for kind, c in colours.items():
        if any(inst["kind"] == kind for inst in result.instances):
            ax.plot([], [], ".", color=c, label=kind)
    if len(t["distance"]):
        ax.plot([], [], "s", color="C5", label="distance")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_ylabel("residual [um]")
    ax.set_title("residuals per artefact instance (seats and reference: norm)")
    if len(labels) <= 60:
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=90, fontsize=6)
    else:
        ax.set_xlabel("artefact instance")
    ax.legend(fontsize=7, loc="best")
    return reports.png(fig)


def plot_parameters(result: CalibrationResult) -> bytes:
    """PNG: free parameter estimates with 2u error bars, one panel per display unit."""
    rows = [r for r in result.parameter_rows() if r["state"] in ("free", "prior-dominated")]
    units = list(dict.fromkeys(r["display_unit"] for r in rows)) or ["-"]
    fig, axes = reports.figure(max(6.0, 0.25 * len(rows) + 3), 2.6 * len(units), rows=len(units))
    for ax, unit in zip(axes[:, 0], units, strict=True):
        rr = [r for r in rows if r["display_unit"] == unit]
        x = np.arange(len(rr))
        ax.errorbar(x, [r["display_value"] for r in rr], yerr=[2 * r["display_u"] for r in rr], fmt="o", ms=3,
                    capsize=2)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xticks(x)
        ax.set_xticklabels([r["name"] for r in rr], rotation=90, fontsize=7)
        ax.set_ylabel(f"[{unit}]")
    axes[0, 0].set_title("estimated errors (p = 0 is the nominal description), bars: 2 u")
    fig.tight_layout()          # fits every label inside the figure: no crop, which would lay it out once more
    return reports.png(fig, crop=False)


def plot_correlation(result: CalibrationResult) -> bytes:
    """PNG: correlation matrix of the free parameters."""
    n = len(result.free)
    fig, ax = reports.figure(max(4.0, 0.22 * n + 2), max(3.5, 0.22 * n + 1.5))
    im = ax.imshow(result.corr if n else np.zeros((1, 1)), vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(n))
    ax.set_yticks(range(n))
    ax.set_xticklabels(result.free, rotation=90, fontsize=6)
    ax.set_yticklabels(result.free, fontsize=6)
    fig.colorbar(im, ax=ax, shrink=0.8)
    ax.set_title("correlation of the estimates")
    return reports.png(fig)


#: the data sets a conformance table can be on: summary key -> title
CONFORMANCE_SETS = {"training": "training data", "holdout": "held-out data"}


def plot_conformance(rows: list[dict], title: str) -> bytes:
    """PNG: one panel a test of ``rows`` (:func:`calibration.validation.conformance`): each item's value
    [um] of the calibrated model, the MPE band (+-MPE for errors, 0..MPE for sizes) shaded when given,
    items beyond it in red, the verdict in the panel's title."""
    rows = [r for r in rows if r["n"]]
    heights = [_PANEL_H + _below_panel(r) for r in rows]
    fig, axes = reports.figure(_CONF_W, _CONF_TOP + sum(heights), rows=len(rows))
    for ax, r in zip(axes[:, 0], rows, strict=True):
        v = np.array([it["value_um"] for it in r["items"]])
        x = np.arange(len(v))
        mpe = r["mpe_um"]
        if mpe is not None:
            ax.axhspan(-mpe if r["signed"] else 0.0, mpe, color="#2ca02c", alpha=0.15, lw=0,
                       label=f"MPE {mpe:g} um")
            for y in ((-mpe, mpe) if r["signed"] else (mpe,)):
                ax.axhline(y, color="#2ca02c", lw=0.8)
            bad = np.abs(v) > mpe
            ax.plot(x[~bad], v[~bad], "o", ms=4, color="C0")
            ax.plot(x[bad], v[bad], "o", ms=5, color="#d62728", label="beyond the MPE")
            verdict = r["result"] + (f" ({r['n_fail']} of {r['n']} beyond)" if r["n_fail"] else "")
        else:
            ax.plot(x, v, "o", ms=4, color="C0")
            verdict = "no MPE given: no pass/fail"
        ax.axhline(0, color="k", lw=0.5)
        lo, hi = min(0.0, v.min()), max(0.0, v.max())
        if mpe is not None:
            lo, hi = min(lo, -mpe if r["signed"] else 0.0), max(hi, mpe)
        pad = 0.1 * (hi - lo or 1.0)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_xlim(-0.7, len(v) - 0.3)
        ax.set_ylabel("[um]")
        ax.set_title(f"{r['standard']} {r['test']}: {verdict}", fontsize=9)
        if len(v) <= 40:
            ax.set_xticks(x)
            ax.set_xticklabels([it["label"] for it in r["items"]], rotation=90, fontsize=6)
        if mpe is not None:
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    axes[0, 0].figure.suptitle(title, fontsize=10)
    # a fixed layout in inches, the room under each panel from its own labels' measured length: tight_layout and a
    # tight crop drew the figure three times (1.4 s -> 0.5 s of CPU a figure of seven panels)
    w, h = fig.get_figwidth(), fig.get_figheight()
    right = _CONF_RIGHT_LEGEND if any(r["mpe_um"] is not None for r in rows) else _CONF_RIGHT
    y = h - _CONF_TOP                   # the top of the next panel (its title, then its plot, then the labels)
    for ax, height in zip(axes[:, 0], heights, strict=True):
        ax.set_position((_CONF_LEFT / w, (y - _PANEL_H) / h, (w - _CONF_LEFT - right) / w,
                         (_PANEL_H - _PANEL_TITLE) / h))
        y -= height
    return reports.png(fig, crop=False)


#: the conformance figure's layout [in]: width, the room above the first panel (the figure's title), left of the
#: panels (tick values and the unit) and right of them (without and with the MPE legend), a panel's height with its
#: title, the title's share of it
_CONF_W, _CONF_TOP, _CONF_LEFT, _CONF_RIGHT, _CONF_RIGHT_LEGEND, _PANEL_H, _PANEL_TITLE = 9.0, 0.55, 1.0, 0.3, 1.75, \
    1.6, 0.3


def _below_panel(r: dict) -> float:
    """The room [in] under a conformance panel: the rotated item labels (their measured length at 6 pt) when
    written, the tick values otherwise, and a gap."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import text_to_path
    if r["n"] > 40:
        return 0.55
    font = FontProperties(size=6)
    longest = max(text_to_path.get_text_width_height_descent(str(it["label"]), font, ismath=False)[0]
                  for it in r["items"])
    return 0.2 + longest / 72.0


def conformance_lines(conf: dict) -> list[str]:
    """Console lines of the ``conformance`` summary entry: one a test and data set."""
    out = [] if conf["mpe_given"] else ["standard tests: no --mpe-*-um option given: figures without pass/fail"]
    for key, what in CONFORMANCE_SETS.items():
        for r in conf.get(key) or ():
            if not r["n"]:
                out.append(f"  {r['standard']} {r['test']} on {what}: no item in this data set (MPE {r['mpe_um']:g} um "
                           "not tested)")
                continue
            head = (f"  {r['standard']} {r['test']} on {what} ({counted(r['n'], 'item')}): "
                    f"max |value| {r['max_abs_um']:.2f} um")
            if r["result"] is None:
                out.append(head + " (no MPE given)")
            else:
                out.append(f"{head} {'<=' if r['result'] == 'PASS' else '>'} MPE {r['mpe_um']:g} um: {r['result']}"
                           + (f" ({r['n_fail']} beyond)" if r["n_fail"] else ""))
    return out


def conformance_pngs(conf: dict, out) -> dict:
    """``{"conformance_<set>_png": path}`` of the conformance plots of ``conf`` (its non-empty sets)."""
    return {f"conformance_{k}_png": Path(out) / f"conformance_{k}.png" for k in CONFORMANCE_SETS if conf.get(k)}


def write_conformance_pngs(conf: dict, files: dict, inputs=()) -> list[Path]:
    """Write the plots of :func:`conformance_pngs` (``files`` holds their paths); returns the paths."""
    written = []
    for k, what in CONFORMANCE_SETS.items():
        if conf.get(k):
            written.append(atomic_write_bytes(files[f"conformance_{k}_png"], plot_conformance(
                conf[k], f"Standard tests on {what}, calibrated model"
                + ("" if conf["mpe_given"] else " (no MPE given: no pass/fail)")), inputs))
    return written


def conformance_html(conf: dict, files: dict) -> list[str]:
    parts = ["<h2>Standard tests (ASME B89.4.22 / ISO 10360-12), calibrated model</h2>",
             f"<p>{html.escape(conf['note'])}</p>"]
    for key, what in CONFORMANCE_SETS.items():
        rows = conf.get(key)
        if not rows:
            continue
        parts.append(f"<h3>On {what}</h3>")
        parts.append(reports.html_table(["standard", "test", "what is tested", "items", "max |value| [um]", "MPE [um]",
                             "result"],
                            [(r["standard"], r["test"], r["what"], r["n"], _fmt(r["max_abs_um"], 4),
                              _fmt(r["mpe_um"], 4), (r["result"] or ("- (no MPE)" if r["n"] else "no item"))
                              + (f" ({r['n_fail']} beyond)" if r["n_fail"] else "")) for r in rows]))
        png = files.get(f"conformance_{key}_png")
        if png is not None:
            parts.append(f"<img src='{html.escape(png.name)}' style='max-width:100%'>")
    return parts


def _line(o) -> str:
    """The file line of an outlier's point, or "length" for a certified length."""
    return "length" if o.point is None else str(o.line)


def _file(o) -> str:
    """The points file of an outlier's point (a point is its file and line), empty for a certified length."""
    return "" if o.point is None or o.file is None else str(o.file)


def _fmt(v, digits=4):
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def _html(result: CalibrationResult, summary: dict, files: dict) -> str:
    estimated = ("free", "prior-dominated")
    par = [(r["name"], r["state"], r["display_unit"], _fmt(r["display_value"], 6),
            _fmt(r["display_u"], 3) if r["state"] in estimated else "-", _fmt(r["display_prior_u"], 3),
            _fmt(r["prior_ratio"], 2)) for r in result.parameter_rows()]
    fixed = [(f.name, f.stage, f.reason) for f in result.fixed]
    idf = result.identifiability_final
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>Calibration report</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse;"
        "font-size:12px}td,th{border:1px solid #bbb;padding:2px 6px}th{background:#eee}</style></head><body>",
        f"<h1>Calibration of {html.escape(result.model.desc.name)}</h1>",
        f"<p>Solver: {html.escape(result.status)}; {result.iterations} iterations; "
        f"{result.n_residuals} residuals, {len(result.free)} parameters, {result.n_nuisance} nuisance unknowns, "
        + (f"dof {result.dof}" if result.redundancy is None else f"redundancy {result.redundancy:.3g} (the prior "
           "included)") + f"; s0 = {result.s0:.4g}. Covariance: {html.escape(result.covariance_source)}.</p>",
        warnings_html(summary.get("warnings", ())),
        f"<p>Identifiability at the solution: rank {idf.rank} of {len(idf.names)}, condition number "
        f"{idf.condition:.4g} (columns scaled by their norms), rank tolerance {idf.rank_tol:g}.</p>",
        "<h2>Fixed parameters (not identifiable from these data)</h2>",
        reports.html_table(["parameter", "stage", "reason"], fixed) if fixed else "<p>none</p>",
    ]
    if summary.get("poorly_determined"):
        parts.append("<p>Poorly determined (large uncertainty; consider fixing): "
                     + html.escape(", ".join(summary["poorly_determined"])) + "</p>")
    for key, title in (("validation_training", "Validation on the training data"),
                       ("validation_holdout", "Validation on held-out data (never seen by the fit)")):
        rows = summary.get(key)
        if rows:
            base = summary.get("nominal_baseline")
            parts += [f"<h2>{title}</h2>", "<p>± the standard uncertainty of each figure: a bootstrap over the "
                      "measurements (whole measurements resampled); '-' with fewer than two "
                      "measurements of its kind."
                      + (f" The {html.escape(base['definition'])}." if base else "") + "</p>",
                      reports.html_table(["figure", "unit", "nominal", "calibrated", "ratio"],
                             [(r["label"], r["unit"], with_u(r["before"], r.get("u_before")),
                               with_u(r["after"], r.get("u_after")), _fmt(r["ratio"], 3)) for r in rows])]
    worse = summary.get("heldout_worse_than_nominal")
    if worse:
        parts.append("<p><b>On the held-out data the calibrated model is worse than the nominal</b>: "
                     + html.escape("; ".join(f"{r['label']} {r['before']:.4g} -> {r['after']:.4g} {r['unit']}"
                                             for r in worse)) + ".</p>")
    if summary.get("conformance"):
        parts += conformance_html(summary["conformance"], files)
    parts += prior_html(result) + discrepancy_html(result, files)
    parts += ["<h2>Parameters</h2>",
              "<p>state: free (estimated, the data dominate), prior-dominated (estimated, but its posterior "
              "variance is at least half its prior's: it stays near the nominal with about the prior's "
              "uncertainty), fixed (not separable from the others, or at a bound; see above), held (not freed). "
              "'prior u': the prior's standard deviation; 'ratio': posterior / prior variance.</p>",
              reports.html_table(["parameter", "state", "unit", "estimate", "u", "prior u", "ratio"], par)]
    if result.outliers:
        parts += ["<h2>Outliers (kept)</h2>" if not result.dropped else "<h2>Outliers</h2>",
                  reports.html_table(["kind", "measurement", "feature", "file", "line", "standardized",
                                      "residual [um]"],
                         [(o.kind, o.measurement, o.feature, _file(o), _line(o), _fmt(o.standardized, 3),
                           _fmt(o.residual * 1e6, 4)) for o in result.outliers])]
    if result.gross:
        parts += ["<h2>Gross errors (left out of the fit)</h2>",
                  "<p>points and certified lengths whose gross-error test (their rows' deletion residual together, "
                  "as the standardized residual of the same false-alarm rate) reached the threshold, left out one at a "
                  "time (the largest first) and the fit redone; 'deletion residual': the point's (or length's) "
                  "residual under the fit without it. <code>--keep-outliers</code> keeps them.</p>",
                  reports.html_table(["measurement", "feature", "file", "line", "standardized", "threshold",
                                      "deletion residual [um]"],
                         [(g.outlier.measurement, g.outlier.feature, _file(g.outlier), _line(g.outlier),
                           _fmt(g.outlier.standardized, 3), _fmt(g.threshold, 3),
                           _fmt(g.residual * 1e6, 4)) for g in result.gross])]
    if result.gross_kept:
        parts += [f"<p>Gross-looking point kept: {html.escape(result.gross_kept)}</p>"]
    if result.dropped:
        parts += ["<h2>Dropped points (refitted without them)</h2>",
                  reports.html_table(["measurement", "feature", "file", "line", "standardized"],
                         [(o.measurement, o.feature, _file(o), _line(o), _fmt(o.standardized, 3))
                          for o in result.dropped])]
    for name, title in (("residuals_png", "Residuals"), ("parameters_png", "Estimates"),
                        ("correlation_png", "Correlations")):
        if name in files:
            parts += [f"<h2>{title}</h2>", f"<img src='{html.escape(files[name].name)}' style='max-width:100%'>"]
    parts.append("</body></html>")
    return "\n".join(parts)


def prior_html(result: CalibrationResult) -> list[str]:
    """The report's section on the prior: each group's scale and how many of its parameters the data
    determine."""
    if result.prior_scales is None:
        return []
    rows = [(g, _fmt(v["scale"], 3) + (" (physical)" if v.get("physical") else " (at most 1)" if v.get("capped")
                                        else ""), len(v["parameters"]),
             _fmt(v["effective_parameters"], 3),
             "; ".join(v["size_source"])) for g, v in result.prior_groups.items()]
    how = (f"chosen by the evidence together with the noise ({len(result.evidence)} rounds)" if result.evidence
           else "given")
    out = ["<h2>Prior</h2>",
           f"<p>Each free parameter ~ N(nominal, (scale x plausible size)^2), one scale a group, {how}. "
           "'determined': the number of the group's parameters the data determine (sum of 1 - posterior/prior "
           "variance).</p>",
           reports.html_table(["group", "scale", "parameters", "determined", "plausible size at scale 1"], rows)]
    if result.prior_only:
        out += ["<p>Left to the prior (the data cannot see them; prior-dominated at the prior's centre):</p>",
                reports.html_table(["parameter", "why"], sorted(result.prior_only.items()))]
    return out


def plot_discrepancy(result: CalibrationResult) -> bytes:
    """PNG: the extrapolative folds' held-out errors [um] (absolute, per residual row) against their distance
    from the nearest pose left in the fold [mm], with the 1.96-sigma envelopes of the fit's own prediction
    (noise and posterior, their mean), of the constant discrepancy and of the growing one."""
    d = result.discrepancy
    g = d.growth if d is not None else None
    fig, ax = reports.figure(6.0, 4.0)
    if g is None or not len(g.d):
        return reports.png(fig)
    ax.plot(g.d * 1e3, np.abs(g.e) * 1e6, ".", ms=3, color="C0", label="held-out error (per row)")
    x = np.linspace(0.0, max(float(g.d.max()), 1e-9), 100)
    v = float(np.mean(g.v))
    for label, sd, style in (("fit's own prediction", np.full_like(x, np.sqrt(v)), "k:"),
                             ("constant discrepancy", np.full_like(x, np.sqrt(v + d.sigma ** 2)), "C1--"),
                             ("growing discrepancy", np.sqrt(v + g.sigma0 ** 2 + (g.growth * x) ** 2), "C3-")):
        ax.plot(x * 1e3, 1.96 * sd * 1e6, style, label=f"1.96 sigma: {label}")
    ax.set_xlabel("distance from the nearest pose left in the fold [mm of ball travel]")
    ax.set_ylabel("|held-out error| [um]")
    ax.set_title("model discrepancy: the poses at the ends of each joint's range held out")
    ax.legend(fontsize=7, loc="best")
    return reports.png(fig)


def discrepancy_pngs(result: CalibrationResult, out) -> dict:
    """``{"discrepancy_png": path}`` in ``out`` when the model discrepancy of ``result`` was fitted as growing
    (:func:`plot_discrepancy` has rows to show), else ``{}``: the plot's path in calibrate's and close-loop's
    outputs alike."""
    d = result.discrepancy
    return {"discrepancy_png": Path(out) / "discrepancy.png"} if d is not None and d.growth is not None else {}


def write_discrepancy_png(result: CalibrationResult, files: dict, inputs=()) -> list[Path]:
    """Write the plot of :func:`discrepancy_pngs` (``files`` holds its path, if any); returns the paths written."""
    if "discrepancy_png" not in files:
        return []
    return [atomic_write_bytes(files["discrepancy_png"], plot_discrepancy(result), inputs)]


def discrepancy_html(result: CalibrationResult, files: dict | None = None) -> list[str]:
    """The report's section on the model discrepancy (:mod:`calibration.discrepancy`), with its plot when
    ``files`` holds it (:func:`discrepancy_pngs`): calibrate's and close-loop's reports alike."""
    d = result.discrepancy
    if d is None:
        return []
    png = (files or {}).get("discrepancy_png")
    return ["<h2>Model discrepancy</h2>",
            f"<p>{_fmt(d.sigma * 1e6, 4)} um per axis: the poses at either end of each joint's range "
            f"({d.share:.0%} of the poses each end, {d.folds} folds) held out in turn and predicted by the fit on the "
            f"rest err {_fmt(d.ratio, 3)} x what that fit predicts (noise and posterior); the excess is the model "
            "discrepancy.</p>"] + _growth_html(d) + (
        [] if png is None else ["<h3>Model discrepancy away from the training poses</h3>",
                                f"<img src='{html.escape(Path(png).name)}' style='max-width:100%'>"])


def _growth_html(d) -> list[str]:
    """The report's sentence on the discrepancy's growth away from the training poses (:class:`calibration.
    discrepancy.Growth`)."""
    g = d.growth
    if d.written_growth is None or g is None:
        floored = " It does not grow away from the training poses (the growth fitted to the same held-out poses is " \
            "floored at 0)." if d.growth is not None else ""
        return [f"<p>{floored} The model file carries it as a constant and tip adds it to every point's "
                "uncertainty.</p>"]
    return [f"<p>Fitted to the same held-out poses as growing with how far the joint motions from the nearest of "
            f"the poses each was predicted from carry the ball (d): sigma_d<sup>2</sup> = sigma_0<sup>2</sup> + (g d)"
            f"<sup>2</sup> with sigma_0 = {_fmt(g.sigma0 * 1e6, 4)} &plusmn; {_fmt(g.u_sigma0 * 1e6, 2)} um and g = "
            f"{_fmt(g.growth * 1e3, 4)} &plusmn; {_fmt(g.u_growth * 1e3, 2)} um per mm (maximum likelihood, "
            f"uncertainties by the delete-one-fold jackknife; d up to {_fmt(g.d_max * 1e3, 4)} mm in the folds, "
            f"likelihood ratio over a constant {_fmt(g.lr, 3)}).</p>"] + _joint_growth_html(d)


def _joint_growth_html(d) -> list[str]:
    """The report's sentence on the growth per joint the model file carries (:class:`calibration.discrepancy.
    JointGrowth`)."""
    j = d.joints
    if j is None or d.written_growth is None:
        return []
    s0, g = d.written
    return [f"<p>Fitted per joint (each joint's own ball travel c<sub>j</sub> from the nearest pose: sigma_d<sup>2"
            f"</sup> = sigma_0<sup>2</sup> + sum g<sub>j</sub><sup>2</sup> c<sub>j</sub>; likelihood ratio over one g "
            f"for every joint {_fmt(j.lr, 3)}), written with the estimates' own uncertainty carried (sqrt(g<sup>2"
            f"</sup> + u<sup>2</sup>)): sigma_0 = {_fmt(s0 * 1e6, 4)} um, g = {html.escape(growth_text(g))} um per mm. "
            "The model file carries them and the training poses (a points file beside it); tip adds sigma_d of "
            "each point's pose to its uncertainty.</p>"]


def write_outputs(result: CalibrationResult, out_dir, *, inputs=(), validation_training=None,
                  validation_holdout=None, extra: dict | None = None, plots: bool = True) -> dict:
    """Write the outputs of ``result`` into ``out_dir`` (created); returns ``{role: Path}``.

    Files: the model file ``<name>-calibrated.toml`` (the base errors folded into a new description, the
    model's effects with their parameters; :mod:`calibration.model_output`), its covariance file
    ``<name>-calibrated-covariance.csv`` and ``<name>-calibrated.urdf``, ``summary.json``, ``parameters.csv``,
    ``residuals.csv``, ``report.html`` and three PNG plots, plus
    ``conformance_training.png`` / ``conformance_holdout.png`` when ``extra`` holds a ``conformance`` entry
    (:func:`calibration.validation.conformance` tables under ``training`` / ``holdout``).
    ``inputs``: files that must never be overwritten (points, artefacts, the nominal arm).
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("the output must be a directory", out)
    name = calibrated_name(result.model.desc.name)
    model_files = model_paths(out, name)
    files = {"description": model_files["model"], "covariance": model_files["covariance"],
             "urdf": model_files["urdf"], "summary": out / "summary.json",
             "parameters": out / "parameters.csv", "residuals": out / "residuals.csv", "report": out / "report.html"}
    conf = (extra or {}).get("conformance") or {}
    if plots:
        files.update({"residuals_png": out / "residuals.png", "parameters_png": out / "parameters.png",
                      "correlation_png": out / "correlation.png"})
        files.update(conformance_pngs(conf, out))
        files.update(discrepancy_pngs(result, out))
    for f in files.values():
        guard_output(f, inputs)
    effects = [e.describe() for e in result.model.effects]
    comment = (f"Calibrated model of '{result.model.desc.name}' written by aacmm calibrate: the description with the "
               f"fitted values folded in"
               + (", and the model's effects with their parameters" if effects else "") + ".\n"
               f"Solver: {result.status}; s0 = {result.s0:.4g}. Read by every --arm option; format: "
               "docs/formats.md, 'The model file'.")
    written = write_model(result, out, name, inputs=inputs, written_by="aacmm calibrate", comment=comment)
    if "training_poses" in written:
        files["training_poses"] = written["training_poses"]
    rows = result.parameter_rows()
    write_csv(files["parameters"], {
        "name": np.array([r["name"] for r in rows], dtype=object),
        "state": np.array([r["state"] for r in rows], dtype=object),
        "unit": np.array([r["display_unit"] for r in rows], dtype=object),
        "value": np.array([r["display_value"] for r in rows]),
        "u": np.array([r["display_u"] for r in rows])}, inputs, fmt="%.9g")
    t = result.residuals
    write_csv(files["residuals"], {
        "measurement": t["measurement"], "feature": t["feature"], "kind": t["kind"], "file": t["file"],
        "line": np.asarray(t["line"], dtype=int), "residual_um": t["value"] * 1e6,
        "dx_um": t["vector"][:, 0] * 1e6, "dy_um": t["vector"][:, 1] * 1e6, "dz_um": t["vector"][:, 2] * 1e6,
        "standardized": t["standardized"]}, inputs, fmt="%.6g")
    summary = result.to_dict()
    summary["arm"] = result.model.desc.name
    summary["effects"] = effects
    summary["calibrated_description"] = files["description"].name
    summary["calibrated_covariance"] = files["covariance"].name
    summary["calibrated_urdf"] = files["urdf"].name
    summary["calibrated_training_poses"] = files["training_poses"].name if "training_poses" in files else None
    summary["validation_training"] = validation_training
    summary["validation_holdout"] = validation_holdout
    summary["poorly_determined"] = poorly_determined(result)
    summary["model_check"] = model_check(result)
    if extra:
        summary.update(extra)
    summary.update(provenance(inputs))
    if plots:
        atomic_write_bytes(files["residuals_png"], plot_residuals(result), inputs)
        atomic_write_bytes(files["parameters_png"], plot_parameters(result), inputs)
        atomic_write_bytes(files["correlation_png"], plot_correlation(result), inputs)
        write_discrepancy_png(result, files, inputs)
        write_conformance_pngs(conf, files, inputs)
    atomic_write_text(files["summary"], json_text(summary), inputs)
    atomic_write_text(files["report"], _html(result, summary, files), inputs)
    return files


#: standard uncertainty beyond which a free parameter is reported as poorly determined, per SI unit
POOR_U = {"m": 1e-4, "rad": 1e-3}


def poorly_determined(result: CalibrationResult) -> list[str]:
    """Free parameters whose standard uncertainty exceeds :data:`POOR_U` (0.1 mm, 1 mrad)."""
    out = []
    for r in result.parameter_rows():
        bound = POOR_U.get(r["unit"])
        if r["state"] == "free" and bound is not None and r["u"] > bound:
            du, fac = display_unit(r["unit"])
            out.append(f"{r['name']} (u = {r['u'] * fac:.3g} {du})")
    return out
