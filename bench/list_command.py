"""``solnic-bench list``: the registered controllers, the built-in scenarios and matrices (and
a matrix file's variants and scenarios)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape
from rich.table import Table

from bench.cli import out_console, user_errors

__all__ = ["list_command"]


@user_errors
def list_command(
    matrix: Optional[Path] = typer.Option(None, "--matrix", help="Also list a matrix file's variants and scenarios."),
) -> None:
    """Registered controllers, built-in scenarios and matrices."""
    from controllers.base import available_controllers

    from bench.matrix import builtin_matrix_path, load_matrix
    from bench.scenarios import builtin_scenarios
    from plant.protocol import available_families, get_family

    spec = load_matrix(matrix, check_resets=False) if matrix is not None else None
    table = Table(title="controllers", title_justify="left")
    for col in ("name", "drive", "description"):
        table.add_column(escape(col))
    for name, cls in available_controllers().items():
        table.add_row(escape(name), cls.drive.value, escape(cls.description or (cls.__doc__ or "").split("\n")[0]))
    for name, cs in (spec.variants.items() if spec else ()):
        table.add_row(escape(name), _drive(cs.base), escape(f"variant of {cs.base}: {cs.options}"))
    out_console.print(table)

    table = Table(title="plant families", title_justify="left")
    for col in ("name", "description"):
        table.add_column(escape(col))
    for name in available_families():
        family = get_family(name)
        table.add_row(escape(name), escape(family.description or (type(family).__doc__ or "").split("\n")[0]))
    out_console.print(table)

    table = Table(title="scenarios", title_justify="left")
    for col in ("name", "plant", "duration [s]", "warm-up [s]", "description"):
        table.add_column(escape(col))
    scenarios = dict(builtin_scenarios())
    if spec:
        scenarios.update({s.name: s for s in spec.scenarios})
    for name, s in scenarios.items():
        told = "" if s.model is None else "; model differs"
        told += "".join(f"; {k} ±{v:.0%}" for k, v in s.mismatch)
        caveats = getattr(s.params, "caveats", None)
        notes = "".join(f" [caveat: {c}]" for c in (caveats() if caveats else ()))
        table.add_row(escape(name), escape(s.family + told), f"{s.duration_s:g}", f"{s.warmup_s:g}",
                      escape(s.description + notes))
    out_console.print(table)
    for quick in (False, True):
        m = load_matrix(builtin_matrix_path(quick), check_resets=False)
        n = len(m.controllers) * len(m.scenarios) * len(m.seeds)
        out_console.print(f"{'--quick' if quick else 'default'} matrix: {n} cells = "
                          f"{len(m.controllers)} controllers × {len(m.scenarios)} scenarios × "
                          f"{len(m.seeds)} seeds ({escape(m.source)})")
    from bench.frontier import frontier_matrix_data, frontier_matrix_path
    from bench.matrix import parse_matrix

    for quick in (False, True):
        m = parse_matrix(frontier_matrix_data(quick), str(frontier_matrix_path(quick)), check_resets=False)
        cells = m.cells()
        points = len({c.controller.name for c in cells})
        out_console.print(f"frontier{' --quick' if quick else ''}: {len(cells)} cells = {points} controller "
                          f"points × {len(m.scenarios)} scenarios × {len(m.seeds)} seeds "
                          f"({escape(str(frontier_matrix_path(quick)))} completed from the registry)")


def _drive(base: str) -> str:
    from controllers.base import get_controller
    return get_controller(base).drive.value
