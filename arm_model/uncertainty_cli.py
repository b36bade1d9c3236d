"""Command-line side of :mod:`arm_model.uncertainty`: the input-uncertainty options every command shares,
and the per-point columns of ``aacmm tip`` (``u_x_mm`` ..., ``cov_xx_um2`` ..., Monte Carlo)."""
from __future__ import annotations

import math

import numpy as np

from .cli_options import number_in, seed
from .uncertainty import (
    COMPLIANCE_U_RELATIVE,
    CONTRIBUTIONS,
    InputUncertainty,
    ParameterCovariance,
    covariance_columns,
    directional_ratio,
    monte_carlo,
    propagate,
)

__all__ = ["add_input_options", "inputs_from_args", "add_tip_options", "wants_uncertainty", "tip_columns",
           "contribution_lines", "u_columns", "refuse_unused", "INPUT_OPTIONS"]


#: the largest values the input-uncertainty options take (their plausible ranges, docs/uncertainty.md):
#: an encoder step of at most a turn, a force uncertainty of at most 100 kN, a relative compliance
#: uncertainty of at most 1000 %, a probing scatter of at most 100 mm (as probing_scatter_um of a model
#: file); at most a million Monte Carlo samples
MAX_ENCODER_RESOLUTION_DEG, MAX_U_FORCE_N, MAX_U_COMPLIANCE_REL, MAX_U_PROBING_UM, MAX_MC = 360.0, 1e5, 10.0, 1e5, 10**6


def add_input_options(p, force: bool = True) -> None:
    """The input uncertainties (each overrides its default, see docs/uncertainty.md); ``force=False``
    leaves out ``--u-force-N`` for a command that has its own (``aacmm ring``)."""
    g = p.add_argument_group("input uncertainties (defaults and their sources: docs/uncertainty.md)")
    g.add_argument("--encoder-resolution-deg", type=number_in(0, MAX_ENCODER_RESOLUTION_DEG), default=None, metavar="R",
                   help="encoder resolution of every joint [deg] (u = R / sqrt(12)); default: each joint's "
                        "encoder_resolution of the description, 0 where not given")
    if force:
        g.add_argument("--u-force-N", type=number_in(0, MAX_U_FORCE_N), nargs=2, default=None,
                       metavar=("BENDING", "AXIAL"),
                       help="standard uncertainty of the force [N] across (probe x, y) and along (z) the stylus; "
                            "default 0.0723 0.0464 (the seed paper's Table 1)")
    g.add_argument("--u-compliance-rel", type=number_in(0, MAX_U_COMPLIANCE_REL), default=None, metavar="R",
                   help=f"standard uncertainty of the probe compliances relative to their value (default "
                        f"{COMPLIANCE_U_RELATIVE:g}, from the seed paper's Table 2 fit); not used for compliances "
                        "the model's covariance holds")
    g.add_argument("--u-probing-um", type=number_in(0, MAX_U_PROBING_UM), default=None, metavar="U",
                   help="probing scatter of a ball centre per axis [um] (default: the model file's "
                        "probing_scatter_um, which calibrate and close-loop write: their residual scatter net of the "
                        "encoder and force-sensor noise propagated with the default inputs; 0 without one)")
    g.add_argument("--u-model-discrepancy-um", type=number_in(0, MAX_U_PROBING_UM), default=None, metavar="U",
                   help="model discrepancy per axis [um]: the model's error beyond its parameters' uncertainty "
                        "away from the poses it was calibrated on, the same at every pose (default: the model "
                        "file's model_discrepancy_um, which calibrate writes from an extrapolative cross-validation, "
                        "grown by its model_discrepancy_growth_um_per_mm for each mm the joint motions from the "
                        "nearest training pose carry the ball; 0 without one)")


def inputs_from_args(arm, args, has_force: bool) -> InputUncertainty:
    """The input uncertainties of an :class:`~arm_model.model_file.Arm` with the options of
    :func:`add_input_options` overriding their defaults."""
    desc = arm.desc
    enc = None if args.encoder_resolution_deg is None else math.radians(args.encoder_resolution_deg) / math.sqrt(12)
    u_force = getattr(args, "u_force_N", None)
    force = None if u_force is None else (u_force[0], u_force[0], u_force[1])
    comp = None if args.u_compliance_rel is None else args.u_compliance_rel * np.asarray(desc.probe.compliance)
    probing = None if args.u_probing_um is None else args.u_probing_um * 1e-6
    u_disc = getattr(args, "u_model_discrepancy_um", None)
    inputs = arm.input_uncertainty(has_force, encoder=enc, force=force, compliance=comp, probing=probing,
                                   discrepancy=None if u_disc is None else u_disc * 1e-6)
    if args.u_compliance_rel is not None:
        inputs.sources["compliance"] = f"given: {args.u_compliance_rel:g} of the declared compliances"
    return inputs


def add_tip_options(p) -> None:
    g = p.add_argument_group("uncertainty of the corrected centres (docs/uncertainty.md)")
    g.add_argument("--uncertainty", action="store_true",
                   help="write u_x_mm, u_y_mm, u_z_mm even when the model carries no parameter covariance "
                        "(the parameters are then taken as exact); with a covariance they are always written")
    g.add_argument("--covariance", action="store_true",
                   help="also write the six terms of each point's 3x3 covariance [um^2] (cov_xx_um2, cov_yy_um2, "
                        "cov_zz_um2, cov_xy_um2, cov_xz_um2, cov_yz_um2)")
    g.add_argument("--mc", type=number_in(2, MAX_MC, kind=int), default=None, metavar="N",
                   help="also a Monte Carlo of N samples of the same inputs: columns u_x_mc_mm ... (with "
                        "--covariance also cov_xx_mc_um2 ...) and the largest relative difference to the linear "
                        "result, per axis and along any direction")
    g.add_argument("--seed", type=seed, default=None, help="seed of the --mc Monte Carlo draws (default 0)")
    add_input_options(p)


def wants_uncertainty(args, parameters: ParameterCovariance | None) -> bool:
    return bool(parameters is not None or args.uncertainty or args.covariance or args.mc)


#: the options of :func:`add_input_options` (option, its attribute)
INPUT_OPTIONS = (("--encoder-resolution-deg", "encoder_resolution_deg"), ("--u-force-N", "u_force_N"),
                 ("--u-compliance-rel", "u_compliance_rel"), ("--u-probing-um", "u_probing_um"),
                 ("--u-model-discrepancy-um", "u_model_discrepancy_um"))


def refuse_unused(args, used: bool, what: str, ask: str, options=INPUT_OPTIONS) -> None:
    """An InputError when one of ``options`` ((option, attribute) pairs; default the input uncertainties) was given
    to a command that will not use it (``used`` False): accepted, it would do nothing, without a word (``tip
    --u-probing-um 3`` wrote no uncertainty). ``what``: what the options are of; ``ask``: how to ask for it."""
    from .errors import InputError
    given = [o for o, attr in options if getattr(args, attr, None) is not None]
    if given and not used:
        raise InputError(f"{', '.join(given)}: option(s) of {what}, which is not asked for ({ask})")


def contribution_lines(res) -> list[str]:
    """One line a contribution: RMS over the points of its standard uncertainty per axis [um], source."""
    lines = []
    for name in CONTRIBUTIONS:
        v = res.summary().get(name)
        if v is None:
            continue
        lines.append(f"  {name:<17} {v[0] * 1e6:8.3f} {v[1] * 1e6:8.3f} {v[2] * 1e6:8.3f}   "
                     f"{res.sources.get(name, '')}")
    return lines


def u_columns(res) -> dict:
    """The standard uncertainty columns ``u_x_mm, u_y_mm, u_z_mm`` of ``aacmm tip`` for a
    :class:`~arm_model.uncertainty.Propagation`."""
    u = res.u
    return {f"u_{a}_mm": u[:, k] * 1e3 for k, a in enumerate("xyz")}


def tip_columns(arm, points, parameters, args) -> tuple[dict, list[str]]:
    """The uncertainty columns of ``aacmm tip`` (mm, um^2) for an :class:`~arm_model.model_file.Arm`
    and a :class:`~arm_model.io.PointSet`, and the lines it prints."""
    inputs = inputs_from_args(arm, args, points.wrench is not None)
    model, p, wrench, aux = arm.model, arm.p, points.wrench, arm.aux(points)
    points_q = points.q
    res = propagate(model, p, points_q, wrench, aux, parameters=parameters, inputs=inputs)
    u = res.u
    cols = u_columns(res)
    if args.covariance:
        cols.update(covariance_columns(res.cov))
    lines = ["uncertainty of the corrected centres (linear, exact Jacobians); RMS over the points [um]:",
             f"  {'contribution':<17} {'x':>8} {'y':>8} {'z':>8}   source"] + contribution_lines(res)
    tot = np.sqrt(np.mean(u ** 2, axis=0)) * 1e6
    lines.append(f"  {'total':<17} {tot[0]:8.3f} {tot[1]:8.3f} {tot[2]:8.3f}")
    if args.mc:
        mc = monte_carlo(model, p, points_q, wrench, aux, parameters=parameters, inputs=inputs,
                         samples=args.mc, seed=args.seed or 0)
        umc = mc.u
        cols.update({f"u_{a}_mc_mm": umc[:, k] * 1e3 for k, a in enumerate("xyz")})
        if args.covariance:
            cols.update({k.replace("_um2", "_mc_um2"): v for k, v in covariance_columns(mc.cov).items()})
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.where(u > 0, umc / u - 1.0, 0.0)
        lines.append(f"Monte Carlo ({args.mc} samples, seed {args.seed or 0}): u_mc / u_linear - 1 over the points "
                     "and "
                     f"axes: median {np.median(rel):+.3f}, largest |.| {np.max(np.abs(rel)):.3f}")
        d = directional_ratio(res.cov, mc.cov) - 1.0
        if np.isfinite(d).any():
            lines.append(f"  along any direction (the covariance terms included): from {np.nanmin(d):+.3f} to "
                         f"{np.nanmax(d):+.3f}" + (f" ({np.isnan(d[:, 0]).sum()} points with a singular linear "
                                                    "covariance left out)" if np.isnan(d).any() else ""))
    return cols, lines
