"""Benchmark scenarios: a plant configuration with a run length and a scoring warm-up (SPEC §5).

Built in:

* ``thesis`` — Table 2-1 (:class:`~plant.params.PlantParams` defaults), 100 s, warm-up 20 s;
* ``quiet-friction`` — the same with no white friction noise, σ2² = 0;
* ``ratio-2`` — k̄s/k̄c = 2 (stiction 2.8, Coulomb 1.4 ozf·in).

A custom scenario is a base scenario plus :class:`PlantParams` overrides (see
:func:`derive_scenario`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from plant.params import PlantParams

__all__ = ["Scenario", "builtin_scenarios", "derive_scenario", "SCENARIO_KEYS"]

# Keys of a custom scenario that are not PlantParams fields.
SCENARIO_KEYS = ("base", "description", "duration_s", "warmup_s")


@dataclass(frozen=True)
class Scenario:
    """A plant and how long to run it.

    Attributes
    ----------
    name : str
        Scenario name (part of the cell id).
    params : PlantParams
        The plant.
    duration_s : float
        Simulated length of a run [s].
    warmup_s : float
        Start of the scoring window [s], in [0, duration_s).
    description : str
        One line for ``solnic-bench list``.
    base : str
        The built-in scenario this one derives from (its own name for a built-in).
    """

    name: str
    params: PlantParams
    duration_s: float
    warmup_s: float
    description: str = ""
    base: str = ""

    def __post_init__(self) -> None:
        for field in ("duration_s", "warmup_s"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"Scenario.{field} must be a finite number, got {value!r}")
            object.__setattr__(self, field, float(value))
        if not self.duration_s >= self.params.sample_period:
            raise ValueError(f"Scenario.duration_s must be at least one sample period "
                             f"({self.params.sample_period!r} s), got {self.duration_s!r}")
        if not 0 <= self.warmup_s < self.duration_s:
            raise ValueError(f"Scenario.warmup_s must be in [0, duration_s = {self.duration_s!r}), "
                             f"got {self.warmup_s!r}")
        if not self.base:
            object.__setattr__(self, "base", self.name)

    def with_durations(self, duration_s: float | None = None, warmup_s: float | None = None) -> "Scenario":
        """A copy with the run length and/or warm-up replaced (validated)."""
        changes: dict[str, Any] = {}
        if duration_s is not None:
            changes["duration_s"] = duration_s
        if warmup_s is not None:
            changes["warmup_s"] = warmup_s
        return dataclasses.replace(self, **changes) if changes else self

    def to_json(self) -> dict[str, Any]:
        return {"base": self.base, "description": self.description, "duration_s": self.duration_s,
                "warmup_s": self.warmup_s, "plant": dataclasses.asdict(self.params)}


def builtin_scenarios() -> dict[str, Scenario]:
    """The built-in scenarios by name."""
    table = PlantParams()
    return {
        "thesis": Scenario("thesis", table, 100.0, 20.0,
                           "Table 2-1, the initial estimates of section 7.3"),
        "quiet-friction": Scenario("quiet-friction", table.replace(friction_noise_psd=0.0), 100.0, 20.0,
                                   "Table 2-1 without white friction noise (σ2 = 0)"),
        "ratio-2": Scenario("ratio-2", table.replace(stiction=2.8, coulomb=1.4), 100.0, 20.0,
                            "k̄s/k̄c = 2 (stiction 2.8, Coulomb 1.4 ozf·in)"),
    }


def derive_scenario(name: str, base: Scenario, overrides: dict[str, Any]) -> Scenario:
    """``base`` with PlantParams overrides and optionally ``duration_s``/``warmup_s``/``description``.

    Raises
    ------
    ValueError
        Naming the field (``PlantParams.<field> ...`` or ``Scenario.<field> ...``) or the
        unknown key.
    """
    plant = {k: v for k, v in overrides.items() if k not in SCENARIO_KEYS}
    params = base.params.replace(**plant) if plant else base.params
    if "description" in overrides:
        description = overrides["description"]
    elif plant:
        description = f"{base.name} with " + ", ".join(f"{k} = {v!r}" for k, v in sorted(plant.items()))
    else:
        description = base.description
    if not isinstance(description, str):
        raise ValueError(f"Scenario.description must be a string, got {description!r}")
    return Scenario(name, params, overrides.get("duration_s", base.duration_s),
                    overrides.get("warmup_s", base.warmup_s), description, base.base)
