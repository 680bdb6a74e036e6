"""One sample interval of the ``stribeck`` family, compiled whole: the pure step.

The event loop is Acker's (plant.multimode.interval): command level changes, the flyback end
(x3 = 0, closed form), breakaway from rest (|x3| = ks, closed form: x3 is deterministic while
stuck, and θ and x5 are frozen, so ks(θ, x5) is a constant), and velocity zero in motion with
SPEC §2's switching table (reflect, reverse, stick). Stuck, the state moves exactly
(plant.multimode.stuck); sliding, by plant.stribeck.moving (Dormand–Prince 5(4) with error
control noise-free; stochastic Heun sub-steps with bridge-located zeros with noise). The
current integrals are exact per segment (x3 is exponential: plant.multimode.segments).

State vector: the six shared entries and θ = c, the load angle [rad] (index 6), which the
position-dependent friction reads.
"""

from __future__ import annotations

import math
import threading

import numpy as np
from numba import njit

from plant.drive import DriveCommand, DriveType
from plant.multimode.segments import torque_crossing_time, torque_integrals
from plant.multimode.stuck import stuck_propagate
from plant.randomness import NoiseExhausted, NoiseStream
from plant.state import EVENT_FIELDS, X1, EventKind, IntervalResult, PlantState, SimOptions, Status
from plant.stribeck.law import effective_levels
from plant.stribeck.moving import noisy_segment, rk_segment

__all__ = ["advance", "N_STATE"]

N_STATE = 7
A1, A2, A3, A4, A5, AKC, AU, ATH = range(8)
_T, _MODE, _FB, _COUNT, _PEAK, _IABS, _ISQ, _CHG, _DUR, _NEV, _NBRK, _NSTK, _NSUB, _STATUS, _NREC, _HRK = range(16)
_SHEET = 16
_O_NOISE, _O_NEWTON, _O_SUB, _O_RSUB, _O_TOL, _O_MAXEV, _O_DIVERGE = range(7)
_OK, _CHATTER, _DIVERGED, _BAD_LEVEL = 0, 1, 2, 3
_STATUS_OF = {_OK: Status.OK, _CHATTER: Status.CHATTER, _DIVERGED: Status.DIVERGED}
_LEVEL, _FLYBACK_END, _BREAKAWAY, _REGIME_END, _STICK, _REVERSAL, _REFLECTION = (int(k) for k in EventKind)


class _RecordFull(Exception):
    """The event buffer is full (the caller enlarges it and runs the interval again)."""


@njit(cache=True)
def _tick(S, n, o):
    S[_COUNT] += n
    if S[_COUNT] > o[_O_MAXEV]:
        S[_STATUS] = _CHATTER
        return True
    return False


@njit(cache=True)
def _event(S, X, kind, o, ev):
    S[_NEV] += 1.0
    n = int(S[_NREC])
    if ev.shape[0] > 0:
        if n >= ev.shape[0]:
            raise _RecordFull()
        ev[n, 0] = S[_T]
        ev[n, 1] = X[A1]
        ev[n, 2] = X[A2]
        ev[n, 3] = X[A3]
        ev[n, 4] = S[_MODE]
        ev[n, 5] = X[AU]
        ev[n, 6] = kind
        S[_NREC] = n + 1
    return _tick(S, 1.0, o)


@njit(cache=True)
def _torque_metrics(S, x3, u, h, bridge, umax, tau3):
    if h <= 0.0:
        return
    integral, absolute, square = torque_integrals(x3, u, h, tau3)
    S[_IABS] += absolute
    S[_ISQ] += square
    S[_CHG] += (u / umax) * integral if bridge else absolute
    S[_DUR] += h


@njit(cache=True)
def _apply_level(X, S, level, bridge, umax):
    if not bridge:
        X[AU] = min(max(level, -umax), umax)
        S[_FB] = 0.0
        return True
    if level != 0.0 and abs(abs(level) - umax) > 1e-9 * umax:
        return False
    if level > 0:
        X[AU], S[_FB] = umax, 0.0
    elif level < 0:
        X[AU], S[_FB] = -umax, 0.0
    elif X[A3] != 0.0:
        X[AU], S[_FB] = -math.copysign(umax, X[A3]), 1.0   # the diodes conduct
    else:
        X[AU], S[_FB] = 0.0, 0.0
    return True


@njit(cache=True)
def _flyback_time(X, S, umax, tau3):
    if S[_FB] == 0.0:
        return math.inf
    return tau3 * math.log1p(abs(X[A3]) / umax)


@njit(cache=True)
def _stuck(X, S, t_end, bridge, p, L, o, z, cursor, ev):
    x3, u = X[A3], X[AU]
    kc, ks = effective_levels(X[ATH], X[A5], L)
    h_end = t_end - S[_T]
    h_fb = _flyback_time(X, S, p.u_max, p.tau3)
    if -ks < u < ks and -ks <= x3 <= ks:
        h_up = h_dn = math.inf
    else:
        h_up = torque_crossing_time(x3, u, ks, p.tau3)
        h_dn = torque_crossing_time(x3, u, -ks, p.tau3)
    if x3 > ks or (x3 == ks and u > ks):
        h_up = 0.0
    elif x3 < -ks or (x3 == -ks and u < -ks):
        h_dn = 0.0
    h = min(h_end, h_fb, h_up, h_dn)
    x1_before = abs(X[A1])
    _torque_metrics(S, x3, u, h, bridge, p.u_max, p.tau3)
    stuck_propagate(X, h, p, o[_O_NOISE] != 0.0, z, cursor)
    S[_PEAK] = max(S[_PEAK], x1_before, abs(X[A1]))      # x1 is monotone while stuck
    if h == h_end:
        S[_T] = t_end
        return False
    S[_T] += h
    if h == h_fb:
        X[A3] = 0.0
        X[AU] = 0.0
        S[_FB] = 0.0
        return _event(S, X, _FLYBACK_END, o, ev)
    X[A3] = ks if h == h_up else -ks
    X[A2] = 0.0
    S[_MODE] = 3.0 if h == h_up else 1.0
    S[_NBRK] += 1.0
    return _event(S, X, _BREAKAWAY, o, ev)


@njit(cache=True)
def _velocity_zero(X, S, L):
    """x2 reached 0 sliding: reflect, reverse or stick (SPEC §2's table); the event kind."""
    mode = int(S[_MODE])
    s = 1.0 if mode == 3 else -1.0
    x3 = X[A3]
    kc, ks = effective_levels(X[ATH], X[A5], L)
    X[A2] = 0.0
    if s * x3 > ks:
        return _REFLECTION
    if -s * x3 > ks:
        S[_MODE] = 1.0 if mode == 3 else 3.0
        S[_NBRK] += 1.0
        return _REVERSAL
    S[_MODE] = 2.0
    S[_NSTK] += 1.0
    return _STICK


@njit(cache=True)
def _moving(X, S, t_end, bridge, p, L, o, z, cursor, ev, hbox):
    s = 1.0 if S[_MODE] == 3.0 else -1.0
    x3, u = X[A3], X[AU]
    h_end = t_end - S[_T]
    h = min(h_end, _flyback_time(X, S, p.u_max, p.tau3))
    if o[_O_NOISE] != 0.0:
        budget = max(o[_O_MAXEV] - S[_COUNT], 1.0)
        advanced, stopped, peak, n = noisy_segment(X, s, h, p, L, o[_O_SUB], o[_O_RSUB], o[_O_TOL], z, cursor,
                                                   S[_PEAK], budget)
    else:
        advanced, stopped, peak, n = rk_segment(X, s, h, L, S[_PEAK], hbox)
    S[_PEAK] = peak
    S[_NSUB] += n
    _torque_metrics(S, x3, u, advanced, bridge, p.u_max, p.tau3)
    if _tick(S, n, o):
        return True
    if stopped:
        S[_T] += advanced
        return _event(S, X, _velocity_zero(X, S, L), o, ev)
    if advanced < h:                        # the sub-step budget ran out
        S[_T] += advanced
        S[_STATUS] = _CHATTER
        return True
    if h == h_end:
        S[_T] = t_end
        return False
    S[_T] += h
    X[A3] = 0.0                              # flyback end: x3 = 0 exactly
    X[AU] = 0.0
    S[_FB] = 0.0
    return _event(S, X, _FLYBACK_END, o, ev)


@njit(cache=True)
def interval_kernel(x, mode, flyback, t0, duration, offsets, levels, bridge, prm, L, o, z, zpos, ev, out):
    """Advance over [t0, t0 + duration) under (offsets, levels); out = [state (7), sheet]."""
    p = prm[0]
    S = out[N_STATE:]
    cursor = np.empty(1, dtype=np.int64)
    cursor[0] = zpos
    X = np.empty(8)
    X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU], X[ATH] = x[0], x[1], x[2], x[3], x[4], p.coulomb, x[5], x[6]
    hbox = np.zeros(1)
    for i in range(_SHEET):
        S[i] = 0.0
    S[_T], S[_MODE], S[_FB] = t0, mode, 1.0 if flyback else 0.0
    S[_PEAK] = abs(X[A1])
    k = offsets.shape[0]
    stop = False
    for seg in range(k):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < k else duration)
        if not _apply_level(X, S, levels[seg], bridge, p.u_max):
            S[_STATUS] = _BAD_LEVEL
            break
        if seg > 0 and _event(S, X, _LEVEL, o, ev):
            break
        while S[_T] < t_seg_end:
            if S[_MODE] == 2.0:
                stop = _stuck(X, S, t_seg_end, bridge, p, L, o, z, cursor, ev)
            else:
                stop = _moving(X, S, t_seg_end, bridge, p, L, o, z, cursor, ev, hbox)
            if stop:
                break
            if not (abs(X[A1]) <= o[_O_DIVERGE]):
                S[_STATUS] = _DIVERGED
                stop = True
                break
        if stop:
            break
    if S[_STATUS] == _OK:
        S[_T] = t0 + duration
    out[0], out[1], out[2], out[3], out[4], out[5], out[6] = X[A1], X[A2], X[A3], X[A4], X[A5], X[AU], X[ATH]
    return cursor[0]


_SCRATCH = threading.local()
_NO_EVENTS = np.empty((0, len(EVENT_FIELDS)))
_NO_NOISE = np.empty(0)


def advance(state: PlantState, command: DriveCommand, params, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """The pure interval step of the ``stribeck`` family (as :func:`plant.multimode.interval.advance`).

    ``options.substep`` and ``reflect_substep`` are the noisy sub-steps away from and in the
    reflection regime, ``bisection_tol`` the width at which a noisy velocity zero is located;
    ``zero_velocity`` is not used (the bridge locator always).

    Raises
    ------
    ValueError
        For a non-positive duration, a command segment at or beyond the interval's end, or a
        bridge level other than 0 and ±u_max.
    """
    h = params.sample_period if duration is None else duration
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"duration must be a finite positive number of seconds, got {duration!r}")
    offsets = command._offsets
    if offsets is None:
        offsets, levels = command.arrays()
    else:
        levels = command._levels
    if offsets[-1] >= h:
        raise ValueError(f"DriveCommand segment at offset {offsets[-1]!r} s lies beyond the interval of {h!r} s")
    bridge = command.drive is DriveType.BRIDGE
    x = np.array(state.x, dtype=np.float64)   # a writable copy: the kernels' one signature (docs/plant.md)
    if x.shape[0] != N_STATE:
        raise ValueError(f"a stribeck state has {N_STATE} entries (x1..x5, u, θ), got {x.shape[0]}")
    noisy = options.noise and noise is not None
    o = options.kernel_vector().copy()
    if not noisy:
        o[0] = 0.0
    out = np.empty(N_STATE + _SHEET)
    ev = getattr(_SCRATCH, "events", None) if record else _NO_EVENTS
    if record and ev is None:
        ev = _SCRATCH.events = np.empty((4096, len(EVENT_FIELDS)))
    z, pos = noise.window() if noisy else (_NO_NOISE, 0)
    while True:
        try:
            pos_after = interval_kernel(x, state.mode, state.flyback, state.t, h, offsets, levels, bridge,
                                        params.kernel_record(), params.law_vector(), o, z, pos, ev, out)
            break
        except NoiseExhausted:
            z, pos = noise.grow(pos)
        except _RecordFull:
            ev = _SCRATCH.events = np.empty((4 * ev.shape[0], len(EVENT_FIELDS)))
    if noisy:
        noise.consumed(pos_after)
    x_out = out[:N_STATE].copy()
    (t, mode, flyback, _, peak, iabs, isq, chg, dur, nev, nbrk, nstk, nsub, code, nrec, _) = out[N_STATE:].tolist()
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max}), got {command.segments!r}")
    x_out.flags.writeable = False
    new = PlantState(t, x_out, int(mode), flyback != 0.0)
    if code == _OK:
        status, message = Status.OK, ""
    elif code == _CHATTER:
        status, message = Status.CHATTER, f"more than {options.max_events} events in one interval at t={t:.6f} s"
    else:
        status, message = Status.DIVERGED, f"|x1| = {abs(x_out[X1]):.3g} rad at t={t:.6f} s"
    events = None
    if record:
        n = int(nrec)
        events = {name: ev[:n, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, status, message, peak, iabs, isq, chg, dur, int(nev), int(nbrk), int(nstk),
                          int(nsub), events)
