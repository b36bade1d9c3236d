"""One base exception for the project; subclasses carry their context."""
from __future__ import annotations

import difflib
import re
import tomllib
from pathlib import Path

__all__ = ["AacmmError", "InputError", "NumericalError", "read_text", "parse_toml", "did_you_mean",
           "unknown_key"]


class AacmmError(Exception):
    """Base of every error the toolkit raises on purpose."""


class InputError(AacmmError):
    """Bad input: names the file, the line (or key) and the column, and what was expected.

    Args:
        message: what is wrong and what was expected.
        path: the file.
        line: 1-based line number, if known.
        column: column name (CSV) or key path (TOML), if known.
    """

    def __init__(self, message: str, path: str | Path | None = None,
                 line: int | None = None, column: str | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        self.column = column
        self.reason = message
        where = []
        if self.path is not None:
            where.append(self.path)
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column '{column}'" if not column.startswith("key ") else column)
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)

    def __reduce__(self):           # pickled whole (from a worker process), not only its text
        return type(self), (self.reason, self.path, self.line, self.column)


class NumericalError(AacmmError):
    """A numerical failure (no convergence, rank deficiency) that must not pass silently."""


def read_text(path: str | Path, what: str) -> str:
    """The UTF-8 text of a user's file (a BOM is dropped), or an InputError naming the file and,
    for a bad byte, its line. ``what`` says which file it is ("the points file")."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {what}: {exc.strerror}", path) from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError("not UTF-8 text", path, raw[: exc.start].count(b"\n") + 1) from None


def parse_toml(text: str, path: str | Path) -> dict:
    """Parse TOML text; a syntax error becomes an InputError naming the file, line and column."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+), column (\d+)", str(exc))
        raise InputError(f"not valid TOML: {exc}", path, int(m.group(1)) if m else None,
                         f"column {m.group(2)}" if m else None) from None


def did_you_mean(word: str, known) -> str:
    """``"; did you mean 'x'?"`` for the known word nearest to ``word`` (difflib), or ``""``.

    A key with a unit suffix (``u_diamter_mm``) is matched by its base name and offered with the
    user's unit (``u_diameter_mm``); ``known`` may hold bases (``"u_diameter"``) or whole keys."""
    from ._units import split_unit
    known = list(dict.fromkeys(known))
    best = []
    parts = split_unit(word)
    if parts is not None:
        near = difflib.get_close_matches(parts[0], known, n=1, cutoff=0.6)
        best = [f"{near[0]}_{parts[1]}"] if near else []
    if not best:
        best = difflib.get_close_matches(word, known, n=1, cutoff=0.6)
    return f"; did you mean '{best[0]}'?" if best and best[0] != word else ""


def unknown_key(key: str, known, shown=None, what: str = "key") -> str:
    """The message for an unknown key (``what="column"``: a CSV column): the nearest known one
    suggested, the known ones listed (``shown``: how to list them, e.g. with ``_<length unit>``;
    default ``known``)."""
    known = list(known)
    return f"unknown {what} '{key}'{did_you_mean(key, known)} (known: {', '.join(shown or known)})"
