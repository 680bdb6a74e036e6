"""Wall time of ``solnic-bench identify`` on simulated logs (issue 25: "fitting time per log ≤ 60 s on 2 cores").

    .venv/bin/python benchmarks/fit_time.py [--seed 7207] [--cases 1] [--workers 2] [--modes auto,own]
                                            [--families multimode,stribeck,lugre,two-mass] [--doublets 0] [--json]

For each family and case a log of the default plan (``design_experiment()``, Table 2-1 noise) is
simulated (``--doublets N``: the plan with N torque doublets per width and direction) from
``tests/identify_draws.draw``'s parameters — the draws and log seeds of the coverage
studies (docs/axis.md: ``rng = default_rng([seed, family index])``, the case-th draw, log seed
``seed·1000 + case``) — and written as CSV; then the command a user runs on it is timed as a
subprocess, wall clock from launch to exit (start-up, imports, the forkserver's workers, the fit, the
bootstrap of 20 replicates, the HTML page): ``identify LOG --family auto --workers N`` ("auto": the
held-out choice over the four families, its two folds on two workers, then the chosen family's fit)
and ``identify LOG --family F --workers N`` ("own": the generating family's fit). The fits' work is
counted, not timed (docs/axis.md, "Budgets"), so every run does the same work; only the wall clock
depends on the machine. The 1-minute load average before each run is printed with it: a figure is
only the machine's when the load was near 0. Exit 1 if any run exceeded 60 s or failed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GOAL_S = 60.0
ROOT = Path(__file__).resolve().parents[1]     # the checkout: tests/identify_draws.py is the studies' draw
FAMILIES = ("multimode", "stribeck", "lugre", "two-mass")


def _log(family: str, seed: int, case: int, path: Path, doublets: int = 0) -> dict:
    """Simulate the case-th coverage-study log of ``family`` at ``seed`` into ``path``; its truth."""
    import numpy as np

    from plant.identification import ExperimentOptions, design_experiment, simulate_log
    from plant.identification.families import FAMILY_FREE
    from plant.identification.log import write_log
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from tests.identify_draws import draw

    rng = np.random.default_rng([seed, list(FAMILY_FREE).index(family)])
    for _ in range(case + 1):
        p = draw(family, rng)
    log, truth = simulate_log(design_experiment(ExperimentOptions(doublets=doublets)), family, p, seed * 1000 + case)
    write_log(log, path)
    return {k: getattr(p, k) for k in ("coulomb", "stiction", "inertia", "motor_time_constant")}


def _identify(log: Path, family: str, workers: int, out: Path) -> tuple[float, str, int]:
    """(wall s, the family the command chose, exit code) of one ``identify`` run."""
    exe = Path(sys.executable).with_name("solnic-bench")
    cmd = [str(exe), "identify", str(log), "--family", family, "--workers", str(workers), "--out", str(out)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"})
    wall = time.perf_counter() - t0
    chosen = next((line.split()[1] for line in proc.stdout.splitlines() if line.startswith("family:")), family)
    return wall, chosen, proc.returncode


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=7207)
    ap.add_argument("--cases", type=int, default=1, help="logs per family (cases 0 … N−1)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--modes", default="auto,own", help="auto, own, or both (comma-separated)")
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--doublets", type=int, default=0, help="torque doublets in the plan (experiment --doublets)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    modes = [m for m in args.modes.split(",") if m]
    if not modes or any(m not in ("auto", "own") for m in modes):
        ap.error(f"--modes: auto and/or own, got {args.modes!r}")
    families = [f for f in args.families.split(",") if f]
    if not families or any(f not in FAMILIES for f in families):
        ap.error(f"--families: among {', '.join(FAMILIES)}, got {args.families!r}")
    rows, bad = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        for family in families:
            for case in range(args.cases):
                log = Path(tmp) / f"{family}-{case}.csv"
                _log(family, args.seed, case, log, args.doublets)
                for mode in modes:
                    load = os.getloadavg()[0]
                    wall, chosen, rc = _identify(log, "auto" if mode == "auto" else family, args.workers,
                                                 Path(tmp) / f"{family}-{case}-{mode}.toml")
                    row = {"family": family, "case": case, "mode": mode, "wall_s": round(wall, 1),
                           "chosen": chosen, "exit": rc, "load_before": round(load, 2)}
                    bad += rc != 0 or wall > GOAL_S
                    rows.append(row)
                    if not args.json:
                        flag = "" if rc == 0 and wall <= GOAL_S else ("  FAILED" if rc else f"  > {GOAL_S:.0f} s")
                        print(f"{family:10s} case {case}  {mode:4s}  {wall:6.1f} s  chose {chosen:10s}"
                              f"  load before {load:4.2f}{flag}", flush=True)
    if args.json:
        print(json.dumps({"seed": args.seed, "workers": args.workers, "doublets": args.doublets, "goal_s": GOAL_S, "rows": rows}))
    else:
        print(f"{len(rows) - bad} of {len(rows)} runs ≤ {GOAL_S:.0f} s on {args.workers} workers (seed {args.seed}, "
              f"doublets {args.doublets})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
