"""Held-out placements of a seat plate: train on one placement, predict the others.

The study the real-data sections of ``docs/studies/calibration.md`` and ``docs/studies/close-loop.md`` report: a plate
with two seats a certified distance apart is measured at several placements (one folder each, with a
``points.csv``); for every training placement, ``aacmm calibrate`` and ``aacmm close-loop`` are run on it
with their default options, and the model each writes is applied by ``aacmm tip`` to the points of the
other placements. Figures per held-out placement (``seat_figures``):

* **seat spread (2 sigma) per hole** [mm]: ``2 sqrt(sum_i |x_i - x_mean|^2 / (n - 1))`` over the n ball
  centres in the hole (twice the RMS radial distance to the hole's mean centre, n - 1 for the mean fitted;
  the single-point articulation figure ``two_rms`` of :mod:`calibration.validation`);
* **distance error** [mm]: distance between the two holes' mean centres minus the certified length;
* **distance error with the capture-order trend removed** [mm] (:func:`order_detrended_distance_error`, a
  diagnostic, not a figure of merit): the same with one linear trend over the points' order in the file, shared by
  both holes, fitted out; it tells an error carried by the order of capture (the plate or the base drifting while
  the holes are measured one after the other, or the poses swept in order) from one the model makes;
* **coverage of u** (when the model carries an uncertainty): the share of the axis values whose deviation
  from their hole's mean centre lies within 1.96 u, for ``tip``'s u of each centre (``inside``) and for the
  standard uncertainty of the deviation itself (``inside_dev``, :func:`deviation_u`: the errors every point of
  the hole shares, such as where the whole seat lands, cancel in a deviation from the hole's mean and are left
  out; the errors of each point alone count with their share in the mean).

Run as ``python scripts/real_seats_study.py`` (see its ``--help``).
"""
from __future__ import annotations

import contextlib
import io
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from arm_model import InputError
from arm_model.log import progress_line

__all__ = ["seat_figures", "order_detrended_distance_error", "deviation_u", "model_deviation_u", "PlacementRow",
           "placement_study", "markdown_table"]


def deviation_u(prop, feature: np.ndarray, holes) -> np.ndarray:
    """(N, 3) [m]: the standard uncertainty per axis of each point's deviation from its hole's mean centre,
    ``x_i - mean_h(x)``, from a :class:`~arm_model.uncertainty.Propagation` made with ``systematic=True``.

    The shared errors (the rows ``S_i`` of :attr:`~arm_model.uncertainty.Propagation.systematic`: parameters and
    compliances; the covariance of points i and k is ``S_i^T S_k``) enter as ``S_i - mean_h(S)``; the rest of each
    point's covariance, ``C_i - S_i^T S_i``, is its own (encoders, force sensor, probing, model discrepancy) and
    enters with the weight it keeps in ``x_i - mean_h(x)``: ``(1 - 2/n) C_ind,i + sum_k C_ind,k / n^2``. Points of no
    hole in ``holes`` get NaN."""
    s = prop.systematic
    if s is None:
        raise ValueError("deviation_u needs a propagation made with systematic=True")
    own = np.einsum("nii->ni", prop.cov) - np.einsum("nri,nri->ni", s, s)
    out = np.full(own.shape, np.nan)
    feature = np.asarray(feature)
    for h in holes:
        sel = feature == h
        n = int(sel.sum())
        if not n:
            continue
        sd = s[sel] - s[sel].mean(axis=0)
        var = np.einsum("nri,nri->ni", sd, sd) + own[sel] * (1 - 2 / n) + own[sel].sum(axis=0) / n ** 2
        out[sel] = np.sqrt(np.clip(var, 0.0, None))
    return out


def model_deviation_u(model: Path, points: Path, holes) -> np.ndarray | None:
    """:func:`deviation_u` of the points file ``points`` corrected by the model file ``model`` (its covariance,
    probing scatter and model discrepancy, as ``aacmm tip`` takes them); None when the model carries no
    parameter covariance."""
    from arm_model.io import read_points
    from arm_model.model_file import parameters_of, read_model_file
    from arm_model.uncertainty import propagate
    arm = read_model_file(Path(model))
    parameters = parameters_of(arm)
    if parameters is None:
        return None
    pts = read_points(Path(points), arm.desc.n_joints)
    prop = propagate(arm.model, arm.p, pts.q, pts.wrench, arm.aux(pts), parameters=parameters,
                     inputs=arm.input_uncertainty(pts.wrench is not None), systematic=True)
    return deviation_u(prop, pts.feature, holes)


def order_detrended_distance_error(x: np.ndarray, feature: np.ndarray, holes: tuple[str, str], length: float) -> float:
    """The distance error [mm] of two holes' centres with one linear trend over the capture order removed: ``x``
    (N, 3) [m] the ball centres in the order they were captured (a points file's rows), ``feature`` each one's hole;
    the points of ``holes`` are fitted by ``x_i = c_h(i) + v (i - i_mean)`` (least squares, per axis: the two centres
    ``c`` and one trend ``v`` [m per point] for both holes), and ``|c_1 - c_0| - length`` is returned. The trend is
    fixed by the order within each hole only (the centres take each hole's mean), and moves the distance by
    ``v`` times the gap between the holes' mean positions in the order: large when the holes were measured one after
    the other and the points drift along the order, nil when the order carries nothing."""
    feature = np.asarray(feature)
    sel = np.isin(feature, holes)
    n = int(sel.sum())
    t = np.arange(n) - (n - 1) / 2.0
    a = np.column_stack([feature[sel] == holes[0], feature[sel] == holes[1], t]).astype(float)
    if np.linalg.matrix_rank(a) < 3:
        raise InputError(f"holes {holes[0]}, {holes[1]}: a trend over the capture order needs two points in a hole")
    coef = np.linalg.lstsq(a, np.asarray(x, float)[sel], rcond=None)[0]
    return float(np.linalg.norm(coef[1] - coef[0]) - length) * 1e3


def seat_figures(x: np.ndarray, feature: np.ndarray, holes: tuple[str, str], length: float,
                 u: np.ndarray | None = None, u_dev: np.ndarray | None = None) -> dict:
    """Spread (2 sigma) of each hole and the distance error (also with the capture-order trend removed,
    :func:`order_detrended_distance_error`), from ball centres ``x`` (N, 3) [m] in their captured order and the
    feature of each point; values [mm]. With the centres' standard uncertainties ``u`` (N, 3) [m], also the
    coverage: ``inside`` of the ``values`` axis deviations from their hole's mean centre lie within 1.96 u;
    with the deviations' own standard uncertainties ``u_dev`` (N, 3) [m] (:func:`deviation_u`), ``inside_dev``
    of them within 1.96 u_dev."""
    out, centre = {}, {}
    inside = values = inside_dev = 0
    for h in holes:
        sel = np.asarray(feature) == h
        xi = x[sel]
        if len(xi) < 2:
            raise InputError(f"hole '{h}': {len(xi)} point(s), a spread needs at least 2")
        d = xi - xi.mean(axis=0)
        out[f"spread_{h}_mm"] = float(2 * np.sqrt(np.sum(d ** 2) / (len(xi) - 1))) * 1e3
        centre[h] = xi.mean(axis=0)
        if u is not None:
            inside += int(np.sum(np.abs(d) <= 1.96 * u[sel]))
        if u_dev is not None:
            inside_dev += int(np.sum(np.abs(d) <= 1.96 * u_dev[sel]))
        values += d.size
    if u is not None:
        out["inside"], out["values"] = inside, values
    if u_dev is not None:
        out["inside_dev"], out["values"] = inside_dev, values
    out["spread_mean_mm"] = float(np.mean([out[f"spread_{h}_mm"] for h in holes]))
    dist = float(np.linalg.norm(centre[holes[0]] - centre[holes[1]]))
    out["distance_mm"] = dist * 1e3
    out["distance_error_mm"] = (dist - length) * 1e3
    out["distance_error_detrended_mm"] = order_detrended_distance_error(x, feature, holes, length)
    return out


@dataclass
class PlacementRow:
    """One training placement, one method, one held-out placement."""
    train: str
    method: str              # "calibrate" or "close-loop"
    test: str
    figures: dict
    effects: tuple = ()

    def to_dict(self) -> dict:
        return {"train": self.train, "method": self.method, "test": self.test, "effects": list(self.effects),
                **self.figures}


def _cli(argv: list[str]) -> str:
    """Run ``aacmm`` in this process; its stdout (raises on a non-zero exit)."""
    from arm_model.cli import main
    buf, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        code = main(argv)
    if code != 0:
        raise RuntimeError(f"aacmm {' '.join(argv)} exited with {code}: {err.getvalue().strip()}")
    return buf.getvalue()


def _tip(points: Path, arm: Path, out: Path, tip_frame: str | None = None):
    """``aacmm tip`` of ``points`` with the model ``arm``: (ball centres (N, 3) [m], features, their standard
    uncertainties (N, 3) [m] or None when the model carries none)."""
    argv = ["tip", str(points), "--arm", str(arm), "-o", str(out)]
    if tip_frame:
        argv += ["--tip-frame", tip_frame]
    _cli(argv)
    import csv
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    x = np.array([[float(r[f"{a}_mm"]) for a in "xyz"] for r in rows]) * 1e-3
    u = None
    if rows and "u_x_mm" in rows[0]:
        u = np.array([[float(r[f"u_{a}_mm"]) for a in "xyz"] for r in rows]) * 1e-3
    return x, np.array([r["feature"] for r in rows]), u


def _loop_model(folder: Path) -> Path | None:
    """The model file ``aacmm close-loop`` wrote in ``folder`` (a description TOML), if any."""
    found = sorted(p for p in folder.glob("*.toml"))
    return found[0] if found else None


def placement_study(root: Path, arm: Path, tip_frame: str | None, out: Path, train=None, progress=None,
                    methods=("calibrate", "close-loop"), options: dict | None = None) -> list[PlacementRow]:
    """Train on each placement (folders of ``root`` with a points.csv; ``train``: only these, ``"a+b"``
    trains on placements a and b together, their points in one file), predict the others; outputs of every
    command under ``out``. ``root`` holds the ``artefacts.toml`` (two seats and
    one certified distance between them). ``methods``: ``close-loop`` runs ``aacmm close-loop``, any other name
    ``aacmm calibrate`` (``calibrate`` with its defaults; e.g. ``geometry`` with ``--effect none`` given in
    ``options``); a name starting ``close-loop`` (``close-loop@1``) runs ``aacmm close-loop`` with that method's
    options (e.g. ``--seed 1``); ``nominal`` applies ``arm`` itself, nothing fitted. ``options``: extra
    command-line options per method (lists)."""
    from arm_model.io import read_artefacts
    root, out = Path(root), Path(out)
    say = progress or progress_line(logging.getLogger(__name__))
    artefacts = root / "artefacts.toml"
    art = read_artefacts(artefacts)
    if len(art.distances) != 1:
        raise InputError("the study needs exactly one certified distance between two seats", artefacts)
    holes, length = tuple(art.distances[0].between), art.distances[0].length
    places = sorted(p.name for p in root.iterdir() if (p / "points.csv").is_file())
    if len(places) < 2:
        raise InputError(f"{len(places)} placement folder(s) with a points.csv: at least 2 needed", root)
    arm_opts = ["--arm", str(arm)] + (["--tip-frame", tip_frame] if tip_frame else [])
    rows: list[PlacementRow] = []
    for tr in train or places:
        group = tr.split("+")
        for g in group:
            if g not in places:
                raise InputError(f"no placement '{g}' (known: {', '.join(places)})", root)
        pts = root / tr / "points.csv"
        if len(group) > 1:                  # several placements trained together: one points file
            parts = [(root / g / "points.csv").read_text().splitlines() for g in group]
            pts = out / tr / "points.csv"
            pts.parent.mkdir(parents=True, exist_ok=True)
            pts.write_text("\n".join(parts[0] + [ln for p in parts[1:] for ln in p[1:] if ln.strip()]) + "\n")
        models = {}
        if "nominal" in methods:
            models["nominal"] = (arm, ())
        for method in (m for m in methods if not m.startswith("close-loop") and m != "nominal"):   # calibrate
            say(f"{tr}: aacmm calibrate ({method})")
            dst = out / tr / method
            _cli(["calibrate", str(pts), str(artefacts), *arm_opts, "-o", str(dst), "--no-plots",
                  *(options or {}).get(method, [])])
            models[method] = (next(dst.glob("*-calibrated.toml")), ())
        for method in (m for m in methods if m.startswith("close-loop")):
            say(f"{tr}: aacmm close-loop ({method})")
            dst = out / tr / method
            _cli(["close-loop", str(pts), str(artefacts), *arm_opts, "-o", str(dst), "--quiet", "--no-plots",
                  *(options or {}).get(method, [])])
            import json
            summary = json.loads((dst / "summary.json").read_text())
            effects = tuple(e["name"] for e in summary["effects_added"])
            model = _loop_model(dst)
            if model is None:
                raise RuntimeError(f"aacmm close-loop wrote no model file in {dst}")
            models[method] = (model, effects)
        for method, (model, effects) in models.items():
            for te in places:
                if te in group:
                    continue
                x, feat, u = _tip(root / te / "points.csv", model, out / tr / f"{method}-tip-{te}.csv",
                                  tip_frame if method == "nominal" else None)
                u_dev = None if u is None else model_deviation_u(model, root / te / "points.csv", holes)
                rows.append(PlacementRow(tr, method, te, seat_figures(x, feat, holes, length, u, u_dev), effects))
                say(f"  {method} -> {te}: spread {rows[-1].figures['spread_mean_mm']:.3f} mm, distance error "
                    f"{rows[-1].figures['distance_error_mm']:+.3f} mm")
    return rows


def _coverage(figs: list[dict], key: str) -> str:
    """The pooled share [%] of the axis values ``key`` counts (``inside`` or ``inside_dev``), or "-"."""
    if not figs or any(key not in f for f in figs):
        return "-"
    return f"{100.0 * sum(f[key] for f in figs) / sum(f['values'] for f in figs):.1f}"


def markdown_table(rows: list[PlacementRow], holes=("hole-0", "hole-1")) -> str:
    """One line per training placement, method and held-out placement, and the mean per method (coverage:
    pooled over the held-out placements)."""
    head = ("| trained on | model | held out | " + " | ".join(f"spread {h} 2σ [mm]" for h in holes)
            + " | distance error [mm] | within 1.96 u [%]: tip's u / the deviation's u | effects added |")
    lines = [head, "|" + "---|" * (6 + len(holes))]
    for r in rows:
        f = r.figures
        lines.append(f"| {r.train} | {r.method} | {r.test} | "
                     + " | ".join(f"{f[f'spread_{h}_mm']:.3f}" for h in holes)
                     + f" | {f['distance_error_mm']:+.3f} | {_coverage([f], 'inside')} / {_coverage([f], 'inside_dev')}"
                     + f" | {', '.join(r.effects) or '-'} |")
    for m in dict.fromkeys(r.method for r in rows):
        sel = [r.figures for r in rows if r.method == m]
        lines.append(f"| **mean** | {m} | all | "
                     + " | ".join(f"{np.mean([f[f'spread_{h}_mm'] for f in sel]):.3f}" for h in holes)
                     + f" | {np.mean([abs(f['distance_error_mm']) for f in sel]):.3f} (mean abs; "
                     + f"{np.mean([abs(f['distance_error_detrended_mm']) for f in sel]):.3f} with the capture-order "
                     + "trend removed) | "
                     + f"{_coverage(sel, 'inside')} / {_coverage(sel, 'inside_dev')} | |")
    return "\n".join(lines)
