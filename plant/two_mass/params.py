"""Parameters of the two-mass plant: Table 2-1 plus a compliant shaft (SPEC §11).

The motor inertia J_m is driven by the motor torque x3 and coupled to the load J by a
torsional spring k_sh and a damper c_sh; friction acts on the load. Units as Table 2-1:
inertia in ozf·in·s², stiffness in ozf·in/rad, damping in ozf·in·s/rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from plant.params import PlantParams

__all__ = ["TwoMassParams"]


@dataclass(frozen=True)
class TwoMassParams(PlantParams):
    """Table 2-1 plus the shaft (SPEC §11 "Families").

    Attributes
    ----------
    motor_inertia : float
        J_m, rotor inertia [ozf·in·s²] (> 0).
    shaft_stiffness : float
        k_sh, torsional stiffness between rotor and load [ozf·in/rad] (> 0).
    shaft_damping : float
        c_sh, torsional damping [ozf·in·s/rad] (≥ 0).

    The defaults give a 149 Hz shaft resonance with ζ = 0.029 (the ``compliant`` scenario),
    J_m = J/10.
    """

    motor_inertia: float = 0.05
    shaft_stiffness: float = 4.0e4
    shaft_damping: float = 2.5

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("motor_inertia", "shaft_stiffness"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"TwoMassParams.{name} must be a finite number > 0, got {value!r}")
            object.__setattr__(self, name, float(value))
        c = self.shaft_damping
        if isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c) or c < 0:
            raise ValueError(f"TwoMassParams.shaft_damping must be a finite number >= 0, got {c!r}")
        object.__setattr__(self, "shaft_damping", float(c))
        for zeta, which in ((self.damping_ratio, "load moving"), (self.stuck_damping_ratio, "load stuck")):
            if abs(zeta - 1.0) < 1e-3:
                raise ValueError(f"TwoMassParams.shaft_damping must not make the shaft critically damped "
                                 f"({which}: damping ratio {zeta:.6g}, |ζ - 1| must be >= 1e-3), got {c!r}")

    @property
    def resonance(self) -> float:
        """Undamped shaft resonance with the load free, √(k_sh·(1/J + 1/J_m)) [rad/s]."""
        return math.sqrt(self.shaft_stiffness * (1.0 / self.inertia + 1.0 / self.motor_inertia))

    @property
    def damping_ratio(self) -> float:
        """ζ of the free resonance: c_sh·(1/J + 1/J_m)/(2ω)."""
        mu = 1.0 / self.inertia + 1.0 / self.motor_inertia
        return self.shaft_damping * mu / (2.0 * self.resonance)

    @property
    def stuck_damping_ratio(self) -> float:
        """ζ of the rotor on the shaft with the load held: c_sh/(2√(k_sh·J_m))."""
        return self.shaft_damping / (2.0 * math.sqrt(self.shaft_stiffness * self.motor_inertia))
