"""SIGKILL in the middle of a matrix, then a re-run: it completes, the cells stored before the
kill are not recomputed, and no row is duplicated or corrupt (real CLI, subprocesses)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent
SEEDS = list(range(8))

pytestmark = pytest.mark.slow


def _stored(out: Path) -> dict[str, tuple[int, bytes]]:
    cells = out / "cells"
    return {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in cells.glob("*.json")} if cells.is_dir() else {}


def test_sigkill_mid_matrix_then_resume(tmp_path):
    matrix = tmp_path / "m.toml"
    matrix.write_text(f'[matrix]\ncontrollers = ["solnic"]\nscenarios = ["thesis"]\nseeds = {SEEDS}\n'
                      f'duration_s = 5\nwarmup_s = 1\n')
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "reports.cli", "run", "--matrix", str(matrix), "--out", str(out), "--workers", "1"]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while len(_stored(out)) < 3:
            assert proc.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "no cells stored in time"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)       # the CLI, its forkserver and its workers
        proc.wait(timeout=30)
    before = _stored(out)
    assert 3 <= len(before) < len(SEEDS), "the kill should land mid-matrix"
    for name, (_, data) in before.items():        # every stored cell is whole
        assert json.loads(data)["status"] == "ok"

    again = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    after = _stored(out)
    assert len(after) == len(SEEDS)
    for name, stamp in before.items():            # not recomputed: same file, same bytes
        assert after[name] == stamp, name
    assert f"{len(before)} already in" in again.stderr
    assert f"{len(SEEDS) - len(before)} computed, {len(before)} resumed" in again.stdout

    for table in (pd.read_parquet(out / "results.parquet"), pd.read_csv(out / "results.csv")):
        assert len(table) == len(SEEDS) and table["cell"].is_unique
        assert sorted(table["seed"]) == SEEDS
        assert (table["status"] == "ok").all()
        assert np.isfinite(table["peak_error_rad"]).all()
    assert not list(out.rglob("*.tmp"))             # temporaries of the killed run are gone
