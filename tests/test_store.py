"""The results store: atomic cell files, resume on the config hash, rebuilt tables, the lock."""

from __future__ import annotations

import dataclasses
import json
import math

import pandas as pd
import pytest

from bench.cells import Cell, ControllerSpec, run_cell
from bench.scenarios import builtin_scenarios
from bench.store import ResultsStore, StoreBusy, results_frame


@pytest.fixture
def cell() -> Cell:
    scenario = builtin_scenarios()["thesis"].with_durations(duration_s=0.5, warmup_s=0.1)
    return Cell(ControllerSpec("solnic", "solnic"), scenario, seed=4)


def test_run_cell_row_and_resume_on_the_config_hash(tmp_path, cell):
    row = run_cell(cell, tmp_path, traces=True)
    assert row["status"] == "ok", row["message"]
    assert row["cell"] == "solnic__thesis__s4" and row["config_hash"] == cell.config_hash
    for col in ("peak_error_rad", "rms_error_rad", "p99_error_rad", "mean_abs_current", "rms_current",
                "supply_charge_rate", "runtime_s", "realtime_factor", "n_events", "n_stick_slip",
                "n_corrections"):
        assert isinstance(row[col], (int, float)) and not math.isnan(row[col]), col
    assert row["ctl_preset"] == "thesis"
    store = ResultsStore(tmp_path)
    assert not store.is_done(cell, traces=True)
    store.save(row)
    assert store.is_done(cell, traces=True)
    assert json.dumps(store.load(cell), sort_keys=True) == json.dumps(row, sort_keys=True)  # exact
    other = dataclasses.replace(cell, scenario=cell.scenario.with_durations(duration_s=0.6))
    assert other.cell_id == cell.cell_id and not store.is_done(other, traces=False)
    (tmp_path / "traces" / f"{cell.cell_id}.rrd").unlink()
    assert store.is_done(cell, traces=False) and not store.is_done(cell, traces=True)
    store.cell_path(cell.cell_id).write_text("{ torn")                          # unreadable: redo
    assert not store.is_done(cell, traces=False)


def test_rebuild_writes_one_row_per_stored_cell_in_matrix_order(tmp_path, cell):
    store = ResultsStore(tmp_path)
    cells = [dataclasses.replace(cell, seed=s) for s in (2, 0, 1)]
    for c in cells[:2]:
        store.save({"cell": c.cell_id, "controller": "solnic", "scenario": "thesis", "seed": c.seed,
                    "status": "ok", "message": "", "config_hash": c.config_hash, "peak_error_rad": 1e-6,
                    "n_events": 3, "ctl_flag": True, "ctl_name": "x"})
    store.rebuild(cells)
    store.rebuild(cells)                                                         # idempotent
    for df in (pd.read_parquet(tmp_path / "results.parquet"), pd.read_csv(tmp_path / "results.csv")):
        assert list(df["seed"]) == [2, 0]
        assert list(df.columns[:4]) == ["cell", "controller", "scenario", "seed"]
    assert not list(tmp_path.rglob("*.tmp"))


def test_results_frame_gives_each_column_one_type():
    df = results_frame([{"cell": "a", "seed": 0, "status": "ok", "ctl_b": True, "ctl_n": 3, "ctl_s": "p"},
                        {"cell": "b", "seed": 1, "status": "error", "ctl_b": math.nan, "ctl_n": math.nan,
                         "ctl_f": 0.5}])
    assert str(df["ctl_b"].dtype) == "boolean" and str(df["ctl_n"].dtype) == "Int64"
    assert df["ctl_f"].dtype == float and df["ctl_s"].isna().tolist() == [False, True]
    df.to_parquet(__import__("io").BytesIO())                                   # parquet accepts it


def test_a_second_run_on_the_same_directory_is_refused(tmp_path):
    store = ResultsStore(tmp_path)
    with store.lock():
        with pytest.raises(StoreBusy, match="another solnic-bench run"):
            with ResultsStore(tmp_path).lock():
                pass
    with store.lock():                                                           # released
        pass


def test_a_failing_cell_is_a_row_not_an_exception(tmp_path, cell):
    bad = dataclasses.replace(cell, controller=ControllerSpec("solnic", "solnic", {"preset": "nope"}))
    row = run_cell(bad, tmp_path, traces=False)
    assert row["status"] == "error" and "unknown preset" in row["message"]
    assert math.isnan(row["peak_error_rad"])
    slow = dataclasses.replace(cell, scenario=cell.scenario.with_durations(duration_s=30.0), time_limit_s=0.05)
    row = run_cell(slow, tmp_path, traces=False)
    assert row["status"] == "error" and "time limit of 0.05 s exceeded" in row["message"]


def test_a_cell_stopped_by_the_time_limit_is_run_again_on_resume(tmp_path, cell):
    """A wall-clock stop depends on machine load, not on the inputs: it must not be final."""
    store = ResultsStore(tmp_path)
    row = {"cell": cell.cell_id, "config_hash": cell.config_hash, "status": "error",
           "message": "time limit of 600 s exceeded at t = 12.00 s"}
    store.save(row)
    assert not store.is_done(cell, traces=False)
    store.save({**row, "message": "ZeroDivisionError: float division by zero"})
    assert store.is_done(cell, traces=False)
