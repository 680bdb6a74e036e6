"""One cell of the benchmark matrix: a controller on a scenario with one seed.

:func:`run_cell` is the pure unit of work that the executors distribute: it builds the plant
and the controller, runs the closed loop, writes the cell's artifacts (the rerun trace and, for
controllers with a report series, the figure series) and returns the cell's results row. It never raises for a failing
cell: a controller that raises, a run over its time limit or a failing artifact gives a row with
status ``error`` and the message.

A cell's identity is its *config hash*: the sha256 of a canonical JSON of everything that
determines its numbers (resolved plant parameters, controller base and options, seed, run length,
warm-up, plugin modules) plus :data:`CODE_VERSION`. The results store resumes on it.

No controller is known here by name: the counter column ``n_corrections`` comes from the
controller's ``counter`` hook, the ``controller_family`` column from its ``family`` (a variant
has its base's family) and the series from ``report_series`` (:mod:`bench.series`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import json
import math
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Any

from bench.metrics import METRIC_COLUMNS
from bench.scenarios import Scenario

__all__ = ["ControllerSpec", "Cell", "run_cell", "code_version", "load_plugins", "RUNTIME_COLUMNS",
           "SIZE_PEAK_COLUMNS", "LEADING_COLUMNS"]

# Columns that measure the machine, not the controller: excluded from determinism checks.
RUNTIME_COLUMNS = ("runtime_s", "realtime_factor", "cell_wall_s")
SIZE_PEAK_COLUMNS = ("peak_error_small_rad", "peak_error_medium_rad", "peak_error_large_rad")
LEADING_COLUMNS = ("cell", "controller", "scenario", "seed", "status", "message", "controller_base",
                   "controller_family", "scenario_base", "duration_s", "warmup_s", *METRIC_COLUMNS, "n_corrections",
                   "runtime_s", "realtime_factor", "simulated_s", *SIZE_PEAK_COLUMNS, "config_hash",
                   "code_version", "cell_wall_s")

# Source that determines a cell's numbers and artifacts; its digest is part of CODE_VERSION.
_ROOT = Path(__file__).resolve().parent.parent
_VERSIONED = ("plant", "controllers", "bench/runner.py", "bench/metrics.py", "bench/cells.py",
              "bench/scenarios.py", "bench/series.py", "bench/traces.py")


@lru_cache(maxsize=1)
def code_version() -> str:
    """``solnic-bench <version> src:<digest>``: the package version and a digest of the source
    files that determine a cell's results (any edit there invalidates stored cells)."""
    try:
        from importlib.metadata import version
        pkg = version("solnic-bench")
    except Exception:  # not installed: the digest still identifies the code
        pkg = "unknown"
    digest = hashlib.sha256()
    for rel in _VERSIONED:
        path = _ROOT / rel
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for f in files:
            if f.is_file():
                digest.update(f.relative_to(_ROOT).as_posix().encode() + b"\0")
                digest.update(f.read_bytes() + b"\0")
    return f"solnic-bench {pkg} src:{digest.hexdigest()[:16]}"


def load_plugins(modules: tuple[str, ...], search_dirs: tuple[str, ...] = ()) -> None:
    """Import plugin modules (they register controllers); ``search_dirs`` go first on sys.path."""
    for d in reversed(search_dirs):
        if d not in sys.path:
            sys.path.insert(0, d)
    for name in modules:
        importlib.import_module(name)


@dataclass(frozen=True)
class ControllerSpec:
    """A controller of the matrix: a registered ``base`` with constructor ``options``.

    ``name`` is the matrix's name for it: the registered name itself, or a variant's name.
    """

    name: str
    base: str
    options: dict[str, Any] = field(default_factory=dict)

    def build(self):
        from controllers.base import make_controller
        return make_controller(self.base, **self.options)

    @property
    def family(self) -> str:
        """The base controller's ``family`` (``""`` if the base is not registered here)."""
        from controllers.base import get_controller
        try:
            return get_controller(self.base).family
        except ValueError:
            return ""

    def to_json(self) -> dict[str, Any]:
        return {"base": self.base, "options": dict(self.options)}


@dataclass(frozen=True)
class Cell:
    """A controller × scenario × seed, with the run length and warm-up of its scenario.

    ``time_limit_s`` (wall clock) and the plugin search directories do not enter the hash;
    ``code_version`` is taken where the cell is made (the process that plans the matrix).
    """

    controller: ControllerSpec
    scenario: Scenario
    seed: int
    time_limit_s: float | None = None
    plugins: tuple[str, ...] = ()
    plugin_dirs: tuple[str, ...] = ()
    code_version: str = field(default_factory=lambda: code_version())

    @property
    def cell_id(self) -> str:
        """Readable id, e.g. ``solnic__thesis__s0`` (also the trace and series file stem)."""
        return f"{self.controller.name}__{self.scenario.name}__s{self.seed}"

    @property
    def duration_s(self) -> float:
        return self.scenario.duration_s

    @property
    def warmup_s(self) -> float:
        return self.scenario.warmup_s

    def config(self) -> dict[str, Any]:
        """Everything that determines the cell's numbers, as plain JSON data."""
        return {
            "controller": {"name": self.controller.name, **self.controller.to_json()},
            "scenario": {"name": self.scenario.name, "base": self.scenario.base,
                         "plant": dataclasses.asdict(self.scenario.params)},
            "seed": self.seed, "duration_s": self.duration_s, "warmup_s": self.warmup_s,
            "plugins": list(self.plugins), "code_version": self.code_version,
        }

    @cached_property
    def config_hash(self) -> str:
        canonical = json.dumps(self.config(), sort_keys=True, separators=(",", ":"), allow_nan=True)
        return hashlib.sha256(canonical.encode()).hexdigest()


class _HardTimeout(BaseException):
    """Raised by SIGALRM when a cell overruns its limit inside code that never returns to the
    runner's per-sample check (a BaseException, so the runner's ``except Exception`` lets it by)."""


@contextlib.contextmanager
def _hard_limit(seconds: float | None) -> Iterator[None]:
    """Backstop for the runner's cooperative limit: SIGALRM after ``seconds``. Only in a
    process's main thread (local pool workers); a no-op elsewhere (dask worker threads)."""
    usable = (seconds is not None and hasattr(signal, "setitimer")
              and threading.current_thread() is threading.main_thread())
    if not usable:
        yield
        return

    def on_alarm(signum, frame):
        raise _HardTimeout(f"hard time limit of {seconds:g} s exceeded")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _scalar(value: Any) -> Any:
    """A JSON/parquet-friendly scalar, or ``_SKIP`` for containers."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if hasattr(value, "item") and getattr(value, "ndim", 0) == 0:   # numpy scalar
        value = value.item()
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value)
    return _SKIP


_SKIP = object()


def _error_message(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _base_row(cell: Cell) -> dict[str, Any]:
    row: dict[str, Any] = {
        "cell": cell.cell_id, "controller": cell.controller.name, "scenario": cell.scenario.name,
        "seed": cell.seed, "status": "error", "message": "", "controller_base": cell.controller.base,
        "controller_family": cell.controller.family,
        "scenario_base": cell.scenario.base, "duration_s": cell.duration_s, "warmup_s": cell.warmup_s,
    }
    for col in (*METRIC_COLUMNS, "n_corrections", "runtime_s", "realtime_factor", "simulated_s",
                *SIZE_PEAK_COLUMNS):
        row[col] = math.nan
    row["config_hash"] = cell.config_hash
    row["code_version"] = cell.code_version
    return row


def run_cell(cell: Cell, out_dir: str | Path, traces: bool) -> dict[str, Any]:
    """Run one cell, write its artifacts under ``out_dir`` and return its results row.

    Artifacts: ``out_dir/traces/<cell>.rrd`` when ``traces``; ``out_dir/series/<cell>.parquet``
    for controllers with a report series (``report_series`` hook). Both are written atomically. The row has
    the columns of :data:`LEADING_COLUMNS` plus the controller's scalar summary, prefixed
    ``ctl_``.
    """
    from bench.runner import run_closed_loop
    from bench.series import figure_series, wants_series
    from bench.traces import write_trace

    wall0 = time.perf_counter()
    out = Path(out_dir)
    row = _base_row(cell)
    try:
        with _hard_limit(None if cell.time_limit_s is None else 1.25 * cell.time_limit_s + 10.0):
            load_plugins(cell.plugins, cell.plugin_dirs)
            controller = cell.controller.build()
            row["controller_family"] = type(controller).family
            series = wants_series(controller)
            result = run_closed_loop(cell.scenario.params, controller, duration_s=cell.duration_s,
                                     warmup_s=cell.warmup_s, seed=cell.seed, record=traces or series,
                                     time_limit_s=cell.time_limit_s)
            row["status"], row["message"] = result.status, result.message
            row.update({k: _scalar(v) for k, v in result.metrics.items()})
            row["simulated_s"] = float(result.simulated_s)
            summary = {k: _scalar(v) for k, v in result.summary.items()}
            counter = type(controller).counter
            corrections = summary.get(counter) if counter else None
            if isinstance(corrections, (int, float)) and not isinstance(corrections, bool):
                row["n_corrections"] = corrections
            row.update({f"ctl_{k}": v for k, v in summary.items() if v is not _SKIP})
            if series:
                frame, peaks = figure_series(result, controller, cell.warmup_s)
                row.update(peaks)
                _write_parquet(frame, out / "series" / f"{cell.cell_id}.parquet")
            if traces:
                write_trace(out / "traces" / f"{cell.cell_id}.rrd", result, recording_id=cell.cell_id)
    except _HardTimeout as exc:
        row["status"], row["message"] = "error", str(exc)
    except Exception as exc:  # a failing cell is a result (STYLE §8)
        prefix = "" if row["status"] == "error" else "artifact: "
        row["status"], row["message"] = "error", prefix + _error_message(exc)
    row["cell_wall_s"] = time.perf_counter() - wall0
    return row


def _write_parquet(frame, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{_token()}.tmp")
    try:
        frame.to_parquet(tmp, index=False)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def _token() -> str:
    return f"{os.getpid()}-{threading.get_ident()}"
