"""The verdicts: does θ ≥ θb (2-6) hold for every scored run, and where does hunting start
against Lmax (2-1); the result columns and their JSON form."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

__all__ = ["BOUND_COLUMNS", "HUNTING_COLUMNS", "bound_verdict", "hunting_onsets"]


BOUND_COLUMNS = ("design", "omega_c", "lag_ratio", "ks_over_kc", "inertia", "noise", "theta_rad",
                 "theta_b_rad", "ratio", "stable", "status")

HUNTING_COLUMNS = ("ks_over_kc", "lmax", "onset_L", "onset_over_lmax", "highest_quiet_L",
                   "lowest_hunting_L", "omega_c", "inertia", "n_initial_errors", "tested_L",
                   "hunting_L", "integral_hunts")


def hunting_onsets(runs: pd.DataFrame) -> pd.DataFrame:
    """One row per k̄s/k̄c: the onset L of hunting against Lmax (2-1).

    An L hunts when any initial error ends in a sustained limit cycle. The onset is the smallest
    tested finite L from which every larger tested finite L hunts (NaN when the largest does not).
    """
    rows = []
    for ratio, g in runs.groupby("ks_over_kc", sort=True):
        finite = g[~g["integral"]]
        by_lag = finite.groupby("lag_ratio")["hunting"].any().sort_index()
        lags = by_lag.index.to_numpy(dtype=float)
        hunts = by_lag.to_numpy(dtype=bool)
        onset = math.nan
        for i in range(len(lags) - 1, -1, -1):
            if not hunts[i]:
                break
            onset = float(lags[i])
        quiet = lags[(lags < onset) & ~hunts] if math.isfinite(onset) else lags[~hunts]
        lmax = float(g["lmax"].iloc[0])
        integral = g[g["integral"]]
        rows.append({
            "ks_over_kc": float(ratio), "lmax": lmax, "onset_L": onset,
            "onset_over_lmax": onset / lmax,
            "highest_quiet_L": float(quiet.max()) if quiet.size else math.nan,
            "lowest_hunting_L": float(lags[hunts].min()) if hunts.any() else math.nan,
            "omega_c": float(g["omega_c"].iloc[0]), "inertia": float(g["inertia"].iloc[0]),
            "n_initial_errors": int(g["offset_factor"].nunique()),
            "tested_L": ";".join(f"{x:.4g}" for x in lags),
            "hunting_L": ";".join(f"{x:.4g}" for x in lags[hunts]),
            "integral_hunts": bool(integral["hunting"].any()) if len(integral) else math.nan,
        })
    return pd.DataFrame(rows, columns=list(HUNTING_COLUMNS))


def bound_verdict(bound: pd.DataFrame) -> dict[str, Any]:
    """Does θ ≥ θb hold for every stable, completed run? The minimum ratio and its design."""
    scored = bound[bound["stable"] & (bound["status"] == "ok") & np.isfinite(bound["ratio"])]
    out: dict[str, Any] = {
        "n_cells": int(len(bound)), "n_stable": int(bound["stable"].sum()),
        "n_scored": int(len(scored)),
        "n_unstable": int((bound["status"] == "unstable").sum()),
        "n_no_design": int((bound["status"] == "no_design").sum()),
        "n_skipped": int((bound["status"] == "skipped").sum()),
        "n_unsteady": int((bound["status"] == "unsteady").sum()),
        "n_failed": int((bound["stable"] & ~bound["status"].isin(["ok", "skipped", "unsteady"])).sum()),
        "n_violations": int((scored["ratio"] < 1.0).sum()),
    }
    out["holds"] = bool(len(scored) > 0 and out["n_violations"] == 0)
    if len(scored):
        row = scored.loc[scored["ratio"].idxmin()]
        out["min_ratio"] = float(row["ratio"])
        out["min_ratio_design"] = {k: _plain(row[k]) for k in
                                   ("design", "omega_c", "lag_ratio", "ks_over_kc", "inertia",
                                    "noise", "theta_rad", "theta_b_rad", "n_slips_window")}
        per_noise = {}
        for noise, g in scored.groupby("noise"):
            r = g.loc[g["ratio"].idxmin()]
            per_noise["on" if noise else "off"] = {"min_ratio": float(r["ratio"]),
                                                   "design": str(r["design"]),
                                                   "ks_over_kc": float(r["ks_over_kc"]),
                                                   "inertia": float(r["inertia"])}
        out["min_ratio_by_noise"] = per_noise
        out["min_ratio_by_crossover"] = {f"{w:g}": float(g["ratio"].min())
                                         for w, g in scored.groupby("omega_c")}
        if "lag_over_lmax" in scored.columns:
            lag_key = scored["lag_over_lmax"].where(np.isfinite(scored["lag_over_lmax"]))
            out["min_ratio_by_lag_over_lmax"] = {
                ("integral" if math.isnan(k) else f"{k:.3g}"): float(g["ratio"].min())
                for k, g in scored.groupby(lag_key.round(3).fillna(math.nan), dropna=False)}
        out["n_fewer_than_2_slips"] = int((scored["n_slips_window"] < 2).sum())
    else:
        out["min_ratio"] = math.nan
    return out


def _plain(v: Any) -> Any:
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        return float(v)
    return v


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    obj = _plain(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj
