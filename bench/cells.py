"""One cell of the benchmark matrix: a controller on a scenario with one seed.

:func:`run_cell` is the pure unit of work that the executors distribute: it builds the plant
and the controller, runs the closed loop, writes the cell's artifacts (the rerun trace, streamed
while the cell runs, and, for controllers with a figure series, the series) and returns the
cell's results row. It never raises for a failing cell: a controller that raises anything
(``SystemExit`` and ``KeyboardInterrupt`` included), a run over its time limit or a failing
artifact gives a row with status ``error``, the message and an ``error_kind``. A cell whose
process dies or hangs is turned into such a row by the driver (:func:`failure_row`).

A cell's identity is its *config hash*: the sha256 of a canonical JSON of everything that
determines its numbers (resolved plant parameters, controller base and options, seed, run length,
warm-up, plugin modules and a digest of their source) plus :data:`CODE_VERSION`. Its
*definition hash* is the same without the code digests: what the user asked for. The results
store resumes on the first and keeps one run directory to one definition per cell id with the
second.

No controller is known here by name: the counter column ``n_corrections`` comes from the
controller's ``counter`` hook, the ``controller_family`` column from its ``family`` (a variant
has its base's family) and the series from ``report_series`` (:mod:`bench.series`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import json
import math
import os
import sys
import threading
import time
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Any

from bench.kernels import KERNEL_COLUMN, numeric_kernel
from bench.metrics import METRIC_COLUMNS
from bench.scenarios import Scenario

__all__ = ["ControllerSpec", "Cell", "run_cell", "code_version", "load_plugins", "plugin_digest",
           "failure_row", "kill_deadline", "RUNTIME_COLUMNS", "SIZE_PEAK_COLUMNS", "LEADING_COLUMNS",
           "ERROR_KINDS", "RETRIED_ERROR_KINDS"]

# Columns that measure the machine, not the controller: excluded from determinism checks.
RUNTIME_COLUMNS = ("runtime_s", "realtime_factor", "cell_wall_s")
SIZE_PEAK_COLUMNS = ("peak_error_small_rad", "peak_error_medium_rad", "peak_error_large_rad")
LEADING_COLUMNS = ("cell", "controller", "scenario", "seed", "status", "message", "controller_base",
                   "controller_family", "scenario_base", "duration_s", "warmup_s", *METRIC_COLUMNS, "n_corrections",
                   "runtime_s", "realtime_factor", "simulated_s", *SIZE_PEAK_COLUMNS, "config_hash",
                   "code_version", "cell_wall_s", "error_kind", "time_limit_s", "definition_hash", "privileged",
                   KERNEL_COLUMN)
# Why a cell has status "error": "run" (the controller or the plant failed: a result of the
# configuration), "time_limit" (over its wall-clock limit), "crash" (its process died),
# "artifact" (its trace or series could not be written). Only "run" errors are final; the
# others depend on the machine and are retried on resume.
ERROR_KINDS = ("run", "time_limit", "crash", "artifact")
RETRIED_ERROR_KINDS = ("time_limit", "crash", "artifact")

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


def plugin_digest(modules: tuple[str, ...], search_dirs: tuple[str, ...] = ()) -> str:
    """sha256 (16 hex digits) of the source of the plugin ``modules`` (imported first): the
    module file, or every ``.py`` file of a package. Editing a plugin changes the config hash."""
    if not modules:
        return ""
    load_plugins(modules, search_dirs)
    digest = hashlib.sha256()
    for name in modules:
        module = sys.modules[name]
        paths = [Path(p) for p in getattr(module, "__path__", [])]
        files = sorted(f for p in paths for f in p.rglob("*.py")) if paths else \
            [Path(module.__file__)] if getattr(module, "__file__", None) else []
        digest.update(name.encode() + b"\0")
        for f in files:
            digest.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


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

    @property
    def privileged(self) -> bool:
        """Whether the base is a privileged bound (sees the true state; not a real controller)."""
        from controllers.base import get_controller
        try:
            return bool(get_controller(self.base).privileged)
        except ValueError:
            return False

    def to_json(self) -> dict[str, Any]:
        return {"base": self.base, "options": dict(self.options)}


@dataclass(frozen=True)
class Cell:
    """A controller × scenario × seed, with the run length and warm-up of its scenario.

    ``time_limit_s`` (wall clock) and the plugin search directories do not enter the hash (an
    error row remembers its limit, see ``bench.store``); ``code_version`` and ``plugin_source``
    (:func:`plugin_digest`) are taken where the cell is made (the process that plans the matrix).
    """

    controller: ControllerSpec
    scenario: Scenario
    seed: int
    time_limit_s: float | None = None
    plugins: tuple[str, ...] = ()
    plugin_dirs: tuple[str, ...] = ()
    code_version: str = field(default_factory=lambda: code_version())
    plugin_source: str = ""

    @property
    def cell_id(self) -> str:
        """Readable id, e.g. ``solnic__thesis__s0`` (also the trace and series file stem)."""
        return f"{self.controller.name}__{self.scenario.name}__s{self.seed}"

    @property
    def process_key(self) -> tuple:
        """Cells with equal keys may share a cell process (bench.isolation): the same plugins,
        from the same directories, with the same source."""
        return (self.plugins, self.plugin_dirs, self.plugin_source, self.code_version)

    @property
    def duration_s(self) -> float:
        return self.scenario.duration_s

    @property
    def warmup_s(self) -> float:
        return self.scenario.warmup_s

    def definition(self) -> dict[str, Any]:
        """What the user asked for: controller, scenario, seed, run length, plugins (no code)."""
        return {
            "controller": {"name": self.controller.name, **self.controller.to_json()},
            "scenario": self.scenario.definition(),
            "seed": self.seed, "duration_s": self.duration_s, "warmup_s": self.warmup_s,
            "plugins": list(self.plugins),
        }

    def config(self) -> dict[str, Any]:
        """Everything that determines the cell's numbers, as plain JSON data."""
        config = {**self.definition(), "code_version": self.code_version}
        if self.plugin_source:
            config["plugin_source"] = self.plugin_source
        return config

    @cached_property
    def config_hash(self) -> str:
        return _sha256(self.config())

    @cached_property
    def definition_hash(self) -> str:
        return _sha256(self.definition())


def _sha256(obj: Any) -> str:
    canonical = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True, default=str)
    return hashlib.sha256(canonical.encode()).hexdigest()


def kill_deadline(cell: Cell) -> float | None:
    """Wall seconds after which the executor kills the cell's process: the limit plus a grace
    for process start and artifacts (the runner itself stops at the limit, between samples)."""
    if cell.time_limit_s is None:
        return None
    return cell.time_limit_s * 1.05 + 2.0


def _scalar(value: Any) -> Any:
    """A JSON/parquet-friendly scalar, or ``_SKIP`` for containers."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if hasattr(value, "item") and getattr(value, "ndim", 0) == 0:   # numpy scalar
        value = value.item()
    if isinstance(value, bool):
        return value
    if isinstance(value, int):   # beyond int64 (parquet's widest integer): a float
        return int(value) if -2**63 <= value < 2**63 else float(value)
    if isinstance(value, float):
        return float(value)
    return _SKIP


_SKIP = object()


def _error_message(exc: BaseException) -> str:
    return str(exc) if isinstance(exc, _TraceLost) else f"{type(exc).__name__}: {exc}"


def _base_row(cell: Cell) -> dict[str, Any]:
    row: dict[str, Any] = {
        "cell": cell.cell_id, "controller": cell.controller.name, "scenario": cell.scenario.name,
        "seed": cell.seed, "status": "error", "message": "", "controller_base": cell.controller.base,
        "controller_family": cell.controller.family,
        "scenario_base": cell.scenario.base, "duration_s": cell.duration_s, "warmup_s": cell.warmup_s,
    }
    if not cell.scenario.default_plant:     # Acker's plant, told exactly: the columns it always had
        row["plant_family"] = cell.scenario.family
        row["model_exact"] = cell.scenario.model is None and not cell.scenario.mismatch
    for col in (*METRIC_COLUMNS, "n_corrections", "runtime_s", "realtime_factor", "simulated_s",
                *SIZE_PEAK_COLUMNS):
        row[col] = math.nan
    row["config_hash"] = cell.config_hash
    row["code_version"] = cell.code_version
    row["error_kind"] = ""
    row["time_limit_s"] = math.nan if cell.time_limit_s is None else float(cell.time_limit_s)
    row["definition_hash"] = cell.definition_hash
    row["privileged"] = cell.controller.privileged   # a bound, told apart without importing its plugin
    row[KERNEL_COLUMN] = ""                           # filled by the process that computes the cell
    return row


def failure_row(cell: Cell, kind: str, message: str, wall_s: float = math.nan) -> dict[str, Any]:
    """The row of a cell that returned no row (its process died or was killed)."""
    row = _base_row(cell)
    row["message"], row["error_kind"], row["cell_wall_s"] = message, kind, wall_s
    return row


def run_cell(cell: Cell, out_dir: str | Path, traces: bool, series: bool = True) -> dict[str, Any]:
    """Run one cell, write its artifacts under ``out_dir`` and return its results row.

    Artifacts: ``out_dir/traces/<cell>.rrd`` when ``traces`` (streamed while the cell runs,
    :class:`bench.traces.TraceRecorder`); ``out_dir/series/<cell>.parquet`` when ``series`` and
    the controller has a report series (``report_series`` hook). Both are written atomically.
    Only a cell that writes its series is recorded; otherwise a controller with a compiled step
    takes the compiled loop, keeping t and x1 for its phase peaks (:func:`bench.series.logs_x1`),
    with the same row. The row has the columns of
    :data:`LEADING_COLUMNS` (``numeric_kernel``: :func:`bench.kernels.numeric_kernel`) plus the controller's scalar summary, prefixed ``ctl_``. A row whose
    status is not ``ok`` has NaN metrics.
    """
    from bench.runner import MemoryRecorder, run_closed_loop
    from bench.series import figure_series, logs_x1, phase_peaks, wants_series
    from bench.traces import TeeRecorder, TraceRecorder

    from bench.names import check_cell_id

    wall0 = time.perf_counter()
    out = Path(out_dir)
    row = _base_row(cell)
    trace = None
    try:
        check_cell_id(cell.cell_id)     # its artifacts' file names: never a path outside out_dir
        row[KERNEL_COLUMN] = numeric_kernel()
        load_plugins(cell.plugins, cell.plugin_dirs)
        controller = cell.controller.build()
        row["controller_family"] = type(controller).family
        row["privileged"] = bool(type(controller).privileged)
        has_series = wants_series(controller)
        write = series and has_series
        memory = MemoryRecorder() if write else None
        x1_log = has_series and not write and logs_x1(controller)
        if traces:
            trace = TraceRecorder(out / "traces" / f"{cell.cell_id}.rrd", recording_id=cell.cell_id)
        recorder = TeeRecorder(trace, memory) if (trace or memory) else None
        truth, factors = cell.scenario.realise(cell.seed)
        row.update({f"mismatch_{k}": v for k, v in factors.items()})
        result = run_closed_loop(truth, controller, family=cell.scenario.family, model=cell.scenario.model_params(),
                                 duration_s=cell.duration_s, warmup_s=cell.warmup_s, seed=cell.seed,
                                 recorder=recorder, time_limit_s=cell.time_limit_s, x1_log=x1_log)
        row["status"], row["message"] = result.status, result.message
        if result.status == "error":
            row["error_kind"] = "time_limit" if result.message.startswith("time limit") else "run"
        if trace is not None and trace.error is not None:   # the numbers are fine; the trace is lost
            raise _TraceLost(trace.error)
        row.update({k: _scalar(v) for k, v in result.metrics.items()})
        row["simulated_s"] = float(result.simulated_s)
        summary = {k: _scalar(v) for k, v in result.summary.items()}
        counter = type(controller).counter
        corrections = summary.get(counter) if counter else None
        if isinstance(corrections, (int, float)) and not isinstance(corrections, bool):
            row["n_corrections"] = corrections
        row.update({f"ctl_{k}": v for k, v in summary.items() if v is not _SKIP})
        if write:
            samples, events, internals = memory.arrays()
            result = dataclasses.replace(result, samples=samples, events=events, internals=internals)
            frame, peaks = figure_series(result, controller, cell.warmup_s)
            row.update(peaks)
            _write_parquet(frame, out / "series" / f"{cell.cell_id}.parquet")
        elif has_series:    # the peaks without the frame: figure_series's call on the x1 log
            row.update(phase_peaks(result, controller.event_times(), cell.warmup_s))
    except BaseException as exc:  # noqa: BLE001 — a failing cell is a result (STYLE §8), whatever it raised
        artifact = row["status"] != "error" or isinstance(exc, _TraceLost) or (trace is not None and trace.error)
        row["status"], row["message"] = "error", ("artifact: " if artifact else "") + _error_message(exc)
        row["error_kind"] = "artifact" if artifact else "run"
    if row["status"] != "ok":
        for col in (*METRIC_COLUMNS, *SIZE_PEAK_COLUMNS):
            row[col] = math.nan
    row["cell_wall_s"] = time.perf_counter() - wall0
    return row


class _TraceLost(Exception):
    """The cell's trace writer gave up (full or hung file system): an ``artifact`` error."""

    def __str__(self) -> str:
        return f"trace: {self.args[0]}"


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
