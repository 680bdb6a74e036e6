"""What bench's commands share on the command line: the two consoles, user errors as one line
and exit code 2, and the ``--out`` directory checks.

The commands themselves live beside what they run (:mod:`bench.run_command`,
:mod:`bench.list_command`, :mod:`bench.bound.command`, :mod:`bench.speed.command`,
:mod:`bench.frontier`); the ``solnic-bench`` program that composes them with the report is
:mod:`reports.cli`.
"""

from __future__ import annotations

import functools
import os
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable

import typer
from rich.console import Console
from rich.markup import escape

from bench.errors import UserError

__all__ = ["UserError", "out_console", "err_console", "user_errors", "out_dir", "writable_dir", "signals_stop",
           "report_phase"]

# Wide when not a terminal, so that logs keep whole tables and one-line messages.
out_console = Console(highlight=False, width=None if sys.stdout.isatty() else 160)
err_console = Console(stderr=True, highlight=False, width=None if sys.stderr.isatty() else 160)


def user_errors(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn user errors into one line on stderr and exit code 2 (no traceback)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except UserError as exc:
            err_console.print(f"error: {escape(str(exc))}", soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper


def out_dir(value: str, flag: str = "--out") -> Path:
    """``--out`` as a path; an empty value is a user error (not the current directory)."""
    if not value.strip():
        raise UserError(f"{flag} must name a directory, got an empty value")
    from bench.names import out_dir_problem

    problem = out_dir_problem(Path(value))
    if problem:
        raise UserError(f"{flag} {value[:60]}...: {problem}" if len(value) > 60 else f"{flag} {value}: {problem}")
    return Path(value)


def writable_dir(path: Path, flag: str = "--out") -> Path:
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


def _stopped(exc: KeyboardInterrupt, what_then: str) -> typer.Exit:
    """One line for a Ctrl-C, SIGTERM or SIGHUP, and the exit code of the run phase (130, 143, 129)."""
    import signal as _signal

    signum = getattr(exc, "signum", None)
    what = _signal.Signals(signum).name if signum else "interrupted"
    err_console.print(f"{what}: {what_then}", soft_wrap=True)
    return typer.Exit(128 + signum if signum else 130)


def signals_stop(fn: Callable[..., Any]) -> Callable[..., Any]:
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


def report_phase(out: Path, build: Callable[[Path], Any]) -> Any:
    """``build(out)``; a Ctrl-C, SIGTERM or SIGHUP meanwhile removes the temporary file
    (``write_atomic``) and says so in one line, with the run phase's exit code."""
    try:
        return build(out)
    except KeyboardInterrupt as exc:
        raise _stopped(exc, f"stopped while writing the report; the results are stored; rebuild it with "
                            f"`solnic-bench report {escape(str(out))}`") from None
