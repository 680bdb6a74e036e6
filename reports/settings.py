"""The report's table of controllers' settings and design figures.

Read from the rows' ``ctl_*`` columns, which every controller fills from its own ``summary()``
(the generic hook of :class:`controllers.base.Controller`): a value that is the same on every
seed of a controller and scenario is a setting or a design figure (gain, crossover, margins,
knobs); a value that varies is a run diagnostic and is left to the per-cell table. Units come
from the key's suffix (``_rad_s`` rad/s, ``_deg`` °, ``_db`` dB, ``_rad`` shown in µrad, ``_hz``
Hz, ``_s`` s). Nothing here knows a controller by name.
"""

from __future__ import annotations

import math
from typing import Any

import pandas as pd

__all__ = ["settings_rows"]

_UNITS = (("_rad_s", "rad/s", 1.0), ("_deg", "°", 1.0), ("_db", "dB", 1.0), ("_rad", "µrad", 1e6),
          ("_hz", "Hz", 1.0), ("_s", "s", 1.0))


def _fmt(key: str, value: Any) -> str:
    name, unit, scale = key, "", 1.0
    for suffix, u, k in _UNITS:
        if key.endswith(suffix):
            name, unit, scale = key[: -len(suffix)], u, k
            break
    name = name.replace("_", " ")
    if isinstance(value, (bool,)) or str(value) in ("True", "False"):
        return f"{name}: {'yes' if str(value) == 'True' else 'no'}"
    try:
        v = float(value) * scale
    except (TypeError, ValueError):
        return f"{name}: {value}"
    if math.isinf(v):
        text = "∞"
    elif v == int(v) and abs(v) < 1e6:
        text = f"{int(v)}"
    else:
        text = f"{v:.3g}"
    return f"{name} = {text}{(' ' + unit) if unit else ''}"


def settings_rows(results: pd.DataFrame) -> list[dict[str, Any]]:
    """One entry per controller (matrix order): ``{"controller", "scenario", "figures": [str]}``,
    the ``ctl_*`` values constant over the seeds of its first scenario (in sorted order)."""
    if results.empty:
        return []
    cols = [c for c in results.columns if c.startswith("ctl_")]
    out = []
    ok = results[results["status"] == "ok"]
    for ctrl in dict.fromkeys(ok["controller"]):
        g = ok[ok["controller"] == ctrl]
        scen = sorted(g["scenario"].unique())[0]
        g = g[g["scenario"] == scen]
        figures = []
        for c in sorted(cols):
            v = g[c].dropna()
            if v.empty or v.astype(str).nunique() != 1:
                continue
            figures.append(_fmt(c[len("ctl_"):], v.iloc[0]))
        out.append({"controller": str(ctrl), "scenario": str(scen), "figures": figures})
    return out
