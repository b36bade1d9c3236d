"""The ``aacmm`` program's entry point: it takes Ctrl-C before it imports the command line.

Importing :mod:`arm_model.cli` (its readers, the output mechanism, the standard library they need) takes 0.1 to
0.3 s; a Ctrl-C then would print a Python traceback, since nothing of the toolkit runs yet to catch it. So this
module imports nothing of the toolkit at its own import: :func:`main` first makes Ctrl-C end the program with the
toolkit's one line and exit 130 (nothing has been read or written yet), then imports the command line, which
takes Ctrl-C over from there (:func:`arm_model.cli.main`).
"""
from __future__ import annotations

import os
import signal

__all__ = ["main"]

_INTERRUPTED = b"aacmm: error: interrupted; nothing written\n"


def _interrupted(signum, frame) -> None:
    try:
        os.write(2, _INTERRUPTED)
    finally:
        os._exit(130)


def main() -> int:
    """Run ``aacmm`` with the arguments of the process (``sys.argv``); its exit status."""
    previous = signal.signal(signal.SIGINT, _interrupted)
    from .cli import main as run
    signal.signal(signal.SIGINT, previous)
    return run()
