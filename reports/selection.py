"""Which cells the claims read: the :class:`Selection` (from ``config.json``) and the row masks
that pick a family's cells out of the results (shared by :mod:`reports.claims` and
:mod:`reports.inputs`, which reads only the series the claims use)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import pandas as pd

from controllers import roles

__all__ = ["Selection", "family_of", "plain"]


@dataclass(frozen=True)
class Selection:
    """Which cells the claims read.

    Attributes
    ----------
    thesis_scenario : str
        Scenario of the thesis run (Table 2-1, 100 s).
    solnic, linear : str
        *Families* (results column ``controller_family``; a variant has its base's family) of
        the dissertation's controller and of the lag-compensated linear controller. A claim
        about "solnic" reads the cells of the family's registered controller itself (its name
        equals ``controller_base``), not its variants.
    adaptive_pulse : str
        Family of the model-free adaptive pulse-width peer (the robustness claims).
    high_error_cost : str
        Marker of the "high error cost" preset: a cell counts when it belongs to the ``solnic``
        family and its controller or scenario name contains this marker.
    typical_cell : str or None
        The series shown as "the typical run" (default: solnic/thesis with the lowest seed).
    """

    thesis_scenario: str = "thesis"
    solnic: str = roles.IDENTIFICATION
    linear: str = roles.CLASSICAL
    adaptive_pulse: str = roles.ADAPTIVE_PULSE
    high_error_cost: str = "high"
    typical_cell: str | None = None

    @classmethod
    def from_config(cls, config: Mapping[str, Any] | None) -> "Selection":
        """Read ``config["report"]["selection"]`` and ``config["report"]["typical_cell"]``."""
        report = (config or {}).get("report") or {}
        sel = dict(report.get("selection") or {})
        if report.get("typical_cell") is not None:
            sel.setdefault("typical_cell", report["typical_cell"])
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(sel) - names)
        if unknown:
            raise ValueError(f"config.report.selection has unknown key(s) {unknown}; "
                             f"known: {sorted(names)}")
        return cls(**sel)


def family_of(r: pd.DataFrame) -> pd.Series:
    """Each row's family: ``controller_family``, else ``controller_base``, else ``controller``."""
    out = r["controller"].astype(str)
    for col in ("controller_base", "controller_family"):
        if col in r.columns:
            v = r[col].astype("string")
            out = v.where(v.notna() & (v != ""), out).astype(str)
    return out


def plain(r: pd.DataFrame, family: str) -> pd.Series:
    """Rows of the registered controller that *is* ``family`` (its name is the family's): not a
    matrix variant of it, nor a registered subclass that inherits the family (solnic-modern)."""
    base = r["controller_base"].astype(str) if "controller_base" in r.columns else r["controller"]
    return (family_of(r) == family) & (r["controller"] == base) & (r["controller"] == family)
