"""Executors: settings are validated; the process pool reproduces an in-process run bit for bit."""

from __future__ import annotations

import json

import pytest

from bench.cells import RUNTIME_COLUMNS, Cell, ControllerSpec, run_cell
from bench.executors import DaskExecutor, ExecutorError, LocalExecutor, make_executor
from bench.scenarios import builtin_scenarios


@pytest.mark.parametrize("kind, workers, scheduler, message", [
    ("threads", None, None, r"--executor must be one of \['local', 'dask'\], got 'threads'"),
    ("local", 0, None, r"--workers must be an integer >= 1, got 0"),
    ("dask", -2, None, r"--workers must be an integer >= 1, got -2"),
    ("local", 2, "tcp://127.0.0.1:8786", r"--scheduler needs --executor dask"),
])
def test_bad_settings_are_user_errors(kind, workers, scheduler, message):
    with pytest.raises(ExecutorError, match=message):
        make_executor(kind, workers, scheduler)


def test_defaults():
    import os
    assert isinstance(make_executor("local"), LocalExecutor) and make_executor("local").workers == os.cpu_count()
    ex = make_executor("dask", 3, "tcp://h:1")
    assert isinstance(ex, DaskExecutor) and ex.address == "tcp://h:1" and ex.workers == 3


def _strip(row: dict) -> str:
    return json.dumps({k: v for k, v in row.items() if k not in RUNTIME_COLUMNS}, sort_keys=True)


def test_process_pool_reproduces_in_process_rows(tmp_path):
    base = builtin_scenarios()["ratio-2"].with_durations(duration_s=1.0, warmup_s=0.2)
    cells = [Cell(ControllerSpec(c, c), base, seed) for c in ("solnic", "dithered") for seed in (0, 1)]
    here = [run_cell(c, tmp_path / "here", False) for c in cells]
    with make_executor("local", 2) as pool:
        there = {i: (row, exc) for i, row, exc in pool.map_unordered(run_cell, [(c, str(tmp_path / "pool"), False)
                                                                                  for c in cells])}
    assert sorted(there) == list(range(len(cells)))
    for i, row in enumerate(here):
        other, exc = there[i]
        assert exc is None and row["status"] == "ok"
        assert _strip(other) == _strip(row)


def test_reused_and_fresh_cell_processes_give_identical_rows(tmp_path, monkeypatch):
    """Cells run one after another in a shared process (in another order than above) or each in
    its own process: the rows are the same bit for bit."""
    base = builtin_scenarios()["thesis"].with_durations(duration_s=1.0, warmup_s=0.2)
    cells = [Cell(ControllerSpec(c, c), base, seed) for seed in (3, 4) for c in ("linear", "solnic-modern", "reset-pid")]
    rows = {}
    for per_process in ("1", "64"):
        monkeypatch.setenv("SOLNIC_BENCH_CELLS_PER_PROCESS", per_process)
        with make_executor("local", 1) as pool:
            calls = [(c, str(tmp_path / per_process), False) for c in reversed(cells)]
            out = {i: (row, exc) for i, row, exc in pool.map_unordered(run_cell, calls,
                                                                        keys=[c.process_key for c in cells])}
        assert all(exc is None and row["status"] == "ok" for row, exc in out.values())
        rows[per_process] = {row["cell"]: _strip(row) for row, _ in out.values()}
    assert rows["1"] == rows["64"]


def _pid_and_mark(mark: bool) -> int:
    import os
    import sys
    if mark:
        sys.modules[__name__].MARKED = True
    return os.getpid() if not getattr(sys.modules[__name__], "MARKED", False) or mark else -1


def _raise_system_exit() -> None:
    raise SystemExit(7)


def test_a_cell_process_is_reused_only_while_healthy(monkeypatch):
    from bench import isolation
    from bench.isolation import CellFailure, call_isolated, retire_idle

    monkeypatch.setenv("SOLNIC_BENCH_CELLS_PER_PROCESS", "3")
    isolation.reopen()
    retire_idle()
    first = call_isolated(_pid_and_mark, (False,), 30, key="k")
    assert call_isolated(_pid_and_mark, (False,), 30, key="k") == first           # reused
    assert call_isolated(_pid_and_mark, (False,), 30, key="other") != first       # another key: another process
    assert call_isolated(_pid_and_mark, (True,), 30, key="k") == first            # third call: then replaced
    assert call_isolated(_pid_and_mark, (False,), 30, key="k") not in (first, -1)  # fresh: no mark inherited
    with pytest.raises(CellFailure) as failure:
        call_isolated(_raise_system_exit, (), 30, key="k")
    assert failure.value.kind == "raised" and "SystemExit: 7" in failure.value.message
    assert call_isolated(_pid_and_mark, (False,), 30, key="k") != first
    assert retire_idle() >= 1
