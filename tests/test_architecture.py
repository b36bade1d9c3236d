"""docs/architecture.md against the code: every file and name it points to exists, and no import runs up
the floors it describes (arm_model below calibration and correction, which do not import each other,
viz on top)."""
from __future__ import annotations

import ast
import functools
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


@functools.cache
def _parse(text: str) -> ast.Module:
    """The syntax tree of a module's ``text``, parsed once for the checks of this file (they only read it)."""
    return ast.parse(text)


def _tree(path) -> ast.Module:
    return _parse(path.read_text(encoding="utf-8"))


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
    for node in ast.walk(_tree(path)):
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


# -- the module graph: no cycle, counting imports inside functions -------------------------------------

def _module_name(path, root=ROOT) -> str:
    """``arm_model/sim/ik.py`` -> ``arm_model.sim.ik``; a package's ``__init__.py`` is the package."""
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _source(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The module a ``from ... import`` statement of ``module`` (a package's ``__init__`` when
    ``is_package``) reads from, its relative dots resolved."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base[:len(base) - node.level + (1 if is_package else 0)]
    return ".".join(base + ([node.module] if node.module else []))


def _import_targets(module: str, is_package: bool, tree: ast.AST, modules: set[str]):
    """(line, imported module) of every import statement anywhere in ``tree`` (inside functions, under
    ``if TYPE_CHECKING`` too) that lands in ``modules``. A relative import is resolved against ``module``;
    ``from pkg import name`` is an edge to ``pkg.name`` when that is a module, else to ``pkg``; ``import
    a.b.c`` is an edge to ``a.b.c`` (or its longest prefix that is a module of the project)."""
    def landing(name):
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, landing(a.name)
        elif isinstance(node, ast.ImportFrom):
            src = _source(module, is_package, node)
            for a in node.names:
                sub = f"{src}.{a.name}"
                yield node.lineno, sub if sub in modules else landing(src)


def module_graph(root=ROOT, packages=tuple(FLOORS)) -> dict[str, dict[str, int]]:
    """module -> {imported module: line of the first such import} over every module of ``packages``."""
    paths = {_module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}
    graph: dict[str, dict[str, int]] = {}
    for module, path in paths.items():
        tree = _tree(path)
        edges = graph.setdefault(module, {})
        for line, target in _import_targets(module, path.name == "__init__.py", tree, set(paths)):
            if target is not None and target != module:
                edges.setdefault(target, line)
    return graph


def import_groups(graph: dict[str, dict[str, int]]) -> list[set[str]]:
    """The strongly connected groups of more than one module (each module of a group imports every other
    one, directly or not): Tarjan's algorithm, iterative."""
    index, low, on_stack, stack, groups, counter = {}, {}, set(), [], [], [0]
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.add(member)
                    if member == node:
                        break
                if len(group) > 1:
                    groups.append(group)
    return groups


def import_cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """One cycle (``[a, b, ..., a]``) for each group of :func:`import_groups`: a shortest path from the
    group's first module back to it."""
    cycles = []
    for group in import_groups(graph):
        first = min(group)
        paths, frontier = {first: [first]}, [first]         # breadth first inside the group, back to first
        cycle = None
        while frontier and cycle is None:
            nxt = []
            for node in frontier:
                for child in sorted(graph[node]):
                    if child == first:
                        cycle = paths[node] + [first]
                        break
                    if child in group and child not in paths:
                        paths[child] = paths[node] + [child]
                        nxt.append(child)
                if cycle:
                    break
            frontier = nxt
        cycles.append(cycle)
    return sorted(cycles)


def _describe(cycle: list[str], graph) -> str:
    steps = [f"{a} (line {graph[a][b]}) -> {b}" for a, b in zip(cycle[:-1], cycle[1:], strict=True)]
    return "\n    ".join(steps)


def test_no_import_cycle_between_modules():
    graph = module_graph()
    assert len(graph) > 80 and sum(map(len, graph.values())) > 200       # the graph found the modules
    groups = sorted(import_groups(graph), key=min)
    assert not groups, "import cycles between modules (imports inside functions count):\n  " + "\n  ".join(
        f"{len(g)} modules tied: {', '.join(sorted(g))}\n  one cycle:\n    {_describe(c, graph)}"
        for g, c in zip(groups, import_cycles(graph), strict=True))


def test_the_cycle_check_sees_a_cycle_through_a_function_level_import(tmp_path):
    """The check itself, on a small tree: a relative import at the top, a submodule named by ``from pkg
    import name``, and the import inside a function that closes the circle."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .sub import b\n")
    (pkg / "sub" / "b.py").write_text("import os\nfrom pkg import c\n")
    (pkg / "c.py").write_text("def f():\n    from .a import g\n")
    (pkg / "d.py").write_text("from pkg.sub import b\n")
    graph = module_graph(tmp_path, ("pkg",))
    assert graph["pkg.a"] == {"pkg.sub.b": 1} and graph["pkg.sub.b"] == {"pkg.c": 2}
    assert graph["pkg.c"] == {"pkg.a": 2} and graph["pkg.d"] == {"pkg.sub.b": 1}
    assert import_cycles(graph) == [["pkg.a", "pkg.sub.b", "pkg.c", "pkg.a"]]
    (pkg / "c.py").write_text("def f():\n    import os\n")
    assert import_cycles(module_graph(tmp_path, ("pkg",))) == []


# -- no function over 100 lines ------------------------------------------------------------------------

#: the longest function (or method) the source may hold, in lines from its ``def`` to its last line
MAX_FUNCTION_LINES = 100


def long_functions(root=ROOT, packages=tuple(FLOORS), limit: int = MAX_FUNCTION_LINES) -> list[str]:
    """``path:line name (n lines)`` of every function of ``packages`` longer than ``limit`` lines (nested
    functions are counted within their parent and on their own)."""
    out = []
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            for node in ast.walk(_tree(path)):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = node.end_lineno - node.lineno + 1
                    if n > limit:
                        out.append(f"{path.relative_to(root)}:{node.lineno} {node.name} ({n} lines)")
    return out


def test_no_function_over_100_lines():
    long = long_functions()
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines (split them into named steps): {long}"


def test_the_length_check_sees_a_long_function(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "m.py").write_text("def short():\n    return 1\n\n\nclass C:\n    def long(self):\n"
                              + "        x = 1\n" * 100 + "        return x\n")
    assert long_functions(tmp_path, ("pkg",)) == ["pkg/m.py:6 long (102 lines)"]
    assert long_functions(tmp_path, ("pkg",), limit=102) == []


# -- shared plumbing is public -------------------------------------------------------------------------

def private_imports(root=ROOT, packages=tuple(FLOORS)) -> list[str]:
    """``path:line`` of every import, in ``packages``, of a ``_private`` module of the project or of a
    ``_private`` name of another module (a name shared across modules is public)."""
    paths = {_module_name(p, root): p for pkg in packages for p in sorted((root / pkg).rglob("*.py"))}
    out = []
    for module, path in paths.items():
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.Import):
                names = [(a.name, None) for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                src = _source(module, path.name == "__init__.py", node)
                names = [(src, a.name) for a in node.names]
            else:
                continue
            for src, name in names:
                if src.split(".")[0] not in packages:
                    continue
                private_module = any(p.startswith("_") and not p.startswith("__") for p in src.split("."))
                private_name = name is not None and name.startswith("_") and not name.startswith("__")
                if private_module or private_name:
                    out.append(f"{path.relative_to(root)}:{node.lineno} imports {src}"
                               + (f".{name}" if name else ""))
    return out


def test_no_private_module_or_name_is_imported_across_modules():
    bad = private_imports()
    assert not bad, f"private modules or names used by other modules (make them public): {bad}"


def test_the_privacy_check_sees_private_imports(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "_hidden.py").write_text("X = 1\n")
    (pkg / "a.py").write_text("def _f():\n    pass\n")
    (pkg / "b.py").write_text("import os\nfrom . import _hidden\nfrom .a import _f\nfrom pkg.a import __doc__\n")
    assert private_imports(tmp_path, ("pkg",)) == ["pkg/b.py:2 imports pkg._hidden", "pkg/b.py:3 imports pkg.a._f"]


def _arm_model_floors() -> list[list[str]]:
    """The floors of the doc's block under "The floors inside `arm_model`", bottom first: each a list of
    module names (``io``), packages (``sim/``) or modules of a package (``sim/cli``)."""
    text = DOC.read_text(encoding="utf-8")
    block = re.search(r"### The floors inside `arm_model`.*?```\n(.*?)```", text, flags=re.S).group(1)
    texts: list[str] = []
    for line in block.splitlines():
        if line[:14].strip():
            texts.append("")
        texts[-1] += " " + line[14:]
    return [[n.strip() for n in re.sub(r"\([^)]*\)", "", s).split(",") if n.strip()] for s in texts]


def test_the_floors_inside_arm_model_are_the_docs():
    floors = _arm_model_floors()
    assert len(floors) >= 5
    where = {name: k for k, floor in enumerate(floors) for name in floor}
    for name in where:
        assert (ROOT / "arm_model" / f"{name.rstrip('/')}{'' if name.endswith('/') else '.py'}").exists(), name

    def floor(module: str) -> int | None:
        parts = module.split(".")[1:]
        if not parts:
            return -1                       # the package's __init__: lazy names only
        for key in ("/".join(parts[:2]), parts[0] + "/", parts[0]):
            if key in where:
                return where[key]
        return None

    graph = module_graph()
    unplaced = [m for m in graph if m.startswith("arm_model") and floor(m) is None]
    assert not unplaced, f"modules of arm_model on no floor of docs/architecture.md: {unplaced}"
    up = [f"{m} (floor {floor(m)}) imports {t} (floor {floor(t)})" for m, targets in graph.items()
          if m.startswith("arm_model") for t in targets if t.startswith("arm_model") and floor(t) > floor(m)]
    assert not up, f"imports that run up the floors of arm_model in docs/architecture.md: {up}"
