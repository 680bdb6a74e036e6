"""Run-directory integrity (issue 11), end to end through the real CLI in subprocesses.

Hostile cells come from a plugin next to the matrix: controllers that ``os._exit``, SIGKILL
themselves, hang in C (``sleep(3)`` from libc: no Python check runs), or raise ``SystemExit`` /
``KeyboardInterrupt`` at their 21st sample. Every case must end as a stored ``error`` row with the
reason while the healthy cells complete, on the local executor and on dask.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from bench.cells import RUNTIME_COLUMNS
from cli_helpers import ROOT, cli, write_matrix

pytestmark = pytest.mark.slow

HOSTILE = ["t-exit", "t-kill", "t-hang", "t-sysexit", "t-kbint"]


def _check_hostile(out: Path) -> pd.DataFrame:
    df = pd.read_parquet(out / "results.parquet").set_index("controller")
    assert sorted(df.index) == sorted(HOSTILE + ["linear"])
    assert df.loc["linear", "status"] == "ok"
    bad = df.loc[HOSTILE]
    assert (bad["status"] == "error").all()
    assert bad["peak_error_rad"].isna().all()                 # failed rows carry NaN metrics
    expect = {"t-exit": ("crash", "exited with code 3"), "t-kill": ("crash", "killed by SIGKILL"),
              "t-hang": ("time_limit", "time limit exceeded"), "t-sysexit": ("run", "SystemExit: 4"),
              "t-kbint": ("run", "KeyboardInterrupt")}
    for name, (kind, fragment) in expect.items():
        assert df.loc[name, "error_kind"] == kind, df.loc[name, ["error_kind", "message"]]
        assert fragment in df.loc[name, "message"]
    return df


@pytest.fixture(scope="module")
def hostile_local(tmp_path_factory) -> Path:
    """The hostile matrix on the local executor (30 s C-level hang, 2 s limit)."""
    tmp = tmp_path_factory.mktemp("hostile")
    matrix = write_matrix(tmp, HOSTILE + ["linear"], time_limit=2)
    t0 = time.monotonic()
    proc = cli("run", "--matrix", matrix, "--out", tmp / "run", "--workers", "2", "--traces", "none")
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert time.monotonic() - t0 < 120          # the 30 s hang was killed at its limit (2 s + grace)
    return tmp


def test_dying_hanging_and_raising_cells_become_error_rows_and_the_rest_completes(hostile_local):
    """Before: one os._exit broke the process pool and lost every cell; a C-level hang ignored
    time_limit_s; SystemExit/KeyboardInterrupt left cells "not run" and retried for ever."""
    _check_hostile(hostile_local / "run")
    # resume: the configuration's own errors are final; a dead or killed cell is run again
    again = cli("run", "--matrix", hostile_local / "m.toml", "--out", hostile_local / "run", "--traces", "none")
    assert again.returncode == 0, again.stderr
    assert "3 computed, 3 resumed" in again.stdout, again.stdout
    _check_hostile(hostile_local / "run")


def test_dask_isolates_the_same_cells_with_bit_identical_rows(hostile_local, tmp_path):
    """Before: time_limit_s did nothing under dask (worker threads), a hung controller hung the run.
    Determinism: every row equals the local executor's except the timing columns and the
    wall-clock figure in a time-limit message."""
    out = tmp_path / "dask"
    proc = cli("run", "--matrix", hostile_local / "m.toml", "--out", out, "--executor", "dask", "--workers", "2",
               "--traces", "none")
    assert proc.returncode == 0, proc.stderr
    remote = _check_hostile(out)
    local = pd.read_parquet(hostile_local / "run" / "results.parquet").set_index("controller")
    keep = [c for c in remote.columns if c not in RUNTIME_COLUMNS and c != "message"]
    pd.testing.assert_frame_equal(remote[keep], local.loc[remote.index, keep], check_exact=True)
    healthy = [c for c in remote.index if remote.loc[c, "error_kind"] != "time_limit"]
    assert (remote.loc[healthy, "message"] == local.loc[healthy, "message"]).all()


def _session_processes(sid: int) -> list[str]:
    """Live processes of session ``sid`` (zombies are dead: they compute and write nothing)."""
    ps = subprocess.run(["ps", "-eo", "pid,sid,stat,args"], capture_output=True, text=True).stdout.splitlines()[1:]
    return [line for line in ps if int(line.split()[1]) == sid and not line.split()[2].startswith("Z")]


def _wait_for(predicate, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.2)
    return False


@pytest.mark.parametrize("signum, code", [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_and_sighup_stop_the_workers_keep_the_cells_and_resume_identically(tmp_path, signum, code):
    """Before: SIGTERM exited 143 without rebuilding the tables and orphaned the workers."""
    matrix = write_matrix(tmp_path, ["t-hold", "t-hang"], seeds=(0,), time_limit=60)
    out = tmp_path / "run"
    env = {**os.environ, "T_HANG_S": "600"}
    proc = subprocess.Popen([sys.executable, "-m", "reports.cli", "run", "--matrix", str(matrix), "--out", str(out),
                             "--workers", "2"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env=env)
    try:
        assert _wait_for(lambda: (out / "cells" / "t-hold__thesis__s0.json").is_file(), 120), "no cell stored"
        os.kill(proc.pid, signum)                                  # the main process only
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == code, stderr
    assert f"{signal.Signals(signum).name}: stopped; 1 cells stored, tables rebuilt" in stderr
    assert "Traceback" not in stderr
    assert _wait_for(lambda: not _session_processes(proc.pid), 10), _session_processes(proc.pid)
    table = pd.read_parquet(out / "results.parquet")
    assert table["cell"].tolist() == ["t-hold__thesis__s0"] and (table["status"] == "ok").all()
    stored = (out / "cells" / "t-hold__thesis__s0.json").read_bytes()
    if signum != signal.SIGTERM:
        return
    # resume (the hang now ends quickly): the stored cell is kept byte for byte, the rest runs
    resumed = cli("run", "--matrix", matrix, "--out", out, env={**os.environ, "T_HANG_S": "0"})
    assert resumed.returncode == 0, resumed.stderr
    assert "1 computed, 1 resumed" in resumed.stdout
    assert (out / "cells" / "t-hold__thesis__s0.json").read_bytes() == stored


def test_sigkill_of_the_main_process_leaves_no_orphan(tmp_path):
    """The cell processes die with the run (PR_SET_PDEATHSIG), so none writes without the lock."""
    matrix = write_matrix(tmp_path, ["t-hang"], seeds=(0, 1), time_limit=60)
    out = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "reports.cli", "run", "--matrix", str(matrix), "--out", str(out),
                             "--workers", "2", "--traces", "none"], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True, env={**os.environ, "T_HANG_S": "600"})
    try:
        assert _wait_for(lambda: len(_session_processes(proc.pid)) >= 5, 120)   # main, tracker, server, 2 cells
        time.sleep(1.0)
        os.kill(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=30)
        assert _wait_for(lambda: not _session_processes(proc.pid), 15), _session_processes(proc.pid)
    finally:
        if _session_processes(proc.pid):
            os.killpg(proc.pid, signal.SIGKILL)
