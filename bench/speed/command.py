"""``solnic-bench speed``: run the comparison, print its tables or JSON, write ``DIR/speed.json``."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

__all__ = ["speed_command"]


def speed_command(
    json_out: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    quick: Annotated[bool, typer.Option("--quick", help="10 s steady window instead of 100 s (+ linear).")] = False,
    out: Annotated[Optional[Path], typer.Option("--out", help="Also write DIR/speed.json.")] = None,
) -> None:
    """Work-precision comparison: exact multimode vs fixed-step Euler vs solve_ivp (SPEC §8)."""
    from rich.console import Console

    from bench.speed.comparison import speed_comparison   # heavy (numba, scipy): only when run
    from bench.speed.tables import _print_table

    err = Console(stderr=True)
    result = speed_comparison(quick, progress=lambda msg: err.print(f"[dim]{msg}[/dim]"))
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "speed.json").write_text(json.dumps(result, indent=2))
    if json_out:
        typer.echo(json.dumps(result, indent=2))
    else:
        _print_table(result, Console(width=None if sys.stdout.isatty() else 140))
