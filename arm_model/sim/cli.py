"""``aacmm simulate``: run a campaign file and write its data, signals and (separately) its truth."""
from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from ..cli import command_help
from ..cli_options import add_output_option, path_arg, seed
from ..log import PROGRESS, counted
from ..output import output_folder
from .campaign import load_campaign
from .run import ARTEFACTS_FILE, POINTS_FILE, REFERENCE_FILE, SIGNALS_DIR, TRUTH_FILE, TRUTH_POINTS_FILE, simulate

__all__ = ["register", "run", "summary"]

log = logging.getLogger(__name__)


def register(sub) -> None:
    p = sub.add_parser(
        "simulate", help=command_help("simulate"),
        description="Simulate a campaign (examples/campaigns/*.toml): a true arm (nominal + parameter errors + "
                    "the effects the campaign switches on), an operator (contact forces like the seed paper's), "
                    "artefacts (ring gauge, spheres, ball bar, seats, plane, tracker nests) or postures seen by motion "
                    f"capture. Writes {POINTS_FILE} (and {REFERENCE_FILE} for tracker rows), {ARTEFACTS_FILE}, "
                    f"{SIGNALS_DIR}/<measurement>.csv (1 kHz force), and the hidden truth {TRUTH_FILE} and "
                    f"{TRUTH_POINTS_FILE}, which no analysis reads. The same seed gives identical bytes.",
        epilog="Campaign file: docs/formats.md §6; every key and its unit: docs/simulator.md. Output files: "
               "docs/formats.md §7.")
    p.add_argument("campaign", type=path_arg, help="campaign TOML file")
    add_output_option(p)
    p.add_argument("--seed", type=seed, default=None,
                   help="seed of every random draw of the simulation (default: the campaign's 'seed')")
    p.add_argument("--no-signals", action="store_true", help="do not write the force-signal files")
    p.add_argument("--samples", action="store_true",
                   help="also write the campaign as a live sample stream, samples.csv (1 kHz: time, joint angles, "
                        "force, trigger; for aacmm live), and its session plan, plan.toml, when every feature is "
                        "probed in one run (docs/simulator.md)")
    p.set_defaults(func=run)


def summary(result, elapsed: float | None = None) -> str:
    """A one-screen summary of a :class:`~arm_model.sim.SimResult`."""
    c = result.campaign
    lines = [f"campaign '{c.name}' (seed {c.seed}), arm '{c.arm.name}', sensor {c.sensor}"]
    sets = [("points", result.points)] + ([("tracker", result.reference_points)] if result.reference_points else [])
    for label, ps in sets:
        if ps is None:
            continue
        meas = ps.measurements()
        lines.append(f"{label}: {counted(len(ps), 'point')} in {counted(len(meas), 'measurement')} "
                     f"({', '.join(meas[:3])}{' ...' if len(meas) > 3 else ''})")
    per_task = result.stats.get("measurements_per_task", {})
    for t in c.tasks:
        seen = ""
        if t.kind == "mocap":
            o = t.opts
            seen = (f": {counted(o['markers'], 'marker')} {o['marker_distance'] * 1e3:g} mm from the tip frame, "
                    f"{counted(o['sessions'], 'session')}, instrument noise {o['noise'] * 1e6:g} um")
        lines.append(f"  task {t.kind:8s} id {t.id:10s} {per_task.get(t.id, t.measurements)} measurement(s){seen}")
    if result.points is not None and len(result.points) and np.any(result.true_wrench):
        f = np.linalg.norm(result.true_wrench[:, :3], axis=1)
        per = {}
        for m, v in zip(result.points.measurement, f, strict=True):
            per.setdefault(m, []).append(v)
        means = np.array([np.mean(v) for v in per.values()])
        maxes = np.array([np.max(v) for v in per.values()])
        lines.append(f"contact force [N]: mean {f.mean():.2f}, max {f.max():.2f}; per measurement: mean "
                     f"{means.min():.2f}-{means.max():.2f}, max {maxes.min():.2f}-{maxes.max():.2f}")
    on = result.truth["effects_on"]
    lines.append(f"effects on: {', '.join(on) if on else 'none (parameter errors only)'}")
    shown = {"encoder_resolution": (180 / np.pi, "deg"), "encoder_noise": (180 / np.pi, "deg"),
             "probing_repeatability": (1e6, "um"), "force_noise": (1.0, "N"), "temperature_noise": (1.0, "C")}
    nz = [f"{k} {v * shown[k][0]:.3g} {shown[k][1]}" for k, v in result.truth["noise"].items() if v]
    instrument = any(t.kind == "mocap" for t in c.tasks)      # its noise is said on its task's line
    lines.append("noise of the arm (1 sigma): " + (", ".join(nz) if nz else "none")
                 + ("; the instrument's: see its task" if instrument else ""))
    s = result.stats
    ik = (f"inverse kinematics: {s['ik_attempts_mean']:.2f} random starts a point on average "
          f"(max {s['ik_attempts_max']}); " if "ik_attempts_mean" in s else "postures only: no inverse kinematics; ")
    lines.append(ik + f"truth check: ball centres on their surfaces within {s['truth_residual_max_m'] * 1e9:.2g} nm"
                 + (" (postures: the core model at the readings on the true tip and markers)"
                    if result.truth.get("marker_offsets") else ""))
    if elapsed is not None:
        lines.append(f"time: {elapsed:.1f} s")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    campaign = load_campaign(args.campaign)
    with output_folder(args.output, campaign.inputs, "simulate") as out:
        result, written = _simulate(args, campaign, out)
    log.info(summary(result, time.perf_counter() - t0))
    written = [out.published(p) for p in written]
    n_sig = sum(1 for p in written if p.parent.name == SIGNALS_DIR)
    log.info(f"wrote {args.output}/: " + ", ".join(p.name for p in written if p.parent.name != SIGNALS_DIR)
          + (f", {n_sig} signal file(s) in {SIGNALS_DIR}/" if n_sig else ""))
    return 0


def _simulate(args, campaign, out):
    if args.no_signals:
        from dataclasses import replace
        campaign = replace(campaign, signals=dict(campaign.signals, enabled=False))

    result = simulate(campaign, seed=args.seed)
    if getattr(args, "samples", False):
        if args.no_signals:
            from ..errors import InputError
            raise InputError("--samples needs the force signals: leave out --no-signals")
        _add_stream(result)
    written = result.write(out.dir, campaign.inputs)
    log.info(f"{counted(len(written), 'file')} written to {args.output}", extra=PROGRESS)
    return result, written


def _add_stream(result) -> None:
    """The sample stream and its plan, among the files the result writes."""
    from ..errors import InputError
    from ..live.plan import format_plan
    from .stream import PLAN_FILE, SAMPLES_FILE, sample_stream, stream_plan
    if any(t.kind == "mocap" for t in result.campaign.tasks):
        raise InputError("--samples writes what a measuring arm streams while it touches artefacts; a "
                         "motion-capture task's postures touch nothing: leave out --samples",
                         result.campaign.source)
    try:
        result.texts[SAMPLES_FILE] = sample_stream(result, result.campaign.seed or 0)
    except ValueError as exc:
        raise InputError(f"--samples: {exc}", result.campaign.source) from None
    plan = stream_plan(result)
    if plan is not None:
        result.texts[PLAN_FILE] = format_plan(plan)
    else:
        log.warning("--samples: a feature is probed in two separate runs, so no plan.toml is written "
                    "(a plan takes each feature once)")
