"""The README's "Write your own controller" example, exactly as printed, through the real CLI."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow


def _example(name: str) -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    m = re.search(rf"<!-- example: {re.escape(name)} -->\n```\w+\n(.*?)\n```", text, re.S)
    assert m, f"README has no example block {name!r}"
    return m.group(1) + "\n"


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "reports.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=600,
                          env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})


def test_readme_plugin_runs_through_the_cli(tmp_path):
    (tmp_path / "nudge.py").write_text(_example("nudge.py"))
    (tmp_path / "nudge.toml").write_text(_example("nudge.toml"))
    listed = _cli("list", "--matrix", tmp_path / "nudge.toml", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert "nudge" in listed.stdout
    proc = _cli("run", "--matrix", tmp_path / "nudge.toml", "--out", tmp_path / "out", "--no-traces",
                cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    df = pd.read_parquet(tmp_path / "out" / "results.parquet").set_index("controller")
    assert set(df.index) == {"nudge", "nudge-wide", "linear"}
    assert (df["status"] == "ok").all(), df["message"]
    assert df.loc["nudge", "controller_family"] == df.loc["nudge-wide", "controller_family"] == "nudge"
    assert df.loc["nudge", "n_corrections"] > 10                       # the counter hook
    assert df.loc["nudge-wide", "ctl_pulses"] < df.loc["nudge", "ctl_pulses"]   # wider band, fewer pulses
    assert (tmp_path / "out" / "report.html").stat().st_size > 0


def test_readme_variant_errors_name_the_field(tmp_path):
    (tmp_path / "nudge.py").write_text(_example("nudge.py"))
    (tmp_path / "nudge.toml").write_text(_example("nudge.toml").replace("band = 10e-6", "band = -1.0"))
    proc = _cli("run", "--matrix", tmp_path / "nudge.toml", "--out", tmp_path / "out", cwd=tmp_path)
    assert proc.returncode == 2
    assert "controllers.nudge-wide.band: band must be > 0 rad, got -1.0" in proc.stderr
    assert not (tmp_path / "out").exists()
