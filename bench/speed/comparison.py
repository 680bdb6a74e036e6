"""The whole comparison: record the sequences, compare on each, add the noisy weak error, and
return it JSON-ready."""

from __future__ import annotations

import dataclasses
import math
import os
import time
from typing import Any

import numpy as np

from bench.speed.closed_loop import closed_loop_em
from bench.speed.compare import _compare
from bench.speed.config import FULL, QUICK, TARGET_ERROR, Progress, SpeedConfig
from bench.speed.contestants import _warm_up_references
from bench.speed.sequence import _window, record_commands, synthetic_pulse_train
from bench.weak_coupled import coupled_weak_error
from bench.weak_error import weak_error_comparison
from bench.exact import EXACT_METHOD
from controllers import roles
from plant.params import PlantParams
from plant.state import Status

__all__ = ["speed_comparison"]


def _technology() -> dict[str, str]:
    return {
        EXACT_METHOD: ("numba-compiled: one compiled call per sample interval (plant.multimode.interval.interval_kernel) "
                      "over the closed forms (3-20)–(3-22); Python calls it once per interval"),
        "fixed_step": "numba-compiled Euler loop (plant.multimode.reference.fixed_step)",
        "fixed_step_python": "the same Euler kernel uncompiled (NUMBA_DISABLE_JIT=1), CPython",
        "solve_ivp": "SciPy DOP853 with a Python right-hand side and terminal events",
        "caveat": ("Like for like: the exact simulator and fixed-step Euler are both numba-compiled machine code "
                   "(the dissertation compared FORTRAN with FORTRAN); speedup_vs_fixed_step_at_1e-6 is that "
                   "ratio. solve_ivp is SciPy with a Python right-hand side. The exact simulator is still called "
                   "from Python once per sample interval, which its time includes."),
    }


def speed_comparison(quick: bool, *, seed: int = 0, config: SpeedConfig | None = None,
                     progress: Progress | None = None) -> dict[str, Any]:
    """Run the work-precision comparison (module docstring) and return it JSON-ready.

    Parameters
    ----------
    quick : bool
        ``QUICK`` (a 10 s steady window) instead of ``FULL`` (100 s, plus the linear sequence).
    seed : int
        Seed of the recording run (noise-free, so it only matters to controllers that draw
        random numbers) and of the noisy real-time-factor runs.
    config : SpeedConfig, optional
        Overrides the preset.
    progress : callable(str), optional
        Receives one line per step.

    Returns
    -------
    dict
        ``rows`` ({method, setting, error, wall_s, realtime_factor, ...}), the speed-ups at
        equal accuracy (``speedup_vs_fixed_step_at_1e-6`` and friends), how they were obtained,
        the reference cross-check, the sequence, the noisy real-time factors and the technology
        caveat. NaN and infinity become None.
    """
    cfg = config or (QUICK if quick else FULL)
    say = progress or (lambda _msg: None)
    wall0 = time.perf_counter()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    params = PlantParams()

    say("warming up the reference kernels")
    _warm_up_references(params)

    say(f"recording solnic closed loop, noise-free, {cfg.record_s:g} s")
    commands, status, message = record_commands(params, roles.IDENTIFICATION, cfg.record_s, seed=seed)
    n_record = int(round(cfg.record_s / params.sample_period))
    if status == Status.OK and len(commands) == n_record:
        source = f"solnic closed loop, noise-free, seed {seed}, thesis defaults, {cfg.record_s:g} s recorded"
    else:
        commands = synthetic_pulse_train(params, cfg.record_s)
        source = (f"synthetic stand-in (solnic run ended '{status}': {message}): 1.3 ms ±u_max pulses "
                  "of alternating sign every 60 ms, open loop")
    main = _compare(_window(params, commands, cfg.window_s, roles.IDENTIFICATION, source), cfg, seed, say, noisy=True)

    result: dict[str, Any] = {
        "rows": main.pop("rows"),
        "speedup_vs_fixed_step_at_1e-6": main.pop("speedup_vs_fixed_step_at_1e-6"),
        "speedup_vs_fixed_step_at_1e-6_lower_bound": main.pop("speedup_vs_fixed_step_at_1e-6_lower_bound"),
        "speedup_vs_solve_ivp_at_1e-6": main.pop("speedup_vs_solve_ivp_at_1e-6"),
        "speedup_vs_fixed_step_python_at_1e-6": main.pop("speedup_vs_fixed_step_python_at_1e-6"),
        "target_error": TARGET_ERROR,
        "error_metric": "max relative Δc error per pulse",
        "error_definition": ("error = error_dc = max over moving pulses of |Δc − Δc_ref| / |Δc_ref| "
                             "(dimensionless); "
                             "error_x1 = max over sample instants of |x1 − x1_ref| / max|x1_ref|; "
                             "the linear_hold sequence has no pulses and uses error_x1"),
        "reference": ("exact multimode simulator, noise-free, same command sequence; cross-checked against "
                      f"solve_ivp rtol={cfg.reference_rtol:g}"),
        **main,
        "technology": _technology(),
    }

    if cfg.weak is not None:
        say(f"noisy weak error: exact vs Euler–Maruyama, Δc of a {cfg.weak.dt_u * 1e3:g} ms pulse, "
            f"{cfg.weak.n_paths} paths each")
        weak = weak_error_comparison(params, cfg.weak, seed=seed)
        result["weak_error"] = weak
        ratio = weak["equal_error"]["mean"]
        result["noisy_speedup_at_equal_weak_error"] = ratio["cost_ratio"]   # EM wall / exact wall per path
        result["noisy_speedup_is_lower_bound"] = ratio["lower_bound"]

    if cfg.coupled is not None:
        say(f"noisy weak error resolved: Euler–Maruyama ladder on shared Brownian paths "
            f"({cfg.coupled.n_coupled} paths), anchored by {cfg.coupled.n_anchor} exact paths")
        result["weak_error_coupled"] = coupled_weak_error(params, cfg.coupled, seed=seed)

    if cfg.closed_loop is not None:
        cl = cfg.closed_loop
        say(f"closed loop with noise: {roles.IDENTIFICATION} peak error over {cl.n_seeds} seeds, "
            f"{cl.duration_s:g} s cells, exact vs Euler–Maruyama at {', '.join(f'{h:g}' for h in cl.steps)} s")
        result["closed_loop_em"] = closed_loop_em(cl, progress=say)

    if cfg.linear_sequence:
        say(f"recording linear closed loop, noise-free, {cfg.record_s:g} s")
        lin_commands, lstatus, lmessage = record_commands(params, roles.CLASSICAL, cfg.record_s, seed=seed)
        if lstatus == Status.OK:
            lin = _compare(_window(params, lin_commands, cfg.window_s, roles.CLASSICAL,
                                   f"linear closed loop, noise-free, seed {seed}, held levels"),
                           cfg, seed, say, noisy=False)
            result["linear_hold"] = lin
        else:
            result["linear_hold"] = {"status": lstatus, "message": lmessage}

    result["mode"] = "quick" if quick and config is None else ("full" if config is None else "custom")
    result["config"] = dataclasses.asdict(cfg)
    result["load_average_1min"] = load
    result["elapsed_s"] = time.perf_counter() - wall0
    return _jsonable(result)


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    return obj
