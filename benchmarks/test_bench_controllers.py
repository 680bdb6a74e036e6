"""CPU per 100 s ``thesis`` cell for every registered controller, and what the compiled loop saves.

Goal (issue #27): ≤ 0.1 s CPU per 100 s thesis cell for every registered controller, dithered
≤ 0.15 s. Each controller runs its 100 s cell (seed 0) the way a study runs it — compiled where
the controller declares a compiled step or a linear law (``compiled_law`` / ``linear_law``), else
the Python loop — and, in the same process, with ``compiled=False`` (the Python loop over the
same ``step``), so the ratio is the compiled loop's saving measured under the same load. Against
an older revision: ``benchmarks/compare_revision.py OTHER --controllers all``. Compiled code is
warmed by a 1 s cell of each path first. ``make benchmark`` runs it (skipped under
``--benchmark-disable``).

Known misses are xfail (the assertion stays the goal): dithered and oracle-pulse have no
compiled step yet (pulse-width neither: 0.096–0.102 s, at the goal); solnic-modern's compiled
idle sample leaves the w2 noise model's backward-equation solves (~625–1560 per cell, ~110–190 µs
each) and its heavy pulse samples in Python (docs/solnic.md).
Measured on the shared 2-core machine under load (2026-11-27, load average ~12, CPU per 100 s):

* this benchmark (05:13 UTC, one process, compiled / Python loop over the same ``step``):
  friction-ff-pid 0.009 / 0.074 s (7.9×), observer-pid 0.019 / 0.087 s (4.5×), reset-pid
  0.011 / 0.081 s (7.5×), linear 0.007 / 0.077 s; pulse-width 0.105 and oracle-pulse 0.418
  (no compiled step: both paths the same);
* ``compare_revision.py`` against 0ed8bc0, the revision issue 27's compiled steps started from
  (alternating processes, median of 2 rounds): friction-ff-pid 0.088 → 0.010 s (8.4×),
  observer-pid 0.100 → 0.019 s (5.2×), reset-pid 0.086 → 0.012 s (7.3×), linear 0.007 → 0.008 s
  (the same compiled loop as before). The controllers without a compiled step came out
  0.96–1.9× apart (pulse-width 0.198 → 0.112, solnic-modern 0.907 → 0.484): the noise of two
  rounds on this machine, not a change (their code path is the same; pulse-width measured
  0.105 s on both paths in one process).
"""

import time

import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import available_controllers, make_controller
from plant.state import Status

pytestmark = pytest.mark.slow

THESIS = builtin_scenarios()["thesis"]
_GOAL_S = {"dithered": 0.15}
_DEFAULT_GOAL_S = 0.1
_MISSES = {"dithered", "oracle-pulse", "pulse-width", "solnic-modern"}


def _cpu(name: str, duration: float, compiled: bool) -> float:
    t0 = time.process_time()
    r = run_closed_loop(THESIS.params, make_controller(name), duration_s=duration,
                        warmup_s=min(THESIS.warmup_s, duration / 5), seed=0, compiled=compiled)
    assert r.status == Status.OK, r.message
    return time.process_time() - t0


_CASES = [pytest.param(c, marks=pytest.mark.xfail(reason="no compiled step yet (module docstring)", strict=False)
                       if c in _MISSES else ()) for c in sorted(available_controllers())]


@pytest.mark.parametrize("controller", _CASES)
def test_thesis_cell_cpu_per_controller(benchmark, controller):
    if benchmark.disabled:   # `make test`: a timing only; the rows are tested in tests/test_compiled_law.py
        pytest.skip("a timing only (make benchmark)")
    for compiled in (True, False):
        _cpu(controller, 1.0, compiled)

    def both():
        return _cpu(controller, THESIS.duration_s, True), _cpu(controller, THESIS.duration_s, False)

    cpu, cpu_python = benchmark.pedantic(both, rounds=1, iterations=1, warmup_rounds=0)
    goal = _GOAL_S.get(controller, _DEFAULT_GOAL_S)
    benchmark.extra_info.update(cpu_s=cpu, cpu_python_loop_s=cpu_python, saving=cpu_python / cpu, goal_s=goal)
    print(f"{controller}: {cpu:.3f} s CPU per 100 s thesis cell (Python loop {cpu_python:.3f} s, "
          f"{cpu_python / cpu:.1f}x), goal {goal:g} s")
    assert cpu <= goal
