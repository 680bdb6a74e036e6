"""``solnic-bench``: the benchmark's command line (typer + rich), composed here because it joins
bench's commands with the report (reports may import bench; bench never imports reports).

Commands (one function each, defined beside what they run; a new command is one more line in
:func:`_compose`):

* ``run`` — run a matrix into ``--out DIR`` (resumes), print the aggregate table, build the report
  (:mod:`bench.run_command`);
* ``report DIR`` — rebuild ``DIR/report.html`` from stored results (here);
* ``list`` — registered controllers and built-in scenarios (:mod:`bench.list_command`);
* ``check-bound`` — the empirical check of inequality (2-6) and the lag limit (2-1) (SPEC §6,
  :mod:`bench.bound`);
* ``speed`` — the work-precision comparison behind the ≥ 1000× claim (SPEC §8, :mod:`bench.speed`);
* ``frontier`` — every controller swept over its knob, the oracle floor and the noise sweeps
  (:mod:`bench.frontier`);
* ``robustness`` — every controller at its default and best thesis point, told Table 2-1, on every
  real plant (:mod:`bench.robustness`).
* ``experiment`` / ``identify LOG`` — the identification plan for a real axis and the fit of a
  plant family to its log, written as a matrix scenario (:mod:`reports.axis`).

Exit codes: 0 done (cells with status ``error`` are results, not failures of the command — also a
cell whose process died or hung); 1 the run directory could not be written (full disk ...) or the
report failed, in one line naming the path; 2 a user error — a malformed matrix, an unknown
controller or scenario, a bad parameter, an unwritable ``--out``, a run directory of another
matrix, a usage error — reported in one line naming the file, line, field or flag, with nothing
written to the results; 130 interrupted (Ctrl-C), 143 SIGTERM, 129 SIGHUP (finished cells are
kept and the tables rebuilt).
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from rich.markup import escape

from bench.bound.command import check_bound_command
from bench.cli import err_console, out_console, out_dir, report_phase, signals_stop, user_errors
from bench.errors import UserError
from bench.frontier import make_frontier_command
from bench.list_command import list_command
from bench.robustness import make_robustness_command
from bench.run_command import make_run_command
from bench.speed.command import speed_command
from reports.axis import experiment_command, identify_command

__all__ = ["app", "main"]


def _build_report(out: Path) -> Path | None:
    """``DIR/report.html`` via reports.build_report_from_dir; None (with a warning) if the
    reports package is not importable."""
    try:
        from reports import build_report_from_dir
    except ImportError as exc:
        err_console.print(f"warning: reports is not importable ({escape(str(exc))}); skipped report.html")
        return None
    return build_report_from_dir(out)


@user_errors
@signals_stop
def report(run_dir: Path = typer.Argument(..., help="A run directory written by `solnic-bench run`.")) -> None:
    """Rebuild DIR/report.html from the results stored in DIR."""
    if str(run_dir).strip():
        out_dir(str(run_dir), "report DIR")
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
        path = report_phase(run_dir, build_report_from_dir)
    except (ValueError, OSError) as exc:   # a malformed or unreadable input file; the message names it
        raise UserError(f"{run_dir}: {exc}") from None
    out_console.print(f"report: {path}")


def _compose() -> typer.Typer:
    """The ``solnic-bench`` app: every command, in the order ``--help`` lists them."""
    app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                      help="Benchmark servo controllers on a plant with stiction and Coulomb friction "
                           "(Acker 1967).")
    run = make_run_command(_build_report)
    app.command("run")(run)
    app.command("report")(report)
    app.command("list")(list_command)
    app.command("check-bound")(user_errors(check_bound_command))
    app.command("speed")(user_errors(speed_command))
    app.command("frontier")(make_frontier_command(run))
    app.command("robustness")(make_robustness_command(run))
    app.command("experiment")(experiment_command)
    app.command("identify")(identify_command)
    return app


app = _compose()


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``solnic-bench`` and ``python -m reports.cli``: click's usage errors (unknown
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
    # CPython marks a KeyboardInterrupt "unhandled" when it leaves any ``exec`` of a string (scipy
    # and dataclasses build functions that way during lazy imports), even if a caller catches it;
    # under ``python -m`` the interpreter then kills itself with SIGINT at exit (-2, not our 130).
    # Each string ``exec`` clears that mark on entry: one empty ``exec`` clears a stale one.
    exec("pass")  # noqa: S102 - constant string, see above

if __name__ == "__main__":
    main()
