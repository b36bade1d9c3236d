"""The folder of a live session, written as the session runs (docs/live.md, "What a session promises").

Unlike every other output of the toolkit (written whole or not at all, :mod:`arm_model.output`), a
session folder grows while the operator measures, so that a crash loses as little as possible:

* the folder is created new: an existing folder that is not empty is never used (a restarted session
  never overwrites an earlier one), and nothing is written outside it;
* every file is only ever appended to, whole lines at a time (one ``write`` system call a file per
  flush), so a killed process leaves files that end at a complete line;
* raw samples are flushed at least every :data:`FLUSH_S` seconds (a point, a contact and an over-force
  event at once); ``session.json`` is replaced atomically at every flush, and says ``"status":
  "running"`` until the session closes (``complete``, ``interrupted``, ``terminated``, ``stopped``):
  a folder whose status is still ``running`` after its process ended was killed, and holds everything
  up to ``updated``.

Files: ``samples.csv`` (the stream as received), ``points.csv`` (points format, one row a contact, the
exact sample values), ``tips.csv`` (``aacmm tip``'s output for it, with uncertainties), ``contacts.csv``,
``events.csv``, ``features.csv``, ``artefacts.toml`` (with a plan) and ``session.json``.
"""
from __future__ import annotations

import contextlib
import datetime
import json
import os
import time
from collections.abc import Iterable
from pathlib import Path

from ..errors import InputError, resolved
from ..output import MARKER, guard_output

__all__ = ["SessionRecord", "FILES", "FLUSH_S", "read_status", "STATUS_FILE", "check_new_folder"]

#: the longest time raw samples wait in memory before they are written [s]
FLUSH_S = 0.5
STATUS_FILE = "session.json"
#: the files of a session folder, by role
FILES = {"samples": "samples.csv", "points": "points.csv", "tips": "tips.csv", "contacts": "contacts.csv",
         "events": "events.csv", "features": "features.csv", "artefacts": "artefacts.toml"}
COMMAND = "aacmm live"


def read_status(folder: str | Path) -> dict | None:
    """The ``session.json`` of a session folder (None when it has none or it does not read), with
    ``"closed"``: False when the status is still ``running`` (a killed session, or one still running)."""
    try:
        data = json.loads((Path(folder) / STATUS_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict):
        return None
    data["closed"] = data.get("status") != "running"
    return data


def _refuse_existing(folder: Path) -> None:
    if not folder.exists():
        return
    if not folder.is_dir():
        raise InputError("the session folder must be a new folder, but a file of that name exists", folder)
    try:
        empty = not os.listdir(folder)
    except OSError as exc:
        raise InputError(f"cannot read the session folder: {exc.strerror}", folder) from None
    if empty:
        return
    status = read_status(folder)
    if status is not None and status.get("command") == COMMAND:
        state = (f"an earlier session (status '{status.get('status')}'"
                 + ("" if status["closed"] else ": it was never closed, so its process was killed or is still "
                                                 f"running; its files hold what it wrote up to {status.get('updated')}")
                 + ")")
    else:
        state = "a folder that is not empty"
    raise InputError(f"the session folder exists and is {state}; a session never writes into an existing "
                     "folder: name a new one (e.g. with the date)", folder)


def check_new_folder(folder: str | Path, inputs: Iterable = ()) -> Path:
    """Refuse (InputError) a session folder that exists and is not empty, or that is or holds an input;
    nothing is created."""
    folder = Path(folder)
    guard_output(folder, inputs)
    _refuse_existing(folder)    # as named, links followed: a link to a pipe (/dev/stdout) resolves to no path
    return resolved(folder) if folder.is_symlink() else Path(os.path.abspath(folder))


class SessionRecord:
    """Append-only writer of a session folder (see the module doc).

    Args:
        folder: the session folder (created with its parents; an existing folder must be empty).
        inputs: the files the session reads (never written over, never inside the folder).
        status: the first content of ``session.json`` (what the session is: source, arm, options).
    """

    def __init__(self, folder: str | Path, inputs: Iterable = (), status: dict | None = None):
        folder = check_new_folder(folder, inputs)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd = os.open(folder / MARKER, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            raise InputError("another session started in this folder at the same time", folder) from None
        except OSError as exc:
            raise InputError(f"cannot create the session folder: {exc.strerror}", folder) from None
        try:
            _write_all(fd, f"{COMMAND}\n".encode())
        except OSError as exc:
            raise _write_failed(exc, folder / MARKER) from None
        finally:
            os.close(fd)
        self.folder = folder
        self._fds: dict[str, int] = {}
        self._buf: dict[str, list[str]] = {}
        self.status = {"command": COMMAND, "status": "running", "pid": os.getpid(),
                       "started": _now(), "updated": _now(), **(status or {})}
        self.next_flush = time.monotonic() + FLUSH_S
        self.closed = False
        self._write_status()

    def path(self, role: str) -> Path:
        return self.folder / FILES[role]

    def open(self, role: str, header: str | None = None) -> None:
        """Create the file of ``role`` (never an existing one), with a ``header`` line."""
        if role in self._fds:
            return
        try:
            self._fds[role] = os.open(self.path(role), os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o666)
        except OSError as exc:
            raise _write_failed(exc, self.path(role)) from None
        self._buf[role] = []
        if header is not None:
            self._buf[role].append(header if header.endswith("\n") else header + "\n")

    def queue(self, role: str) -> list:
        """The list of lines queued for the file of ``role`` (append whole lines to it; the fastest way)."""
        return self._buf[role]

    def append(self, role: str, text: str) -> None:
        """Queue whole lines (``text`` ends with a line end) for the file of ``role``."""
        self._buf[role].append(text)

    def write_file(self, role: str, text: str) -> None:
        """Write a small file whole (``artefacts.toml``), once."""
        try:
            fd = os.open(self.path(role), os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            try:
                _write_all(fd, text.encode("utf-8"))
            finally:
                os.close(fd)
        except OSError as exc:
            raise _write_failed(exc, self.path(role)) from None

    def flush(self, update: dict | None = None) -> None:
        """Write every queued line (one write a file); with ``update``, also replace ``session.json`` with
        it merged (at the timed flushes and at the end: its counts lag the files by at most
        :data:`FLUSH_S`)."""
        for role, buf in self._buf.items():
            if buf:
                data = "".join(buf).encode("utf-8")
                buf.clear()
                fd = self._fds[role]
                size = os.fstat(fd).st_size
                try:
                    _write_all(fd, data)
                except OSError as exc:      # a full disk: a part written is cut off, the file ends at a whole line
                    with contextlib.suppress(OSError):
                        os.ftruncate(fd, size)
                    raise _write_failed(exc, self.path(role)) from None
        if update is not None:
            self.status.update(update)
            self.status["updated"] = _now()
            self._write_status()
            self.next_flush = time.monotonic() + FLUSH_S

    def close(self, status: str, message: str, update: dict | None = None) -> None:
        """Flush, fsync and close every file; ``session.json`` says ``status`` and ``message``."""
        if self.closed:
            return
        self.flush({**(update or {}), "status": status, "message": message, "closed": _now()})
        for fd in self._fds.values():
            try:
                os.fsync(fd)
            except OSError:
                pass
            os.close(fd)
        self._fds.clear()
        self.closed = True

    def _write_status(self) -> None:
        tmp = self.folder / f".{STATUS_FILE}.tmp"
        try:
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(self.status, fh, indent=1, allow_nan=False, default=str)
                fh.write("\n")
            os.replace(tmp, self.folder / STATUS_FILE)
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise _write_failed(exc, self.folder / STATUS_FILE) from None


def _write_failed(exc: OSError, path: Path) -> InputError:
    """A write of the session folder that the system refused (a full disk, a quota): the file named, and what the
    folder keeps (every file ends at a whole line; ``session.json`` at its last write, ``"status": "running"``)."""
    return InputError(f"cannot write the session's file: {exc.strerror or exc}; the session stops, and its folder "
                      "keeps what was written before (every file ends at a whole line; session.json says "
                      "\"running\" as of its last write)", path)


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _now() -> str:
    return datetime.datetime.now(datetime.UTC).astimezone().isoformat(timespec="milliseconds")
