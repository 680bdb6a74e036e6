"""One run of a cell: design the linear loop, run it closed loop and score it (a failing design
or run is a row, not an error)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.bound.cells import BoundCell, HuntingCell, _lag_label
from bench.bound.plan import COULOMB, RAMP_VELOCITY
from bench.hunting import detect_hunting, merged_trace
from controllers.base import Controller
from plant.drive import DriveCommand
from plant.params import PlantParams

__all__ = ["run_bound_cell", "run_hunting_cell"]


#: Fraction of window samples in motion above which a run counts as steadily sliding.
_SLIDING_FRACTION = 0.99


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
