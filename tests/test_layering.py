"""The layering rule of DESIGN.md, checked on the source: ``shipid/models/`` imports nothing above it
(no identifier, simulator, manoeuvres, validation, nor any of their users), at module level or inside a
function."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "shipid"
#: Packages/modules a model may not import (everything that takes a model, and the layers above it).
FORBIDDEN = ("identify", "simulate", "manoeuvres", "validation", "report", "control", "routing", "glider",
             "studies", "commands", "cli", "kvlcc2_study")


def _imports(path: Path, package: list[str] | None = None) -> list[tuple[int, str]]:
    """Absolute dotted names of every import in ``path`` (relative imports resolved against its package,
    by default the one it sits in under ``shipid/``), with their lines."""
    if package is None:
        package = list(path.relative_to(PKG.parent).parts[:-1])
    out = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append((node.lineno, mod))
            out += [(node.lineno, f"{mod}.{a.name}") for a in node.names]  # "from .. import simulate"
    return out


def _violations(files) -> list[str]:
    bad = []
    for f in files:
        for line, name in _imports(f):
            parts = name.split(".")
            if parts[0] == "shipid" and len(parts) > 1 and parts[1] in FORBIDDEN:
                bad.append(f"{f.relative_to(PKG.parent)}:{line} imports {name}")
    return bad


def test_models_import_nothing_above_them():
    files = sorted((PKG / "models").rglob("*.py"))
    assert len(files) >= 5
    bad = _violations(files)
    assert not bad, "shipid/models/ must not import the layers above it:\n" + "\n".join(bad)


def test_the_integration_floor_imports_no_identifier():
    """``integrate``, ``simulate`` and the compiled numerics (``_kernel``, ``_jit``) sit below the identifier
    (its refinement, consistency replay and compiled filter use them): they import none of the layers above."""
    above = set(FORBIDDEN) - {"simulate"}
    files = [PKG / f for f in ("integrate.py", "simulate.py", "_kernel.py", "_jit.py")]
    bad = [f"{f.relative_to(PKG.parent)}:{line} imports {name}" for f in files for line, name in _imports(f)
           if name.split(".")[0] == "shipid" and len(name.split(".")) > 1 and name.split(".")[1] in above]
    assert not bad, "the integration floor must not import the layers above it:\n" + "\n".join(bad)


@pytest.mark.parametrize("source, expected", [
    ("from ..simulate import simulate\n", {"shipid.simulate"}),
    ("def f():\n    from ..identify.batch import OutputErrorRefiner\n", {"shipid.identify"}),
    ("from .. import manoeuvres\n", {"shipid.manoeuvres"}),
    ("import shipid.validation as v\n", {"shipid.validation"}),
    ("from .base import Model\nfrom .._jit import rebind\nfrom ..logs import TrialLog\nimport numpy as np\n", set()),
])
def test_the_check_sees_every_import_form(tmp_path, source, expected):
    """The parser resolves relative imports (also inside functions) and reports each forbidden one."""
    f = tmp_path / "m.py"
    f.write_text(source)
    found = {".".join(name.split(".")[:2]) for line, name in _imports(f, package=["shipid", "models"])
             if name.split(".")[0] == "shipid" and name.split(".")[1:2] and name.split(".")[1] in FORBIDDEN}
    assert found == expected
