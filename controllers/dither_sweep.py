"""Sweep of the square-wave dither (A_d, f_d) on the closed loop (SPEC §4 "Dithered linear").

Each cell runs :class:`~controllers.dithered.DitheredController` on a ramp with
:func:`bench.runner.run_closed_loop` and reports peak error and motor-current cost.
:func:`best_dither` picks the defaults: the lowest mean peak error among frequencies above
the bandwidth limit (section 2.2: slower dither cannot beat (2-6)).

Recorded sweep (the defaults of ``dithered``): Table 2-1, 100 s runs scored after 20 s,
noise on, seeds 0–2, linear design ωc = 48.7 rad/s (7.75 Hz), L = 6::

    df = dither_sweep(workers=2)        # the defaults below; 135 runs, about 3 min on 2 cores
    best_dither(df)                     # → (18.0, 250.0)

Mean peak error [µrad] (A_d = 0: 1233 µrad, mean |x3| 0.82, rms x3 0.95 ozf·in):

    f_d [Hz] | A_d:  2      4      6      8      12     14     16     18
    5 (< ωc)       2766   7649  12649  17651  26561  30123  35240  40185
    25             297    739    987   1204   1550   1709   2193   3198
    125            911    576    268    138    178    188    228    244
    250            1070   908    745    570    249    158    104    62
    500            1209   1070   987    902    740    659    567    482

Mean |x3| [ozf·in] at 125 Hz: 0.89 0.86 0.81 0.99 1.49 1.73 1.98 2.23; at 250 Hz:
0.79 0.87 0.96 0.86 0.81 0.89 1.00 1.12 (same A_d columns). Dither slower than ωc only adds
error; above it the error falls once the motor-filtered ripple, A_d·tanh(1/(4·f_d·τ3)),
approaches k̄s. Best above both ωc and the 50 Hz Nyquist rate: A_d = 18 ozf·in at 250 Hz,
62 µrad (seeds: 58, 98, 30), mean |x3| 1.12, rms x3 1.30 ozf·in. A_d stops at 18 = 0.9·u_max
so that the linear command keeps about k̄s of headroom before clipping.
"""

from __future__ import annotations

import itertools
import math
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Iterable

import pandas as pd

from bench.runner import run_closed_loop
from controllers.dithered import DitheredController
from controllers.linear import design_linear
from plant.params import PlantParams

__all__ = ["dither_sweep", "best_dither"]

_AMPLITUDES = (0.0, 2.0, 4.0, 6.0, 8.0, 12.0, 14.0, 16.0, 18.0)  # ozf·in
_FREQUENCIES_HZ = (5.0, 25.0, 125.0, 250.0, 500.0)
_COLUMNS = ("peak_error_rad", "rms_error_rad", "mean_abs_current", "rms_current",
            "supply_charge_rate", "n_stick_slip", "runtime_s")


def _cell(args: tuple) -> dict[str, Any]:
    params, amplitude, frequency, seed, duration_s, warmup_s, noise, options = args
    ctrl = DitheredController(dither_amplitude=amplitude, dither_frequency=frequency, **options)
    res = run_closed_loop(params, ctrl, duration_s=duration_s, warmup_s=warmup_s, seed=seed,
                          noise=noise)
    row = {"amplitude": amplitude, "frequency_hz": frequency, "seed": seed, "status": res.status}
    row.update({k: res.metrics.get(k, math.nan) for k in _COLUMNS})
    return row


def dither_sweep(params: PlantParams | None = None,
                 amplitudes: Iterable[float] = _AMPLITUDES,
                 frequencies_hz: Iterable[float] = _FREQUENCIES_HZ, *,
                 seeds: Iterable[int] = (0, 1, 2), duration_s: float = 100.0, warmup_s: float = 20.0,
                 noise: bool = True, workers: int = 1, **linear_options: Any) -> pd.DataFrame:
    """Peak error and current of the dithered loop over a grid of A_d [ozf·in] and f_d [Hz].

    Parameters
    ----------
    params : PlantParams, optional
        The plant; default Table 2-1 (ramp of ``command_velocity_initial``).
    amplitudes, frequencies_hz : iterable of float
        Grid of A_d ≥ 0 and f_d > 0.
    seeds : iterable of int
        Seeds of each cell.
    duration_s, warmup_s : float
        Run length and unscored warm-up [s].
    workers : int
        Processes; 1 runs in this process.
    **linear_options
        Options of the linear design (e.g. ``crossover``).

    Returns
    -------
    pandas.DataFrame
        One row per (amplitude, frequency_hz, seed): status, peak/rms error [rad],
        mean |x3|, rms x3, supply charge rate [ozf·in], stick-slip count, runtime, plus
        ``crossover_hz`` of the design and flags ``above_crossover`` (2π·f_d > ωc) and
        ``above_nyquist`` (f_d > 1/(2τs)).
    """
    params = PlantParams() if params is None else params
    amplitudes, frequencies_hz, seeds = list(amplitudes), list(frequencies_hz), list(seeds)
    if any(not (math.isfinite(a) and 0 <= a < params.u_max) for a in amplitudes):
        raise ValueError(f"amplitudes must be in [0, u_max = {params.u_max}), got {amplitudes}")
    if any(not (math.isfinite(f) and f > 0) for f in frequencies_hz):
        raise ValueError(f"frequencies_hz must be finite and > 0, got {frequencies_hz}")
    if not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    design = design_linear(params, linear_options.get("crossover"),
                           linear_options.get("lag_ratio"),
                           **{k: v for k, v in linear_options.items()
                              if k in ("integral", "phase_margin_deg", "lag_corner_fraction")})
    jobs = [(params, float(a), float(f), int(s), duration_s, warmup_s, noise, linear_options)
            for f, a, s in itertools.product(frequencies_hz, amplitudes, seeds)]
    if workers == 1:
        rows = [_cell(j) for j in jobs]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            rows = list(pool.map(_cell, jobs))
    df = pd.DataFrame(rows)
    omega_c = design.crossover_rad_s
    df["crossover_hz"] = omega_c / (2 * math.pi)
    df["above_crossover"] = 2 * math.pi * df["frequency_hz"] > omega_c
    df["above_nyquist"] = df["frequency_hz"] > 0.5 / params.sample_period
    return df


def best_dither(df: pd.DataFrame, *, above: str = "above_nyquist") -> tuple[float, float]:
    """(A_d, f_d) with the lowest seed-mean peak error among ``ok`` cells flagged ``above``.

    ``above`` is ``"above_crossover"`` (ωb = ωc) or ``"above_nyquist"`` (ωb = π/τs, the
    thesis's bandwidth limit); cells with A_d = 0 are excluded.
    """
    if above not in ("above_crossover", "above_nyquist"):
        raise ValueError(f"above must be 'above_crossover' or 'above_nyquist', got {above!r}")
    ok = df[(df["status"] == "ok") & df[above] & (df["amplitude"] > 0)]
    if ok.empty:
        raise ValueError("no ok cell with dither above the bandwidth limit in the sweep")
    mean_peak = ok.groupby(["amplitude", "frequency_hz"])["peak_error_rad"].mean()
    amplitude, frequency = mean_peak.idxmin()
    return float(amplitude), float(frequency)
