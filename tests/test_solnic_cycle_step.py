"""solnic-modern's post-hand-over cycle compiled in the joint step (:mod:`controllers.solnic.cycle_step`).

The reference is the same controller with the cycle off (``cycle_in_loop = False``: every such
sample is the Python step inside the loop, itself checked against the runner's Python loop in
tests/test_solnic_in_loop.py) and the runner's Python loop (``compiled=False``). Rows, the
summary, the evaluation log and the NIS list must be equal bit for bit (``==``, NaN = NaN), and
the filter, schedule, pending cycle and t_max at the end too; and the compiled cycle must have
taken most of the post-hand-over samples (else the test would not test it). The pieces whose bits are not obviously the Python's — libm's ``pow`` for ``x**2``,
libm's ``erf`` for ``NormalDist.cdf``, the trigger — are compared with their Python originals.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
import pytest
from numba import njit

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from controllers.solnic import cycle_step
from controllers.solnic.strategy import plan_trigger

RUNTIME = ("runtime_s", "realtime_factor")


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b


def _run(scenario, seed, duration, *, cycle=True, compiled=True, **fields):
    sc = builtin_scenarios()[scenario]
    c = make_controller("solnic-modern", **fields)
    c.cycle_in_loop = cycle
    post = []                                    # Python samples after the grid's hand-over
    staged = c._staged_step
    c._staged_step = lambda: post.append(c.grid is None) or staged()
    r = run_closed_loop(sc.params, c, duration_s=duration, warmup_s=duration / 5, seed=seed, family=sc.family,
                        model=sc.model, compiled=compiled)
    pend = c._pending
    state = (c._t_max, c._undecided, c.joint.z.tolist(), c.joint.P.tolist(), c.joint.motion_prior,
             None if pend is None else [v.tolist() if isinstance(v, np.ndarray) else v for v in vars(pend).values()],
             vars(c.schedule), c.joint.n_motion_updates)
    row = (r.status, r.message, {k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.summary,
           c.log, c._nis, state)
    return row, sum(post), c


@pytest.mark.parametrize("scenario, seed", [("thesis", 0), ("thesis", 1), ("disturbed", 2), ("delayed", 3),
                                            ("quiet-friction", 4)])
def test_cycle_rows_equal_the_python_cycle(scenario, seed):
    """On and off: the same rows, log and NIS; on, most post-hand-over samples stay compiled."""
    on, n_on, c_on = _run(scenario, seed, 30.0)
    off, n_off, _ = _run(scenario, seed, 30.0, cycle=False)
    for a, b in zip(on, off):
        assert _same(a, b)
    assert c_on.counts["grid_handover_cycle"] > 0 and c_on.counts["cycles_evaluated"] > 100
    assert n_off > 100 and n_on < 0.25 * n_off, (n_on, n_off)


def test_cycle_rows_equal_the_runner_python_loop():
    """Against the runner's Python loop (no compiled step at all), thesis seed 5, with braked pairs."""
    on, _, c = _run("thesis", 5, 30.0)
    ref, _, _ = _run("thesis", 5, 30.0, compiled=False)
    for a, b in zip(on, ref):
        assert _same(a, b)
    assert c.counts["braked_pulses"] > 0


def test_cycle_without_the_grid():
    """friction_grid off: the cycle runs from the start (no hand-over)."""
    on, n_on, _ = _run("thesis", 6, 20.0, friction_grid=False)
    off, n_off, _ = _run("thesis", 6, 20.0, cycle=False, friction_grid=False)
    for a, b in zip(on, off):
        assert _same(a, b)
    assert n_on < 0.25 * n_off


@njit(cache=True)
def _sq_many(x, two):
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        out[i] = cycle_step._sq(x[i], two)
    return out


@njit(cache=True)
def _cdf_many(x):
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        out[i] = 0.5 * (1.0 + math.erf((x[i] - 0.0) / (1.0 * math.sqrt(2.0))))
    return out


def test_pow_and_cdf_are_pythons():
    """``_sq`` is CPython's ``x**2`` and the cycle's cdf is ``NormalDist().cdf``, on 200 000 inputs
    over 40 decades and both signs (and 0, ±inf, NaN)."""
    rng = np.random.default_rng(27)
    x = rng.standard_normal(200_000) * 10.0 ** rng.uniform(-20, 20, 200_000)
    x = np.concatenate((x, [0.0, -0.0, math.inf, -math.inf, math.nan]))
    got = _sq_many(x, 2.0)
    want = np.array([v ** 2 for v in x.tolist()])
    assert np.array_equal(got, want, equal_nan=True)
    z = np.concatenate((rng.standard_normal(200_000) * 3.0, rng.uniform(-40, 40, 1000), [0.0, math.inf, -math.inf]))
    nd = NormalDist()
    assert np.array_equal(_cdf_many(z), np.array([nd.cdf(v) for v in z.tolist()]))


@njit(cache=True)
def _trigger(x1, x4, x4_std, dc, horizon, earliest, duration, over):
    return cycle_step._trigger(x1, x4, x4_std, dc, horizon, earliest, duration, over)


def test_trigger_is_plan_trigger():
    """``_trigger`` against :func:`plan_trigger` on 20 000 random cases (both x̂4 branches, the
    overshoot correction, offsets inside the interval)."""
    rng = np.random.default_rng(5)
    n_fire = 0
    for _ in range(20_000):
        x1, x4 = rng.normal(0, 2e-5), rng.choice([0.0, rng.normal(0, 3e-4)])
        std, dc = abs(rng.normal(0, 1e-4)), rng.uniform(0, 4e-5)
        earliest, duration = max(0.0, rng.uniform(-5e-4, 5e-4)), rng.uniform(0, 2e-3)
        ref = plan_trigger(x1, x4, std, dc, horizon=1e-3, earliest=earliest, duration=duration, overshoot_factor=1.5)
        fires, sign, offset, over = _trigger(x1, x4, std, dc, 1e-3, earliest, duration, 1.5)
        assert fires == (ref is not None)
        if ref is not None:
            n_fire += 1
            assert (sign, offset, over) == (ref.sign, ref.offset, ref.overshoot)
    assert n_fire > 1000
