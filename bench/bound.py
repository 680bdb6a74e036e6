"""Empirical check of inequality (2-6) and of the lag limit (2-1) (SPEC §6).

Two sweeps of the lag-compensated linear design of :mod:`controllers.linear`:

* **Bound sweep (2-6).** A cell is one LTI design — crossover ωc, lag ratio L or the pure
  integral — on one plant (k̄s/k̄c with k̄c = 1.4 ozf·in, inertia J), noise on or off, tracking a
  ramp x4 = 30 µrad/s. Its measured steady peak error θ (the continuous-time peak |x1| of
  :func:`bench.runner.run_closed_loop` over a window after the transient) is compared with

      θb = (k̄s − k̄c)/(2·J·ωc²)   (2-6)

  at the design's own crossover. The verdict: does θ ≥ θb hold for every stable design?
* **Hunting sweep (2-1).** At a stationary set-point, noise off, L is swept around
  Lmax = 2k̄s/(k̄s − k̄c)  (2-1); the onset is the smallest tested L from which every larger tested
  L ends in a sustained stick-slip limit cycle (:func:`bench.hunting.detect_hunting`).

Ramp runs
    x4 is held at exactly 30 µrad/s (VAR(x4) = 0 and τ4 = 1e9 s, so it neither wanders nor
    decays). x5(0) = 0 in every run so that the plant's mean friction ratio is the labelled one;
    with noise on, w1, w2 and w5 act as in Table 2-1.

Durations
    Everything here is slow because the ramp is: while the shaft is stuck the error grows at
    v = 30 µrad/s only. Two time scales set a run:

    * t_s = k̄s/(J·ωc²·v), the time the ramp needs to cover the error at which the crossover
      stiffness J·ωc² balances stiction; the stick-slip periods of lag loops with L ≤ Lmax are
      1–3·t_s here (much shorter with larger L or the pure integral);
    * t_first = k̄s/(S·v), S = |C(1)| the static stiffness: a stuck lag (type-0) loop first
      breaks away when the wound-up lag torque reaches k̄s (0 for the pure integral).

    warm-up = t_first + 0.5·t_s + 5 s and window = 1.5·t_s + t_first + 10 s (:class:`SweepPlan`):
    the window starts after the first breakaway and its aftermath, and a stick-slip cycle of a
    lag loop (at most ~2·t_first long) normally fits in it. A run is never cut short: a cell that
    does not fit the sweep's cap is not run (status ``skipped``). A run whose window holds no
    breakaway and no steady sliding has a peak that is still rising; it is not scored (status
    ``unsteady``, its window peak kept in ``theta_window_rad``). ``n_slips_window`` and the peaks
    of the window's two halves let a reader check the rest. Because t_s ∝ 1/ωc², the lowest
    crossover swept on every plant is 20 rad/s (30 in ``--quick``); 10 rad/s is probed on two
    heavy (J = 1) plants only, where one stick-slip cycle still takes 10–30 simulated minutes.

Hunting runs
    A perfectly quiet set-point starting at x1 = 0 never moves. Each run instead starts from an
    initial error: the compensator sees y − e0 (a set-point step of e0 at t = 0), which — the
    plant being invariant to a shift of c — is the same as starting stuck at x1 = −e0 from a
    stationary set-point. Whether a limit cycle is reached depends on e0, so several
    e0 = f·k̄s/(J·ωc²) are tried; an L hunts when any of them ends hunting. The crossover is the
    benchmark's (:func:`controllers.linear.highest_crossover` for Table 2-1), fixed over L.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
import zlib
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated, Any, Callable, Iterable, Optional

import numpy as np
import pandas as pd
import typer

from bench.errors import UserError
from bench.hunting import detect_hunting, merged_trace
from bench.store import write_atomic
from controllers.base import Controller
from plant.drive import DriveCommand
from plant.params import PlantParams

__all__ = [
    "RAMP_VELOCITY", "COULOMB", "BOUND_COLUMNS", "HUNTING_COLUMNS", "SweepPlan", "BoundCell",
    "HuntingCell", "BoundResult", "sweep_plan", "highest_stable_crossover", "bound_cells",
    "hunting_cells", "run_bound_cell", "run_hunting_cell", "hunting_onsets", "bound_verdict",
    "check_bound", "check_bound_command",
]

#: Commanded ramp velocity of the bound sweep, x4 [rad/s] (SPEC §6).
RAMP_VELOCITY = 30e-6
#: Mean Coulomb friction k̄c of every swept plant [ozf·in] (Table 2-1); k̄s = ratio·k̄c.
COULOMB = 1.4

BOUND_COLUMNS = ("design", "omega_c", "lag_ratio", "ks_over_kc", "inertia", "noise", "theta_rad",
                 "theta_b_rad", "ratio", "stable", "status")
HUNTING_COLUMNS = ("ks_over_kc", "lmax", "onset_L", "onset_over_lmax", "highest_quiet_L",
                   "lowest_hunting_L", "omega_c", "inertia", "n_initial_errors", "tested_L",
                   "hunting_L", "integral_hunts")

_MODES = ("full", "quick", "tiny")
#: Fraction of window samples in motion above which a run counts as steadily sliding.
_SLIDING_FRACTION = 0.99


# --- the plan ------------------------------------------------------------------------------

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


# --- cells ---------------------------------------------------------------------------------

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
        lmax = 2 * ratio / (ratio - 1)                      # (2-1) with k̄s = ratio·k̄c
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
        lmax = 2 * ratio / (ratio - 1)
        specs = [(m * lmax, False) for m in plan.hunting_multiples]
        if plan.hunting_integral:
            specs.append((math.inf, True))
        for lag, integral in specs:
            for f in plan.hunting_offsets:
                key = (ratio, lag, integral, f)
                cells.append(HuntingCell(ratio, plan.hunting_inertia, plan.hunting_crossover, lag,
                                         integral, f, _hunting_duration(ratio), _seed("hunt", *key)))
    return cells


# --- one run -------------------------------------------------------------------------------

class _Observed(Controller):
    """An inner controller acting on y − e0 (a set-point step of e0 [rad] at t = 0).

    It reports no internals, so that a recorded run stores only the plant's samples and events
    (the per-sample internals log would otherwise cost as much as the control law).
    """

    def __init__(self, inner: Controller, step_rad: float = 0.0) -> None:
        self.inner = inner
        self.step_rad = float(step_rad)
        self.drive = inner.drive

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        self.inner.reset(params, rng)

    def step(self, y: float) -> DriveCommand:
        return self.inner.step(y - self.step_rad)

    def summary(self) -> dict[str, Any]:
        return self.inner.summary()


def _durations(cell: BoundCell, static_stiffness: float) -> tuple[float, float, str]:
    """(warm-up, duration, note) of a ramp run; duration 0: the run does not fit the cap.

    A run is never cut short to fit: a window shorter than one stick-slip cycle can miss the
    breakaway and under-state θ.
    """
    ks = COULOMB * cell.ks_over_kc
    t_s = cell.time_scale()
    t_first = ks / (static_stiffness * RAMP_VELOCITY) if math.isfinite(static_stiffness) else 0.0
    warmup = t_first + cell.warmup_ts * t_s + 5.0
    window = cell.window_ts * t_s + 10.0 + cell.window_tf * t_first
    if warmup + window > cell.cap_s:
        return warmup, 0.0, (f"needs {warmup + window:.0f} s (first breakaway after ~{t_first:.0f} s),"
                             f" more than the cap {cell.cap_s:.0f} s")
    return warmup, warmup + window, ""


def run_bound_cell(cell: BoundCell) -> dict[str, Any]:
    """Design, run and score one bound cell; a failing design or run is a row, not an error."""
    from bench.runner import run_closed_loop
    from controllers import roles
    from controllers.base import get_controller
    from controllers.linear import design_linear

    LinearController = get_controller(roles.CLASSICAL)   # the LTI family the bound is about

    params = cell.params()
    lmax = params.lag_ratio_limit
    theta_b = params.classical_bound(cell.omega_c)            # (2-6) at the design's crossover
    row: dict[str, Any] = {
        "design": f"{_lag_label(cell.lag_ratio, cell.integral, lmax)}, ωc={cell.omega_c:.4g}",
        "omega_c": cell.omega_c, "lag_ratio": cell.lag_ratio, "ks_over_kc": cell.ks_over_kc,
        "inertia": cell.inertia, "noise": cell.noise, "theta_rad": math.nan, "theta_b_rad": theta_b,
        "ratio": math.nan, "stable": False, "status": "", "lag_over_lmax": cell.lag_ratio / lmax,
        "lmax": lmax, "integral": cell.integral, "lead_stages": math.nan,
        "phase_margin_deg": math.nan, "gain_margin_db": math.nan, "static_stiffness": math.nan,
        "quasi_static_rad": math.nan, "noise_drive_rms": math.nan, "warmup_s": math.nan,
        "duration_s": math.nan, "n_slips_window": math.nan, "moving_fraction": math.nan,
        "theta_window_rad": math.nan, "peak_first_half_rad": math.nan,
        "peak_second_half_rad": math.nan, "seed": cell.seed,
        "runtime_s": 0.0, "message": "",
    }
    lag = None if cell.integral else cell.lag_ratio
    try:
        design = design_linear(params, cell.omega_c, lag, integral=cell.integral)
    except ValueError as exc:
        row.update(status="no_design", message=str(exc))
        return row
    stiffness = design.static_stiffness
    row.update(stable=bool(design.stable), lead_stages=design.lead_stages,
               phase_margin_deg=design.phase_margin_deg, gain_margin_db=design.gain_margin_db,
               static_stiffness=stiffness, noise_drive_rms=design.noise_drive_rms,
               quasi_static_rad=params.stiction / stiffness)  # (2-2): θe = ks/S.S.
    if not design.stable:
        row.update(status="unstable", message="closed-loop pole on or outside the unit circle")
        return row
    warmup, duration, note = _durations(cell, stiffness)
    row.update(warmup_s=warmup, duration_s=duration, message=note)
    if duration == 0.0:
        row["status"] = "skipped"
        return row
    controller = LinearController(crossover=cell.omega_c, lag_ratio=lag, integral=cell.integral)
    result = run_closed_loop(params, _Observed(controller), duration_s=duration, warmup_s=warmup,
                             seed=cell.seed, noise=cell.noise, record=True, x5_initial=0.0)
    row["runtime_s"] = result.runtime_s
    row["status"] = result.status
    if result.message:
        row["message"] = "; ".join(m for m in (note, result.message) if m)
    if result.status != "ok":
        return row
    peak = float(result.metrics["peak_error_rad"])
    t, x1, mode = merged_trace(result.samples, result.events)
    in_win = t >= warmup
    moving = mode[in_win] != 2
    starts = np.flatnonzero(np.diff(moving.astype(np.int8), prepend=np.int8(moving[0])) == 1)
    sliding = float(np.mean(result.samples["mode"][result.samples["t"] >= warmup] != 2))
    half = warmup + 0.5 * (duration - warmup)
    first, second = in_win & (t < half), t >= half
    row.update(theta_window_rad=peak, n_slips_window=int(starts.size), moving_fraction=sliding,
               peak_first_half_rad=float(np.max(np.abs(x1[first]), initial=0.0)),
               peak_second_half_rad=float(np.max(np.abs(x1[second]), initial=0.0)))
    if starts.size == 0 and sliding < _SLIDING_FRACTION:
        # stuck through the whole window: the error is still ramping towards a breakaway that
        # the window does not reach, so its peak is not the cycle's
        row.update(status="unsteady", message="no breakaway in the scoring window; "
                                              "theta_window_rad is a lower bound of θ")
        return row
    row.update(theta_rad=peak, ratio=peak / theta_b)
    return row


def run_hunting_cell(cell: HuntingCell) -> dict[str, Any]:
    """One stationary set-point run from initial error e0; hunting per :func:`detect_hunting`."""
    from bench.runner import run_closed_loop
    from controllers import roles
    from controllers.base import get_controller

    LinearController = get_controller(roles.CLASSICAL)
    params = cell.params()
    e0 = cell.offset_factor * params.stiction / (cell.inertia * cell.omega_c**2)
    lmax = params.lag_ratio_limit
    row: dict[str, Any] = {
        "ks_over_kc": cell.ks_over_kc, "lmax": lmax, "lag_ratio": cell.lag_ratio,
        "lag_over_lmax": cell.lag_ratio / lmax, "integral": cell.integral, "omega_c": cell.omega_c,
        "inertia": cell.inertia, "initial_error_rad": e0, "offset_factor": cell.offset_factor,
        "duration_s": cell.duration_s, "noise": False, "status": "", "hunting": False,
        "moved": False, "n_slips": 0, "period_s": math.nan, "amplitude_rad": math.nan,
        "reversal_fraction": math.nan, "reason": "", "runtime_s": 0.0,
    }
    inner = LinearController(crossover=cell.omega_c, lag_ratio=None if cell.integral else cell.lag_ratio,
                             integral=cell.integral)
    result = run_closed_loop(params, _Observed(inner, e0), duration_s=cell.duration_s,
                             seed=cell.seed, noise=False, record=True)
    row.update(status=result.status, runtime_s=result.runtime_s)
    if result.status != "ok":
        row["reason"] = result.message
        return row
    t, x1, mode = merged_trace(result.samples, result.events)
    verdict = detect_hunting(t, x1 - e0, mode, require_reversals=True)
    row.update(hunting=verdict.sustained, moved=bool(np.any(mode != 2)), n_slips=verdict.n_slips,
               period_s=verdict.period_s, amplitude_rad=verdict.amplitude_rad,
               reversal_fraction=verdict.reversal_fraction, reason=verdict.reason)
    return row


# --- aggregation ---------------------------------------------------------------------------

def hunting_onsets(runs: pd.DataFrame) -> pd.DataFrame:
    """One row per k̄s/k̄c: the onset L of hunting against Lmax (2-1).

    An L hunts when any initial error ends in a sustained limit cycle. The onset is the smallest
    tested finite L from which every larger tested finite L hunts (NaN when the largest does not).
    """
    rows = []
    for ratio, g in runs.groupby("ks_over_kc", sort=True):
        finite = g[~g["integral"]]
        by_lag = finite.groupby("lag_ratio")["hunting"].any().sort_index()
        lags = by_lag.index.to_numpy(dtype=float)
        hunts = by_lag.to_numpy(dtype=bool)
        onset = math.nan
        for i in range(len(lags) - 1, -1, -1):
            if not hunts[i]:
                break
            onset = float(lags[i])
        quiet = lags[(lags < onset) & ~hunts] if math.isfinite(onset) else lags[~hunts]
        lmax = float(g["lmax"].iloc[0])
        integral = g[g["integral"]]
        rows.append({
            "ks_over_kc": float(ratio), "lmax": lmax, "onset_L": onset,
            "onset_over_lmax": onset / lmax,
            "highest_quiet_L": float(quiet.max()) if quiet.size else math.nan,
            "lowest_hunting_L": float(lags[hunts].min()) if hunts.any() else math.nan,
            "omega_c": float(g["omega_c"].iloc[0]), "inertia": float(g["inertia"].iloc[0]),
            "n_initial_errors": int(g["offset_factor"].nunique()),
            "tested_L": ";".join(f"{x:.4g}" for x in lags),
            "hunting_L": ";".join(f"{x:.4g}" for x in lags[hunts]),
            "integral_hunts": bool(integral["hunting"].any()) if len(integral) else math.nan,
        })
    return pd.DataFrame(rows, columns=list(HUNTING_COLUMNS))


def bound_verdict(bound: pd.DataFrame) -> dict[str, Any]:
    """Does θ ≥ θb hold for every stable, completed run? The minimum ratio and its design."""
    scored = bound[bound["stable"] & (bound["status"] == "ok") & np.isfinite(bound["ratio"])]
    out: dict[str, Any] = {
        "n_cells": int(len(bound)), "n_stable": int(bound["stable"].sum()),
        "n_scored": int(len(scored)),
        "n_unstable": int((bound["status"] == "unstable").sum()),
        "n_no_design": int((bound["status"] == "no_design").sum()),
        "n_skipped": int((bound["status"] == "skipped").sum()),
        "n_unsteady": int((bound["status"] == "unsteady").sum()),
        "n_failed": int((bound["stable"] & ~bound["status"].isin(["ok", "skipped", "unsteady"])).sum()),
        "n_violations": int((scored["ratio"] < 1.0).sum()),
    }
    out["holds"] = bool(len(scored) > 0 and out["n_violations"] == 0)
    if len(scored):
        row = scored.loc[scored["ratio"].idxmin()]
        out["min_ratio"] = float(row["ratio"])
        out["min_ratio_design"] = {k: _plain(row[k]) for k in
                                   ("design", "omega_c", "lag_ratio", "ks_over_kc", "inertia",
                                    "noise", "theta_rad", "theta_b_rad", "n_slips_window")}
        per_noise = {}
        for noise, g in scored.groupby("noise"):
            r = g.loc[g["ratio"].idxmin()]
            per_noise["on" if noise else "off"] = {"min_ratio": float(r["ratio"]),
                                                   "design": str(r["design"]),
                                                   "ks_over_kc": float(r["ks_over_kc"]),
                                                   "inertia": float(r["inertia"])}
        out["min_ratio_by_noise"] = per_noise
        out["min_ratio_by_crossover"] = {f"{w:g}": float(g["ratio"].min())
                                         for w, g in scored.groupby("omega_c")}
        if "lag_over_lmax" in scored.columns:
            lag_key = scored["lag_over_lmax"].where(np.isfinite(scored["lag_over_lmax"]))
            out["min_ratio_by_lag_over_lmax"] = {
                ("integral" if math.isnan(k) else f"{k:.3g}"): float(g["ratio"].min())
                for k, g in scored.groupby(lag_key.round(3).fillna(math.nan), dropna=False)}
        out["n_fewer_than_2_slips"] = int((scored["n_slips_window"] < 2).sum())
    else:
        out["min_ratio"] = math.nan
    return out


def _plain(v: Any) -> Any:
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating, float)):
        return float(v)
    return v


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    obj = _plain(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None if math.isnan(obj) else ("inf" if obj > 0 else "-inf")
    return obj


# --- the check -----------------------------------------------------------------------------

@dataclass
class BoundResult:
    """What :func:`check_bound` measured and wrote."""

    plan: SweepPlan
    bound: pd.DataFrame
    hunting: pd.DataFrame
    hunting_runs: pd.DataFrame
    verdict: dict[str, Any]
    paths: dict[str, Path] = field(default_factory=dict)
    wall_s: float = 0.0


def _run_any(cell: BoundCell | HuntingCell) -> tuple[str, dict[str, Any]]:
    if isinstance(cell, BoundCell):
        return "bound", run_bound_cell(cell)
    return "hunting", run_hunting_cell(cell)


def _execute(cells: list, workers: int, progress: Callable[[int, int], None] | None
             ) -> tuple[list[dict], list[dict]]:
    """Run cells on a process pool, most expensive first (keeps both workers busy to the end)."""
    order = sorted(range(len(cells)), key=lambda i: -cells[i].cost())
    results: dict[int, tuple[str, dict]] = {}
    total = len(cells)
    if workers <= 1:
        for n, i in enumerate(order, 1):
            results[i] = _run_any(cells[i])
            if progress:
                progress(n, total)
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            pending = {pool.submit(_run_any, cells[i]): i for i in order}
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    results[pending.pop(fut)] = fut.result()
                    if progress:
                        progress(len(results), total)
    bound = [results[i][1] for i in range(total) if results[i][0] == "bound"]
    hunting = [results[i][1] for i in range(total) if results[i][0] == "hunting"]
    return bound, hunting


def _write_csv(path: Path, df: pd.DataFrame) -> None:
    write_atomic(path, df.to_csv(index=False))


def check_bound(quick: bool, out_dir: Path, workers: int | None = None,
                progress: Callable[[int, int], None] | None = None, *, tiny: bool = False
                ) -> BoundResult:
    """Run the (2-6) and (2-1) sweeps and write ``bound.csv``, ``hunting.csv``,
    ``hunting_runs.csv`` and ``bound_verdict.json`` to ``out_dir``.

    Parameters
    ----------
    quick : bool
        The reduced sweep of ``--quick`` (≤ 2 min on 2 cores).
    out_dir : Path
        Output directory (created).
    workers : int, optional
        Worker processes; default ``os.cpu_count()``.
    progress : callable, optional
        Called as ``progress(done, total)`` after each cell.
    tiny : bool
        A minimal sweep for the test suite only.
    """
    t0 = time.perf_counter()
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers!r}")
    workers = workers or os.cpu_count() or 1
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"--out {out_dir}: exists and is not a directory")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"--out {out_dir}: cannot create it ({exc.strerror or exc})") from None
    plan = sweep_plan("tiny" if tiny else "quick" if quick else "full")
    bcells, hcells = bound_cells(plan), hunting_cells(plan)
    bound_rows, hunting_rows = _execute([*bcells, *hcells], workers, progress)

    bound = pd.DataFrame(bound_rows)
    bound = bound[list(BOUND_COLUMNS) + [c for c in bound.columns if c not in BOUND_COLUMNS]]
    runs = pd.DataFrame(hunting_rows)
    onsets = hunting_onsets(runs)
    verdict = bound_verdict(bound)
    base = _table_2_1()
    verdict.update({
        "inequality": "theta >= theta_b = (ks - kc) / (2 J omega_c^2)  (2-6)",
        "classical_limit_rad": base.classical_bound(),         # ωb = π/τs, Table 2-1
        "hunting": [{k: _plain(r[k]) for k in ("ks_over_kc", "lmax", "onset_L", "onset_over_lmax",
                                               "highest_quiet_L")}
                    for _, r in onsets.iterrows()],
        "mode": plan.mode, "workers": workers, "wall_s": time.perf_counter() - t0,
        "plan": asdict(plan),
        "ramp_velocity_rad_s": RAMP_VELOCITY,
        "hunting_noise": False,
    })
    paths = {"bound": out_dir / "bound.csv", "hunting": out_dir / "hunting.csv",
             "hunting_runs": out_dir / "hunting_runs.csv", "verdict": out_dir / "bound_verdict.json"}
    _write_csv(paths["bound"], bound)
    _write_csv(paths["hunting"], onsets)
    _write_csv(paths["hunting_runs"], runs)
    write_atomic(paths["verdict"], json.dumps(_json_safe(verdict), indent=2) + "\n")
    return BoundResult(plan, bound, onsets, runs, verdict, paths, time.perf_counter() - t0)


# --- the command ---------------------------------------------------------------------------

def _g(v: Any, digits: int = 3) -> str:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return str(v)
    if math.isnan(x):
        return "—"
    if math.isinf(x):
        return "∞"
    return f"{x:.{digits}g}"


def _tables(result: BoundResult) -> Iterable[Any]:
    from rich import box
    from rich.table import Table

    b = result.bound
    scored = b[b["stable"] & (b["status"] == "ok")]
    t = Table(title="Inequality (2-6): θ/θb per plant and noise (stable designs, status ok)",
              title_justify="left", box=box.SIMPLE_HEAD)
    for name in ("ks/kc", "J", "noise", "runs", "stable", "scored", "min θ/θb", "at design", "θ µrad",
                 "θb µrad", "max θ/θb"):
        t.add_column(name, justify="left" if name == "at design" else "right")
    for (ratio, inertia, noise), g in b.groupby(["ks_over_kc", "inertia", "noise"], sort=True):
        s = scored[(scored["ks_over_kc"] == ratio) & (scored["inertia"] == inertia)
                   & (scored["noise"] == noise)]
        if len(s):
            r = s.loc[s["ratio"].idxmin()]
            best = [_g(r["ratio"]), str(r["design"]), _g(r["theta_rad"] * 1e6, 4),
                    _g(r["theta_b_rad"] * 1e6, 4), _g(s["ratio"].max())]
        else:
            best = ["—"] * 5
        t.add_row(_g(ratio), _g(inertia), "on" if noise else "off", str(len(g)),
                  str(int(g["stable"].sum())), str(len(s)), *best,
                  style="red" if len(s) and s["ratio"].min() < 1 else None)
    yield t
    h = Table(title="Lag limit (2-1): onset of hunting at a stationary set-point (noise off)",
              title_justify="left", box=box.SIMPLE_HEAD)
    for name in ("ks/kc", "Lmax", "onset L", "onset/Lmax", "highest quiet L", "ωc", "tested L",
                 "integral hunts"):
        h.add_column(name, justify="right")
    for _, r in result.hunting.iterrows():
        h.add_row(_g(r["ks_over_kc"]), _g(r["lmax"]), _g(r["onset_L"]), _g(r["onset_over_lmax"]),
                  _g(r["highest_quiet_L"]), _g(r["omega_c"]), str(r["tested_L"]),
                  _g(r["integral_hunts"]) if not isinstance(r["integral_hunts"], (bool, np.bool_))
                  else ("yes" if r["integral_hunts"] else "no"))
    yield h


def _verdict_lines(result: BoundResult) -> list[str]:
    v = result.verdict
    lines = [f"classical limit (2-6) at ωb = π/τs for Table 2-1: {v['classical_limit_rad'] * 1e6:.3g} µrad"]
    if v["n_scored"] == 0:
        lines.append("verdict: no stable design completed; nothing to judge")
        return lines
    d = v["min_ratio_design"]
    word = "HOLDS" if v["holds"] else "VIOLATED"
    lines.append(f"verdict: θ ≥ θb {word} for {v['n_scored']} scored runs "
                 f"({v['n_violations']} below the bound); minimum θ/θb = {v['min_ratio']:.3g} at "
                 f"{d['design']}, ks/kc = {d['ks_over_kc']:g}, J = {d['inertia']:g}, "
                 f"noise {'on' if d['noise'] else 'off'} (θ = {d['theta_rad'] * 1e6:.4g} µrad, "
                 f"θb = {d['theta_b_rad'] * 1e6:.4g} µrad)")
    lines.append(f"not scored: {v['n_unstable']} unstable, {v['n_no_design']} without a design, "
                 f"{v['n_skipped']} over the time cap, {v['n_unsteady']} without a breakaway in "
                 f"the window, {v['n_failed']} failed runs")
    lines.append(f"wall time {result.wall_s:.1f} s on {v['workers']} worker(s); files: "
                 + ", ".join(str(p) for p in result.paths.values()))
    return lines


def check_bound_command(
    quick: Annotated[bool, typer.Option("--quick", help="Reduced sweep (about 1–2 min on 2 cores).")] = False,
    out: Annotated[Path, typer.Option("--out", help="Output directory.")] = Path("results"),
    workers: Annotated[Optional[int], typer.Option("--workers", min=1,
                                                   help="Worker processes (default: all cores).")] = None,
    tiny: Annotated[bool, typer.Option("--tiny", hidden=True, help="Minimal sweep for tests.")] = False,
) -> None:
    """Check inequality (2-6) and the lag limit (2-1) empirically (SPEC §6).

    Sweeps lead/lag and pure-integral designs over crossover, lag ratio, k̄s/k̄c, inertia and
    noise on a 30 µrad/s ramp, and L around Lmax at a stationary set-point. Writes
    OUT/bound.csv, OUT/hunting.csv, OUT/hunting_runs.csv and OUT/bound_verdict.json.
    """
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn

    console = Console(highlight=False, width=None if sys.stdout.isatty() else 160)
    if workers is not None and workers < 1:
        raise typer.BadParameter(f"must be >= 1, got {workers}", param_hint="--workers")
    with Progress("[progress.description]{task.description}", BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=True) as bar:
        task = bar.add_task("check-bound", total=None)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        result = check_bound(quick, out, workers, progress, tiny=tiny)
    for table in _tables(result):
        console.print(table)
    for line in _verdict_lines(result):
        console.print(line)
