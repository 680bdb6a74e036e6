"""CPU per 100 s cell on ``disturbed``, ``quantized`` and ``delayed`` against the same controller on
``thesis``, measured in the same run (issue #22 goal: ≤ 1.5×).

Seed 0; compiled code warmed first by a 1 s cell of each, so the ratio is of simulation, not of
compilation. ``make benchmark`` runs it (skipped under ``--benchmark-disable``). Pairs known to
miss the goal are marked xfail with the reason (the assertion stays the goal):

* ``disturbed``: the disturbance path (plant/multimode/disturbed.py) is Python over numpy, with
  no compiled interval and no compiled linear-law loop yet;
* ``delayed`` with ``linear``: since issue 27 the linear law runs on ``quantized`` and ``delayed``
  in the compiled-law loop (plant/law_step.py; before, the per-sample Python path: 10.5× and
  13.5×); the delay adds a segment boundary, hence plant work, to every interval, and the ratio
  measured 0.99–1.6× over three runs (loaded machine, 2026-11-27 04:30–05:15 UTC; quantized
  1.2–1.4×): at the goal, within the noise, so left marked.

Measured on the shared, heavily loaded 2-core machine (one run): quantized/thesis linear 10.5,
solnic-modern 0.88, pulse-width 1.02; delayed/thesis linear 13.5, solnic-modern 0.99, pulse-width
1.39. ``disturbed`` was not benchmarked here; from a matrix run (same machine, seeds 0-2, CPU per
100 s cell): solnic-modern ~5x, pulse-width ~34x, linear ~900x (its thesis cell is the compiled loop).
After the disturbed path's caches (same loaded machine, seed 0, one process, old and new path
alternated, CPU per 100 s cell, results bit-identical): dithered 63.0 -> 35.7 s (thesis 0.46 s:
137x -> 78x), pulse-width 2.51 -> 1.60 s (26x -> 16x), linear 1.12 -> 0.78 s (thesis 0.01 s in the
compiled loop: ~170x -> ~115x).
"""

import pytest

from bench.scenarios import builtin_scenarios
from benchmarks.cell_cost import cell_cpu

pytestmark = pytest.mark.slow

_GOAL = 1.5
_MISSES = {("disturbed", "linear"), ("disturbed", "solnic-modern"), ("disturbed", "pulse-width"),
           ("delayed", "linear")}


_CASES = [pytest.param(s, c, marks=pytest.mark.xfail(reason="known miss, see module docstring", strict=False)
                       if (s, c) in _MISSES else ())
          for s in ("disturbed", "quantized", "delayed") for c in ("linear", "solnic-modern", "pulse-width")]


@pytest.mark.parametrize("name, controller", _CASES)
def test_real_plant_cell_cost_ratio(benchmark, name, controller):
    if benchmark.disabled:   # `make test`: 100 s cells only to time them; `make benchmark` runs it
        pytest.skip("a timing only (make benchmark)")
    scen = builtin_scenarios()
    thesis, other = scen["thesis"], scen[name]
    for sc in (thesis, other):
        cell_cpu(sc, controller, 1.0)

    def both():
        return cell_cpu(thesis, controller, thesis.duration_s), cell_cpu(other, controller, other.duration_s)

    cpu_thesis, cpu_other = benchmark.pedantic(both, rounds=1, iterations=1, warmup_rounds=0)
    ratio = cpu_other / cpu_thesis
    benchmark.extra_info.update(cpu_thesis_s=cpu_thesis, cpu_other_s=cpu_other, ratio=ratio)
    print(f"{controller} on {name}: thesis {cpu_thesis:.3f} s, {name} {cpu_other:.3f} s CPU, ratio {ratio:.2f}")
    assert ratio <= _GOAL
