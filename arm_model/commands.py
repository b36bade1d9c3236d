"""``aacmm tip`` and ``aacmm urdf``."""
from __future__ import annotations

import argparse
import logging
import os
import shutil
from pathlib import Path

import numpy as np

from .checks import JointLimitTally, log_warnings
from .cli import command_help
from .cli_options import (
    add_arm_options,
    add_frame_options,
    add_output_option,
    arm_inputs,
    model_from_args,
    output_path,
    path_arg,
)
from .csv_io import format_csv
from .errors import InputError
from .io import concat_points, iter_points
from .model_file import Arm
from .output import output_file
from .urdf import kept_link_names, urdf_text

__all__ = ["register", "tip_table", "tip_centres"]

log = logging.getLogger(__name__)


def register(sub) -> None:
    p = sub.add_parser(
        "tip", help=command_help("tip"),
        description="Read a points CSV (encoder angles and, if present, the contact force) and write, per point, "
                    "the rigid ball centre, the deflection-corrected ball centre [mm] and the deflection [um]. "
                    "Points whose force exceeds the probe's calibrated range are flagged (over_force = 1), "
                    "never dropped.")
    p.add_argument("points", type=path_arg, help="points CSV (docs/formats.md §3)")
    add_arm_options(p)
    add_output_option(p, "file", "output CSV")
    p.add_argument("--reference-frame", action="store_true",
                   help="also write where the reference instrument (tracker, motion capture) would see each marker: "
                        "x_ref_mm, y_ref_mm, z_ref_mm (x1_ref_mm ... for several markers), in the instrument's frame "
                        "of the row's session, with the frames and marker offsets of a model file written by "
                        "aacmm calibrate on reference points; where the points carry the instrument's own "
                        "coordinates, also their distance error_ref_um (error1_ref_um ...), measured - predicted")
    from .uncertainty_cli import add_tip_options
    add_tip_options(p)
    p.set_defaults(func=run_tip)

    u = sub.add_parser(
        "urdf", help=command_help("urdf"),
        description="Write the URDF (links, joints, the probe's virtual elastic joints, visuals) generated "
                    "from an arm description. The repository's urdf/aacmm7.urdf is made this way.")
    u.add_argument("arm", type=path_arg, help="arm description TOML or a shipped arm's name (aacmm7), or a URDF with "
                                          "--tip-frame, to see the chain the toolkit reads from it "
                                          "(docs/formats.md §2)")
    add_frame_options(u)
    add_output_option(u, "file", "output URDF")
    u.set_defaults(func=run_urdf)

    e = sub.add_parser(
        "examples", help=command_help("examples"),
        description="Copy the shipped example campaigns (campaigns/*.toml, for aacmm simulate), the example "
                    "data (data/: a simulated ring campaign, real measured robot data with its licence), the "
                    "shipped arm descriptions (arms/: the nominal aacmm7 as a DH table, a template for yours) and "
                    "the user docs (docs/, e.g. docs/formats.md) with the README they link to (README.md) into DIR. "
                    "Existing files are never overwritten.")
    e.add_argument("dir", type=output_path, help="destination folder (created)")
    e.set_defaults(func=run_examples)


def tip_centres(arm, points, motion: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rigid, corrected) ball centres (N, 3) [m] of ``aacmm tip`` for a :class:`~arm_model.io.PointSet`;
    ``arm`` an :class:`~arm_model.model_file.Arm` (every effect applied) or a description. Rigid: at a
    zero force reading; corrected: with the points' wrench (= rigid without force columns). ``motion``: each
    joint's last move (N, J) [1] (None: from the points, :func:`arm_model.model.points_motion`)."""
    if not isinstance(arm, Arm):
        arm = Arm(arm)
    rigid = arm.ball_centres(points, rigid=True, motion=motion)
    corrected = arm.ball_centres(points, motion=motion) if points.wrench is not None else rigid.copy()
    return rigid, corrected


def tip_table(arm, points, centres: tuple[np.ndarray, np.ndarray] | None = None,
              reference_frame: bool = False) -> dict:
    """Columns of the ``aacmm tip`` output for a :class:`~arm_model.io.PointSet`; ``arm`` an
    :class:`~arm_model.model_file.Arm` (every effect applied) or a description. ``x_rigid_mm``: the
    ball centre at a zero force reading; ``x_mm``: with the points' wrench. ``centres``: the (rigid,
    corrected) centres of :func:`tip_centres`, when the caller has them. ``reference_frame``: also the markers
    as the reference instrument would see them (:func:`reference_columns`)."""
    if not isinstance(arm, Arm):
        arm = Arm(arm)
    desc = arm.desc
    rigid, corrected = tip_centres(arm, points) if centres is None else centres
    delta = corrected - rigid
    cols = {"measurement": points.measurement, "feature": points.feature}
    for k, axis in enumerate("xyz"):
        cols[f"{axis}_rigid_mm"] = rigid[:, k] * 1e3
    for k, axis in enumerate("xyz"):
        cols[f"{axis}_mm"] = corrected[:, k] * 1e3
    for k, axis in enumerate("xyz"):
        cols[f"d{axis}_um"] = delta[:, k] * 1e6
    cols["deflection_um"] = np.linalg.norm(delta, axis=1) * 1e6
    cols["over_force"] = points.over_force(desc.probe.max_force).astype(int)
    if reference_frame:
        cols.update(reference_columns(arm, points))
    return cols


def _check_tracker(arm: Arm, path) -> None:
    """An :class:`InputError` when ``arm`` holds no reference instrument's frame (``--reference-frame``)."""
    if arm.tracker is None:
        raise InputError("--reference-frame needs a model file with the reference instrument's frame "
                         "([[reference_frame]]), as aacmm calibrate writes it from points with reference columns",
                         path)


def reference_columns(arm: Arm, points) -> dict:
    """``x_ref_mm, y_ref_mm, z_ref_mm`` (``x1_ref_mm`` ... for several markers): each marker of ``arm.tracker``
    where the instrument would see it [mm] in the frame of the row's session, and ``error_ref_um``
    (``error1_ref_um`` ...): the 3D distance [um] measured - predicted where ``points`` carry the
    instrument's coordinates of as many markers."""
    from .tracker import DEFAULT_SESSION, check_sessions, marker_positions
    _check_tracker(arm, arm.desc.source)
    sessions = points.session if points.session is not None else np.full(len(points), DEFAULT_SESSION, object)
    check_sessions(arm.tracker, sessions, points.path)
    predicted = marker_positions(arm.model, arm.p, points.q, arm.tracker, sessions,
                                 arm.aux(points, wrench=np.zeros((len(points), 6)), contact=False))
    k = predicted.shape[1]
    cols = {}
    for m in range(k):
        tag = "" if k == 1 else str(m + 1)
        for a, axis in enumerate("xyz"):
            cols[f"{axis}{tag}_ref_mm"] = predicted[:, m, a] * 1e3
    if points.n_markers == k:
        for m in range(k):
            cols[f"error{'' if k == 1 else m + 1}_ref_um"] = np.linalg.norm(points.ref[:, m] - predicted[:, m],
                                                                              axis=1) * 1e6
    return cols


class _TipTally:
    """What ``aacmm tip`` reports of the points it wrote (merged over the parts of a file read in
    parallel, in file order)."""

    def __init__(self, desc, path: str):
        self.n, self.measurements, self.kinds = 0, {}, set()
        self.d_sum, self.d_max, self.flagged, self.flagged_count = 0.0, 0.0, [], 0
        self.limits = JointLimitTally(desc, path)

    def add(self, block, cols) -> None:
        self.n += len(block)
        self.measurements.update(dict.fromkeys(block.measurement.tolist()))
        self.kinds.add(block.force_kind)
        d = cols["deflection_um"]
        self.d_sum, self.d_max = self.d_sum + float(d.sum()), max(self.d_max, float(d.max()))
        if len(self.flagged) < 11:
            self.flagged += block.lines[cols["over_force"].astype(bool)][:11].tolist()
        self.flagged_count += int(cols["over_force"].sum())
        self.limits.add(block.q, block.lines, block.q_units)

    def merge(self, other: _TipTally) -> None:
        self.n += other.n
        self.measurements.update(other.measurements)
        self.kinds |= other.kinds
        self.d_sum, self.d_max = self.d_sum + other.d_sum, max(self.d_max, other.d_max)
        self.flagged = (self.flagged + other.flagged)[:11]
        self.flagged_count += other.flagged_count
        self.limits.merge(other.limits)


def _tip_rows(arm, path, blocks, out: Path, header: bool, extra=None, reference_frame: bool = False) -> _TipTally:
    """Write the ``aacmm tip`` rows of ``blocks`` (of the points file ``path``) to ``out`` (appending);
    ``extra(block)``: more columns (the uncertainties); ``reference_frame``: the instrument's columns."""
    tally = _TipTally(arm.desc, str(path))
    with open(out, "ab") as fh:
        for block in blocks:
            cols = tip_table(arm, block, reference_frame=reference_frame)
            if extra is not None:
                cols.update(extra(block))
            fh.write(format_csv(cols, "%.6f", header=header and tally.n == 0))
            tally.add(block, cols)
    return tally


def _append(dst: Path, src: Path) -> None:
    """Append the file ``src`` to the file ``dst`` (in the kernel where it can: copy_file_range)."""
    with open(src, "rb") as fi, open(dst, "r+b") as fo:
        size, done = os.fstat(fi.fileno()).st_size, 0
        fo.seek(0, os.SEEK_END)
        try:
            while done < size:
                n = os.copy_file_range(fi.fileno(), fo.fileno(), size - done)
                if n == 0:
                    break
                done += n
        except (AttributeError, OSError):   # not on this system or across these file systems
            pass
        fi.seek(done)
        fo.seek(0, os.SEEK_END)
        shutil.copyfileobj(fi, fo, 1 << 24)


def _tip_part(arm, path, out: Path, span, known_header, reference_frame: bool) -> _TipTally:
    """One part of a large points file, in a worker process (see :func:`run_tip`)."""
    from . import kinematics
    kinematics.THREADS = 1                           # the other cores run the other parts
    return _tip_rows(arm, path, iter_points(path, arm.desc.joint_quantities, span=span, known_header=known_header),
                     out, header=span[0] == 0, reference_frame=reference_frame)


def run_tip(args: argparse.Namespace) -> int:
    # block by block: a file of millions of rows in bounded memory; a large file is read in parts by
    # worker processes (one a core, up to 2), each part written to its own file and the parts joined in
    # order; nothing is written on an error (the first error in file order is the one reported)
    from .csv_io import csv_spans
    from .parallel import fork_map, workers
    with output_file(args.output, [args.points, *arm_inputs(args)], writes=".csv") as tmp:
        arm = model_from_args(args)
        desc = arm.desc
        ref = args.reference_frame
        if ref:
            _check_tracker(arm, args.arm)
        from .model_file import parameters_of
        from .uncertainty_cli import refuse_unused, tip_columns, wants_uncertainty
        parameters = parameters_of(arm)
        uncertain = wants_uncertainty(args, parameters)
        refuse_unused(args, uncertain, "the uncertainty", "add --uncertainty; a model file with a covariance gives it "
                      "always")
        refuse_unused(args, bool(args.mc), "the Monte Carlo", "add --mc N", (("--seed", "seed"),))
        # one block: the uncertainty summary is over all points; a point's last move is from the point before it
        whole = uncertain or "motion" in arm.model.needs()
        split = None if whole else csv_spans(args.points, workers())
        ulines = []
        if whole:
            def extra(block):
                ucols, lines = tip_columns(arm, block, parameters, args)
                ulines.extend(lines)
                return ucols
            tally = _tip_rows(arm, args.points, [concat_points(iter_points(args.points, desc.joint_quantities))], tmp,
                              True, extra if uncertain else None, ref)
        elif split is None:
            tally = _tip_rows(arm, args.points, iter_points(args.points, desc.joint_quantities), tmp, True,
                              reference_frame=ref)
        else:
            known_header, spans = split
            parts = [tmp] + [tmp.with_name(f"{tmp.name}.part{k}") for k in range(1, len(spans))]
            try:
                tallies = fork_map(_tip_part, [(arm, str(args.points), part, span, known_header, ref)
                                               for part, span in zip(parts, spans, strict=True)])
                for part in parts[1:]:
                    _append(tmp, part)
            finally:
                for part in parts[1:]:
                    part.unlink(missing_ok=True)
            tally = tallies[0]
            for t in tallies[1:]:
                tally.merge(t)
            if not tally.n:
                raise InputError("no points after the header line", args.points, known_header[0] + 1)
    n, kinds, flagged, flagged_count = tally.n, tally.kinds, tally.flagged, tally.flagged_count
    log.info(f"{n} points in {len(tally.measurements)} measurement(s) -> {args.output}")
    if ref:
        k = arm.tracker.n_markers
        log.info(f"reference instrument: {k} marker(s) predicted in the frame of each row's session "
                 f"({', '.join(repr(s) for s in arm.tracker.sessions)})"
                 + ("; u_x_mm ... are of the tip in the base frame and hold the fitted frame's and marker "
                    "offsets' share, which cancels in x_ref_mm ... (no u there: docs/uncertainty.md, 'A robot "
                    "seen by a tracker only')" if getattr(arm, "covariance", None) is not None else ""))
    if arm.effects:
        log.info("effects applied: " + ", ".join(e.describe(arm.desc) for e in arm.effects))
    if kinds == {None}:
        log.info("no force columns: corrected = rigid (no deflection applied)")
    elif desc.probe.lever == 0.0:
        log.warning("the tip has no stylus (it lies at the last joint's origin: a flange, a marker): the force "
                    "columns bend nothing, corrected = rigid; for the deflection of a compliant probe give a tip "
                    "frame at its ball")
    else:
        if "two-channel" in kinds:
            log.info("two-channel force sensor (f_bend, f_axial): the bending force along probe y is not measured "
                  "and is taken as zero")
        log.info(f"deflection: mean {tally.d_sum / n:.2f} um, max {tally.d_max:.2f} um")
    for line in ulines:
        log.info(line)
    if flagged_count:
        log.warning(f"{flagged_count} point(s) over the probe's calibrated force range "
              f"({desc.probe.max_force:g} N), flagged in column over_force; lines {', '.join(map(str, flagged[:10]))}"
              + (" ..." if flagged_count > 10 else ""))
    log_warnings(tally.limits.warnings())
    return 0


def run_examples(args: argparse.Namespace) -> int:
    from .shipped import copy_examples
    written = copy_examples(args.dir)
    log.info(f"examples -> {args.dir}/ ({', '.join(p.name for p in written)}); start with {args.dir}/README.md; "
             f"try: aacmm simulate {args.dir}/campaigns/paper-ring.toml -o out/paper-ring")
    return 0


def run_urdf(args: argparse.Namespace) -> int:
    with output_file(args.output, arm_inputs(args), writes=".urdf") as tmp:
        arm = model_from_args(args)
        desc = arm.desc
        base, tip = kept_link_names(desc)
        tmp.write_text(urdf_text(desc, base_link=base, tip_link=tip), encoding="utf-8")
    log.info(f"URDF of '{desc.name}' ({desc.n_joints} joints + 3 elastic probe joints) -> {args.output}; its chain "
             f"runs from '{base}' to the ball link '{tip}' (--tip-frame {tip})")
    if arm.effects:
        log.info("note: a URDF holds the geometry only; the model's effects ("
              + ", ".join(e.describe(arm.desc) for e in arm.effects) + ") are not in it")
    return 0
