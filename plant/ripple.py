"""Position-dependent friction (SPEC §11): k̄c and k̄s scaled by 1 + a·sin(2π·θ/λ + φ).

θ is the load angle c [rad] (a family that uses the ripple tracks it as an extra state entry,
:data:`THETA`, after the six shared ones). A rolling bearing's or a gear mesh's drag repeats
with the angle; one harmonic is the first term of that Fourier series.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from numba import njit

from plant.params import PlantParams

__all__ = ["RippleParams", "ripple_factor", "THETA", "finite_field"]

THETA = 6          # state index of the load angle θ = c [rad] in the families that track it


def finite_field(cls_name: str, name: str, value: object) -> float:
    """``value`` as a float, or a ValueError naming ``<cls_name>.<name>``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{cls_name}.{name} must be a finite real number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class RippleParams(PlantParams):
    """:class:`PlantParams` plus one harmonic of position-dependent friction.

    Attributes
    ----------
    friction_ripple : float
        a, relative amplitude, |a| < 1 (so the levels stay positive) [-]. 0: off.
    ripple_period : float
        λ, angular period of the ripple, > 0 [rad].
    ripple_phase : float
        φ, phase at θ = 0 [rad].
    """

    friction_ripple: float = 0.0
    ripple_period: float = 0.01
    ripple_phase: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        name = type(self).__name__
        for field in ("friction_ripple", "ripple_period", "ripple_phase"):
            object.__setattr__(self, field, finite_field(name, field, getattr(self, field)))
        if not abs(self.friction_ripple) < 1.0:
            raise ValueError(f"{name}.friction_ripple must be in (-1, 1), got {self.friction_ripple!r}")
        if not self.ripple_period > 0.0:
            raise ValueError(f"{name}.ripple_period must be > 0 rad, got {self.ripple_period!r}")


@njit(cache=True)
def ripple_factor(theta, a, wavenumber, phase):
    """1 + a·sin(k·θ + φ), k = 2π/λ [rad⁻¹]."""
    if a == 0.0:
        return 1.0
    return 1.0 + a * math.sin(wavenumber * theta + phase)
