"""Correction models of a ring-gauge campaign: the seed paper's four and the project's full-wrench one.

The paper's models (Eq. 3-9): each ball centre is moved by ``|d| = f c`` along the unit vector from the
point to the cylinder axis, perpendicular to it (the plane through the point normal to the axis cuts the
axis at the foot point), then the cylinder is fitted again. ``c`` is the probe's bending compliance of
the arm description (the paper's FEM value 0.0142 mm/N in the nominal arm) and ``f`` is, per model:

* ``point``: the point's own bending force [N] (see :mod:`correction.signals` for the definition),
* ``mean``, ``max10``, ``max``: the measurement's mean, mean of the 10 largest, maximum bending force.

The full-wrench model (``wrench``): the ball centres are evaluated again through the probe's virtual
elastic joint of the arm model, ``arm_model.ball_centres(desc, q, wrench)``, with each point's full
force vector (and torque, when the points file has one), then the cylinder is fitted again. It needs no
assumption on the direction of the force and acts on the whole 3-D deflection.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from arm_model import InputError, NumericalError
from arm_model.geometry import CylinderFit, ring_fit
from arm_model.io import PointSet, read_force_signal
from arm_model.output import safe_name

from .signals import ForceSummary, PointForces, find_point_forces, force_summary, forces_from_columns

__all__ = ["PAPER_MODELS", "MODELS", "MODEL_LABELS", "paper_correction", "correct_ring", "RingMeasurement",
           "RingCampaign", "analyse_ring_campaign", "ring_uncertainties", "measurement_forces", "table2",
           "campaign_summary"]

#: the paper's four models, in the order of its Table 2 (point, mean, max, 10Max) kept as labelled
PAPER_MODELS = ("point", "mean", "max", "max10")
#: every model of a campaign: the initial (rigid) evaluation, the paper's four, the full wrench
MODELS = ("initial",) + PAPER_MODELS + ("wrench",)
MODEL_LABELS = {"initial": "initial", "point": "point force", "mean": "mean force", "max": "max force",
                "max10": "10Max force", "wrench": "full wrench"}


def paper_correction(centres, cylinder: CylinderFit, force, compliance: float) -> np.ndarray:
    """The paper's Eq. 8: ``p' = p + |f c| u``, u the unit vector from p to the axis.

    Args:
        centres: (N, 3) ball centres [m].
        cylinder: the fit of ``centres`` giving the axis.
        force: scalar or (N,) force [N] (the bending force magnitude, per point or one value).
        compliance: [m/N].

    Returns: (N, 3) corrected ball centres [m].
    """
    p = np.asarray(centres, float)
    d = np.abs(np.broadcast_to(np.asarray(force, float), (len(p),)) * compliance)
    return p + d[:, None] * cylinder.to_axis(p)


@dataclass(frozen=True)
class RingMeasurement:
    """One measurement of the ring: its per-point forces and one :class:`RingFit` per model.

    ``fits`` maps model name (see :data:`MODELS`) to the fit; ``summary`` holds the paper's mean, max and
    10Max of the bending forces [N]; ``lines`` the points file lines of its rows."""
    id: str
    forces: PointForces
    summary: ForceSummary
    fits: dict
    lines: np.ndarray | None = None
    rows: np.ndarray | None = None

    @property
    def n_points(self) -> int:
        return len(self.forces)

    def diameter_error(self, model: str) -> float:
        return self.fits[model].diameter_error

    def form_error(self, model: str) -> float:
        return self.fits[model].form_error


def correct_ring(rigid, ball_diameter: float, reference_diameter: float | None, compliance: float,
                 forces: PointForces, wrench_centres=None, models=MODELS) -> dict:
    """Fit the ring initially and after each correction model.

    Args:
        rigid: (N, 3) rigid ball centres (what the arm software reports) [m].
        ball_diameter: [m]; reference_diameter: the ring's certified diameter [m] or None.
        compliance: the bending compliance used by the paper's models [m/N].
        forces: per-point forces (:class:`PointForces`).
        wrench_centres: (N, 3) deflection-corrected ball centres for the full-wrench model [m].
        models: which models to evaluate (subset of :data:`MODELS`).

    Returns: {model: RingFit}.
    """
    fits = {"initial": ring_fit(rigid, ball_diameter, reference_diameter)}
    axis = fits["initial"].cylinder.axis
    bend = forces.bending
    s = force_summary(bend)
    values = {"point": bend, "mean": s.mean, "max": s.max, "max10": s.max10}
    for m in models:
        if m in values:
            moved = paper_correction(rigid, fits["initial"].cylinder, values[m], compliance)
            fits[m] = ring_fit(moved, ball_diameter, reference_diameter, axis_hint=axis)
        elif m == "wrench":
            if wrench_centres is None:
                raise ValueError("the full-wrench model needs wrench_centres")
            fits[m] = ring_fit(wrench_centres, ball_diameter, reference_diameter, axis_hint=axis)
        elif m != "initial":
            raise ValueError(f"unknown model {m!r} (known: {', '.join(MODELS)})")
    return fits


@dataclass(frozen=True)
class RingCampaign:
    """A ring-gauge campaign analysed: the ring feature, its reference diameter [m], the compliance the
    paper's models used [m/N], and the measurements in file order; the ring's certified standard
    uncertainty of the diameter and its form error [m] when the artefacts file gives them."""
    feature: str
    reference_diameter: float | None
    ball_diameter: float
    compliance: float
    force_kind: str
    measurements: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    u_diameter: float | None = None
    reference_form_error: float | None = None

    @property
    def models(self) -> tuple:
        return tuple(m for m in MODELS if all(m in r.fits for r in self.measurements))

    def column(self, model: str, what: str = "diameter_error") -> np.ndarray:
        """(M,) per-measurement values [m]: ``diameter_error``, ``diameter`` or ``form_error``."""
        return np.array([getattr(r.fits[model], what) for r in self.measurements], float)

    def force_values(self, which: str) -> np.ndarray:
        """(M,) per-measurement force summary [N]: ``mean``, ``max10`` or ``max``."""
        return np.array([getattr(r.summary, which) for r in self.measurements], float)


def measurement_forces(points: PointSet, measurement: str, signals=None) -> PointForces:
    """Per-point forces of every row of one measurement: one peak a point (capture order) of its force
    signal if ``signals`` is given (a folder holding ``<measurement>.csv``, or a mapping {measurement:
    :class:`arm_model.io.ForceSignal`}), else the points file's force columns."""
    rows = np.flatnonzero(points.measurement == measurement)
    if signals is None:
        return forces_from_columns(points, rows)
    if isinstance(signals, Mapping):
        if measurement not in signals:
            raise InputError(f"no force signal for measurement '{measurement}' (signals given for: "
                             f"{', '.join(sorted(signals)) or 'none'})", points.path)
        return find_point_forces(signals[measurement], len(rows), measurement)
    path = Path(signals) / safe_name(measurement, ".csv")
    if not path.exists():
        raise InputError(f"no force signal for measurement '{measurement}' (expected one file a measurement, "
                         f"named <measurement>.csv; characters other than letters, digits and . _ + - "
                         f"become _; docs/formats.md §5)", path)
    return find_point_forces(read_force_signal(path), len(rows), measurement)


def analyse_ring_campaign(desc, points: PointSet, artefacts, feature: str | None = None, signals=None,
                          compliance: float | None = None, models=MODELS, arm=None) -> RingCampaign:
    """Analyse a ring-gauge campaign: per measurement, the per-point forces, the ring initially (rigid ball
    centres from the encoder angles) and after each correction model.

    Args:
        desc: the arm description (``arm_model.load_description``).
        points: the points (``arm_model.read_points``).
        artefacts: ``arm_model.read_artefacts``; the ring is its feature of kind "ring".
        feature: the ring's feature id; None takes the only ring feature.
        signals: folder of force signals, one ``<measurement>.csv`` a measurement, or a mapping {measurement:
            ForceSignal}, or None to use the points file's force columns.
        compliance: compliance of the paper's models [m/N]; None takes the probe's bending compliance.
        models: subset of :data:`MODELS`.
        arm: the arm model whose effects every ball centre gets (``arm_model.model_file.Arm``, e.g. a
            calibrated model file); None: the description alone.
    """
    from arm_model.model_file import Arm
    arm = Arm(desc) if arm is None else arm
    arm.check_points(points)
    rings = artefacts.of_kind("ring")
    if feature is None:
        if len(rings) != 1:
            raise InputError(f"{len(rings)} ring features in the artefacts file; name one with --feature "
                             f"(rings: {', '.join(f.id for f in rings) or 'none'})", artefacts.path)
        ring = rings[0]
    else:
        ring = artefacts.features.get(feature)
        if ring is None or ring.kind != "ring":
            raise InputError(f"no ring feature '{feature}' (rings: {', '.join(f.id for f in rings) or 'none'})",
                             artefacts.path)
    on_ring = points.feature == ring.id
    if not np.any(on_ring):
        raise InputError(f"no point of the points file touches the ring '{ring.id}'", points.path, None, "feature")
    if signals is not None and not isinstance(signals, Mapping):
        files: dict[str, str] = {}
        for mid in points.measurements():
            other = files.setdefault(safe_name(mid, ".csv"), mid)
            if other != mid:
                raise InputError(f"measurements '{other}' and '{mid}' would both read the signal file "
                                 f"{safe_name(mid, '.csv')}; rename one", points.path, None, "measurement")
    c = desc.probe.bending_compliance_x if compliance is None else float(compliance)
    notes = []
    kind = None
    out = []
    for mid in points.measurements():
        rows = np.flatnonzero(points.measurement == mid)
        sel = on_ring[rows]
        if not np.any(sel):
            continue
        forces_all = measurement_forces(points, mid, signals)
        kind = forces_all.kind
        forces = PointForces(forces_all.force[sel], forces_all.kind, forces_all.source,
                             None if forces_all.index is None else forces_all.index[sel],
                             None if forces_all.time is None else forces_all.time[sel],
                             None if forces_all.prominence is None else forces_all.prominence[sel],
                             forces_all.noise)
        idx = rows[sel]
        if len(idx) < 6:
            raise InputError(f"measurement '{mid}' has {len(idx)} points on the ring; a cylinder needs at "
                             "least 6", points.path, int(points.line_numbers[idx[0]]), "measurement")
        sub = points.select(idx)
        rigid = arm.ball_centres(sub, rigid=True)
        wrench = forces.force
        if points.torque is not None:
            wrench = np.column_stack([wrench, points.torque[idx]])
        wrench_centres = arm.ball_centres(sub, wrench=wrench) if "wrench" in models else None
        try:
            fits = correct_ring(rigid, desc.probe.ball_diameter, ring.diameter, c, forces, wrench_centres, models)
        except NumericalError as exc:       # the one measurement whose points give no ring, named
            line = int(points.line_numbers[idx[0]])
            raise NumericalError(f"{points.path}, line {line}, measurement '{mid}': {exc}") from None
        out.append(RingMeasurement(mid, forces, force_summary(forces.bending), fits, points.line_numbers[idx], idx))
    if kind == "two-channel":
        notes.append("two-channel force sensor (f_bend, f_axial): the bending force along probe y is not "
                     "measured and is taken as zero; the full-wrench model sees the probe-x bending only")
    return RingCampaign(ring.id, ring.diameter, desc.probe.ball_diameter, c, kind or "", out, notes,
                        ring.u_diameter, ring.form_error)


def ring_uncertainties(arm, points: PointSet, campaign: RingCampaign, parameters, inputs) -> list:
    """Per measurement: ``(diameter, form)``, the standard uncertainties of the diameter and of the form
    error of the cylinder fitted to the corrected ball centres
    (:class:`arm_model.feature_uncertainty.DiameterUncertainty`, :class:`~.FormUncertainty`), from the
    covariance of each centre (:func:`arm_model.uncertainty.propagate`: the model's parameter
    covariance ``parameters`` or None, the input uncertainties ``inputs``), the errors the points share
    propagated jointly."""
    from arm_model.feature_uncertainty import diameter_sensitivity, diameter_uncertainty, form_uncertainty
    from arm_model.uncertainty import propagate

    aux = arm.aux(points)
    out = []
    for r in campaign.measurements:
        wrench = r.forces.force
        if points.torque is not None:
            wrench = np.column_stack([wrench, points.torque[r.rows]])
        res = propagate(arm.model, arm.p, points.q[r.rows], wrench, None if aux is None else aux.select(r.rows),
                        parameters=parameters, inputs=inputs, systematic=True)
        fit = r.fits.get("wrench", r.fits["initial"])
        sens = diameter_sensitivity(fit.centres, fit.cylinder)
        out.append((diameter_uncertainty(sens, res.cov, res.systematic,
                                         0 if parameters is None else len(parameters.names)),
                    form_uncertainty(fit.centres, fit.cylinder, res.cov, res.systematic)))
    return out


def ring_warnings(desc, points: PointSet, campaign: RingCampaign) -> list:
    """The input warnings of a ring campaign (:mod:`arm_model.checks`): joint angles beyond their
    limits in the points file, and forces over the probe's range among the forces the analysis used
    (the force signals' peaks with ``--signals``, else the points file's columns)."""
    from arm_model.checks import joint_limit_warning, over_force_warning, radians_warning
    lines = points.lines if points.lines is not None else np.arange(1, len(points) + 1)
    out = [joint_limit_warning(desc, points.q, lines, points.path), radians_warning(desc, points.q, lines, points.path,
                                                                                     points.q_units)]
    if campaign.measurements:
        force = np.vstack([r.forces.force for r in campaign.measurements])
        where = np.concatenate([r.lines for r in campaign.measurements])
        out.append(over_force_warning(force, where, desc.probe.max_force, points.path))
    return [w for w in out if w is not None]


#: the fewest measurements a ring campaign can be analysed with (repeatability, correlations)
MIN_MEASUREMENTS = 3


def check_reportable(campaign: RingCampaign, points: PointSet) -> None:
    """Refuse a campaign the report (budgets, correlations) cannot say anything about: too few
    measurements, or forces that are the same in every measurement (all zero: nothing to correct,
    nothing to correlate)."""
    measurements = campaign.measurements
    if len(measurements) < MIN_MEASUREMENTS:
        raise InputError(f"{len(measurements)} measurement(s) of the ring; the analysis (repeatability in the "
                         f"budgets, correlation of the error with the force) needs at least {MIN_MEASUREMENTS}",
                         points.path, None, "measurement")
    for which in ("mean", "max10", "max"):
        v = np.array([getattr(r.summary, which) for r in measurements], float)
        if np.ptp(v) == 0:
            what = "zero" if np.all(v == 0) else f"{v[0]:.6g} N"
            raise InputError(f"the {which} force is {what} in every measurement: no force to correct with or to "
                             "correlate with (check the force columns or the force signals)",
                             measurements[0].forces.source, None, None)


def table2(campaign: RingCampaign) -> dict:
    """Columns of a Table 2-like table [mm, %]: per measurement, diameter error initially and after each
    model with its improvement ``(|initial| - |corrected|) / |initial|`` in % (an over-correction that
    flips the sign and grows the error is negative), and the form errors."""
    cols = {"measurement": np.array([r.id for r in campaign.measurements], dtype=object)}
    init = campaign.column("initial") * 1e3
    for m in campaign.models:
        cols[f"diameter_error_{m}_mm"] = campaign.column(m) * 1e3
        if m != "initial":
            with np.errstate(divide="ignore", invalid="ignore"):
                cols[f"improvement_{m}_pct"] = ((np.abs(init) - np.abs(cols[f"diameter_error_{m}_mm"]))
                                                 / np.abs(init) * 100.0)
    for m in campaign.models:
        cols[f"form_error_{m}_mm"] = campaign.column(m, "form_error") * 1e3
    for w in ("mean", "max10", "max"):
        cols[f"force_{w}_N"] = campaign.force_values(w)
    return cols


def campaign_summary(campaign: RingCampaign) -> dict:
    """Per model: mean |diameter error| [mm], its reduction against the initial one [%], mean form error
    [mm] and its change [%] (positive = larger form error)."""
    init_d = np.mean(np.abs(campaign.column("initial")))
    init_f = np.mean(campaign.column("initial", "form_error"))
    out = {}
    for m in campaign.models:
        d = np.mean(np.abs(campaign.column(m)))
        f = np.mean(campaign.column(m, "form_error"))
        out[m] = {"mean_abs_diameter_error_mm": d * 1e3,
                  "diameter_error_reduction_pct": (1 - d / init_d) * 100.0 if init_d > 0 else float("nan"),
                  "mean_form_error_mm": f * 1e3,
                  "form_error_change_pct": (f / init_f - 1) * 100.0 if init_f > 0 else float("nan"),
                  "max_form_error_increase_mm": float(np.max(campaign.column(m, "form_error")
                                                             - campaign.column("initial", "form_error"))) * 1e3}
    return out
