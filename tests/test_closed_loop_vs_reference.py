"""Every registered controller, closed loop and noise-free, against ``solve_ivp`` with events.

Each controller runs 20 s (the dithered one 6 s: its 250 Hz square wave alone gives ~9000
solve_ivp segments, against ~2500 for the others' 20 s) on the exact plant (default parameters, and a second plant with
other inertia, motor lag and friction), its commands are recorded, and the
same command sequence is replayed by ``plant.multimode.reference.event_driven`` (DOP853, rtol 1e-13,
terminal events at every mode change, interior x1 extrema as non-terminal events). The exact
simulator must agree to 1e-9 relative (to the run's largest |x1|) at every sample instant and in
the peak error over the scoring window.

The replays are independent, so they run two at a time in worker processes.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from bench.runner import run_closed_loop
from controllers import available_controllers, make_controller
from controllers.base import Controller
from plant import PlantParams
from plant.multimode.reference import event_driven, schedule_from_commands

pytestmark = pytest.mark.slow

DURATION_S, WARMUP_S = 20.0, 5.0
SHORT = {"dithered": (6.0, 2.0)}                    # (duration, warm-up) [s]
PLANTS = {"table-2-1": PlantParams(),
          "other": PlantParams(inertia=0.8, motor_time_constant=5e-3, coulomb=1.1, stiction=1.9)}


class _Recording(Controller):
    """Passes the inner controller's commands through and keeps them."""

    def __init__(self, inner: Controller) -> None:
        self.inner, self.commands = inner, []
        self.drive = inner.drive
        self.privileged = inner.privileged      # a bound (oracle) still gets the true state

    def reset(self, params, rng):
        self.inner.reset(params, rng)

    def observe_truth(self, state, plant):
        self.inner.observe_truth(state, plant)

    def step(self, y):
        cmd = self.inner.step(y)
        self.commands.append(cmd)
        return cmd


def _case(args: tuple[str, str]) -> dict:
    name, plant = args
    params = PLANTS[plant]
    duration, warmup = SHORT.get(name, (DURATION_S, WARMUP_S))
    rec = _Recording(make_controller(name))
    run = run_closed_loop(params, rec, duration_s=duration, warmup_s=warmup, seed=0, noise=False, record=True)
    if run.status != "ok":
        return {"status": run.status, "message": run.message}
    times = np.arange(len(rec.commands) + 1) * params.sample_period
    ref = event_driven(params, schedule_from_commands(rec.commands, params.sample_period), sample_times=times,
                       rtol=1e-13, atol=1e-22, peak_from=warmup)
    return {"status": run.status, "message": run.message, "exact_x1": run.samples["x1"],
            "ref_x1": ref["x1_at"][:len(run.samples["x1"])], "exact_peak": run.metrics["peak_error_rad"],
            "ref_peak": ref["peak_abs_x1"], "n_segments": ref["n_segments"]}


CASES = [(name, plant) for name in sorted(available_controllers()) for plant in PLANTS]


@pytest.fixture(scope="module")
def replays() -> dict[tuple[str, str], dict]:
    # the dithered replays (thousands of solve_ivp segments) go first, so that the two workers
    # finish together instead of one waiting for a long case submitted last
    order = sorted(CASES, key=lambda c: c[0] != "dithered")
    with ProcessPoolExecutor(max_workers=2) as pool:
        return dict(zip(order, pool.map(_case, order)))


@pytest.mark.parametrize("case", CASES, ids=[f"{n}-{p}" for n, p in CASES])
def test_exact_closed_loop_matches_solve_ivp(replays, case):
    r = replays[case]
    assert r["status"] == "ok", r["message"]
    scale = np.max(np.abs(r["ref_x1"]))
    assert scale > 0
    assert np.max(np.abs(r["exact_x1"] - r["ref_x1"])) <= 1e-9 * scale
    assert abs(r["exact_peak"] - r["ref_peak"]) <= 1e-9 * r["ref_peak"]
