"""Run-directory integrity (issue 11), end to end through the real CLI: a second matrix into
the same ``--out`` and a full disk. (The hostile cells and the signals are in
``test_run_integrity.py``; the two files run on separate test workers.)"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pandas as pd
import pytest

from cli_helpers import cli, write_matrix

pytestmark = pytest.mark.slow


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
