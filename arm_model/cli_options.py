"""The command-line toolbox every ``aacmm`` command uses: argparse types for numbers checked at the
boundary (finite, in range, named in the message) and the one type of every path argument (:func:`path_arg`), the
``--arm`` options with the one loader of the arm they name, and the one ``-o/--output`` option."""
from __future__ import annotations

import argparse
import logging
import math
from pathlib import Path

from .csv_io import SPACE, parse_number
from .errors import InputError, path_problem
from .model_file import Arm, load_model

__all__ = ["add_arm_options", "add_frame_options", "add_output_option", "output_path", "file_output_path",
           "path_arg", "folder_arg",
           "arm_from_args", "arm_inputs", "model_from_args", "number_in", "positive", "non_negative", "at_least",
           "fraction", "finite", "seed", "port", "duration_s", "MAX_WAIT_S", "comma_list"]

log = logging.getLogger(__name__)


def _number(text: str, kind=float):
    """``text`` as a finite float or a whole number, by the files' number rule (:func:`arm_model.csv_io.parse_number`:
    ASCII digits only, so no "4_5" for 45 nor another script's digits; no nan or inf)."""
    what = "a whole number" if kind is int else "a finite number"
    v = parse_number(text)
    if v is None or not math.isfinite(v) or (kind is int and not text.strip(SPACE).lstrip("+-").isdecimal()):
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
    return int(text.strip(SPACE)) if kind is int else v


def number_in(low=None, high=None, *, low_open=False, high_open=False, kind=float):
    """argparse type: a finite number (``kind`` float or int) in the interval from ``low`` to ``high``
    (either may be None: unbounded; ``*_open``: the end itself excluded)."""
    lo = "" if low is None else ("(" if low_open else "[") + f"{low:g}"
    hi = "" if high is None else f"{high:g}" + (")" if high_open else "]")
    if low is not None and high is not None:
        want = f"in {lo}, {hi}"
    elif low is not None:
        want = f"{'>' if low_open else '>='} {low:g}"
    elif high is not None:
        want = f"{'<' if high_open else '<='} {high:g}"
    else:
        want = ""

    def parse(text: str):
        v = _number(text, kind)
        if ((low is not None and (v < low or (low_open and v == low)))
                or (high is not None and (v > high or (high_open and v == high)))):
            raise argparse.ArgumentTypeError(f"must be {want}, got {text}")
        return v
    parse.__name__ = "whole number" if kind is int else "number"     # argparse names the type in messages
    return parse


def comma_list(text: str, option: str, what: str, give: str) -> tuple[str, ...]:
    """The items of a comma-separated list option (``--holdout a,b``, ``--candidates x,y``), each stripped of
    its padding: an InputError naming ``option`` for a list of nothing, an empty item (``a,,b`` or a trailing
    comma: the ``$ID`` of an unset shell variable, as an empty argument is) or an item given twice. ``what``: one
    item's kind ("measurement"), ``give``: what the option takes, for the messages."""
    items = tuple(t.strip(SPACE) for t in text.split(","))
    if not any(items):
        raise InputError(f"{option} names no {what} (got {text!r}): give {give}")
    if not all(items):
        k = items.index("")
        raise InputError(f"{option} {text!r}: item {k + 1} of {len(items)} is empty (a comma too many, or an unset "
                         f"shell variable?): give {give}")
    twice = sorted({t for t in items if items.count(t) > 1})
    if twice:
        raise InputError(f"{option} names {', '.join(twice)} twice")
    return items


def positive(kind=float):
    """argparse type: a finite number > 0 (``kind`` float or int)."""
    return number_in(0, low_open=True, kind=kind)


def non_negative(kind=float):
    """argparse type: a finite number >= 0."""
    return number_in(0, kind=kind)


def at_least(minimum: int):
    """argparse type: a whole number >= ``minimum``."""
    return number_in(minimum, kind=int)


#: argparse type: a number in (0, 1)
fraction = number_in(0, 1, low_open=True, high_open=True)
#: argparse type: a finite number (any sign)
finite = number_in()
#: argparse type: a random seed, a whole number from 0 to 2**53 (exact as a JSON number and a TOML integer in every
#: file that records it: --seed 2**64 made simulate write a truth.toml its reader refuses, exit 3)
seed = number_in(0, 2 ** 53, kind=int)
#: argparse type: a TCP port
port = number_in(1, 65535, kind=int)
#: the longest time [s] an option may ask a command to wait or serve (about 116 days): beyond it a number is a typo
#: (``--linger-s 1e308`` served the live view until Ctrl-C)
MAX_WAIT_S = 1e7


def duration_s(zero: bool = True):
    """argparse type: a time to wait [s], finite, from 0 (``zero``; else above 0) to :data:`MAX_WAIT_S`."""
    return number_in(0, MAX_WAIT_S, low_open=not zero)


def path_arg(text: str, folder: bool = False) -> Path:
    """argparse type of every path argument of the toolkit (an input file, ``--arm``, an output): the path, or an
    argparse error saying why the text as given cannot name one (:func:`arm_model.errors.path_problem`)."""
    why = path_problem(text, folder)
    if why:
        raise argparse.ArgumentTypeError(why)
    return Path(text)


def folder_arg(text: str) -> Path:
    """argparse type of a folder that a command reads (``ring --signals DIR``): :func:`path_arg` for a folder."""
    return path_arg(text, folder=True)


def _not_stdout(text: str) -> None:
    if text == "-":             # (it wrote a file named "-" where standard output was meant)
        raise argparse.ArgumentTypeError("'-' (standard output) is not an output of the toolkit: name a file or "
                                         "folder (./- for a file of that name)")


def output_path(text: str) -> Path:
    """argparse type of an output folder (``-o``): :func:`path_arg` for a folder, and not ``-``."""
    _not_stdout(text)
    return path_arg(text, folder=True)


def file_output_path(text: str) -> Path:
    """argparse type of an output that is one file (``tip -o``, ``urdf -o``, ``view --html``): :func:`path_arg` for
    a file (no trailing slash), and not ``-``."""
    _not_stdout(text)
    return path_arg(text)


def add_output_option(p, kind: str = "folder", what: str = "", *, as_it_runs: bool = False) -> None:
    """``-o/--output``, the one output of every command, defined here for all: ``kind`` "folder" (metavar DIR) or
    "file" (FILE); ``what`` names it in the help ("CSV", "session folder"). Its promises are kept by
    :mod:`arm_model.output`, which every command writes through: never over an input (nor a folder holding
    one), nothing written outside ``-o``, the whole output or nothing (``as_it_runs``: a folder written as the
    command runs, ``aacmm live``'s session, which starts new or empty)."""
    if kind not in ("folder", "file"):
        raise ValueError(f"kind must be 'folder' or 'file', got {kind!r}")
    folder = kind == "folder"
    name = what or ("output folder" if folder else "output file")
    how = ("a new (or empty) folder, written as the command runs" if as_it_runs else
           "created, or an earlier output of this command replaced; written whole or not at all" if folder else
           "written whole or not at all")
    never = "never an input or a folder holding one" if folder else "never one of the inputs"
    p.add_argument("-o", "--output", type=output_path if folder else file_output_path, required=True,
                   metavar="DIR" if folder else "FILE",
                   help=f"{name} ({how}; {never}; nothing is written outside it)")


def add_arm_options(p, help_arm: str = "the arm: a shipped arm's name (aacmm7), a model file or description TOML "
                                       "(the effects a model file holds are applied) or a URDF with --tip-frame "
                                       "(docs/formats.md §2, docs/own-arm.md)") -> None:
    """``--arm`` with :func:`add_frame_options` and ``--masses``, the same for every subcommand."""
    p.add_argument("--arm", type=path_arg, required=True, help=help_arm)
    add_frame_options(p)
    p.add_argument("--masses", type=path_arg, default=None, metavar="TOML",
                   help="for a URDF arm: link masses and centres of mass ([[link]] name, mass_kg, com_x_mm, "
                        "com_y_mm, com_z_mm), replacing the URDF's <inertial>; gravity torques (joint "
                        "compliance) need masses")


def add_frame_options(p) -> None:
    """``--tip-frame`` and ``--base-frame``: the chain of an arm given as a URDF."""
    p.add_argument("--tip-frame", default=None, metavar="LINK",
                   help="for an arm given as a URDF: the link at the ball centre, in any orientation (its z axis "
                        "is the probe's, along the tool; the chain runs from the root to it; force range and "
                        "compliances default to the seed paper's probe)")
    p.add_argument("--base-frame", default=None, metavar="LINK",
                   help="for an arm given as a URDF: the link its chain starts at (default the URDF's root; its "
                        "frame is the base frame of every output), e.g. after a floating joint, an arm on a torso "
                        "whose joints the points do not give, or a humanoid's sole (the leg walked backwards)")
    p.add_argument("--hold-joint", action="append", default=None, metavar="JOINT[=VALUE]", type=_hold_joint,
                   help="for an arm given as a URDF: a moving joint of the chain the points do not give, held at "
                        "VALUE (deg, or mm for a prismatic joint; default 0) as a fixed joint, e.g. a tool "
                        "changer's joint between the last arm joint and the tip frame (repeat for several)")


def _hold_joint(text: str) -> tuple[str, float]:
    """``--hold-joint JOINT[=VALUE]`` -> (name, value in deg or mm)."""
    name, sep, value = text.partition("=")
    if not name.strip():
        raise argparse.ArgumentTypeError(f"'{text}': give a joint name, JOINT or JOINT=VALUE")
    if not sep:
        return name.strip(), 0.0
    try:
        v = _number(value)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"'{text}': VALUE must be a number (finite; deg, or mm; or leave out "
                                         "'=VALUE' for 0)") from None
    if abs(v) > 1e4:
        raise argparse.ArgumentTypeError(f"'{text}': VALUE must be within +-10000 (deg, or mm)")
    return name.strip(), v


def model_from_args(args: argparse.Namespace) -> Arm:
    """The arm named by :func:`add_arm_options`: description, effects and their parameter values
    (:class:`arm_model.model_file.Arm`), read by the one loader every subcommand uses."""
    hold = tuple(getattr(args, "hold_joint", None) or ())      # a joint given twice: refused by the parser
    key = (args.arm, args.tip_frame, getattr(args, "masses", None), getattr(args, "base_frame", None), hold)
    cached = getattr(args, "_arm_loaded", None)
    if cached is None or cached[0] != key:        # read once per command line (arm_inputs reads it first)
        arm = load_model(*key[:2], masses=key[2], base_frame=key[3], hold=dict(hold) or None)
        args._arm_loaded = (key, arm)
        log.debug(f"arm {args.arm}: '{arm.desc.name}', {arm.desc.n_joints} joints, effects: "
                  f"{', '.join(e.describe(arm.desc) for e in arm.effects) or 'none'}"
                  + (f", covariance {arm.covariance}" if arm.covariance else ""))
    return args._arm_loaded[1]


def arm_inputs(args: argparse.Namespace) -> list:
    """Every file the ``--arm`` options read: the arm, the ``--masses`` file and the covariance and training poses
    files a model file names. Outputs are never written over any of them (:func:`arm_model.output.guard_output`).
    A shipped arm given by name is its file (the name is no file of the current folder: `--arm aacmm7 -o aacmm7` was
    refused as an output over an input)."""
    from .shipped import arm_path
    files = [arm_path(args.arm), getattr(args, "masses", None)]
    try:
        arm = model_from_args(args)
        named = [arm.covariance, arm.training_poses]
    except InputError:
        named = []          # the command reports the bad arm itself when it loads it
    return [f for f in files + named if f is not None]


def arm_from_args(args: argparse.Namespace):
    """The description of the arm named by :func:`add_arm_options` (its effects, if any, left out:
    commands that evaluate points use :func:`model_from_args`)."""
    return model_from_args(args).desc
