"""``aacmm``: the command line. Each subcommand lives in the package it belongs to and exposes
``register(subparsers)``; this module only dispatches and turns every error into one clear message:

- bad input (:class:`~arm_model.InputError` and the toolkit's other errors), a file or folder the
  system refuses (``OSError``), too little memory: the message, exit 2;
- a numerical failure (:class:`~arm_model.NumericalError`: no convergence, rank deficiency, data that do not
  determine the result): "numerical failure: ...", exit 4, nothing written;
- Ctrl-C or SIGTERM: "interrupted", exit 130 (143 for SIGTERM), nothing written (or, when the output was
  already published, that it was: :func:`arm_model.output.published_outputs`);
- a closed standard output (``aacmm tip ... | head -1``): quiet;
- anything else is a bug: a message asking for a report, exit 3; ``--debug`` adds the traceback.

Every subcommand accepts ``-q/--quiet`` (warnings and errors only) and ``-v/--verbose`` (debug messages
too), defined once here; the messages go through :mod:`logging` (:mod:`arm_model.log`).

Outputs are written complete or not at all (:mod:`arm_model.output`), so no error leaves a partial
output behind.
"""
from __future__ import annotations

import argparse
import functools
import importlib
import importlib.util
import logging
import os
import platform
import signal
import sys
import time
import traceback

from .errors import AacmmError, NumericalError
from .log import console, escaped, level_from_flags
from .output import published_outputs
from .shipped import version

__all__ = ["main", "COMMAND_MODULES", "EXIT_INPUT", "EXIT_INTERNAL", "EXIT_NUMERICAL", "EXIT_STATUS"]

#: exit codes: 0 done, 1 done but some runs failed (study montecarlo), 2 bad input or a file/system
#: error, 3 internal error (a bug), 4 numerical failure (inputs read, no result the toolkit stands by), 130 Ctrl-C,
#: 143 SIGTERM
EXIT_INPUT, EXIT_INTERNAL, EXIT_NUMERICAL = 2, 3, 4
#: the exit statuses as ``aacmm --help`` states them (docs/guarantees.md, section 4, says the same)
EXIT_STATUS = ("Exit status: 0 done; 1 study montecarlo: done, but some runs failed (listed); 2 bad input or a file "
               "the system refuses (one message naming the file, line and column; nothing written); 3 internal "
               "error (please report it); 4 numerical failure: the inputs were read, but the computation gave no "
               "result to stand by (no convergence, rank deficiency, data that do not determine the fit; one "
               "message saying what to try; nothing written); 130/143 interrupted by Ctrl-C/SIGTERM. "
               "docs/guarantees.md")

log = logging.getLogger(__name__)

#: every subcommand, in the order of ``aacmm --help``: the module that registers it (``register(subparsers)``)
#: and its one-line help. ``aacmm --help`` lists them without importing any of those modules, and
#: ``aacmm CMD ...`` imports only CMD's module, so the start-up stays short.
COMMANDS = {
    "tip": ("arm_model.commands", "rigid and deflection-corrected ball centres for a points file"),
    "urdf": ("arm_model.commands", "generate the URDF of an arm description"),
    "examples": ("arm_model.commands", "copy the example campaigns, data and docs into a folder"),
    "simulate": ("arm_model.sim.cli", "simulate a measurement campaign on a virtual arm with a hidden truth"),
    "view": ("viz.cli", "show the arm, probe deflection, artefacts and residuals in a headless meshcat viewer"),
    "ring": ("correction.cli", "ring-gauge campaign: force peaks, cylinder fits, the paper's four models and the "
                               "full-wrench correction, correlations, GUM budgets, HTML report"),
    "paper": ("correction.cli",
              "the seed paper's Tables 1-3 reproduced from its own data and budgets; the loop closed"),
    "calibrate": ("calibration.cli", "identify the arm's kinematic parameters from artefact measurements"),
    "study": ("calibration.cli", "plan a calibration campaign: Monte Carlo runs, pose-set choice"),
    "close-loop": ("calibration.loop_cli", "find what the model lacks: calibrate, diagnose, add the effect, repeat"),
    "live": ("viz.live_cli", "live measurement session: stream in, corrected points with their uncertainty, "
                             "events and feature fits out as the operator probes, recorded as it goes"),
}
COMMAND_MODULES = tuple(dict.fromkeys(module for module, _ in COMMANDS.values()))


def command_help(name: str) -> str:
    """The one-line help of subcommand ``name`` (for its module's ``register``)."""
    return COMMANDS[name][1]


def _requested(argv) -> str | None:
    """The subcommand named on the command line (the first word not an option: the top-level
    options take no value), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


_DEBUG_HELP = "on an internal error, print the Python traceback (for a bug report)"
_QUIET_HELP = "only warnings and errors (no summary, no progress)"
_VERBOSE_HELP = "also debug messages (inputs read, model used, timings, files written)"


def _add_common(parser: argparse.ArgumentParser, top: bool) -> None:
    """--debug, -q/--quiet and -v/--verbose on ``parser`` and every subcommand below it: defined once
    here, accepted before or after the subcommand (``aacmm -q tip ...`` or ``aacmm tip ... -q``)."""
    default = {} if top else {"default": argparse.SUPPRESS}
    parser.add_argument("--debug", action="store_true", help=_DEBUG_HELP, **default)
    talk = parser.add_mutually_exclusive_group()
    talk.add_argument("-q", "--quiet", action="store_true", help=_QUIET_HELP, **default)
    talk.add_argument("-v", "--verbose", action="store_true", help=_VERBOSE_HELP, **default)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _add_common(sub, False)


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The ``aacmm`` parser. With ``argv`` (the command line), only the subcommand it names is built in
    full (the others are listed for ``--help``); without, every subcommand.

    Built once a process for each set of subcommand modules (a few milliseconds, which a program or a test
    calling :func:`main` many times paid each time) and shared: parse with it, never change it. Parsing reads a
    parser and never changes it; the subcommands' ``func`` and defaults are fixed when it is built."""
    return _build(_modules(argv))


def _modules(argv: list[str] | None) -> tuple[str, ...]:
    """The modules whose subcommands the parser for ``argv`` builds in full (None: all of them)."""
    if argv is None:
        return COMMAND_MODULES
    wanted = _requested(argv)
    return (COMMANDS[wanted][0],) if wanted in COMMANDS else ()


@functools.lru_cache(maxsize=len(COMMAND_MODULES) + 2)
def _build(modules: tuple[str, ...]) -> argparse.ArgumentParser:
    parser = _Parser(
        prog="aacmm",
        description="Portable measuring arm toolkit: deflection-aware ball centres from encoder angles and "
                    "contact force, simulation, ring-gauge analysis, calibration and closing the loop. "
                    "Files carry units in their column and key names (mm, deg, N ...); every format: "
                    "docs/formats.md (in a clone, or DIR/docs/formats.md after `aacmm examples DIR`).",
        epilog=EXIT_STATUS)
    parser.add_argument("--version", action=_Version, nargs=0, help="show the toolkit's version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in modules:
        if importlib.util.find_spec(module.rsplit(".", 1)[0]) is None or importlib.util.find_spec(module) is None:
            continue
        importlib.import_module(module).register(sub)            # every subcommand of that module
    for name, (module, text) in COMMANDS.items():
        if name not in sub.choices and module not in modules:
            sub.add_parser(name, help=text, add_help=False)     # listed only: not the one that runs
    _add_common(parser, True)
    return parser


class _StoreOnce(argparse.Action):
    """argparse's ``store`` (an option's value), refusing an option given twice: ``--arm a.toml --arm b.toml`` or
    ``live --feature seat:a --feature seat:b`` took the last one without a word. Options meant to repeat use
    ``action="append"``."""

    def __call__(self, parser, namespace, values, option_string=None):
        if option_string is not None:
            given = namespace.__dict__.setdefault("_options_given", set())
            if self.dest in given:
                parser.error(f"argument {'/'.join(self.option_strings)}: given twice (it takes one value; the "
                             "last would silently replace the first)")
            given.add(self.dest)
        setattr(namespace, self.dest, values)


class _AppendOnce(argparse._AppendAction):
    """argparse's ``append`` (a repeatable option), refusing a value given twice: ``--hold j1.d --hold j1.d``,
    ``--effect thermal --effect thermal`` or ``--hold-joint j7 --hold-joint j7=5`` (a value that is a (name, value)
    pair is the same when its name is) were taken as if once, or the last one silently won."""

    def __call__(self, parser, namespace, values, option_string=None):
        key = values[0] if isinstance(values, tuple) else values
        if any((v[0] if isinstance(v, tuple) else v) == key for v in getattr(namespace, self.dest, None) or ()):
            parser.error(f"argument {'/'.join(self.option_strings)}: {key} given more than once: give each once")
        super().__call__(parser, namespace, values, option_string)


class _Parser(argparse.ArgumentParser):
    """argparse's parser whose error message (it may quote an argument: a file name with a newline) is one
    line, control characters escaped, whose options taking one value refuse to be given twice and whose repeatable
    options refuse a value given twice (subcommands' parsers are of the same class)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.register("action", None, _StoreOnce)
        self.register("action", "store", _StoreOnce)
        self.register("action", "append", _AppendOnce)

    def error(self, message: str):
        super().error(escaped(message))

    def _get_values(self, action, arg_strings):
        # an option's value "--" attached (--mc=--, -o--): Python 3.11's argparse drops it as the end of the options
        # and stores an empty list, which the command took as no value (--mc=-- ran no Monte Carlo, exit 0) or met
        # as a list (-o=--: exit 3)
        if action.option_strings and action.nargs in (None, argparse.OPTIONAL) and arg_strings == ["--"]:
            self.error(f"argument {'/'.join(action.option_strings)}: expected a value, got '--'")
        return super()._get_values(action, arg_strings)


class _Version(argparse.Action):
    """``--version``: the installed version, looked up only when asked (importlib.metadata is slow to
    import, and ``aacmm --help`` should start fast)."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"aacmm-toolkit {version()}")
        parser.exit()


class Terminated(BaseException):
    """SIGTERM, raised like Ctrl-C so that every output being written is removed."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _quiet_stdout() -> None:
    """Standard output was closed by its reader: send the rest to /dev/null, silently."""
    try:
        fd = sys.stdout.fileno()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    except (AttributeError, OSError, ValueError):
        pass


def _os_message(exc: OSError) -> str:
    text = exc.strerror or str(exc) or type(exc).__name__
    names = [str(f) for f in (exc.filename, exc.filename2) if f is not None]
    return f"{', '.join(names)}: {text}" if names else text


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if any("\0" in str(a) for a in argv):      # only from a program (a shell cannot pass one)
        print("aacmm: error: a command-line argument holds a NUL character", file=sys.stderr)
        return EXIT_INPUT
    try:        # loading the commands takes a second: Ctrl-C then is one line too, never a traceback
        parser = build_parser(argv)
    except KeyboardInterrupt:
        print("aacmm: error: interrupted; nothing written", file=sys.stderr)
        return 130
    empty = next((a for a in argv if a == "" or (a.startswith("--") and a.endswith("=") and "=" not in a[:-1])),
                 None)
    if empty is not None:       # "$DIR" of an unset variable: "" is read as "." by every path (examples "" wrote
        parser.error(f"an empty argument{f' ({empty})' if empty else ''}: a file, folder or value left out "
                     "(an unset shell variable?)")      # into the current folder)
    args = parser.parse_args(argv)
    if args.quiet and args.verbose:
        parser.error("-q/--quiet and -v/--verbose exclude each other")
    name = "aacmm " + args.command + (f" {args.study}" if getattr(args, "study", None) else "")

    def error(text: str) -> None:
        try:
            print(f"{name}: error: {escaped(text)}", file=sys.stderr, flush=True)
        except (OSError, ValueError):
            pass

    previous = None
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:          # not the main thread: leave SIGTERM alone
        pass
    written: list = []          # the outputs already published when something ends the command

    def done() -> str:
        if not written:
            return "nothing written"
        return f"the output was already written completely: {', '.join(str(p) for p in written)}"

    try:
        with console(level_from_flags(args.quiet, args.verbose)), published_outputs(written):
            t0 = time.perf_counter()
            log.debug(f"aacmm-toolkit {version()}, Python {platform.python_version()}: {name}")
            code = int(args.func(args) or 0)
            log.debug(f"{name}: done in {time.perf_counter() - t0:.2f} s, exit {code}")
        try:
            sys.stdout.flush()
        except BrokenPipeError:
            _quiet_stdout()
        return code
    except NumericalError as exc:
        error(f"numerical failure: {exc}; {done()}")
        return EXIT_NUMERICAL
    except AacmmError as exc:
        error(str(exc))
        return EXIT_INPUT
    except BrokenPipeError:
        _quiet_stdout()
        return 141
    except KeyboardInterrupt:
        error(f"interrupted; {done()}")
        return 130
    except Terminated:
        error(f"terminated; {done()}")
        return 143
    except MemoryError:
        error(f"out of memory: the input is too large for this machine; {done()}")
        return EXIT_INPUT
    except OSError as exc:
        error(f"{_os_message(exc)}; {done()}")
        return EXIT_INPUT
    except Exception as exc:        # a bug: say so, never a bare traceback
        if getattr(args, "debug", False):
            traceback.print_exc()
        error(f"internal error ({type(exc).__name__}: {exc}). This is a bug: please report it with the "
              "command line and its input files" + ("" if getattr(args, "debug", False)
                                                    else " (add --debug for the traceback)")
              + f"; {done()}")
        return EXIT_INTERNAL
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
