"""``solnic-bench``: the benchmark's command line (typer + rich).

Commands (one function each; a new command is one more ``@app.command`` function):

* ``run`` — run a matrix into ``--out DIR`` (resumes), print the aggregate table, build the report;
* ``report DIR`` — rebuild ``DIR/report.html`` from stored results;
* ``list`` — registered controllers and built-in scenarios;
* ``check-bound`` — the empirical check of inequality (2-6) and the lag limit (2-1) (SPEC §6);
* ``speed`` — the work-precision comparison behind the ≥ 1000× claim (SPEC §8);
* ``frontier`` — every controller swept over its knob, the oracle floor and the noise sweeps
  (:mod:`bench.frontier`).

Exit codes: 0 done (cells with status ``error`` are results, not failures of the command — also a
cell whose process died or hung); 1 the run directory could not be written (full disk ...) or the
report failed, in one line naming the path; 2 a user error — a malformed matrix, an unknown
controller or scenario, a bad parameter, an unwritable ``--out``, a run directory of another
matrix, a usage error — reported in one line naming the file, line, field or flag, with nothing
written to the results; 130 interrupted (Ctrl-C), 143 SIGTERM, 129 SIGHUP (finished cells are
kept and the tables rebuilt).
"""

from __future__ import annotations

import functools
import os
import shlex
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable, Optional

import typer
from rich import box
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from bench.errors import UserError

__all__ = ["app", "main", "UserError"]

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Benchmark servo controllers on a plant with stiction and Coulomb friction "
                       "(Acker 1967).")
# Wide when not a terminal, so that logs keep whole tables and one-line messages.
out_console = Console(highlight=False, width=None if sys.stdout.isatty() else 160)
err_console = Console(stderr=True, highlight=False, width=None if sys.stderr.isatty() else 160)


def _user_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn user errors into one line on stderr and exit code 2 (no traceback)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except UserError as exc:
            err_console.print(f"error: {escape(str(exc))}", soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper


def _out_dir(value: str, flag: str = "--out") -> Path:
    """``--out`` as a path; an empty value is a user error (not the current directory)."""
    if not value.strip():
        raise UserError(f"{flag} must name a directory, got an empty value")
    from bench.names import out_dir_problem

    problem = out_dir_problem(Path(value))
    if problem:
        raise UserError(f"{flag} {value[:60]}...: {problem}" if len(value) > 60 else f"{flag} {value}: {problem}")
    return Path(value)


def _writable_dir(path: Path, flag: str = "--out") -> Path:
    """Create ``path`` if needed and prove it writable (a probe file, removed again)."""
    if path.exists() and not path.is_dir():
        raise UserError(f"{flag} {path}: exists and is not a directory")
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-probe.", suffix=".tmp", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UserError(f"{flag} {path}: cannot write: {exc.strerror or exc}") from None
    return path


def _build_report(out: Path) -> Path | None:
    """``DIR/report.html`` via reports.build_report_from_dir; None (with a warning) if the
    reports package is not importable."""
    try:
        from reports import build_report_from_dir
    except ImportError as exc:
        err_console.print(f"warning: reports is not importable ({escape(str(exc))}); skipped report.html")
        return None
    return build_report_from_dir(out)


def _stopped(exc: KeyboardInterrupt, what_then: str) -> typer.Exit:
    """One line for a Ctrl-C, SIGTERM or SIGHUP, and the exit code of the run phase (130, 143, 129)."""
    import signal as _signal

    signum = getattr(exc, "signum", None)
    what = _signal.Signals(signum).name if signum else "interrupted"
    err_console.print(f"{what}: {what_then}", soft_wrap=True)
    return typer.Exit(128 + signum if signum else 130)


def _signals_stop(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Run a command with SIGTERM/SIGHUP handled like Ctrl-C for its whole length (the run phase
    nests its own handling), so that no phase dies silently or leaves a temporary file."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from bench.driver import stop_on_signals

        try:
            with stop_on_signals():
                return fn(*args, **kwargs)
        except KeyboardInterrupt as exc:
            raise _stopped(exc, "stopped; what was stored is kept") from None

    return wrapper


def _report_phase(out: Path, build: Callable[[Path], Any]) -> Any:
    """``build(out)``; a Ctrl-C, SIGTERM or SIGHUP meanwhile removes the temporary file
    (``write_atomic``) and says so in one line, with the run phase's exit code."""
    try:
        return build(out)
    except KeyboardInterrupt as exc:
        raise _stopped(exc, f"stopped while writing the report; the results are stored; rebuild it with "
                            f"`solnic-bench report {escape(str(out))}`") from None


def _fmt(v: float, digits: int = 3) -> str:
    if v != v:  # NaN
        return "—"
    return f"{v:.{digits}g}"


def _print_aggregate(results, matrix) -> None:
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


@app.command("run")
@_user_errors
@_signals_stop
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
    out = _out_dir(out_value)
    pool = make_executor(executor, workers, scheduler)
    from bench.matrix import builtin_matrix_path, load_matrix
    spec = load_matrix(matrix if matrix is not None else builtin_matrix_path(quick))
    from bench.store import check_layout
    check_layout(out)
    _writable_dir(out)

    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)

    from bench.driver import run_matrix

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
    _print_aggregate(results, spec)
    bad = results[results["status"] != "ok"] if len(results) else results
    for _, r in bad.iterrows():
        err_console.print(f"{escape(r['cell'])}: {escape(r['status'])}: {escape(str(r['message']))}", soft_wrap=True)
    out_console.print(f"{len(results)} cells in {out / 'results.parquet'} ({len(results) - len(bad)} ok, "
                      f"{len(outcome.computed)} computed, {outcome.skipped} resumed) in {outcome.elapsed_s:.1f} s")
    for cell, why in outcome.lost:
        err_console.print(f"{escape(cell)}: not run: {escape(why)}", soft_wrap=True)
    if outcome.interrupted:
        import signal as _signal
        what = _signal.Signals(outcome.signal).name if outcome.signal else "interrupted"
        err_console.print(f"{what}: stopped; {len(outcome.computed)} cells stored, tables rebuilt; run again with "
                          f"--out {out} to resume", soft_wrap=True)
        raise typer.Exit(128 + outcome.signal if outcome.signal else 130)
    try:
        path = _report_phase(out, _build_report)
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


@app.command("report")
@_user_errors
@_signals_stop
def report(run_dir: Path = typer.Argument(..., help="A run directory written by `solnic-bench run`.")) -> None:
    """Rebuild DIR/report.html from the results stored in DIR."""
    if str(run_dir).strip():
        _out_dir(str(run_dir), "report DIR")
    if not str(run_dir).strip() or not run_dir.is_dir():
        raise UserError(f"{run_dir}: no such run directory")
    if not (run_dir / "results.parquet").is_file() and not any(run_dir.glob("cells/*.json")):
        raise UserError(f"{run_dir}: no results (no results.parquet, no cells/); run `solnic-bench run --out "
                        f"{run_dir}` first")
    try:
        from reports import build_report_from_dir
    except ImportError as exc:
        err_console.print(f"error: reports is not importable: {escape(str(exc))}")
        raise typer.Exit(1) from None
    try:
        path = _report_phase(run_dir, build_report_from_dir)
    except (ValueError, OSError) as exc:   # a malformed or unreadable input file; the message names it
        raise UserError(f"{run_dir}: {exc}") from None
    out_console.print(f"report: {path}")


@app.command("list")
@_user_errors
def list_(
    matrix: Optional[Path] = typer.Option(None, "--matrix", help="Also list a matrix file's variants and scenarios."),
) -> None:
    """Registered controllers, built-in scenarios and matrices."""
    from controllers.base import available_controllers

    from bench.matrix import builtin_matrix_path, load_matrix
    from bench.scenarios import builtin_scenarios

    spec = load_matrix(matrix, check_resets=False) if matrix is not None else None
    table = Table(title="controllers", title_justify="left")
    for col in ("name", "drive", "description"):
        table.add_column(escape(col))
    for name, cls in available_controllers().items():
        table.add_row(escape(name), cls.drive.value, escape(cls.description or (cls.__doc__ or "").split("\n")[0]))
    for name, cs in (spec.variants.items() if spec else ()):
        table.add_row(escape(name), _drive(cs.base), escape(f"variant of {cs.base}: {cs.options}"))
    out_console.print(table)

    table = Table(title="scenarios", title_justify="left")
    for col in ("name", "duration [s]", "warm-up [s]", "description"):
        table.add_column(escape(col))
    scenarios = dict(builtin_scenarios())
    if spec:
        scenarios.update({s.name: s for s in spec.scenarios})
    for name, s in scenarios.items():
        table.add_row(escape(name), f"{s.duration_s:g}", f"{s.warmup_s:g}", escape(s.description))
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


# The sweep and the speed comparison live in their own modules; one line each registers them.
from bench.bound import check_bound_command  # noqa: E402
from bench.speed import speed_command  # noqa: E402
from bench.frontier import frontier_command  # noqa: E402

app.command("check-bound")(_user_errors(check_bound_command))
app.command("speed")(_user_errors(speed_command))
app.command("frontier")(_user_errors(frontier_command))


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``solnic-bench`` and ``python -m bench.cli``: click's usage errors (unknown
    flag, missing value, bad type) become one line ``error: ...`` and exit 2, like every user error."""
    try:
        try:
            from typer._click import exceptions as click_errors   # typer >= 0.22 vendors click
        except ImportError:  # pragma: no cover - older typer on click
            from click import exceptions as click_errors

        try:
            code = app(args=argv, standalone_mode=False)
        except getattr(click_errors, "NoArgsIsHelpError", ()) as exc:   # bare command: its help
            exc.show()
            sys.exit(2)
        except click_errors.UsageError as exc:
            where = f"{exc.ctx.command_path}: " if exc.ctx is not None else ""
            err_console.print(f"error: {escape(where + ' '.join(exc.format_message().split()))}", soft_wrap=True)
            sys.exit(2)
        except click_errors.ClickException as exc:
            err_console.print(f"error: {escape(' '.join(exc.format_message().split()))}", soft_wrap=True)
            sys.exit(exc.exit_code)
        except typer.Abort:   # Ctrl-C outside a run
            err_console.print("interrupted")
            sys.exit(130)
        except UserError as exc:  # raised outside a command body; commands handle their own
            err_console.print(f"error: {escape(str(exc))}", soft_wrap=True)
            sys.exit(2)
        sys.exit(code if isinstance(code, int) else 0)
    finally:
        if argv is None:   # the program itself (not a test calling main): see below
            _ignore_signals_while_exiting()


def _ignore_signals_while_exiting() -> None:
    """The command is done (its exit code is decided): a Ctrl-C or SIGTERM during the
    interpreter's shutdown (up to ~1 s: atexit, finalizers) must not turn it into a killed process
    (exit -2/-15, no message). Python keeps an ignored signal ignored through finalization."""
    import signal as _signal

    for sig in (_signal.SIGINT, _signal.SIGTERM, _signal.SIGHUP):
        try:
            _signal.signal(sig, _signal.SIG_IGN)
        except (ValueError, OSError):   # not the main thread (tests): nothing to protect
            pass


if __name__ == "__main__":
    main()
