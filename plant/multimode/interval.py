"""One sample interval of the exact plant, compiled whole: the pure step of the simulator.

:func:`advance` takes (state, command, params, noise, options) and returns an
:class:`~plant.state.IntervalResult`: the new state, a status, the interval's exact current
integrals, counts and peak |x1|, and on request its event records. Nothing the caller owns is
changed except the noise stream's read position.

Between events the plant is linear and time-invariant (multimode linearization, chapters 3
and 4), so the state jumps from event to event with X⁺ = Φ(h)·X + N. The events are

* command level changes (the command's segments);
* the end of flyback, x3 = 0 (closed form, section 4.5);
* breakaway, |x3| = ks while stuck (closed form: x3 is deterministic);
* the end of the reflection regime, when the torque in the direction of motion falls to ks
  (closed form);
* velocity zero in a moving mode: noise-free (or σ2 = 0) the first root of the closed-form
  mean velocity, to ~1e-15 s (plant.multimode.moving); noisy, the bridge or Newton locator
  (plant.multimode.zero_velocity). At a velocity zero the switching table of SPEC §2 applies: reflect
  while the torque still breaks stiction forward, reverse when it breaks it backward, stick
  otherwise (x2 set to exactly 0).

The Coulomb and stiction levels are kc = k̄c + x5 and ks = k̄s + x5, clamped at 0.

Layout: plant.multimode.stuck (mode 2), plant.multimode.moving (modes 1 and 3), plant.multimode.zero_velocity (locators),
plant.multimode.segments (torque events and integrals); this module drives them over one interval.
"""

from __future__ import annotations

import math
import threading
from functools import lru_cache

import numpy as np
from numba import njit
from numba.np.arrayobj import reshape_unchecked

from plant.drive import DriveCommand, DriveType
from plant.multimode.moving import deterministic_move, first_mean_zero
from plant.params import PlantParams
from plant.randomness import NoiseExhausted, NoiseStream
from plant.multimode.segments import torque_crossing_time, torque_integrals
from plant.state import EVENT_FIELDS, N_STATE, X1, EventKind, IntervalResult, PlantState, SimOptions, Status
from plant.multimode.stuck import stuck_propagate
from plant.multimode.bridge_loop import bridge_run
from plant.multimode.zero_velocity import LADDER, bisection_tables, ladder_thresholds, newton_segment, substep_tables

__all__ = ["advance"]

A1, A2, A3, A4, A5, AKC, AU = range(7)

# Work sheet S (float64) shared by the kernel's parts.
_T, _MODE, _FB, _COUNT, _PEAK, _IABS, _ISQ, _CHG, _DUR, _NEV, _NBRK, _NSTK, _NSUB, _STATUS, _NREC = range(15)
_SHEET = 15
# Plan vector: SimOptions.kernel_vector, then the step-ladder thresholds TH (2 × LADDER) of
# plant.multimode.zero_velocity.ladder_thresholds.
_O_NOISE, _O_NEWTON, _O_SUB, _O_RSUB, _O_TOL, _O_MAXEV, _O_DIVERGE = range(7)
_O_LADDER = 7
# Scratch floats of bridge_run (plant.multimode.bridge_loop), allocated once per interval.
_WORK = 400
# Kernel status codes.
_OK, _CHATTER, _DIVERGED, _BAD_LEVEL = 0, 1, 2, 3
_STATUS_OF = {_OK: Status.OK, _CHATTER: Status.CHATTER, _DIVERGED: Status.DIVERGED}
_LEVEL, _FLYBACK_END, _BREAKAWAY, _REGIME_END, _STICK, _REVERSAL, _REFLECTION = (int(k) for k in EventKind)


class _RecordFull(Exception):
    """The event buffer is full (the caller enlarges it and runs the interval again)."""


# --- bookkeeping ------------------------------------------------------------------------------

@njit(cache=True, _nrt=False)
def _event(S, X, kind, o, ev):
    """Count an event (chatter guard) and record it if asked; True when the interval must stop."""
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


@njit(cache=True, _nrt=False)
def _tick(S, n, o):
    S[_COUNT] += n
    if S[_COUNT] > o[_O_MAXEV]:
        S[_STATUS] = _CHATTER
        return True
    return False


@njit(cache=True, _nrt=False)
def _torque_metrics(S, x3, u, h, bridge, p):
    if h <= 0.0:
        return
    integral, absolute, square = torque_integrals(x3, u, h, p.tau3)
    S[_IABS] += absolute
    S[_ISQ] += square
    if bridge:
        S[_CHG] += (u / p.u_max) * integral   # on: draws i; flyback: returns it
    else:
        S[_CHG] += absolute                    # a linear stage draws |i|
    S[_DUR] += h


@njit(cache=True, _nrt=False)
def _apply_level(X, S, level, bridge, p):
    """Set u for a new command level; False for a level the bridge cannot produce."""
    umax = p.u_max
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


@njit(cache=True, _nrt=False)
def _flyback_time(X, S, p):
    if S[_FB] == 0.0:
        return math.inf
    return p.tau3 * math.log1p(abs(X[A3]) / p.u_max)


@njit(cache=True, _nrt=False)
def _end_flyback(X, S):
    X[A3] = 0.0
    X[AU] = 0.0
    S[_FB] = 0.0


# --- mode 2 -----------------------------------------------------------------------------------

@njit(cache=True, _nrt=False)
def _stuck(X, S, t_end, bridge, p, o, z, cursor, ev):
    """Stuck until t_end, the flyback end or breakaway; True when the interval must stop."""
    x3, u = X[A3], X[AU]
    ks = max(p.stiction + X[A5], 0.0)
    h_end = t_end - S[_T]
    h_fb = _flyback_time(X, S, p)
    if -ks < u < ks and -ks <= x3 <= ks:
        h_up = h_dn = math.inf          # x3 heads to u inside (−ks, ks): no breakaway possible
    else:
        h_up = torque_crossing_time(x3, u, ks, p.tau3)
        h_dn = torque_crossing_time(x3, u, -ks, p.tau3)
    if x3 > ks or (x3 == ks and u > ks):
        h_up = 0.0      # already at (or past) stiction and rising: breaks away now
    elif x3 < -ks or (x3 == -ks and u < -ks):
        h_dn = 0.0
    h = min(h_end, h_fb, h_up, h_dn)
    x1_before = abs(X[A1])
    _torque_metrics(S, x3, u, h, bridge, p)
    stuck_propagate(X, h, p, o[_O_NOISE] != 0.0, z, cursor)
    S[_PEAK] = max(S[_PEAK], x1_before, abs(X[A1]))      # x1 is monotone while stuck
    if h == h_end:
        S[_T] = t_end
        return False
    S[_T] += h
    if h == h_fb:
        _end_flyback(X, S)
        return _event(S, X, _FLYBACK_END, o, ev)
    X[A3] = ks if h == h_up else -ks
    X[A2] = 0.0
    S[_MODE] = 3.0 if h == h_up else 1.0
    S[_NBRK] += 1.0
    return _event(S, X, _BREAKAWAY, o, ev)


# --- modes 1 and 3 ----------------------------------------------------------------------------

@njit(cache=True, _nrt=False)
def _velocity_zero(X, S, p):
    """x2 has reached 0 in mode 1 or 3: reflect, reverse or stick (SPEC §2); the event kind."""
    mode = int(S[_MODE])
    s = 1.0 if mode == 3 else -1.0
    x3 = X[A3]
    ks = max(p.stiction + X[A5], 0.0)
    X[A2] = 0.0
    if s * x3 > ks:
        return _REFLECTION                       # torque still breaks stiction forward
    if -s * x3 > ks:
        S[_MODE] = 1.0 if mode == 3 else 3.0     # breaks stiction the other way
        S[_NBRK] += 1.0
        return _REVERSAL
    S[_MODE] = 2.0
    S[_NSTK] += 1.0
    return _STICK


@njit(cache=True, _nrt=False)
def _moving_plan(X, S, t_end, p):
    """The moving segment's horizon: (mode, s, x3, u, ks, h_end, h_fb, reflecting, h).

    Sets X[AKC] to the clamped Coulomb level (a function of X[A5] and p: idempotent)."""
    mode = int(S[_MODE])
    s = 1.0 if mode == 3 else -1.0
    x3, u = X[A3], X[AU]
    ks = max(p.stiction + X[A5], 0.0)
    X[AKC] = p.coulomb if p.coulomb + X[A5] >= 0.0 else -X[A5]   # kc clamped at 0
    h_end = t_end - S[_T]
    h_fb = _flyback_time(X, S, p)
    # At breakaway x3 = ±ks exactly and still rising: that is inside the reflection regime.
    reflecting = s * x3 > ks or (s * x3 == ks and s * u > ks)
    h_reg = math.inf
    if reflecting and s * u < ks:
        h_reg = torque_crossing_time(x3, u, s * ks, p.tau3)
        if h_reg == math.inf:          # within rounding of ks and heading below it
            reflecting = False
    h = min(h_end, h_fb, h_reg)
    return mode, s, x3, u, ks, h_end, h_fb, reflecting, h


@njit(cache=True, _nrt=False)
def _moving_bridge(X, S, mode, x3, u, h, reflecting, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, W):
    """The bridge locator (or the reflection) over the segment; (stopped, must stop now).

    The thresholds TH (2 × LADDER, from the plan vector) and the fresh step's 7 × 7 and 4 × 4
    scratch (W[14:95]) are strided views built in place by numba's ``reshape_unchecked`` (what
    ``as_strided`` lowers to; ``as_strided`` itself is refused without reference counting):
    ``reshape`` calls into numba's runtime, four times per segment."""
    budget = max(o[_O_MAXEV] - S[_COUNT], 1.0)
    f = W.itemsize
    TH = reshape_unchecked(o[_O_LADDER:_O_LADDER + 2 * LADDER], (2, LADDER), (LADDER * f, f))
    advanced, stopped, peak, n, chattered = bridge_run(
        X, mode, h, reflecting, o[_O_SUB], o[_O_RSUB], o[_O_TOL], p, TP, TL, TH, BPh, BPw, BG, BC, z, cursor,
        S[_PEAK], budget, W, reshape_unchecked(W[14:63], (7, 7), (7 * f, f)),
        reshape_unchecked(W[63:79], (4, 4), (4 * f, f)), reshape_unchecked(W[79:95], (4, 4), (4 * f, f)))
    _torque_metrics(S, x3, u, advanced, bridge, p)
    S[_PEAK] = peak
    S[_NSUB] += n
    S[_T] += advanced
    if chattered or _tick(S, n, o):
        S[_STATUS] = _CHATTER
        return stopped, True
    return stopped, False


@njit(cache=True, _nrt=False)
def _moving_end(X, S, stopped, s, ks, h, h_end, h_fb, t_end, p, o, ev):
    """The event that ended the moving segment; True when the interval must stop."""
    if stopped:
        kind = _velocity_zero(X, S, p)
        return _event(S, X, kind, o, ev)
    if h == h_end:
        S[_T] = t_end
        return False
    if h == h_fb:
        _end_flyback(X, S)
        return _event(S, X, _FLYBACK_END, o, ev)
    X[A3] = s * ks              # end of the reflection regime: exactly at stiction
    return _event(S, X, _REGIME_END, o, ev)


@njit(cache=True)
def _moving(X, S, t_end, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, ev, W):
    """Moving until t_end or the next event; True when the interval must stop."""
    mode, s, x3, u, ks, h_end, h_fb, reflecting, h = _moving_plan(X, S, t_end, p)
    noise_on = o[_O_NOISE] != 0.0
    white = noise_on and p.sigma2_sq > 0.0
    if white and (reflecting or o[_O_NEWTON] == 0.0):
        stopped, chattered = _moving_bridge(X, S, mode, x3, u, h, reflecting, bridge, p, o, TP, TL, BPh, BPw, BG, BC,
                                            z, cursor, W)
        if chattered:
            return True
    elif white:
        advanced, stopped, peak = newton_segment(X, mode, h, p, z, cursor, S[_PEAK])
        _torque_metrics(S, x3, u, advanced, bridge, p)
        S[_PEAK] = peak
        S[_NSUB] += 1.0
        S[_T] += advanced
    else:
        tau = math.inf if reflecting else first_mean_zero(mode, X, p, h)
        stopped = tau <= h
        advanced = tau if stopped else h
        _torque_metrics(S, x3, u, advanced, bridge, p)
        S[_PEAK] = deterministic_move(mode, X, p, advanced, noise_on, z, cursor, S[_PEAK])
        S[_T] += advanced
        if stopped:
            X[A2] = 0.0
    return _moving_end(X, S, stopped, s, ks, h, h_end, h_fb, t_end, p, o, ev)


@njit(cache=True, _nrt=False)
def _fast_span(X, S, t_end, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, ev, W):
    """The interval loop's body (:func:`interval_kernel`) up to ``t_end`` while every moving
    segment takes the bridge locator: the same calls in the same order. Compiled without numba's
    reference counting (nothing it calls allocates), which otherwise costs atomic increments
    and decrements of every array argument and view at each of the ~25 events and ~125 noisy
    sub-steps of a dithered sample. Returns 0 at ``t_end``, 1 when the interval must stop, −1
    when the next moving segment needs another locator (Newton): nothing of it has happened yet
    but X[AKC] (set again by :func:`_moving`), and the caller runs that segment.
    """
    while S[_T] < t_end:
        if S[_MODE] == 2.0:
            stop = _stuck(X, S, t_end, bridge, p, o, z, cursor, ev)
        else:
            mode, s, x3, u, ks, h_end, h_fb, reflecting, h = _moving_plan(X, S, t_end, p)
            if not (reflecting or o[_O_NEWTON] == 0.0):
                return -1
            stopped, chattered = _moving_bridge(X, S, mode, x3, u, h, reflecting, bridge, p, o, TP, TL, BPh, BPw,
                                                BG, BC, z, cursor, W)
            stop = chattered or _moving_end(X, S, stopped, s, ks, h, h_end, h_fb, t_end, p, o, ev)
        if stop:
            return 1
        if not (abs(X[A1]) <= o[_O_DIVERGE]):          # also catches NaN
            S[_STATUS] = _DIVERGED
            return 1
    return 0


# --- the interval -----------------------------------------------------------------------------

@njit(cache=True, _nrt=False)
def _fast_segments(X, S, t0, duration, offsets, levels, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, ev, W):
    """:func:`interval_kernel`'s loop over the command's segments when every moving segment takes
    the bridge locator (noise on, σ2 > 0, no Newton): the same calls in the same order, all
    inside code compiled without reference counting (:func:`_fast_span`)."""
    k = offsets.shape[0]
    for seg in range(k):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < k else duration)
        if not _apply_level(X, S, levels[seg], bridge, p):
            S[_STATUS] = _BAD_LEVEL
            return
        if seg > 0 and _event(S, X, _LEVEL, o, ev):
            return
        if _fast_span(X, S, t_seg_end, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, ev, W) == 1:
            return


@njit(cache=True)
def fast_applies(prm, o):
    """True when every moving segment takes the bridge locator (noise on, σ2 > 0, no Newton):
    then :func:`interval_fast` is the whole interval."""
    return o[_O_NOISE] != 0.0 and prm[0].sigma2_sq > 0.0 and o[_O_NEWTON] == 0.0


@njit(cache=True, _nrt=False)
def interval_fast(x, mode, flyback, t0, duration, offsets, levels, bridge, prm, o, TP, TL, BPh, BPw, BG, BC, z, zpos,
                  ev, out, cursor, X, W):
    """:func:`interval_kernel` when :func:`fast_applies`, compiled without reference counting,
    on the caller's scratch: ``cursor`` (1 int64), ``X`` (7 floats) and ``W`` (_WORK floats,
    zeroed here as interval_kernel's own). A compiled loop allocates them once per chunk."""
    p = prm[0]
    cursor[0] = zpos
    for i in range(_WORK):
        W[i] = 0.0
    X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU] = x[0], x[1], x[2], x[3], x[4], p.coulomb, x[5]
    S = out[6:]
    for i in range(_SHEET):
        S[i] = 0.0
    S[_T], S[_MODE], S[_FB] = t0, mode, 1.0 if flyback else 0.0
    _fast_segments(X, S, t0, duration, offsets, levels, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, ev, W)
    if S[_STATUS] == _OK:
        S[_T] = t0 + duration
    out[0], out[1], out[2], out[3], out[4], out[5] = X[A1], X[A2], X[A3], X[A4], X[A5], X[AU]
    return cursor[0]


@njit(cache=True)
def interval_kernel(x, mode, flyback, t0, duration, offsets, levels, bridge, prm, o, TP, TL, BPh, BPw, BG, BC, z,
                    zpos, ev, out):
    """Advance over [t0, t0 + duration) under the command (offsets, levels); see advance().

    ``out[:6]`` receives the new state, ``out[6:]`` the work sheet; returns the new read
    position in the normal buffer ``z`` (from ``zpos``). When :func:`fast_applies` the interval
    is :func:`interval_fast` (no reference counting); otherwise the general loop below.
    """
    p = prm[0]
    if fast_applies(prm, o):
        return interval_fast(x, mode, flyback, t0, duration, offsets, levels, bridge, prm, o, TP, TL, BPh, BPw, BG, BC,
                             z, zpos, ev, out, np.empty(1, dtype=np.int64), np.empty(7), np.empty(_WORK))
    x_out = out[:6]
    S = out[6:]
    cursor = np.empty(1, dtype=np.int64)
    cursor[0] = zpos
    X = np.empty(7)
    white = o[_O_NOISE] != 0.0 and p.sigma2_sq > 0.0     # noisy moving segments: _fast_span
    W = np.zeros(_WORK if white else 1)                  # bridge_segment's scratch (noise-free: unused)
    X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU] = x[0], x[1], x[2], x[3], x[4], p.coulomb, x[5]
    for i in range(_SHEET):
        S[i] = 0.0
    S[_T], S[_MODE], S[_FB] = t0, mode, 1.0 if flyback else 0.0
    k = offsets.shape[0]
    for seg in range(k):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < k else duration)
        if not _apply_level(X, S, levels[seg], bridge, p):
            S[_STATUS] = _BAD_LEVEL
            break
        if seg > 0 and _event(S, X, _LEVEL, o, ev):
            break
        stop = False
        while S[_T] < t_seg_end:
            if white:
                r = _fast_span(X, S, t_seg_end, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, ev, W)
                if r == 1:
                    stop = True
                    break
                if r == 0:
                    break
            if S[_MODE] == 2.0:
                stop = _stuck(X, S, t_seg_end, bridge, p, o, z, cursor, ev)
            else:
                stop = _moving(X, S, t_seg_end, bridge, p, o, TP, TL, BPh, BPw, BG, BC, z, cursor, ev, W)
            if stop:
                break
            if not (abs(X[A1]) <= o[_O_DIVERGE]):          # also catches NaN
                S[_STATUS] = _DIVERGED
                stop = True
                break
        if stop:
            break
    if S[_STATUS] == _OK:
        S[_T] = t0 + duration
    x_out[0], x_out[1], x_out[2], x_out[3], x_out[4], x_out[5] = X[A1], X[A2], X[A3], X[A4], X[A5], X[AU]
    return cursor[0]


_NO_EVENTS = np.empty((0, len(EVENT_FIELDS)))

# The event records are written into a per-thread scratch buffer that only grows (the events
# are copied out, so no result aliases it). A fresh small buffer per interval overflowed often,
# and an exception raised inside a numba kernel leaks its array arguments: a dithered cell
# recording its trace grew by ~2 MB per simulated second. Overflow now happens a few times per
# process at most.
_SCRATCH = threading.local()


def _event_scratch() -> np.ndarray:
    ev = getattr(_SCRATCH, "events", None)
    if ev is None:
        ev = _SCRATCH.events = np.empty((4096, len(EVENT_FIELDS)))
    return ev
_NO_NOISE = np.empty(0)


def advance(state: PlantState, command: DriveCommand, params: PlantParams, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """Advance the plant over one interval under ``command``: the pure step.

    Parameters
    ----------
    state : PlantState
        Start state; not modified.
    command : DriveCommand
        Levels for [t, t + duration); every segment must start inside the interval.
    params : PlantParams
    noise : NoiseStream or None
        The plant-noise stream. ``None`` (or ``options.noise=False``) runs noise-free.
    options : SimOptions
    duration : float, optional
        Interval length [s]; default ``params.sample_period``.
    record : bool
        Return the event records (``IntervalResult.events``).

    Returns
    -------
    IntervalResult
        ``status`` is ``ok``, ``chatter`` or ``diverged``; the state is where it stopped.

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
    noisy = options.noise and noise is not None
    o, TP, TL, BPh, BPw, BG, BC = _plan(params, options, noisy)
    out = np.empty(N_STATE + _SHEET)
    ev = _event_scratch() if record else _NO_EVENTS
    if noisy:
        z, pos = noise.window()
    else:
        z, pos = _NO_NOISE, 0
    while True:
        try:
            pos_after = interval_kernel(x, state.mode, state.flyback, state.t, h, offsets, levels, bridge,
                                        params.kernel_record(), o, TP, TL, BPh, BPw, BG, BC, z, pos, ev, out)
            break
        except NoiseExhausted:
            z, pos = noise.grow(pos)
        except _RecordFull:
            ev = _SCRATCH.events = np.empty((4 * ev.shape[0], len(EVENT_FIELDS)))
    if noisy:
        noise.consumed(pos_after)
    x_out = out[:N_STATE]
    (t, mode, flyback, _, peak, iabs, isq, chg, dur, nev, nbrk, nstk, nsub, code, nrec) = out[N_STATE:].tolist()
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max}), got {command.segments!r}")
    x_out.flags.writeable = False
    new = PlantState(t, x_out, int(mode), flyback != 0.0)
    if code == _OK:
        status, message = Status.OK, ""
    else:
        status, message = _STATUS_OF[code], _message(code, new, options)
    events = None
    if record:
        n = int(nrec)
        events = {name: ev[:n, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, status, message, peak, iabs, isq, chg, dur, int(nev), int(nbrk), int(nstk),
                          int(nsub), events)


def _plan(params: PlantParams, options: SimOptions, noisy: bool) -> tuple[np.ndarray, ...]:
    """(plan vector, step-ladder and bisection tables) for this plant and these options.

    The plan vector is the options vector followed by the ladder thresholds (``_O_LADDER``).

    Kept on the options object next to the params it was built for (an identity check, cheaper
    than hashing both at every interval); the tables themselves are a pure function of
    (params, options), see :func:`_tables`.
    """
    memo = options.__dict__.get("_plan")
    if memo is None or memo[0] is not params or memo[1] != noisy:
        o = options.kernel_vector() if noisy else _quiet_vector(options)
        TH, *tables = _tables(params, options)
        o = np.concatenate((o, TH.ravel()))
        o.flags.writeable = False
        memo = (params, noisy, (o, *tables))
        object.__setattr__(options, "_plan", memo)
    return memo[2]


@lru_cache(maxsize=64)
def _tables(params: PlantParams, options: SimOptions) -> tuple[np.ndarray, ...]:
    """Ladder thresholds, Φ and noise factors of the step ladder, bridge laws of the bisection.

    The ladder (plant.multimode.zero_velocity): widths h_j·2^k, k < LADDER, from h_0 = ``substep`` and
    h_1 = ``reflect_substep``, for both moving modes, with the thresholds TH[j, k] that decide
    when a rung may be used. A memo of a pure function of (params, options): it saves
    recomputing them at every segment and bisection level and cannot change a result (the
    kernels compute the same numbers when a width is not in the table).
    """
    prm = params.kernel_record()[0]
    TP, TL = np.empty((2, 2, LADDER, 7, 7)), np.empty((2, 2, LADDER, 4, 4))
    substep_tables(prm, options.substep, options.reflect_substep, TP, TL)
    TH = ladder_thresholds(params.alpha, params.sigma2_sq, params.sigma5_sq, params.beta5, options.substep,
                           options.reflect_substep)
    levels = max(0, math.ceil(math.log2(options.substep / options.bisection_tol)))
    BPh, BPw = np.empty((2, levels, 7, 7)), np.empty((2, levels, 7, 7))
    BG, BC = np.empty((2, levels, 4, 4)), np.empty((2, levels, 4, 4))
    bisection_tables(prm, options.substep, BPh, BPw, BG, BC)
    tables = (TH, TP, TL, BPh, BPw, BG, BC)
    for a in tables:
        a.flags.writeable = False
    return tables


def _quiet_vector(options: SimOptions) -> np.ndarray:
    vec = options.__dict__.get("_quiet_vector")
    if vec is None:
        vec = options.kernel_vector().copy()
        vec[_O_NOISE] = 0.0
        vec.flags.writeable = False
        object.__setattr__(options, "_quiet_vector", vec)
    return vec


def _message(code: int, state: PlantState, options: SimOptions) -> str:
    if code == _CHATTER:
        return f"more than {options.max_events} events in one interval at t={state.t:.6f} s"
    return f"|x1| = {abs(state.x[X1]):.3g} rad at t={state.t:.6f} s"


# --- for compiled callers ---------------------------------------------------------------------
# A caller that runs many intervals in one compiled loop (plant.multimode.law_loop) calls
# interval_kernel itself with the inputs advance() would pass: kernel_inputs() gives the options
# vector and tables, the work-sheet positions below read the kernel's results, and
# interval_status() turns a status code into what advance() returns.
SHEET_T, SHEET_MODE, SHEET_FLYBACK, SHEET_PEAK = _T, _MODE, _FB, _PEAK
SHEET_ABS, SHEET_SQ, SHEET_CHARGE, SHEET_DURATION = _IABS, _ISQ, _CHG, _DUR
SHEET_EVENTS, SHEET_BREAKAWAYS, SHEET_STICKS, SHEET_SUBSTEPS, SHEET_STATUS = _NEV, _NBRK, _NSTK, _NSUB, _STATUS
SHEET_SIZE, STATUS_OK, WORK_SIZE = _SHEET, _OK, _WORK
NO_EVENTS = _NO_EVENTS


def kernel_inputs(params: PlantParams, options: SimOptions, noisy: bool) -> tuple[np.ndarray, ...]:
    """(options vector, TP, TL, BPh, BPw, BG, BC): interval_kernel's arguments after ``prm``."""
    return _plan(params, options, noisy)


def interval_status(code: int, state: PlantState, options: SimOptions) -> tuple[Status, str]:
    """The :class:`Status` and message of a kernel status code (as in :func:`advance`)."""
    if code == _OK:
        return Status.OK, ""
    return _STATUS_OF[code], _message(code, state, options)
