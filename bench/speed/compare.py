"""One sequence compared: every contestant run on it, the equal-accuracy speed-ups, the per-pulse
probe and the noisy real-time factors."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from bench.speed.accuracy import (_MOVING_DC_RAD, _errors, _fixed_step_at, _lower_bound, _ratio,
                                  _tolerance_at)
from bench.speed.config import _AT, TARGET_ERROR, Progress, SpeedConfig
from bench.speed.contestants import _best_time, _exact_child, _fixed_step_child, _in_fresh_process, _timed
from bench.speed.sequence import _Sequence
from bench.exact import EXACT_METHOD, advance, event_driven, fixed_step, schedule_from_commands
from plant.state import X1, X2, X3, X4, X5, SimOptions, Status


def _row(method: str, setting: str, errors: dict[str, Any], wall: float, duration: float,
         **extra: Any) -> dict[str, Any]:
    return {"method": method, "setting": setting, **errors, "wall_s": wall,
            "realtime_factor": duration / wall if wall > 0 else math.inf, **extra}


def _compare(seq: _Sequence, cfg: SpeedConfig, seed: int, say: Progress, *, noisy: bool) -> dict[str, Any]:
    p, T = seq.params, seq.duration
    say(f"[{seq.name}] exact simulator in a fresh process (x{cfg.exact_processes})")
    children = [_in_fresh_process(_exact_child, p, seq.state0, seq.commands, seed, noisy and i == 0)
                for i in range(cfg.exact_processes)]
    exact = children[0]
    if exact["status"] != Status.OK:
        raise RuntimeError(f"exact replay ended with status {exact['status']}")
    ref_x1 = exact["x1"]
    exact_wall = min(c["cold_s"] for c in children)

    say(f"[{seq.name}] reference cross-check: solve_ivp rtol={cfg.reference_rtol:g}")
    t0 = time.perf_counter()
    xref = event_driven(p, seq.schedule, rtol=cfg.reference_rtol, atol=1e-22, x0=seq.x0,
                        sample_times=seq.sample_times)["x1_at"]
    xref_wall = time.perf_counter() - t0
    agreement = _errors(xref, ref_x1, seq)

    rows = [_row(EXACT_METHOD, "exact (closed forms)", agreement, exact_wall, T,
                 wall_warm_cache_s=min(c["warm_s"] for c in children),
                 wall_with_metrics_s=min(c["with_metrics_s"] for c in children),
                 error_basis=f"disagreement with solve_ivp rtol={cfg.reference_rtol:g}")]

    fixed_rows = []
    for h in cfg.fixed_steps:
        say(f"[{seq.name}] fixed-step Euler h={h:g} s")
        wall, res, n = _best_time(lambda: _timed(lambda: fixed_step(p, seq.schedule, h, x0=seq.x0,
                                                                     sample_every=p.sample_period)))
        fixed_rows.append(_row("fixed_step", f"h={h:g} s", _errors(res.x1_samples[:, 0], ref_x1, seq), wall, T,
                               step_s=h, n_steps=res.n_steps, repeats=n, technology="numba"))
    rows += fixed_rows

    ivp_rows = []
    for tol in cfg.rtols:
        say(f"[{seq.name}] solve_ivp DOP853 rtol={tol:g}")
        wall, out = _timed(lambda: event_driven(p, seq.schedule, rtol=tol, x0=seq.x0, sample_times=seq.sample_times))
        ivp_rows.append(_row("solve_ivp", f"rtol={tol:g}", _errors(out["x1_at"], ref_x1, seq), wall, T,
                             rtol=tol, n_segments=int(out["n_segments"])))
    rows += ivp_rows
    rows.append(_row("solve_ivp_reference", f"rtol={cfg.reference_rtol:g}", agreement, xref_wall, T,
                     rtol=cfg.reference_rtol, error_basis="disagreement with the exact simulator"))

    python_rows = []
    for h in cfg.python_fixed_steps:
        say(f"[{seq.name}] fixed-step Euler h={h:g} s, uncompiled (NUMBA_DISABLE_JIT=1)")
        res = _in_fresh_process(_fixed_step_child, p, seq.schedule, h, seq.x0, env={"NUMBA_DISABLE_JIT": "1"})
        python_rows.append(_row("fixed_step_python", f"h={h:g} s", _errors(res["x1"], ref_x1, seq), res["wall_s"], T,
                                step_s=h, n_steps=res["n_steps"], repeats=1, technology="CPython (numba off)",
                                jit_disabled=res["jit_disabled"]))
    rows += python_rows

    fixed_need = _fixed_step_at(fixed_rows, TARGET_ERROR)
    ivp_need = _tolerance_at(ivp_rows, TARGET_ERROR)
    probe_out = _probe(seq, cfg, say) if seq.n_pulses and cfg.probe_pulses and cfg.probe_steps else None
    lower = _lower_bound(fixed_rows, probe_out, exact_wall, T)
    by_metric = {}
    for metric in ("error_x1", "error_dc"):
        f = _fixed_step_at([{**r, "error": r[metric]} for r in fixed_rows], TARGET_ERROR)
        i = _tolerance_at([{**r, "error": r[metric]} for r in ivp_rows], TARGET_ERROR)
        by_metric[metric] = {"fixed_step": _ratio(f["wall_s"], exact_wall), "fixed_step_how": f["how"],
                             "solve_ivp": _ratio(i["wall_s"], exact_wall), "solve_ivp_how": i["how"]}
    python_need: dict[str, Any] = {"wall_s": None, "how": "not run"}
    if python_rows and fixed_need.get("step_s"):
        per_step = python_rows[-1]["wall_s"] / python_rows[-1]["n_steps"]
        steps = T / fixed_need["step_s"]
        python_need = {"wall_s": per_step * steps, "step_s": fixed_need["step_s"], "per_step_s": per_step,
                       "how": f"numba Euler's error curve ({fixed_need['how']}) x the uncompiled kernel's "
                              "measured cost per step"}
    out = {
        "rows": rows,
        "exact_wall_s": exact_wall,
        f"speedup_vs_fixed_step_at_{_AT}": _ratio(fixed_need["wall_s"], exact_wall),
        f"speedup_vs_fixed_step_at_{_AT}_lower_bound": lower["speedup"],
        f"speedup_vs_solve_ivp_at_{_AT}": _ratio(ivp_need["wall_s"], exact_wall),
        f"speedup_vs_fixed_step_python_at_{_AT}": _ratio(python_need["wall_s"], exact_wall),
        "equal_accuracy": {"fixed_step": fixed_need, "solve_ivp": ivp_need, "fixed_step_python": python_need,
                           "fixed_step_lower_bound": lower},
        "speedup_at_1e-6_by_metric": by_metric,
        "reference_disagreement": {"solve_ivp_rtol": cfg.reference_rtol, **agreement},
        "fixed_step_probe": probe_out,
        "sequence": _describe(seq, ref_x1),
    }
    if noisy:
        out["noisy"] = _noisy(seq, cfg, exact, seed, say)
    return out


def _probe(seq: _Sequence, cfg: SpeedConfig, say: Progress) -> dict[str, Any]:
    """Euler below the finest full step, pulse by pulse (module docstring, item 4)."""
    p, tau = seq.params, seq.params.sample_period
    states = [seq.state0]
    opts = SimOptions(noise=False)
    for command in seq.commands:
        step = advance(states[-1], command, p, None, opts)
        state, status, message = step.state, step.status, step.message
        if status != Status.OK:
            raise RuntimeError(f"exact replay for the probe failed: {status}: {message}")
        states.append(state)
    r = seq.command_motion()
    candidates = []
    for a, b in zip(seq.pulse_bounds[:-1], seq.pulse_bounds[1:]):
        start = states[a]
        if not (start.mode == 2 and not start.flyback and start.x[X3] == 0.0):
            continue                            # Euler's start state has no flyback flag
        end = next((e for e in range(a + 1, b + 1) if states[e].mode == 2 and not states[e].flyback), None)
        if end is None:
            continue
        dc_ref = (states[end].x[X1] + r[end]) - (start.x[X1] + r[a])
        if abs(dc_ref) > _MOVING_DC_RAD:
            candidates.append((a, end, dc_ref))
    if not candidates:
        return {"rows": [], "n_pulses": 0}
    pick = np.unique(np.linspace(0, len(candidates) - 1, min(cfg.probe_pulses, len(candidates))).round().astype(int))
    chosen = [candidates[i] for i in pick]
    rows = []
    for h in cfg.probe_steps:
        say(f"[probe] fixed-step Euler h={h:g} s on {len(chosen)} pulses")
        rel, steps, wall = [], 0, 0.0
        for a, end, dc_ref in chosen:
            st = states[a]
            sched = schedule_from_commands(seq.commands[a:end], tau)
            x0 = np.array([st.x[X1], st.x[X2], st.x[X3], st.x[X4], st.x[X5], float(st.mode)])
            w, res = _timed(lambda: fixed_step(p, sched, h, x0=x0))
            dc = (res.final[0, 0] + r[end]) - (st.x[X1] + r[a])
            rel.append(abs(dc - dc_ref) / abs(dc_ref))
            steps, wall = steps + res.n_steps, wall + w
        rows.append({"step_s": h, "error_dc": max(rel), "error_dc_median": float(np.median(rel)),
                     "n_steps": steps, "wall_s": wall})
    return {"rows": rows, "n_pulses": len(chosen), "pulse_starts_s": [seq.state0.t + a * tau for a, _, _ in chosen]}


def _noisy(seq: _Sequence, cfg: SpeedConfig, exact: dict[str, Any], seed: int, say: Progress) -> dict[str, Any]:
    """Real-time factors with the noise on (no error metric: the paths' noise differs)."""
    p, T = seq.params, seq.duration
    rows = [{"method": EXACT_METHOD, "setting": "exact, noisy (bridge zero locator)", "wall_s": exact["noisy_s"],
             "realtime_factor": T / exact["noisy_s"], "status": exact["noisy_status"],
             "n_events": exact["noisy_events"], "n_substeps": exact["noisy_substeps"]}]
    for h in cfg.noisy_fixed_steps:
        say(f"[{seq.name}] noisy Euler–Maruyama h={h:g} s")
        wall, _, n = _best_time(lambda: _timed(lambda: fixed_step(
            p, seq.schedule, h, x0=seq.x0, sample_every=p.sample_period,
            rng=np.random.default_rng(np.random.SeedSequence(seed)))))
        rows.append({"method": "fixed_step", "setting": f"Euler–Maruyama h={h:g} s", "wall_s": wall,
                     "realtime_factor": T / wall, "repeats": n})
    return {"rows": rows, "note": "the same command sequence replayed open loop with process noise on; "
                                  "no strong-error comparison (each method draws its own noise)"}


def _describe(seq: _Sequence, ref_x1: np.ndarray) -> dict[str, Any]:
    """The window; ``dc_ref_rad`` is [min, median, max] |Δc_ref| of the moving pulses."""
    widths = []
    for b in seq.pulse_bounds[:-1]:
        segs = seq.commands[b].segments
        for (o, lvl), nxt in zip(segs, list(segs[1:]) + [(seq.params.sample_period, 0.0)]):
            if lvl != 0.0:
                widths.append(nxt[0] - o)
    out = {"name": seq.name, "source": seq.source, "t_start_s": seq.recorded_at_s, "duration_s": seq.duration,
           "n_intervals": len(seq.commands), "n_pulses": seq.n_pulses,
           "pulse_width_s": [min(widths), max(widths)] if widths else None,
           "drive": seq.commands[0].drive.value, "x1_ref_peak_rad": float(np.max(np.abs(ref_x1))),
           "headline_error": "error_dc" if seq.n_pulses else "error_x1"}
    if seq.n_pulses:
        b = seq.pulse_bounds
        c_ref = ref_x1 + seq.command_motion()
        dc = np.abs(c_ref[b[1:]] - c_ref[b[:-1]])
        moving = dc > _MOVING_DC_RAD
        out.update(n_moving_pulses=int(moving.sum()),
                   dc_ref_rad=[float(dc[moving].min()), float(np.median(dc[moving])), float(dc[moving].max())]
                   if moving.any() else None)
    return out
