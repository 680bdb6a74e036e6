"""CPU per 100 s cell on the ``compliant`` scenario against the same controller on ``thesis``.

Goal (issue #22): the compliant plant costs at most 3× the thesis plant's CPU per 100 s cell for
linear, solnic-modern and pulse-width, measured in the same run (seed 0; compiled code warmed
first by a 1 s cell of each, so the ratio is of simulation, not of compilation). ``make benchmark``
runs it (skipped under ``--benchmark-disable``); measured 2.49-2.55 (linear), 1.10-1.12 (solnic-modern),
2.41-2.50 (pulse-width) on the shared 2-core machine (two runs).
"""

import time

import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from plant.state import Status

pytestmark = pytest.mark.slow


def _cpu(scenario, controller, duration):
    t0 = time.process_time()
    res = run_closed_loop(scenario.params, make_controller(controller), duration_s=duration,
                          warmup_s=min(scenario.warmup_s, duration / 5), seed=0, family=scenario.family)
    assert res.status == Status.OK, res.message
    return time.process_time() - t0


@pytest.mark.parametrize("controller", ["linear", "solnic-modern", "pulse-width"])
def test_compliant_cell_cost_ratio(benchmark, controller):
    if benchmark.disabled:   # `make test`: six 100 s cells only to time them; `make benchmark` runs it
        pytest.skip("a timing only (make benchmark)")
    scen = builtin_scenarios()
    thesis, compliant = scen["thesis"], scen["compliant"]
    for sc in (thesis, compliant):
        _cpu(sc, controller, 1.0)

    def both():
        return _cpu(thesis, controller, thesis.duration_s), _cpu(compliant, controller, compliant.duration_s)

    cpu_thesis, cpu_compliant = benchmark.pedantic(both, rounds=1, iterations=1, warmup_rounds=0)
    ratio = cpu_compliant / cpu_thesis
    benchmark.extra_info.update(cpu_thesis_s=cpu_thesis, cpu_compliant_s=cpu_compliant, ratio=ratio)
    print(f"{controller}: thesis {cpu_thesis:.3f} s, compliant {cpu_compliant:.3f} s CPU, ratio {ratio:.2f}")
    assert ratio <= 3.0
