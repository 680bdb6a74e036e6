"""Parameters of the ``stribeck`` family: Acker's plant with a Stribeck curve and viscous drag."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from plant.ripple import RippleParams, finite_field

__all__ = ["StribeckParams"]


@dataclass(frozen=True)
class StribeckParams(RippleParams):
    """Table 2-1 plus the sliding law F(v) = kc + (ks − kc)·exp(−(|v|/v_s)^δ) + b·|v| (SPEC §11).

    Attributes
    ----------
    stribeck_velocity : float
        v_s > 0 [rad/s]. Default 4e-3 rad/s: the speed scale of the pulses a positioning
        controller emits on Table 2-1 (a 1.5 ms bridge pulse peaks near 3 mrad/s on Acker's plant), so that
        a pulse's friction lies on the falling part of the curve, where the law matters. A
        v_s far above it makes a pulse slide at ks throughout; far below, the plant is
        Acker's. (Table I of Canudas de Wit et al. 1995 has 1 mm/s, i.e. 4e-3 rad/s at a
        10 in lever arm.)
    stribeck_exponent : float
        δ > 0 [-]; 2 (Gaussian, Armstrong-Hélouvry 1991, and the 1995 paper) by default.
    viscous : float
        b ≥ 0 [ozf·in·s/rad]. Default 0.2: grease drag that adds 0.2 ozf·in (14 % of k̄c)
        at a 1 rad/s slew and under 0.1 % of k̄c at pulse speeds, where Acker's plant
        (b = 0) is a good model.

    The levels are kc = k̄c·m(θ) + x5 and ks = k̄s·m(θ) + x5, clamped at ≥ 0, with
    m(θ) = 1 + a·sin(2π·θ/λ + φ) the ripple of :class:`~plant.ripple.RippleParams`.
    """

    stribeck_velocity: float = 4e-3
    stribeck_exponent: float = 2.0
    viscous: float = 0.2

    def __post_init__(self) -> None:
        super().__post_init__()
        name = type(self).__name__
        for field in ("stribeck_velocity", "stribeck_exponent", "viscous"):
            object.__setattr__(self, field, finite_field(name, field, getattr(self, field)))
        if not self.stribeck_velocity > 0.0:
            raise ValueError(f"{name}.stribeck_velocity must be > 0 rad/s, got {self.stribeck_velocity!r}")
        if not self.stribeck_exponent > 0.0:
            raise ValueError(f"{name}.stribeck_exponent must be > 0, got {self.stribeck_exponent!r}")
        if not self.viscous >= 0.0:
            raise ValueError(f"{name}.viscous must be >= 0 ozf·in·s/rad, got {self.viscous!r}")

    def law_vector(self) -> np.ndarray:
        """The compiled kernels' parameter vector (plant.stribeck.moving: LAW_* slots), cached."""
        vec = self.__dict__.get("_law_vector")
        if vec is None:
            vec = np.array([self.alpha, self.beta3, self.beta4, self.beta5, self.coulomb, self.stiction,
                            self.stribeck_velocity, self.stribeck_exponent, self.viscous, self.friction_ripple,
                            2.0 * np.pi / self.ripple_period, self.ripple_phase, self.sigma2_sq, self.sigma5_sq])
            vec.flags.writeable = False
            object.__setattr__(self, "_law_vector", vec)
        return vec
