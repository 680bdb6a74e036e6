"""Hostile inputs of issue 11: each is one line ``error: ...`` naming the file, key, path or flag, the
right exit code, no traceback; plus the store's hostile values and the streamed trace."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.cells import Cell, ControllerSpec, failure_row, run_cell
from bench.scenarios import builtin_scenarios
from bench.store import ResultsStore, write_atomic

ROOT = Path(__file__).resolve().parent.parent
TINY = '[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\nduration_s = 1\nwarmup_s = 0.2\n'


def _cases(tmp: Path) -> dict[str, tuple[list[str], int, list[str]]]:
    """name -> (arguments, exit code, fragments of the one error line)."""
    def matrix(name: str, text: str, encoding: str = "utf-8") -> str:
        path = tmp / name
        path.write_bytes(text.encode(encoding))
        return str(path)

    parquet_dir = tmp / "parquet-dir"
    (parquet_dir / "results.parquet").mkdir(parents=True)
    cells_file = tmp / "cells-file"
    cells_file.mkdir()
    (cells_file / "cells").write_text("x")
    (tmp / "empty").mkdir()
    tiny = matrix("tiny.toml", TINY)
    out = str(tmp / "out")
    return {
        "dev-zero": (["run", "--matrix", "/dev/zero", "--out", out], 2, ["/dev/zero: cannot read the matrix file: not a regular file"]),
        "matrix-dir": (["run", "--matrix", str(tmp), "--out", out], 2, [f"{tmp}: cannot read the matrix file: not a regular file"]),
        "parquet-is-dir": (["run", "--matrix", tiny, "--out", str(parquet_dir)], 2,
                           [f"{parquet_dir / 'results.parquet'}: exists and is not a regular file"]),
        "cells-is-file": (["run", "--matrix", tiny, "--out", str(cells_file)], 2,
                          [f"{cells_file / 'cells'}: exists and is not a directory"]),
        "bad-scheme": (["run", "--matrix", tiny, "--out", out, "--executor", "dask", "--scheduler", "foo://h:1"], 2,
                       ["--scheduler 'foo://h:1': expected"]),
        "unknown-flag": (["run", "--bogus"], 2, ["No such option: --bogus"]),
        "bad-int": (["run", "--workers", "two"], 2, ["Invalid value for '--workers'"]),
        "empty-out": (["run", "--matrix", tiny, "--out", ""], 2, ["--out must name a directory"]),
        "report-empty": (["report", str(tmp / "empty")], 2, [f"{tmp / 'empty'}: no results"]),
        "dither-amplitude": (["run", "--out", out, "--matrix", matrix(
            "dither.toml", TINY.replace('"linear"', '"d-big"') + '[controllers.d-big]\nbase = "dithered"\n'
                                                                  'dither_amplitude = 1e6\n')], 2,
            ["dither.toml: controllers.d-big.dither_amplitude: rejected on scenario 'thesis'", "u_max"]),
        "warmup-half-sample": (["run", "--out", out, "--matrix", matrix(
            "warm.toml", TINY.replace("warmup_s = 0.2", "warmup_s = 0.996"))], 2,
            ["warm.toml: matrix.warmup_s: scenario 'thesis': warmup_s = 0.996 s leaves no sample to score"]),
        "huge-time-limit": (["run", "--out", out, "--matrix", matrix("limit.toml", TINY + "time_limit_s = 1e300\n")], 2,
                            ["limit.toml: matrix.time_limit_s: must be <= 604800 s"]),
        "traces-policy": (["run", "--matrix", tiny, "--out", out, "--traces", "some"], 2,
                          ["--traces must be one of all, first-seed, none"]),
    }


_SUBPROCESS = ("dev-zero", "unknown-flag")   # through the real executable; the rest in-process via main()


def _one_line_error(stderr: str, code: int, returncode: int, fragments, name: str) -> None:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert returncode == code, (name, stderr)
    assert "Traceback" not in stderr and len(lines) == 1 and lines[0].startswith("error: "), (name, stderr)
    for fragment in fragments:
        assert fragment in lines[0], (name, fragment, lines[0])


@pytest.mark.slow
def test_hostile_inputs_through_the_executable(tmp_path):
    cases = _cases(tmp_path)
    for name in _SUBPROCESS:
        args, code, fragments = cases[name]
        proc = subprocess.run([sys.executable, "-m", "reports.cli", *args], cwd=ROOT, capture_output=True, text=True,
                              timeout=120)
        _one_line_error(proc.stderr, code, proc.returncode, fragments, name)
    assert not (tmp_path / "out").exists()


def test_hostile_inputs_are_one_line_errors_with_the_right_exit_code(tmp_path, capsys):
    from reports.cli import main

    cases = _cases(tmp_path)
    for name, (args, code, fragments) in cases.items():
        if name in _SUBPROCESS:
            continue
        with pytest.raises(SystemExit) as stop:
            main(args)
        _one_line_error(capsys.readouterr().err, code, stop.value.code, fragments, name)
    assert not (tmp_path / "out").exists()          # nothing written for a user error
    assert not any((tmp_path / "parquet-dir").glob("cells")) and not any((tmp_path / "empty").iterdir())


@pytest.mark.slow
def test_a_matrix_with_a_utf8_bom_is_read(tmp_path):
    (tmp_path / "bom.toml").write_bytes(TINY.encode("utf-8-sig"))
    proc = subprocess.run([sys.executable, "-m", "reports.cli", "list", "--matrix", str(tmp_path / "bom.toml")],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr


@pytest.fixture(scope="module")
def cell() -> Cell:
    scenario = builtin_scenarios()["thesis"].with_durations(duration_s=1.0, warmup_s=0.2)
    return Cell(ControllerSpec("linear", "linear"), scenario, 0, time_limit_s=60.0)


def test_huge_and_non_finite_summary_values_are_stored_and_rebuilt(tmp_path, cell):
    """Before: a summary value of 2**70 raised OverflowError in store.rebuild on every later run."""
    store = ResultsStore(tmp_path)
    row = {**failure_row(cell, "run", "x"), "status": "ok", "ctl_big": 2**70, "ctl_huge": 10**400,
           "ctl_inf": math.inf, "ctl_nan": math.nan, "ctl_small": -(2**63)}
    store.save(row)
    df = store.rebuild([cell])
    back = pd.read_parquet(tmp_path / "results.parquet")
    assert back["ctl_big"].iloc[0] == float(2**70) and back["ctl_huge"].iloc[0] == math.inf
    assert math.isinf(back["ctl_inf"].iloc[0]) and math.isnan(back["ctl_nan"].iloc[0])
    assert back["ctl_small"].iloc[0] == -(2**63) and len(df) == 1


def test_error_rows_are_final_only_when_the_configuration_caused_them(tmp_path, cell):
    store = ResultsStore(tmp_path)
    for kind, done in (("run", True), ("time_limit", False), ("crash", False), ("artifact", False)):
        store.save(failure_row(cell, kind, "why"))
        assert store.is_done(cell, traces=False) is done, kind
    store.save(failure_row(cell, "run", "ValueError: ..."))
    other_limit = Cell(cell.controller, cell.scenario, cell.seed, time_limit_s=120.0)
    assert other_limit.config_hash == cell.config_hash
    assert not store.is_done(other_limit, traces=False)     # the limit changed: try again


def test_failed_rows_carry_nan_metrics(tmp_path, cell):
    bad = Cell(ControllerSpec("d", "dithered", {"dither_amplitude": 1e9}), cell.scenario, 0)
    row = run_cell(bad, tmp_path, traces=False)
    assert row["status"] == "error" and row["error_kind"] == "run"
    assert all(math.isnan(row[k]) for k in ("peak_error_rad", "rms_error_rad", "mean_abs_current", "rms_current"))


def test_enospc_while_storing_leaves_no_half_written_file(tmp_path, monkeypatch):
    """The patched-writer variant of the full-disk test (works without mounting a tmpfs)."""
    target = tmp_path / "cells" / "a.json"
    write_atomic(target, "old")
    monkeypatch.setattr("bench.store.os.fdopen", lambda fd, mode: _FullFile(fd))
    with pytest.raises(OSError, match="No space left"):
        write_atomic(target, json.dumps({"x": 1}))
    assert target.read_text() == "old" and not list(target.parent.glob(".*.tmp"))


class _FullFile:
    def __init__(self, fd):
        self.fd = fd

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        import os
        os.close(self.fd)

    def write(self, data):
        raise OSError(28, "No space left on device")


def test_streamed_trace_equals_the_trace_written_from_memory(tmp_path):
    """The TraceRecorder (chunks of 7 intervals, so many flushes) writes the same entity data as
    write_trace does from a run recorded in memory."""
    from rerun.chunk import RrdReader

    from bench.runner import run_closed_loop
    from bench.traces import TraceRecorder, write_trace
    from controllers.base import make_controller
    from plant.params import PlantParams

    params = PlantParams()
    recorded = run_closed_loop(params, make_controller("solnic"), duration_s=1.5, seed=2, record=True)
    write_trace(tmp_path / "memory.rrd", recorded, recording_id="m")
    streamed = run_closed_loop(params, make_controller("solnic"), duration_s=1.5, seed=2,
                               recorder=TraceRecorder(tmp_path / "stream.rrd", recording_id="s", chunk=7))
    assert streamed.metrics["peak_error_rad"] == recorded.metrics["peak_error_rad"]

    def columns(path):
        out = {}
        for chunk in RrdReader(path).store().stream().to_chunks():
            if chunk.is_static:
                continue
            rb = chunk.to_record_batch()
            t = rb.column(rb.schema.get_field_index("time")).cast("int64").to_numpy()
            v = np.array([x[0] for x in rb.column(rb.schema.get_field_index("Scalars:scalars")).to_pylist()])
            ts, vs = out.get(chunk.entity_path, (np.empty(0, np.int64), np.empty(0)))
            out[chunk.entity_path] = (np.r_[ts, t], np.r_[vs, v])
        return out

    a, b = columns(tmp_path / "memory.rrd"), columns(tmp_path / "stream.rrd")
    assert sorted(a) == sorted(b) and len(a) > 6
    for entity in a:
        np.testing.assert_array_equal(a[entity][0], b[entity][0], err_msg=entity)
        np.testing.assert_array_equal(a[entity][1], b[entity][1], err_msg=entity)
