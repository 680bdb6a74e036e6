"""Run-directory integrity (issue 11), end to end through the real CLI in subprocesses.

Hostile cells come from a plugin next to the matrix: controllers that ``os._exit``, SIGKILL
themselves, hang in C (``sleep(3)`` from libc: no Python check runs), or raise ``SystemExit`` /
``KeyboardInterrupt`` at their 21st sample. Every case must end as a stored ``error`` row with the
reason while the healthy cells complete, on the local executor and on dask.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from bench.cells import RUNTIME_COLUMNS

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow

PLUGIN = '''
import ctypes, os, signal
from controllers.base import Controller, register
from plant.drive import DriveCommand

LEVEL = 0.0


class _Hostile(Controller):
    description = "test only: misbehaves at its 21st sample"

    def reset(self, params, rng):
        self.n = 0

    def step(self, y):
        self.n += 1
        if self.n > 20:
            self.misbehave()
        return DriveCommand.hold(LEVEL)

    def misbehave(self):
        pass


@register("t-hold")
class Hold(_Hostile):
    pass


@register("t-exit")
class Exit(_Hostile):
    def misbehave(self):
        os._exit(3)


@register("t-kill")
class Kill(_Hostile):
    def misbehave(self):
        os.kill(os.getpid(), signal.SIGKILL)


@register("t-hang")
class Hang(_Hostile):
    def misbehave(self):          # once: sleep in C, where no Python-level check can run
        if not getattr(self, "slept", False):
            self.slept = True
            ctypes.CDLL(None).sleep(int(os.environ.get("T_HANG_S", "30")))


@register("t-sysexit")
class SysExit(_Hostile):
    def misbehave(self):
        raise SystemExit(4)


@register("t-kbint")
class KbInt(_Hostile):
    def misbehave(self):
        raise KeyboardInterrupt
'''

HOSTILE = ["t-exit", "t-kill", "t-hang", "t-sysexit", "t-kbint"]


def cli(*args, cwd=ROOT, timeout: float = 240, env=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=timeout, env=env)


def write_matrix(directory: Path, controllers, seeds=(0,), duration=1, time_limit=None, name="m.toml",
                 extra="") -> Path:
    (directory / "hostile_plugin.py").write_text(PLUGIN)
    text = (f'[matrix]\nplugins = ["hostile_plugin"]\ncontrollers = {json.dumps(list(controllers))}\n'
            f'scenarios = ["thesis"]\nseeds = {list(seeds)}\nduration_s = {duration}\nwarmup_s = 0.2\n')
    if time_limit is not None:
        text += f"time_limit_s = {time_limit}\n"
    path = directory / name
    path.write_text(text + extra)
    return path


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
    proc = subprocess.Popen([sys.executable, "-m", "bench.cli", "run", "--matrix", str(matrix), "--out", str(out),
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
    proc = subprocess.Popen([sys.executable, "-m", "bench.cli", "run", "--matrix", str(matrix), "--out", str(out),
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


def test_a_second_matrix_into_the_same_out_is_refused_and_a_grown_one_is_accepted(tmp_path):
    """Before: a 5 s matrix silently replaced the 20 s rows of the same ids and dropped the others."""
    first = write_matrix(tmp_path, ["t-hold"], seeds=(0, 1), duration=2, name="first.toml")
    out = tmp_path / "run"
    assert cli("run", "--matrix", first, "--out", out, "--traces", "none").returncode == 0
    before = {p.name: p.read_bytes() for p in (out / "cells").iterdir()}
    shorter = write_matrix(tmp_path, ["t-hold"], seeds=(0, 1), duration=1, name="shorter.toml")
    fewer = write_matrix(tmp_path, ["t-hold"], seeds=(0,), duration=2, name="fewer.toml")
    for matrix, fragment in ((shorter, "cell 't-hold__thesis__s0' was run with another definition (duration_s 2"),
                             (fewer, "holds cell 't-hold__thesis__s1', which this matrix does not have")):
        proc = cli("run", "--matrix", matrix, "--out", out, "--traces", "none")
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
        assert proc.returncode == 2 and len(lines) == 1 and fragment in lines[0], proc.stderr
        assert "use another --out" in lines[0]
    assert {p.name: p.read_bytes() for p in (out / "cells").iterdir()} == before
    grown = write_matrix(tmp_path, ["t-hold"], seeds=(0, 1, 2), duration=2, name="grown.toml")
    proc = cli("run", "--matrix", grown, "--out", out, "--traces", "none")
    assert proc.returncode == 0 and "1 computed, 2 resumed" in proc.stdout, proc.stdout + proc.stderr
    first = pd.read_parquet(out / "results.parquet")
    assert len(first) == 3
    # an edited plugin (same definition, new source) is run again. Before: the config hash
    # ignored plugin source, so the stale rows were reported as done.
    plugin = tmp_path / "hostile_plugin.py"
    plugin.write_text(plugin.read_text().replace("LEVEL = 0.0", "LEVEL = 0.05"))
    proc = cli("run", "--matrix", grown, "--out", out, "--traces", "none")
    assert proc.returncode == 0 and "3 computed, 0 resumed" in proc.stdout, proc.stdout
    second = pd.read_parquet(out / "results.parquet")
    assert (second["config_hash"] != first["config_hash"]).all()
    assert (second["mean_abs_current"] != first["mean_abs_current"]).all()    # the new level was simulated


def _mount_tmpfs(path: Path, size: str) -> bool:
    path.mkdir()
    try:
        return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                              capture_output=True, timeout=10).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


def test_a_full_disk_is_one_line_exit_1_and_nothing_half_written(tmp_path):
    matrix = write_matrix(tmp_path, ["t-hold"], seeds=(0, 1), duration=1)
    disk = tmp_path / "disk"
    if not _mount_tmpfs(disk, "8m"):
        pytest.skip("cannot mount a tmpfs here (the patched-writer test in test_store_hostile covers ENOSPC)")
    try:
        out = disk / "run"
        first = write_matrix(tmp_path, ["t-hold"], seeds=(0,), duration=1, name="one.toml")
        assert cli("run", "--matrix", first, "--out", out, "--traces", "none").returncode == 0
        fd = os.open(disk / "filler", os.O_WRONLY | os.O_CREAT)      # fill the disk to the last byte
        try:
            for size in (65536, 4096, 1):
                try:
                    while True:
                        os.write(fd, b"\0" * size)
                except OSError:
                    pass
        finally:
            os.close(fd)
        proc = cli("run", "--matrix", matrix, "--out", out, "--traces", "none")
        lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error")]
        assert proc.returncode == 1, proc.stderr
        assert "Traceback" not in proc.stderr and len(lines) == 1
        assert "No space left on device" in lines[0] and str(out) in lines[0]
        assert not list(out.rglob("*.tmp"))                    # no half-written file
        for p in (out / "cells").glob("*.json"):
            json.loads(p.read_text())                          # every stored cell is whole
        pd.read_parquet(out / "results.parquet")
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True, timeout=10)
