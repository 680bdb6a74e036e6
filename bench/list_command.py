"""``solnic-bench list``: the registered controllers, the built-in scenarios and matrices (and
a matrix file's variants and scenarios).

The listing comes from the registries (controllers, plant families, scenarios, matrices, the
frontier completed from the controllers' knobs), and building them imports every controller and
family (numba, scipy: about a second). Without ``--matrix`` the listing depends only on the
source of the ``controllers``, ``plant`` and ``bench`` packages, so it is kept as JSON in
``bench/__pycache__/list-<digest>.json``, the digest a sha256 of every ``.py`` and ``.toml``
file of those packages (read in tens of ms, as :mod:`plant._jit_cache` does for the kernels).
A later ``list`` with the same source prints from it without importing either registry. The
cache is used only in a process that has not imported a registry yet (a plugin could have
added to it) and is skipped silently where the folder is read-only.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import sys
from pathlib import Path
from typing import Any, Optional

import typer
from rich.markup import escape
from rich.table import Table

from bench.cli import out_console, user_errors

__all__ = ["list_command"]

_CACHE_VERSION = "1"
_SOURCE_PACKAGES = ("controllers", "plant", "bench")


@user_errors
def list_command(
    matrix: Optional[Path] = typer.Option(None, "--matrix", help="Also list a matrix file's variants and scenarios."),
) -> None:
    """Registered controllers, built-in scenarios and matrices."""
    if matrix is not None:
        from bench.matrix import load_matrix

        _render(_listing(load_matrix(matrix, check_resets=False)))
        return
    _render(_cached_listing())


def _source_digest() -> str | None:
    """sha256 (16 hex) of every .py and .toml file of the listing's packages; None if one is not
    a plain folder of files."""
    digest = hashlib.sha256(f"{_CACHE_VERSION} {sys.version}".encode())
    for package in _SOURCE_PACKAGES:
        spec = importlib.util.find_spec(package)          # finds, does not import
        locations = list(spec.submodule_search_locations or []) if spec else []
        if len(locations) != 1 or not os.path.isdir(locations[0]):
            return None
        root = Path(locations[0])
        for path in sorted(root.rglob("*")):
            if path.suffix in (".py", ".toml") and "__pycache__" not in path.parts:
                digest.update(f"{package}/{path.relative_to(root).as_posix()}".encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _cached_listing() -> dict[str, Any]:
    """The built-in listing, from the cache when the source is unchanged (module docstring)."""
    fresh = "controllers.base" not in sys.modules and "plant.protocol" not in sys.modules
    key = _source_digest() if fresh else None
    path = None
    if key is not None:
        path = Path(__file__).resolve().parent / "__pycache__" / f"list-{key}.json"
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError):
            pass
    listing = _listing(None)
    if path is not None:
        try:
            path.parent.mkdir(exist_ok=True)
            for stale in path.parent.glob("list-*.json"):
                stale.unlink(missing_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_text(json.dumps(listing))
            tmp.replace(path)
        except OSError:          # a read-only install: no cache
            pass
    return listing


def _listing(spec: Any) -> dict[str, Any]:
    """Every row and line ``list`` prints, from the registries (imports them)."""
    from controllers.base import available_controllers

    from bench.matrix import builtin_matrix_path, load_matrix
    from bench.scenarios import builtin_scenarios
    from plant.protocol import available_families, get_family

    controllers = [[name, cls.drive.value, cls.description or (cls.__doc__ or "").split("\n")[0]]
                   for name, cls in available_controllers().items()]
    controllers += [[name, _drive(cs.base), f"variant of {cs.base}: {cs.options}"]
                    for name, cs in (spec.variants.items() if spec else ())]
    families = []
    for name in available_families():
        family = get_family(name)
        families.append([name, family.description or (type(family).__doc__ or "").split("\n")[0]])
    scenarios = dict(builtin_scenarios())
    if spec:
        scenarios.update({s.name: s for s in spec.scenarios})
    scenario_rows = []
    for name, s in scenarios.items():
        told = "" if s.model is None else "; model differs"
        told += "".join(f"; {k} ±{v:.0%}" for k, v in s.mismatch)
        caveats = getattr(s.params, "caveats", None)
        notes = "".join(f" [caveat: {c}]" for c in (caveats() if caveats else ()))
        scenario_rows.append([name, s.family + told, f"{s.duration_s:g}", f"{s.warmup_s:g}", s.description + notes])
    lines = []
    for quick in (False, True):
        m = load_matrix(builtin_matrix_path(quick), check_resets=False)
        n = len(m.controllers) * len(m.scenarios) * len(m.seeds)
        lines.append(f"{'--quick' if quick else 'default'} matrix: {n} cells = "
                     f"{len(m.controllers)} controllers × {len(m.scenarios)} scenarios × "
                     f"{len(m.seeds)} seeds ({m.source})")
    from bench.frontier import frontier_matrix_data, frontier_matrix_path
    from bench.matrix import parse_matrix

    for quick in (False, True):
        m = parse_matrix(frontier_matrix_data(quick), str(frontier_matrix_path(quick)), check_resets=False)
        cells = m.cells()
        points = len({c.controller.name for c in cells})
        lines.append(f"frontier{' --quick' if quick else ''}: {len(cells)} cells = {points} controller "
                     f"points × {len(m.scenarios)} scenarios × {len(m.seeds)} seeds "
                     f"({frontier_matrix_path(quick)} completed from the registry)")
    return {"controllers": controllers, "families": families, "scenarios": scenario_rows, "lines": lines}


def _render(listing: dict[str, Any]) -> None:
    """Print the listing: three tables and the matrix lines."""
    for title, columns, key in (("controllers", ("name", "drive", "description"), "controllers"),
                                ("plant families", ("name", "description"), "families"),
                                ("scenarios", ("name", "plant", "duration [s]", "warm-up [s]", "description"),
                                 "scenarios")):
        table = Table(title=title, title_justify="left")
        for col in columns:
            table.add_column(escape(col))
        for row in listing[key]:
            table.add_row(*(escape(str(v)) for v in row))
        out_console.print(table)
    for line in listing["lines"]:
        out_console.print(escape(line))


def _drive(base: str) -> str:
    from controllers.base import get_controller
    return get_controller(base).drive.value
