"""Hunting (stick-slip limit cycle) detection: synthetic traces, then the closed loop (2-1)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.hunting import detect_hunting, merged_trace, slip_episodes

DT = 1e-3
AMPLITUDE = 1e-3  # rad


def _trace(slip_times: np.ndarray, directions: np.ndarray, *, t_end: float = 40.0,
           slip_s: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Synthetic stick-slip: stuck at x1 = ∓A, each slip moves the shaft to ±A in ``slip_s``."""
    t = np.arange(0.0, t_end, DT)
    mode = np.full(t.size, 2)
    x1 = np.zeros(t.size)
    velocity = np.zeros(t.size)
    level = 0.0
    for ts, d in zip(slip_times, directions):
        on = (t >= ts) & (t < ts + slip_s)
        mode[on] = 3 if d > 0 else 1
        velocity[on] = d * 2 * AMPLITUDE / slip_s
        x1[on] = level + (t[on] - ts) * velocity[on]
        level = d * AMPLITUDE
        x1[t >= ts + slip_s] = level
    return t, x1, mode, velocity


def _alternating(times: np.ndarray) -> np.ndarray:
    return np.where(np.arange(times.size) % 2 == 0, 1, -1)


def test_periodic_reversing_slips_are_hunting() -> None:
    times = np.arange(1.0, 40.0, 2.0)
    t, x1, mode, _ = _trace(times, _alternating(times))
    v = detect_hunting(t, x1, mode, require_reversals=True)
    assert v.sustained, v.reason
    assert v.period_s == pytest.approx(2.0, abs=2 * DT)
    assert v.period_spread == pytest.approx(0.0, abs=1e-3)
    assert v.reversal_fraction == 1.0
    assert v.amplitude_rad == pytest.approx(AMPLITUDE, rel=1e-6)
    assert v.n_slips == 10  # slip starts at 21, 23, …, 39 s in the tail [20, 40)


def test_jittered_period_still_hunting() -> None:
    rng = np.random.default_rng(1)
    times = np.cumsum(rng.uniform(1.8, 2.2, 19))
    t, x1, mode, _ = _trace(times, _alternating(times))
    v = detect_hunting(t, x1, mode)
    assert v.sustained, v.reason
    assert v.period_spread < 0.2


def test_slips_that_stop_are_settled() -> None:
    times = np.arange(1.0, 12.0, 2.0)  # a transient: slips until 11 s, then stuck to 40 s
    t, x1, mode, _ = _trace(times, _alternating(times))
    v = detect_hunting(t, x1, mode)
    assert not v.sustained
    assert v.last_motion_s == pytest.approx(11.05, abs=2 * DT)
    # even with the whole run as the window: the last 29 s are quiet, far beyond 2 periods
    v = detect_hunting(t, x1, mode, tail_fraction=1.0)
    assert not v.sustained and "settled" in v.reason


def test_never_moving_is_settled() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    v = detect_hunting(t, -30e-6 * t, np.full(t.size, 2))
    assert not v.sustained and v.n_slips == 0 and np.isnan(v.last_motion_s)


def test_irregular_slips_are_not_periodic() -> None:
    rng = np.random.default_rng(2)
    times = np.cumsum(rng.exponential(1.0, 200))
    times = times[times < 199.0]
    t, x1, mode, _ = _trace(times, _alternating(times), t_end=200.0, slip_s=0.01)
    v = detect_hunting(t, x1, mode)
    assert not v.sustained and "periodic" in v.reason
    assert v.period_spread > 1.0


def test_one_way_stick_slip_needs_no_reversals_unless_asked() -> None:
    times = np.arange(0.5, 40.0, 1.0)
    t, x1, mode, _ = _trace(times, np.ones(times.size, dtype=int))
    assert detect_hunting(t, x1, mode).sustained
    v = detect_hunting(t, x1, mode, require_reversals=True)
    assert not v.sustained and v.reversal_fraction == 0.0


def test_velocity_input_agrees_with_mode_input() -> None:
    times = np.arange(1.0, 40.0, 2.0)
    t, x1, mode, velocity = _trace(times, _alternating(times))
    a = detect_hunting(t, x1, mode)
    b = detect_hunting(t, x1, velocity=velocity, velocity_tol=1e-9)
    assert a == b


def test_slip_episodes_on_an_event_trace() -> None:
    t = np.array([0.0, 1.0, 1.001, 1.02, 2.0, 3.0, 3.004, 3.03])
    mode = np.array([2, 2, 3, 2, 2, 2, 1, 2])
    assert slip_episodes(t, np.where(mode == 3, 1, np.where(mode == 1, -1, 0))) == [
        (1.001, 1.001, 1), (3.004, 3.004, -1)]


def test_short_sticks_inside_a_slip_merge() -> None:
    t = np.array([0.0, 1.0, 1.01, 1.02, 1.03, 1.2, 2.0, 2.01, 2.3])
    d = np.array([0, 1, 0, 1, 1, 0, -1, 1, 0])
    # a direct reversal (−1 → +1 without a stick) stays one episode, named by its first point
    assert slip_episodes(t, d, min_stick_s=0.05) == [(1.0, 1.03, 1), (2.0, 2.01, -1)]
    assert slip_episodes(t, d) == [(1.0, 1.0, 1), (1.02, 1.03, 1), (2.0, 2.01, -1)]


def test_merged_trace_orders_samples_and_events() -> None:
    samples = {"t": np.array([0.0, 0.01, 0.02]), "x1": np.array([0.0, 1.0, 2.0]),
               "mode": np.array([2.0, 2.0, 3.0])}
    events = {"t": np.array([0.015]), "x1": np.array([1.5]), "mode": np.array([3.0])}
    t, x1, mode = merged_trace(samples, events)
    np.testing.assert_array_equal(t, [0.0, 0.01, 0.015, 0.02])
    np.testing.assert_array_equal(x1, [0.0, 1.0, 1.5, 2.0])
    assert mode.dtype.kind == "i" and list(mode) == [2, 2, 3, 3]


@pytest.mark.parametrize("kwargs, match", [
    ({"x1": np.zeros(3)}, "x1 must have the shape"),
    ({"mode": np.array([2, 2, 5, 2])}, "mode values"),
    ({"mode": None}, "exactly one of mode and velocity"),
    ({"velocity": np.zeros(4)}, "exactly one of mode and velocity"),
    ({"t": np.array([0.0, 2.0, 1.0, 3.0])}, "nondecreasing"),
    ({"tail_fraction": 0.0}, "tail_fraction"),
    ({"min_cycles": 2}, "min_cycles"),
    ({"max_period_spread": 0.0}, "max_period_spread"),
    ({"min_stick_s": -1.0}, "min_stick_s"),
    ({"max_quiet_periods": -1.0}, "max_quiet_periods"),
])
def test_errors(kwargs: dict, match: str) -> None:
    args = {"t": np.arange(4.0), "x1": np.zeros(4), "mode": np.full(4, 2)}
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        detect_hunting(args.pop("t"), args.pop("x1"), args.pop("mode"), **args)


# --- closed loop: a stationary set-point after a command transient ---------------------------

def _hunting_run(lag_ratio: float, seed: int):
    from bench.runner import run_closed_loop
    from controllers.linear import LinearController
    from plant.params import PlantParams

    # From the runner's initial state (x1 = 0, stuck, no current) a constant set-point never
    # moves the shaft. x4(0) = 10 mrad/s decaying with τ4 = 1 s steps r by 10 mrad within a
    # few seconds, so the shaft slips during the transient; the set-point is then stationary
    # (x4 < 1e-14 rad/s after 30 s). Hunting is conditional: a slip that happens to stop
    # within ks/(K·L) of zero error ends it, so the seeds are fixed.
    p = PlantParams(command_velocity_initial=1e-2, command_velocity_tau=1.0,
                    command_velocity_std=0.0)
    res = run_closed_loop(p, LinearController(lag_ratio=lag_ratio), duration_s=40.0, seed=seed,
                          noise=True, record=True)
    assert res.status == "ok", res.message
    return p, detect_hunting(*merged_trace(res.samples, res.events), require_reversals=True)


def test_lag_far_above_lmax_hunts() -> None:
    """L = 8·Lmax (Lmax = 6 for Table 2-1, (2-1)) hunts on nearly every seed. Hunting is
    conditional (a slip that stops within ks/(K·L) of zero error ends it), so one seed proves
    little either way: over seeds 0-9 at least 8 must sustain stick-slip reversals (measured on
    numpy 2.4 / python-control 0.10.2: 9 of 10, seed 1 settles after 7 slips)."""
    verdicts = [_hunting_run(8.0 * 6.0, seed)[1] for seed in range(10)]
    hunting = [v for v in verdicts if v.sustained]
    print("L = 48:", [v.reason for v in verdicts])
    assert len(hunting) >= 8, [v.reason for v in verdicts]
    assert all(v.reversal_fraction >= 0.9 for v in hunting)


@pytest.mark.parametrize("seed", [0, 1])
def test_lag_far_below_lmax_settles(seed: int) -> None:
    p, v = _hunting_run(2.0, seed)  # L = Lmax/3
    print(f"L = 2, seed {seed}: {v}")
    assert not v.sustained, v.reason
    assert 0 < v.last_motion_s < 10.0  # it did slip during the transient, then settled
