"""The ``lugre`` family with an Ornstein–Uhlenbeck disturbance torque d on the load (SPEC §11).

ḋ = −d/τd + √(2/τd)·σd·w_d adds to the load's torque balance, J·v̇ = x3 + d − F (LuGre has no
stuck mode, so there is no separate breakaway test: the bristles yield when x3 + d exceeds
what they hold). The state carries d as a ninth entry, x = [x1, x2, x3, x4, x5, u, θ, z, d].

Scheme: the family's noisy Lie–Trotter splitting (plant.lugre.interval) on its sub-step grid
of ``substep``, with d one more noise: over each sub-step the deterministic flow (the family's
Dormand–Prince segment) holds d at its start value — x3 and u enter the law only as x3 + d, so
the segment runs with both shifted by d — then the noise kicks of the family, then d's exact
OU transition d⁺ = ρ·d + σd·√(1 − ρ²)·ζ, ρ = e^(−h/τd). Holding d is the left-point rule for
∫d: mean local error O(h²), variance O(h³), so the splitting stays weak order 1. Noise off,
d(t) = d(0)·e^(−t/τd): with d(0) = 0 the interval is the compiled step (d stays 0); otherwise
each sub-step holds d at its midpoint value (second order in ``substep``).

With ``disturbance_torque_std`` = 0 the family never enters this module (bit for bit).
"""

from __future__ import annotations

import math

import numpy as np

from plant.drive import DriveCommand, DriveType
from plant.lugre import integrate
from plant.lugre import interval as compiled
from plant.lugre.integrate import scratch, segment
from plant.lugre.law import L_VS
from plant.lugre.interval import VELOCITY_THRESHOLD, _noise_kick
from plant.randomness import NoiseStream
from plant.state import EVENT_FIELDS, EventKind, IntervalResult, PlantState, SimOptions, Status
from plant.stribeck.disturbed import _apply_level, _Noise, _ou, _Run

__all__ = ["N_X", "D", "advance", "initial_state"]

N_X = 9          # x1, x2, x3, x4, x5, u, θ, z, d
D = 8
A1, A2, A3, A4, A5, AKC, AU, ATH, AZ = range(9)
_MAX_STEPS = compiled._MAX_STEPS


def initial_state(params, x5: float) -> PlantState:
    x = np.zeros(N_X)
    x[3] = params.command_velocity_initial
    x[4] = x5
    x.flags.writeable = False
    return PlantState(0.0, x, 2, False)


def _mode_of(v):
    return 3 if v > VELOCITY_THRESHOLD else (1 if v < -VELOCITY_THRESHOLD else 2)


def _mode_event(run, old, new):
    run.mode = new
    if old == 2:
        run.nbrk += 1
        return EventKind.BREAKAWAY
    if new == 2:
        run.nstk += 1
        return EventKind.STICK
    run.nbrk += 1
    return EventKind.REVERSAL


def advance(state: PlantState, command: DriveCommand, params, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """One interval of the disturbed LuGre plant; the contract of plant.lugre.interval.advance
    (status ``error`` where g(v) = 0, :func:`plant.lugre.interval.undefined_message`)."""
    try:
        return _advance(state, command, params, noise, options, duration=duration, record=record)
    except ZeroDivisionError:
        return IntervalResult(state, Status.ERROR, compiled.undefined_message(state, params), abs(float(state.x[0])),
                              0.0, 0.0, 0.0, 0.0, 0, 0, 0, 0, None)


def _advance(state: PlantState, command: DriveCommand, params, noise: NoiseStream | None,
             options: SimOptions = SimOptions(), *, duration: float | None = None,
             record: bool = False) -> IntervalResult:
    h = params.sample_period if duration is None else float(duration)
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"duration must be a finite positive number of seconds, got {duration!r}")
    x = np.asarray(state.x, dtype=float)
    if x.shape != (N_X,):
        raise ValueError(f"a disturbed lugre state has {N_X} entries (x1..x5, u, θ, z, d), got shape {x.shape}")
    noisy = bool(options.noise and noise is not None)
    if not noisy and x[D] == 0.0:                 # d stays 0: the compiled step
        r = compiled.advance(state._replace(x=x[:D]), command, params, None, options, duration=duration,
                             record=record)
        xo = np.append(r.state.x, 0.0)
        xo.flags.writeable = False
        return r._replace(state=r.state._replace(x=xo))
    offsets, levels = command.arrays()
    if offsets[-1] >= h:
        raise ValueError(f"DriveCommand segment at offset {offsets[-1]!r} s lies beyond the interval of {h!r} s")
    bridge = command.drive is DriveType.BRIDGE
    nz = _Noise(noise) if noisy else None
    p = params
    X = np.array([x[0], x[1], x[2], x[3], x[4], p.coulomb, x[5], x[6], x[7]])
    d = float(x[D])
    run = _Run(p, options, state.t, state.mode, state.flyback, record)
    run.peak = abs(X[A1])
    L, tol = run.L, integrate.TOLERANCES
    W, K = scratch()
    work = np.zeros(7)
    tau3, taud = p.motor_time_constant, p.disturbance_torque_tau
    t0 = state.t
    stop = False
    for seg in range(len(offsets)):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < len(offsets) else h)
        if not _apply_level(X, run, float(levels[seg]), bridge):
            raise ValueError(f"bridge drive levels must be 0 or ±u_max ({p.u_max}), got {command.segments!r}")
        stop = seg > 0 and run.event(X, EventKind.LEVEL)
        while not stop and run.t < t_seg_end:
            h_end = t_seg_end - run.t
            h_fb = tau3 * math.log1p(abs(X[A3]) / p.u_max) if run.fb else math.inf
            hs = min(h_end, h_fb, options.substep)
            x3, u = X[A3], X[AU]
            shift = d if noisy else d * math.exp(-0.5 * hs / taud)
            X[A3], X[AU] = x3 + shift, u + shift
            old = run.mode
            advanced, new, peak, steps = segment(X, hs, L, run.peak, run.hbox, VELOCITY_THRESHOLD, old, 0.0, tol, W, K,
                                                 math.inf, math.inf)
            X[AU] = u
            X[A3] = u + (x3 - u) * math.exp(-advanced / tau3)
            run.peak = peak
            run.nsub += steps
            run.torque(x3, u, advanced, bridge)
            if run.nsub > _MAX_STEPS:
                run.status = Status.CHATTER
                break
            full = advanced >= hs
            run.t = t_seg_end if (full and hs == h_end) else run.t + advanced
            if full and hs == h_fb and hs != h_end:
                X[A3] = X[AU] = 0.0
                run.fb = False
                if run.event(X, EventKind.FLYBACK_END):
                    stop = True
                    break
            if noisy and full:
                z, cur = nz.ready()
                r = X[A2] / L[L_VS]
                quad = -math.expm1(-r * r) * advanced   # w2 through s(v)² at the flow's end (held)
                _noise_kick(X, advanced, quad, run.prm, L, z, cur, work)
                new = _mode_of(X[A2])
            d = _ou(d, advanced, p, nz)
            if new != old and run.event(X, _mode_event(run, old, new)):
                stop = True
                break
            if not (abs(X[A1]) <= options.diverge_error):
                run.status = Status.DIVERGED
                stop = True
                break
        if stop or run.status is not Status.OK:
            break
    if nz is not None:
        nz.done()
    if run.status is Status.OK:
        run.t = t0 + h
    xo = np.array([X[A1], X[A2], X[A3], X[A4], X[A5], X[AU], X[ATH], X[AZ], d])
    xo.flags.writeable = False
    new_state = PlantState(run.t, xo, int(run.mode), bool(run.fb))
    status, message = run.status, ""
    if status is Status.CHATTER:
        message = f"integrator or event budget exhausted in one interval at t={run.t:.6f} s"
    elif status is Status.DIVERGED:
        message = f"|x1| = {abs(X[A1]):.3g} rad at t={run.t:.6f} s"
    events = None
    if record:
        arr = np.array(run.events, dtype=float).reshape(-1, len(EVENT_FIELDS))
        events = {name: arr[:, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new_state, status, message, run.peak, run.iabs, run.isq, run.chg, run.dur, run.nev,
                          run.nbrk, run.nstk, run.nsub, events)
