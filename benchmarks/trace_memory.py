"""Peak RSS of one cell with and without its rerun trace (issue 11: traces stream to disk).

Usage: ``python benchmarks/trace_memory.py [--controller dithered] [--duration 600] [--traces]``
prints ``{"peak_rss_mb": ..., "trace_mb": ..., "wall_s": ...}`` for one cell run in this
process (run it twice, with and without ``--traces``, in fresh processes).
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from pathlib import Path

from bench.cells import Cell, ControllerSpec, run_cell
from bench.scenarios import builtin_scenarios


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", default="dithered")
    parser.add_argument("--duration", type=float, default=600.0)
    parser.add_argument("--traces", action="store_true")
    args = parser.parse_args()
    scenario = builtin_scenarios()["thesis"].with_durations(duration_s=args.duration)
    cell = Cell(ControllerSpec(args.controller, args.controller), scenario, 0)
    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        row = run_cell(cell, out, args.traces)
        wall = time.perf_counter() - t0
        trace = Path(out) / "traces" / f"{cell.cell_id}.rrd"
        size = trace.stat().st_size / 1e6 if trace.exists() else 0.0
    print(json.dumps({"controller": args.controller, "duration_s": args.duration, "traces": args.traces,
                      "status": row["status"], "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "trace_mb": round(size, 2), "wall_s": round(wall, 1)}))


if __name__ == "__main__":
    main()
