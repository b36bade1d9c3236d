"""``aacmm ring`` (a ring-gauge campaign, every correction model, report) and ``aacmm paper`` (the seed
paper's tables reproduced, the loop closed on its Table 2)."""
from __future__ import annotations

import argparse
import logging

import numpy as np

from arm_model import InputError, NumericalError, read_artefacts, read_points
from arm_model.checks import log_warnings
from arm_model.cli import command_help
from arm_model.cli_options import (
    add_arm_options,
    add_output_option,
    arm_inputs,
    folder_arg,
    model_from_args,
    number_in,
    path_arg,
)
from arm_model.io import check_features
from arm_model.log import counted
from arm_model.output import output_folder
from arm_model.uncertainty_cli import add_input_options

__all__ = ["register", "run_ring", "run_paper"]

log = logging.getLogger(__name__)


def register(sub) -> None:
    r = sub.add_parser(
        "ring", help=command_help("ring"),
        description="Analyse a ring-gauge campaign as the seed paper does and beyond. Per measurement: the force "
                    "at each captured point (one peak of the force signal a point with --signals, else the points "
                    "file's force columns), the ring fitted by orthogonal least squares (diameter = ball-centre "
                    "cylinder + ball diameter, form error = max - min radial deviation), then corrected by the "
                    "paper's four models (each point moved by f x compliance towards the axis with f = the point's "
                    "bending force, or the measurement's mean, 10Max or max) and by the full-wrench model (ball "
                    "centres evaluated again through the probe's elastic joint with each point's force vector). "
                    "Writes report.html, summary.json, table2.csv, correlations.csv, budgets.csv, roundness.csv (each "
                    "point's radial deviation from the fitted cylinder against its angle, initial and corrected: "
                    "the data of the polar roundness plots) and figures/*.png into the output folder "
                    "(docs/formats.md).")
    r.add_argument("points", type=path_arg, help="points CSV (docs/formats.md §3) with the ring's points")
    r.add_argument("artefacts", type=path_arg,
                   help="artefacts TOML (docs/formats.md §4) with the ring (kind = \"ring\")")
    add_arm_options(r)
    r.add_argument("--signals", type=folder_arg, metavar="DIR",
                   help="folder of force signals, one <measurement>.csv a measurement (docs/formats.md §5); "
                        "without it the points file's force columns are used")
    r.add_argument("--feature", metavar="ID", help="id of the ring feature when the artefacts file has several rings")
    r.add_argument("--compliance-mm-per-N", type=number_in(0, 1e3, low_open=True), dest="compliance", metavar="C",
                   help="compliance of the paper's four models (default: the arm's probe bending compliance, "
                        "0.0142 mm/N in the nominal arm)")
    r.add_argument("--u-force-N", type=number_in(0, 1e5, low_open=True), dest="u_force", default=None,
                   metavar="BENDING",
                   help="standard uncertainty of a measured force for the budgets' u_cor = 2 c u_force "
                        "and of the bending force (probe x, y) in the points' covariances (default 0.0723 N: "
                        "the paper's bending sensor, Table 1 terms combined; the axial stays 0.0464 N: one value, "
                        "where aacmm tip's --u-force-N takes the bending and the axial)")
    r.add_argument("--delta-T-C", type=number_in(0, 1e4), dest="delta_t", default=0.5, metavar="DT",
                   help="temperature variation during the test for the budgets' u_t (default 0.5 C, the paper's)")
    r.add_argument("--probability-pct", type=number_in(0, 100, low_open=True, high_open=True), dest="probability",
                   default=95.0, metavar="P",
                   help="coverage probability of the expanded uncertainties (default 95)")
    r.add_argument("--no-plots", action="store_true", help="skip the PNG figures (figures/ is not written)")
    add_input_options(r, force=False)
    add_output_option(r)
    r.set_defaults(func=run_ring)

    p = sub.add_parser(
        "paper", help=command_help("paper"),
        description="Reproduce the seed paper (Gonzalez-Madruga et al., Sensors 2013): the forces each model of "
                    "its Table 2 implies, its Pearson coefficients and improvement figures, its uncertainty "
                    "budgets (Tables 1 and 3) term by term with GTC, with every printed figure that does not "
                    "follow from its own terms reported; then close the loop: the residual after the FEM probe "
                    "correction against the force, the compliance in series that explains it, cross-validated "
                    "leave-one-out. Writes report.html, summary.json, table2_implied.csv, findings.csv and "
                    "figures/*.png.",
        epilog="Output files: docs/formats.md §7, docs/ring-pipeline.md.")
    p.add_argument("--table2", type=path_arg, default=None, metavar="CSV",
                   help="a Table 2 CSV in the bundled format (default: the bundled correction/data/paper_table2.csv; "
                        "docs/ring-pipeline.md)")
    add_output_option(p)
    p.set_defaults(func=run_paper)


def run_ring(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from arm_model.model_file import parameters_of
    from arm_model.uncertainty import FORCE_SENSOR_U_N
    from arm_model.uncertainty_cli import inputs_from_args

    from .models import analyse_ring_campaign, campaign_summary, check_reportable, ring_uncertainties, ring_warnings
    from .report import DEFAULT_U_FORCE, ring_budgets, ring_report

    inputs = {"points": args.points, "artefacts": args.artefacts, "arm": args.arm}
    if args.signals is not None and not args.signals.is_dir():
        raise InputError("--signals must be a folder of <measurement>.csv force signals", args.signals)
    with output_folder(args.output, [args.points, args.artefacts, *arm_inputs(args)], "ring",
                       input_folders=[args.signals]) as out:
        arm = model_from_args(args)
        desc = arm.desc
        points = read_points(args.points, desc.joint_quantities)
        artefacts = read_artefacts(args.artefacts)
        check_features(points, artefacts)
        compliance = None if args.compliance is None else args.compliance * 1e-3
        campaign = analyse_ring_campaign(desc, points, artefacts, args.feature, args.signals, compliance, arm=arm)
        check_reportable(campaign, points)
        warnings = ring_warnings(desc, points, campaign)
        u_force = DEFAULT_U_FORCE if args.u_force is None else args.u_force
        budgets = ring_budgets(campaign, u_force=u_force, delta_t=args.delta_t, probability=args.probability)
        parameters = parameters_of(arm)
        unc_inputs = inputs_from_args(arm, args, has_force=True)
        if args.u_force is not None:
            unc_inputs = replace(unc_inputs, force=np.array([args.u_force, args.u_force, FORCE_SENSOR_U_N[2]]),
                                 sources=unc_inputs.sources | {"force sensor": f"given: {args.u_force:g} N bending"})
        try:
            point_unc = ring_uncertainties(arm, points, campaign, parameters, unc_inputs)
        except NumericalError as exc:   # the points passed their reader: a numerical failure (exit 4), file named
            raise NumericalError(f"{args.points}: diameter uncertainty from the points: {exc}") from None
        inputs["signals"] = args.signals
        written = ring_report(campaign, out.dir, inputs, budgets, warnings, point_unc,
                              parameters.source if parameters is not None else None, plots=not args.no_plots)
    s = campaign_summary(campaign)
    log.info(f"ring '{campaign.feature}': {counted(len(campaign.measurements), 'measurement')}, "
          f"{counted(sum(r.n_points for r in campaign.measurements), 'point')}; forces from "
          f"{'signals in ' + str(args.signals) if args.signals else 'the points file'}")
    if arm.effects:
        log.info("effects applied to every ball centre: " + ", ".join(e.describe(arm.desc) for e in arm.effects))
    for n in campaign.notes:
        log.info(f"note: {n}")
    log_warnings(warnings)
    log.info(f"{'model':<12} {'mean |dD| [mm]':>15} {'reduction':>10} {'mean form [mm]':>15}")
    for m, v in s.items():
        log.info(f"{m:<12} {v['mean_abs_diameter_error_mm']:>15.4f} {v['diameter_error_reduction_pct']:>9.1f}% "
              f"{v['mean_form_error_mm']:>15.4f}")
    u = [d.u for d, _ in point_unc]
    uf = [f.u for _, f in point_unc]
    log.info("from the points' covariances (k = 1; "
          + ('parameters from ' + parameters.source if parameters is not None
             else 'no parameter covariance: parameters exact') + "):"
          f"\n  diameter uncertainty {min(u) * 1e3:.4f} .. {max(u) * 1e3:.4f} mm; form-error uncertainty "
          f"{min(uf) * 1e3:.4f} .. {max(uf) * 1e3:.4f} mm")
    if args.u_force is None:
        log.info(f"budgets: u_force = {DEFAULT_U_FORCE} N (the paper's bending sensor; set --u-force-N for yours)")
    log.info(f"{counted(len(written), 'file')} -> {args.output}/ (report.html, summary.json, ...)")
    return 0


def run_paper(args: argparse.Namespace) -> int:
    from .paper import load_paper_table2
    from .report import paper_report, paper_summary

    with output_folder(args.output, [args.table2], "paper") as out:
        table = load_paper_table2(args.table2)
        written = paper_report(out.dir, args.table2)
    s = paper_summary(table)
    bad = [f for f in s["findings"] if not f["consistent"]]
    log.info(f"Table 2 ({len(table.initial)} measurements): Pearson r with the (0, 0) point: "
          + ", ".join(f"{c['force'].replace('_force_N', '')} {c['r']:.3f}"
                      for c in s["pearson"] if c["with_reference"]))
    log.info("improvement (reduction of the mean |diameter error|): "
          + ", ".join(f"{m.replace('_force', '')} {d['mean_abs_reduction_pct']:.1f}%"
                      for m, d in s["improvement"].items()))
    log.info(f"{len(bad)} printed figures of Tables 1 and 3 do not follow from their own terms (see findings.csv)")
    L = s["loop"]
    log.info(f"loop: residual after the FEM correction vs mean force r = {L['r_residual_force']:.3f}; series "
             f"compliance {L['series_compliance_mm_per_N']:.4f} mm/N; LOO RMS {L['rms_before_mm']:.4f} -> "
          f"{L['loo_rms_after_mm']:.4f} mm")
    log.info(f"{counted(len(written), 'file')} -> {args.output}/")
    return 0
