"""Square-wave dither: segment construction, controller, and its closed-loop cost and benefit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers.base import get_controller
from controllers.dithered import DitheredController, square_wave_segments
from controllers.linear import LinearController
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

TAU_S = 0.01


def _level_at(segments: tuple, offset: float) -> float:
    offsets = [o for o, _ in segments]
    return segments[int(np.searchsorted(offsets, offset, side="right")) - 1][1]


@pytest.mark.parametrize("frequency, phase", [(250.0, 0.37), (125.0, 0.0), (37.0, 0.9), (5.0, 0.5)])
def test_segments_follow_the_square_wave(frequency: float, phase: float) -> None:
    base, amplitude, limit = 0.3, 2.0, 20.0
    rng = np.random.default_rng(0)
    for n in (0, 1, 7, 9_999):
        t0 = n * TAU_S
        segs = square_wave_segments(t0, TAU_S, base, amplitude, frequency, phase, limit)
        DriveCommand(segs, DriveType.LINEAR)  # a valid command
        # sq(θ) = +1 where sin(2πθ) > 0: an independent statement of the same wave
        for off in rng.uniform(0.0, TAU_S, 200):
            s = math.sin(2 * math.pi * (frequency * (t0 + off) + phase))
            if abs(s) < 1e-6:
                continue
            assert _level_at(segs, off) == base + amplitude * math.copysign(1.0, s)


def test_dither_above_nyquist_switches_inside_the_interval() -> None:
    segs = square_wave_segments(0.123, TAU_S, 0.0, 1.0, 250.0, 0.37, 20.0)
    assert len(segs) - 1 in (4, 5)  # 10 ms / 2 ms half-period
    widths = np.diff([o for o, _ in segs][1:])  # between interior switches
    np.testing.assert_allclose(widths, 2e-3, rtol=1e-9)
    assert [lv for _, lv in segs] == [(-1.0) ** k for k in range(len(segs))]


def test_full_cycles_average_to_the_base_level() -> None:
    base = -0.7
    total = 0.0
    for n in range(4):  # 40 ms = 2 periods of 50 Hz
        segs = square_wave_segments(n * TAU_S, TAU_S, base, 3.0, 50.0, 0.21, 20.0)
        bounds = [o for o, _ in segs] + [TAU_S]
        total += sum(level * (b - a) for (a, b), (_, level) in zip(zip(bounds, bounds[1:]), segs))
    assert total / (4 * TAU_S) == pytest.approx(base, abs=1e-12)


def test_clipping_and_zero_amplitude() -> None:
    segs = square_wave_segments(0.0, TAU_S, 18.0, 4.0, 100.0, 0.0, 20.0)
    assert {level for _, level in segs} == {20.0, 14.0}
    assert square_wave_segments(0.0, TAU_S, 25.0, 0.0, 100.0, 0.0, 20.0) == ((0.0, 20.0),)


def test_zero_amplitude_is_the_linear_controller() -> None:
    p = PlantParams()
    lin, dit = LinearController(), DitheredController(dither_amplitude=0.0)
    lin.reset(p, np.random.default_rng(0))
    dit.reset(p, np.random.default_rng(0))
    for y in 1e-5 * np.sin(np.arange(200) * 0.1):
        assert dit.step(y) == lin.step(y)


def test_phase_comes_from_the_controller_rng() -> None:
    p = PlantParams()

    def commands(seed: int, **kw) -> list:
        c = DitheredController(dither_amplitude=2.0, dither_frequency=37.0, **kw)
        c.reset(p, np.random.default_rng(seed))
        return [c.step(1e-6 * k).segments for k in range(20)]

    assert commands(1) == commands(1)
    assert commands(1) != commands(2)
    first = commands(1, random_phase=False)[0]
    assert first[0] == (0.0, pytest.approx(2.0 - 0.0))  # φ = 0: the wave starts high


@pytest.mark.parametrize("kwargs, match", [
    ({"dither_amplitude": -1.0}, "dither_amplitude"),
    ({"dither_amplitude": math.nan}, "dither_amplitude"),
    ({"dither_frequency": 0.0}, "dither_frequency"),
    ({"dither_frequency": math.inf}, "dither_frequency"),
    ({"random_phase": 1}, "random_phase"),
    ({"lag_ratio": 0.1}, "lag_ratio"),
])
def test_option_errors(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        DitheredController(**kwargs)


def test_amplitude_must_be_below_u_max() -> None:
    c = DitheredController(dither_amplitude=25.0)
    with pytest.raises(ValueError, match="dither_amplitude"):
        c.reset(PlantParams(), np.random.default_rng(0))
    assert get_controller("dithered") is DitheredController


# --- closed loop ------------------------------------------------------------------------------

def _ripple_stats(amplitude: float, frequency: float, tau3: float) -> tuple[float, float]:
    """Mean |x3| and rms x3 of the steady first-order response to a ±A square wave (closed form).

    Over a rising half-period h: x3(s) = A − (A + P)·e^{−s/τ3}, with P = A·tanh(h/(2τ3)).
    """
    h = 0.5 / frequency
    peak = amplitude * math.tanh(h / (2 * tau3))
    s = np.linspace(0.0, h, 200_001)
    x = amplitude - (amplitude + peak) * np.exp(-s / tau3)
    return float(np.mean(np.abs(x))), float(np.sqrt(np.mean(x**2)))


@pytest.fixture(scope="module")
def dither_runs() -> dict[float, dict]:
    from bench.runner import run_closed_loop

    p = PlantParams()
    out = {}
    for amplitude in (0.0, 4.0, 12.0, 16.0):
        c = DitheredController(dither_amplitude=amplitude, dither_frequency=125.0)
        res = run_closed_loop(p, c, duration_s=4.0, warmup_s=2.0, seed=0, noise=False)
        assert res.status == "ok", res.message
        out[amplitude] = res.metrics
    return out


def test_current_rises_with_amplitude(dither_runs: dict) -> None:
    amps = sorted(dither_runs)
    mean_abs = [dither_runs[a]["mean_abs_current"] for a in amps]
    rms = [dither_runs[a]["rms_current"] for a in amps]
    assert all(np.diff(mean_abs) > 0) and all(np.diff(rms) > 0)
    tau3 = PlantParams().motor_time_constant
    for a in amps[1:]:
        # the dither ripple is a lower bound: mean|b + r| ≥ mean|r| for a symmetric ripple r
        mean_ripple, rms_ripple = _ripple_stats(a, 125.0, tau3)
        assert dither_runs[a]["mean_abs_current"] >= 0.98 * mean_ripple
        assert dither_runs[a]["rms_current"] >= 0.98 * rms_ripple


def test_peak_error_falls_once_dither_breaks_stiction(dither_runs: dict) -> None:
    p = PlantParams()
    tau3 = p.motor_time_constant
    h = 0.5 / 125.0
    for a, runs in dither_runs.items():
        ripple = a * math.tanh(h / (2 * tau3))  # peak torque ripple [ozf·in]
        if ripple < 0.5 * p.stiction:  # too weak to break stiction: the ramp just pulls away
            assert runs["n_stick_slip"] == 0
            assert runs["peak_error_rad"] == pytest.approx(30e-6 * 4.0, rel=0.01)
        elif ripple > p.stiction:
            assert runs["n_stick_slip"] > 100
            assert runs["peak_error_rad"] < dither_runs[0.0]["peak_error_rad"] / 4


# --- the sweep ----------------------------------------------------------------------------------

def test_sweep_table_and_best_choice() -> None:
    import pandas as pd

    from bench.tuning import best_setting, knob_sweep

    df = knob_sweep("dithered", {"dither_amplitude": (0.0, 12.0), "dither_frequency": (5.0, 125.0)},
                    seeds=(0,), duration_s=1.5, warmup_s=0.5, noise=False)
    assert len(df) == 4 and set(df["status"]) == {"ok"}
    for col in ("peak_error_rad", "mean_abs_current", "rms_current", "dither_amplitude",
                "dither_frequency", "seed"):
        assert col in df.columns
    # zero amplitude is the linear loop whatever the frequency
    zero = df[df["dither_amplitude"] == 0.0]["peak_error_rad"].to_numpy()
    assert zero[0] == zero[1]
    synthetic = pd.DataFrame({
        "dither_amplitude": [2.0, 4.0, 4.0, 8.0], "dither_frequency": [25.0, 125.0, 125.0, 250.0],
        "seed": [0, 0, 1, 0], "status": ["ok"] * 4, "peak_error_rad": [1e-6, 3e-5, 1e-5, 4e-5]})
    above = synthetic["dither_frequency"] > 50.0
    assert best_setting(synthetic, where=above) == {"dither_amplitude": 4.0,
                                                    "dither_frequency": 125.0}  # 2e-5 beats 4e-5
    assert best_setting(synthetic) == {"dither_amplitude": 2.0, "dither_frequency": 25.0}
    failed = synthetic.assign(status=["ok", "error", "ok", "ok"])   # one failed seed disqualifies
    assert best_setting(failed, where=above) == {"dither_amplitude": 8.0, "dither_frequency": 250.0}


@pytest.mark.parametrize("kwargs, match", [
    ({"grid": {"dither_amplitude": (-1.0,)}}, "dither_amplitude"),
    ({"grid": {"dither_frequency": (0.0,)}}, "dither_frequency"),
    ({"grid": {"dither_phase": (0.0,)}}, "dither_phase"),
    ({"grid": {"dither_amplitude": ()}}, "grid"),
    ({"workers": 0}, "workers"),
    ({"scenario": "moon"}, "scenario"),
])
def test_sweep_errors(kwargs: dict, match: str) -> None:
    from bench.tuning import knob_sweep

    with pytest.raises(ValueError, match=match):
        knob_sweep("dithered", **kwargs)


def test_best_setting_errors() -> None:
    import pandas as pd

    from bench.tuning import best_setting

    df = pd.DataFrame({"dither_amplitude": [0.0], "dither_frequency": [250.0], "seed": [0],
                       "status": ["error"], "peak_error_rad": [1e-5]})
    with pytest.raises(ValueError, match="every seed ok"):
        best_setting(df)
    with pytest.raises(ValueError, match="no eligible"):
        best_setting(df, where=df["dither_frequency"] > 1e3)
