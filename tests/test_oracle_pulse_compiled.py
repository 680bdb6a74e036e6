"""oracle-pulse's on-time search compiled by the multimode family (``PlantFamily.pulse_on_time``):
the same numbers as the Python search over ``pulse_motion`` it replaces.

The reference is :func:`controllers.oracle_pulse._on_time_for` (the Illinois regula falsi in
Python, one compiled ``pulse_motion`` call per trial pulse), which the oracle still runs for a
family without the fast path; with the fast path removed from :class:`plant.protocol.TruePlant`
the oracle runs exactly its code before the change.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from controllers.oracle_pulse import _MAX_ITERATIONS, _TOL_S, _on_time_for
from controllers.models.acker import max_on_time
from plant.params import PlantParams
from plant.protocol import TruePlant, get_family
from plant.state import PlantState

RUNTIME = ("runtime_s", "realtime_factor")
SCENARIOS = ("thesis", "disturbed", "quantized", "delayed", "stribeck", "compliant")


def _row(r):
    return r.status, r.message, {k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.summary


def _run(scenario, seed):
    sc = builtin_scenarios()[scenario]
    return run_closed_loop(sc.params, make_controller("oracle-pulse"), duration_s=4.0, warmup_s=1.0, seed=seed,
                           family=sc.family, model=sc.model)


def test_compiled_search_is_the_python_search_bit_for_bit():
    rng = np.random.default_rng(7)
    params = PlantParams()
    truth = TruePlant(get_family(builtin_scenarios()["thesis"].family), params)
    dtu_max = max_on_time(params)
    checked = 0
    for _ in range(40):
        x = np.array([rng.normal(0, 5e-6), 0.0, 0.0, rng.normal(0, 3e-5), rng.normal(0, 0.3), 0.0])
        x.flags.writeable = False
        state = PlantState(0.0, x, 2, False)
        motion = float(rng.uniform(0.2e-6, 12e-6))
        sign = int(rng.choice([-1, 1]))
        fast = truth.pulse_on_time(state, motion, sign, dtu_max, _TOL_S, _MAX_ITERATIONS)

        def response(dtu):
            dc, t_stop = truth.pulse_motion(state, dtu, sign)
            return abs(dc), t_stop

        slow = _on_time_for(motion, dtu_max, response)
        assert fast is not None and fast == slow             # every float of the triple, exactly
        checked += slow[1] >= motion
    assert checked >= 30                                     # mostly real roots, not the dtu_max cap


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_oracle_rows_are_those_of_the_python_search(scenario, monkeypatch):
    for seed in range(5):
        compiled = _run(scenario, seed)
        with monkeypatch.context() as m:
            m.setattr(TruePlant, "pulse_on_time", lambda *a: None)   # the oracle's own Python search
            before = _run(scenario, seed)
        assert before.status == "ok" and before.summary["pulses"] >= 3
        assert _row(compiled) == _row(before), (scenario, seed)
