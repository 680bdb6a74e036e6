"""Provenance of a run, for ``DIR/meta.json``: code revision, date, interpreter, packages, executor."""

from __future__ import annotations

import datetime as dt
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

from bench.cells import code_version

__all__ = ["run_metadata", "git_revision", "PACKAGES"]

PACKAGES = ("solnic-bench", "numpy", "scipy", "numba", "control", "pandas", "pyarrow", "rerun-sdk", "dask",
            "distributed", "typer", "rich", "jinja2", "plotly")
_ROOT = Path(__file__).resolve().parent.parent


def git_revision(root: Path = _ROOT) -> tuple[str | None, bool | None]:
    """(``git rev-parse HEAD``, whether tracked files differ from it); (None, None) without git."""
    try:
        rev = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True,
                             timeout=10)
        if rev.returncode != 0:
            return None, None
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                                capture_output=True, text=True, timeout=10)
        dirty = bool(status.stdout.strip()) if status.returncode == 0 else None
        return rev.stdout.strip() or None, dirty
    except (OSError, subprocess.SubprocessError):
        return None, None


def _versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def run_metadata(*, command: str = "", executor: dict[str, Any] | None = None, **extra: Any) -> dict[str, Any]:
    """The provenance record of a run starting now (``extra`` keys are added verbatim)."""
    rev, dirty = git_revision()
    return {
        "git_revision": rev,
        "git_dirty": dirty,
        "created_utc": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command": command or " ".join(sys.argv),
        "host": platform.node(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "code_version": code_version(),
        "packages": _versions(),
        **(executor or {}),
        **extra,
    }
