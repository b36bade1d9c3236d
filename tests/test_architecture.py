"""docs/architecture.md against the code: every file and name it points to exists, and no import runs up
the floors it describes (arm_model below calibration and correction, which do not import each other,
viz on top)."""
from __future__ import annotations

import ast
import importlib
import inspect
import re

import pytest

from conftest import ROOT

DOC = ROOT / "docs" / "architecture.md"
#: the floor of each package; an import may only go to a lower floor (or inside its own package)
FLOORS = {"arm_model": 0, "calibration": 1, "correction": 1, "viz": 2}
#: backticked words of the doc that are command-line words, not code
CLI_WORDS = {"aacmm", "-o"}


def _spans() -> list[str]:
    """The backticked spans of the doc, outside its fenced blocks."""
    text = re.sub(r"```.*?```", "", DOC.read_text(encoding="utf-8"), flags=re.S)
    return re.findall(r"`([^`\n]+)`", text)


def _paths() -> list:
    """Every file or folder the doc names; a bare ``x.py`` is in the folder of the last full path
    before it (``calibration/problem.py``, ``solver.py``)."""
    out, folder = [], None
    for s in _spans():
        if not re.fullmatch(r"[\w/]+(\.py)?/?", s) or not (s.endswith(".py") or s.endswith("/")):
            continue
        if "/" in s.rstrip("/"):
            folder = (ROOT / s).parent if s.endswith(".py") else ROOT / s.rstrip("/")
            out.append(ROOT / s)
        elif s.endswith("/"):
            out.append(ROOT / s)
        else:
            assert folder is not None, f"{s} is named before any folder"
            out.append(folder / s)
    return out


def _module(path) -> str:
    return ".".join(path.relative_to(ROOT).with_suffix("").parts)


def test_every_path_the_doc_names_exists():
    paths = _paths()
    assert len(paths) > 30      # the parser found the doc's paths
    missing = [str(p.relative_to(ROOT)) for p in paths if not p.exists()]
    assert not missing, f"docs/architecture.md names paths that do not exist: {missing}"


def test_every_name_the_doc_names_is_in_the_code():
    modules = [importlib.import_module(_module(p)) for p in _paths()
               if p.suffix == ".py" and p.parts[len(ROOT.parts)] in FLOORS]
    from arm_model.effects import Effect
    apply_args = set(inspect.signature(Effect.apply).parameters)
    missing, checked = [], 0
    for s in _spans():
        name = re.sub(r"\(.*\)$", "", s)
        if s in CLI_WORDS or s.endswith(".py") or not re.fullmatch(r"[A-Za-z_][\w.]*", name):
            continue
        checked += 1
        if "." in name:
            mod, _, attr = name.rpartition(".")
            if not hasattr(importlib.import_module(mod), attr):
                missing.append(s)
        elif not (any(hasattr(m, name) for m in modules) or hasattr(Effect, name) or name in apply_args
                  or importlib.util.find_spec(name) is not None):
            missing.append(s)
    assert checked > 20 and not missing, f"docs/architecture.md names what the code does not have: {missing}"


def _imports(path):
    """(line, top-level package) of every absolute import in ``path``, inside functions too."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module.split(".")[0]


@pytest.mark.parametrize("package", sorted(FLOORS))
def test_no_import_runs_up(package):
    up = [f"{path.relative_to(ROOT)}:{line} imports {top}"
          for path in sorted((ROOT / package).rglob("*.py"))
          for line, top in _imports(path)
          if top in FLOORS and top != package and FLOORS[top] >= FLOORS[package]]
    assert not up, f"imports that run up (or across) the floors of docs/architecture.md: {up}"


def test_the_import_check_sees_an_upward_import(tmp_path):
    """The check itself: an import inside a function is found."""
    f = tmp_path / "m.py"
    f.write_text("def f():\n    from calibration.loop import close_loop\n    import viz.scene\n")
    assert list(_imports(f)) == [(2, "calibration"), (3, "viz")]
