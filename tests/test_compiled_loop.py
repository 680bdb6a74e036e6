"""The compiled closed loop of a linear law (the multimode family's fast path) against the Python loop.

The Python loop — ``step`` then ``advance`` at every sample — is the reference; the compiled
path must give bit-identical metrics for the linear and dithered controllers, with and without
noise, on several plants and seeds, also when the noise buffer runs out inside an interval.
"""

from __future__ import annotations

import math

import pytest

from plant import law_driver
from plant.multimode import law_loop as compiled_loop
from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from controllers.linear import LinearController

RUNTIME = ("runtime_s", "realtime_factor")


def _both(name, scenario, seed, noise=True, duration=12.0, **options):
    params = builtin_scenarios()[scenario].params
    runs = [run_closed_loop(params, make_controller(name, **options), duration_s=duration, warmup_s=3.0, seed=seed,
                            noise=noise, compiled=compiled) for compiled in (False, True)]
    return [({k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.status, r.summary) for r in runs]


@pytest.mark.parametrize("name, scenario, seed, noise, options", [
    ("linear", "thesis", 0, True, {}),
    ("linear", "ratio-2", 5, True, {"crossover": 20.0, "lag_ratio": 2.0}),
    ("linear", "thesis", 1, False, {}),
    ("dithered", "thesis", 2, True, {}),
    ("dithered", "quiet-friction", 3, True, {"dither_frequency": 125.0, "dither_amplitude": 8.0}),
    ("dithered", "thesis", 4, False, {"dither_amplitude": 0.0}),
])
def test_compiled_law_is_bit_identical_to_the_python_loop(name, scenario, seed, noise, options):
    from plant.multimode.interval import interval_kernel
    python, compiled = _both(name, scenario, seed, noise, **options)
    # the compiled loop adds no specialization: it, advance and pulse_motion's noise-free intervals
    # (plant/multimode/pulse.py) all pass a writable state vector and typed (not literal) ints and
    # bools, one signature (docs/plant.md, "One compiled signature per kernel")
    assert [sig[0].mutable for sig in interval_kernel.signatures] == [True]
    assert python[1] == compiled[1] == "ok"
    assert python[0] == compiled[0]          # every metric, exactly
    assert python[2] == compiled[2]


def test_noise_buffer_refills_and_overruns_inside_an_interval_change_nothing(monkeypatch):
    """A tiny margin makes the compiled loop return for noise before most intervals and lets
    dithered intervals run out of normals inside the kernel (NoiseExhausted, redone)."""
    params = builtin_scenarios()["thesis"].params
    python = run_closed_loop(params, make_controller("dithered"), duration_s=3.0, warmup_s=1.0, seed=7,
                             compiled=False)
    monkeypatch.setattr(law_driver, "NOISE_MARGIN", 64)
    grown = []
    original = compiled_loop.NoiseStream.grow
    monkeypatch.setattr(compiled_loop.NoiseStream, "grow", lambda self, pos: grown.append(pos) or original(self, pos))
    compiled = run_closed_loop(params, make_controller("dithered"), duration_s=3.0, warmup_s=1.0, seed=7)
    assert len(grown) > 10
    assert python.status == compiled.status == "ok"
    assert {k: v for k, v in python.metrics.items() if k not in RUNTIME} == \
           {k: v for k, v in compiled.metrics.items() if k not in RUNTIME}


def test_a_subclass_that_overrides_step_is_not_compiled():
    class Offset(LinearController):       # not registered: the registry stays as shipped
        def step(self, y):
            return super().step(y + 1e-6)

    c = Offset()
    c.reset(builtin_scenarios()["thesis"].params, None)
    assert c.linear_law() is None
    assert make_controller("linear").linear_law() is None           # before reset: no design yet


def test_time_limit_stops_the_compiled_loop():
    params = builtin_scenarios()["thesis"].params
    r = run_closed_loop(params, make_controller("linear"), duration_s=50.0, seed=0, time_limit_s=1e-9)
    assert r.status == "error" and r.message.startswith("time limit of 1e-09 s exceeded at t = ")
    assert 1.0 <= r.simulated_s <= 20.0       # within the first chunks of 1000 samples (10 s)
    assert math.isnan(r.metrics["peak_error_rad"])


def test_compiled_dither_segments_are_the_square_wave():
    """plant.linear_drive.square_wave_segments (what both the compiled loop and the dithered
    controller run) against the wave's definition, sq(θ) = sign(sin 2πθ), on random intervals,
    levels, amplitudes (some clipping), frequencies and phases."""
    import numpy as np

    from plant.linear_drive import square_wave_segments
    rng = np.random.default_rng(3)
    offs, levs = np.empty(64), np.empty(64)
    for _ in range(3000):
        t0 = int(rng.integers(0, 100000)) * 0.01
        base, amp = rng.uniform(-30, 30), float(rng.choice([0.0, 2.0, 18.0, 40.0, rng.uniform(0, 30)]))
        freq, phase = float(rng.choice([25.0, 125.0, 250.0, 500.0, rng.uniform(1, 1000)])), rng.random()
        k = square_wave_segments(t0, 0.01, base, amp, freq, phase, 26.0, offs, levs)
        o, lv = offs[:k], levs[:k]
        assert o[0] == 0.0 and np.all(np.diff(o) > 0) and o[-1] < 0.01 and np.all(np.diff(lv) != 0)
        for off in rng.uniform(0.0, 0.01, 20):
            s = math.sin(2 * math.pi * (freq * (t0 + off) + phase))
            if abs(s) < 1e-6 or np.min(np.abs(o[1:] - off), initial=1.0) < 1e-9:
                continue
            want = min(max(base + (amp if s > 0 else -amp if amp else 0.0), -26.0), 26.0)
            assert lv[np.searchsorted(o, off, side="right") - 1] == want
