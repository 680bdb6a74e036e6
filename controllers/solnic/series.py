"""Solnic's report hooks: the series of figures 7-2 to 7-5 that its cycle log gives, and the
labelled instants of its corrections (protocol v2, :mod:`controllers.base`).

From the controller's cycle ``log`` (one entry per evaluated cycle), held on the sample grid
from the cycle's time on:

* ``dc_large_rad`` — Δc_p of the last large cycle [rad] (held from its launch t_a);
* ``dc_rel_mismatch`` — |Δc_e − Δc_p|/Δc_p of the last evaluated cycle [–] (held from its
  evaluation t_b).

Event instants: ``pulse`` (every launch), and ``phase:<size>`` with size ``startup`` (sizes −1
and 0 of section 7.2), ``small``, ``medium`` or ``large`` ((6-6)–(6-8)); the runner's report
computes the peak error per size from the phases (:func:`bench.series.phase_peaks`).
"""

from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from controllers.solnic.strategy import LARGE, MEDIUM, SMALL

__all__ = ["held", "log_series", "cycle_event_times", "SIZE_NAMES"]

SIZE_NAMES = {SMALL: "small", MEDIUM: "medium", LARGE: "large"}


def held(t: np.ndarray, times: list[float], values: list[float]) -> np.ndarray:
    """Zero-order hold of (times, values) on the grid ``t`` (NaN before the first time)."""
    out = np.full(np.shape(t), np.nan)
    if not times:
        return out
    order = np.argsort(times, kind="stable")
    ts, vs = np.asarray(times, dtype=float)[order], np.asarray(values, dtype=float)[order]
    idx = np.searchsorted(ts, t, side="right") - 1
    ok = idx >= 0
    out[ok] = vs[idx[ok]]
    return out


def log_series(log: list[dict[str, Any]], t: np.ndarray) -> dict[str, np.ndarray]:
    """``dc_large_rad`` and ``dc_rel_mismatch`` on the sample instants ``t`` [s]."""
    large = [e for e in log if e.get("size") == LARGE]
    evaluated = [e for e in log if e.get("dc_p", 0.0) != 0]
    return {
        "dc_large_rad": held(t, [e["t_a"] for e in large], [e["dc_p"] for e in large]),
        "dc_rel_mismatch": held(t, [e["t_b"] for e in evaluated],
                                [abs(e["dc_e"] - e["dc_p"]) / abs(e["dc_p"]) for e in evaluated]),
    }


def cycle_event_times(cycles: Iterable[tuple[float, int]]) -> dict[str, np.ndarray]:
    """``pulse`` and ``phase:<size>`` instants [s] from (launch time, size) of every cycle."""
    cycles = list(cycles)
    out = {"pulse": np.array([t for t, _ in cycles], dtype=float)}
    for name in ("startup", *SIZE_NAMES.values()):
        out[f"phase:{name}"] = np.array(
            [t for t, s in cycles if SIZE_NAMES.get(s, "startup") == name], dtype=float)
    return out
