"""The check: every cell of the plan on a process pool, the verdicts, and the files
``bound.csv``, ``hunting.csv``, ``hunting_runs.csv`` and ``bound_verdict.json``."""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import pandas as pd

from bench.bound.cells import BoundCell, HuntingCell, bound_cells, hunting_cells
from bench.bound.plan import RAMP_VELOCITY, SweepPlan, _table_2_1, sweep_plan
from bench.bound.run import run_bound_cell, run_hunting_cell
from bench.bound.verdict import BOUND_COLUMNS, _json_safe, _plain, bound_verdict, hunting_onsets
from bench.errors import UserError
from bench.store import write_atomic

__all__ = ["BoundResult", "check_bound"]


@dataclass
class BoundResult:
    """What :func:`check_bound` measured and wrote."""

    plan: SweepPlan
    bound: pd.DataFrame
    hunting: pd.DataFrame
    hunting_runs: pd.DataFrame
    verdict: dict[str, Any]
    paths: dict[str, Path] = field(default_factory=dict)
    wall_s: float = 0.0


def _run_any(cell: BoundCell | HuntingCell) -> tuple[str, dict[str, Any]]:
    if isinstance(cell, BoundCell):
        return "bound", run_bound_cell(cell)
    return "hunting", run_hunting_cell(cell)


def _execute(cells: list, workers: int, progress: Callable[[int, int], None] | None
             ) -> tuple[list[dict], list[dict]]:
    """Run cells on a process pool, most expensive first (keeps both workers busy to the end)."""
    order = sorted(range(len(cells)), key=lambda i: -cells[i].cost())
    results: dict[int, tuple[str, dict]] = {}
    total = len(cells)
    if workers <= 1:
        for n, i in enumerate(order, 1):
            results[i] = _run_any(cells[i])
            if progress:
                progress(n, total)
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            pending = {pool.submit(_run_any, cells[i]): i for i in order}
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    results[pending.pop(fut)] = fut.result()
                    if progress:
                        progress(len(results), total)
    bound = [results[i][1] for i in range(total) if results[i][0] == "bound"]
    hunting = [results[i][1] for i in range(total) if results[i][0] == "hunting"]
    return bound, hunting


def _write_csv(path: Path, df: pd.DataFrame) -> None:
    write_atomic(path, df.to_csv(index=False))


def check_bound(quick: bool, out_dir: Path, workers: int | None = None,
                progress: Callable[[int, int], None] | None = None, *, tiny: bool = False
                ) -> BoundResult:
    """Run the (2-6) and (2-1) sweeps and write ``bound.csv``, ``hunting.csv``,
    ``hunting_runs.csv`` and ``bound_verdict.json`` to ``out_dir``.

    Parameters
    ----------
    quick : bool
        The reduced sweep of ``--quick`` (≤ 2 min on 2 cores).
    out_dir : Path
        Output directory (created).
    workers : int, optional
        Worker processes; default ``os.cpu_count()``.
    progress : callable, optional
        Called as ``progress(done, total)`` after each cell.
    tiny : bool
        A minimal sweep for the test suite only.
    """
    t0 = time.perf_counter()
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers!r}")
    workers = workers or os.cpu_count() or 1
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"--out {out_dir}: exists and is not a directory")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--out {out_dir}: cannot create it ({exc.strerror or exc})") from None
    plan = sweep_plan("tiny" if tiny else "quick" if quick else "full")
    bcells, hcells = bound_cells(plan), hunting_cells(plan)
    bound_rows, hunting_rows = _execute([*bcells, *hcells], workers, progress)

    bound = pd.DataFrame(bound_rows)
    bound = bound[list(BOUND_COLUMNS) + [c for c in bound.columns if c not in BOUND_COLUMNS]]
    runs = pd.DataFrame(hunting_rows)
    onsets = hunting_onsets(runs)
    verdict = bound_verdict(bound)
    base = _table_2_1()
    verdict.update({
        "inequality": "theta >= theta_b = (ks - kc) / (2 J omega_c^2)  (2-6)",
        "classical_limit_rad": base.classical_bound(),         # ωb = π/τs, Table 2-1
        "hunting": [{k: _plain(r[k]) for k in ("ks_over_kc", "lmax", "onset_L", "onset_over_lmax",
                                               "highest_quiet_L")}
                    for _, r in onsets.iterrows()],
        "mode": plan.mode, "workers": workers, "wall_s": time.perf_counter() - t0,
        "plan": asdict(plan),
        "ramp_velocity_rad_s": RAMP_VELOCITY,
        "hunting_noise": False,
    })
    paths = {"bound": out_dir / "bound.csv", "hunting": out_dir / "hunting.csv",
             "hunting_runs": out_dir / "hunting_runs.csv", "verdict": out_dir / "bound_verdict.json"}
    _write_csv(paths["bound"], bound)
    _write_csv(paths["hunting"], onsets)
    _write_csv(paths["hunting_runs"], runs)
    write_atomic(paths["verdict"], json.dumps(_json_safe(verdict), indent=2) + "\n")
    return BoundResult(plan, bound, onsets, runs, verdict, paths, time.perf_counter() - t0)
