"""``aacmm``: the command line. Each subcommand lives in the package it belongs to and exposes
``register(subparsers)``; this module only dispatches and turns errors into one clear message."""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys

from ._errors import AacmmError
from .shipped import version

__all__ = ["main", "COMMAND_MODULES"]

#: modules that each register one or more subcommands, in the order of ``aacmm --help``
COMMAND_MODULES = (
    "arm_model.commands",        # tip, urdf
    "arm_model.sim.cli",         # simulate
    "viz.cli",                   # view
    "correction.cli",            # ring
    "calibration.cli",           # calibrate, study
    "calibration.loop_cli",      # close-loop
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="aacmm",
        description="Portable measuring arm toolkit: deflection-aware ball centres from encoder angles and "
                    "contact force, simulation, ring-gauge analysis, calibration and closing the loop. "
                    "Files carry units in their column and key names (mm, deg, N ...); every format: docs/formats.md.")
    parser.add_argument("--version", action="version", version=f"aacmm-toolkit {version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        if importlib.util.find_spec(name.rsplit(".", 1)[0]) is None or importlib.util.find_spec(name) is None:
            continue
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except AacmmError as exc:
        print(f"aacmm {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"aacmm {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
