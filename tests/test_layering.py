"""The package's floors, checked on the source: every module of ``shipid/`` sits on one floor, imports only
modules on its own floor or below (never one above), and no chain of imports returns to where it started.

Data flow one way -- files -> log adapters -> ``TrialLog`` -> identify -> result -> validation -> uncertainty ->
report; control, routing and the glider take a model; campaigns run all of them; the CLI sits on top -- and the
floors below say the same in code.  Imports inside functions count like module-level ones: deferring an import
hides a loop from Python, not from this test.  A new module must be given a floor here (the test names it).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "shipid"

#: Floors from the bottom up: each a name and the dotted modules/packages (below ``shipid``) on it.  A module
#: takes the floor of its longest listed prefix.  ``""`` is the package's own ``__init__`` (the public API).
FLOORS = [
    ("foundation", ("_version", "_io", "_blas", "_jit", "datasets", "savitsky", "scaling", "results")),
    ("logs", ("logs",)),
    ("models", ("models",)),
    ("numerics", ("integrate", "_kernel", "simulate")),
    ("environment", ("environment",)),
    ("manoeuvres", ("manoeuvres",)),
    ("synthetic logs", ("synthetic",)),
    ("results", ("identify.result", "identify.verdict", "identify.plausibility")),
    ("identification", ("identify",)),
    ("validation", ("validation",)),
    ("uncertainty", ("uncertainty",)),
    ("report", ("report",)),
    ("applications", ("control", "routing", "glider")),
    # cross-validation and model choice use fits and validation, as campaigns do: they belong here
    ("campaigns", ("campaign", "crossval", "selection")),
    ("interface", ("commands", "cli", "__main__", "")),
]


def _module_name(path: Path, root: Path = PKG) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path, module: str | None = None, is_package: bool | None = None) -> list[tuple[int, str, bool]]:
    """``(line, dotted name, inside a function)`` of every import in ``path``: relative imports resolved against
    its package; ``from m import a`` gives ``m.a`` (a submodule, or a name of ``m``: :func:`import_graph` takes
    the longest prefix that is a module)."""
    if module is None:
        module = _module_name(path)
    if is_package is None:
        is_package = path.name == "__init__.py"
    package = module.split(".") if is_package else module.split(".")[:-1]
    out: list[tuple[int, str, bool]] = []

    def visit(node, local: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                out.extend((child.lineno, a.name, inner) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package[:len(package) - child.level + 1]
                    mod = ".".join(base + ([child.module] if child.module else []))
                else:
                    mod = child.module or ""
                out.extend((child.lineno, f"{mod}.{a.name}", inner) for a in child.names)
            visit(child, inner)

    visit(ast.parse(path.read_text(), filename=str(path)), False)
    return out


def import_graph(root: Path = PKG) -> tuple[dict[str, Path], dict[str, dict[str, int]]]:
    """Modules of the package at ``root`` and, per module, the package modules it imports (-> first line)."""
    files = {_module_name(f, root): f for f in sorted(root.rglob("*.py"))}
    top = root.name
    graph: dict[str, dict[str, int]] = {m: {} for m in files}
    for mod, f in files.items():
        for line, name, _ in _imports(f, mod, f.name == "__init__.py"):
            if name.split(".")[0] != top:
                continue
            parts = name.split(".")
            target = next((".".join(parts[:k]) for k in range(len(parts), 0, -1) if ".".join(parts[:k]) in files),
                          None)
            if target is not None and target != mod:
                graph[mod].setdefault(target, line)
    return files, graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The import loops: strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    counter = [0]

    def connect(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return found


def floor_of(module: str, floors=FLOORS) -> int | None:
    """Index of the floor of ``module`` (dotted, with the package name first), or None when it has none."""
    rel = module.split(".", 1)[1] if "." in module else ""
    best, best_len = None, -1
    for i, (_, prefixes) in enumerate(floors):
        for p in prefixes:
            if (rel == p or (p and rel.startswith(p + "."))) and len(p) > best_len:
                best, best_len = i, len(p)
    return best


def upward(graph: dict[str, dict[str, int]], files: dict[str, Path], floors=FLOORS) -> list[str]:
    bad = []
    for mod, targets in sorted(graph.items()):
        for target, line in sorted(targets.items()):
            a, b = floor_of(mod, floors), floor_of(target, floors)
            if a is not None and b is not None and b > a:
                bad.append(f"{files[mod].parent.name}/{files[mod].name}:{line} {mod} ({floors[a][0]}) imports "
                           f"{target} ({floors[b][0]})")
    return bad


def test_every_module_has_a_floor():
    files, _ = import_graph()
    assert len(files) > 50
    missing = sorted(m for m in files if floor_of(m) is None)
    assert not missing, "give these modules a floor in tests/test_layering.py FLOORS: " + ", ".join(missing)


def test_no_module_imports_a_floor_above_its_own():
    files, graph = import_graph()
    bad = upward(graph, files)
    assert not bad, "imports that climb a floor (move the shared code down, or the importer up):\n" + "\n".join(bad)


def test_no_import_cycles():
    _, graph = import_graph()
    loops = cycles(graph)
    assert not loops, "import cycles (each group imports itself through the others):\n" + "\n".join(
        " <-> ".join(c) for c in loops)


#: Where function-local imports are the rule, not the exception (the package docstring says why): the CLI's
#: commands load the library only for the command that runs.
LOCAL_IMPORTS_ALLOWED = ("commands", "cli", "__main__")


def unexplained_local_imports(root: Path = PKG) -> list[str]:
    """Function-local imports without a comment giving the reason (on the import's line, or on the comment line
    directly above the run of imports it belongs to)."""
    files, _ = import_graph(root)
    bad = []
    for mod, f in files.items():
        rel = mod.split(".", 1)[1] if "." in mod else ""
        if any(rel == p or rel.startswith(p + ".") for p in LOCAL_IMPORTS_ALLOWED):
            continue
        lines = f.read_text().split("\n")
        for line, name, local in _imports(f, mod, f.name == "__init__.py"):
            if not local:
                continue
            i = line - 1
            explained = "#" in lines[i]
            while not explained and i > 0 and lines[i - 1].strip().startswith(("import ", "from ")):
                i -= 1
                explained = "#" in lines[i]
            explained = explained or (i > 0 and lines[i - 1].strip().startswith("#"))
            if not explained:
                bad.append(f"{f.relative_to(root.parent)}:{line} imports {name.rsplit('.', 1)[0]} inside a function")
    return sorted(set(bad))


def test_function_local_imports_say_why():
    """An import inside a function hides a dependency from the reader (and, before this test, hid import
    loops): outside the CLI's commands it is kept only to defer an optional or heavy dependency, and says so."""
    bad = unexplained_local_imports()
    assert not bad, ("move these imports to the top of their module, or give the reason in a comment on the "
                     "line:\n" + "\n".join(bad))


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def test_the_checker_sees_a_planted_cycle_and_an_upward_import(tmp_path):
    """A package with a loop hidden in a function (a -> b at module level, b -> a inside a function) and a
    module that imports the floor above it: the checker finds both; without them it finds nothing."""
    root = tmp_path / "pkg"
    _write(root, {"__init__.py": "", "low/__init__.py": "", "high/__init__.py": "",
                  "low/a.py": "from . import b\n",
                  "low/b.py": "def f():\n    from .a import g\n    return g\n",
                  "low/c.py": "def f():\n    from ..high import h\n",
                  "high/h.py": "from ..low.a import b\n"})
    floors = [("low", ("low",)), ("high", ("high",)), ("top", ("",))]
    files, graph = import_graph(root)
    assert cycles(graph) == [["pkg.low.a", "pkg.low.b"]]
    assert [s.split(" imports ")[1] for s in upward(graph, files, floors)] == ["pkg.high.h (high)"]
    (root / "low/b.py").write_text("def f():\n    return 1\n")
    (root / "low/c.py").write_text("from .a import b\n")
    files, graph = import_graph(root)
    assert cycles(graph) == [] and upward(graph, files, floors) == []


@pytest.mark.parametrize("source, expected", [
    ("from ..simulate import simulate\n", {"shipid.simulate"}),
    ("def f():\n    from ..identify.batch import OutputErrorRefiner\n", {"shipid.identify"}),
    ("from .. import manoeuvres\n", {"shipid.manoeuvres"}),
    ("import shipid.validation as v\n", {"shipid.validation"}),
    ("from .base import Model\nfrom .._jit import rebind\nfrom ..logs import TrialLog\nimport numpy as np\n",
     {"shipid.models", "shipid._jit", "shipid.logs"}),
])
def test_the_parser_sees_every_import_form(tmp_path, source, expected):
    """Relative imports (also inside functions) resolve to the package's dotted names."""
    f = tmp_path / "m.py"
    f.write_text(source)
    found = {".".join(name.split(".")[:2]) for _, name, _ in _imports(f, "shipid.models.m", False)
             if name.split(".")[0] == "shipid" and len(name.split(".")) > 1}
    assert found == expected


def test_the_local_import_check_wants_a_reason(tmp_path):
    root = tmp_path / "pkg"
    _write(root, {"__init__.py": "", "a.py": "def f():\n    import json\n",
                  "b.py": "def f():\n    import numba  # optional extra\n",
                  "c.py": "def f():\n    # optional extras, only when plotting\n    import matplotlib\n    import numba\n",
                  "commands/__init__.py": "", "commands/x.py": "def f():\n    import json\n"})
    assert unexplained_local_imports(root) == ["pkg/a.py:2 imports json inside a function"]


#: Longest module (lines) that needs no stated reason.
MAX_LINES = 700


def test_long_modules_say_why_they_are_one_file():
    """A newcomer finds a room by its name; a module past ~700 lines holds several rooms unless it says why it
    does not: its first line is ``# Why one file: <reason>``."""
    bad = [f"{f.relative_to(PKG.parent)} ({n} lines)" for f in sorted(PKG.rglob("*.py"))
           if (n := len(f.read_text().splitlines())) > MAX_LINES
           and not f.read_text().startswith("# Why one file: ")]
    assert not bad, ("split these modules by job, or give the reason on their first line "
                     "('# Why one file: ...'):\n" + "\n".join(bad))
