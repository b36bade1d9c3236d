"""``aacmm calibrate`` and ``aacmm study`` (``montecarlo``, ``poses``)."""
from __future__ import annotations

import argparse
import logging
from dataclasses import replace

import numpy as np

from arm_model import InputError
from arm_model.checks import log_warnings, point_warnings
from arm_model.cli import command_help
from arm_model.cli_options import (
    add_arm_options,
    add_output_option,
    arm_inputs,
    at_least,
    comma_list,
    fraction,
    model_from_args,
    non_negative,
    number_in,
    path_arg,
    seed,
)
from arm_model.csv_io import parse_number
from arm_model.discrepancy import growth_text
from arm_model.errors import resolved
from arm_model.io import json_text, read_artefacts, read_points
from arm_model.log import counted, progress_line
from arm_model.model_file import Arm
from arm_model.output import output_folder
from arm_model.parallel import cores
from arm_model.units import STATED_SIGMA_M

from .options import GROSS_THRESHOLD

__all__ = ["register", "run_calibrate", "run_montecarlo", "run_poses", "fit_options", "free_names"]

log = logging.getLogger(__name__)


def _effects(keys):
    from arm_model.effects import EFFECTS
    out = []
    if "none" in (keys or ()) and len(set(keys)) > 1:
        raise InputError(f"--effect none is the geometry alone: it takes no other --effect (got "
                         f"{', '.join(k for k in keys if k != 'none')})")
    for k in keys or ():
        if k == "none":
            continue
        if k not in EFFECTS:
            raise InputError(f"unknown effect '{k}' (known: {', '.join(EFFECTS)}, or none)")
        out.append(EFFECTS[k]())
    return tuple(out)


def parse_holdout(text: str | None):
    """``--holdout`` (of calibrate and close-loop): None, a fraction in (0, 1) or a list of measurement ids."""
    if text is None:
        return None
    v = parse_number(text)
    if v is None:                       # the files' number rule: "0.2", not "0_2" nor another script's digits
        return list(comma_list(text, "--holdout", "measurement", "measurement ids, comma-separated, or a fraction"))
    if not 0.0 < v < 1.0:
        raise InputError(f"--holdout fraction must be in (0, 1), got {text}")
    return v


def campaign_inputs(p) -> None:
    """Points, artefacts, arm, reference points and output folder (shared with ``aacmm close-loop``)."""
    p.add_argument("points", type=path_arg,
                   help="points CSV (docs/formats.md §3); its reference columns (x_ref_mm ..., or x1_ref_mm ... for "
                        "several markers) are a tracker's coordinates")
    p.add_argument("artefacts", type=path_arg, nargs="?", default=None,
                   help="artefacts TOML (docs/formats.md §4); leave it out for a campaign of tracker (reference) "
                        "coordinates only: every row a free point with reference columns")
    add_arm_options(p, "nominal arm: a shipped arm's name (aacmm7), a description TOML or model file, or a URDF "
                       "with --tip-frame (docs/formats.md §2, docs/own-arm.md)")
    reference_points_option(p)
    add_output_option(p)


def reference_points_option(p) -> None:
    """``--reference-points``: a second points file of reference coordinates (calibrate, close-loop, study poses)."""
    p.add_argument("--reference-points", type=path_arg, default=None,
                   help="a second points CSV whose rows all carry reference coordinates (x_ref_mm ...), e.g. tracker "
                        "nests, joined to the points file (docs/formats.md §3)")


def marker_option(p) -> None:
    """``--marker-offset``: where the reference instrument's markers sit on the tip frame."""
    p.add_argument("--marker-offset", choices=("fit", "zero"), default=None,
                   help="fit: each marker of the reference columns sits at an unknown offset on the tip frame "
                        "(a motion-capture marker or a tracker target on a robot's flange), estimated with the fit "
                        "and written to the model file; zero: the instrument sees the tip point itself (a tracker's "
                        "reflector in the probe's place). Default: fit without an artefacts file, zero with one")


#: argparse type of a stated standard uncertainty [um]: arm_model.units.STATED_SIGMA_M (1 pm to 100 mm), as a
#: certified distance's u_length_mm
SIGMA_UM = number_in(STATED_SIGMA_M[0] * 1e6, STATED_SIGMA_M[1] * 1e6)
#: argparse type of a maximum permissible error [um] (``--mpe-*-um``): a stated length tolerance, the same range
#: (1e-300 failed every item and 1e308 passed every one, a verdict without meaning)
MPE_UM = SIGMA_UM
#: argparse type of a threshold on a standardized residual [sigma]: from 1 (a residual within one standard deviation
#: is no outlier; 1e-300 reported every point as one) to 1e6
THRESHOLD_SIGMA = number_in(1, 1e6)


def sigma_options(p, prior_default: str | None = None) -> None:
    """The stated uncertainties that weight the residuals and the prior (shared with ``aacmm close-loop``, whose
    ``--prior-scale`` defaults to ``prior_default``)."""
    p.add_argument("--sigma-probe-um", type=SIGMA_UM, default=None,
                   help="standard uncertainty of a probed ball centre per axis [um] (default 10, a starting value: "
                        "a residual is judged against it only when stated)")
    p.add_argument("--sigma-ref-um", type=SIGMA_UM, default=None,
                   help="standard uncertainty of a reference-instrument coordinate per axis [um] (default 10, a "
                        "starting value: a residual is judged against it only when stated)")
    p.add_argument("--sigma-length-um", type=SIGMA_UM, default=None,
                   help="standard uncertainty of a certified length without u_length_mm [um] "
                        "(default: --sigma-probe-um)")
    p.add_argument("--weights", choices=("data", "stated"), default="data",
                   help="data (default): the sigmas above are starting values; the noise of each group of rows "
                        "(points per artefact kind, reference points, lengths) is estimated from the fit's residuals "
                        "(variance components), jointly with the prior's scales, the rows re-weighted and the fit "
                        "repeated until it settles; stated: use the sigmas as given")
    p.add_argument("--plausible-length-mm", type=number_in(1e-6, 1e6), default=None,
                   help="plausible size of a joint row's length error [mm] (angles: 1 mrad per mm of it) at prior "
                        "scale 1 (default 1 mm, 1 mrad; the evidence scales them); with --prior-scale off, the size "
                        "the --min-resolution rule judges against (default there: the larger of 1 mm and ten times "
                        "the noise of one point, angles 0.01 rad per mm)")
    default = "off" if prior_default is None else prior_default
    auto = prior_default == "auto"
    p.add_argument("--prior-scale", type=loop_prior_scale if auto else prior_scale, default=prior_default,
                   metavar="auto|evidence|off|FACTOR" if auto else "evidence|off|FACTOR",
                   help="evidence: a Gaussian prior on every free parameter, centred on the nominal value, standard "
                        "deviation its group's scale times its plausible error size (groups: lengths, joint offsets, "
                        "axis angles, the tip or marker offset, the probe's compliance, each effect), each scale "
                        "chosen by the evidence (type-II maximum likelihood) together with the noise: poorly "
                        "resolved parameters are shrunk towards the nominal and reported as prior-dominated, never "
                        "held; FACTOR: every group at that scale; off: no prior (--min-resolution may then hold "
                        "weak parameters)" + ("; auto: evidence when the base model holds a joint compliance "
                                                "(its prior is physical), else off" if auto else "")
                   + f". Default {default} (docs/calibration.md)")
    p.add_argument("--prior-groups", choices=("separate", "pooled"), default="separate",
                   help="with the evidence's scales: separate (default): each group its own scale; pooled: the "
                        "geometric groups (lengths, joint offsets, axis angles, the tip or marker offset) one scale, "
                        "one fixed point of the evidence over the four (docs/calibration.md)")
    p.add_argument("--arm-scale", choices=("prior", "data"), default="prior",
                   help="prior (default): the lengths' prior shrinks the arm's uniform scale too; data: a flat prior "
                        "on the scale, where the data set it within 0.5 %% (a certified length does; not the default: "
                        "docs/calibration.md)")




#: the range of a ``--prior-scale`` factor: below 1e-6 (1 nm on a 1 mm plausible size, far below any arm's
#: resolution) the prior holds every parameter at its nominal value (FitOptions takes wider factors, up to the limits
#: of its arithmetic, :data:`calibration.options.PRIOR_FACTOR_LIMITS`)
PRIOR_FACTOR_RANGE = (1e-6, 1e3)


def loop_prior_scale(text: str):
    """``close-loop --prior-scale``: "auto" (:class:`calibration.loop.LoopSettings`) or :func:`prior_scale`'s."""
    return "auto" if text.strip().lower() == "auto" else prior_scale(text, words="auto, evidence, off")


def prior_scale(text: str, words: str = "evidence, off"):
    """``--prior-scale``: None (off), "evidence" or a finite factor in :data:`PRIOR_FACTOR_RANGE`; ``words``: the
    words the option takes, for the message."""
    t = text.strip().lower()
    if t == "off":
        return None
    if t == "evidence":
        return "evidence"
    lo, hi = PRIOR_FACTOR_RANGE
    try:
        v = number_in(lo, hi)(t)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"expected {words} or a number in [{lo:g}, {hi:g}]: {exc}") from None
    return v


def model_options(p) -> None:
    """``--effect``, ``--free`` and ``--hold``: the model and which of its parameters are fitted (one definition,
    one meaning, for ``aacmm calibrate``, ``aacmm close-loop`` and the studies)."""
    from arm_model.effects import EFFECTS
    p.add_argument("--effect", action="append", metavar="KEY",
                   help="add an effect of arm_model.effects to the model (repeatable): "
                        f"{', '.join(EFFECTS)}. Its parameters are fitted (see --free); close-loop: it is part of "
                        "the base model, not a candidate. Without --effect both add joint_compliance for a robot "
                        "whose links carry masses (a URDF with <inertial> tags, or any arm seen by a tracker only), "
                        "with its physical prior; "
                        "'--effect none': the geometry alone")
    p.add_argument("--free", action="append", metavar="PATTERN",
                   help="parameters to identify, by name or glob (repeatable), e.g. 'j*.d', 'probe.*', "
                        "'j3.theta_offset'. Default: every joint-row error, probe.x/y/z and the parameters of the "
                        "model's effects (--effect, and those of a model file given as --arm; probe compliances "
                        "only when named). close-loop also frees the parameters of every effect it adds")
    p.add_argument("--hold", action="append", metavar="PATTERN",
                   help="parameters to hold at their value in --arm (the nominal's, or a model file's), removed "
                        "from the free set (repeatable)")


def _common_fit_options(p) -> None:
    model_options(p)
    sigma_options(p, prior_default="evidence")
    p.add_argument("--rank-tol", type=fraction, default=None,
                   help="relative singular value below which a parameter combination counts as not "
                        "identifiable (default 1e-4)")
    p.add_argument("--min-resolution", type=non_negative(), default=0.0, metavar="FRACTION",
                   help="with --prior-scale off only: hold parameters of the description (joint rows, probe) and of "
                        "the encoders' reading errors (eccentricity, joint_gain) the data would resolve only to worse "
                        "than this fraction of a plausible error size (the practical-resolution rule of earlier "
                        "versions: 0.1). Default 0: every linearly independent parameter is estimated")


def register(sub) -> None:
    c = sub.add_parser(
        "calibrate", help=command_help("calibrate"),
        description="Kinematic calibration in CasADi: the arm's parameter errors (DH or URDF joint origins, probe "
                    "offset, compliances, effects) from points on ball bars, seats, spheres, rings, cylinders, "
                    "planes and reference (tracker) points, with the artefacts' unknowns (centres, axes, "
                    "T_ref_base) solved jointly. Reports which parameter combinations the data cannot identify "
                    "(held fixed and listed, or the fit stops), uncertainties and correlations, outliers "
                    "(kept unless --drop-outliers), and validation figures (ASME B89.4.22 / ISO 10360-12 terms) "
                    "nominal vs calibrated on the training data and on held-out measurements. Writes a NEW "
                    "calibrated model file (the description with every effect and its parameters, TOML, read by every "
                    "--arm), its covariance (CSV) and URDF, summary.json, CSV tables and report.html.",
        epilog="Parameter names: docs/calibration.md. Examples: aacmm calibrate points.csv artefacts.toml "
               "--arm aacmm7 --reference-points points-ref.csv --holdout 0.2 -o out/cal; a robot seen by a tracker "
               "(no artefacts file): aacmm calibrate tracker.csv --arm robot.urdf --tip-frame flange --holdout 0.2 "
               "-o out/cal (docs/own-arm.md)")
    campaign_inputs(c)
    marker_option(c)
    _common_fit_options(c)
    c.add_argument("--holdout", default=None, metavar="IDS|FRACTION",
                   help="data kept out of the fit for validation: a fraction (0.2) drawn at random, or (with "
                        "--holdout-by measurement) a comma-separated list of measurement ids")
    c.add_argument("--holdout-by", choices=("measurement", "pose"), default=None,
                   help="measurement (default): whole measurements held out (the fraction drawn per artefact kind), "
                        "their features and reference frame fitted on themselves, the reference points also "
                        "predicted with the training fit's T_ref_base; pose: that fraction of every feature's poses "
                        "held out, each predicted against its feature as fitted on the training poses (reference "
                        "points: with the training fit's T_ref_base), so one placement of one artefact can be "
                        "validated")
    c.add_argument("--holdout-points", type=path_arg, default=None, metavar="FILE",
                   help="a points CSV of poses kept out of the fit (a stated validation set, the same columns as "
                        "the points file), each predicted against its feature (measurement and feature ids of the "
                        "points file) as fitted on the training points, as --holdout-by pose does")
    c.add_argument("--seed", type=seed, default=0, help="seed of the random --holdout draw (default 0)")
    c.add_argument("--reference", choices=("fit", "identity", "off"), default="fit",
                   help="reference coordinates: fit T_ref_base (default), take them as base coordinates "
                        "(identity: the base pose becomes identifiable) or ignore them")
    c.add_argument("--on-unidentifiable", choices=("fix", "stop"), default="fix",
                   help="hold unidentifiable parameters fixed and list them (default), or stop with the list")
    _outlier_options(c)
    _covariance_options(c)
    c.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    mpe_options(c)
    c.set_defaults(func=run_calibrate)

    s = sub.add_parser(
        "study", help=command_help("study"),
        description="Calibration studies before measuring. 'montecarlo': simulate a campaign many times (new noise "
                    "and poses each run), calibrate on the training measurements, validate on held-out ones; "
                    "reports parameter errors against the truth next to the reported uncertainties and the "
                    "predicted accuracy after calibration. 'poses': choose the measurements that identify the "
                    "parameters best by the observability index O1 (Borm and Menq 1991).",
        epilog="File formats: docs/formats.md; the studies: docs/calibration.md.")
    ss = s.add_subparsers(dest="study", metavar="STUDY", required=True)
    m = ss.add_parser("montecarlo", help="Monte Carlo over noise and pose sets with the simulator",
                      description="Run a simulator campaign (examples/campaigns/*.toml) --runs times with seeds "
                                  "--seed, --seed+1, ...; each run is calibrated and validated on held-out "
                                  "measurements. Local processes by default; --scheduler sends the runs to a Dask "
                                  "cluster. Writes study.json and prints a table.")
    m.add_argument("campaign", type=path_arg, help="campaign TOML of the simulator (docs/formats.md §6)")
    m.add_argument("--runs", type=number_in(1, 100_000, kind=int), default=20,
                   help="number of runs (default 20; at most 100000)")
    m.add_argument("--seed", type=seed, default=0,
                   help="seed of the first run's simulation (run i uses --seed + i; default 0)")
    m.add_argument("--holdout", type=number_in(0, 1, high_open=True), default=0.25, metavar="FRACTION",
                   help="held-out fraction of measurements, in [0, 1) (default 0.25; 0: none, every run fits all "
                        "its measurements, and the study reports the parameters against the truth without a "
                        "predicted accuracy)")
    m.add_argument("--workers", type=number_in(1, cores(), kind=int), default=None,  # more: memory, no speed
                   help=f"local processes, at most the cores this process may run on ({cores()} here; default: all)")
    m.add_argument("--scheduler", default=None,
                   help="Dask scheduler address, e.g. tcp://10.0.0.5:8786 (instead of --workers: the cluster's "
                        "workers run the runs; each needs this toolkit installed, not the campaign's files)")
    add_output_option(m)
    _common_fit_options(m)
    m.set_defaults(func=run_montecarlo)
    q = ss.add_parser("poses", help="choose measurements by the observability index O1",
                      description="Greedy choice of --count measurements of a points file (a candidate pool, "
                                  "measured or simulated) maximising O1 = (prod s_i)^(1/m)/sqrt(n) of the "
                                  "identification Jacobian; compared with random choices of the same size.")
    q.add_argument("points", type=path_arg, help="candidate points CSV (docs/formats.md §3)")
    q.add_argument("artefacts", type=path_arg, nargs="?", default=None,
                   help="artefacts TOML (docs/formats.md §4); none for reference (tracker) points only")
    add_arm_options(q, "nominal arm: a shipped arm's name (aacmm7), a description TOML, or a URDF with --tip-frame "
                       "(docs/formats.md §2)")
    reference_points_option(q)
    marker_option(q)
    q.add_argument("--count", type=at_least(1), required=True, help="how many measurements to choose")
    add_output_option(q)
    _common_fit_options(q)
    q.set_defaults(func=run_poses)


def mpe_options(p) -> None:
    """``--mpe-<test>-um``: the maximum permissible error of each standard test (ISO 10360-12, ASME B89.4.22)."""
    from .validation import MPE_TESTS
    g = p.add_argument_group(
        "standard tests with a maximum permissible error (MPE)",
        "Each test of the validation (calibrated model, on the training data and on the held-out data; for "
        "close-loop: the final model on every point and the design fit on the outer test set) is "
        "plotted (conformance_*.png) with every tested item; given its MPE [um] (1e-6 to 1e5) it "
        "gets PASS (every item within the MPE) or FAIL in the console, summary.json and the report. Without "
        "these options: the plots and figures without pass/fail. Details: docs/calibration.md.")
    for t in MPE_TESTS:
        g.add_argument(t.option, type=MPE_UM, default=None, metavar="UM", dest=f"mpe_{t.key.replace('-', '_')}",
                       help=f"{t.standard} {t.name}: {t.what}")


def mpe_from_args(args) -> dict:
    """{test key: MPE [m]} of the given ``--mpe-*-um`` options."""
    from .validation import MPE_TESTS
    out = {}
    for t in MPE_TESTS:
        v = getattr(args, f"mpe_{t.key.replace('-', '_')}", None)
        if v is not None:
            out[t.key] = v * 1e-6
    return out


def weights_from_args(args):
    """The :class:`~calibration.data.Weights` of ``--sigma-*-um``; one not given is left to ``Weights``: its default
    (:data:`calibration.data.SIGMA_DEFAULT`), named in ``defaulted``."""
    from .data import Weights
    return Weights(*(None if v is None else v * 1e-6 for v in (args.sigma_probe_um, args.sigma_ref_um,
                                                                args.sigma_length_um)))


def fit_options(args, **fields):
    """The :class:`~calibration.options.FitOptions` of the fit options on the command line (``--min-resolution``,
    ``--plausible-length-mm``, ``--weights``, ``--prior-scale``, ``--rank-tol``), with ``fields`` set too."""
    from .options import FitOptions
    prior = getattr(args, "prior_scale", None)
    if args.min_resolution and prior is not None:
        raise InputError(f"--min-resolution holds weak parameters without a prior: give --prior-scale off with it "
                         f"(the prior, --prior-scale {prior}, shrinks them instead)")
    kw = {"min_resolution": args.min_resolution or None,
          "weights_from_data": getattr(args, "weights", "stated") == "data", "prior_scale": prior,
          "arm_scale": getattr(args, "arm_scale", "prior"), "prior_groups": getattr(args, "prior_groups", "separate")}
    if getattr(args, "plausible_length_mm", None) is not None:
        kw["prior_length"] = args.plausible_length_mm * 1e-3
    if args.rank_tol is not None:
        kw["rank_tol"] = args.rank_tol
    return FitOptions(**{**kw, **fields})


def free_names(model, args, data=None):
    """The names of the parameters to fit: ``--free`` (default :func:`~calibration.calibrate.default_free` of
    the model on ``data``) without ``--hold``."""
    from .calibrate import default_free, resolve_parameters
    free = resolve_parameters(model.spec, args.free or default_free(model, data))
    if args.hold:
        held = set(resolve_parameters(model.spec, args.hold))
        if not [i for i in free if i not in held]:
            chosen = f"--free {' '.join(args.free)}" if args.free else "the default free set"
            raise InputError(f"nothing is left to estimate: --hold {' '.join(args.hold)} holds every parameter of "
                             f"{chosen} ({len(free)}); a calibration with no free parameter would write the model "
                             "it started from as if calibrated. Hold fewer parameters (the nominal model as it is: "
                             "aacmm tip)")
        undone = next((p for p in args.free or () if set(resolve_parameters(model.spec, [p])) <= held), None)
        if undone is not None:      # `--free j1.a --hold j1.a`: one of the two does nothing
            raise InputError(f"--free {undone}: every parameter it names is held by --hold {' '.join(args.hold)}; "
                             "give a parameter to one of the two")
        free = [i for i in free if i not in held]
    return [model.spec.names[i] for i in free]


def model_effects(arm, keys):
    """The effects of a loaded ``--arm`` model followed by those of ``--effect`` (an effect kind the
    model already holds is an error: its parameters would be declared twice)."""
    from arm_model.model import ArmModel
    added = _effects(keys)
    twice = sorted({e.key for e in added} & {e.key for e in arm.effects})
    if twice:
        raise InputError(f"the arm model already holds the effect(s) {', '.join(twice)}; drop the --effect option "
                         "(the model's effects start from their values in the file)", arm.desc.source)
    try:
        return ArmModel(arm.desc, tuple(arm.effects) + added)
    except ValueError as exc:
        raise InputError(f"--effect: {exc}", arm.desc.source) from None


#: the ``--effect`` kinds the measured contact force alone drives (the probe's bending, the force sensor's errors)
FORCE_DRIVEN = ("probe_compliance", "probe_compliance_matrix", "force_sensor")
#: the ``--effect`` kinds a joint's load drives: the contact force's torque, or gravity's on the links' masses
LOAD_DRIVEN = ("joint_compliance", "lateral_compliance")


def _undriven_why(sets) -> tuple[list, str] | None:
    """(the files, what they lack) when none of the PointSets ``sets`` (None: a file not given) carries a measured
    contact force, else None."""
    from .candidates import has_force
    sets = [s for s in sets if s is not None]
    if any(has_force(s) for s in sets):
        return None
    names = list(dict.fromkeys(s.path for s in sets))
    return names, (f"{' and '.join(names)} {'hold' if len(names) > 1 else 'holds'} "
                   + ("no force columns (fx_N, fy_N, fz_N)" if all(s.force is None for s in sets)
                      else "no force (its columns zero on every row)"))


def refuse_undriven_effects(keys, desc, *sets, without_force: tuple[list, str] | None = None) -> None:
    """An InputError for an ``--effect`` of ``keys`` that nothing in the data drives, which the fit would hold at
    zero ("no effect on the data") as if estimated: a :data:`FORCE_DRIVEN` kind on points (``sets``: the PointSets
    of the command, None for a file not given) with no measured force (no force columns, or zero throughout), a
    :data:`LOAD_DRIVEN` kind there on an arm without masses (under gravity alone a robot's joints still bend: kept).
    ``without_force``: (the files, what they lack) when the data are known to hold no force before they exist (a
    simulated campaign without a force sensor), instead of ``sets``."""
    if "thermal" in (keys or ()):
        _refuse_constant_temperature(sets)
    asked = [k for k in keys or () if k in FORCE_DRIVEN + LOAD_DRIVEN]
    undriven = (without_force or _undriven_why(sets)) if asked else None
    if undriven is None:
        return
    names, held = undriven
    for k in asked:
        if k in FORCE_DRIVEN:
            raise InputError(f"--effect {k} is driven by the measured contact force, and {held}: nothing could "
                             "estimate it (the fit would hold it at zero); leave it out, or give the force the probe "
                             "measured", names[0], 1)
        if not any(j.mass > 0 for j in desc.joints):
            raise InputError(f"--effect {k} turns under a joint's load, the contact force's torque or gravity's on the "
                             f"links' masses, and {held} while the arm has no masses (no <inertial> in its URDF, no "
                             "mass_kg in its description): nothing could estimate it; leave it out, or give the link "
                             "masses (--masses) or the force", names[0], 1)


def _refuse_constant_temperature(sets) -> None:
    """An InputError for ``--effect thermal`` on points (``sets``: PointSets, None for a file not given) whose
    temperature spans less than :data:`calibration.candidates.MIN_TEMPERATURE_SPAN`, the range close-loop needs to
    offer it: the links' growth is then either no effect on the data (at 20 °C) or a constant scale the lengths
    already take, and the fit would write it 'fixed' at zero. Points without a temperature are refused where the
    effect's inputs are checked."""
    from .candidates import MIN_TEMPERATURE_SPAN
    sets = [s for s in sets if s is not None and s.temperature is not None]
    if not sets or not all(np.all(np.isfinite(s.temperature)) for s in sets):
        return
    t = np.concatenate([s.temperature for s in sets])
    span = float(np.ptp(t))
    if span < MIN_TEMPERATURE_SPAN:
        names = list(dict.fromkeys(s.path for s in sets))
        raise InputError(f"--effect thermal grows the links with the measured temperature, and the temperature of "
                         f"{' and '.join(names)} varies by {span:.3g} K only (at least {MIN_TEMPERATURE_SPAN:g} K "
                         "needed, as close-loop needs to offer it): nothing could estimate it (the fit would hold it "
                         "at zero); leave it out, or give points measured over a range of temperatures", names[0], 1,
                         "temperature_C")


def refuse_undriven_free(model, free, hold, *sets, without_force: tuple[list, str] | None = None) -> None:
    """An InputError for a ``--free`` pattern naming a parameter that the measured contact force alone drives (the
    probe's compliance ``probe.compliance_*``, the parameters of a :data:`FORCE_DRIVEN` effect of a model file) on
    points ``sets`` with no measured force, and not held by ``hold``: the fit would report it "fixed: no effect on the
    data" and write the model as if it had been estimated, as :func:`refuse_undriven_effects` refuses for
    ``--effect``. The default free set names no probe compliance (:func:`calibration.calibrate.default_free`).
    ``without_force``: as :func:`refuse_undriven_effects`."""
    from .calibrate import resolve_parameters
    undriven = (without_force or _undriven_why(sets)) if free else None
    if undriven is None:
        return
    names, held_by_data = undriven
    spec = model.spec
    driven = {i for i, n in enumerate(spec.names) if n.startswith("probe.compliance")}
    driven |= {i for e, sl in model.effect_slices() if e.key in FORCE_DRIVEN for i in range(sl.start, sl.stop)}
    held = set(resolve_parameters(spec, hold)) if hold else set()
    for pat in free:
        hit = [spec.names[i] for i in resolve_parameters(spec, [pat]) if i in driven and i not in held]
        if hit:
            it, one = ("it", "it") if len(hit) == 1 else ("them", "they")
            raise InputError(f"--free {pat} names {', '.join(hit)}, driven by the measured contact force alone, and "
                             f"{held_by_data}: nothing could estimate {it} (the fit would hold {it} as {one} "
                             f"{'is' if len(hit) == 1 else 'are'}, as if estimated); name the other parameters only, "
                             f"hold {it} with --hold, or give the force the probe measured", names[0], 1)


def _check_reference_options(args, data) -> None:
    """``--reference identity`` and ``--marker-offset`` are about the reference instrument's points: given on data
    that hold none (no reference columns in the points file, no ``--reference-points``), they would be silently
    ignored; an InputError instead."""
    ref = data.points.ref
    if ref is not None and np.isfinite(ref).any():
        return
    given = [f"--reference {args.reference}" if getattr(args, "reference", "fit") == "identity" else None,
             None if getattr(args, "marker_offset", None) is None else f"--marker-offset {args.marker_offset}"]
    given = [g for g in given if g]
    if given:
        verb = "concern" if len(given) > 1 else "concerns"
        raise InputError(f"{' and '.join(given)} {verb} the reference instrument's points (columns x_ref_mm, "
                         "y_ref_mm, z_ref_mm, or --reference-points), and the data hold none: leave "
                         f"{'them' if len(given) > 1 else 'it'} out, or give the reference points", args.points)


def _load_data(args, defaults: bool = False):
    """(model, data, the arm's values, warnings) of the command's inputs; with ``defaults`` (calibrate) and no
    ``--effect``, the model with :func:`calibration.calibrate.default_effects` added (said on the console)."""
    from .calibrate import default_effects
    from .data import make_data
    arm = model_from_args(args)
    desc = arm.desc
    model = model_effects(arm, args.effect)
    if defaults and args.effect is None:
        model = assume_masses(model, args)
        desc = model.desc
    points = read_points(args.points, desc.joint_quantities)
    artefacts = None if args.artefacts is None else read_artefacts(args.artefacts)
    reference = None if args.reference_points is None else read_points(args.reference_points, desc.joint_quantities)
    heldout = _heldout_points(args, desc)
    warnings = []
    for pts in (points, reference, heldout):
        if pts is not None:
            Arm(desc, model.effects).check_points(pts)
            warnings += point_warnings(desc, pts)
    log_warnings(warnings)          # at once: a fit that then fails (exit 4) has said what it saw in the inputs
    model = with_artefact_drift(_drift_about_the_session(model, points), points.measurements())
    data = make_data(points, artefacts, reference=reference, marker_offsets=args.marker_offset, heldout=heldout)
    _check_reference_options(args, data)
    refuse_undriven_effects(args.effect, desc, points, reference, heldout)
    refuse_undriven_free(model, args.free, args.hold, points, reference)
    added = default_effects(model, data) if defaults and args.effect is None else ()
    if added:
        from arm_model.model import ArmModel
        model = ArmModel(desc, tuple(model.effects) + added)
        log.info(f"effect {', '.join(e.describe() for e in added)} added: a robot whose links carry masses bends "
                 "under its own weight (each compliance's prior: non-negative, at most 10 mrad under its joint's RMS "
                 "gravity torque); --effect none for the geometry alone")
    return model, data.for_model(model), arm.values, warnings


def assume_masses(model, args):
    """``model``, or with its links' masses assumed from the chain's geometry
    (:func:`calibration.calibrate.with_assumed_masses`: a URDF without any ``<inertial>`` and no ``--masses``), said
    on the console; the default estimation then gives it a joint compliance under gravity as any robot."""
    from .calibrate import ASSUMED_DENSITY, with_assumed_masses
    assumed = None if getattr(args, "masses", None) is not None else with_assumed_masses(model)
    if assumed is None:
        return model
    tool = " but the tool's" if model.desc.joints[-1].mass > 0 else ""
    log.info(f"{model.desc.source or 'the URDF'} gives no link masses{tool}: each link taken as a uniform rod of "
             f"{ASSUMED_DENSITY:g} kg/m from its joint to the next (the last to the tip), for the gravity torques of "
             "the joint compliance; its compliances are per N m of these torques (--masses FILE to give the "
             "masses, --effect none for the geometry alone)")
    return assumed


def with_artefact_drift(model, measurements):
    """``model`` with a drift of the artefact asked by ``--effect artefact_drift`` (no measurements named) given one
    displacement per measurement of ``measurements`` (:class:`~arm_model.effects.ArtefactDrift`), put after the
    other effects (its shift is along the base axes at the joint angles they leave)."""
    from arm_model.effects import ArtefactDrift
    from arm_model.model import ArmModel
    drifts = [e for e in model.effects if isinstance(e, ArtefactDrift) and not e.measurements]
    if not drifts:
        return model
    rest = tuple(e for e in model.effects if not isinstance(e, ArtefactDrift) or e.measurements)
    return ArmModel(model.desc, rest + (ArtefactDrift(measurements=tuple(measurements)),))


def _drift_about_the_session(model, points):
    """A drift asked by ``--effect thermal_drift`` (its time origin 0) taken about the middle of the points' time
    span, as the loop's candidate is (:meth:`ThermalDrift.reference_of`): the geometry fitted is the session's
    middle, not the clock's zero."""
    import dataclasses

    from arm_model.effects import ThermalDrift
    from arm_model.model import ArmModel
    if points.time is None or not len(points.time) or not any(
            isinstance(e, ThermalDrift) and e.reference_time_s == 0.0 for e in model.effects):
        return model
    t_ref = ThermalDrift.reference_of(points.time)
    return ArmModel(model.desc, tuple(dataclasses.replace(e, reference_time_s=t_ref)
                                      if isinstance(e, ThermalDrift) and e.reference_time_s == 0.0 else e
                                      for e in model.effects))


def _heldout_points(args, desc):
    """The ``--holdout-points`` file read (None without it); refused beside ``--holdout`` or as the points file."""
    path = getattr(args, "holdout_points", None)
    if path is None:
        return None
    if args.holdout is not None:
        raise InputError("--holdout-points and --holdout both choose the held-out data: give one of them")
    if args.holdout_by == "measurement":
        raise InputError("--holdout-points predicts each held-out pose against its feature fitted on the training "
                         "points (as --holdout-by pose), not whole measurements: leave --holdout-by out")
    if resolved(path) == resolved(args.points):
        raise InputError("--holdout-points names the points file itself: the held-out poses are a file of their own",
                         path)
    return read_points(path, desc.joint_quantities)


def _split(args, data):
    """(training data, held-out data or None, held-out pose mask over ``data`` or None) of ``--holdout``:
    whole measurements (``--holdout-by measurement``) or a share of every feature's poses (``pose``); of
    ``--holdout-points``: that file's rows, each predicted against its feature fitted on the training rows."""
    from .data import heldout_mask, split_holdout, split_poses
    if getattr(args, "holdout_points", None) is not None:
        mask = heldout_mask(data, str(args.holdout_points))
        return data.select(~mask), None, mask
    holdout = parse_holdout(args.holdout)
    if holdout is None:
        if args.holdout_by == "pose":
            raise InputError("--holdout-by pose needs --holdout FRACTION (the share of every feature's poses)")
        return data, None, None
    if args.holdout_by in (None, "measurement"):
        train, test = split_holdout(data, holdout, args.seed)
        return train, test, None
    if not isinstance(holdout, float):
        raise InputError(f"--holdout-by pose takes a fraction of every feature's poses, not measurement ids "
                         f"(got {args.holdout!r})")
    mask = split_poses(data, holdout, args.seed)
    if not mask.any():
        raise InputError(f"--holdout {args.holdout} --holdout-by pose holds out no pose: every feature has too few "
                         "poses to spare one (a feature keeps the fewest its fit needs, plus one)")
    return data.select(~mask), None, mask

def _covariance_options(c) -> None:
    """The parameters' covariance: its scale, and the region effect the covariance file adds to it."""
    c.add_argument("--covariance-scale", "--covariance", dest="covariance", choices=("residual", "stated"),
                   default="residual",
                   help="scale the parameters' covariance by the residual variance factor s0^2 (default) or trust "
                        "the stated uncertainties (s0 = 1); --covariance is the older spelling (aacmm tip's "
                        "--covariance is another option: it writes each point's covariance)")
    region_option(c)


def region_option(p) -> None:
    """``--region-effect``: the parameters' random effect between regions of the joint space in the covariance file
    (``calibrate`` and ``close-loop``: :mod:`calibration.region`)."""
    p.add_argument("--region-effect", action="store_true",
                   help="also estimate how much the parameters shift between regions of the joint space (the "
                        "training poses cut into 2-4 regions, each predicted by the fit without it; kept only when a "
                        "Monte Carlo test at 5%% finds it) and add it to the covariance file, so aacmm tip's u of a "
                        "pose the fit never saw carries it; parameters.csv and the report keep the posterior's u "
                        "(summary.json: region_effect). Off by default (docs/uncertainty.md)")


def _outlier_options(c) -> None:
    """The outliers' options: reported beyond ``--outlier-threshold``; dropped, kept, or the gross ones left out."""
    c.add_argument("--outlier-threshold", type=THRESHOLD_SIGMA, default=4.0,
                   help="standardized residual beyond which a point is reported as an outlier (default 4)")
    which = c.add_mutually_exclusive_group()        # the outliers: dropped, kept, or the gross ones left out
    which.add_argument("--drop-outliers", action="store_true", help="drop every point and certified length whose "
                       "gross-error test reaches --outlier-threshold and refit, in rounds (listed); default: leave out "
                       "the gross errors (--gross-threshold), keep the others")
    c.add_argument("--gross-threshold", type=THRESHOLD_SIGMA, default=None,
                   help=f"standardized residual from which a point (its rows' deletion residual together, at the "
                        f"row-by-row false-alarm rate) is a gross error: left out and the fit redone, one at a time, "
                        f"at most 5%% of the points, and listed (default {GROSS_THRESHOLD:g})")
    which.add_argument("--keep-outliers", action="store_true",
                       help="keep every point in the fit, gross errors too (they are reported)")


def gross_threshold(args: argparse.Namespace) -> float | None:
    """``--gross-threshold`` (default :data:`GROSS_THRESHOLD`), or None with ``--keep-outliers``; given beside
    ``--keep-outliers`` or ``--drop-outliers``, which leave no point to it, it is an InputError."""
    if args.gross_threshold is not None and (args.keep_outliers or args.drop_outliers):
        other = "--keep-outliers keeps every point" if args.keep_outliers else "--drop-outliers drops every outlier"
        raise InputError(f"--gross-threshold {args.gross_threshold:g} leaves out the gross errors, but {other}: give "
                         "one of them")
    if args.keep_outliers:
        return None
    return GROSS_THRESHOLD if args.gross_threshold is None else args.gross_threshold


def _points_and_rows(data, noun: str = "point") -> str:
    """``"40 points"``, or ``"40 points (43 rows)"`` when some rows repeat a reading (counted once by the fit:
    :meth:`calibration.data.CalibrationData.counts`); ``noun``: what a point is called ("training point")."""
    n = data.counts()
    rows = "" if n["n_rows"] == n["n_points"] else f" ({counted(n['n_rows'], 'row')})"
    return counted(n["n_points"], noun) + rows


def run_calibrate(args: argparse.Namespace) -> int:
    from .calibrate import calibrate, nominal_baseline
    from .model_output import refine_torques, with_fitted_torques
    from .report import write_outputs
    from .validation import worse_than_nominal
    inputs = [args.points, args.artefacts, *arm_inputs(args), args.reference_points, args.holdout_points]
    with output_folder(args.output, inputs, "calibrate") as out:
        model, data, values, warnings = _load_data(args, defaults=True)
        if any(e.key == "joint_compliance" for e in model.effects):
            from .candidates import no_torque_reason
            why = no_torque_reason(model.desc, data)
            if why:
                log.warning(f"joint compliance cannot be identified: {why}")
        train, test, poses = _split(args, data)
        options = fit_options(args, free=free_names(model, args, data), values=values, weights=weights_from_args(args),
                              on_unidentifiable=args.on_unidentifiable, outlier_threshold=args.outlier_threshold,
                              drop_outliers=args.drop_outliers, covariance=args.covariance, reference=args.reference,
                              gross_threshold=gross_threshold(args), region_effect=args.region_effect)
        say = progress_line(log)            # a long fit (10^5 points: minutes) says where it is
        say(f"fitting the model to {_points_and_rows(train)} (with the noise, the prior and the model discrepancy from "
            "the data)")
        res = refine_torques(calibrate(model, train, options))
        say("the nominal baseline and the validation figures")
        base = nominal_baseline(model, res.data, replace(res.options, weights=res.weights))
        # the held-out rows' torques on the calibrated description, as the model file (tip) evaluates them
        test, data = with_fitted_torques(test, res), with_fitted_torques(data, res)
        held = (None if test is None and poses is None else
                (res, test, base) if poses is None else (res, data, base, ~poses))
        val_train, val_test, conf = conformance_entry(mpe_from_args(args), (res, res.data, base), held)
        worse = worse_than_nominal(val_test or [])
        say("writing the model file and the report")
        files = write_outputs(res, out.dir, inputs=inputs, validation_training=val_train,
                              validation_holdout=val_test, plots=not args.no_plots,
                              extra={"inputs": {"points": str(args.points),
                                                "artefacts": None if args.artefacts is None else str(args.artefacts),
                                                "arm": str(args.arm),
                                                "reference_points": None if args.reference_points is None
                                                else str(args.reference_points),
                                                "holdout_points": None if args.holdout_points is None
                                                else str(args.holdout_points)},
                                     "holdout": (None if test is None else test.measurements()),
                                     "holdout_by": ("pose" if args.holdout_points is not None
                                                   else args.holdout_by or "measurement"),
                                     "holdout_poses": (None if poses is None
                                                       else [int(i) for i in np.flatnonzero(poses)]),
                                     "nominal_baseline": _baseline_entry(base),
                                     "heldout_worse_than_nominal": worse,
                                     "conformance": conf,
                                     "warnings": [w.as_dict() for w in warnings]})
    files = {k: out.published(v) for k, v in files.items()}
    _log_calibration(res, data, train, test, poses, (val_train, val_test, conf, worse), files)
    return 0


#: a standardized residual this large is no noise but a wrong reading (the console says how to refit without it)
GROSS_STANDARDIZED = 8.0

NOMINAL_NOTE = ("nominal = the description with only the tip offset (probe or marker) fitted, the artefacts' "
                "unknowns and the reference frame solved as for the calibrated model")


def _baseline_entry(base) -> dict:
    """summary.json's ``nominal_baseline``: what the nominal of every figure is, and its fitted tip offset."""
    return {"definition": NOMINAL_NOTE, "fitted": list(base.free),
            "values_mm": {n: base.value(n) * 1e3 for n in base.free}, "s0": base.s0,
            "tracker": None if base.tracker is None else base.tracker.to_dict()}


def sessions_without_frame(res, test) -> list[str]:
    """The sessions of the held-out data ``test`` (reference rows) that the fit ``res`` has no frame for."""
    if test is None or res.tracker is None or test.reference is None:
        return []
    rows = np.all(np.isfinite(test.reference), axis=1)
    return [s for s in dict.fromkeys(test.sessions[rows].astype(str).tolist()) if res.tracker.frame(s) is None]


#: fixed parameters listed one a line on the console (all of them with -v, and always in summary.json); a humanoid
#: touching one plane holds about 90 of its 105 candidates, each with a combination of a dozen terms
MAX_FIXED_LINES = 12


def _log_fixed(fixed) -> None:
    """The fixed parameters, one a line: those at a bound first (what the data wanted), then the rank's, at most
    :data:`MAX_FIXED_LINES` in all unless verbose; the rest counted, pointing to where they are listed."""
    order = sorted(fixed, key=lambda f: "bound" not in f.reason)
    shown = order if log.isEnabledFor(logging.DEBUG) else order[:MAX_FIXED_LINES]
    for f in shown:
        log.info(f"  fixed {f.name}: {f.reason}")
    if len(order) > len(shown):
        log.info(f"  ... and {len(order) - len(shown)} more fixed parameters, each with the combination the data "
                 "cannot see: summary.json 'fixed', parameters.csv (-v lists them here)")


def _log_calibration(res, data, train, test, poses, validation, files) -> None:
    """The console report of ``aacmm calibrate``."""
    from .report import poorly_determined
    from .validation import ratio_text, with_u
    val_train, val_test, conf, worse = validation
    held = ("" if test is None and poses is None else
            f", {counted(len(test), 'held-out point')} in {counted(len(test.measurements()), 'measurement')}"
            if poses is None else f", {counted(int(poses.sum()), 'held-out pose')} ("
            + ("the --holdout-points file's" if np.any(data.files[poses] != data.files[~poses][0]) and
               np.all(data.files[poses] == data.files[poses][0]) and data.files[poses][0] != data.points.path
               else "a share of every feature's") + ")")
    log.info(f"{_points_and_rows(train, 'training point')} in {counted(len(train.measurements()), 'measurement')}"
             + held)
    if data.points.force_kind == "two-channel":
        log.info("two-channel force sensor: the probe-y force is not measured and is taken as zero")
    for line in noise_lines(res):
        log.info(line)
    log.info(f"solver: {res.status} after {res.iterations} iterations; s0 = {res.s0:.3f}; "
             f"{len(res.free)} parameters free, {res.n_nuisance} nuisance unknowns, "
             + (f"dof {res.dof}" if res.redundancy is None else
                f"redundancy {res.redundancy:.3g} of {res.n_residuals} rows (the prior included)"))
    idf = res.identifiability_final
    log.info(f"identifiability: rank {idf.rank}/{len(idf.names)} at the solution, condition number {idf.condition:.3g}")
    _log_fixed(res.fixed)
    for text in poorly_determined(res):
        log.info(f"  poorly determined: {text}")
    for g in res.gross:
        o = g.outlier
        where = " ".join(x for x in (o.measurement, f"length {o.feature}" if o.point is None else o.feature,
                                     None if o.line is None else f"line {o.line}") if x)
        log.warning(f"gross error left out of the fit: {where}: standardized "
                    f"{o.standardized:+.1f} (from {g.threshold:g}), {g.residual * 1e3:.3f} mm from the fit without "
                    "it; --keep-outliers keeps it")
    if res.gross_kept:
        log.warning(f"gross-looking point kept: {res.gross_kept}")
    if res.dropped:
        log.info(f"{len(res.dropped)} outlier(s) dropped and refitted (the gross-error test at --outlier-threshold):")
        for o in res.dropped[:10]:
            log.info(f"  {o.measurement} {o.feature} {'length' if o.point is None else f'line {o.line}'}: "
                     f"standardized {o.standardized:+.1f}")
    if res.outliers:
        log.info(f"{len(res.outliers)} outlier(s) ({'flagged row by row, kept' if res.dropped else 'kept'}):")
        for o in res.outliers[:10]:
            log.info(f"  {o.measurement} {o.feature} line {o.line}: standardized {o.standardized:+.1f}")
        gross = [o for o in res.outliers if abs(o.standardized) >= GROSS_STANDARDIZED]
        if gross and not res.dropped and res.options is not None and res.options.gross_threshold is None:
            log.warning(f"{len(gross)} outlier(s) at {GROSS_STANDARDIZED:g} standard deviations or more: a wrong "
                        "reading (a swapped marker, a slipped ball) pulls every parameter towards it; "
                        "--drop-outliers refits without them")
    if res.redundancy is not None and res.redundancy < 1.0:
        log.warning(f"the fit passes through its training points (redundancy {res.redundancy:.2g} rows, the prior "
                    "included: more parameters than the data have dimensions): its training figures say nothing of "
                    "its accuracy; judge it on held-out data (--holdout, --holdout-points) and by the model "
                    "discrepancy")
    for title, rows in (("training", val_train), ("held-out", val_test)):
        if rows:
            log.info(f"validation on {title} data (nominal -> calibrated; {NOMINAL_NOTE}; ± standard uncertainty, "
                     "bootstrap over its measurements):")
            for r in rows:
                log.info(f"  {r['label']}: {with_u(r['before'], r['u_before'])} -> {with_u(r['after'], r['u_after'])} "
                         f"{r['unit']} ({ratio_text(r['ratio'])})")
    new = sessions_without_frame(res, test)
    if new:
        log.info(f"note: held-out session(s) {', '.join(repr(s) for s in new)} have no frame from the training data: "
                 "'frames and markers of the training fit' fits their frame on the held-out points themselves (the "
                 "model and the markers' offsets as trained; another placement of the instrument is always "
                 "registered anew), and the model file holds the frames of the training sessions only")
    if worse:
        log.warning("on the held-out data the calibrated model is WORSE than the nominal: "
                    + "; ".join(f"{r['label']} {r['before']:.4g} -> {r['after']:.4g} {r['unit']}" for r in worse))
    log_conformance(conf)
    budget = res.probing_budget()
    if budget is not None:
        log.info(f"probing scatter per axis: {budget['gross'] * 1e6:.4g} um in the residuals, of which encoders "
                 f"{budget['encoders'] * 1e6:.3g} um and force sensor {budget['force sensor'] * 1e6:.3g} um "
                 f"(propagated, default inputs) -> {budget['net'] * 1e6:.4g} um of the contact itself (tip's default)")
        if budget["floored"]:
            log.warning("the propagated encoder and force-sensor noise alone exceed the residual scatter: the probing "
                        "scatter is set to 0 (their stated uncertainties are larger than this campaign shows)")
    if res.discrepancy is not None:
        d = res.discrepancy
        log.info(f"model discrepancy per axis: {d.sigma * 1e6:.4g} um (poses at the ends of each joint's range held "
                 f"out in turn: their errors {d.ratio:.2f} x what the fit predicts)")
        if d.growth is not None and d.written_growth is None:
            log.info("  not growing away from the training poses (the fitted growth is floored at 0): written as a "
                     "constant")
        elif d.growth is not None:
            g = d.growth
            log.info(f"  growing away from the training poses: {g.sigma0 * 1e6:.4g} +- {g.u_sigma0 * 1e6:.2g} um at "
                     f"them + {g.growth * 1e3:.4g} +- {g.u_growth * 1e3:.2g} um per mm of ball travel from the nearest "
                     f"(measured up to {g.d_max * 1e3:.4g} mm; likelihood ratio over a constant {g.lr:.3g})")
        if d.written_growth is not None:
            s0, gj = d.written
            log.info(f"  per joint, with their uncertainty carried: {s0 * 1e6:.4g} um at the training poses + "
                     f"{growth_text(gj)} um per mm of each joint's ball travel from the nearest; tip adds it to "
                     "every point's u")
    if res.region is not None:
        log.info(f"region effect: {res.region.summary()}")
    log.info(f"model file -> {files['description']} (covariance {files['covariance'].name}); report -> "
             f"{files['report']}")


def conformance_entry(mpe: dict, training: tuple, holdout: tuple | None = None, sets: str = "") -> tuple:
    """The standard tests of ``calibrate`` and ``close-loop`` (one implementation): ``training`` and
    ``holdout`` each ``(result, data)`` or ``(result, data, baseline[, train_mask])`` (:func:`_validation`), the
    fit whose calibrated model is tested, the data it is tested on (``holdout`` None: none) and the nominal
    baseline it is compared with. Returns (validation rows on training, on holdout or None, the summary's
    ``conformance`` entry: ``mpe_given``, ``mpe_um``, ``note`` (``sets`` appended: what the two data sets
    are), ``training``, ``holdout``)."""
    val_train, conf_train = _validation(*training, mpe=mpe)  # type: ignore[misc]
    val_test, conf_test = _validation(*holdout, mpe=mpe) if holdout is not None else (None, None)  # type: ignore[misc]
    conf = {"mpe_given": bool(mpe), "mpe_um": {k: v * 1e6 for k, v in mpe.items()},
            "note": ("PASS: every tested item of the calibrated model within the MPE given by its "
                     "--mpe-*-um option; FAIL: at least one beyond." if mpe else
                     "No --mpe-*-um option given: the standard tests' figures, no pass/fail.")
                    + " Items: every certified length, sphere and seat of the data set (docs/calibration.md)."
                    + (f" {sets}" if sets else ""),
            "training": conf_train, "holdout": conf_test}
    return val_train, val_test, conf


def log_conformance(conf: dict) -> None:
    """The standard tests of :func:`conformance_entry` on the console."""
    from .report import conformance_lines
    if conf["training"] or conf["holdout"]:
        log.info("standard tests, calibrated model (ASME B89.4.22 / ISO 10360-12):")
        for line in conformance_lines(conf):
            log.info(line)


def _validation(res, data, base=None, train_mask=None, mpe=None):
    """The before/after figure rows and the standard tests (:func:`calibration.validation.conformance`) of
    the calibrated model on ``data``. Before: ``base`` (a :func:`calibration.calibrate.nominal_baseline` fit)
    or, without one, the nominal description (p = 0). The reference points are also predicted with each fit's
    own frames and marker offsets when ``data`` is not the fit's (the nominal's, without a baseline: fitted on
    the training data, :func:`calibration.tracking.fit_tracker`). ``train_mask``: only the poses outside it
    are held out, each against its feature fitted on the poses inside
    (:func:`calibration.validation.validate_poses`; no standard tests)."""
    from .tracking import fit_tracker
    from .validation import conformance, figure_rows, validate, validate_poses
    m, w, mode = res.model, res.weights, res.reference_mode
    p0 = np.zeros(m.spec.size) if base is None else base.p
    if train_mask is not None:
        return figure_rows(validate_poses(m, p0, data, train_mask, w, mode),
                           validate_poses(m, res.p, data, train_mask, w, mode)), None
    own = data is res.data

    def tracker(fit):
        if own or res.tracker is None:
            return None
        return fit_tracker(m, p0, res.data, w, mode) if fit is None else fit.tracker
    before = validate(m, p0, data, w, mode, tracker=tracker(base))
    after = validate(m, res.p, data, w, mode, tracker=tracker(res))
    return figure_rows(before, after), conformance(after, mpe, before)


def prior_lines(res) -> list[str]:
    """Console lines: the prior's scale of each group (chosen by the evidence or given) and the parameters the
    prior dominates."""
    if res.prior_scales is None:
        return []
    from .calibrate import display_unit
    evidence = bool(res.evidence)
    out = ["prior: each free parameter ~ N(nominal, (its group's scale x its plausible size)^2)"
           + (f", the scales chosen by the evidence ({len(res.evidence)} rounds"
              + ("" if res.evidence[-1].get("settled", True) else "; " + res.evidence[-1]["note"]) + ")"
              if evidence else " (scales given)") + ":"]
    if res.pooled_groups():
        out.append(f"  one scale for {', '.join(res.pooled_groups())} (--prior-groups pooled)")
    for g, v in res.prior_groups.items():
        physical = (" (a physical prior: not chosen by the evidence)" if v.get("physical") else
                    " (a physical maximum: the evidence may shrink it, never above 1)" if v.get("capped") else "")
        out.append(f"  {g}: scale {v['scale']:.3g}{physical}; the data determine {v['effective_parameters']:.1f} of "
                   f"its {len(v['parameters'])} parameters")
    dominated = [r for r in res.parameter_rows() if r["state"] == "prior-dominated"]
    if dominated:
        out.append(f"prior-dominated ({len(dominated)}: the data add less than the prior; they stay near the nominal "
                   "with about the prior's uncertainty, which the covariance carries):")
        for r in dominated:
            du, _ = display_unit(r["unit"])
            why = res.prior_only.get(r["name"])
            out.append(f"  {r['name']}: {r['display_value']:.4g} ± {r['display_u']:.3g} {du} (prior ± "
                       f"{r['display_prior_u']:.3g}, posterior/prior variance {r['prior_ratio']:.2f})"
                       + ("" if why is None else f"; prior only: {why}"))
    return out


def noise_lines(res) -> list[str]:
    """Console lines: the noise of each row group, estimated from the fit, and the weights used."""
    out = []
    if res.weights_history:
        out.append(f"noise from the data (variance components, {len(res.weights_history)} fit(s)):")
        if not res.weights_history[-1].get("settled", True):
            out.append("  warning: " + res.weights_history[-1]["note"])
    for v in res.variance:
        what = f"{v['group']} points" if v["group"] != "length" else "lengths"
        used = res.weights.factor(v["group"])
        if v["group"] == "length":
            size = f"x{used:.3g} the certified/stated uncertainties"
        else:
            start = f"{v['sigma_um'] / used:.3g} um"
            said = f"stated {start}" if res.weights.stated_sigma_of(v["group"]) else f"default {start}, not stated"
            size = f"{v['sigma_um']:.3g} um per axis ({said})"
        if v.get("no_scatter"):
            out.append(f"  {what}: {size}; not estimated: the residuals show no scatter (below 1e-6 um: the same "
                       f"poses repeated?)")
        elif not v["estimated"]:
            out.append(f"  {what}: {size}; not estimated (redundancy {v['redundancy']:.2g} of {v['rows']} rows, "
                       f"too little)")
        elif res.weights_history:
            out.append(f"  {what}: {size}; redundancy {v['redundancy']:.1f} of {v['rows']} rows"
                       + ("; estimated from few redundant rows because the stated uncertainty is refuted by the "
                          "residuals (chi-square beyond 1e-6)" if v.get("stated_refuted") else ""))
        else:
            out.append(f"  {what}: residual/stated ratio {v['factor']:.3g} (redundancy {v['redundancy']:.1f} of "
                       f"{v['rows']} rows); --weights data would use it")
    return out + prior_lines(res)


def run_montecarlo(args: argparse.Namespace) -> int:
    from arm_model.sim import load_campaign

    from .study import RunSettings, SimSource, monte_carlo
    camp = load_campaign(args.campaign)            # checks the file before any run starts
    if args.scheduler is not None and args.workers is not None:
        raise InputError("--workers counts local processes, and --scheduler sends the runs to a Dask cluster's "
                         "workers instead: give one of them")
    with output_folder(args.output, camp.inputs, "study montecarlo") as out:
        from arm_model.model import ArmModel
        model = ArmModel(camp.arm, _effects(args.effect))
        if camp.sensor == "none":       # simulated points without force columns: as calibrate refuses them
            why = ([str(args.campaign)], f"{args.campaign} simulates no force sensor (sensor = \"none\": its points "
                                         "hold no force columns)")
            refuse_undriven_effects(args.effect, camp.arm, without_force=why)
            refuse_undriven_free(model, args.free, args.hold, without_force=why)
        settings = RunSettings(holdout=args.holdout, effects=_effects(args.effect),
                               fit=fit_options(args, free=free_names(model, args), weights=weights_from_args(args)))
        mc = monte_carlo(SimSource(camp), args.runs, seed=args.seed, settings=settings,
                         scheduler=args.scheduler, workers=args.workers)
        mc.check()
        from arm_model.shipped import provenance
        (out.dir / "study.json").write_text(json_text({**mc.to_dict(), **provenance(camp.inputs)}), encoding="utf-8")
    log.info(f"{args.runs - len(mc.failures)} of {counted(args.runs, 'run')} succeeded")
    for f in mc.failures[:5]:
        log.info(f"  seed {f['seed']}: {f['error']}")
    log.info("predicted accuracy on held-out data (median / 95th percentile):" if args.holdout else
             "no predicted accuracy: --holdout 0 holds no data out")
    for a in mc.accuracy.values():
        log.info(f"  {a['label']}: nominal {a['before_median']:.2f}/{a['before_p95']:.2f} -> calibrated "
              f"{a['after_median']:.2f}/{a['after_p95']:.2f} {a['unit']}")
    from .calibrate import display_unit
    if mc.s0:
        s0 = np.array(mc.s0)
        log.info(f"residual scale factor s0 over the runs: median {np.median(s0):.2f} (range "
                 f"{s0.min():.2f}-{s0.max():.2f})"
              + ("; far from 1: the stated --sigma-* do not match the residuals, and one factor cannot rescale "
                 "residual groups that are mis-stated differently (docs/uncertainty.md)"
                 if abs(np.median(s0) - 1) > 0.2 else ""))
    lo, hi = next(iter(mc.parameters.values()))["z_rms_95"] if mc.parameters else (0.0, 0.0)
    log.info(f"parameters: RMS error vs truth, mean reported u, within 3u, z = error / u: RMS (right uncertainties "
          f"give {lo:.2f}-{hi:.2f} for {len(mc.s0)} runs, 95 %) and mean (bias), verdict:")
    for n, v in mc.parameters.items():
        du, fac = display_unit(model.spec.units[model.spec.index(n)])
        log.info(f"  {n:22s} {v['rms_error'] * fac:10.4g} {v['mean_u'] * fac:10.4g} {du:5s} "
                 f"{100 * v['within_3u']:5.0f} %"
              f" {v['z_rms']:6.2f} {v['z_mean']:+6.2f}  {v['verdict']}")
    log.info(f"-> {args.output / 'study.json'}")
    return 0 if not mc.failures else 1


def run_poses(args: argparse.Namespace) -> int:
    from .study import select_measurements
    inputs = [args.points, args.artefacts, *arm_inputs(args), args.reference_points]
    with output_folder(args.output, inputs, "study poses") as out:
        model, data, _, warnings = _load_data(args)
        n = len(data.measurements())
        if args.count > n:
            raise InputError(f"--count {args.count}: the points file has {n} measurement(s)", args.points)
        # the choice is made at the nominal, before any fit
        fit = fit_options(args, free=free_names(model, args, data), weights=weights_from_args(args),
                          weights_from_data=False)
        sel = select_measurements(model, data, args.count, fit)
        from arm_model.shipped import provenance
        (out.dir / "poses.json").write_text(json_text({**sel.to_dict(), **provenance(inputs)}), encoding="utf-8")
    log.info(f"{len(sel.parameters)} identifiable parameters; chosen measurements (O1, random sets' O1):")
    for m, o, r, n in zip(sel.chosen, sel.o1, sel.o1_random, sel.n_points, strict=True):
        log.info(f"  {m:20s} O1 {o:10.4g}   random {r:10.4g}   ({counted(n, 'point')})")
    log.info(f"-> {args.output / 'poses.json'}")
    return 0
