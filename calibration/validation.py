"""Validation in the terms of the arm standards (ASME B89.4.22, ISO 10360-12), on any data set.

With the parameters held fixed, each feature of the data is fitted on its own (no certified length
is used to place a centre) and the standard figures are computed:

* single-point articulation test (seats): per measurement, the deviations of the ball centres from
  their mean; per axis ``(max - min) / 2`` and ``2 s`` (s with n - 1), and radially ``2 * RMS``
  (``2 sqrt(sum d^2 / (n - 1))``) and the maximum deviation;
* length test (ball bar, length bar, seat pairs): measured minus certified centre distance, the
  centres fitted with the certified sphere diameter (seats: the mean centre);
* effective diameter test (spheres; rings and cylinders likewise): fitted diameter minus certified,
  with the radius free (instances with at least :data:`DIAMETER_MIN_POINTS` points: a ball-bar
  sphere probed 6 times gives a centre, not a diameter);
* planes: flatness (max - min of the signed distances); reference points: the 3D errors (RMS and max)
  after the best-fit frames ``T_ref_base`` (and marker offsets) of every session, and, given the frames and
  offsets of a fit on other data (:class:`arm_model.tracker.Tracker`: the training data of the same
  instrument stations), the errors with those: a prediction (``reference_*_predicted``);

:func:`before_after` tabulates the figures of two parameter vectors (nominal and calibrated), each
with a standard uncertainty from :func:`bootstrap`: the figures of the calibrated model are fixed
properties of that model (its parameter error is what they measure), so what is uncertain is how well
the few measurements represent the arm's use. The bootstrap resamples the measurements with
replacement; the standard deviation of the resampled figure is its standard uncertainty.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from arm_model.geometry import feature_diameter, smallest_enclosing_sphere
from arm_model.model import ArmModel
from arm_model.tracker import Tracker
from arm_model.units import STATED_SIGMA_M

from .data import CalibrationData, Weights
from .kinds import MIN_POINTS
from .problem import Problem
from .solver import blas_threads, levenberg_marquardt

__all__ = ["Validation", "validate", "validate_poses", "heldout_residuals", "unit_sse", "before_after", "figure_rows",
           "bootstrap", "with_u", "ratio_text", "FIGURES", "DIAMETER_MIN_POINTS", "BOOTSTRAP_SAMPLES", "MpeTest",
           "MPE_TESTS", "conformance", "worse_than_nominal"]

#: resamples of :func:`bootstrap` (the relative precision of a standard deviation from B resamples
#: is about 1 / sqrt(2 B): 3 % for 500)
BOOTSTRAP_SAMPLES = 500

#: fewest points on a sphere, ring or cylinder for a diameter figure
DIAMETER_MIN_POINTS = 9

#: summary figures: key -> (label, unit shown, factor from SI)
FIGURES = {
    "articulation_half_range": ("single-point articulation: max over seats and axes of (max-min)/2", "um", 1e6),
    "articulation_2sigma": ("single-point articulation: max over seats and axes of 2 s", "um", 1e6),
    "articulation_2rms": ("single-point articulation: max over seats of 2 RMS radial deviation", "um", 1e6),
    "articulation_max": ("single-point articulation: max radial deviation", "um", 1e6),
    "length_error_max": ("length test: max |measured - certified|", "um", 1e6),
    "length_error_rms": ("length test: RMS of measured - certified", "um", 1e6),
    "sphere_diameter_error_max": ("effective diameter: max |fitted - certified| (spheres)", "um", 1e6),
    "ring_diameter_error_max": ("ring/cylinder diameter: max |fitted - certified|", "um", 1e6),
    "sphere_form_max": ("sphere form: max (max - min) radial residual", "um", 1e6),
    "flatness_max": ("plane flatness: max (max - min)", "um", 1e6),
    "reference_rms": ("reference points: RMS 3D error after best-fit transform", "um", 1e6),
    "reference_max": ("reference points: max 3D error after best-fit transform", "um", 1e6),
    "reference_rms_predicted": ("reference points: RMS 3D error, frames and markers of the training fit", "um", 1e6),
    "reference_max_predicted": ("reference points: max 3D error, frames and markers of the training fit", "um", 1e6),
    "pose_rms": ("held-out poses: RMS distance from their feature fitted on the training poses", "um", 1e6),
    "pose_max": ("held-out poses: max distance from their feature fitted on the training poses", "um", 1e6),
}


@dataclass
class Validation:
    """Validation figures of one parameter vector on one data set (lengths [m])."""
    articulation: list = field(default_factory=list)
    lengths: list = field(default_factory=list)
    diameters: list = field(default_factory=list)
    planes: list = field(default_factory=list)
    reference: dict | None = None
    #: the reference points' errors [m] and their measurements (for :func:`bootstrap`; not in :meth:`to_dict`)
    reference_errors: tuple | None = field(default=None, repr=False)
    #: reference points with the frames and marker offsets of another fit: n, RMS, max [m]
    reference_predicted: dict | None = None
    reference_predicted_errors: tuple | None = field(default=None, repr=False)
    #: held-out poses against their features fitted on the training poses: n, RMS, max [m]
    poses: dict | None = None
    pose_errors: tuple | None = field(default=None, repr=False)

    def summary(self) -> dict:
        """Key figures (SI) by :data:`FIGURES` key; absent kinds are left out."""
        out = {}
        if self.articulation:
            out["articulation_half_range"] = max(max(a["half_range"]) for a in self.articulation)
            out["articulation_2sigma"] = max(max(a["two_sigma"]) for a in self.articulation)
            out["articulation_2rms"] = max(a["two_rms"] for a in self.articulation)
            out["articulation_max"] = max(a["max_radial"] for a in self.articulation)
        if self.lengths:
            e = np.array([item["error"] for item in self.lengths])
            out["length_error_max"] = float(np.max(np.abs(e)))
            out["length_error_rms"] = float(np.sqrt(np.mean(e ** 2)))
        sph = [d for d in self.diameters if d["kind"] == "sphere"]
        rng = [d for d in self.diameters if d["kind"] != "sphere"]
        if sph:
            out["sphere_diameter_error_max"] = max(abs(d["error"]) for d in sph)
            out["sphere_form_max"] = max(d["form"] for d in sph)
        if rng:
            out["ring_diameter_error_max"] = max(abs(d["error"]) for d in rng)
        if self.planes:
            out["flatness_max"] = max(pl["flatness"] for pl in self.planes)
        if self.reference:
            out["reference_rms"] = self.reference["rms"]
            out["reference_max"] = self.reference["max"]
        for key, item in (("reference", self.reference_predicted), ("pose", self.poses)):
            if item:
                suffix = "_predicted" if key == "reference" else ""
                out[f"{key}_rms{suffix}"], out[f"{key}_max{suffix}"] = item["rms"], item["max"]
        return out

    def to_dict(self) -> dict:
        def clean(v):
            if isinstance(v, np.ndarray):
                return v.tolist()
            if isinstance(v, (np.floating, np.integer)):
                return v.item()
            if isinstance(v, dict):
                return {k: clean(x) for k, x in v.items()}
            if isinstance(v, (list, tuple)):
                return [clean(x) for x in v]
            return v
        return clean({"summary": self.summary(), "articulation": self.articulation, "lengths": self.lengths,
                      "diameters": self.diameters, "planes": self.planes, "reference": self.reference,
                      "reference_predicted": self.reference_predicted, "poses": self.poses})


def _articulation(x: np.ndarray) -> dict:
    dev = x - x.mean(axis=0)
    n = len(x)
    radial = np.linalg.norm(dev, axis=1)
    return {"n": n, "centre": x.mean(axis=0), "half_range": (dev.max(axis=0) - dev.min(axis=0)) / 2,
            "two_sigma": 2 * dev.std(axis=0, ddof=1),
            "two_rms": float(2 * np.sqrt(np.sum(radial ** 2) / (n - 1))), "max_radial": float(radial.max()),
            "enclosing_diameter": 2.0 * smallest_enclosing_sphere(x)[1]}


def validate(model: ArmModel, p, data: CalibrationData, weights: Weights | None = None,
             reference: str = "fit", tracker: Tracker | None = None) -> Validation:
    """Validation figures of ``model`` with parameters ``p`` (full vector, SI) on ``data``; ``tracker`` (the
    frames and marker offsets of a fit on other data of the same instrument stations) adds the reference
    points' errors with those (``reference_predicted``) beside those after their own best fit (left out
    where a session of ``data`` has too few reference points to fit its own frame: a prediction needs none)."""
    from .tracking import as_predicted, own_frames_fit
    with blas_threads(1):
        held = as_predicted(data, tracker, reference)
        if held is data:
            return _validate(model, p, data, weights, reference)
        pred = _validate(model, p, held, weights, reference)
        val = _validate(model, p, data, weights, reference) if own_frames_fit(data) else replace(pred, reference=None,
                                                                                               reference_errors=None)
        assert pred.reference is not None, "data with reference points are validated on them"
        val.reference_predicted = {k: pred.reference[k] for k in ("n", "rms", "max")}
        val.reference_predicted_errors = pred.reference_errors
        return val


def _validate(model, p, data, weights, reference) -> Validation:
    weights = weights or Weights()
    p = np.asarray(p, dtype=float)
    val = Validation()
    prob = Problem(model, data, weights, [], distances=False, reference=reference)
    x_all, _ = prob.centres(p)
    states = levenberg_marquardt(prob, p, prob.initial_states(p)).states
    table = prob.residual_table(p, states)
    lines = data.points.lines
    for i, it in enumerate(prob.instances):
        xi = x_all[prob._pos[it.points]]
        base = {"measurement": it.measurement, "feature": it.feature, "kind": it.kind,
                "line": None if lines is None else int(lines[it.points[0]])}
        if it.kind == "seat" and len(it.points) >= 2:
            val.articulation.append({**base, **_articulation(xi)})
        elif it.kind == "plane":
            v = table["value"][table["instance"] == i]
            val.planes.append({**base, "n": len(v), "flatness": float(v.max() - v.min())})
    _reference_figures(val, prob, states, table, data)
    # lengths: centres of the features (certified diameters), no length used in the fit
    centre = {(it.measurement, it.feature): states[i][:3] for i, it in enumerate(prob.instances)
              if it.kind in ("seat", "sphere")}
    for dist in data.artefacts.distances:
        fa, fb = dist.between
        for m in data.measurements():
            if (m, fa) in centre and (m, fb) in centre:
                measured = float(np.linalg.norm(centre[(m, fa)] - centre[(m, fb)]))
                val.lengths.append({"measurement": m, "between": [fa, fb], "certified": dist.length,
                                    "measured": measured, "error": measured - dist.length})
    # diameters with the radius free
    keep = [it for it in prob.instances if it.kind in ("sphere", "ring", "cylinder")
            and len(it.points) >= max(MIN_POINTS[it.kind][1], DIAMETER_MIN_POINTS)]
    if keep:
        rows = np.sort(np.concatenate([it.points for it in keep]))
        sub = data.select(rows)
        prob_r = Problem(model, sub, weights, [], free_radius=True, distances=False, reference="off")
        st = levenberg_marquardt(prob_r, p, prob_r.initial_states(p)).states
        tab = prob_r.residual_table(p, st)
        ball = model.desc.probe.ball_diameter
        for i, it in enumerate(prob_r.instances):
            feat = data.artefacts.features[it.feature]
            radius = st[i][3] if it.kind == "sphere" else st[i][12]
            fitted = feature_diameter(it.kind, radius, ball)
            v = tab["value"][tab["instance"] == i]
            val.diameters.append({"measurement": it.measurement, "feature": it.feature, "kind": it.kind,
                                  "n": len(it.points), "certified": feat.diameter, "fitted": float(fitted),
                                  "error": float(fitted - feat.diameter), "form": float(v.max() - v.min())})
    return val


def _reference_figures(val: Validation, prob: Problem, states, table, data: CalibrationData) -> None:
    """The reference points' 3D errors over every session: ``val.reference`` (``n``, ``rms``, ``max``,
    ``tracker``: the frames and marker offsets) and ``val.reference_errors``."""
    frames = [i for i, it in enumerate(prob.instances) if it.kind == "reference"]
    if not frames:
        return
    sel = np.isin(table["instance"], frames)
    e = table["value"][sel]
    val.reference = {"n": len(e), "rms": float(np.sqrt(np.mean(e ** 2))), "max": float(e.max()),
                     "tracker": prob.tracker(states).to_dict()}
    val.reference_errors = (e, np.asarray(data.points.measurement)[table["point"][sel]])


def heldout_residuals(model: ArmModel, p, data: CalibrationData, weights: Weights, reference: str = "fit",
                      train=None, cov: tuple | None = None, tracker: Tracker | None = None) -> dict:
    """Residual rows of held-out points with the parameters ``p`` held: ``r`` weighted (n,), ``e`` [m] (n,),
    ``measurement``, ``kind`` and ``point`` (index into ``data``, -1 for a length) per row, ``nuisance``:
    the number of nuisance unknowns solved on these rows (0 with ``train``: they are solved on the training poses),
    ``held``: the number held at the training fit's values (``tracker``'s frames and offsets,
    :func:`calibration.tracking.held_unknowns`), and ``propagated``: with ``cov`` = (names, covariance [SI]) of the
    fitted parameters and ``train`` None, the sum over the rows of the variance the parameters' uncertainty adds to
    each weighted residual once the nuisance unknowns are solved on the rows, ``tr(P J C J^T P)`` (``J`` the
    weighted rows' Jacobian in those parameters, ``P`` the projection off the nuisance unknowns' columns); else None.

    ``train`` None: every point of ``data`` is held out and every nuisance unknown (centre, axis, plane) is solved
    on ``data`` alone, but those of the reference instrument that ``tracker`` (the training fit's) holds: each
    session's ``T_ref_base`` and the markers' offsets are the training fit's
    (:func:`calibration.tracking.as_predicted`, the rule of ``calibrate``'s held-out figures), a session it has no
    frame for is solved on ``data``. ``train`` a mask: the points where it holds are the training poses; the
    nuisance unknowns are solved on them, and the rows of the other points are returned (a held-out pose against
    the centre fitted on the rest of its feature's poses); the lengths then belong to training."""
    from .tracking import as_predicted, held_unknowns
    given, data = data, as_predicted(data, tracker, reference)
    prob = Problem(model, data, weights, [], reference=reference)
    if train is None:
        states = levenberg_marquardt(prob, p, prob.initial_states(p)).states
        keep = np.ones(prob.n_rows, bool)
    else:
        train = np.asarray(train, bool)
        sub = Problem(model, data.select(train), weights, [], reference=reference)
        fitted = {(it.measurement, it.feature): st for it, st in
                  zip(sub.instances, levenberg_marquardt(sub, p, sub.initial_states(p)).states, strict=True)}
        start = prob.initial_states(p)
        states = [fitted.get((it.measurement, it.feature), s0) for it, s0 in zip(prob.instances, start, strict=True)]
        missing = [f"{it.measurement} {it.feature}" for it in prob.instances
                   if (it.measurement, it.feature) not in fitted]
        if missing:
            raise ValueError(f"no training pose on {', '.join(missing)}: its centre cannot be predicted")
        keep = (prob.row_distance < 0) & ~train[np.maximum(prob.row_point, 0)]
    r = prob.evaluate(p, states, jac=False).r
    # the parameters' uncertainty along what the frames and offsets absorb is not a prediction's: projected off
    # their columns as when they are solved (the held frames' and offsets' own share: ``held``)
    propagated = (_propagated(prob if data is given else Problem(model, given, weights, [], reference=reference), p,
                              states, cov) if cov is not None and train is None else None)
    pts = data.points
    meas = np.empty(len(r), dtype=object)
    kind = np.empty(len(r), dtype=object)
    ok = prob.row_distance < 0
    meas[ok] = pts.measurement[prob.row_point[ok]]
    kind[ok] = [prob.instances[i].kind for i in prob.row_instance[ok]]
    for row in np.flatnonzero(~ok):
        meas[row] = prob.distance_items[prob.row_distance[row]].measurement
        kind[row] = "length"
    point = np.where(ok, prob.row_point, -1)
    return {"r": r[keep], "e": (r * prob.sigma)[keep], "measurement": meas[keep], "kind": kind[keep],
            "point": point[keep], "nuisance": int(prob.n_nuisance) if train is None else 0,
            "held": held_unknowns(data, reference), "propagated": propagated}


def _propagated(prob: Problem, p, states, cov: tuple) -> float | None:
    """``tr(P J C J^T P)`` of :func:`heldout_residuals` (None when the covariance is not finite)."""
    names, c = cov
    c = np.asarray(c, dtype=float)
    if not len(names) or c.shape != (len(names), len(names)) or not np.all(np.isfinite(c)):
        return None
    spec = prob.model.spec
    ev = prob.with_free([spec.index(n) for n in names]).evaluate(p, states, jac=True)
    jp, jt = ev.jp, ev.jt.toarray()
    if jt.shape[1]:
        jp = jp - jt @ np.linalg.lstsq(jt, jp, rcond=None)[0]
    return float(np.sum((jp @ c) * jp))


def unit_sse(keys: list, r: np.ndarray) -> dict:
    """{unit: (sum of its squared residuals, its number of rows)} of the residual rows ``r`` whose units are
    ``keys`` (one a row: a measurement, a point, (measurement, point)), in the order units first appear. One pass
    over the rows (grouping by a mask per unit was quadratic in the held-out points: the per-pose folds of 10^4
    points); each unit's rows summed in their order, bit for bit as a boolean mask of them would be."""
    rows: dict = {}
    for n, key in enumerate(keys):
        rows.setdefault(key, []).append(n)
    return {key: (float(np.sum(r[idx] ** 2)), len(idx)) for key, idx in rows.items()}


def _point_norms(e: np.ndarray, point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(idx, norms)``: the points of the rows ``point`` (N,) (-1: a row of no point, left out), ascending, and the
    norm [m] of each one's rows of ``e`` (N,) [m], bit for bit ``sqrt(sum(e[point == i] ** 2))`` but in one pass
    (:func:`unit_sse`; that mask per point was quadratic in the rows: 5000 points took seconds)."""
    on = point >= 0
    sums = unit_sse(point[on].tolist(), np.asarray(e, dtype=float)[on])
    idx = np.array(sorted(sums), dtype=point.dtype)
    return idx, np.sqrt(np.array([sums[i][0] for i in idx.tolist()], dtype=float))


def validate_poses(model: ArmModel, p, data: CalibrationData, train, weights: Weights | None = None,
                   reference: str = "fit") -> Validation:
    """Figures of the poses of ``data`` outside the mask ``train``, each predicted against its feature as
    fitted on the training poses (a seat's centre, a sphere, a plane, a ring's axis; the reference points
    with the ``T_ref_base`` fitted on the training reference points): ``poses`` = n, RMS and max of each
    held-out point's distance [m] (the norm of its residual rows), with the errors by measurement for
    :func:`bootstrap`."""
    with blas_threads(1):
        h = heldout_residuals(model, p, data, weights or Weights(), reference, train)
    idx, e = _point_norms(h["e"], h["point"])
    val = Validation()
    if len(e):
        val.poses = {"n": int(len(e)), "rms": float(np.sqrt(np.mean(e ** 2))), "max": float(e.max())}
        val.pose_errors = (e, np.asarray(data.points.measurement)[idx])
    return val


def worse_than_nominal(rows: list[dict]) -> list[dict]:
    """The rows of :func:`figure_rows` (nominal before, calibrated after) where the calibrated model is worse
    than the nominal: ``after > before``, beyond rounding (:data:`arm_model.units.STATED_SIGMA_M`; rows in um)."""
    return [r for r in rows if r["after"] > r["before"] and r["after"] >= STATED_SIGMA_M[0] * 1e6]


def _units(val: Validation) -> dict:
    """Measurement id -> its items: (list name, item); ``"reference"`` items are the errors [m]."""
    out: dict = {}
    for name in ("articulation", "lengths", "diameters", "planes"):
        for item in getattr(val, name):
            out.setdefault(item["measurement"], []).append((name, item))
    for name, errors in (("reference", val.reference_errors), ("reference_predicted", val.reference_predicted_errors),
                         ("poses", val.pose_errors)):
        if errors is not None:
            e, meas = errors
            for m in dict.fromkeys(meas.tolist()):
                out.setdefault(m, []).append((name, e[meas == m]))
    return out


def _summary_of(items) -> dict:
    v = Validation()
    errors: dict = {}
    for name, item in items:
        if name in ("reference", "reference_predicted", "poses"):
            errors.setdefault(name, []).append(item)
        else:
            getattr(v, name).append(item)
    for name, parts in errors.items():
        e = np.concatenate(parts)
        setattr(v, name, {"n": len(e), "rms": float(np.sqrt(np.mean(e ** 2))), "max": float(np.max(np.abs(e)))})
    return v.summary()


def resamples(n: int, samples: int = BOOTSTRAP_SAMPLES, seed: int = 0):
    """The bootstrap's draws over ``n`` units (measurements): ``samples`` index arrays of ``n`` drawn with
    replacement, seeded (the same data give the same uncertainties)."""
    rng = np.random.default_rng(seed)
    for _ in range(samples):
        yield rng.integers(0, n, n)


def bootstrap(val: Validation, samples: int = BOOTSTRAP_SAMPLES, seed: int = 0) -> dict:
    """Standard uncertainty [SI] of each figure of ``val.summary()`` by a bootstrap over the
    measurements: the measurements resampled with replacement (each with all its items: a seat's
    articulation, a length, a diameter, its reference points; resampling whole measurements only, the
    spread inside a measurement enters through the spread between them, as Davison and Hinkley (1997,
    section 3.8) recommend for two-stage data), the figure recomputed on each resample and its
    standard deviation (ddof 1) returned. A figure whose items come from fewer than two measurements
    gets None. Seeded: the same data give the same uncertainties."""
    units = _units(val)
    count: dict = {}
    for items in units.values():
        for key in _summary_of(items):
            count[key] = count.get(key, 0) + 1
    out = {k: None for k in val.summary()}
    ids = list(units)
    draws: dict = {k: [] for k, n in count.items() if n >= 2}
    if not draws:
        return out
    for idx in resamples(len(ids), samples, seed):
        items = [it for m in idx for it in units[ids[m]]]
        for k, x in _summary_of(items).items():
            if k in draws:
                draws[k].append(x)
    for k, xs in draws.items():
        if len(xs) >= 2:
            out[k] = float(np.std(xs, ddof=1))
    return out


def ratio_text(ratio: float | None) -> str:
    """A row's nominal/calibrated ratio as the console shows it: ``"15.70x"``, or that there is none."""
    return "no ratio: the calibrated figure is below 1 pm" if ratio is None else f"{ratio:.2f}x"


def with_u(value, u, digits: int = 2) -> str:
    """``"12.30 ± 0.45"`` (``"12.30"`` without an uncertainty)."""
    if value is None:
        return "-"
    return f"{value:.{digits}f}" + ("" if u is None else f" ± {u:.{digits}f}")


def before_after(model: ArmModel, p_before, p_after, data: CalibrationData, weights: Weights | None = None,
                 reference: str = "fit") -> list[dict]:
    """Rows ``{key, label, unit, before, after, ratio, u_before, u_after}`` (values in the shown unit)
    of the validation figures of ``p_before`` (e.g. zeros: the nominal arm) and ``p_after`` on
    ``data``; ``u_*``: standard uncertainties by :func:`bootstrap` over the measurements (None with
    fewer than two measurements of the figure's kind)."""
    return figure_rows(validate(model, p_before, data, weights, reference),
                       validate(model, p_after, data, weights, reference))


def figure_rows(va: Validation, vb: Validation) -> list[dict]:
    """The rows of :func:`before_after` from the two validations (before, after)."""
    a, b = va.summary(), vb.summary()
    ua, ub = bootstrap(va), bootstrap(vb)
    rows = []
    for key, (label, unit, factor) in FIGURES.items():
        if key in a and key in b:
            # every figure is a length [m]: below the smallest stated uncertainty it is rounding (a seat probed at
            # one pose repeated), and a ratio to it is no measured gain (it was printed "infx")
            ratio = a[key] / b[key] if b[key] >= STATED_SIGMA_M[0] else None
            rows.append({"key": key, "label": label, "unit": unit, "before": a[key] * factor,
                         "after": b[key] * factor, "ratio": ratio,
                         "u_before": None if ua.get(key) is None else ua[key] * factor,
                         "u_after": None if ub.get(key) is None else ub[key] * factor})
    return rows


# ---------------------------------------------------------------------------------------------------
# conformance with maximum permissible errors (MPE)

@dataclass(frozen=True)
class MpeTest:
    """One acceptance test of the arm standards: its ``key`` (the option ``--mpe-<key>-um``), standard,
    name, what one tested value is, and whether the values are signed (an error against a certified
    value: passes when ``|value| <= MPE``, drawn against a +-MPE band) or sizes (``0 <= value <= MPE``)."""
    key: str
    standard: str
    name: str
    what: str
    signed: bool

    @property
    def option(self) -> str:
        return f"--mpe-{self.key}-um"

    def values(self, val: Validation) -> list[tuple[str, float]]:
        """(label, value [m]) of every tested item of ``val`` (a measurement and its feature or length)."""
        sph = [d for d in val.diameters if d["kind"] == "sphere"]
        if self.key in ("e-uni", "volumetric"):
            return [(f"{x['measurement']} {' - '.join(x['between'])}", x["error"]) for x in val.lengths]
        if self.key in ("p-size", "eff-diameter"):
            return [(f"{d['measurement']} {d['feature']}", d["error"]) for d in sph]
        if self.key == "p-form":
            return [(f"{d['measurement']} {d['feature']}", d["form"]) for d in sph]
        if self.key == "l-dia":
            return [(f"{a['measurement']} {a['feature']}", a["enclosing_diameter"]) for a in val.articulation]
        if self.key == "spat":
            return [(f"{a['measurement']} {a['feature']}", a["max_radial"]) for a in val.articulation]
        raise KeyError(self.key)


#: the tests an MPE can be given for, in report order
MPE_TESTS = (
    MpeTest("e-uni", "ISO 10360-12", "E_UNI", "length error: measured - certified centre distance of each "
            "certified length (ball bar, seat pairs), |error| <= MPE", True),
    MpeTest("p-size", "ISO 10360-12", "P_Size", "probing size error: fitted - certified diameter of each sphere "
            f"(at least {DIAMETER_MIN_POINTS} points, radius free), |error| <= MPE", True),
    MpeTest("p-form", "ISO 10360-12", "P_Form", "probing form error: max - min radial residual of each sphere "
            "(radius free), <= MPE", False),
    MpeTest("l-dia", "ISO 10360-12", "L_Dia", "articulated location error: diameter of the smallest sphere "
            "enclosing the ball centres of each seat (one centre an articulation), <= MPE", False),
    MpeTest("spat", "ASME B89.4.22", "single-point articulation", "largest distance of a seat's ball centres "
            "from their mean (delta_max), <= MPE", False),
    MpeTest("eff-diameter", "ASME B89.4.22", "effective diameter", "fitted - certified diameter of each sphere, "
            "|error| <= MPE", True),
    MpeTest("volumetric", "ASME B89.4.22", "volumetric length", "measured - certified centre distance of each "
            "certified length, |error| <= MPE", True),
)


def conformance(val: Validation, mpe: dict | None = None, before: Validation | None = None) -> list[dict]:
    """Every test of :data:`MPE_TESTS` the data hold items for, on the validation ``val`` (the calibrated
    model): ``{key, standard, test, what, option, signed, n, items: [{label, value_um, nominal_um}],
    max_abs_um, mpe_um, result, n_fail}``, ``mpe`` {key: MPE [m]} (tests without one: ``mpe_um`` and
    ``result`` None), ``result`` "PASS" when every item is within the MPE, else "FAIL" (with the failing
    count ``n_fail``); ``nominal_um`` the same item under ``before`` (the nominal model) when given. A
    test with an MPE but no item in the data gets a row with ``n`` 0 and ``result`` None (not tested)."""
    mpe = mpe or {}
    out = []
    for t in MPE_TESTS:
        items = t.values(val)
        if not items:
            if mpe.get(t.key) is not None:
                out.append({"key": t.key, "standard": t.standard, "test": t.name, "what": t.what,
                            "option": t.option, "signed": t.signed, "n": 0, "items": [], "max_abs_um": None,
                            "mpe_um": mpe[t.key] * 1e6, "result": None, "n_fail": None})
            continue
        nominal = dict(t.values(before)) if before is not None else {}
        v = np.array([x for _, x in items]) * 1e6
        row = {"key": t.key, "standard": t.standard, "test": t.name, "what": t.what, "option": t.option,
               "signed": t.signed, "n": len(items),
               "items": [{"label": lab, "value_um": float(x * 1e6),
                          "nominal_um": None if lab not in nominal else float(nominal[lab] * 1e6)}
                         for lab, x in items],
               "max_abs_um": float(np.max(np.abs(v))), "mpe_um": None, "result": None, "n_fail": None}
        if mpe.get(t.key) is not None:
            m = mpe[t.key] * 1e6
            bad = int(np.sum(np.abs(v) > m))
            row.update(mpe_um=m, result="FAIL" if bad else "PASS", n_fail=bad)
        out.append(row)
    return out
