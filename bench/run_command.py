"""``solnic-bench run``: run a matrix into ``--out DIR`` (resumes), print the aggregate table and
build the report.

The report is built by whoever composes the program (:mod:`reports.cli`): bench does not import
reports, so :func:`make_run_command` takes the report builder as an argument.
"""

from __future__ import annotations

import shlex
import sys
from pathlib import Path
from typing import Any, Callable, Optional

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

from bench.cli import err_console, out_console, out_dir, report_phase, signals_stop, user_errors, writable_dir
from bench.errors import UserError

__all__ = ["ReportBuilder", "make_run_command", "print_aggregate"]

#: Writes ``DIR/report.html`` from a run directory and returns its path (None: skipped, said why).
ReportBuilder = Callable[[Path], Optional[Path]]


def _fmt(v: float, digits: int = 3) -> str:
    if v != v:  # NaN
        return "—"
    return f"{v:.{digits}g}"


def print_aggregate(results, matrix) -> None:
    """The terminal table of the run: per controller × scenario, over the ok seeds."""
    from bench.aggregate import aggregate

    agg = aggregate(results, ([c.name for c in matrix.controllers], [s.name for s in matrix.scenarios]))
    if agg.empty:
        out_console.print("no results")
        return
    table = Table(title="Over seeds (status ok only): mean, worst and spread (sd). "
                        "Peak and RMS error in µrad, currents in ozf·in, runtime in s.",
                  title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
    columns = [("controller", "left"), ("scenario", "left"), ("ok", "right")]
    stats = [("peak_error_rad", "peak", ("mean", "worst", "sd")), ("rms_error_rad", "RMS err", ("mean",)),
             ("mean_abs_current", "mean|i|", ("mean", "worst", "sd")), ("rms_current", "RMS i", ("mean",)),
             ("runtime_s", "runtime", ("mean", "worst"))]
    for name, justify in columns:
        table.add_column(name, justify=justify, overflow="fold")
    for _, label, kinds in stats:
        for kind in kinds:
            table.add_column(f"{label}\n{kind}", justify="right", no_wrap=True)
    suffix = {"mean": "_mean", "worst": "_worst", "sd": "_spread"}
    for _, r in agg.iterrows():
        cells = [escape(r["controller"]), escape(r["scenario"]), f"{r['ok']}/{r['cells']}"]
        cells += [_fmt(r[col + suffix[k]], 2 if k == "sd" else 3) for col, _, kinds in stats for k in kinds]
        table.add_row(*cells, style=None if r["ok"] == r["cells"] else "red")
    out_console.print(table)


def make_run_command(build_report: ReportBuilder) -> Callable[..., None]:
    """The ``run`` command, building the report with ``build_report`` after the cells."""

    @user_errors
    @signals_stop
    def run(
        matrix: Optional[Path] = typer.Option(None, "--matrix", help="Matrix TOML file (default: the built-in default matrix)."),
        quick: bool = typer.Option(False, "--quick", help="The built-in quick matrix (about a minute on 2 cores)."),
        out_value: str = typer.Option("results", "--out", help="Run directory; a re-run resumes it."),
        executor: str = typer.Option("local", "--executor", help="local (process pool) or dask."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", help="dask scheduler address (default: a LocalCluster)."),
        workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes (default: CPU count)."),
        traces_policy: Optional[str] = typer.Option(None, "--traces", help="Which cells write a rerun trace: all, "
                                                    "first-seed (default: one per controller x scenario) or none."),
        no_traces: bool = typer.Option(False, "--no-traces", help="Same as --traces none."),
    ) -> None:
        """Run a benchmark matrix: DIR/results.{parquet,csv}, DIR/traces/*.rrd, DIR/report.html."""
        from bench.executors import make_executor   # light: the flags are checked before the simulator loads

        if matrix is not None and quick:
            raise UserError("--matrix and --quick exclude each other")
        if no_traces and traces_policy not in (None, "none"):
            raise UserError(f"--no-traces and --traces {traces_policy} exclude each other")
        traces = "none" if no_traces else (traces_policy or "first-seed")
        if traces not in ("all", "first-seed", "none"):
            raise UserError(f"--traces must be one of all, first-seed, none; got {traces!r}")
        out = out_dir(out_value)
        pool = make_executor(executor, workers, scheduler)
        from bench.matrix import builtin_matrix_path, load_matrix
        spec = load_matrix(matrix if matrix is not None else builtin_matrix_path(quick))
        from bench.store import check_layout
        check_layout(out)
        writable_dir(out)

        from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                                   TimeRemainingColumn)

        from bench.driver import run_matrix
        from bench.kernels import mixed_kernels_note

        progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                            TimeElapsedColumn(), TextColumn("eta"), TimeRemainingColumn(),
                            console=err_console, transient=False)
        task = None

        def on_start(to_run: int, done: int) -> None:
            nonlocal task
            n = to_run + done
            how = f" ({pool.kind}, {min(pool.workers, to_run)} workers)" if to_run else ""
            err_console.print(f"{spec.source}: {n} cells, {done} already in {out}, {to_run} to run{how}")
            if to_run:
                task = progress.add_task("cells", total=to_run)
                progress.start()

        def on_cell(row: dict[str, Any]) -> None:
            status = row["status"]
            mark = "" if status == "ok" else f" [red]{escape(status)}[/red]"
            progress.update(task, advance=1, description=f"{escape(row['cell'])}{mark}")

        try:
            outcome = run_matrix(spec, out, executor=pool, traces=traces, on_start=on_start, on_cell=on_cell,
                                 command=shlex.join(["solnic-bench", *sys.argv[1:]]))
        except OSError as exc:   # the run directory cannot be written: what was stored stays stored
            progress.stop()
            where = exc.filename or out
            err_console.print(f"error: {escape(str(where))}: {escape(exc.strerror or str(exc))} (cells stored so far "
                              f"are kept; run again with --out {escape(str(out))} to resume)", soft_wrap=True)
            raise typer.Exit(1) from None
        finally:
            progress.stop()

        results = outcome.results
        print_aggregate(results, spec)
        bad = results[results["status"] != "ok"] if len(results) else results
        for _, r in bad.iterrows():
            err_console.print(f"{escape(r['cell'])}: {escape(r['status'])}: {escape(str(r['message']))}", soft_wrap=True)
        out_console.print(f"{len(results)} cells in {out / 'results.parquet'} ({len(results) - len(bad)} ok, "
                          f"{len(outcome.computed)} computed, {outcome.skipped} resumed) in {outcome.elapsed_s:.1f} s")
        for cell, why in outcome.lost:
            err_console.print(f"{escape(cell)}: not run: {escape(why)}", soft_wrap=True)
        mixed = mixed_kernels_note(results)
        if mixed:
            err_console.print(f"note: {escape(mixed)}", soft_wrap=True)
        if outcome.interrupted:
            import signal as _signal
            what = _signal.Signals(outcome.signal).name if outcome.signal else "interrupted"
            err_console.print(f"{what}: stopped; {len(outcome.computed)} cells stored, tables rebuilt; run again with "
                              f"--out {out} to resume", soft_wrap=True)
            raise typer.Exit(128 + outcome.signal if outcome.signal else 130)
        try:
            path = report_phase(out, build_report)
        except typer.Exit:
            raise
        except Exception as exc:  # the results are stored; say what failed, exit 1
            err_console.print(f"error: report: {type(exc).__name__}: {escape(str(exc))} "
                              f"(results are stored; retry with `solnic-bench report {out}`)", soft_wrap=True)
            raise typer.Exit(1) from None
        if path is not None:
            out_console.print(f"report: {path}")
        if outcome.lost:
            err_console.print(f"{len(outcome.lost)} cells were not run; run again with --out {out} to resume")
            raise typer.Exit(1)

    return run
