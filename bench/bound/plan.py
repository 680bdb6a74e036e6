"""What ``check-bound`` sweeps: the :class:`SweepPlan` of ``full``, ``quick`` and ``tiny`` (the
module doc of :mod:`bench.bound` says why these crossovers, plants and durations)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from plant.params import PlantParams

__all__ = ["RAMP_VELOCITY", "COULOMB", "SweepPlan", "sweep_plan", "highest_stable_crossover"]


#: Commanded ramp velocity of the bound sweep, x4 [rad/s] (SPEC §6).
RAMP_VELOCITY = 30e-6

#: Mean Coulomb friction k̄c of every swept plant [ozf·in] (Table 2-1); k̄s = ratio·k̄c.
COULOMB = 1.4


_MODES = ("full", "quick", "tiny")


@dataclass(frozen=True)
class SweepPlan:
    """What one check-bound run sweeps.

    Attributes
    ----------
    mode : str
        ``full``, ``quick`` or ``tiny`` (tests only).
    crossovers : tuple of float
        Design crossovers ωc [rad/s] of the bound sweep.
    lag_absolute : tuple of float
        Lag ratios L given as numbers (each ≥ 1).
    lag_multiples : tuple of float
        Lag ratios given as multiples of each plant's Lmax (2-1).
    integral : bool
        Also sweep the pure integral.
    plants : tuple of (ks_over_kc, inertia)
        Plants of the bound sweep; k̄c = :data:`COULOMB`, inertia J [ozf·in·s²].
    noise : tuple of bool
        Noise settings of the bound sweep.
    cap_s : float
        Longest simulated run of the bound sweep [s].
    hunting_ratios : tuple of float
        k̄s/k̄c of the hunting sweep (J = ``hunting_inertia``).
    hunting_crossover : float
        ωc of the hunting sweep [rad/s].
    hunting_multiples : tuple of float
        Lag ratios of the hunting sweep, as multiples of Lmax.
    hunting_offsets : tuple of float
        Initial errors e0 as multiples of k̄s/(J·ωc²).
    hunting_integral : bool
        Also run the pure integral at the set-point.
    hunting_inertia : float
        J of the hunting sweep [ozf·in·s²].
    warmup_ts, window_ts, window_tf : float
        Warm-up beyond the first breakaway in units of t_s; scoring window in units of t_s
        plus ``window_tf``·t_first (module docstring).
    probes : tuple of (omega_c, ks_over_kc, inertia)
        Extra low-crossover cells on plants where t_s is affordable (heavy J), with the
        ``lag_multiples`` lags and the integral only.
    probe_cap_s : float
        Longest simulated run of a probe [s].
    """

    mode: str
    crossovers: tuple[float, ...]
    lag_absolute: tuple[float, ...]
    lag_multiples: tuple[float, ...]
    integral: bool
    plants: tuple[tuple[float, float], ...]
    noise: tuple[bool, ...]
    cap_s: float
    hunting_ratios: tuple[float, ...]
    hunting_crossover: float
    hunting_multiples: tuple[float, ...]
    hunting_offsets: tuple[float, ...]
    hunting_integral: bool = True
    hunting_inertia: float = 0.5
    warmup_ts: float = 0.5
    window_ts: float = 1.5
    window_tf: float = 1.0
    probes: tuple[tuple[float, float, float], ...] = ()
    probe_cap_s: float = 3000.0

    def __post_init__(self) -> None:
        if self.mode not in _MODES:
            raise ValueError(f"SweepPlan.mode must be one of {_MODES}, got {self.mode!r}")
        _positive_tuple("crossovers", self.crossovers)
        _positive_tuple("lag_multiples", self.lag_multiples, allow_empty=True)
        _positive_tuple("hunting_multiples", self.hunting_multiples, allow_empty=True)
        _positive_tuple("hunting_offsets", self.hunting_offsets)
        if any(not (isinstance(x, (int, float)) and x >= 1) for x in self.lag_absolute):
            raise ValueError(f"SweepPlan.lag_absolute must hold numbers >= 1, got {self.lag_absolute!r}")
        if not self.plants:
            raise ValueError("SweepPlan.plants must not be empty")
        for ratio, inertia in self.plants:
            if not (ratio > 1 and math.isfinite(ratio)):
                raise ValueError(f"SweepPlan.plants ks_over_kc must be > 1, got {ratio!r}")
            if not inertia > 0:
                raise ValueError(f"SweepPlan.plants inertia must be > 0, got {inertia!r}")
        if any(not r > 1 for r in self.hunting_ratios):
            raise ValueError(f"SweepPlan.hunting_ratios must be > 1, got {self.hunting_ratios!r}")
        if not self.noise or any(not isinstance(n, bool) for n in self.noise):
            raise ValueError(f"SweepPlan.noise must be a non-empty tuple of bools, got {self.noise!r}")
        for name in ("cap_s", "probe_cap_s", "hunting_crossover", "hunting_inertia", "window_ts"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SweepPlan.{name} must be > 0, got {getattr(self, name)!r}")
        for omega, ratio, inertia in self.probes:
            if not (omega > 0 and ratio > 1 and inertia > 0):
                raise ValueError(f"SweepPlan.probes entries must be (omega_c > 0, ks_over_kc > 1, "
                                 f"inertia > 0), got {(omega, ratio, inertia)!r}")
        for name in ("warmup_ts", "window_tf"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"SweepPlan.{name} must be >= 0, got {getattr(self, name)!r}")


def _positive_tuple(name: str, values: tuple, *, allow_empty: bool = False) -> None:
    if not values and not allow_empty:
        raise ValueError(f"SweepPlan.{name} must not be empty")
    if any(not (isinstance(x, (int, float)) and x > 0 and math.isfinite(x)) for x in values):
        raise ValueError(f"SweepPlan.{name} must hold finite numbers > 0, got {values!r}")


def _table_2_1() -> PlantParams:
    return PlantParams()


def highest_stable_crossover(params: PlantParams | None = None, lag_ratio: float | None = None, *,
                             integral: bool = False, tol: float = 0.1) -> float:
    """Highest ωc [rad/s] whose discrete lead/lag loop is still stable (bisection).

    Stability of the linear loop depends on ωc, τs, τ3 and L only: the compensator gain scales
    with J and friction is not in the linear model.
    """
    from controllers.linear import design_linear

    params = params or _table_2_1()

    def stable(omega: float) -> bool:
        try:
            return design_linear(params, omega, lag_ratio, integral=integral).stable
        except ValueError:
            return False

    lo, hi = 1.0, math.pi / params.sample_period
    if not stable(lo):
        raise ValueError("no stable crossover above 1 rad/s")
    if stable(hi * 0.999):
        return hi * 0.999
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if stable(mid) else (lo, mid)
    return lo


def sweep_plan(mode: str = "full") -> SweepPlan:
    """The plan of ``full``, ``quick`` or ``tiny`` (resolves the design-dependent crossovers).

    The crossover grid runs from 20 rad/s (30 for quick) through the benchmark's feasible
    crossover (phase margin 45°, gain margin 6 dB), their geometric mean with the top, to 98 %
    of the highest crossover at which the 45° design is still stable (its gain margin there is
    under 2 dB). ``full`` adds 10 rad/s probes on two J = 1 plants.
    """
    from controllers.linear import highest_crossover

    if mode not in _MODES:
        raise ValueError(f"mode must be one of {_MODES}, got {mode!r}")
    base = _table_2_1()
    feasible = highest_crossover(base)
    top = round(0.98 * min(highest_stable_crossover(base, base.lag_ratio_limit),
                           highest_stable_crossover(base, integral=True)), 1)
    mid_high = round(math.sqrt(feasible * top), 1)
    if mode == "full":
        return SweepPlan(
            mode, crossovers=(20.0, 30.0, feasible, mid_high, top), lag_absolute=(1.0, 2.0, 4.0),
            lag_multiples=(1.0, 1.5, 3.0), integral=True,
            plants=((1.1, 0.5), (1.25, 0.5), (1.5, 0.5), (2.0, 0.5), (1.5, 0.25), (1.5, 1.0)),
            noise=(False, True), cap_s=1200.0,
            hunting_ratios=(1.1, 1.25, 1.5, 2.0), hunting_crossover=feasible,
            hunting_multiples=(0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0),
            hunting_offsets=(0.4, 0.6, 0.8, 1.0, 1.3, 1.7),
            probes=((10.0, 1.1, 1.0), (10.0, 2.0, 1.0)))
    if mode == "quick":
        return SweepPlan(
            mode, crossovers=(30.0, feasible, top), lag_absolute=(1.0,),
            lag_multiples=(1.0, 3.0), integral=True,
            plants=((1.1, 0.5), (1.5, 0.5), (2.0, 0.5), (1.5, 1.0)),
            noise=(False, True), cap_s=600.0,
            hunting_ratios=(1.1, 1.5, 2.0), hunting_crossover=feasible,
            hunting_multiples=(1.0, 1.5, 2.0, 3.0), hunting_offsets=(0.6, 0.8, 1.7),
            hunting_integral=False)
    return SweepPlan(
        mode, crossovers=(feasible,), lag_absolute=(), lag_multiples=(1.0,), integral=True,
        plants=((2.0, 1.0),), noise=(False, True), cap_s=300.0,
        hunting_ratios=(1.5,), hunting_crossover=feasible, hunting_multiples=(1.0, 3.0),
        hunting_offsets=(0.8,), hunting_integral=False)
