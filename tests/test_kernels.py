"""Each row names the numeric kernels that computed it; `run` and the report say when rows mix them.

The truth for the kernel names is the environment: where ``OPENBLAS_CORETYPE`` forces OpenBLAS's
kernel (as this machine's shell does), every OpenBLAS listed must run that kernel. The tests never
set it (the machine's rules forbid changing it in tests and CI).
"""

from __future__ import annotations

import os
import re

import numpy as np
import pandas as pd
import pytest

from bench.cells import Cell, ControllerSpec, run_cell
from bench.kernels import KERNEL_COLUMN, mixed_kernels_note, numeric_kernel
from bench.scenarios import builtin_scenarios


def test_numeric_kernel_lists_numpys_and_scipys_blas_and_the_simd_level():
    text = numeric_kernel()
    parts = text.split("; ")
    assert parts[-1].startswith("simd ") and len(parts[-1]) > len("simd ")
    libs = {p.split(" ")[0]: p.split(" ") for p in parts[:-1]}
    # the wheels ship their own OpenBLAS: numpy's (numpy's @) and scipy's (numba's @ and np.dot)
    assert {"numpy", "scipy"} <= set(libs), text
    forced = os.environ.get("OPENBLAS_CORETYPE")
    for owner, (_, api, version, arch) in libs.items():
        assert re.fullmatch(r"\d+(\.\d+)+", version), text
        if api == "openblas" and forced:
            assert arch.lower() == forced.lower(), (forced, text)


def test_a_cells_row_carries_its_kernel_and_a_failure_row_an_empty_one(tmp_path):
    base = builtin_scenarios()["thesis"].with_durations(duration_s=0.5, warmup_s=0.1)
    row = run_cell(Cell(ControllerSpec("linear", "linear"), base, 0), tmp_path, False)
    assert row["status"] == "ok" and row[KERNEL_COLUMN] == numeric_kernel()
    from bench.cells import failure_row
    assert failure_row(Cell(ControllerSpec("linear", "linear"), base, 1), "crash", "x")[KERNEL_COLUMN] == ""


def test_mixed_kernels_note_names_each_kernel_with_its_rows():
    a, b = "numpy openblas 0.3.31 Haswell; simd AVX512_ICL", "numpy openblas 0.3.31 SkylakeX; simd AVX512_ICL"
    one = pd.DataFrame({KERNEL_COLUMN: [a, a, "", np.nan]})
    assert mixed_kernels_note(one) is None
    assert mixed_kernels_note(pd.DataFrame({"x": [1]})) is None
    note = mixed_kernels_note(pd.DataFrame({KERNEL_COLUMN: [a, b, b, "", np.nan]}))
    assert note is not None and "2 numeric kernels" in note
    assert f"[{a}]: 1 rows" in note and f"[{b}]: 2 rows" in note


@pytest.mark.parametrize("mixed", [False, True])
def test_the_report_inputs_say_when_rows_mix_kernels(tmp_path, mixed):
    from reports.inputs import load_inputs
    a, b = "numpy openblas 1 Haswell; simd X", "numpy openblas 1 SkylakeX; simd X"
    rows = pd.DataFrame({"controller": ["c", "c"], "scenario": ["s", "s"], "seed": [0, 1], "status": ["ok", "ok"],
                         "peak_error_rad": [1e-5, 2e-5], KERNEL_COLUMN: [a, b if mixed else a]})
    rows.to_parquet(tmp_path / "results.parquet")
    notes = load_inputs(tmp_path).notes
    hits = [n for n in notes if "numeric kernels" in n]
    assert len(hits) == (1 if mixed else 0), notes
