"""Every file a command writes passes the reader that will read it: checked before it is published.

:func:`arm_model.output.output_folder` and :func:`~arm_model.output.output_file` hand every file they
are about to publish to :func:`arm_model.output.check_output`, which finds the file's kind (:data:`KINDS`: by its suffix
and its first bytes, never by the writer's say-so, so that no writer can forget it) and reads it with
that kind's reader, the very function a command uses to read such a file:

========================  =========================================  ===========================================
kind                      recognised by                              read back by
========================  =========================================  ===========================================
model file                ``.toml`` with a ``convention`` key        ``load_model`` as every ``--arm`` reads it,
                                                                     with its covariance file as ``tip`` reads it
session plan              ``.toml`` with ``measurement`` or a         ``read_plan`` (``aacmm live --plan``)
                          feature's ``points``
artefacts file            ``.toml`` with ``feature`` / ``distance``   ``read_artefacts``
covariance file           ``.csv``, header ``parameter,unit,value,u``  ``read_covariance``
points file               ``.csv``, header ``measurement,feature,``   ``read_points``
                          and joint columns ``q1_...``
sample stream             ``.csv``, header ``time_s`` (or ``t_s``)    ``aacmm live``'s line reader
                          and joint columns ``q1_...``
force signal              ``.csv``, header starting ``time_s``        ``read_force_signal``
residuals file            ``.csv`` with ``line`` and ``dx_um``, or     ``aacmm view --residuals``'s reader
                          ``rx_um``
URDF                      ``.urdf``                                  the URDF reader's checks (every number in
                                                                     range, the tree; the tip frame is the user's)
JSON file                 ``.json``                                  a strict JSON reader (no NaN, no Infinity:
                                                                     standard JSON, as other tools read it)
========================  =========================================  ===========================================

Other files (HTML reports, PNG plots, text tables, ``tip``'s point table, the simulator's truth files, which
no reader of the toolkit takes) are not read back. A refusal is a bug of the toolkit, not of the user's
input: :class:`UnreadableOutput` (exit 3, "please report it"), and nothing is published.
"""
from __future__ import annotations

import importlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import InputError

__all__ = ["UnreadableOutput", "KINDS", "kind_of", "read_back", "read_as"]


class UnreadableOutput(RuntimeError):
    """A file a command wrote is refused by the reader that will read it, or read back does not give what
    was written (a bug: exit 3, nothing written). ``path``: the file; ``reason``: what is wrong."""

    def __init__(self, reason: str, path: str | Path | None = None):
        self.reason, self.path = reason, None if path is None else str(path)
        super().__init__(f"{self.path}: {reason}" if self.path is not None else reason)

    def __reduce__(self):
        return type(self), (self.reason, self.path)


@dataclass(frozen=True)
class Kind:
    """A kind of output file: its ``name``, the file ``suffix``, ``matches`` (of the file's top-level TOML
    table for ``.toml``, of its first line otherwise: for the suffixes several kinds share) and its reader
    (``"module:function"``, imported when a file of the kind is read: ``function(path)`` returns what it
    read or raises an InputError)."""
    name: str
    suffix: str
    matches: Callable[[Any], bool]        # the TOML data (a dict) or the first line (a str)
    reader: str


def _header(line: str) -> list[str]:
    return [c.strip() for c in line.split(",")]


def _is_plan(data: dict) -> bool:
    features = data.get("feature")
    return "measurement" in data or (isinstance(features, list) and
                                     any(isinstance(f, dict) and "points" in f for f in features))


KINDS: tuple[Kind, ...] = (
    Kind("model file", ".toml", lambda data: "convention" in data, "arm_model.model_file:read_model_file"),
    Kind("session plan", ".toml", _is_plan, "arm_model.live.plan:read_plan"),
    Kind("artefacts file", ".toml", lambda data: "feature" in data or "distance" in data,
         "arm_model.io:read_artefacts"),
    Kind("covariance file", ".csv", lambda line: _header(line)[:4] == ["parameter", "unit", "value", "u"],
         "arm_model.model_file:read_covariance"),
    Kind("points file", ".csv", lambda line: _header(line)[:2] == ["measurement", "feature"]
         and any(h.startswith("q1_") for h in _header(line)), "arm_model.io:read_points"),
    Kind("sample stream", ".csv", lambda line: _header(line)[0] in ("time_s", "t_s")
         and any(h.startswith("q1_") for h in _header(line)), "arm_model.live.samples:read_samples"),
    Kind("force signal", ".csv", lambda line: _header(line)[0] == "time_s", "arm_model.io:read_force_signal"),
    # the viewer's reader (a floor above: imported by name, as arm_model.cli names every command's module)
    Kind("residuals file", ".csv", lambda line: {"line", "dx_um"} <= set(_header(line)) or "rx_um" in _header(line),
         "viz.residuals:read_residuals"),
    Kind("URDF", ".urdf", lambda line: True, "arm_model.urdf_import:_read_urdf"),
    Kind("JSON file", ".json", lambda line: True, "arm_model.readback:read_json"),
)
#: a TOML file of none of the kinds above (the simulator's truth): it must still be TOML
OTHER_TOML = Kind("TOML file", ".toml", lambda data: True, "arm_model.readback:read_toml")


def read_as(suffix: str) -> str | None:
    """What the toolkit reads a file named with ``suffix`` as ("TOML", "CSV", "URDF", "JSON": the readers of
    :data:`KINDS` are chosen by the suffix), or None for a suffix no reader takes."""
    suffix = suffix.lower()
    return suffix[1:].upper() if suffix and any(k.suffix == suffix for k in KINDS) else None


def _toml_data(path: Path) -> dict | None:
    """The TOML at ``path`` (None when it is not TOML: it is then read back, and refused, as TOML)."""
    import tomllib
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, RecursionError, UnicodeDecodeError):
        return None


def read_json(path: Path):
    """Standard JSON (RFC 8259): no ``NaN``, ``Infinity``, which Python writes and other tools refuse."""
    def refuse(word):
        raise InputError(f"'{word}' is not JSON (a value nobody resolved must be written as null)", path)
    try:
        return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)
    except (ValueError, UnicodeDecodeError) as exc:
        line = getattr(exc, "lineno", None)
        raise InputError(f"not valid JSON: {exc}", path, line) from None


def read_toml(path: Path):
    """Any other TOML the toolkit writes must still be TOML."""
    from .errors import parse_toml, read_text
    return parse_toml(read_text(path, "the file"), path)


def _first_line(path: Path) -> str:
    with open(path, "rb") as fh:
        return fh.readline(1 << 16).decode("utf-8", "replace").lstrip("\ufeff").rstrip("\r\n")


def kind_of(path: Path, name: str | None = None) -> Kind | None:
    """The :class:`Kind` of the file at ``path`` (``name``: the name it will be published under, for its
    suffix; default ``path``'s), or None for a file no reader of the toolkit takes."""
    suffix = Path(name or path).suffix.lower()
    kinds = [k for k in KINDS if k.suffix == suffix]
    if not kinds:
        return None
    if suffix == ".toml":
        data = _toml_data(path)
        return next((k for k in kinds if data is not None and k.matches(data)), OTHER_TOML)
    line = _first_line(path)
    return next((k for k in kinds if k.matches(line)), None)


def read_back(path: str | Path, published: str | Path | None = None):
    """Read the file ``path`` (to be published as ``published``) with the reader of its kind; returns
    what the reader returned (None for a file of no kind). A refusal is an :class:`UnreadableOutput`
    naming the published file, its kind and the reader's located message."""
    path = Path(path)
    published = Path(published or path)
    kind = kind_of(path, published.name)
    if kind is None:
        return None
    module, _, function = kind.reader.partition(":")
    reader = getattr(importlib.import_module(module), function)
    try:
        return reader(path)
    except InputError as exc:
        where = ", ".join(w for w in (f"line {exc.line}" if exc.line is not None else None,
                                      exc.column) if w)
        raise UnreadableOutput(f"this command wrote a {kind.name} that its reader refuses"
                               f"{' (' + where + ')' if where else ''}: {exc.reason}", published) from None
