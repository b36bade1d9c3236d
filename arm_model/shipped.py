"""Files that ship with the toolkit: the nominal arm, the example campaigns and data.

In a source checkout they are the repository's ``urdf/`` and ``examples/``; an installed wheel carries a
copy under ``arm_model/_shipped/`` (made by ``setup.py`` at build time), so ``--arm aacmm7`` and
``aacmm examples DIR`` work from any folder without a clone. Light: no numpy at import.
"""
from __future__ import annotations

import functools
import hashlib
import shutil
from pathlib import Path

__all__ = ["SHIPPED_ARMS", "shipped_path", "arm_path", "version", "provenance", "copy_examples"]

_PACKAGE = Path(__file__).resolve().parent
#: shipped arms by name -> path relative to the shipped root
SHIPPED_ARMS = {"aacmm7": "urdf/aacmm7.dh.toml"}


def _root() -> Path:
    installed = _PACKAGE / "_shipped"
    return installed if installed.is_dir() else _PACKAGE.parent


def shipped_path(rel: str) -> Path:
    """Path of a shipped file or folder (``"urdf/aacmm7.dh.toml"``, ``"examples"``)."""
    return _root() / rel


def arm_path(value: str | Path) -> Path:
    """``value`` as a path; a shipped arm's name (``aacmm7``) that is not an existing file becomes
    the shipped description."""
    p = Path(value)
    name = str(value)
    if name in SHIPPED_ARMS and not p.exists():
        return shipped_path(SHIPPED_ARMS[name])
    return p


@functools.lru_cache(maxsize=1)
def version() -> str:
    """The installed version of aacmm-toolkit (looked up once a process: every summary records it)."""
    from importlib.metadata import PackageNotFoundError, version as _v
    try:
        return _v("aacmm-toolkit")
    except PackageNotFoundError:
        return "0+unknown"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def provenance(inputs) -> dict:
    """What every ``summary.json`` records: the toolkit's version and the SHA-256 of each input file
    (a folder: each file in it, sorted). ``inputs``: paths, or a ``{role: path}`` dict; None skipped."""
    paths = inputs.values() if isinstance(inputs, dict) else inputs
    files: dict[str, str] = {}
    for p in paths:
        if p is None:
            continue
        p = arm_path(p)                 # a shipped arm given by name: its file
        if p.is_dir():
            for f in sorted(q for q in p.rglob("*") if q.is_file()):
                files[str(f)] = _sha256(f)
        elif p.is_file():
            files[str(p)] = _sha256(p)
    return {"aacmm_version": version(), "input_sha256": files}


def copy_examples(dest: str | Path) -> list[Path]:
    """Copy the example campaigns and data (with their licences), the shipped arm descriptions (``arms/``,
    a template for your own DH table), the user docs and the README (``README.md``, which the docs link to as
    ``../README.md``; left out where ``dest`` has one of its own) into ``dest`` (created if needed), whole or not
    at all: copied into a temporary folder beside them first, the top-level entries (``campaigns/``, ``data/``,
    ``live/``, ``arms/``, ``docs/``, ``README.md``) then renamed into ``dest``. Refuses an entry that exists already
    (a file, a folder, a symbolic link, which would lead the copy outside ``dest``): nothing is written over or
    through. Returns the top-level entries written."""
    import os
    import tempfile

    from .errors import InputError, resolved
    from .output import write_error
    dest = Path(dest)
    src = shipped_path("examples")
    if not src.is_dir():
        raise InputError("the example files are not installed with this copy of the toolkit", src)
    pairs = [(sub, Path(sub.name)) for sub in sorted(src.iterdir()) if not sub.name.startswith((".", "__"))]
    pairs += [(shipped_path(rel), Path("arms") / Path(rel).name) for rel in SHIPPED_ARMS.values()]
    if shipped_path("docs").is_dir():
        pairs.append((shipped_path("docs"), Path("docs")))
    # the guides link to ../README.md (its first own measurement); a folder's own README.md is left as it is
    if shipped_path("README.md").is_file() and not os.path.lexists(dest / "README.md"):
        pairs.append((shipped_path("README.md"), Path("README.md")))
    files = [(f, t / f.relative_to(s)) for s, t in pairs if s.is_dir() for f in s.rglob("*")
             if f.is_file() and "__pycache__" not in f.parts]
    files += [(s, t) for s, t in pairs if s.is_file()]
    tops = list(dict.fromkeys(t.parts[0] for _, t in files))
    read = [src] + [s for s, _ in pairs if s.is_dir()]
    inside = next((r for r in read if resolved(dest).is_relative_to(resolved(r))), None)
    if inside is not None:      # the copy would walk its own output (and the next copy would ship it)
        raise InputError(f"refusing to write the examples into the folder {inside} they are copied from: choose a "
                         "folder outside it", dest)
    clashes = [dest / t for t in tops if os.path.lexists(dest / t)]
    if clashes:
        raise InputError(f"refusing to write over or into {len(clashes)} existing entr"
                         f"{'y' if len(clashes) == 1 else 'ies'}, e.g. {clashes[0]}: choose a new folder", dest)
    new_dest = not os.path.lexists(dest)
    dest.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=".examples.tmp-", dir=dest))
    moved: list[Path] = []
    try:
        for f, t in files:
            try:
                (stage / t).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(f, stage / t)
            except OSError as exc:      # a full disk: named where the file would have been, not the temporary copy
                raise write_error(exc, stage, dest, "the examples") or exc from None
        for t in tops:
            if os.path.lexists(dest / t):       # made meanwhile: never replaced
                raise InputError("refusing to write over an entry made while copying", dest / t)
            os.rename(stage / t, dest / t)
            moved.append(dest / t)
    except BaseException:
        for m in moved:
            shutil.rmtree(m, ignore_errors=True)
        shutil.rmtree(stage, ignore_errors=True)
        if new_dest:
            shutil.rmtree(dest, ignore_errors=True)
        raise
    shutil.rmtree(stage, ignore_errors=True)
    return [dest / t for t in tops]
