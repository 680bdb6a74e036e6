"""``pulse-width`` stepped by one compiled function (``compiled_law``): the same rows as its Python form.

The reference is the controller's per-sample Python as it was before its step was compiled
(tests/pulse_width_reference.py, stepped by the runner's Python loop). The compiled step — run
by the family's compiled loop, or called from the Python loop — must give every metric and the
summary bit for bit, on every scenario family, with the quantized sensor, the compute delay and
the disturbance torque (which has no compiled loop: the Python loop calls the compiled step).
"""

from __future__ import annotations

import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from pulse_width_reference import PythonPulseWidth

RUNTIME = ("runtime_s", "realtime_factor")
SCENARIOS = ("thesis", "disturbed", "quantized", "delayed", "stribeck", "compliant")


def _row(r):
    return r.status, r.message, {k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.summary


def _run(c, scenario, seed, **kw):
    sc = builtin_scenarios()[scenario]
    calls = []
    step = c.step
    c.step = lambda y: calls.append(1) or step(y)          # counts the Python steps
    r = run_closed_loop(sc.params, c, duration_s=6.0, warmup_s=1.0, seed=seed, family=sc.family, model=sc.model, **kw)
    return r, len(calls), c


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_compiled_rows_are_the_python_forms_rows(scenario):
    for seed in range(5):
        before, n_before, ref = _run(PythonPulseWidth(), scenario, seed)
        compiled, n_compiled, c = _run(make_controller("pulse-width"), scenario, seed)
        python, n_python, _ = _run(make_controller("pulse-width"), scenario, seed, compiled=False)
        assert before.status == "ok" and n_before == n_python == 600
        assert before.summary["model_inversions"] > 0          # the RLS model is in use, not only start-up
        if scenario != "disturbed":                             # no compiled loop with a disturbance torque
            assert n_compiled == 0                              # the compiled loop really ran
        assert _row(compiled) == _row(before) == _row(python), (scenario, seed)
        assert c.internals() == ref.internals()                 # the state it is left in, too
        assert c.model.predict(c.width) == ref.model.predict(ref.width)


def test_recorded_pulse_times_are_the_python_forms():
    """A recorded run steps from Python; its pulse instants are the reference's."""
    _, _, ref = _run(PythonPulseWidth(), "thesis", 3, record=True)
    _, _, c = _run(make_controller("pulse-width"), "thesis", 3, record=True)
    assert c.event_times()["pulse"].size > 20
    assert c.event_times()["pulse"].tolist() == ref.event_times()["pulse"].tolist()
