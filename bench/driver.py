"""Run a matrix into a run directory: resume, distribute, store each cell, rebuild the tables.

The order of events, so that a kill at any moment leaves a consistent directory:

1. take the directory lock and remove temporaries of a killed run;
2. find the cells still to do (no stored row with the same config hash, or a missing trace);
3. start the executor (a scheduler that cannot be reached fails here, before anything is
   written), then write ``config.json`` and ``meta.json``;
4. store each finished cell's row as its own file the moment it arrives;
5. rebuild ``results.parquet``/``results.csv`` from the cell files — also after Ctrl-C or a
   failure — and complete ``meta.json``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from bench.cells import Cell, run_cell
from bench.executors import Executor
from bench.matrix import Matrix
from bench.provenance import run_metadata
from bench.scenarios import builtin_scenarios
from bench.store import ResultsStore

__all__ = ["RunOutcome", "run_matrix", "run_config"]


@dataclass
class RunOutcome:
    """What a call of :func:`run_matrix` did."""

    results: pd.DataFrame
    total: int
    skipped: int
    computed: list[str] = field(default_factory=list)
    lost: list[tuple[str, str]] = field(default_factory=list)   # (cell, why) not stored
    interrupted: bool = False
    elapsed_s: float = 0.0


def run_config(matrix: Matrix, traces: bool) -> dict[str, Any]:
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
        "plant": dataclasses.asdict(thesis.params),
        "warmup_s": thesis.warmup_s,
        "duration_s": thesis.duration_s,
        "traces": traces,
        "cells": [c.cell_id for c in matrix.cells()],
    }


def run_matrix(matrix: Matrix, out_dir: str | Path, *, executor: Executor, traces: bool = True,
               on_start: Callable[[int, int], None] | None = None,
               on_cell: Callable[[dict[str, Any]], None] | None = None,
               command: str = "") -> RunOutcome:
    """Run the cells of ``matrix`` that ``out_dir`` does not hold yet.

    ``on_start(to_run, already_done)`` is called once the work is known; ``on_cell(row)`` after
    each stored cell. ``executor`` is started here (only if there is work) and closed.
    A KeyboardInterrupt stops the run after storing what finished; the outcome says so.
    """
    t0 = time.perf_counter()
    store = ResultsStore(out_dir)
    cells = matrix.cells()
    with store.lock():
        store.clean_temporaries()
        todo: list[Cell] = [c for c in cells if not store.is_done(c, traces)]
        outcome = RunOutcome(pd.DataFrame(), len(cells), len(cells) - len(todo))
        if todo:
            executor.workers = max(1, min(executor.workers, len(todo)))
            executor.start()    # an unreachable scheduler fails here, before anything is written
        if on_start:
            on_start(len(todo), outcome.skipped)
        meta = run_metadata(command=command, executor=executor.describe() if todo else {"executor": None},
                            cells=len(cells), to_run=len(todo))
        try:
            store.write_json("config.json", run_config(matrix, traces))
            store.write_json("meta.json", meta)
            if todo:
                calls = [(c, str(store.root), traces) for c in todo]
                try:
                    for i, row, exc in executor.map_unordered(run_cell, calls):
                        if exc is not None:
                            outcome.lost.append((todo[i].cell_id, f"{type(exc).__name__}: {exc}"))
                            continue
                        store.save(row)
                        outcome.computed.append(row["cell"])
                        if on_cell:
                            on_cell(row)
                except KeyboardInterrupt:
                    outcome.interrupted = True
        finally:
            if todo:
                executor.close(cancel=True)
            outcome.results = store.rebuild(cells)
            outcome.elapsed_s = time.perf_counter() - t0
            meta.update(finished_utc=_utc_now(), elapsed_s=round(outcome.elapsed_s, 3),
                        computed=len(outcome.computed), lost=len(outcome.lost),
                        interrupted=outcome.interrupted,
                        cells_ok=int((outcome.results.get("status", pd.Series(dtype=str)) == "ok").sum()))
            store.write_json("meta.json", meta)
    return outcome


def _utc_now() -> str:
    import datetime as dt
    return dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
