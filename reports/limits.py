"""Closed-form limits of the thesis, computed from the run's plant configuration.

* Classical limit (2-6): θe ≥ (k̄s − k̄c)/(2·J·ωb²), with ωb = π/τs (Nyquist, SPEC §6) [rad].
* Bohacek–Tuteur lag-ratio limit (2-1): Lmax = 2k̄s/(k̄s − k̄c) [–].

The report never hard-codes 7.09 µrad or 6: both follow from the plant parameters stored in
``config.json`` (key ``"plant"``, or ``"scenarios" → "thesis" → "plant"``). When neither is
present the :class:`plant.PlantParams` defaults (Table 2-1) are used and :attr:`PlantLimits.source`
says so, so the report can show it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from plant.params import bohacek_tuteur_limit, lti_peak_bound

__all__ = ["PlantLimits", "limits_from_config", "lag_ratio_limit", "scenario_limits"]

# Table 2-1 values, used only when a configuration carries no plant section.
_TABLE_2_1 = {"stiction": 2.1, "coulomb": 1.4, "inertia": 0.5, "sample_period": 0.01}


@dataclass(frozen=True)
class PlantLimits:
    """The plant parameters that set the limits, and the limits themselves.

    Attributes
    ----------
    stiction, coulomb : float
        k̄s, k̄c [ozf·in].
    inertia : float
        J [ozf·in·s²].
    sample_period : float
        τs [s].
    source : str
        Where the parameters came from (a config key path, or the defaults).
    """

    stiction: float
    coulomb: float
    inertia: float
    sample_period: float
    source: str = "config"

    def __post_init__(self) -> None:
        for name in ("stiction", "coulomb", "inertia", "sample_period"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"PlantLimits.{name} must be a finite number, got {value!r}")
        if self.inertia <= 0 or self.sample_period <= 0:
            raise ValueError("PlantLimits.inertia and sample_period must be > 0")
        if self.stiction < self.coulomb:
            raise ValueError(
                f"PlantLimits.stiction must be >= coulomb ({self.coulomb!r}), got {self.stiction!r}")

    @property
    def nyquist_bandwidth(self) -> float:
        """ωb = π/τs [rad/s]."""
        return math.pi / self.sample_period

    @property
    def classical_limit_rad(self) -> float:
        """θe,min = (k̄s − k̄c)/(2·J·ωb²)  (2-6) [rad]."""
        return lti_peak_bound(self.stiction, self.coulomb, self.inertia, self.nyquist_bandwidth)

    def bound_at(self, omega: float) -> float:
        """θb = (k̄s − k̄c)/(2·J·ω²)  (2-6) at bandwidth ``omega`` [rad]."""
        return lti_peak_bound(self.stiction, self.coulomb, self.inertia, omega)

    @property
    def lmax(self) -> float:
        """Lmax = 2k̄s/(k̄s − k̄c)  (2-1) [–]."""
        return lag_ratio_limit(self.stiction / self.coulomb if self.coulomb > 0 else math.inf)


def lag_ratio_limit(ks_over_kc: float) -> float:
    """Lmax = 2k̄s/(k̄s − k̄c) = 2r/(r − 1) with r = k̄s/k̄c  (2-1); inf at r = 1, 2 as r → ∞."""
    r = float(ks_over_kc)
    # (2-1) at k̄s = r, k̄c = 1 (k̄s = 1, k̄c = 0 when k̄c vanishes): the same operations as 2r/(r − 1)
    return bohacek_tuteur_limit(1.0, 0.0) if math.isinf(r) else bohacek_tuteur_limit(r, 1.0)


def limits_from_config(config: Mapping[str, Any] | None) -> PlantLimits:
    """Read k̄s, k̄c, J and τs from ``config["plant"]`` (or the thesis scenario's plant).

    Missing fields fall back to Table 2-1 (the ``PlantParams`` defaults); ``source`` records it.
    """
    config = config or {}
    candidates: list[tuple[str, Any]] = [("config.plant", config.get("plant"))]
    scenarios = config.get("scenarios")
    if isinstance(scenarios, Mapping) and isinstance(scenarios.get("thesis"), Mapping):
        candidates.append(("config.scenarios.thesis.plant", scenarios["thesis"].get("plant")))
    for source, plant in candidates:
        if isinstance(plant, Mapping) and plant:
            values = {k: float(plant.get(k, _TABLE_2_1[k])) for k in _TABLE_2_1}
            missing = sorted(k for k in _TABLE_2_1 if k not in plant)
            note = f"{source}" + (f" (defaults for {', '.join(missing)})" if missing else "")
            return PlantLimits(**values, source=note)
    return PlantLimits(**_TABLE_2_1,
                       source="PlantParams defaults (Table 2-1): no plant section in config")


def scenario_limits(config: Mapping[str, Any] | None) -> dict[str, PlantLimits]:
    """Each scenario's own limits, from ``config["scenarios"][name]["plant"]`` (Table 2-1 for
    missing fields); empty when the configuration records no scenarios. The classical limit
    (2-6) of a scenario is its ``classical_limit_rad``."""
    out: dict[str, PlantLimits] = {}
    scenarios = (config or {}).get("scenarios")
    if not isinstance(scenarios, Mapping):
        return out
    for name, spec in scenarios.items():
        plant = spec.get("plant") if isinstance(spec, Mapping) else None
        plant = plant if isinstance(plant, Mapping) else {}
        try:
            out[str(name)] = PlantLimits(**{k: float(plant.get(k, _TABLE_2_1[k])) for k in _TABLE_2_1},
                                         source=f"config.scenarios.{name}.plant")
        except (TypeError, ValueError):
            continue
    return out
