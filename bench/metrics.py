"""Metrics of one closed-loop run (SPEC §3), from the plant's exact integrals and the samples."""

from __future__ import annotations

import math

import numpy as np

from plant.multimode import Accumulator

__all__ = ["run_metrics", "METRIC_COLUMNS"]

METRIC_COLUMNS = (
    "peak_error_rad", "rms_error_rad", "p99_error_rad", "mean_abs_current", "rms_current",
    "supply_charge_rate", "scored_s", "n_events", "n_stick_slip", "n_substeps",
)


def run_metrics(acc: Accumulator, x1_window: np.ndarray) -> dict[str, float]:
    """Metrics over the scoring window.

    Parameters
    ----------
    acc : Accumulator
        Exact integrals of the window: peak |x1| on the continuous trajectory, ∫|x3|, ∫x3²,
        supply charge, duration.
    x1_window : ndarray
        x1 [rad] at the sample instants inside the window (RMS and 99th percentile).
    """
    T = acc.duration
    x = np.abs(np.asarray(x1_window, dtype=float))
    nan = math.nan
    return {
        "peak_error_rad": max(acc.peak_abs_error, float(x.max(initial=0.0))),
        "rms_error_rad": float(np.sqrt(np.mean(x**2))) if x.size else nan,
        "p99_error_rad": float(np.percentile(x, 99)) if x.size else nan,
        "mean_abs_current": acc.int_abs_current / T if T > 0 else nan,
        "rms_current": math.sqrt(acc.int_sq_current / T) if T > 0 else nan,
        "supply_charge_rate": acc.supply_charge / T if T > 0 else nan,
        "scored_s": T,
        "n_events": acc.n_events,
        "n_stick_slip": acc.n_breakaways,
        "n_substeps": acc.n_substeps,
    }
