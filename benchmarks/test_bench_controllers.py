"""CPU per 100 s ``thesis`` cell for every registered controller, and what the compiled loop saves.

Goal (issue #27): ≤ 0.1 s CPU per 100 s thesis cell for every registered controller, dithered
≤ 0.15 s. Each controller runs its 100 s cell (seed 0) the way a study runs it — compiled where
the controller declares a compiled step or a linear law (``compiled_law`` / ``linear_law``), else
the Python loop — and, in the same process, with ``compiled=False`` (the Python loop over the
same ``step``), so the ratio is the compiled loop's saving measured under the same load. Against
an older revision: ``benchmarks/compare_revision.py OTHER --controllers all``. Compiled code is
warmed by a 1 s cell of each path first. ``make benchmark`` runs it (skipped under
``--benchmark-disable``).

Known misses are xfail (the assertion stays the goal): dithered (its cell is the exact bridge's
sub-steps: normals, the bridge loop, erfc/log; at the goal on seed 0 since the eleventh session,
0.209 → 0.148 s against 0fa69d0, seeds 1, 3, 4 at 0.153–0.158 s; docs/plant.md "Eleventh
session"), so a non-strict xfail, and solnic-modern (the idle step's
backward-equation solves and ~1130 Python samples a cell, since 8f0a95b called from inside the
compiled loop: 0.302 → 0.234 s against 578603d, solnic 0.060 → 0.043 s; the full solve's second
moment beside the first: 0.223 → 0.208 s against 75447cc; the Python sample going on from the
step's filter updates and trigger test, the joint EKF's launch and constraints compiled: 0.217 →
0.195 s against b0b4871; docs/solnic.md); oracle-pulse is
at the goal (0.093–0.097 s) and over it under load, so it stays a non-strict xfail.
Measured with ``compare_revision.py`` against deed667, the revision before issue 27's work
(2026-11-27 10:20 UTC, 2 cores loaded by two helpers, alternating fresh processes, medians of 3,
seed 0; every controller gave the same status and peak error in both trees):

================ ========= ========= =========
controller       this [s]  deed667   speed-up
================ ========= ========= =========
dithered         0.257     0.463     1.80×
friction-ff-pid  0.006     0.084     14.3×
linear           0.005     0.007     1.54×
observer-pid     0.011     0.094     8.8×
oracle-pulse     0.096     0.601     6.3×
pulse-width      0.013     0.097     7.5×
reset-pid        0.007     0.083     12.7×
solnic           0.056     0.138     2.5×
solnic-modern    0.274     0.417     1.5×
================ ========= ========= =========
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
_MISSES = {"dithered", "oracle-pulse", "solnic-modern"}


def _cpu(name: str, duration: float, compiled: bool) -> float:
    t0 = time.process_time()
    r = run_closed_loop(THESIS.params, make_controller(name), duration_s=duration,
                        warmup_s=min(THESIS.warmup_s, duration / 5), seed=0, compiled=compiled)
    assert r.status == Status.OK, r.message
    return time.process_time() - t0


_CASES = [pytest.param(c, marks=pytest.mark.xfail(reason="over the goal (module docstring)", strict=False)
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
