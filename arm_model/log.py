"""How the toolkit talks: one :mod:`logging` logger per package, one console handler set up by ``aacmm``.

Library code logs and never prints: ``log = logging.getLogger(__name__)`` (a child of its package's
logger: ``arm_model``, ``calibration``, ``correction`` or ``viz``), then

- ``log.info(...)``: what a command did (its summary), on standard output;
- ``log.info(..., extra=PROGRESS)``: a progress step ("[  12.3 s] screening ..."), on standard error;
- ``log.warning(...)``: something the user must look at ("warning: ..."), on standard error;
- ``log.debug(...)``: details for ``--verbose`` ("debug: ..."), on standard error.

The ``aacmm`` command line installs the handler with :func:`console` for the time of one command: INFO by
default, WARNING with ``-q/--quiet``, DEBUG with ``-v/--verbose``. Used as a library the toolkit says
nothing until the caller configures :mod:`logging` (the Python convention). Errors are not logged: they
are raised, and the command line prints them (exit 2).

:class:`Progress` is the progress display of long loops: on a terminal one line redrawn with ``\\r``;
otherwise (a log file, a pipe) one plain line every 10 % and at the end, never a ``\\r``.
"""
from __future__ import annotations

import contextlib
import logging
import math
import re
import sys
import time
import warnings

from .errors import INVISIBLE

__all__ = ["PACKAGES", "PROGRESS", "console", "Progress", "progress_line", "level_from_flags", "counted", "escaped"]

#: the packages whose loggers the command line configures
PACKAGES = ("arm_model", "calibration", "correction", "viz")
#: libraries that log: their records go through the same console handler (never Python's bare fallback)
LIBRARIES = ("yourdfpy",)

#: control characters (C0, DEL, C1, the Unicode line and paragraph separators) but the tab, and the invisible and
#: text-direction ones (errors.INVISIBLE)
_CONTROL = re.compile(f"[\x00-\x08\x0a-\x1f\x7f-\x9f\u2028\u2029{INVISIBLE}]")
_ESCAPES = {"\n": "\\n", "\r": "\\r"}
#: the most characters of a one-line message (an error, a warning, a progress or debug line): beyond, its middle is cut
MAX_LINE = 4000


def _escape(m: re.Match) -> str:
    c = m.group()
    return _ESCAPES.get(c) or (f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}")


def escaped(text: str, keep_newlines: bool = False) -> str:
    """``text`` with every control character shown as its escape (a newline as ``\\n``, ESC as ``\\x1b``),
    so that a name holding one (a file name with a newline) cannot split a message or forge another line
    (``warning: ...``), nor drive the terminal. ``keep_newlines``: the text's own line breaks kept (a
    summary of several lines); every other control character escaped. The tab is kept. A one-line message
    longer than :data:`MAX_LINE` characters (a value of a megabyte quoted in an error) keeps its start (the file,
    line and column) and its end, the middle left out and counted."""
    if keep_newlines:
        return "\n".join(_CONTROL.sub(_escape, line) for line in text.split("\n"))
    if len(text) > MAX_LINE:
        head, tail = MAX_LINE * 2 // 3, MAX_LINE // 4
        text = f"{text[:head]} ... [{len(text) - head - tail} characters left out] ... {text[-tail:]}"
    return _CONTROL.sub(_escape, text)


#: ``extra=`` of a progress record
PROGRESS = {"progress": True}


def counted(n: int, word: str, plural: str | None = None) -> str:
    """``"1 point"``, ``"0 points"``, ``"3 points"``: a count with its noun in the right number
    (``plural``: when not ``word + "s"``)."""
    return f"{n} {word if n == 1 else (plural or word + 's')}"


def level_from_flags(quiet: bool, verbose: bool) -> int:
    """The console level of ``-q/--quiet`` and ``-v/--verbose``."""
    return logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO


class _ConsoleFormatter(logging.Formatter):
    def __init__(self, t0: float):
        super().__init__()
        self.t0 = t0

    def format(self, record: logging.LogRecord) -> str:
        # a warning, an error, a progress step and a debug line are one line each: any control character in
        # them (a newline in a file name) is escaped; the summary (INFO) keeps its own line breaks
        plain = record.levelno == logging.INFO and not getattr(record, "progress", False)
        text = escaped(record.getMessage(), keep_newlines=plain)
        if record.levelno >= logging.ERROR:
            return f"error: {text}"
        if record.levelno >= logging.WARNING:
            return f"warning: {text}"
        if getattr(record, "progress", False):
            return f"[{record.created - self.t0:6.1f} s] {text}"
        if record.levelno < logging.INFO:
            return f"debug: {text}"
        return text


class ConsoleHandler(logging.Handler):
    """INFO records on standard output, every other record on standard error (the streams current at
    each record, so a redirection made after the handler was created is followed). A closed pipe
    (``BrokenPipeError``) is raised to the command, which ends quietly."""

    def __init__(self, level: int = logging.NOTSET):
        super().__init__(level)
        self.setFormatter(_ConsoleFormatter(time.time()))

    def emit(self, record: logging.LogRecord) -> None:
        try:
            to_err = record.levelno != logging.INFO or getattr(record, "progress", False)
            stream = sys.stderr if to_err else sys.stdout
            stream.write(self.format(record) + "\n")
            stream.flush()
        except BrokenPipeError:
            raise
        except Exception:           # logging's own convention: never let a message break the command
            self.handleError(record)


@contextlib.contextmanager
def console(level: int = logging.INFO):
    """The console handler on every package logger at ``level`` for the time of the block; the loggers'
    earlier levels, handlers and propagation are restored afterwards (a command run inside another one,
    or from a test, leaves no trace)."""
    handler = ConsoleHandler()
    saved = []
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        # a library's warning (numpy's overflow, ...) as one console line, its source only with -v
        log = logging.getLogger(PACKAGES[0])
        log.warning(f"{category.__name__}: {message}")
        log.debug(f"  (raised at {filename}:{lineno})")
    warnings.showwarning = show
    for name in PACKAGES + LIBRARIES:
        logger = logging.getLogger(name)
        saved.append((logger, logger.level, logger.handlers[:], logger.propagate))
        logger.handlers = [handler]
        logger.setLevel(level if name in PACKAGES else max(level, logging.WARNING))
        logger.propagate = False
    try:
        yield handler
    finally:
        warnings.showwarning = shown
        for logger, lvl, handlers, propagate in saved:
            logger.handlers = handlers
            logger.setLevel(lvl)
            logger.propagate = propagate


def progress_line(logger: logging.Logger):
    """A ``callable(str)`` that logs each text as a progress step of ``logger`` (for code that takes a
    ``progress`` callback)."""
    return lambda text: logger.info(text, extra=PROGRESS)


def _is_tty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def _duration(seconds: float) -> str:
    """``"40 s"``, ``"17 min"``, ``"2.3 h"``: a duration to the precision an estimate has."""
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


class Progress:
    """A progress display for ``total`` steps: ``label [#####.....] k/n  elapsed``.

    Shown when ``logger`` is enabled for INFO (not with ``--quiet``; not in library use unless the caller
    configured logging) and ``enabled`` is true. On a terminal (standard error a tty, or ``stream`` given
    and a tty) the line is redrawn in place with ``\\r``; otherwise one progress record is logged at the
    first step past every ``every_pct`` percent and at the end, so a log file gets plain lines.

    ``estimate``: also the time left, from the rate so far (``about 16 min left``); in a log file then also
    a line ``first_s`` seconds after the start and every ``every_s`` seconds between the percent steps, so
    that a long run says early how long it will take.
    """

    def __init__(self, total: int, label: str = "", logger: logging.Logger | None = None,
                 enabled: bool = True, stream=None, width: int = 30, every_pct: float = 10.0,
                 estimate: bool = False, first_s: float = 2.0, every_s: float = 30.0):
        self.total, self.label, self.width = int(total), label, width
        self.logger = logger or logging.getLogger("arm_model")
        self.stream = stream
        self.enabled = bool(enabled) and self.logger.isEnabledFor(logging.INFO)
        self.tty = self.enabled and _is_tty(self._stream())
        self.every = max(float(every_pct), 1e-9)
        self.estimate, self.every_s = estimate, every_s
        self.done = 0
        self._next_pct = 0.0
        self.t0 = time.perf_counter()
        self._next_time = self.t0 + first_s if estimate else math.inf
        self._draw()

    def _stream(self):
        return self.stream if self.stream is not None else sys.stderr

    def _bar(self) -> str:
        k = int(self.width * min(self.done, self.total) / max(self.total, 1))
        return f"{self.label} [{'#' * k}{'.' * (self.width - k)}] {self.done}/{self.total}"

    def _left(self, now: float) -> str:
        if not self.estimate or not 0 < self.done < self.total:
            return ""
        return f", about {_duration((now - self.t0) * (self.total - self.done) / self.done)} left"

    def _draw(self) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if self.tty:
            stream = self._stream()
            stream.write(f"\r{self._bar()}  {now - self.t0:.1f} s{self._left(now)}\033[K")
            if self.done >= self.total:
                stream.write("\n")
            stream.flush()
            return
        pct = 100.0 * self.done / max(self.total, 1)
        if self.done and (pct >= self._next_pct or self.done >= self.total or now >= self._next_time):
            self.logger.info(f"{self.label} {self.done}/{self.total} ({pct:.0f} %){self._left(now)}", extra=PROGRESS)
            while self._next_pct <= pct:
                self._next_pct += self.every
            if self.estimate:
                self._next_time = now + self.every_s

    def update(self, n: int = 1) -> None:
        self.done += n
        self._draw()
