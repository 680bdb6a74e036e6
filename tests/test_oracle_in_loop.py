"""oracle-pulse in the families' compiled loops: a privileged compiled step that reads the truth.

The reference is the runner's Python loop (``compiled=False``): ``observe_truth`` and the
oracle's ``step`` at every sample. In the compiled loop the waiting samples are
:func:`controllers.oracle_pulse._oracle_step`, reading the true state the loop appends to ``p``
(``CompiledLaw.truth``); a sample that may fire is handed back to the Python ``step``. Every
metric and the summary must be those of the reference, bit for bit, on every family with a
compiled loop, with the quantized sensor, the compute delay and the x1 log. The truth reaches a
compiled step only for a class with ``privileged = True``: the runner refuses it otherwise.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from controllers.base import Controller
from controllers.law import CompiledLaw, law_command
from plant.drive import DriveType
from plant.state import X1

RUNTIME = ("runtime_s", "realtime_factor")


def _row(r):
    return r.status, r.message, {k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.summary


def _run(controller, scenario, seed, *, duration=4.0, **kw):
    sc = builtin_scenarios()[scenario]
    calls = []
    step = controller.step
    controller.step = lambda y: calls.append(1) or step(y)        # counts the Python steps
    r = run_closed_loop(sc.params, controller, duration_s=duration, warmup_s=1.0, seed=seed, family=sc.family,
                        model=sc.model, **kw)
    return r, len(calls)


@pytest.mark.parametrize("scenario, seed, band", [
    ("thesis", 0, 4e-6), ("thesis", 1, 0.5e-6), ("quiet-friction", 2, 16e-6), ("quantized", 3, 4e-6),
    ("delayed", 4, 2e-6), ("disturbed", 5, 4e-6), ("stribeck", 6, 4e-6), ("compliant", 7, 8e-6), ("lugre", 8, 4e-6),
])
def test_oracle_rows_in_the_compiled_loop_are_the_python_loops(scenario, seed, band):
    python, n_py = _run(make_controller("oracle-pulse", band=band), scenario, seed, compiled=False)
    fast, n_fast = _run(make_controller("oracle-pulse", band=band), scenario, seed)
    assert python.status == "ok" and python.summary["pulses"] >= 3
    assert _row(fast) == _row(python), scenario
    n_samples = round(4.0 / builtin_scenarios()[scenario].params.sample_period)
    assert n_py == n_samples
    # only the samples that may fire reach Python: at least one per pulse, and few
    assert python.summary["pulses"] <= n_fast < 0.2 * n_samples


def test_oracle_x1_log_in_the_compiled_loop_is_the_python_loops():
    python, _ = _run(make_controller("oracle-pulse", band=1e-6), "thesis", 9, compiled=False, x1_log=True)
    fast, n_fast = _run(make_controller("oracle-pulse", band=1e-6), "thesis", 9, x1_log=True)
    n_samples = round(4.0 / builtin_scenarios()["thesis"].params.sample_period)
    assert _row(fast) == _row(python) and n_fast < 0.2 * n_samples
    for got, want in ((fast.samples, python.samples), (fast.events, python.events)):
        for key in ("t", "x1"):
            np.testing.assert_array_equal(got[key], want[key])


# ---------------------------------------------------------------- who may read the truth
@njit(cache=True)
def _truth_probe_step(s, p, y, offs, levs):
    """Hold 0 and keep, for the test, p's length, the t and x1 the truth tail gives and Σ x1."""
    h = int(p[0])
    s[0] = p.shape[0]
    if p.shape[0] > h:
        s[1], s[2] = p[-3], p[h + X1]
        s[3] += p[h + X1]
    offs[0], levs[0] = 0.0, 0.0
    return 1


class _Probe(Controller):
    drive = DriveType.BRIDGE
    wants_truth = True

    def reset(self, params, rng):
        self._s, self._p = np.zeros(4), np.array([1.0])
        self._offs, self._levs = np.zeros(1), np.zeros(1)

    def step(self, y):
        return law_command(_truth_probe_step(self._s, self._p, y, self._offs, self._levs), self._offs, self._levs,
                           DriveType.BRIDGE)

    def compiled_law(self):
        return CompiledLaw(_truth_probe_step, self._s, self._p, DriveType.BRIDGE, 1, truth=self.wants_truth)


class _PrivilegedProbe(_Probe):
    privileged = True

    def observe_truth(self, state, plant):
        pass


def test_a_compiled_step_reads_the_truth_only_when_privileged():
    sc = builtin_scenarios()["thesis"]
    # a real controller whose compiled step asks for the truth: the run is refused
    r = run_closed_loop(sc.params, _Probe(), duration_s=1.0, seed=0)
    assert r.status == "error" and "not privileged" in r.message
    # without asking, its p is its own parameters only
    blind = _Probe()
    blind.wants_truth = False
    assert run_closed_loop(sc.params, blind, duration_s=1.0, seed=0).status == "ok"
    assert blind._s[0] == 1.0 and blind._s[3] == 0.0
    # a privileged one sees, at every sample, the state the runner logs at that sample instant
    bound = _PrivilegedProbe()
    r = run_closed_loop(sc.params, bound, duration_s=1.0, seed=0, x1_log=True)
    assert r.status == "ok"
    t, x1 = r.samples["t"], r.samples["x1"]
    assert len(t) == round(1.0 / sc.params.sample_period) and bound._s[0] == 1.0 + 6 + 3
    assert (bound._s[1], bound._s[2]) == (t[-1], x1[-1])
    acc = 0.0
    for v in x1:
        acc += v
    assert bound._s[3] == acc and acc != 0.0


def test_firing_samples_run_inside_the_loop(monkeypatch):
    """A sample that may fire runs the Python step from inside the compiled loop (objmode): the
    loop is entered once for the first such sample's hand-back (the runner hands over the true
    plant) and once more, not once per pulse — and the row is still the Python loop's."""
    import plant.multimode.law_loop as mm

    entries = []
    real = mm.run_law_chunks
    monkeypatch.setattr(mm, "run_law_chunks", lambda *a, **k: entries.append(1) or real(*a, **k))
    python, _ = _run(make_controller("oracle-pulse", band=0.5e-6), "thesis", 3, compiled=False)
    fast, _ = _run(make_controller("oracle-pulse", band=0.5e-6), "thesis", 3)
    assert _row(fast) == _row(python) and python.summary["pulses"] >= 20
    assert len(entries) == 2, len(entries)
