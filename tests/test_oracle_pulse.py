"""The oracle-pulse bound: peak error equals its band on a friction-noise-free plant, and it sits
below the real pulse controller (solnic) on quiet-friction."""

from __future__ import annotations

import numpy as np
import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers.base import get_controller, make_controller
from plant.params import PlantParams

QUIET = builtin_scenarios()["quiet-friction"].params


def _run(name, params=QUIET, duration=20.0, warmup=5.0, seed=0, **options):
    return run_closed_loop(params, make_controller(name, **options), duration_s=duration,
                           warmup_s=warmup, seed=seed)


@pytest.mark.parametrize("band", [0.5e-6, 3e-6])
def test_noise_free_friction_peak_is_the_band_and_pulse_rate_is_the_drift_over_twice_the_band(band):
    # σ2 = 0 and the true pulse law: every pulse lands exactly at +b, so the error sweeps
    # [−b, +b] at the drift rate |x4| ≈ 30 µrad/s and pulses come every 2b/|x4| seconds. While
    # the shaft decelerates (ẋ1 = x2 − x4 < 0 before it sticks) x1 can top the landing point by
    # at most the drift over one pulse's motion, x4·t_stop with t_stop < 5 ms (plant.multimode.pulse).
    r = _run("oracle-pulse", band=band, duration=15.0, warmup=5.0)
    assert r.status == "ok", r.message
    x4 = PlantParams().command_velocity_initial
    assert band <= r.metrics["peak_error_rad"] <= band + 1.1 * x4 * 5e-3
    expected = 15.0 * x4 / (2 * band)
    assert r.summary["pulses"] == pytest.approx(expected, rel=0.1)


def test_the_bound_is_privileged_and_refuses_to_run_blind():
    cls = get_controller("oracle-pulse")
    assert cls.privileged and cls.family == "bound" and "band" in cls.knobs
    c = make_controller("oracle-pulse")
    c.reset(QUIET, np.random.default_rng(0))
    with pytest.raises(RuntimeError, match="observe_truth"):
        c.step(0.0)
    with pytest.raises(ValueError, match="band"):
        make_controller("oracle-pulse", band=-1.0)


def test_oracle_beats_solnic_on_quiet_friction_at_no_more_current():
    # For each seed some band of the bound reaches a lower peak than solnic with no more mean
    # current (a point of the oracle's frontier dominates solnic's point).
    for seed in (0, 1):
        sol = _run("solnic", seed=seed, duration=20.0)
        peak, current = sol.metrics["peak_error_rad"], sol.metrics["mean_abs_current"]
        points = [_run("oracle-pulse", seed=seed, band=b).metrics for b in (1e-6, 3e-6, 10e-6, 30e-6)]
        assert any(p["peak_error_rad"] < peak and p["mean_abs_current"] <= current for p in points), \
            (peak, current, [(p["peak_error_rad"], p["mean_abs_current"]) for p in points])
