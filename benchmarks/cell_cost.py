"""CPU of one closed-loop cell of a built-in scenario: the common measure of the real-plant cost
benchmarks (a ratio to the same controller on thesis, measured in the same run)."""

import time

from bench.runner import run_closed_loop
from controllers import make_controller
from plant.state import Status


def cell_cpu(scenario, controller: str, duration: float) -> float:
    """CPU seconds of ``controller`` on ``scenario`` for ``duration`` s (seed 0; the controller is
    told the scenario's model); the cell must end ok."""
    t0 = time.process_time()
    res = run_closed_loop(scenario.params, make_controller(controller), duration_s=duration,
                          warmup_s=min(scenario.warmup_s, duration / 5), seed=0, family=scenario.family,
                          model=scenario.model)
    assert res.status == Status.OK, res.message
    return time.process_time() - t0
