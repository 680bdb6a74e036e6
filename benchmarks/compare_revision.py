"""CPU per 100 s thesis cell: this checkout against another revision, measured in one run.

    git worktree add --detach /tmp/base e27ccb7
    .venv/bin/python benchmarks/compare_revision.py /tmp/base [--rounds 3] [--json] [--controllers all|a,b]

Each cell runs in a fresh interpreter with ``PYTHONPATH`` set to one tree (JIT compilation and
imports are excluded: the child warms up on a 1 s cell first and times the 100 s cell with
``time.process_time``). The two trees alternate round by round, so machine load affects both
alike; the ratio of the medians is reported, and whether both trees gave the same status and peak
error in every round ("same peak", a bit-identity check of the cell's headline number). The other
revision's API is only used through ``run_closed_loop`` and ``make_controller``, which both
revisions share.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

_CHILD = r"""
import json, sys, time
from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
name = sys.argv[1]
th = builtin_scenarios()["thesis"]
run_closed_loop(th.params, make_controller(name), duration_s=1.0, seed=99)
t0 = time.process_time()
r = run_closed_loop(th.params, make_controller(name), duration_s=th.duration_s, warmup_s=th.warmup_s, seed=0)
cpu = time.process_time() - t0
print(json.dumps({"cpu_s": cpu, "status": r.status, "peak_error_rad": r.metrics["peak_error_rad"]}))
"""

CONTROLLERS = ("linear", "dithered", "solnic")


def _cell(tree: Path, name: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", _CHILD, name], cwd=tree, env=env, capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", type=Path, help="work tree of the other revision")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--controllers", default=",".join(CONTROLLERS),
                    help="comma-separated names, or 'all' (every controller registered in this tree)")
    args = ap.parse_args()
    if args.controllers == "all":
        from controllers import available_controllers
        names = tuple(sorted(available_controllers()))
    else:
        names = tuple(n.strip() for n in args.controllers.split(",") if n.strip())
    here = Path(__file__).resolve().parent.parent
    times: dict[tuple[str, str], list[float]] = {}
    peaks: dict[tuple[str, str], set] = {}
    for _ in range(args.rounds):
        for name in names:
            for label, tree in (("this", here), ("other", args.other.resolve())):
                cell = _cell(tree, name)
                times.setdefault((label, name), []).append(cell["cpu_s"])
                peaks.setdefault((label, name), set()).add((cell["status"], cell["peak_error_rad"]))
    rows = []
    for name in names:
        this, other = statistics.median(times["this", name]), statistics.median(times["other", name])
        rows.append({"controller": name, "this_cpu_s": this, "other_cpu_s": other, "speedup": other / this,
                     "same_peak": peaks["this", name] == peaks["other", name] and len(peaks["this", name]) == 1})
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(f"{'controller':<16} {'this [s]':>9} {'other [s]':>10} {'speed-up':>9} {'same peak':>10}")
    for r in rows:
        print(f"{r['controller']:<16} {r['this_cpu_s']:>9.3f} {r['other_cpu_s']:>10.3f} {r['speedup']:>8.2f}x "
              f"{'yes' if r['same_peak'] else 'NO':>10}")


if __name__ == "__main__":
    main()
