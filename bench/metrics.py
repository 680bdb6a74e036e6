"""Metrics of one closed-loop run (SPEC §3), from the plant's exact interval integrals and the samples."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plant.state import IntervalResult

__all__ = ["WindowTotals", "run_metrics", "METRIC_COLUMNS", "unphysical"]

METRIC_COLUMNS = (
    "peak_error_rad", "rms_error_rad", "p99_error_rad", "mean_abs_current", "rms_current",
    "supply_charge_rate", "scored_s", "n_events", "n_stick_slip", "n_substeps",
)


@dataclass
class WindowTotals:
    """Running sums over the scoring window of the exact per-interval quantities."""

    duration: float = 0.0
    peak_abs_error: float = 0.0
    int_abs_current: float = 0.0
    int_sq_current: float = 0.0
    supply_charge: float = 0.0
    n_events: int = 0
    n_breakaways: int = 0
    n_substeps: int = 0

    def add(self, step: IntervalResult) -> None:
        """Add one interval of the window."""
        self.duration += step.duration
        if step.peak_abs_error > self.peak_abs_error:
            self.peak_abs_error = step.peak_abs_error
        self.int_abs_current += step.int_abs_current
        self.int_sq_current += step.int_sq_current
        self.supply_charge += step.supply_charge
        self.n_events += step.n_events
        self.n_breakaways += step.n_breakaways
        self.n_substeps += step.n_substeps


def run_metrics(totals: WindowTotals, x1_window: np.ndarray) -> dict[str, float]:
    """Metrics over the scoring window.

    Parameters
    ----------
    totals : WindowTotals
        Exact integrals of the window: peak |x1| on the continuous trajectory, ∫|x3|, ∫x3²,
        supply charge, duration, counts.
    x1_window : ndarray
        x1 [rad] at the sample instants inside the window (RMS and 99th percentile).

    A window without any integrated time (a run that failed before it) gives NaN for every
    error and current metric, never 0.
    """
    T = totals.duration
    x = np.abs(np.asarray(x1_window, dtype=float))
    nan = math.nan
    scored = T > 0
    return {
        "peak_error_rad": max(totals.peak_abs_error, float(x.max(initial=0.0))) if scored else nan,
        "rms_error_rad": float(np.sqrt(np.mean(x**2))) if x.size and scored else nan,
        "p99_error_rad": float(np.percentile(x, 99)) if x.size and scored else nan,
        "mean_abs_current": totals.int_abs_current / T if scored else nan,
        "rms_current": math.sqrt(totals.int_sq_current / T) if scored else nan,
        "supply_charge_rate": totals.supply_charge / T if scored else nan,
        "scored_s": T,
        "n_events": totals.n_events,
        "n_stick_slip": totals.n_breakaways,
        "n_substeps": totals.n_substeps,
    }


def unphysical(x: np.ndarray, metrics: dict[str, float], u_max: float) -> str | None:
    """Why a run that ended ``ok`` is not a result (None if it is): its final state ``x`` or a
    metric is not finite, or a current metric exceeds what the drive can give.

    The motor torque follows the drive through a first-order lag (3-2) and |u| <= u_max, so
    |x3| <= u_max at all times and mean |i| <= RMS i <= u_max [ozf·in]; a larger value is a
    numerical failure (a float that lost every digit), not a measurement. The runner turns a
    reason into status ``diverged``.
    """
    state = np.asarray(x, dtype=float)
    if not np.all(np.isfinite(state)):
        return f"diverged: the plant state left the finite range (x = {np.array2string(state, precision=3)})"
    for key, value in metrics.items():
        if isinstance(value, float) and not math.isfinite(value):
            return f"diverged: metric {key} = {value!r} is not finite"
    limit = u_max * (1.0 + 1e-9)
    for key in ("mean_abs_current", "rms_current"):
        value = metrics.get(key, 0.0)
        if value > limit:
            return f"diverged: {key} = {value!r} ozf·in exceeds u_max = {u_max!r} ozf·in"
    return None
