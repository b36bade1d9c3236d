"""One base exception for the project; subclasses carry their context."""
from __future__ import annotations

import difflib
import os
import re
import stat
import tomllib
import unicodedata
from pathlib import Path

__all__ = ["AacmmError", "InputError", "NumericalError", "read_text", "open_input", "decode_text", "parse_toml",
           "did_you_mean", "unknown_key", "id_problem", "path_problem", "resolved", "beside", "named_in",
           "text_lines", "INVISIBLE", "MAX_ID_LENGTH"]


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
            where.append(column if column.startswith(("key ", "column ")) else f"column '{column}'")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)

    def __reduce__(self):           # pickled whole (from a worker process), not only its text
        return type(self), (self.reason, self.path, self.line, self.column)


class NumericalError(AacmmError):
    """A numerical failure (no convergence, rank deficiency) that must not pass silently."""


_LONE_CR = re.compile(rb"\r(?!\n|\Z)")     # at the very end: a CRLF cut at its LF


def decode_text(raw: bytes, path: str | Path, first_line: int = 1) -> str:
    """The text of ``raw``, bytes of a user's text file starting at line ``first_line`` (one place for
    every reader): UTF-8, no NUL byte (binary data, or a UTF-16 file), no carriage return that ends a
    line alone (classic Mac line ends, which would merge or shift the numbered lines); else an
    InputError naming the file and the line."""
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError("not UTF-8 text (save the file as UTF-8)", path,
                         first_line + raw[: exc.start].count(b"\n")) from None
    k = raw.find(b"\0")
    if k >= 0:
        raise InputError("a NUL byte: binary data, or a UTF-16 file (save the file as UTF-8 text)", path,
                         first_line + raw[:k].count(b"\n"))
    if b"\r" in raw:
        m = _LONE_CR.search(raw)
        if m:
            raise InputError("a carriage return alone ends a line (old Mac line ends): save the file (or send "
                             "the stream) with LF or CRLF line ends", path, first_line + raw[: m.start()].count(b"\n"))
    return text


def text_lines(text: str) -> list[str]:
    """The lines of a decoded text (:func:`decode_text`), numbered as every message and every text editor numbers
    them: a line ends at a line feed (or CRLF) only. Python's ``splitlines`` also ends one at VT, FF, FS, GS, RS,
    NEL and the Unicode line and paragraph separators, which split a CSV row in two and shifted the line of every
    message after it."""
    lines = text.split("\n")
    if lines[-1] == "":
        lines.pop()
    return [line[:-1] if line.endswith("\r") else line for line in lines]


def open_input(path: str | Path, what: str):
    """A user's input file opened for reading bytes, or an InputError naming it (``what``: which file
    it is, "the points file"). A folder, a FIFO or a device is refused: it is not a file (and reading
    a FIFO would wait forever). A path is opened as given: ``"samples.csv/"`` is refused as the system refuses it
    (not a directory; ``Path`` would drop the separator and read the file: the command line's paths are checked as
    given by :func:`arm_model.cli_options.path_arg`)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))     # a FIFO's open would wait
    except IsADirectoryError:
        raise InputError(f"cannot read {what}: it is a folder, not a file", path) from None
    except OSError as exc:
        raise InputError(f"cannot read {what}: {exc.strerror or exc}", path) from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputError(f"cannot read {what}: " + ("it is a folder, not a file" if stat.S_ISDIR(mode)
                                                       else "not a regular file"), path)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except OSError as exc:
        os.close(fd)
        raise InputError(f"cannot read {what}: {exc.strerror or exc}", path) from None
    except BaseException:
        os.close(fd)
        raise


_SEPARATORS = tuple(s for s in (os.sep, os.altsep) if s)


def path_problem(text: str, folder: bool = False, base: str | Path | None = None) -> str | None:
    """Why ``text``, a path as given (on the command line: :func:`arm_model.cli_options.path_arg`, whatever the
    spelling of its option; or in a file: a model file's ``covariance``, a campaign's ``arm``), cannot name a file
    (``folder``: a folder) that a command reads or writes, or None; ``base``: the folder a relative path is
    relative to (default the current one). Checked on the text as given, before :class:`pathlib.Path` drops a
    trailing ``/`` or ``/.``:

    - an empty path names the current folder ("$DIR" of an unset variable);
    - a byte that is not UTF-8 (calibrate wrote its whole fit, then failed on residuals.csv, exit 3), a line break,
      tab or other control character, an invisible or text-direction character, or white space at its
      ends (:func:`id_problem`): the outputs name their inputs (summary.json, residuals.csv, whose
      reader strips its cells) and the console quotes them, and could not name this one;
    - a path ending in ``/`` or ``/.`` that the system refuses as "Not a directory" (``samples.csv/``);
    - a file given with a trailing ``/`` or ``/.`` (``t.csv/`` names a folder; Path() dropped it and the file
      ``t.csv`` was read or written)."""
    if not text.strip():
        return "expected a path, got an empty one (an unset shell variable?)"
    bad = next((c for c in text if "\ud800" <= c <= "\udfff"), None)
    if bad is not None:         # a name's byte that is not UTF-8 (Python's argv holds it as a lone surrogate)
        byte = f" (byte 0x{ord(bad) - 0xDC00:02x})" if ord(bad) >= 0xDC80 else ""
        return (f"the path {ascii(text)[:60]} is not UTF-8 text{byte}: the outputs, which name their inputs, could "
                "not name it; rename the file (or its folder)")
    why = id_problem(text)
    if why:
        return f"the path {why}: rename the file (or its folder)"
    tail = next((s + d for s in _SEPARATORS for d in ("", ".") if text.endswith(s + d)), None)
    if tail is None:            # Path() keeps what the system sees: the command that uses the path says what is wrong
        return None
    try:
        os.stat(text if base is None else os.path.join(base, text))
    except NotADirectoryError as exc:
        return f"{text!r}: {exc.strerror}: a path that ends in {tail!r} names a folder"
    except (OSError, ValueError):       # absent, unreadable: the command that uses it says so
        pass
    if not folder:
        plain = text[:-len(tail)].rstrip("".join(_SEPARATORS))
        return (f"{text!r} ends with {tail!r}, which names a folder: a file is expected here"
                + (f" (give {plain!r})" if plain else ""))
    return None


def resolved(path: str | Path) -> Path:
    """``path`` with its symbolic links resolved (as far as they exist); a link loop is an InputError (every user
    path is resolved through here: ``Path.resolve`` raises RuntimeError on a loop before Python 3.13)."""
    try:
        return Path(path).resolve()
    except (RuntimeError, OSError):     # Python < 3.13: RuntimeError on a loop; later: OSError ELOOP
        raise InputError("cannot follow the path: a loop of symbolic links", path) from None


def beside(file: str | Path) -> Path:
    """The folder the paths named inside ``file`` are relative to: that of the file itself, its symbolic links
    followed (a link to a file is not a copy of its folder: the files it names were written, or shipped, beside the
    real file). :func:`named_in` is the rule for one name."""
    return resolved(file).parent


def named_in(file: str | Path, name: str | Path) -> Path:
    """A path ``name`` named inside ``file`` (a campaign's ``arm``, a URDF's ``<mesh filename>``, a model file's
    ``covariance`` and ``training_poses``): as it is when absolute, else relative to :func:`beside` ``file``."""
    path = Path(name)
    return path if path.is_absolute() else beside(file) / path


def read_text(path: str | Path, what: str) -> str:
    """The UTF-8 text of a user's file (a BOM is dropped; checked by :func:`decode_text`), or an
    InputError naming the file and, for a bad byte, its line. ``what`` says which file it is ("the
    points file"); :func:`open_input` refuses what is not a file."""
    with open_input(path, what) as fh:
        try:
            raw = fh.read()
        except OSError as exc:
            raise InputError(f"cannot read {what}: {exc.strerror or exc}", path) from None
    return decode_text(raw[3:] if raw.startswith(b"\xef\xbb\xbf") else raw, path)


def parse_toml(text: str, path: str | Path) -> dict:
    """Parse TOML text; a syntax error becomes an InputError naming the file, line and column, and so does an
    integer beyond 64 bits (TOML 1.0: "an integer that cannot be represented losslessly must be an error";
    Python's reader takes 10**400, which every float() then met as an OverflowError, exit 3)."""
    try:
        data = tomllib.loads(text)
    except RecursionError:
        raise InputError("not valid TOML: arrays or tables nested too deeply", path) from None
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+), column (\d+)", str(exc))
        raise InputError(f"not valid TOML: {exc}", path, int(m.group(1)) if m else None,
                         f"column {m.group(2)}" if m else None) from None
    where = _wide_integer(data, ())
    if where is not None:
        from .toml_lines import key_path_text, toml_key_lines
        lines = toml_key_lines(text)
        line = next((lines[where[:k]] for k in range(len(where), 0, -1) if where[:k] in lines), None)
        raise InputError("not valid TOML: an integer beyond 64 bits (a TOML integer is from -2**63 to 2**63 - 1)",
                         path, line,
                         f"key '{key_path_text(where)}'")
    return data


def _wide_integer(value, where: tuple) -> tuple | None:
    """The key path of the first integer of a parsed TOML value outside TOML's 64-bit range, or None."""
    if isinstance(value, dict):
        items = value.items()
    elif isinstance(value, list):
        items = enumerate(value)
    else:
        return where if isinstance(value, int) and not -2 ** 63 <= value < 2 ** 63 else None
    return next((w for k, v in items if (w := _wide_integer(v, (*where, k))) is not None), None)


def did_you_mean(word: str, known) -> str:
    """``"; did you mean 'x'?"`` for the known word nearest to ``word`` (difflib), or ``""``.

    A key with a unit suffix (``u_diamter_mm``) is matched by its base name and offered with the
    user's unit (``u_diameter_mm``); ``known`` may hold bases (``"u_diameter"``) or whole keys."""
    from .units import split_unit
    known = list(dict.fromkeys(known))
    best = []
    parts = split_unit(word)
    if parts is not None:
        near = difflib.get_close_matches(parts[0], known, n=1, cutoff=0.6)
        # a base name takes the user's unit; a whole key (a unit of its own) is offered as it is
        best = [near[0] if split_unit(near[0]) is not None else f"{near[0]}_{parts[1]}"] if near else []
    if not best:
        best = difflib.get_close_matches(word, known, n=1, cutoff=0.6)
    return f"; did you mean '{best[0]}'?" if best and best[0] != word else ""


def unknown_key(key: str, known, shown=None, what: str = "key") -> str:
    """The message for an unknown key (``what="column"``: a CSV column): the nearest known one
    suggested, the known ones listed (``shown``: how to list them, e.g. with ``_<length unit>``;
    default ``known``)."""
    known = list(known)
    return f"unknown {what} '{key}'{did_you_mean(key, known)} (known: {', '.join(shown or known)})"


#: characters that show nothing or turn the text around: a byte-order mark or a zero-width space (an id that prints
#: as another: '\ufeffring-01' beside 'ring-01', from a byte-order mark left inside a file by two exports joined) and
#: the bidirectional embeddings, overrides and isolates (they reverse the rest of a terminal line: a message shown as
#: another). No id or name holds one (:func:`id_problem`); every message shows them escaped
#: (:func:`arm_model.log.escaped`)
INVISIBLE = "\u200b\ufeff\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069"

#: the longest id or name [characters]: a name, not a payload (every row repeats it; ids of 10 000 characters
#: are read in memory in proportion to the file, tests/test_reliability_round5.py)
MAX_ID_LENGTH = 100_000


def id_problem(text) -> str | None:
    """Why ``text`` cannot be a measurement or feature id, or None: an id is one non-empty line of text (a line
    break or another control character would split the row of every CSV file that carries it, which its reader
    then refuses) of at most :data:`MAX_ID_LENGTH` characters, without white space at its ends (read back
    stripped, it would name something else)."""
    if not isinstance(text, str) or not text.strip():
        return f"must be a non-empty text, got {_short(text)}"
    if text != text.strip():            # a CSV reader strips its cells: " j1" would read back as "j1"
        return (f"must not begin or end with white space (every CSV reader strips its cells, so it would read back "
                f"as {_short(text.strip())}), got {_short(text)}")
    if len(text) > MAX_ID_LENGTH:
        return f"must be at most {MAX_ID_LENGTH} characters long, got {len(text)} ({_short(text)})"
    bad = next((c for c in text if unicodedata.category(c) in ("Cc", "Zl", "Zp")), None)
    if bad is not None:
        return f"must be one line of text without control characters, got {_short(text)} (holding {bad!r})"
    bad = next((c for c in text if c in INVISIBLE), None)
    if bad is not None:
        return (f"must not hold an invisible or text-direction character, got {ascii(text)[:60]} (holding "
                f"{ascii(bad)})")
    return None


def _short(value, width: int = 60) -> str:
    """``repr(value)`` cut to about ``width`` characters (a message quotes a value, it does not reprint it)."""
    r = repr(value)
    return r if len(r) <= width else r[:width - 5] + "...'" + f" ({len(r)} characters)"
