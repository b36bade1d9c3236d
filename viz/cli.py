"""``aacmm view``: the arm at a captured point (or animated through a measurement) in a headless
meshcat server, or written as a self-contained page / a screenshot."""
from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import tempfile
import time
from pathlib import Path

import numpy as np

from arm_model import InputError, NumericalError, check_features, read_artefacts, read_points
from arm_model.checks import log_warnings, point_warnings
from arm_model.cli import command_help
from arm_model.cli_options import (
    add_arm_options,
    arm_inputs,
    duration_s,
    file_output_path,
    model_from_args,
    number_in,
    path_arg,
    port,
    positive,
)
from arm_model.errors import resolved
from arm_model.output import output_file
from arm_model.uncertainty_cli import INPUT_OPTIONS, add_input_options, refuse_unused

from .errors import ViewerError
from .placement import place_features
from .residuals import read_residuals, residual_origins

__all__ = ["register", "run"]

log = logging.getLogger(__name__)

#: argparse type of a drawing scale: a finite number in [0.001, 1e9]
SCALE = number_in(1e-3, 1e9)      # (a scale of 1e-320 drew every arrow 0 long, without a word)
#: points an animation shows a second: one every 1000 s to 10000 a second (the page's clip keeps each frame's time
#: in a 32-bit float: 1e-300 a second put every frame at infinity, a page that never moved)
POINTS_PER_S = number_in(1e-3, 1e4)


def register(sub) -> None:
    p = sub.add_parser(
        "view", help=command_help("view"),
        description="Show the arm at a captured point of a points file (or animated through the points) in a "
                    "meshcat server on 127.0.0.1 with no display, and print its URL; or write the same scene as "
                    "one self-contained HTML page (--html) or a PNG screenshot (--screenshot, headless Chromium). "
                    "The scene: the arm (URDF visuals) with the probe deflected by the measured force, the probe "
                    "ball, the deflection as a green arrow from the rigid to the corrected ball centre drawn "
                    "--scale times long, the measured ball centres, artefacts placed by fitting their points "
                    "(--artefacts) and residual vectors (--residuals). The scales are printed and written on "
                    "the page. The server stops at Ctrl-C, at SIGTERM, or after --open-s.")
    p.add_argument("points", type=path_arg, help="points CSV (docs/formats.md §3)")
    add_arm_options(p)
    p.add_argument("--measurement", metavar="ID", help="show only the points of this measurement id (default: all)")
    pose = p.add_mutually_exclusive_group()
    pose.add_argument("--point", type=positive(int), default=1, metavar="N",
                      help="show the arm at the N-th point of the selection, file order (default 1)")
    pose.add_argument("--animate", action="store_true",
                      help="animate the arm through every point of the selection (embedded in --html pages)")
    p.add_argument("--points-per-s", "--fps", dest="fps", type=POINTS_PER_S, default=None, metavar="F",
                   help="when animating: points shown a second, 0.001 to 10000 (default 2; --fps is the older "
                        "spelling; it is not the live view's display rate)")
    p.add_argument("--scale", type=SCALE, default=None,
                   help="length of the deflection arrow per length of deflection (e.g. 1000: 0.1 mm is drawn "
                        "100 mm long); default: from the data, so that the median deflection shown is drawn "
                        f"about {ARROW_TARGET_M * 1e3:g} mm long, well outside the 24 mm ball marker "
                        "(a 1-2-5 number, printed)")
    p.add_argument("--artefacts", type=path_arg, help="artefacts TOML (docs/formats.md §4): draw each feature, placed "
                   "by fitting its points in each measurement")
    p.add_argument("--residuals", type=path_arg, help="residuals CSV: x_mm, y_mm, z_mm, rx_um, ry_um, rz_um, or the "
                   "residuals.csv of aacmm calibrate (line, dx_um, dy_um, dz_um; see docs/viewer.md): draw "
                   "each residual vector")
    p.add_argument("--residual-scale", type=SCALE, default=None,
                   help="length of a residual line (and of the line from a tracker's marker to where the "
                        "instrument saw it) per length of residual; default: from the data, so that the median "
                        f"one is drawn about {ARROW_TARGET_M * 1e3:g} mm long (a 1-2-5 number, printed)")
    p.add_argument("--ellipsoids", action="store_true",
                   help="draw the 95 %% uncertainty ellipsoid of every corrected ball centre of the selection, from "
                        "the model's parameter covariance (a model file from calibrate; a plain description: "
                        "parameters exact) and the input uncertainties below (docs/uncertainty.md)")
    p.add_argument("--ellipsoid-scale", type=SCALE, default=None, metavar="S",
                   help="drawn size of an ellipsoid per true size; default: from the data, so that the median "
                        f"largest semi-axis is drawn about {ELLIPSOID_TARGET_M * 1e3:g} mm (a 1-2-5 number, printed)")
    add_input_options(p)
    p.add_argument("--html", type=file_output_path, metavar="OUT.html", help="write the scene as a self-contained page")
    p.add_argument("--screenshot", type=file_output_path, metavar="OUT.png",
                   help="render the page in headless Chromium and write a PNG (800 x 600)")
    p.add_argument("--browser", metavar="PATH", help="Chromium executable for --screenshot (default: chromium "
                   "on PATH)")
    p.add_argument("--serve", action="store_true",
                   help="keep serving after writing --html/--screenshot (serving is the default without them, "
                        "and with --open-s)")
    p.add_argument("--port", type=port, help="web port of the viewer (default: the first free one from 7000)")
    p.add_argument("--open-s", "--open-seconds", dest="open_seconds", type=duration_s(zero=False),
                   metavar="S", help="stop the server after S seconds (default: run until Ctrl-C; --open-seconds is "
                                     "the older spelling)")
    p.set_defaults(func=run)


def _selection(points, measurement: str | None):
    if measurement is None:
        return points
    mask = points.measurement == measurement
    if not mask.any():
        known = ", ".join(points.measurements()[:20])
        raise InputError(f"no measurement '{measurement}' (the file has: {known})", points.path, None,
                         "measurement")
    return points.select(mask)


def run(args: argparse.Namespace) -> int:
    refuse_unused(args, args.ellipsoids, "the ellipsoids", "add --ellipsoids",
                  INPUT_OPTIONS + (("--ellipsoid-scale", "ellipsoid_scale"),))
    refuse_unused(args, args.animate, "the animation", "add --animate", (("--points-per-s", "fps"),))
    refuse_unused(args, args.screenshot is not None, "the screenshot", "add --screenshot OUT.png",
                  (("--browser", "browser"),))
    args.fps = 2.0 if args.fps is None else args.fps
    inputs = [f for f in (args.points, *arm_inputs(args), args.artefacts, args.residuals) if f is not None]
    if args.html is not None and args.screenshot is not None and resolved(args.html) == resolved(args.screenshot):
        raise InputError("--html and --screenshot name the same file", args.html)
    if args.screenshot is not None:
        from .browser import find_chromium
        find_chromium(args.browser)   # before any work: a missing browser is reported at once
    with contextlib.ExitStack() as outputs:    # --html and --screenshot: both complete, or neither
        tmp = {k: outputs.enter_context(output_file(getattr(args, k), inputs, writes=suffix))
               for k, suffix in (("html", ".html"), ("screenshot", ".png")) if getattr(args, k) is not None}
        return _run(args, inputs, outputs, tmp)


#: the length [m] the median deflection's arrow is drawn by default (the ball marker is 12 mm in radius)
ARROW_TARGET_M = 0.06


#: the length [m] the median ellipsoid's largest semi-axis is drawn by default (the dots are 6 mm wide)
ELLIPSOID_TARGET_M = 0.012


def arrow_scale(deflection_um) -> float:
    """The default arrow scale: the 1-2-5 number that draws the median nonzero deflection [um] closest to
    :data:`ARROW_TARGET_M` long (1000 when nothing is deflected)."""
    return nice_scale(np.asarray(deflection_um, dtype=float) * 1e-6, ARROW_TARGET_M)


def nice_scale(lengths_m, target_m: float, default: float = 1000.0) -> float:
    """The 1-2-5 number that draws the median nonzero length [m] closest to ``target_m`` long
    (``default`` when every length is zero)."""
    d = np.asarray(lengths_m, dtype=float)
    d = d[np.isfinite(d) & (d > 0)]
    if not len(d):
        return default
    ideal = target_m / np.median(d)
    steps = [m * 10.0 ** e for e in range(int(np.floor(np.log10(ideal))) - 1, int(np.floor(np.log10(ideal))) + 2)
             for m in (1, 2, 5)]
    return float(min(steps, key=lambda v: abs(np.log(v / ideal))))


def _run(args, inputs, outputs, tmp) -> int:
    # read everything first: a bad file stops here, before a server starts or a file is written
    arm = model_from_args(args)
    desc = arm.desc
    points = read_points(args.points, desc.joint_quantities)
    arm.check_points(points)
    artefacts = read_artefacts(args.artefacts) if args.artefacts else None
    if artefacts is not None:
        check_features(points, artefacts)
    residuals = read_residuals(args.residuals) if args.residuals else None
    sel = _selection(points, args.measurement)
    if not args.animate and args.point > len(sel):
        raise InputError(f"--point {args.point}: the selection has {len(sel)} point(s)", points.path)
    wrench = sel.wrench
    centres = arm.ball_centres(sel)
    rigid = arm.ball_centres(sel, rigid=True)
    d_um = np.linalg.norm(centres - rigid, axis=1) * 1e6
    if args.scale is None:
        args.scale = arrow_scale(d_um if args.animate else d_um[args.point - 1:args.point])
    # a tracker's markers, unless they are the ball centres (no offsets) of points the instrument did not see
    tip_only = arm.tracker is not None and arm.tracker.offsets is None and sel.ref is None
    marker_notes: list[str] = []
    markers = None if arm.tracker is None or tip_only else _markers(arm, sel, marker_notes)
    drawn = residuals is not None or (markers is not None and markers[1] is not None)
    refuse_unused(args, drawn, "the drawing of residuals", "add --residuals FILE; or, for a tracker's markers, a "
                  "model file with [[reference_frame]] and points with its reference columns",
                  (("--residual-scale", "residual_scale"),))
    serve = args.serve or args.open_seconds is not None or (args.html is None and args.screenshot is None)

    from .view import View  # heavy backends from here on

    with View(desc, port=args.port) as view:
        if args.animate:
            view.animate(sel.q, wrench, fps=args.fps, scale=args.scale)
            shown = range(len(sel))
        else:
            i = args.point - 1
            view.show_pose(sel.q[i], None if wrench is None else wrench[i], scale=args.scale)
            shown = [i]
        view.show_points(centres, name="ball centres (corrected)")
        notes = []
        if artefacts is not None:
            placements, notes = place_features(artefacts, sel.measurement, sel.feature, centres,
                                               desc.probe.ball_diameter)
            view.show_artefacts(placements, artefacts.distances)
        if args.ellipsoids:
            _ellipsoids(arm, sel, args, view)
        notes += marker_notes
        if residuals is not None:
            if args.measurement is not None:   # the selected measurement's (and those of no measurement)
                residuals = residuals.select(np.isin(residuals.measurement, ["", args.measurement]))
            all_markers = None if arm.tracker is None else _markers(arm, points)[0]
            origins, vectors, skipped = residual_origins(residuals, points, arm.ball_centres(points), all_markers)
            if skipped:
                notes.append(f"{skipped} residual(s) of {residuals.path} name points that are not those of "
                             f"{points.path} (another file, or another measurement or feature at that line); not "
                             "drawn")
            if len(vectors):
                _default_scale(args, vectors)
                view.show_residuals(origins, vectors, scale=args.residual_scale)
        if markers is not None:
            predicted, seen = markers
            if seen is not None:
                _default_scale(args, (seen - predicted).reshape(-1, 3))
            view.show_markers(predicted.reshape(-1, 3), None if seen is None else seen.reshape(-1, 3),
                              scale=args.residual_scale or 1.0)
        _report(arm, sel, centres, d_um, shown, wrench, args, view, notes)
        if args.html is not None:
            view.write_html(tmp["html"], inputs=inputs)
        if args.screenshot is not None:
            _screenshot(view, args, tmp["screenshot"])
        outputs.close()                     # publish the files now, before serving
        if args.html is not None:
            log.info(f"page -> {args.html}")
        if args.screenshot is not None:
            log.info(f"screenshot -> {args.screenshot}")
        if serve:
            _serve(view, args.open_seconds)
    return 0


def _default_scale(args, vectors) -> None:
    """``--residual-scale`` from the data when not given: the median of ``vectors`` (N, 3) [m] drawn about
    :data:`ARROW_TARGET_M` long."""
    if args.residual_scale is None:
        args.residual_scale = nice_scale(np.linalg.norm(vectors, axis=1), ARROW_TARGET_M)


def _markers(arm, sel, notes: list | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """A tracker's markers in the points ``sel`` (a model file with ``[[reference_frame]]``): where the model
    puts them, (N, K, 3) [m] base frame, and where the instrument saw them (the points' reference columns
    mapped into the base frame by the model's frame of each row's session), or None when the points do not
    carry them (said in ``notes``)."""
    from arm_model.tracker import DEFAULT_SESSION, Tracker, marker_positions
    tr = arm.tracker
    n = len(sel)
    on_tip = Tracker((DEFAULT_SESSION,), np.eye(4), tr.offsets)
    predicted = marker_positions(arm.model, arm.p, sel.q, on_tip, [DEFAULT_SESSION] * n,
                                 arm.aux(sel, wrench=np.zeros((n, 6)), contact=False))
    if sel.ref is None:
        return predicted, None
    sessions = sel.session if sel.session is not None else np.full(n, DEFAULT_SESSION, object)
    missing = sorted({str(s) for s in sessions if tr.frame(s) is None})
    why = (f"{sel.n_markers} marker(s) in the points, {tr.n_markers} in the model file" if sel.n_markers != tr.n_markers
           else f"the model file has no frame for session(s) {', '.join(repr(s) for s in missing)}" if missing
           else None)
    if why is not None:
        if notes is not None:
            notes.append(f"the instrument's coordinates of {sel.path} are not drawn: {why}")
        return predicted, None
    inv = np.array([np.linalg.inv(tr.frame(s)) for s in sessions])
    seen = np.einsum("nij,nkj->nki", inv[:, :3, :3], sel.ref) + inv[:, None, :3, 3]
    return predicted, seen


def _ellipsoids(arm, sel, args, view) -> None:
    """The 95 % uncertainty ellipsoids of the selection's corrected centres (arm_model.uncertainty)."""
    from arm_model.model_file import parameters_of
    from arm_model.uncertainty import propagate
    from arm_model.uncertainty_cli import inputs_from_args

    from .scene import coverage_factor
    parameters = parameters_of(arm)
    inputs = inputs_from_args(arm, args, sel.wrench is not None)
    res = propagate(arm.model, arm.p, sel.q, sel.wrench, arm.aux(sel), parameters=parameters, inputs=inputs)
    if not np.all(np.isfinite(res.cov)):
        raise NumericalError("the uncertainty of a corrected centre is not finite")
    if args.ellipsoid_scale is None:
        semi = coverage_factor() * np.sqrt(np.maximum(np.linalg.eigvalsh(res.cov)[:, -1], 0.0))
        args.ellipsoid_scale = nice_scale(semi, ELLIPSOID_TARGET_M)
    view.show_ellipsoids(res.centres, res.cov, args.ellipsoid_scale)
    u = np.sqrt(np.mean(res.u ** 2, axis=0)) * 1e6
    log.info(f"uncertainty of the corrected centres, RMS over the {len(sel)} point(s): u_x {u[0]:.3f}, u_y {u[1]:.3f}, "
          f"u_z {u[2]:.3f} um (parameters: {res.sources['parameters']})")


def _report(arm, sel, centres, d_um, shown, wrench, args, view, notes) -> None:
    desc = arm.desc
    log.info(f"{len(sel)} point(s) of {sel.path}" + (f", measurement '{args.measurement}'" if args.measurement else ""))
    for line in view.legend:
        log.info("  " + line)
    if wrench is None:
        log.info("no force columns: no deflection (the arrows have zero length)")
    elif sel.force_kind == "two-channel":
        log.info("two-channel force sensor (f_bend, f_axial): the bending force along probe y is not measured and "
              "is taken as zero")
    if arm.effects:
        log.info("effects applied to the ball centres: " + ", ".join(e.describe(arm.desc) for e in arm.effects)
              + " (the arm is drawn with its description's geometry)")
    if len(shown) == 1:
        i = shown[0]
        line = "" if sel.lines is None else f", line {sel.lines[i]}"
        log.info(f"point {i + 1}: measurement '{sel.measurement[i]}'{line}; ball centre (mm) "
              + ", ".join(f"{v:.4f}" for v in centres[i] * 1e3) + f"; deflection {d_um[i]:.2f} um, drawn "
              f"{d_um[i] * args.scale / 1e3:.1f} mm long")
    else:
        log.info(f"animated through {len(shown)} points at {args.fps:g} per second; deflection {d_um.min():.2f} to "
              f"{d_um.max():.2f} um")
    log_warnings(point_warnings(desc, sel))
    for note in notes:
        log.info("note: " + note)


def _screenshot(view, args, out_png) -> None:
    from .browser import screenshot

    with tempfile.TemporaryDirectory(prefix="aacmm-view-") as tmp:
        page = Path(tmp) / "scene.html"
        page.write_text(view.html(), encoding="utf-8")
        screenshot(page, out_png, browser=args.browser)


def _serve(view, seconds: float | None) -> None:
    def stop(signum, frame):
        raise SystemExit(0)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        # the address is the command's result, not a message: printed even with --quiet
        print(f"meshcat server: {view.url}", flush=True)
        log.info("serving " + (f"for {seconds:g} s" if seconds else "until Ctrl-C"))
        end = None if seconds is None else time.monotonic() + seconds
        try:
            while end is None or time.monotonic() < end:
                if not view.server.running:
                    raise ViewerError(f"the meshcat server at {view.url} stopped unexpectedly")
                time.sleep(0.2)
        except KeyboardInterrupt:
            pass
        log.info("server stopped")
    finally:
        signal.signal(signal.SIGTERM, previous)
