"""The report's "Plants and models" section: what each scenario's truth is and what controllers were told.

A scenario's truth is a plant family with its parameters; controllers are told a model (a
``PlantParams``), the truth's own fields unless the scenario says otherwise, and the truth may
differ from it per seed by lognormal factors (``mismatch``). This module turns the run's
configuration (``config.json`` → ``scenarios``) and its rows (``mismatch_<field>`` columns)
into plain tables: one row per scenario, and one row per scenario and seed with its factors.
"""

from __future__ import annotations

from typing import Any, Mapping

import pandas as pd

__all__ = ["plants_context"]


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def plants_context(config: Mapping[str, Any] | None, results: pd.DataFrame) -> dict[str, Any]:
    """``{"scenarios": [...], "factors": {"header": [...], "rows": [...]}, "all_default": bool}``.

    Each scenario row: name, family (the truth's), the fields in which the model differs from
    the truth ("told k̄c = 1.4 (truth 1.8)"), and the mismatch spec ("coulomb ±20 %").
    """
    scenarios = dict((config or {}).get("scenarios") or {})
    rows, any_special = [], False
    for name, spec in scenarios.items():
        plant = spec.get("plant") or {}
        family = spec.get("family")
        model = spec.get("model") or {}
        mismatch = spec.get("mismatch") or {}
        told = [f"{k} = {_fmt(v)} (truth {_fmt(plant.get(k))})" for k, v in sorted(model.items())
                if plant.get(k) != v]
        any_special |= bool(family or told or mismatch)
        rows.append({"name": name, "family": family or "Acker's plant (default)",
                     "told": "; ".join(told) if told else "the truth's own parameters",
                     "mismatch": ", ".join(f"{k} ±{100 * v:.0f} %" for k, v in sorted(mismatch.items())) or "none"})
    cols = [c for c in results.columns if c.startswith("mismatch_")] if len(results) else []
    factor_rows: list[list[str]] = []
    if cols:
        per_seed = (results.dropna(subset=cols, how="all").groupby(["scenario", "seed"], sort=True)[cols].first())
        for (scenario, seed), values in per_seed.iterrows():
            factor_rows.append([str(scenario), str(seed)] + ["" if pd.isna(v) else f"{v:.4f}" for v in values])
    return {"scenarios": rows, "all_default": not any_special,
            "factors": {"header": ["scenario", "seed"] + [f"{c[len('mismatch_'):]} ×" for c in cols],
                        "rows": factor_rows}}
