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

__all__ = ["UserError", "out_console", "err_console", "user_errors", "out_dir", "writable_dir"]

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
