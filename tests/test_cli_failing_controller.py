"""A controller that raises gives an ``error`` row while the other cells complete.

The failing controller is injected through the matrix's ``plugins`` key: a module next to the
matrix file registers it (the matrix file's directory is searched first).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow

PLUGIN = '''
from controllers.base import Controller, register
from plant.drive import DriveCommand


@register("test-raises")
class RaisesController(Controller):
    """Holds zero drive, then raises at its 51st sample."""

    description = "test only: raises at the 51st sample"

    def reset(self, params, rng):
        self.n = 0

    def step(self, y):
        self.n += 1
        if self.n > 50:
            raise RuntimeError("injected failure")
        return DriveCommand.hold(0.0)
'''


def test_raising_controller_gives_an_error_row_and_the_rest_complete(tmp_path):
    (tmp_path / "bench_test_plugin.py").write_text(PLUGIN)
    (tmp_path / "m.toml").write_text(
        '[matrix]\nplugins = ["bench_test_plugin"]\ncontrollers = ["test-raises", "solnic"]\n'
        'scenarios = ["thesis"]\nseeds = [0, 1]\nduration_s = 3\nwarmup_s = 1\n')
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "reports.cli", "run", "--matrix", tmp_path / "m.toml",
                           "--out", out, "--no-traces"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_parquet(out / "results.parquet")
    assert len(df) == 4
    bad = df[df["controller"] == "test-raises"]
    assert (bad["status"] == "error").all()
    assert bad["message"].str.contains("RuntimeError: injected failure").all()
    good = df[df["controller"] != "test-raises"]
    assert (good["status"] == "ok").all() and len(good) == 2
    assert "test-raises__thesis__s0: error: RuntimeError: injected failure" in proc.stderr
