"""``aacmm live``: a live measurement session from a sample stream (docs/live.md).

A thin layer over :class:`arm_model.live.Session`: it opens the source (:mod:`arm_model.live.sources`),
reads the header, pushes each line's sample, prints points and events as they come, draws the live view
(:mod:`viz.live`) and closes the session folder with how it ended. Ctrl-C and SIGTERM end the session
cleanly (the folder is complete up to the last sample read; exit 130 / 143); a bad line is counted and
skipped (``--strict``: it stops the session, exit 2).
"""
from __future__ import annotations

import argparse
import csv
import logging
import os
import signal
import time
from pathlib import Path
from typing import TYPE_CHECKING

from arm_model import InputError
from arm_model.cli import command_help
from arm_model.cli_options import (
    add_arm_options,
    add_output_option,
    arm_inputs,
    duration_s,
    model_from_args,
    number_in,
    path_arg,
    port,
)
from arm_model.live.session import RATE_HZ_RANGE

if TYPE_CHECKING:          # only for the annotations: the live modules load when the command runs
    from arm_model.live import SampleLayout, Session
    from arm_model.live.samples import SampleBlock
    from arm_model.live.sources import LineSource, Pacer

    from .live import LiveView

__all__ = ["register", "run_live", "WARN_FIRST"]

log = logging.getLogger(__name__)

#: events of one kind (dropped, late, bad lines) printed one by one before they are only counted
WARN_FIRST = 5
#: the slowest replay (``--speed``): a thousandth of real time (1e-300 waited 1e297 s for the second sample)
MIN_SPEED = 1e-3


def _speed(text: str) -> float:
    """argparse type of ``--speed``: 0 (as fast as possible) or from :data:`MIN_SPEED` to 1e6."""
    v = number_in(0, 1e6)(text)
    if 0 < v < MIN_SPEED:
        raise argparse.ArgumentTypeError(f"must be 0 (as fast as possible) or in [{MIN_SPEED:g}, 1e+06], got {text}")
    return v


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live", help=command_help("live"),
        description="Run a live measurement session: read samples (time, joint angles, force, optional torque, "
                    "temperature and trigger: docs/formats.md §8) from SOURCE, find each contact, write one "
                    "deflection-corrected point a contact at its force peak with its uncertainty, flag over-force "
                    "and joint-limit events as they happen, refit the features of a plan after each point, and "
                    "record everything in the session folder as it goes (docs/live.md).",
        epilog="Exit status: 0 the stream ended; 2 a bad header, option or file (nothing written), or a bad line "
               "with --strict or a stream that failed (a connection reset: the session is kept, said partial); "
               "130/143 Ctrl-C/SIGTERM (the session is kept, complete up "
               "to the last sample read).")
    p.add_argument("source", type=_source,
                   help="a recorded stream (a file: replayed at its time stamps, see --speed), '-' (standard input), "
                        "tcp://HOST:PORT (connect to a server sending the lines) or udp://HOST:PORT (listen for "
                        "datagrams of whole lines)")
    add_arm_options(p)
    add_output_option(p, "folder", "the session folder", as_it_runs=True)
    p.add_argument("--plan", type=path_arg, default=None, help="session plan TOML: the features in order, their kind, "
                                                          "certificate and number of points (docs/formats.md §9)")
    p.add_argument("--feature", default=None, metavar="KIND:ID[:DIAMETER_MM]",
                   help="ad hoc: every point belongs to one feature of this kind (instead of --plan)")
    p.add_argument("--measurement", default=None, metavar="ID",
                   help="the measurement id written on every point of the session (default: the plan's, else the "
                        "session folder's name)")
    p.add_argument("--speed", type=_speed, default=None,
                   help=f"replay a file at this many times real time, {MIN_SPEED:g} to 1e6 (default 1; 0: as fast as "
                        "possible)")
    p.add_argument("--rate-Hz", type=number_in(*RATE_HZ_RANGE), default=None,
                   help="the nominal sample rate (default: estimated from the first intervals); longer gaps "
                        "count as dropped samples; when the median of the first 16 intervals is off it by more than "
                        "1.5x, a 'rate' event says so with both figures")
    p.add_argument("--strict", action="store_true", help="stop the session at the first bad line (default: "
                                                          "count it, say where, and skip it)")
    p.add_argument("--stop-after-idle-s", type=duration_s(zero=False), default=None, metavar="S",
                   help="end the session when no line came for S seconds (a network stream that does not end)")
    g = p.add_argument_group("contacts (docs/live.md)")
    g.add_argument("--contact", choices=("force", "trigger"), default="force",
                   help="find contacts from the force (default) or from the trigger column (the arm's button)")
    g.add_argument("--contact-on-N", type=number_in(0, 1e5, low_open=True), default=None,
                   help="the smoothed force, its zero removed, that starts a contact (default 0.1; raised to 8 "
                        "times the noise the sensor shows out of contact)")
    g.add_argument("--contact-off-N", type=number_in(0, 1e5, low_open=True), default=None,
                   help="below it the contact ends (default 0.05, less than --contact-on-N; raised to 4 times "
                        "the noise)")
    g.add_argument("--min-dwell-s", type=number_in(0, 1e4), default=None,
                   help="how long the force must stay at or above --contact-on-N for a point (default 0.02)")
    g.add_argument("--smooth-s", type=number_in(0, 10), default=None,
                   help="time constant of the force's smoothing for contacts (default 0.005; 0: none)")
    g.add_argument("--baseline-s", type=number_in(0, 1e4), default=None,
                   help="time constant of the zero that follows the sensor out of contact (default 2; 0: the "
                        "force is not zeroed)")
    v = p.add_argument_group("live view (docs/viewer.md)")
    v.add_argument("--view", action="store_true", help="serve the live view on 127.0.0.1 (the URL is printed)")
    v.add_argument("--port", type=port, default=None, help="web port of the viewer (default: the first free one "
                                                            "from 7000)")
    v.add_argument("--fps", type=number_in(0.5, 60), default=None, metavar="F",
                   help="frames the live view draws a second (default 10)")
    v.add_argument("--linger-s", type=duration_s(), default=None, metavar="S",
                   help="keep serving the view S seconds after the stream ended (at most 1e7; Ctrl-C ends it)")
    from arm_model.uncertainty_cli import add_input_options
    add_input_options(p)
    p.set_defaults(func=run_live)


class _Stop:
    """Ctrl-C and SIGTERM set a flag that the loop reads (the session then closes cleanly)."""

    def __init__(self):
        self.reason: str | None = None
        self._old = {}

    def __enter__(self) -> _Stop:
        for sig, reason in ((signal.SIGINT, "interrupted"), (signal.SIGTERM, "terminated")):
            try:
                self._old[sig] = signal.signal(sig, lambda *_, r=reason: self._set(r))
            except ValueError:          # not the main thread
                pass
        return self

    def _set(self, reason: str) -> None:
        self.reason = self.reason or reason

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def _header(source: LineSource, stop: _Stop, idle_s: float | None = None) -> tuple:
    """(line number, cells) of the stream's header: its first line that is not blank (UDP: the first that names the
    time column, ``time_s`` or ``t_s``; every datagram line before it, a sample, a line cut in two, bytes that are not
    text, skipped and counted, so that a session started late joins at the next header). ``idle_s``
    (``--stop-after-idle-s``): no line for that long is an InputError (a stream that never starts: nothing is
    written)."""
    from arm_model.csv_io import blank_record
    from arm_model.live.samples import TIME_COLUMNS
    from arm_model.live.sources import line_text
    skipped, since = 0, time.monotonic()
    for item in source.lines():
        if stop.reason:
            return None, None, skipped
        if item is None:
            if idle_s and time.monotonic() - since > idle_s:
                before = f", {skipped} line(s) before it skipped" if skipped else ""
                raise InputError(f"no line came for {idle_s:g} s (--stop-after-idle-s): the stream sent no header "
                                 f"(time_s, q1_deg ...{before}); nothing written", source.name)
            continue
        since = time.monotonic()
        no, raw = item
        try:
            text = line_text(raw, source.name, no)
            if blank_record(text):
                continue
            cells = next(csv.reader([text.lstrip("\ufeff")], strict=True))
        except (InputError, csv.Error) as exc:
            if source.datagrams:
                skipped += 1
                continue
            if isinstance(exc, InputError):
                raise
            raise InputError(f"the header is not valid CSV: {exc}", source.name, no) from None
        if source.datagrams and not {c.strip() for c in cells} & set(TIME_COLUMNS):
            skipped += 1
            continue
        return no, cells, skipped
    raise InputError("the stream ended before its header line (time_s, q1_deg ...)", source.name)


def run_live(args: argparse.Namespace) -> int:
    from arm_model.live import ContactOptions, Session, read_plan, single_feature_plan
    from arm_model.live.record import check_new_folder
    from arm_model.live.samples import SampleLayout
    from arm_model.live.sources import open_source
    from arm_model.uncertainty_cli import inputs_from_args, refuse_unused
    if args.plan is not None and args.feature is not None:
        raise InputError("give --plan or --feature, not both")
    given = [o for o, v in (("--port", args.port), ("--fps", args.fps), ("--linger-s", args.linger_s)) if v is not None]
    if given and not args.view:
        raise InputError(f"{', '.join(given)}: option(s) of the live view, which is not asked for (add --view)")
    force = {"on": ("--contact-on-N", args.contact_on_N), "off": ("--contact-off-N", args.contact_off_N),
             "dwell": ("--min-dwell-s", args.min_dwell_s), "smooth": ("--smooth-s", args.smooth_s),
             "baseline": ("--baseline-s", args.baseline_s)}
    given = [o for o, v in force.values() if v is not None]
    if given and args.contact == "trigger":     # a trigger contact lasts while the button is held, whatever the force
        raise InputError(f"{', '.join(given)}: option(s) of force contacts, which --contact trigger does not use")
    file = _is_file(args.source)        # a file is replayed at its time stamps; a stream comes as it comes
    refuse_unused(args, file, "a file's replay", f"{args.source} is a stream, taken as its lines come",
                  (("--speed", "speed"),))
    refuse_unused(args, not file, "a stream that may fall silent", f"the file {args.source} is read to its end",
                  (("--stop-after-idle-s", "stop_after_idle_s"),))
    args.speed = 1.0 if args.speed is None else args.speed
    try:
        contact = ContactOptions(source=args.contact, **{k: v for k, (_, v) in force.items() if v is not None})
    except ValueError as exc:
        raise InputError(f"contact options: {exc}") from None
    arm = model_from_args(args)
    plan = read_plan(args.plan) if args.plan else (single_feature_plan(args.feature) if args.feature else None)
    files = [args.plan, *arm_inputs(args)] + ([Path(args.source)] if _is_file(args.source) else [])
    check_new_folder(args.output, files)
    source = open_source(args.source)
    _say_small_buffer(source)
    try:
        with _Stop() as stop:
            line, cells, skipped = _header(source, stop, args.stop_after_idle_s)
            if cells is None:
                log.info(f"{stop.reason} before the header: nothing written")
                return 130 if stop.reason == "interrupted" else 143
            layout = SampleLayout(cells, arm.desc.n_joints, source.name, line)
            session = Session(arm, args.output, plan=plan, contact=contact, layout=layout,
                              inputs=inputs_from_args(arm, args, layout.force_kind is not None),
                              measurement=args.measurement, rate=args.rate_Hz, inputs_files=files,
                              status=_status(args, source, files))
            return _run(args, source, session, layout, stop, skipped)
    finally:
        source.close()


def _say_small_buffer(source: LineSource) -> None:
    from arm_model.live.sources import UDP_BUFFER_BYTES
    granted = getattr(source, "buffer_bytes", None)
    if granted is not None and granted < UDP_BUFFER_BYTES:
        log.warning(f"the UDP receive buffer is {granted // 1024} KiB (the system's limit): a pause of the session "
                    f"longer than that buffer holds loses datagrams (counted as dropped samples); "
                    f"'sysctl -w net.core.rmem_max={UDP_BUFFER_BYTES}' raises the limit")


def _is_file(spec: str) -> bool:
    return spec != "-" and "://" not in spec


def _source(text: str) -> str:
    """argparse type of SOURCE: as given; a file's path checked as every path argument is
    (:func:`arm_model.cli_options.path_arg`)."""
    if _is_file(text):
        path_arg(text)
    return text


def _status(args: argparse.Namespace, source: LineSource, files: list) -> dict:
    """session.json's first keys; ``reproduce``: the command that, run in the session folder, writes its tips.csv
    again byte for byte (a file it names is named from there; the points' last moves are points.csv's
    q1_move_sign ... columns, which a joint's hysteresis needs and every session with a folder writes)."""
    import shlex

    from arm_model.shipped import SHIPPED_ARMS, provenance

    def there(path) -> str:     # a relative path as seen from the session folder
        if Path(path).is_absolute() or (str(path) in SHIPPED_ARMS and not Path(path).exists()):
            return str(path)
        return os.path.relpath(Path(path).absolute(), Path(args.output).absolute())
    tip = ["aacmm", "tip", "points.csv", "--arm", there(args.arm)]
    tip += ["--tip-frame", args.tip_frame] if args.tip_frame else []
    tip += ["--base-frame", args.base_frame] if getattr(args, "base_frame", None) else []
    tip += [x for name, v in getattr(args, "hold_joint", None) or () for x in ("--hold-joint", f"{name}={v!r}")]
    tip += ["--masses", there(args.masses)] if args.masses else []
    for opt in ("encoder_resolution_deg", "u_compliance_rel", "u_probing_um", "u_model_discrepancy_um"):
        if getattr(args, opt, None) is not None:
            tip += ["--" + opt.replace("_", "-"), repr(getattr(args, opt))]
    if getattr(args, "u_force_N", None) is not None:
        tip += ["--u-force-N", *map(repr, args.u_force_N)]
    return {"source": source.name, "speed": args.speed if source.replay else None,
            "plan": None if args.plan is None else str(args.plan), "feature": args.feature,
            "reproduce": shlex.join(tip + ["--uncertainty", "-o", "tips-again.csv"]),
            **provenance([f for f in files if f is not None])}


def _run(args: argparse.Namespace, source: LineSource, session: Session, layout: SampleLayout, stop: _Stop,
         skipped: int) -> int:
    """The session's loop: push the samples of the lines that came together (a block), show what they bring, keep
    the view drawn. A replay is paced sample by sample (the samples due within :data:`AHEAD_S` go together)."""
    from arm_model.live.sources import Pacer
    view = _start_view(args, session)
    pacer = Pacer(args.speed if source.replay else 0.0)
    said: dict[str, int] = {}
    idle_since = time.monotonic()
    watch_idle = args.stop_after_idle_s is not None
    status, message, code = "complete", "the stream ended", 0

    def idle() -> bool:
        session.tick()
        if view is not None:
            view.update()
        return stop.reason is not None
    try:
        for chunk in source.chunks():
            if stop.reason:
                break
            if chunk is None:
                if idle() or (args.stop_after_idle_s and time.monotonic() - idle_since > args.stop_after_idle_s):
                    break
                continue
            if watch_idle:
                idle_since = time.monotonic()
            ended = False
            for item in _blocks(chunk, source, layout):
                if stop.reason:
                    ended = True
                    break
                if isinstance(item, InputError):
                    _show(session.bad_line(item), said)
                    if args.strict:
                        status, message, code = "stopped", f"stopped at a bad line (--strict): {item}", 2
                        ended = True
                        break
                    continue
                if not _push(item, session, pacer, idle, view, said):
                    ended = True
                    break
            if ended:
                break
    except OSError as exc:
        status, code = "stopped", 2
        message = (f"{exc.filename or source.name}: the stream failed: {exc.strerror or exc}; the session is partial: "
                   "the samples the stream had still to send never came")
    except Exception as exc:
        # any other error inside the session (a bug included): the session is closed as stopped, saying why (never
        # left 'running' as if killed), and the error goes on to its exit status (2, 3 or 4)
        for out in session.close("stopped", f"stopped by an error: {exc}"):
            _show(out, said)
        raise
    if stop.reason and code == 0:
        status = stop.reason
        message = "interrupted (Ctrl-C)" if status == "interrupted" else "terminated (SIGTERM)"
        code = 130 if status == "interrupted" else 143
    for out in session.close(status, message):
        _show(out, said)
    _summary(session, said, skipped, status, message)
    if view is not None:
        _finish_view(args, session, view, stop)
    if code == 2:
        raise InputError(message.split(": ", 1)[1] if message.startswith("stopped at") else message)
    return code


#: the first characters of a line that is neither blank nor a header
_SAMPLE_START = frozenset("0123456789+-.")


def _blocks(chunk: list, source: LineSource, layout: SampleLayout) -> list:
    """The samples of the lines that came together, as blocks (:class:`~arm_model.live.samples.SampleBlock`), and
    each bad line's :class:`InputError`, in the stream's order (blank lines and, over UDP, a repeated header
    skipped)."""
    from arm_model.csv_io import blank_record
    from arm_model.live.sources import chunk_texts
    header_text, datagrams = ",".join(layout.header), source.datagrams
    from arm_model.live.session import BLOCK_LEAST
    items = chunk_texts(chunk, source.name)
    texts: list[str] = [x[1] for x in items if not isinstance(x, InputError)]
    if len(texts) == len(items) >= BLOCK_LEAST and all(x[:1] in _SAMPLE_START for x in texts):    # no blank, no header
        return layout.parse_block(texts, [x[0] for x in items])
    out: list = []
    nos: list[int] = []
    texts = []
    for item in items:
        if isinstance(item, InputError):
            out += _parsed(layout, texts, nos)
            out.append(item)
            texts, nos = [], []
            continue
        no, text = item
        if not text or (datagrams and text == header_text) or blank_record(text):
            continue
        texts.append(text)
        nos.append(no)
    return out + _parsed(layout, texts, nos)


def _parsed(layout: SampleLayout, texts: list[str], nos: list[int]) -> list:
    """A block of the lines (:meth:`SampleLayout.parse_block`), or for a few, each line's ``(sample, text, line)``
    (or its error): a line that comes alone costs no arrays."""
    from arm_model.live.session import BLOCK_LEAST
    if len(texts) >= BLOCK_LEAST:
        return layout.parse_block(texts, nos)
    out: list = []
    for text, no in zip(texts, nos, strict=True):
        try:
            out.append((layout.parse(text, no), text, no))
        except InputError as exc:
            out.append(exc)
    return out


def _push(block: SampleBlock | tuple, session: Session, pacer: Pacer, idle, view: LiveView | None,
          said: dict) -> bool:
    """Push a block, in the parts that are due (a paced replay), or one ``(sample, text, line)``; False when the
    pacing was interrupted."""
    if isinstance(block, tuple):
        if pacer.speed > 0 and not pacer.wait(block[0].t, idle):
            return False
        for o in session.push_sample(*block):
            _show(o, said)
        if view is not None:
            view.update()
        return True
    k = 0
    while k < block.n:
        if pacer.speed > 0 and not pacer.wait(block.t[k], idle):
            return False
        end = pacer.released(block.t_arr, k)
        for o in session.push_block(block, k, end):
            _show(o, said)
        if view is not None:
            view.update()
        k = end
    return True


def _start_view(args: argparse.Namespace, session: Session) -> LiveView | None:
    if not args.view:
        return None
    from .live import LiveView
    view = LiveView(session, port=args.port, **({} if args.fps is None else {"fps": args.fps}))
    print(f"live view: {view.url}", flush=True)
    return view


def _finish_view(args: argparse.Namespace, session: Session, view: LiveView, stop: _Stop) -> None:
    try:
        view.update(force=True)
        page = view.write_html(session.record.folder / "view.html")
        log.info(f"the last view as a page -> {page}")
        linger = args.linger_s or 0.0
        end = time.monotonic() + linger
        if linger and not stop.reason:
            log.info(f"serving the live view {args.linger_s:g} s more: {view.url} (Ctrl-C ends)")
        while not stop.reason and time.monotonic() < end:
            time.sleep(0.1)
    finally:
        view.close()


def _show(out: object, said: dict) -> None:
    """Print what the session brought: points (and fits) as info, events as warnings (dropped, late and
    bad lines one by one :data:`WARN_FIRST` times, then only counted)."""
    from arm_model.live import Event, FeatureFit, LivePoint
    if isinstance(out, LivePoint):
        log.info(str(out))
    elif isinstance(out, FeatureFit):
        log.info(f"  {out.describe()}")
    elif isinstance(out, Event):
        n = said[out.kind] = said.get(out.kind, 0) + 1
        if out.kind in ("over_force", "joint_limit", "clock_jump", "end", "rate") or n <= WARN_FIRST:
            log.warning(str(out))
        elif n == WARN_FIRST + 1:
            log.warning(f"more '{out.kind}' events are counted, not shown (events.csv has each)")


def _jumps(c: dict) -> str:
    """The time stamps off the stream's clock, when there were any."""
    return "".join(f", {c[k]} {what}" for k, what in (("time_jumps", "bad time stamp(s)"),
                                                       ("clock_jumps", "clock jump(s)")) if c[k])


def _summary(session: Session, said: dict, skipped: int, status: str, message: str) -> None:
    c = session.counts
    folder = session.record.folder
    log.info(f"{c['samples']} samples, {c['points']} points ({c['over_force']} over-force), {c['bumps']} touches "
             f"shorter than {session.contact_options.dwell:g} s, dropped {c['dropped']}, late {c['late']}, bad lines "
             f"{c['bad_lines']}" + _jumps(c) + (f", {skipped} datagram line(s) before the header" if skipped else "")
             + f" -> {folder}")
    if not c["points"]:
        log.info("no point was taken: the folder has no points.csv and no tips.csv, and session.json no reproduce "
                 "command (null)")
    noise = session.noise()
    if noise is not None:
        d = session.thresholds()
        log.info(f"force noise out of contact: {', '.join(f'{v:.4f}' for v in noise)} N (x, y, z); contact "
                 f"thresholds {d['on']:.3g} / {d['off']:.3g} N"
                 + (" (raised to the noise)" if d["on"] > session.contact_options.on else ""))
    if status != "complete":
        log.warning(f"session {status}: {message}; {folder} holds every sample read until then "
                    f"(session.json: status '{status}')")
