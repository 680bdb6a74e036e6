"""``solnic-bench check-bound``: run the check with a progress bar, print its tables and verdict."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

__all__ = ["check_bound_command"]


def check_bound_command(
    quick: Annotated[bool, typer.Option("--quick", help="Reduced sweep (about 1–2 min on 2 cores).")] = False,
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("results"),
    workers: Annotated[Optional[int], typer.Option("--workers", min=1,
                                                   help="Worker processes (default: all cores).")] = None,
    tiny: Annotated[bool, typer.Option("--tiny", hidden=True, help="Minimal sweep for tests.")] = False,
) -> None:
    """Check inequality (2-6) and the lag limit (2-1) empirically (SPEC §6).

    Sweeps lead/lag and pure-integral designs over crossover, lag ratio, k̄s/k̄c, inertia and
    noise on a 30 µrad/s ramp, and L around Lmax at a stationary set-point. Writes
    OUT/bound.csv, OUT/hunting.csv, OUT/hunting_runs.csv and OUT/bound_verdict.json.
    """
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    from bench.bound.check import check_bound   # heavy (numba, scipy, the plant): only when run
    from bench.bound.tables import _tables, _verdict_lines

    console = Console(highlight=False, width=None if sys.stdout.isatty() else 160)
    if workers is not None and workers < 1:
        raise typer.BadParameter(f"must be >= 1, got {workers}", param_hint="--workers")
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=True) as bar:
        task = bar.add_task("check-bound", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        result = check_bound(quick, out, workers, progress, tiny=tiny)
    for table in _tables(result):
        console.print(table)
    for line in _verdict_lines(result):
        console.print(line)
