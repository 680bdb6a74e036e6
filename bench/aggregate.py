"""The aggregate table: per controller × scenario, mean, worst and spread over seeds.

Only cells with status ``ok`` enter the statistics; ``ok`` counts them against all cells.
"Worst" is the largest value (every aggregated metric is better when smaller); "spread" is the
sample standard deviation over seeds (NaN with one seed).
"""

from __future__ import annotations

import math

import pandas as pd

__all__ = ["aggregate", "AGGREGATED"]

# (column, label, scale): the metrics of the terminal table
AGGREGATED = (
    ("peak_error_rad", "peak |x1| [µrad]", 1e6),
    ("rms_error_rad", "RMS x1 [µrad]", 1e6),
    ("mean_abs_current", "mean |i| [ozf·in]", 1.0),
    ("rms_current", "RMS i [ozf·in]", 1.0),
    ("runtime_s", "runtime [s]", 1.0),
)


def aggregate(results: pd.DataFrame, order: tuple[list[str], list[str]] | None = None) -> pd.DataFrame:
    """One row per (controller, scenario): ``ok``, ``cells`` and ``<col>_mean/_worst/_spread``.

    ``order`` = (controllers, scenarios) sorts the rows in matrix order (default: by name).
    Values are in the display units of :data:`AGGREGATED` (errors in µrad).
    """
    if results.empty:
        return pd.DataFrame()
    rows = []
    for (ctrl, scen), g in results.groupby(["controller", "scenario"], sort=True):
        ok = g[g["status"] == "ok"]
        row = {"controller": ctrl, "scenario": scen, "ok": len(ok), "cells": len(g)}
        for col, _, scale in AGGREGATED:
            v = (ok[col].astype(float) * scale).dropna() if col in ok else pd.Series(dtype=float)
            row[f"{col}_mean"] = float(v.mean()) if len(v) else math.nan
            row[f"{col}_worst"] = float(v.max()) if len(v) else math.nan
            row[f"{col}_spread"] = float(v.std(ddof=1)) if len(v) > 1 else math.nan
        rows.append(row)
    df = pd.DataFrame(rows)
    if order is not None:
        ctrl_rank = {c: i for i, c in enumerate(order[0])}
        scen_rank = {s: i for i, s in enumerate(order[1])}
        df = df.sort_values(["controller", "scenario"], key=lambda s: s.map(
            ctrl_rank if s.name == "controller" else scen_rank).fillna(1e9)).reset_index(drop=True)
    return df
