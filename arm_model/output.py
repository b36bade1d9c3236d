"""Every output of every command, complete or absent (one place).

A command that writes a folder does so inside :func:`output_folder`::

    with output_folder(args.output, inputs, "calibrate") as out:
        write_report(..., out.dir)          # any writer, into a fresh temporary folder beside -o
    log.info(f"report -> {args.output / 'report.html'}")

The temporary folder sits beside ``-o`` (same file system). When the block ends normally it is renamed
into place: an earlier output of the same command at ``-o`` is replaced only then, as a whole (no stale
file of an earlier run survives, and two runs into one ``-o`` at once never mix: the last to finish
wins, each complete). On any error, Ctrl-C or SIGTERM the temporary folder is removed and ``-o`` is as
it was. A command that writes one file uses :func:`output_file` (temporary file, then ``os.replace``).

Before anything is published, every file is read back by the reader that will read it
(:mod:`arm_model.readback`: a model file as ``--arm`` reads it, points as ``read_points`` ...); a file its
reader refuses is a bug of the toolkit, :class:`~arm_model.readback.UnreadableOutput` (exit 3), and
nothing is published.

Refused before any work, with an :class:`InputError` (exit 2): ``-o`` that is an input, holds an input,
is a file where a folder is expected (or the reverse), sits below a file, cannot be written, is not a
regular file or folder (a device such as ``/dev/null``, a FIFO, a socket: never replaced, never written
into), or is a non-empty folder that is not an earlier output of the same command (``-o .`` never
empties a folder of the user's). File names built from input text (arm names, measurement ids) go through
:func:`safe_name` and are checked by :meth:`Output.path` to stay inside the folder.
"""
from __future__ import annotations

import contextlib
import contextvars
import errno
import logging
import os
import shutil
import stat
import tempfile
import unicodedata
import zlib
from pathlib import Path

from .errors import InputError, resolved
from .readback import UnreadableOutput, read_as, read_back

__all__ = ["output_folder", "output_file", "check_suffix", "Output", "safe_name", "guard_output", "atomic_write_bytes",
           "MARKER", "published_outputs", "check_output", "write_error"]

log = logging.getLogger(__name__)

#: the file that marks a folder as an output of ``aacmm <command>`` (its text: ``aacmm <command>``)
MARKER = ".aacmm-output"
_MAX_NAME = 120


#: the temporary folders being written (a file written into one is part of that output, not an output of its
#: own) and the list that :func:`published_outputs` fills, for the current command
_STAGES: contextvars.ContextVar[tuple] = contextvars.ContextVar("aacmm_stages", default=())
_PUBLISHED: contextvars.ContextVar[list | None] = contextvars.ContextVar("aacmm_published", default=None)


@contextlib.contextmanager
def published_outputs(into: list):
    """Append to ``into`` every output (``-o`` file or folder) published while the block runs, so that
    what ends the command later (Ctrl-C, an error) can say what is already in place."""
    token = _PUBLISHED.set(into)
    try:
        yield into
    finally:
        _PUBLISHED.reset(token)


def _published(final: Path) -> None:
    into = _PUBLISHED.get()
    if into is not None and not any(_inside(final, s) for s in _STAGES.get()):
        into.append(final)


def safe_name(text: str, suffix: str = "") -> str:
    """A file name made from input text (an arm name, a measurement id), that cannot leave its folder.

    Letters, digits and ``. _ + -`` are kept; every other character (``/``, ``\\``, ``:``, spaces,
    control characters, markup) becomes ``_``; a leading dot becomes ``_`` (no hidden files, no
    ``..``); an empty text gives ``_``; a name longer than 120 bytes (UTF-8: 40 CJK characters) is cut
    and given a checksum of the whole text, so that the suffixes of a command's files still fit a file
    name's 255 bytes. The same text always gives the same name, so a reader finds what a writer wrote.
    """
    text = unicodedata.normalize("NFC", str(text))
    name = "".join(c if (c.isalnum() or c in "._+-") and c.isprintable() else "_" for c in text)
    if name.startswith("."):
        name = "_" + name[1:]
    if not name:
        name = "_"
    raw = name.encode("utf-8")
    if len(raw) > _MAX_NAME:            # bytes, not characters: a file name holds 255 bytes
        name = f"{raw[:_MAX_NAME - 9].decode('utf-8', 'ignore')}-{zlib.crc32(text.encode('utf-8')):08x}"
    return name + suffix


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _through_link(final: Path, what: str) -> Path:
    """The output path ``final``, or the target of the symbolic link it is (written through, the link kept); a link
    whose target's folder does not exist is an InputError: as a shell's > does, no folder is made for it elsewhere,
    outside every path the user named. A link to what is not ``what`` ("a regular file", "a folder") nor a folder
    (``/dev/stdout``: a link to a pipe, whose target is no path) is refused as such, named as given."""
    if not final.is_symlink():
        return final
    _refuse_special(final, what)
    target = resolved(final)
    if not target.parent.is_dir():
        raise InputError(f"the output is a symbolic link to {target}, whose folder does not exist (a link is "
                         "written through, never a folder made for it elsewhere)", final)
    return target


def guard_output(out: str | Path, inputs=(), input_folders=()) -> Path:
    """Refuse an output (file or folder) that is one of the inputs or holds one, or that lies inside one of
    ``input_folders`` (folders the command reads files from, ``ring --signals DIR``), by resolved path, or that is
    an input file under another name (a hard link: ``tip -o copy.csv`` replaced ``copy.csv``, a link to the points
    file)."""
    out = Path(out)
    ro = resolved(out)
    for p in (*inputs, *input_folders):
        if p is None:
            continue
        rp = resolved(p)
        if rp == ro:
            raise InputError("refusing to write the output over an input file", out)
        if _same_file(ro, rp):
            raise InputError(f"refusing to write the output over an input file: it is the input {p} under another "
                             "name (a hard link)", out)
        if _inside(rp, ro):
            raise InputError(f"refusing to write the output over an input: the output folder holds the "
                             f"input {p} and is replaced as a whole; choose another output folder", out)
    for p in input_folders:
        if p is not None and _inside(ro, resolved(p)):
            raise InputError(f"refusing to write the output into the input folder {p} (the command reads its "
                             "files); choose an output outside it", out)
    return out


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` both exist and are one file (:func:`os.path.samefile`: device and inode)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def _mode(umask_mode: int) -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask_mode & ~umask


def _special(path: Path) -> str | None:
    """What ``path`` is when it exists (links followed) and is neither a regular file nor a folder: "a
    device", "a FIFO (named pipe)", "a socket" (or "not a regular file"); else None."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a socket" if stat.S_ISSOCK(mode) else \
        "not a regular file"


def _refuse_special(path: Path, what: str) -> None:
    kind = _special(path)
    if kind is not None:
        raise InputError(f"the output exists and is {kind}, not {what}: it is never replaced nor written into; "
                         f"name a new {what.removeprefix('a ')}", path)


def _oserror(exc: OSError, what: str, path: Path) -> InputError:
    reason = exc.strerror or str(exc)
    if exc.errno == errno.ENOTDIR:
        reason = "a file is in the way (a folder is expected)"
    return InputError(f"cannot {what}: {reason}", path)


#: errors of a write that the output's place causes (disk full, quota, file size limit): named after the output
_WRITE_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


def write_error(exc: OSError, stage: Path, final: Path, what: str) -> InputError | None:
    """The InputError of an OSError raised while the output was being written into ``stage`` (the
    temporary folder or file), naming where the file would have been published (the system names the
    temporary path, or nothing: a full disk fails a write, not an open); None for an OSError of
    something else (an input)."""
    names = [Path(os.path.abspath(os.fsdecode(f))) for f in (exc.filename, exc.filename2) if f is not None]
    name = next((n for n in names if _inside(n, stage)), None)      # a copy names its source first
    inside = name is not None
    if not inside and exc.errno not in _WRITE_ERRNOS:
        return None
    where = final / name.relative_to(stage) if inside and name != stage else final
    return InputError(f"cannot write {what}: {exc.strerror or exc}; nothing written", where)


def _published_error(exc: InputError | UnreadableOutput, stage: Path, final: Path):
    """``exc`` naming where its file would have been published, when it names a file of the temporary
    folder (a file of the output refused while being written or read back); else None."""
    if exc.path is None or not _inside(Path(os.path.abspath(exc.path)), stage):
        return None
    where = final / Path(os.path.abspath(exc.path)).relative_to(stage)
    if isinstance(exc, UnreadableOutput):
        return UnreadableOutput(exc.reason, where)
    return InputError(exc.reason, where, exc.line, exc.column)


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; the ones created, outermost first."""
    missing = []
    p = folder
    while not p.exists():
        if p.is_symlink():
            raise InputError("the output's folder is a broken symbolic link", p)
        missing.append(p)
        p = p.parent
    if not p.is_dir():
        raise InputError("the output would be below a file, not a folder", p)
    created = []
    for q in reversed(missing):
        try:
            q.mkdir()
        except FileExistsError:
            if not q.is_dir():
                raise InputError("the output would be below a file, not a folder", q) from None
            continue
        except OSError as exc:
            _remove_empty(created)
            raise _oserror(exc, "create the output's folder", q) from None
        created.append(q)
    return created


def _remove_empty(created: list[Path]) -> None:
    for q in reversed(created):
        with contextlib.suppress(OSError):
            q.rmdir()


class Output:
    """The temporary folder a command writes into (``dir``); see :func:`output_folder`."""

    def __init__(self, stage: Path, final: Path):
        self.dir = stage
        self.final = final
        self._names: dict[str, str] = {}

    def path(self, *parts: str, source: str | None = None) -> Path:
        """The path of a file inside the folder (its parent folders created). Each part must be one
        plain name (use :func:`safe_name` for input text); two different sources that give the same
        name are refused. ``source`` is the input text the name was made from, for the message."""
        for part in parts:
            if not part or part in (".", "..") or "/" in part or "\\" in part or "\0" in part:
                raise ValueError(f"not a plain file name: {part!r}")
        rel = "/".join(parts)
        key = source if source is not None else rel
        other = self._names.setdefault(rel, key)
        if other != key:
            raise InputError(f"'{source}' and '{other}' give the same output file name '{rel}'; rename one")
        p = self.dir.joinpath(*parts)
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def published(self, path: str | Path) -> Path:
        """Where a file written into the temporary folder will be once published."""
        return self.final / Path(path).relative_to(self.dir)


def _owner(folder: Path) -> str | None:
    """``"aacmm <command>"`` for an earlier output, ``""`` for an empty folder, None otherwise."""
    try:
        if not os.listdir(folder):
            return ""
        return (folder / MARKER).read_text(encoding="utf-8").strip()
    except (OSError, UnicodeDecodeError):
        return None


def _not_ours(final: Path, owner: str | None, command: str) -> InputError:
    what = f"an output of '{owner}'" if owner and owner.startswith("aacmm ") else "not an earlier output of aacmm"
    return InputError(f"the output folder exists, is not empty and is {what}; an output folder is replaced "
                      f"as a whole, so name a new or empty folder (or an earlier output of aacmm {command})",
                      final)


def _check_folder(final: Path, command: str) -> None:
    if not final.exists():
        return
    _refuse_special(final, "a folder")
    if not final.is_dir():
        raise InputError("the output must be a folder, but a file of that name exists", final)
    if _inside(Path.cwd().resolve(), final):
        raise InputError("the output folder would replace the current folder (or one above it); "
                         "name a new folder", final)
    if not os.access(final, os.R_OK | os.X_OK):
        raise InputError("cannot read the output folder: permission denied", final)
    owner = _owner(final)
    if owner not in ("", f"aacmm {command}"):
        raise _not_ours(final, owner, command)


def _publish(stage: Path, final: Path, command: str) -> None:
    """Rename ``stage`` to ``final``. An existing ``final`` is first moved aside (atomically, so no
    other run can change it meanwhile), checked to be an earlier output of ``command`` (else put back
    and refused) and removed after."""
    aside = []
    try:
        for _ in range(1000):
            try:
                os.rename(stage, final)
                break
            except OSError as exc:
                if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                    raise
            old = Path(tempfile.mkdtemp(prefix=f".{final.name}.old-", dir=final.parent))
            try:
                os.rename(final, old)        # replaces the empty folder just made
            except FileNotFoundError:        # another run moved it: try again
                old.rmdir()
                continue
            owner = _owner(old)
            if owner not in ("", f"aacmm {command}"):
                with contextlib.suppress(OSError):
                    os.rename(old, final)
                    raise _not_ours(final, owner, command)
                raise InputError(f"the output folder was replaced meanwhile by something else, now at {old}",
                                 final)
            aside.append(old)
        else:
            raise InputError("the output folder keeps being replaced by other runs", final)
    finally:
        for old in aside:
            shutil.rmtree(old, ignore_errors=True)


def check_output(stage: Path, final: Path) -> None:
    """Read back every file of a command's output before it is published: ``stage`` the temporary folder
    (or file), ``final`` where it will be published. Raises :class:`UnreadableOutput` for the first
    file refused (in name order)."""
    files = [stage] if stage.is_file() else sorted(p for p in stage.rglob("*") if p.is_file() and p.name != MARKER)
    for p in files:
        read_back(p, final if p == stage else final / p.relative_to(stage))


@contextlib.contextmanager
def output_folder(final: str | Path, inputs=(), command: str = "", input_folders=()):
    """Write a command's output folder complete or not at all (see the module's doc).

    Args:
        final: the ``-o`` folder.
        inputs: the command's input files and folders (``None`` entries ignored): never written over,
            never inside the output folder.
        command: the subcommand (``"calibrate"``, ``"study montecarlo"``); an existing non-empty folder
            is replaced only if an earlier run of the same command wrote it.
        input_folders: folders the command reads files from (``None`` entries ignored): the output is never
            one of them, inside one, nor holds one.
    Yields:
        an :class:`Output`; write into ``out.dir``.
    """
    final = Path(final)
    guard_output(final, inputs, input_folders)
    final = Path(os.path.abspath(final))
    final = _through_link(final, "a folder")
    if final.name in ("", ".", ".."):
        raise InputError("name an output folder", final)
    _check_folder(final, command)
    created = _make_parents(final.parent)
    try:
        stage = Path(tempfile.mkdtemp(prefix=f".{final.name}.tmp-", dir=final.parent))
    except OSError as exc:
        _remove_empty(created)
        raise _oserror(exc, "write the output folder", final) from None
    try:
        os.chmod(stage, _mode(0o777))
        (stage / MARKER).write_text(f"aacmm {command}\n", encoding="utf-8")
        token = _STAGES.set(_STAGES.get() + (stage,))
        try:
            yield Output(stage, final)
        finally:
            _STAGES.reset(token)
        n_files = sum(1 for p in stage.rglob("*") if p.is_file()) - 1     # counted before another run may
        check_output(stage, final)                                          # replace the published folder
        _publish(stage, final, command)
        _published(final)
        log.debug(f"{final}: {n_files} file(s) written")
    except (OSError, InputError, UnreadableOutput) as exc:
        shutil.rmtree(stage, ignore_errors=True)
        _remove_empty(created)
        named = write_error(exc, stage, final, "the output folder") if isinstance(exc, OSError) else \
            _published_error(exc, stage, final)
        if named is None:
            raise
        raise named from None
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        _remove_empty(created)
        raise


@contextlib.contextmanager
def output_file(final: str | Path, inputs=(), writes: str | None = None):
    """Write one output file complete or not at all: yields a temporary path beside ``final``;
    when the block ends normally it replaces ``final`` (``os.replace``), else it is removed. A symbolic
    link at ``final`` is followed: its target is replaced, the link stays. ``writes``: the suffix of the
    format written (".csv", ".urdf", ".html", ".png"); a name whose suffix the toolkit reads as another
    format (``tip -o out.json``: every reader would take it as JSON) is an InputError before any work."""
    final = Path(final)
    guard_output(final, inputs)         # over an input: said first
    check_suffix(final, writes)
    final = _through_link(final, "a regular file")      # written through the link (as a shell's > does), the link kept
    if final.is_dir():
        raise InputError("the output is a file, but a folder of that name exists", final)
    if final.name in ("", ".", ".."):
        raise InputError("name an output file", final)
    _refuse_special(final, "a regular file")
    created = _make_parents(final.parent)
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{final.name}.tmp-", suffix=final.suffix, dir=final.parent)
    except OSError as exc:
        _remove_empty(created)
        raise _oserror(exc, "write the output file", final) from None
    tmp = Path(tmp_name)
    try:
        os.fchmod(fd, _mode(0o666))      # mkstemp makes 0600; outputs get the usual mode
        os.close(fd)
        yield tmp
        if final.is_dir():
            raise InputError("the output is a file, but a folder of that name exists", final)
        _refuse_special(final, "a regular file")        # made meanwhile
        if not any(_inside(final, s) for s in _STAGES.get()):      # else read back with its folder
            check_output(tmp, final)
        os.replace(tmp, final)
        _published(final)
        log.debug(f"{final}: written ({final.stat().st_size} bytes)")
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        _remove_empty(created)
        named = write_error(exc, tmp, final, "the output file") if isinstance(exc, OSError) else \
            _published_error(exc, tmp, final) if isinstance(exc, (InputError, UnreadableOutput)) else None
        if named is None:
            raise
        raise named from None


def check_suffix(final: Path, writes: str | None) -> None:
    """An output file named ``final`` holds a ``writes`` file (its suffix, e.g. ".csv"; None: any): its name
    must not have the suffix of another format the toolkit reads (:func:`arm_model.readback.read_as`), or the
    file would be refused by its own read-back and misread by every command given it."""
    suffix = final.suffix.lower()
    if writes is None or _FORMATS.get(suffix, suffix[1:].upper()) == _FORMATS.get(writes.lower()):
        return
    other = read_as(suffix)
    if other is not None:
        raise InputError(f"a '{final.suffix}' file is read as {other} by the toolkit, but this command writes "
                         f"{writes[1:].upper()}: name the output '{writes}' (or with a suffix no reader takes)", final)
    if suffix in _FORMATS:      # view --html x.png: a page no image viewer opens, a screenshot no browser shows
        raise InputError(f"a '{final.suffix}' file is {_FORMATS[suffix]}, but {_FORMATS[writes.lower()]} is written "
                         f"there: name the output '{writes}' (or with a suffix of no other format)", final)


#: the suffixes of formats a file's name promises (an output named with another format's is refused)
_FORMATS = {".html": "HTML", ".htm": "HTML", ".xhtml": "HTML", ".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG",
            ".gif": "GIF", ".webp": "WebP", ".svg": "SVG", ".pdf": "PDF", ".bmp": "BMP", ".tif": "TIFF",
            ".tiff": "TIFF", ".csv": "CSV", ".toml": "TOML", ".urdf": "URDF", ".json": "JSON", ".zip": "ZIP",
            ".gz": "gzip", ".npy": "NumPy", ".npz": "NumPy"}


def atomic_write_bytes(path: str | Path, data: bytes, inputs=()) -> Path:
    """Write ``data`` to the file ``path`` complete or not at all (never over an input)."""
    path = Path(path)
    with output_file(path, inputs) as tmp:
        tmp.write_bytes(data)
    return path

