"""The architecture as a test: import arrows run plant ← controllers ← bench ← reports only, no
import cycles inside a layer, and bench/ and reports/ never name a registered controller.

Every import counts: module-level and function-level ``import``/``from ... import`` statements
(read with :mod:`ast` from the source, so an import hidden in a function body is seen) and
``importlib.import_module("...")`` / ``__import__("...")`` calls with a string literal.
"""

from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAYERS = ("plant", "controllers", "bench", "reports")   # each may import only those before it


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@lru_cache(maxsize=1)
def _modules() -> dict[str, Path]:
    """Every module of the four layers: dotted name → source file."""
    return {_module_name(p): p for layer in LAYERS for p in sorted((ROOT / layer).rglob("*.py"))}


def _resolve(name: str, modules) -> str | None:
    """The project module that ``name`` denotes (its longest existing prefix), or None outside."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        candidate = ".".join(parts[:i])
        if candidate in modules:
            return candidate
    return None


def _imports(module: str, is_package: bool, source: str, modules) -> list[tuple[str, int]]:
    """``(imported project module, line)`` for every import in ``source``, at any depth."""
    package = module if is_package else module.rpartition(".")[0]
    found: list[tuple[str | None, int]] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(_resolve(alias.name, modules), node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:                                    # relative: from . / .. import
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:                          # from pkg import submodule → pkg.submodule
                sub = f"{base}.{alias.name}"
                found.append((sub if sub in modules else _resolve(base, modules), node.lineno))
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            func = node.func
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if fname in ("import_module", "__import__"):
                found.append((_resolve(node.args[0].value, modules), node.lineno))
    return [(m, line) for m, line in found if m is not None and m != module]


@lru_cache(maxsize=1)
def _graph() -> dict[str, list[tuple[str, int]]]:
    """Module → the project modules it imports (with the line)."""
    modules = _modules()
    return {m: _imports(m, p.name == "__init__.py", p.read_text(encoding="utf-8"), modules)
            for m, p in modules.items()}


def _layer(module: str) -> int:
    return LAYERS.index(module.split(".")[0])


def test_the_scanner_sees_every_kind_of_import():
    """The scanner itself, on a made-up module: each import form yields its project module."""
    source = ("import plant.params\nimport numpy\nfrom plant import drive\nfrom . import frontier\n"
              "from plant.state import X1\n"
              "def f():\n    from reports.build import build_report\n"
              "    import importlib\n    importlib.import_module('controllers.roles')\n")
    got = {m for m, _ in _imports("bench.made_up", False, source, _modules())}
    assert got == {"plant.params", "plant.drive", "bench.frontier", "plant.state", "reports.build",
                   "controllers.roles"}


def test_every_import_arrow_runs_down_the_layers():
    """plant imports nothing of the others, controllers only plant, bench plant and controllers."""
    upward = [f"{_modules()[m].relative_to(ROOT)}:{line}: imports {target}"
              for m, edges in _graph().items() for target, line in edges if _layer(target) > _layer(m)]
    assert not upward, "\n".join(upward)


def _cycles(layer: str) -> list[list[str]]:
    """Import cycles among the modules of ``layer`` (strongly connected components of more than
    one module, found with Tarjan's depth-first search)."""
    nodes = [m for m in _graph() if m.split(".")[0] == layer]
    edges = {m: sorted({t for t, _ in _graph()[m] if t.split(".")[0] == layer}) for m in nodes}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in nodes:
        if v not in index:
            visit(v)
    return components


def test_cycle_finder_finds_a_known_cycle(monkeypatch):
    graph = {"bench.a": [("bench.b", 1)], "bench.b": [("bench.c", 1)], "bench.c": [("bench.a", 1)],
             "bench.d": [("bench.a", 1)]}
    monkeypatch.setitem(globals(), "_graph", lambda: graph)
    assert _cycles("bench") == [["bench.a", "bench.b", "bench.c"]]


@pytest.mark.parametrize("layer", [
    "plant",
    "controllers",
    "bench",
    "reports",
])
def test_no_import_cycle_inside_a_layer(layer):
    cycles = _cycles(layer)
    assert not cycles, "import cycles: " + "; ".join(" ↔ ".join(c) for c in cycles)


def _string_literals(path: Path) -> list[tuple[str, int]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    return [(node.value, node.lineno) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)]


def test_bench_and_reports_never_name_a_registered_controller():
    """No string literal in bench/ or reports/ equals a registered controller name; the names
    live in the registry (controllers/, with the roles in controllers/roles.py) and the built-in
    matrix TOML files (bench/matrices/, not Python).

    Excluded, and why: only whole-literal equality counts, because names such as "linear" are
    English words that prose uses (docstrings, messages, the Jinja templates); identifiers are not
    checked for the same reason (``Selection.solnic`` and ``Selection.linear`` are the config keys
    ``report.selection.solnic/linear``, whose values come from controllers.roles)."""
    from controllers.base import available_controllers

    names = set(available_controllers())
    assert len(names) >= 2     # the check is not vacuous
    offenders = [f"{path.relative_to(ROOT)}:{line}: {value!r}"
                 for layer in ("bench", "reports") for path in sorted((ROOT / layer).rglob("*.py"))
                 for value, line in _string_literals(path) if value in names]
    assert not offenders, "\n".join(offenders)


def test_bench_and_reports_never_name_a_plant_family():
    """bench/ and reports/ reach a plant only through plant.protocol: no string literal equals a
    plant family's name and no import names a family's module (plant.<family>...). Families and
    their built-in scenarios live in plant/ (``PlantFamily.scenarios``)."""
    from plant.protocol import BUILTIN_FAMILIES, available_families

    names = set(available_families())
    assert {"multimode", "two-mass"} <= names     # the check is not vacuous
    modules = {m.rsplit(".", 1)[-1] for m in BUILTIN_FAMILIES.values()}
    offenders = []
    for layer in ("bench", "reports"):
        for path in sorted((ROOT / layer).rglob("*.py")):
            rel = path.relative_to(ROOT)
            offenders += [f"{rel}:{line}: {value!r}" for value, line in _string_literals(path) if value in names]
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                mod = node.module if isinstance(node, ast.ImportFrom) else None
                mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [mod] if mod else []
                offenders += [f"{rel}:{node.lineno}: import {m}" for m in mods
                              if m.startswith("plant.") and m.split(".")[1] in modules]
    assert not offenders, "\n".join(offenders)
