"""Run a campaign: plan -> operator -> inverse kinematics on the true arm -> readings -> files.

The steps draw from independent random streams spawned from the seed (truth, plan, operator,
inverse kinematics, noise, signals), so the same seed gives the same bytes, and changing e.g. the
noise does not move the points.
"""
from __future__ import annotations

import csv
import io
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..description import toml_text
from ..effects import Geometry
from ..errors import InputError, NumericalError
from ..io import (
    Artefacts,
    Distance,
    Feature,
    ForceSignal,
    PointSet,
    atomic_write_text,
    format_artefacts,
    guard_output,
    parse_artefacts,
    parse_points,
)
from ..log import counted, progress_line
from ..output import safe_name
from ..readback import UnreadableOutput
from .artefacts import Plan, make_plan
from .campaign import Campaign
from .ik import IKTargets, ball_jacobian, solve_ik
from .operator import OperatorDraw, draw_operator, force_signal, measurement_slices
from .truth import POSE_EFFECTS, Truth, build_truth, si_key

__all__ = ["SimResult", "simulate", "TRUTH_HEADER", "POINTS_FILE", "REFERENCE_FILE", "ARTEFACTS_FILE",
           "TRUTH_FILE", "TRUTH_POINTS_FILE", "SUMMARY_FILE", "SIGNALS_DIR"]

POINTS_FILE = "points.csv"
REFERENCE_FILE = "points-ref.csv"
ARTEFACTS_FILE = "artefacts.toml"
TRUTH_FILE = "truth.toml"
TRUTH_POINTS_FILE = "truth-points.csv"
SUMMARY_FILE = "summary.json"
SIGNALS_DIR = "signals"
TRUTH_HEADER = ("# TRUTH of a simulated campaign. No analysis reads this file: it holds the hidden true arm, "
                "its effects and the artefacts' placement, only to score results.")

_FMT = {"q": "%.12f", "force": "%.6f", "temperature": "%.6f", "time": "%.3f", "ref": "%.9f"}


@dataclass
class SimResult:
    """What :func:`simulate` made, in memory (SI).

    Attributes:
        campaign: the campaign simulated.
        points: the points file as :func:`arm_model.read_points` reads it (all rows but the tracker's; when
            every row is seen by the instrument, as in a campaign of postures only, all of them, with ``ref``).
        reference_points: the tracker rows (with ``ref``) when the campaign also has rows without, else None.
        artefacts: the artefacts file as :func:`arm_model.read_artefacts` reads it; None when the campaign
            touches no artefact (postures only).
        signals: measurement id -> :class:`arm_model.io.ForceSignal` (as read back from its CSV).
        truth: the hidden truth: ``p`` (name -> true value, SI), ``p_vector``, ``spec``, ``model``
            (the core ArmModel of the truth), ``effects`` (settings), ``noise``, ``placements``,
            ``T_ref_base`` (instrument frame -> (4, 4): a tracker task's id, a motion-capture task's id or
            ``<id>-s<k>`` for its session k), ``marker_offsets`` (motion-capture task id -> (K, 3) [m], tip
            frame), ``operator`` (per-measurement force levels).
        true_centres: (N, 3) [m] true deflected ball centres of ``points`` rows (base frame).
        true_q: (N, J) [rad] true joint angles of ``points`` rows.
        true_wrench: (N, 6) true wrench (probe frame) of ``points`` rows.
        ref_true_centres, ref_true_q: the same for ``reference_points`` rows (or None).
        stats: numbers for the summary (IK attempts, truth residuals ...).
    """
    campaign: Campaign
    points: PointSet
    reference_points: PointSet | None
    artefacts: Artefacts
    signals: dict
    truth: dict
    true_centres: np.ndarray
    true_q: np.ndarray
    true_wrench: np.ndarray
    ref_true_centres: np.ndarray | None
    ref_true_q: np.ndarray | None
    stats: dict
    texts: dict = field(default_factory=dict, repr=False)

    def write(self, out_dir: str | Path, inputs=()) -> list[Path]:
        """Write every file into ``out_dir`` (atomically, never over the campaign's inputs or
        ``inputs``); returns the paths written."""
        out_dir = Path(out_dir)
        protect = list(self.campaign.inputs) + list(inputs)
        texts = dict(self.texts, **{SUMMARY_FILE: self.summary_json(protect)})
        for name in texts:
            guard_output(out_dir / name, protect)
        written = []
        for name, text in texts.items():
            written.append(atomic_write_text(out_dir / name, text, protect))
        return written

    def summary_json(self, inputs=()) -> str:
        """``summary.json``: the campaign, seed, arm, counts and files written (no truth: that is in
        ``truth.toml``), with the toolkit version and each input's SHA-256 (:func:`provenance`,
        ``inputs`` and the campaign's)."""
        from ..shipped import provenance
        c = self.campaign

        def count(ps):
            return {"points": len(ps), "measurements": len(ps.measurements())} if ps is not None else None
        summary = {"campaign": c.name, "seed": c.seed, "arm": c.arm.name, "sensor": c.sensor,
                   "points": count(self.points), "reference_points": count(self.reference_points),
                   "effects_on": list(self.truth["effects_on"]), "files": sorted(self.texts),
                   **provenance(list(dict.fromkeys(list(c.inputs) + list(inputs))))}
        return json.dumps(summary, indent=1, allow_nan=False) + "\n"


# ---------------------------------------------------------------------------------------------
# text writers (deterministic formats)

def _csv_text(columns: dict) -> str:
    """CSV text from {name: (values, fmt or None for text)}."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    names = list(columns)
    w.writerow(names)
    cells = []
    for name in names:
        values, fmt = columns[name]
        cells.append([str(v) for v in values] if fmt is None else [fmt % v for v in values])
    w.writerows(zip(*cells, strict=True))
    return buf.getvalue()


def _artefacts_text(plan: Plan, campaign: Campaign) -> str:
    features = [Feature(f["id"], f["kind"], *(f.get(k) for k in ("diameter", "u_diameter", "form_error")))
                for f in plan.features]
    distances = [Distance(tuple(between), length, u) for between, length, u, _ in plan.distances]
    return format_artefacts(features, distances,
                            f"Artefacts of the simulated campaign '{campaign.name}' (docs/formats.md §4).")


def _plain(v):
    """numpy scalars/arrays -> Python values, recursively (for tomli_w)."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items() if x is not None}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_plain(x) for x in (v.tolist() if isinstance(v, np.ndarray) else v)]
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    return v


_SETTING_UNITS = {"amplitude": "rad", "phase": "rad", "amplitude2": "rad", "phase2": "rad",
                  "stiffness": "Nm_per_rad", "alpha": "per_K", "bending_x": "m_per_N", "bending_y": "m_per_N",
                  "axial": "m_per_N", "offset": "N", "probe_alpha": "per_K", "stiffness_x": "Nm_per_rad",
                  "stiffness_y": "Nm_per_rad", "coupling_xy": "m_per_N", "coupling_xz": "m_per_N",
                  "coupling_yz": "m_per_N", **{f"d{a}_u{b}": "m" for a in "xyz" for b in "xyz"}}


def _with_units(d):
    if isinstance(d, list):
        return [_with_units(x) for x in d]
    if not isinstance(d, dict):
        return d
    return {(f"{k}_{_SETTING_UNITS[k]}" if k in _SETTING_UNITS else k): _with_units(v) for k, v in d.items()}


def _truth_text(campaign: Campaign, truth: Truth, plan: Plan, draw: OperatorDraw, stats: dict) -> str:
    spec = truth.model.spec
    noise_units = {"encoder_resolution": "rad", "encoder_noise": "rad", "probing_repeatability": "m",
                   "force_noise": "N", "temperature_noise": "C"}
    doc = {
        "campaign": campaign.name, "seed": campaign.seed, "arm": campaign.arm.name, "sensor": campaign.sensor,
        "effects_on": truth.effects_on(),
        "parameters": {si_key(n, u): float(v) for n, u, v in zip(spec.names, spec.units, truth.p, strict=True)},
        "effects": _with_units(truth.settings),
        "noise": {f"{k}_{noise_units[k]}": v for k, v in campaign.noise.items()},
        "operator": {"measurements": list(draw.level), "level_N": [draw.level[m] for m in draw.level]},
        "artefact": plan.placements,
        "stats": stats,
    }
    comment = (TRUTH_HEADER.removeprefix("# ") + f"\nCampaign '{campaign.name}', seed {campaign.seed}. SI units, named "
               "in every key; [parameters] is the true parameter vector of the core ArmModel(nominal arm, effects on), "
               "errors added to the nominal description.")
    return toml_text(_plain(doc), comment)


# ---------------------------------------------------------------------------------------------

def _rng_streams(seed: int) -> dict[str, np.random.Generator]:
    names = ("truth", "plan", "operator", "ik", "noise", "signals", "tracker")
    seqs = np.random.SeedSequence(seed).spawn(len(names))
    return {n: np.random.default_rng(s) for n, s in zip(names, seqs, strict=True)}


def _x_directions(plan: Plan, force: np.ndarray, rng) -> np.ndarray:
    """Required probe x axis: along the force's part across the stylus (rotated by the operator's
    roll error), NaN where the roll is free."""
    x = np.full_like(force, np.nan)
    for i in np.flatnonzero(plan.roll_along_force):
        u = plan.stylus[i]
        f = force[i] - (force[i] @ u) * u
        f /= np.linalg.norm(f)
        a = rng.uniform(-1, 1) * plan.roll_jitter[i]
        x[i] = np.cos(a) * f + np.sin(a) * np.cross(u, f)
    return x


def _check_model(truth):
    """The core model of the truth without its force-sensor effect and its parameters: what the true
    geometry gives at the exact readings and the true wrench."""
    from ..model import ArmModel
    no_sensor = [e for e in truth.model.effects if e.key != "force_sensor"]
    keep = np.concatenate([np.arange(truth.model.base_size)] +
                          [np.arange(sl.start, sl.stop) for e, sl in truth.model.effect_slices()
                           if e.key != "force_sensor"]).astype(int)
    return ArmModel(truth.model.desc, tuple(no_sensor)), truth.p[keep]


def _truth_check(truth, plan, q_enc, wrench, aux, labels):
    """The truth check: the core model evaluated on exact readings lands on the target surface (a
    posture: on the true tip); (the true ball centres (n, 3) [m], their distance from the targets (n,) [m])
    or a NumericalError."""
    check_model, p = _check_model(truth)
    centres = check_model.ball_centres(q_enc, wrench, p, aux)
    residual = np.linalg.norm(centres - plan.position, axis=1)
    if residual.max() > 1e-9:
        i = int(np.argmax(residual))
        raise NumericalError(f"truth check failed: the true ball centre of {labels[i]} is "
                             f"{residual[i] * 1e9:.3g} nm off its target")
    return centres, residual


def _at_point(geom, desc, offset) -> Geometry:
    """``geom`` with its probe point moved by ``offset`` (3,) [m], given in the tip (probe) frame."""
    rm = np.eye(3) if desc.probe.rotation is None else np.asarray(desc.probe.rotation, float)
    shift = rm @ np.asarray(offset, float)
    return Geometry([list(r) for r in geom.rows], [geom.p_last[a] + shift[a] for a in range(3)], list(geom.compliance))


def _true_markers(truth, plan, campaign, q_true, q_enc, aux) -> np.ndarray | None:
    """(N, K, 3) [m] the true markers of the posture rows in the base frame (NaN elsewhere): the true tip
    frame at the true joint values moved by each marker's offset; checked against the core model at the
    exact readings (``arm_model.tracker.marker_positions``) to 1 nm. None without a motion-capture task."""
    if not plan.markers:
        return None
    from ..tracker import Tracker, marker_positions
    tid, offsets = next(iter(plan.markers.items()))
    rows = np.flatnonzero(plan.posture)
    n = len(rows)
    geom = truth.geometry(aux.temperature[rows])
    ball, z, x = truth.pose(q_true[rows], geom, np.zeros((n, 6)))
    rot = np.stack([x, np.cross(z, x), z], axis=2)
    out = np.full((len(plan), len(offsets), 3), np.nan)
    out[rows] = ball[:, None, :] + np.einsum("nij,kj->nki", rot, offsets)
    if any(isinstance(e, POSE_EFFECTS) for e in truth.model.effects):
        # a pose-dependent effect (a lateral compliance) turns the links past its joint: every marker moves with
        # them, by the effect evaluated at the marker itself (the tip frame's origin moved plus the unturned offset
        # misses the turn of the offset: 0.27 mm on a Panda whose shoulder tilts under gravity)
        out[rows] = np.stack([truth.pose(q_true[rows], _at_point(geom, truth.nominal, o), np.zeros((n, 6)))[0]
                              for o in offsets], axis=1)
    model, p = _check_model(truth)
    core = marker_positions(model, p, q_enc[rows], Tracker(("",), np.eye(4), offsets), [""] * n, aux.select(rows))
    worst = float(np.max(np.linalg.norm(core - out[rows], axis=2), initial=0.0))
    if worst > 1e-9:
        raise NumericalError(f"truth check failed: a marker of task '{tid}' is {worst * 1e9:.3g} nm off where the "
                             "core model puts it")
    return out


def _readings(nz: dict, nrng, truth, q_true, q_enc, draw, wrench):
    """The noisy readings (encoders, temperature, force sensor) of the exact ones."""
    n = len(q_enc)
    q_read = q_enc.copy()
    if nz["probing_repeatability"] > 0:
        jac = ball_jacobian(truth, q_true, draw.temperature, wrench)
        dx = nrng.normal(0.0, nz["probing_repeatability"], (n, 3))
        q_read += np.einsum("nij,nj->ni", np.linalg.pinv(jac), dx)
    if nz["encoder_noise"] > 0:
        q_read += nrng.normal(0.0, nz["encoder_noise"], q_read.shape)
    if nz["encoder_resolution"] > 0:
        q_read = np.round(q_read / nz["encoder_resolution"]) * nz["encoder_resolution"]
    temp_read = draw.temperature + (nrng.normal(0.0, nz["temperature_noise"], n)
                                    if nz["temperature_noise"] > 0 else 0.0)
    f_read = truth.sensor_reading(wrench[:, :3])
    if nz["force_noise"] > 0:
        f_read = f_read + nrng.normal(0.0, nz["force_noise"], f_read.shape)
    return q_read, temp_read, f_read


def _signals(campaign, plan, draw, truth, f_read, srng, texts: dict) -> dict:
    """The force signal of every measurement (its text added to ``texts``), read back as the reader does."""
    sensor, nz = campaign.sensor, campaign.noise
    chans = (0, 2) if sensor == "two-channel" else (0, 1, 2)
    names = ("f_bend_N", "f_axial_N") if sensor == "two-channel" else ("fx_N", "fy_N", "fz_N")
    signals = {}
    for mid, idx in measurement_slices(plan.measurement).items():
        if plan.posture[idx].all():          # a posture touches nothing: no pulse to record
            continue
        peaks = np.array([[float(_FMT["force"] % v) for v in f_read[i, list(chans)]] for i in idx])
        t, f = force_signal(draw.time[idx], peaks, truth.force_offset[list(chans)], draw.windows[mid],
                            campaign.signals, nz["force_noise"], srng)
        cols = {"time_s": (t, _FMT["time"])}
        for c, name in enumerate(names):
            cols[name] = (f[:, c], _FMT["force"])
        text = _fast_csv(cols)
        rel = f"{SIGNALS_DIR}/{safe_name(mid, '.csv')}"
        if rel in texts:
            raise InputError(f"two measurement ids give the same signal file name {rel}; rename the task "
                             "ids (letters, digits and . _ + - keep a name as it is)", campaign.source)
        texts[rel] = text
        arr = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2)
        force = arr[:, 1:]
        if sensor == "two-channel":
            force = np.column_stack([force[:, 0], np.zeros(len(force)), force[:, 1]])
        signals[mid] = ForceSignal(rel, arr[:, 0], force, "two-channel" if sensor == "two-channel" else "xyz")
    return signals


def _stats(campaign, plan, attempts, residual, f_true) -> dict:
    """The campaign's counts and checks, for the truth file (``attempts``: the inverse kinematics' random
    starts of each contact row; none for a campaign of postures only)."""
    per_task = {t.id: len(set(plan.measurement[plan.task == k])) for k, t in enumerate(campaign.tasks)}
    ik = {} if not len(attempts) else {"ik_attempts_mean": float(attempts.mean()),
                                       "ik_attempts_max": int(attempts.max())}
    return {"points": int(len(plan)), "measurements": len(set(plan.measurement)), "measurements_per_task": per_task,
            **ik, "truth_residual_max_m": float(residual.max()),
            "force_mean_N": float(np.linalg.norm(f_true, axis=1).mean()),
            "force_max_N": float(np.linalg.norm(f_true, axis=1).max())}


def _truth_columns(desc, plan, q_true, q_enc, centres, f_true, draw) -> dict:
    """The columns of the truth points file: true and encoder joint values (each in its unit), true ball
    centres, forces and temperature."""
    files = np.where(plan.reference & ~plan.reference.all(), REFERENCE_FILE, POINTS_FILE)
    cols = {"measurement": (plan.measurement, None), "feature": (plan.feature, None), "file": (files, None)}
    for k, (unit, factor) in enumerate(desc.joint_column_units):
        cols[f"q{k + 1}_true_{unit}"] = (q_true[:, k] * factor, "%.12f")
    for k, (unit, factor) in enumerate(desc.joint_column_units):
        cols[f"q{k + 1}_enc_{unit}"] = (q_enc[:, k] * factor, "%.12f")
    for k, a in enumerate("xyz"):
        cols[f"{a}_true_mm"] = (centres[:, k] * 1e3, "%.9f")
    for k, a in enumerate("xyz"):
        cols[f"f{a}_true_N"] = (f_true[:, k], "%.9f")
    cols["temperature_true_C"] = (draw.temperature, "%.6f")
    return cols


def _drift_artefacts(plan, velocity, time) -> None:
    """Every artefact creeping at ``velocity`` (3,) [m/s] (base frame; ``[environment] artefact_drift``): the ball
    centre of each contact row taken at ``time`` [s] sits ``velocity * time`` from its artefact's given place (the
    place at time 0). A posture's target is the true tip and moves with nothing."""
    v = np.asarray(velocity, dtype=float)
    if np.any(v):
        rows = ~np.asarray(plan.posture, dtype=bool)
        plan.position[rows] = plan.position[rows] + np.outer(np.asarray(time, dtype=float)[rows], v)


def _solve(truth, plan, draw, x_dir, labels, rng, say):
    """True joint angles (N, J) [rad], wrenches (N, 6) and the inverse kinematics' random starts of the
    contact rows: the inverse kinematics on the true arm for the rows that touch something, a posture's own
    joint values (no contact)."""
    n = len(plan)
    q_true, wrench = plan.q_start.copy(), np.zeros((n, 6))
    rows = np.flatnonzero(~plan.posture)
    if not rows.size:
        return q_true, wrench, np.zeros(0, int)
    targets = IKTargets(plan.position, plan.stylus, x_dir, draw.force, draw.torque, draw.temperature,
                        plan.stylus_axis, plan.stylus_cone).take(rows)
    say("inverse kinematics on the true arm ...")
    ik = solve_ik(truth, targets, rng, labels=[labels[i] for i in rows], starts=plan.q_start[rows])
    q_true[rows], wrench[rows] = ik.q, ik.wrench
    return q_true, wrench, ik.attempts


def _reference(plan, campaign, rows, centres, markers, trng) -> np.ndarray:
    """(rows, K, 3) [m] what the instrument reports for ``rows``: a nest's ball centre or a posture's K
    markers, in the row's instrument frame, plus its noise (drawn frame by frame, in the plan's order)."""
    k = 1 if markers is None else markers.shape[1]
    seen = np.broadcast_to(centres[rows, None, :], (rows.size, k, 3)).copy()
    if markers is not None:
        posture = plan.posture[rows]
        seen[posture] = markers[rows[posture]]
    ref = np.empty_like(seen)
    for frame, T in plan.T_ref_base.items():
        sel = plan.frame[rows] == frame
        p = seen[sel] @ T[:3, :3].T + T[:3, 3]
        ref[sel] = p + trng.normal(0.0, plan.ref_noise[frame], (int(sel.sum()), 3) if k == 1 else p.shape
                                   ).reshape(p.shape)
    return ref


def _temperature_told(campaign) -> bool:
    """Whether a temperature column tells anything: a varying environment, its noise or a thermal truth."""
    env = campaign.environment
    return bool(env["drift"] or env["cycle_amplitude"] or campaign.noise["temperature_noise"]
                or campaign.truth["thermal"] is not None)


def _points_columns(campaign, plan, rows, readings, draw, ref) -> dict:
    """The points file's columns of ``rows``: ids (and each row's session where the reference rows have
    several instrument frames), encoder readings, force and temperature readings, capture time, and the
    reference columns ``ref`` (rows, K, 3) [m] (None: a file without them)."""
    desc, sensor = campaign.arm, campaign.sensor
    q_read, temp_read, f_read = readings
    cols = {"measurement": (plan.measurement[rows], None), "feature": (plan.feature[rows], None)}
    if ref is not None and len(set(plan.frame[plan.reference])) > 1:
        cols["session"] = (plan.frame[rows], None)
    for k, (unit, factor) in enumerate(desc.joint_column_units):
        cols[f"q{k + 1}_{unit}"] = (q_read[rows, k] * factor, _FMT["q"])
    if sensor == "xyz":
        for k, a in enumerate("xyz"):
            cols[f"f{a}_N"] = (f_read[rows, k], _FMT["force"])
    elif sensor == "two-channel":
        cols["f_bend_N"] = (f_read[rows, 0], _FMT["force"])
        cols["f_axial_N"] = (f_read[rows, 2], _FMT["force"])
    if not plan.posture[rows].all() or _temperature_told(campaign):
        cols["temperature_C"] = (temp_read[rows], _FMT["temperature"])
    cols["time_s"] = (draw.time[rows], _FMT["time"])
    if ref is not None:
        names = [""] if ref.shape[1] == 1 else [str(m + 1) for m in range(ref.shape[1])]
        for m, tag in enumerate(names):
            for k, a in enumerate("xyz"):
                cols[f"{a}{tag}_ref_mm"] = (ref[:, m, k] * 1e3, _FMT["ref"])
    return cols


def _own_points(text: str, name: str, joints):
    """The points file the simulator wrote, read as every command reads it; a refusal is the simulator's bug
    (:class:`~arm_model.readback.UnreadableOutput`, exit 3; docs/guarantees.md, section 1b), never bad input naming
    a file the user did not give."""
    try:
        return parse_points(text, name, joints)
    except InputError as exc:
        raise UnreadableOutput(f"the simulated points file is refused by its reader: {exc}", name) from None


def simulate(campaign: Campaign, seed: int | None = None, progress=None) -> SimResult:
    """Simulate ``campaign`` (seed: the campaign's unless given). ``progress``: optional callable
    taking a message, called at each stage (default: a progress record of this module's logger). Raises
    :class:`~arm_model.NumericalError` if a point
    cannot be reached or the truth check fails."""
    if not isinstance(campaign, Campaign):
        raise TypeError(f"simulate: campaign must be a Campaign (arm_model.sim.load_campaign reads a file), got "
                        f"{type(campaign).__name__}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise ValueError(f"simulate: seed must be a whole number >= 0 (as --seed), got {seed!r}")
    say = progress or progress_line(logging.getLogger(__name__))
    seed = campaign.seed if seed is None else int(seed)
    if seed != campaign.seed:
        from dataclasses import replace
        campaign = replace(campaign, seed=seed)
    rng = _rng_streams(seed)
    desc = campaign.arm
    truth = build_truth(desc, campaign.truth, rng["truth"], campaign.sensor)
    plan = make_plan(campaign, rng["plan"], truth)
    say(f"{counted(len(plan), 'point')} in {counted(len(set(plan.measurement)), 'measurement')} planned")
    draw = draw_operator(plan, campaign.operator, campaign.environment, campaign.signals, rng["operator"])
    x_dir = _x_directions(plan, draw.force, rng["operator"])
    _drift_artefacts(plan, campaign.environment["artefact_drift"], draw.time)
    labels = [f"{m} row {i + 1} (feature {f})"
              for i, (m, f) in enumerate(zip(plan.measurement, plan.feature, strict=True))]
    q_true, wrench, attempts = _solve(truth, plan, draw, x_dir, labels, rng["ik"], say)
    # physical torques and the readings the encoders give
    if truth.needs_torques():
        say("gravity and contact torques (Pinocchio, true arm) ...")
        tau_g, tau_c = truth.torques(q_true, wrench)
    else:
        tau_g = tau_c = np.zeros_like(q_true)
    aux = truth.aux(draw.temperature, tau_g, tau_c)
    q_enc = truth.encoder_readings(q_true, aux)
    posture = np.flatnonzero(plan.posture)
    if posture.size:          # a posture's target is the true tip
        plan.position[posture] = truth.pose(q_true[posture], truth.geometry(draw.temperature[posture]),
                                            np.zeros((posture.size, 6)))[0]
    centres, residual = _truth_check(truth, plan, q_enc, wrench, aux, labels)
    markers = _true_markers(truth, plan, campaign, q_true, q_enc, aux)
    readings = _readings(campaign.noise, rng["noise"], truth, q_true, q_enc, draw, wrench)
    # files
    say("writing files in memory ...")
    texts = {}
    ref_rows = np.flatnonzero(plan.reference)
    main_rows = np.flatnonzero(~plan.reference)  # type: ignore[operator]
    points = ref_points = None
    if main_rows.size:
        texts[POINTS_FILE] = _csv_text(_points_columns(campaign, plan, main_rows, readings, draw, None))
        points = _own_points(texts[POINTS_FILE], POINTS_FILE, desc.joint_quantities)
    if ref_rows.size:           # beside the points file, or the points file itself when every row has them
        name = REFERENCE_FILE if main_rows.size else POINTS_FILE
        ref = _reference(plan, campaign, ref_rows, centres, markers, rng["tracker"])
        texts[name] = _csv_text(_points_columns(campaign, plan, ref_rows, readings, draw, ref))
        ref_points = _own_points(texts[name], name, desc.joint_quantities)
        if not main_rows.size:
            points, ref_points, main_rows = ref_points, None, ref_rows
    artefacts = None
    if plan.features or plan.distances:
        texts[ARTEFACTS_FILE] = _artefacts_text(plan, campaign)
        artefacts = parse_artefacts(texts[ARTEFACTS_FILE], ARTEFACTS_FILE)
    # force signals, one a measurement that touches something
    signals = {}
    if campaign.sensor != "none" and campaign.signals["enabled"]:
        say("force signals ...")
        signals = _signals(campaign, plan, draw, truth, readings[2], rng["signals"], texts)
    f_true = wrench[:, :3]
    stats = _stats(campaign, plan, attempts, residual, f_true)
    texts[TRUTH_FILE] = _truth_text(campaign, truth, plan, draw, stats)
    texts[TRUTH_POINTS_FILE] = "# TRUTH: true values per captured point; no analysis reads this file.\n" + \
        _csv_text(_truth_columns(desc, plan, q_true, q_enc, centres, f_true, draw))
    truth_dict = {"p": truth.values, "aliases": truth.aliases, "p_vector": truth.p.copy(), "spec": truth.model.spec,
                  "model": truth.model,
                  "effects": truth.settings, "effects_on": truth.effects_on(), "noise": dict(campaign.noise),
                  "placements": plan.placements, "T_ref_base": dict(plan.T_ref_base),
                  "marker_offsets": {k: v.copy() for k, v in plan.markers.items()},
                  "operator": dict(draw.level), "cross_talk": truth.cross_talk.copy(),
                  "description": truth.description, "truth": truth,
                  "tau_gravity": tau_g, "tau_contact": tau_c, "q_enc": q_enc, "temperature": draw.temperature,
                  "force_base": draw.force}
    has_ref = ref_points is not None
    return SimResult(campaign, points, ref_points, artefacts, signals, truth_dict,
                     centres[main_rows], q_true[main_rows], wrench[main_rows],
                     centres[ref_rows] if has_ref else None, q_true[ref_rows] if has_ref else None,
                     stats, texts)


def _fast_csv(columns: dict) -> str:
    """Numeric CSV text (every column with its % format), deterministic; one formatting pass."""
    names = list(columns)
    arr = np.column_stack([columns[k][0] for k in names])
    row = ",".join(columns[k][1] for k in names) + "\n"
    return ",".join(names) + "\n" + (row * len(arr)) % tuple(arr.ravel().tolist())
