"""Where a key of a TOML text is, for messages that name the line (one place for every TOML reader:
descriptions and model files, artefacts files, session plans, campaigns)."""
from __future__ import annotations

import re

__all__ = ["toml_key_lines", "key_path_text", "top_key_line"]


def _split_key(text: str) -> tuple[str, ...]:
    """``a."b.c".d`` -> ("a", "b.c", "d")."""
    return tuple(p.strip().strip('"') for p in re.findall(r'"[^"]*"|[^.]+', text))


def _strip_comment(line: str) -> str:
    """``line`` without its comment: from the first ``#`` outside a quoted string."""
    quote, i = None, 0
    while i < len(line):
        c = line[i]
        if quote is not None:
            if c == "\\" and quote == '"':
                i += 1                                  # an escaped character of a basic string
            elif c == quote:
                quote = None
        elif c in "\"'":
            quote = c
        elif c == "#":
            return line[:i]
        i += 1
    return line


def toml_key_lines(text: str) -> dict[tuple, int]:
    """Map a key path to its 1-based line, for messages.

    A path is a tuple of table names, 0-based indices of array-of-tables entries and the key, e.g.
    ``("joint", 2, "d_mm")``, ``("effect", 0, "parameter", 3, "value_urad")``; a table or array entry
    itself maps without a key (``("probe",)``, ``("joint", 2)``). Arrays of tables written as
    ``[[name]]`` headers and as inline tables one a line (``name = [`` then ``{ k = v, ... },``) are
    both followed; a dotted key ``a.b = 1`` maps as ``("a", "b")`` (and ``("a",)``).
    """
    lines: dict[tuple, int] = {}
    counts: dict[tuple, int] = {}
    prefix: tuple = ()
    array: tuple | None = None          # inside "key = [" over several lines: the array's path
    for no, raw in enumerate(text.split("\n"), start=1):
        line = _strip_comment(raw).strip()
        if array is not None:
            if line.startswith("]"):
                array = None
                continue
            if line.startswith("{"):
                counts[array] = counts.get(array, -1) + 1
                item = array + (counts[array],)
                lines[item] = no
                for key in re.findall(r'(?:^\{|,)\s*("[^"]*"|[\w-]+)\s*=', line):
                    lines[item + (key.strip('"'),)] = no
            continue
        m = re.match(r"^\[\[\s*(.+?)\s*\]\]$", line) or re.match(r"^\[\s*(.+?)\s*\]$", line)
        if m:
            names = _split_key(m.group(1))
            path: tuple = ()
            for k, name in enumerate(names):
                path += (name,)
                if k < len(names) - 1 and path in counts:
                    path += (counts[path],)
            if line.startswith("[["):
                counts[path] = counts.get(path, -1) + 1
                path += (counts[path],)
            prefix = path
            lines[prefix] = no
            continue
        m = re.match(r'^((?:"[^"]*"|[\w-]+)(?:\s*\.\s*(?:"[^"]*"|[\w-]+))*)\s*=\s*(.*)$', line)
        if m:
            keys = _split_key(m.group(1))           # a dotted key a.b = 1 also gives its table a
            for k in range(1, len(keys)):
                lines.setdefault(prefix + keys[:k], no)
            lines[prefix + keys] = no
            if m.group(2) == "[":
                array = prefix + keys
    return lines


def key_path_text(path: tuple) -> str:
    """``("joint", 2, "d_mm")`` -> ``joint[3].d_mm`` (1-based entries, as users count)."""
    out = ""
    for p in path:
        if isinstance(p, int):
            out += f"[{p + 1}]"
        else:
            out += ("." if out else "") + p
    return out or "top level"


def top_key_line(lines: dict[tuple, int], key: str) -> int | None:
    """The line of the top-level ``key`` in :func:`toml_key_lines`'s map: ``key = ...``, ``[key]`` or the
    first ``[[key]]``; None when the text does not hold it."""
    return lines.get((key,), lines.get((key, 0)))
