"""The runs of a plan: one :class:`BoundCell` per (plant, design, noise) of the (2-6) sweep and
one :class:`HuntingCell` per (k̄s/k̄c, L, initial error) of the (2-1) sweep, each with its seed."""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass
from typing import Any

from bench.bound.plan import COULOMB, RAMP_VELOCITY, SweepPlan
from plant.params import PlantParams, bohacek_tuteur_limit

__all__ = ["BoundCell", "HuntingCell", "bound_cells", "hunting_cells"]


def _seed(*key: Any) -> int:
    return zlib.crc32(repr(key).encode()) & 0x7FFFFFFF


def _lag_label(lag_ratio: float, integral: bool, lmax: float) -> str:
    if integral:
        return "integral"
    k = lag_ratio / lmax
    if abs(k - 1) < 1e-9:
        return f"L=Lmax={lag_ratio:.3g}"
    for m in (1.5, 2.0, 3.0):
        if abs(k - m) < 1e-9:
            return f"L={m:g}·Lmax={lag_ratio:.3g}"
    return f"L={lag_ratio:.3g}"


@dataclass(frozen=True)
class BoundCell:
    """One run of the bound sweep: a design on a plant, noise on or off, on the ramp."""

    ks_over_kc: float
    inertia: float
    omega_c: float
    lag_ratio: float      # inf for the pure integral
    integral: bool
    noise: bool
    cap_s: float
    seed: int
    warmup_ts: float = 0.5
    window_ts: float = 1.5
    window_tf: float = 1.0

    def params(self) -> PlantParams:
        return PlantParams(inertia=self.inertia, coulomb=COULOMB, stiction=COULOMB * self.ks_over_kc,
                           command_velocity_std=0.0, command_velocity_initial=RAMP_VELOCITY,
                           command_velocity_tau=1e9)

    def time_scale(self) -> float:
        """t_s = k̄s/(J·ωc²·v) [s] (module docstring)."""
        return COULOMB * self.ks_over_kc / (self.inertia * self.omega_c**2 * RAMP_VELOCITY)

    def cost(self) -> float:
        """A rough relative cost for scheduling (simulated seconds)."""
        lag = 0.0 if self.integral else 5.0 / self.lag_ratio   # t_first ≈ 5·t_s/L
        return min((self.warmup_ts + self.window_ts + (1 + self.window_tf) * lag)
                   * self.time_scale(), self.cap_s)


@dataclass(frozen=True)
class HuntingCell:
    """One run of the hunting sweep: stationary set-point, initial error e0, noise off."""

    ks_over_kc: float
    inertia: float
    omega_c: float
    lag_ratio: float      # inf for the pure integral
    integral: bool
    offset_factor: float
    duration_s: float
    seed: int

    def params(self) -> PlantParams:
        return PlantParams(inertia=self.inertia, coulomb=COULOMB, stiction=COULOMB * self.ks_over_kc,
                           command_velocity_std=0.0, command_velocity_initial=0.0)

    def cost(self) -> float:
        return self.duration_s


def bound_cells(plan: SweepPlan) -> list[BoundCell]:
    """Every (plant, crossover, lag, noise) cell of the bound sweep, then the probes."""
    def lag_specs(ratio: float, absolute: tuple[float, ...]) -> list[tuple[float, bool]]:
        lmax = bohacek_tuteur_limit(ratio, 1.0)            # (2-1) with k̄s = ratio·k̄c
        lags = sorted({float(x) for x in absolute} | {m * lmax for m in plan.lag_multiples})
        return [(lag, False) for lag in lags] + ([(math.inf, True)] if plan.integral else [])

    runs = [(ratio, inertia, omega, lag_specs(ratio, plan.lag_absolute), plan.cap_s)
            for ratio, inertia in plan.plants for omega in plan.crossovers]
    runs += [(ratio, inertia, omega, lag_specs(ratio, ()), plan.probe_cap_s)
             for omega, ratio, inertia in plan.probes]
    cells = []
    for ratio, inertia, omega, specs, cap in runs:
        for lag, integral in specs:
            for noise in plan.noise:
                key = (ratio, inertia, omega, lag, integral, noise)
                cells.append(BoundCell(ratio, inertia, float(omega), lag, integral, noise, cap,
                                       _seed("bound", *key), plan.warmup_ts, plan.window_ts,
                                       plan.window_tf))
    return cells


def _hunting_duration(ratio: float) -> float:
    # Slip spacing at onset grows as k̄s − k̄c shrinks (≈ 15 s at k̄s/k̄c = 1.1): keep ≥ 4 slips
    # in the detector's tail half.
    return max(60.0, 35.0 * 0.7 / (COULOMB * (ratio - 1)))


def hunting_cells(plan: SweepPlan) -> list[HuntingCell]:
    """Every (ratio, L, initial error) cell of the hunting sweep."""
    cells = []
    for ratio in plan.hunting_ratios:
        lmax = bohacek_tuteur_limit(ratio, 1.0)            # (2-1)
        specs = [(m * lmax, False) for m in plan.hunting_multiples]
        if plan.hunting_integral:
            specs.append((math.inf, True))
        for lag, integral in specs:
            for f in plan.hunting_offsets:
                key = (ratio, lag, integral, f)
                cells.append(HuntingCell(ratio, plan.hunting_inertia, plan.hunting_crossover, lag,
                                         integral, f, _hunting_duration(ratio), _seed("hunt", *key)))
    return cells
