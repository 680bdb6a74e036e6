"""CPU of frontier cells of controllers with a report series, every cell recorded with its series
written (before issue 27's rule) against the matrix's rule (:func:`bench.driver.reads_series`:
other cells unrecorded where the controller labels no phase), in one process, alternating.

    .venv/bin/python benchmarks/series_cost.py [--per-controller 6] [--slice-seeds 0 1]

Prints the median CPU per cell of each series controller's non-figure cells, both ways, and the
total CPU of a slice of the frontier (every cell of the series controllers on the given seeds
and thesis), both ways; each row is checked equal both ways (timing columns aside).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from bench.cells import RUNTIME_COLUMNS, run_cell
from bench.driver import reads_series
from bench.frontier import frontier_matrix_data
from bench.matrix import parse_matrix
from bench.series import wants_series


def _cpu(cell, out: Path, series: bool) -> tuple[float, dict]:
    t0 = time.process_time()
    row = run_cell(cell, out, False, series)
    return time.process_time() - t0, row


def _same(a: dict, b: dict) -> bool:
    strip = lambda r: {k: v for k, v in r.items() if k not in RUNTIME_COLUMNS}   # noqa: E731
    sa, sb = strip(a), strip(b)
    return sa.keys() == sb.keys() and all(sa[k] == sb[k] or (sa[k] != sa[k] and sb[k] != sb[k]) for k in sa)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-controller", type=int, default=6, help="non-figure cells per series controller")
    ap.add_argument("--slice-seeds", type=int, nargs="*", default=[0, 1])
    args = ap.parse_args()
    matrix = parse_matrix(frontier_matrix_data(), "frontier")
    lowest = min(matrix.seeds)
    cells = matrix.cells()
    series_bases = {c.controller.base for c in cells if wants_series(c.controller.build())}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        for base in sorted(series_bases):     # compile/load everything once
            cell = next(c for c in cells if c.controller.base == base)
            _cpu(cell, out / "warm", True), _cpu(cell, out / "warm", False)
        print(f"frontier: {len(cells)} cells, series controllers {sorted(series_bases)}")
        for base in sorted(series_bases):
            pool = [c for c in cells if c.controller.base == base and not reads_series(c, lowest)]
            step = max(1, len(pool) // args.per_controller)
            before, after = [], []
            for cell in pool[::step][:args.per_controller]:
                b, rb = _cpu(cell, out / "before", True)
                a, ra = _cpu(cell, out / "after", False)
                assert _same(rb, ra), cell.cell_id
                before.append(b), after.append(a)
            mb, ma = statistics.median(before), statistics.median(after)
            print(f"{base}: {len(pool)} non-figure cells; median CPU per cell {mb:.4f} s recorded -> "
                  f"{ma:.4f} s by the rule ({mb / ma:.1f}x), n = {len(before)}")
        part = [c for c in cells if c.controller.base in series_bases and c.seed in args.slice_seeds
                and c.scenario.name == "thesis"]
        tb = ta = 0.0
        for cell in part:
            b, rb = _cpu(cell, out / "slice-before", True)
            a, ra = _cpu(cell, out / "slice-after", False if not reads_series(cell, lowest) else True)
            assert _same(rb, ra), cell.cell_id
            tb, ta = tb + b, ta + a
        n_fig = sum(reads_series(c, lowest) for c in part)
        print(f"slice (series controllers, thesis, seeds {args.slice_seeds}): {len(part)} cells, {n_fig} write a "
              f"series; CPU {tb:.2f} s recorded -> {ta:.2f} s by the rule ({tb / ta:.2f}x)")


if __name__ == "__main__":
    main()
