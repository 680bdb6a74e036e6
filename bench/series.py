"""The solnic figure series (figures 7-2 to 7-5) and the peak error per correction size.

Layout: ``reports.inputs`` (``DIR/series/<cell>.parquet``), one row per sample instant:

* ``t`` [s], ``x1`` [rad] — from the run's samples;
* ``ks_hat_pct``, ``kc_hat_pct`` — k̂s, k̂c as % of the true effective ks, kc at that instant;
* ``x4_hat_pct`` — x̂4 as % of the true x4;
* ``cost_small``, ``cost_medium``, ``cost_large``, ``dc_ratio``, ``cycle_size`` — the
  controller's internals after the step at that instant (held between updates);
* ``ks_kc_corr`` — P_kc,ks/√(P_kc,kc·P_ks,ks) from the friction filter's covariance;
* ``n_cost_updates`` — the controller's count if its internals report one, else the number of
  changes of (costs, Δc ratio) so far (each cost computation recomputes all four);
* ``dt_opt_rel_error`` — |Δt_u,opt − optimum|/optimum, optimum from the summary's
  ``dtu_opt_adjusted``;
* ``dc_large_rad``, ``dc_rel_mismatch`` — from the controller's cycle ``log`` (Δc_p of the last
  large cycle; |Δc_e − Δc_p|/Δc_p of the last evaluated cycle), held from the cycle's time on.

Peak error per size: cycle *i* of the controller's ``log`` (size s_i, launched at t_a,i) owns
[t_a,i, t_a,i+1). ``peak_error_<size>_rad`` is the largest |x1| at the samples and plant events
in the scoring window inside the cycles of that size. Interior extrema between events are not
included; they lie within x4²/(2α·kc) ≈ 2e-10 rad of the nearest velocity-zero event for Table 2-1.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from bench.runner import RunResult

__all__ = ["wants_series", "figure_series"]

_SIZES = {1: "peak_error_small_rad", 2: "peak_error_medium_rad", 3: "peak_error_large_rad"}
_LARGE = 3


def wants_series(controller: Any) -> bool:
    """Solnic and its variants get a figure series (their runs are always recorded)."""
    try:
        from controllers.solnic import SolnicController
    except ImportError:
        return False
    return isinstance(controller, SolnicController)


def _ratio_pct(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den != 0, 100.0 * num / den, np.nan)


def _changes(columns: list[np.ndarray]) -> np.ndarray:
    """Cumulative count of steps at which any column changes (NaN → NaN is no change)."""
    n = len(columns[0]) if columns else 0
    changed = np.zeros(n, dtype=bool)
    for c in columns:
        prev = np.r_[np.nan, c[:-1]]
        same = (c == prev) | (np.isnan(c) & np.isnan(prev))
        changed |= ~same
    return np.cumsum(changed).astype(float)


def _held(t: np.ndarray, times: list[float], values: list[float]) -> np.ndarray:
    """Zero-order hold of (times, values) on the grid ``t`` (NaN before the first time)."""
    out = np.full(t.shape, np.nan)
    if not times:
        return out
    order = np.argsort(times, kind="stable")
    ts, vs = np.asarray(times)[order], np.asarray(values, dtype=float)[order]
    idx = np.searchsorted(ts, t, side="right") - 1
    ok = idx >= 0
    out[ok] = vs[idx[ok]]
    return out


def figure_series(result: RunResult, controller: Any, warmup_s: float = 0.0,
                  ) -> tuple[pd.DataFrame, dict[str, float]]:
    """The series frame and the per-size peaks of a recorded solnic run (see module docstring).

    ``warmup_s`` [s] is the start of the scoring window, for the peaks.
    """
    s, internals = result.samples or {}, result.internals or {}
    n = len(s.get("t", ()))
    if internals:
        n = min(n, min(len(v) for v in internals.values()))
    t = np.asarray(s.get("t", ()), dtype=float)[:n]
    col = {k: np.asarray(v, dtype=float)[:n] for k, v in internals.items()}
    nan = np.full(n, np.nan)

    def get(key: str) -> np.ndarray:
        return col.get(key, nan)

    def sample(key: str) -> np.ndarray:
        return np.asarray(s.get(key, nan), dtype=float)[:n]

    frame = pd.DataFrame({"t": t, "x1": sample("x1")})
    frame["ks_hat_pct"] = _ratio_pct(get("ks_hat"), sample("ks_true"))
    frame["kc_hat_pct"] = _ratio_pct(get("kc_hat"), sample("kc_true"))
    frame["x4_hat_pct"] = _ratio_pct(get("x4_hat"), sample("x4"))
    for key in ("cost_small", "cost_medium", "cost_large", "dc_ratio", "cycle_size"):
        frame[key] = get(key)
    with np.errstate(divide="ignore", invalid="ignore"):
        frame["ks_kc_corr"] = get("P_kc_ks") / np.sqrt(get("P_kc_kc") * get("P_ks_ks"))
    if "n_cost_updates" in col:
        frame["n_cost_updates"] = col["n_cost_updates"]
    else:
        frame["n_cost_updates"] = _changes([get(k) for k in ("cost_small", "cost_medium", "cost_large",
                                                              "dc_ratio")])
    summary = result.summary or {}
    opt = summary.get("dtu_opt_adjusted")
    if isinstance(opt, (int, float)) and math.isfinite(opt) and opt > 0:
        frame["dt_opt_rel_error"] = np.abs(get("dtu_opt") - opt) / opt
    log = [e for e in getattr(controller, "log", []) or [] if isinstance(e, dict)]
    if log:
        large = [e for e in log if e.get("size") == _LARGE and "t_a" in e and "dc_p" in e]
        frame["dc_large_rad"] = _held(t, [e["t_a"] for e in large], [e["dc_p"] for e in large])
        evaluated = [e for e in log if {"t_b", "dc_e", "dc_p"} <= e.keys() and e["dc_p"] != 0]
        frame["dc_rel_mismatch"] = _held(t, [e["t_b"] for e in evaluated],
                                         [abs(e["dc_e"] - e["dc_p"]) / abs(e["dc_p"]) for e in evaluated])
    return frame, _size_peaks(result, log, warmup_s)


def _size_peaks(result: RunResult, log: list[dict[str, Any]], warmup_s: float) -> dict[str, float]:
    peaks = {name: math.nan for name in _SIZES.values()}
    cycles = sorted((e["t_a"], e.get("t_b", e["t_a"]), e.get("size")) for e in log if "t_a" in e)
    if not cycles:
        return peaks
    parts_t, parts_x = [], []
    for arrays in (result.samples, result.events):
        if arrays and len(arrays.get("t", ())):
            parts_t.append(np.asarray(arrays["t"], dtype=float))
            parts_x.append(np.abs(np.asarray(arrays["x1"], dtype=float)))
    if not parts_t:
        return peaks
    t, x = np.concatenate(parts_t), np.concatenate(parts_x)
    starts = np.array([c[0] for c in cycles])
    # cycle i owns [t_a,i, t_a,i+1); the last logged one ends at its evaluation t_b (the cycle
    # launched then is still pending and not in the log)
    ends = np.r_[starts[1:], max(cycles[-1][1], cycles[-1][0])]
    sizes = np.array([c[2] if c[2] is not None else np.nan for c in cycles], dtype=float)
    owner = np.searchsorted(starts, t, side="right") - 1
    valid = (owner >= 0) & (t >= warmup_s)
    valid[valid] &= t[valid] <= ends[owner[valid]]
    for size, name in _SIZES.items():
        mask = valid.copy()
        mask[valid] = sizes[owner[valid]] == size
        if mask.any():
            peaks[name] = float(x[mask].max())
    return peaks
