"""Run a matrix into a run directory: resume, distribute, store each cell, rebuild the tables.

The order of events, so that a kill at any moment leaves a consistent directory:

1. take the directory lock and remove temporaries of a killed run;
2. refuse a matrix of another definition (:meth:`ResultsStore.check_matrix`), then find the
   cells still to do (no stored row with the same config hash, a retried error, or a missing
   trace the traces policy wants);
3. start the executor (a scheduler that cannot be reached fails here, before anything is
   written), then write ``config.json`` and ``meta.json``;
4. store each finished cell's row as its own file the moment it arrives — a cell whose process
   died, overran its limit or raised anything is stored as an ``error`` row with the reason;
5. rebuild ``results.parquet``/``results.csv`` from the cell files — also after Ctrl-C,
   SIGTERM, SIGHUP or a failure — and complete ``meta.json``.

SIGTERM and SIGHUP are handled like Ctrl-C while the run holds the directory: the cell
processes are killed (none survives the run), finished cells stay stored, the tables are
rebuilt, and :attr:`RunOutcome.signal` says which signal stopped the run.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from bench.cells import Cell, failure_row, kill_deadline, run_cell
from bench.executors import Executor
from bench.isolation import CellFailure
from bench.matrix import Matrix
from bench.provenance import run_metadata
from bench.scenarios import builtin_scenarios
from bench.store import ResultsStore
from plant.params import as_definition

__all__ = ["RunOutcome", "run_matrix", "run_config", "Stopped", "wants_trace", "reads_series", "stop_on_signals"]


class Stopped(KeyboardInterrupt):
    """SIGTERM or SIGHUP arrived: stop like Ctrl-C (a KeyboardInterrupt, so the same paths run)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def _stop_on_signals():
    """Turn SIGTERM/SIGHUP into :class:`Stopped` (main thread only); a second one during the
    cleanup is ignored so that the tables are rebuilt."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {}

    def handler(signum, frame):
        for sig in previous:
            signal.signal(sig, signal.SIG_IGN)
        raise Stopped(signum)

    for sig in (signal.SIGTERM, signal.SIGHUP):
        previous[sig] = signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


stop_on_signals = _stop_on_signals   # also the report phase of the CLI (a message, no temporary file)


def wants_trace(cell: Cell, policy: str, first_seed: int | None) -> bool:
    """Whether the traces policy (``all``, ``first-seed``, ``none``) keeps this cell's trace."""
    if policy == "all":
        return True
    if policy == "first-seed":
        return cell.seed == first_seed
    if policy == "none":
        return False
    raise ValueError(f"traces policy must be one of all, first-seed, none; got {policy!r}")


def reads_series(cell: Cell, lowest_seed: int | None) -> bool:
    """Whether the report reads this cell's series (:func:`reports.inputs._series_read`), so
    that the cell writes it (:func:`bench.cells.run_cell`'s ``series``).

    The claims read the series of the identification controller itself
    (:data:`controllers.roles.IDENTIFICATION`, not a variant) on the thesis scenario, every
    seed; the typical run (figures 7-2…7-5) is the lowest-seed cell in
    :func:`reports.build._typical_run`'s order. So: those cells, and every controller ×
    scenario on the matrix's lowest seed. A ``config.json`` edited afterwards to select other
    cells (``report.selection``, ``report.typical_cell``) finds only these series.
    """
    from controllers import roles

    if cell.seed == lowest_seed:
        return True
    spec = cell.controller
    return (spec.name == spec.base == roles.IDENTIFICATION and cell.scenario.name == _THESIS
            and spec.family == roles.IDENTIFICATION)


_THESIS = "thesis"   # reports.selection.Selection.thesis_scenario's default


@dataclass
class RunOutcome:
    """What a call of :func:`run_matrix` did."""

    results: pd.DataFrame
    total: int
    skipped: int
    computed: list[str] = field(default_factory=list)
    lost: list[tuple[str, str]] = field(default_factory=list)   # (cell, why) not stored
    interrupted: bool = False
    signal: int | None = None        # SIGTERM/SIGHUP that stopped the run (None: Ctrl-C or none)
    elapsed_s: float = 0.0


def run_config(matrix: Matrix, traces: bool | str) -> dict[str, Any]:
    """``config.json``: the resolved matrix, for the report and for humans.

    ``plant`` and ``warmup_s`` are the thesis scenario's (the report's classical limit and
    scoring window); the built-in thesis is used when the matrix does not run it.
    """
    thesis = next((s for s in matrix.scenarios if s.name == "thesis"), None)
    if thesis is None:
        thesis = builtin_scenarios()["thesis"]
        try:
            thesis = thesis.with_durations(matrix.duration_s, matrix.warmup_s)
        except ValueError:  # the overrides only fit the matrix's own scenarios
            pass
    return {
        "matrix": matrix.to_json(),
        "controllers": {c.name: c.to_json() for c in matrix.controllers},
        "scenarios": {s.name: s.to_json() for s in matrix.scenarios},
        "plant": as_definition(thesis.params),
        "warmup_s": thesis.warmup_s,
        "duration_s": thesis.duration_s,
        "traces": traces,
        "cells": [c.cell_id for c in matrix.cells()],
    }


def run_matrix(matrix: Matrix, out_dir: str | Path, *, executor: Executor, traces: bool | str = "first-seed",
               on_start: Callable[[int, int], None] | None = None,
               on_cell: Callable[[dict[str, Any]], None] | None = None,
               command: str = "") -> RunOutcome:
    """Run the cells of ``matrix`` that ``out_dir`` does not hold yet.

    ``traces``: ``"all"``, ``"first-seed"`` (one trace per controller × scenario) or ``"none"``
    (True/False mean all/none). ``on_start(to_run, already_done)`` is called once the work is
    known; ``on_cell(row)`` after each stored cell. ``executor`` is started here (only if there
    is work) and closed. A KeyboardInterrupt, SIGTERM or SIGHUP stops the run after storing what
    finished; the outcome says so.

    Raises
    ------
    RunDirConflict
        ``out_dir`` holds cells of another matrix definition (nothing is written).
    OSError
        The run directory cannot be written (full disk ...); what was stored stays stored.
    """
    policy = {True: "all", False: "none"}.get(traces, traces)  # type: ignore[call-overload]
    t0 = time.perf_counter()
    store = ResultsStore(out_dir)
    cells = matrix.cells()
    first_seed = matrix.seeds[0] if matrix.seeds else None
    trace_of = {c.cell_id: wants_trace(c, policy, first_seed) for c in cells}
    lowest_seed = min(matrix.seeds) if matrix.seeds else None
    series_of = {c.cell_id: reads_series(c, lowest_seed) for c in cells}
    with _stop_on_signals(), store.lock():
        store.check_matrix(cells)
        store.clean_temporaries()
        todo: list[Cell] = [c for c in cells if not store.is_done(c, trace_of[c.cell_id])]
        outcome = RunOutcome(pd.DataFrame(), len(cells), len(cells) - len(todo))
        started = False
        meta: dict[str, Any] = {}
        try:
            if todo:
                executor.workers = max(1, min(executor.workers, len(todo)))
                executor.start()    # an unreachable scheduler fails here, before anything is written
                started = True
            if on_start:
                on_start(len(todo), outcome.skipped)
            meta = run_metadata(command=command, executor=executor.describe() if todo else {"executor": None},
                                cells=len(cells), to_run=len(todo))
            store.write_json("config.json", run_config(matrix, policy))
            store.write_json("meta.json", meta)
            if todo:
                calls = [(c, str(store.root), trace_of[c.cell_id], series_of[c.cell_id]) for c in todo]
                keys = [c.process_key for c in todo]
                for i, row, exc in executor.map_unordered(run_cell, calls, [kill_deadline(c) for c in todo], keys):
                    if exc is not None:
                        kind = exc.kind if isinstance(exc, CellFailure) else "crash"
                        row = failure_row(todo[i], "crash" if kind == "raised" else kind,
                                          str(exc) if isinstance(exc, CellFailure) else f"{type(exc).__name__}: {exc}")
                    store.save(row)
                    outcome.computed.append(row["cell"])
                    if on_cell:
                        on_cell(row)
        except KeyboardInterrupt as exc:   # Ctrl-C, or SIGTERM/SIGHUP (Stopped)
            outcome.interrupted = True
            outcome.signal = getattr(exc, "signum", None)
        finally:
            if started:
                executor.close(cancel=True)
            if meta:   # the run got as far as writing: rebuild the tables from what is stored
                outcome.results = store.rebuild(cells)
                outcome.elapsed_s = time.perf_counter() - t0
                meta.update(finished_utc=_utc_now(), elapsed_s=round(outcome.elapsed_s, 3),
                            computed=len(outcome.computed), lost=len(outcome.lost),
                            interrupted=outcome.interrupted, signal=outcome.signal,
                            cells_ok=int((outcome.results.get("status", pd.Series(dtype=str)) == "ok").sum()))
                store.write_json("meta.json", meta)
    return outcome


def _utc_now() -> str:
    import datetime as dt
    return dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
