"""One sample interval of the ``lugre`` family, compiled whole: the pure step.

No stuck mode: the LuGre law holds the shaft in pre-sliding by itself. Within each constant-
drive segment the state (v, z, D) is integrated by Dormand–Prince 5(4) with error
control (plant.lugre.integrate, which says why explicit) with x3, x4, x5 exact; the segment ends at the command's level
changes and at the flyback end (x3 = 0, closed form: x3 does not depend on the motion), so
those events are exact. The mode (for traces and counts) is 3/1 while x2 > +v_th / < −v_th
and 2 between, v_th = :data:`VELOCITY_THRESHOLD`; a change is recorded as a breakaway,
stick or reversal event at the integrator's step end.

With noise, sub-steps: the deterministic flow (Dormand–Prince at ``NOISY_TOLERANCES``, RTOL
1e-6; plant.lugre.integrate), then the noise increments — w2 on x2 through the sliding part of
the contact, s(v)² = 1 − exp(−(x2/v_s)²) (SPEC §2's "w2 acts only while moving", made
continuous: LuGre has no stuck mode, and full w2 in pre-sliding would shake a resting shaft at
√(σ2²/(2J·σ1)) ≈ 0.75 mrad/s RMS) with variance α²σ2²·∫s(v)²dt along the flow, the exact
Gaussian (x1, x4) increment of w4 (plant.multimode.stuck) and x5's exact Ornstein–Uhlenbeck
increment (x5 is not frozen: there is no stuck mode). This Lie–Trotter splitting is weak order 1.
A sub-step is ``SimOptions.substep`` (0.1 ms) long while the shaft slides (s² > PRESLIDING =
1e-4, |x2| > 0.01·v_s); one that starts in pre-sliding runs to the end of the drive segment,
the flyback end or the first step end where s² > PRESLIDING (that step kept ≤ ``substep``), so
w2 there (≤ 1e-4 of its sliding intensity) is not cut into 100 pieces per sample; a mode change
also ends a sub-step. Checked: the fine Euler–Maruyama statistics (tests/test_lugre.py; on 12000
paths the sd ratios 1.004, 0.984, 0.985, 0.964 against 1.014, 0.997, 0.984, 0.961 with the
0.1 ms grid everywhere at RTOL 1e-10) and the flow against Radau with the noisy path taken.

State: the six shared entries, θ = c (index 6) and the bristle deflection z [rad] (index 7).
"""

from __future__ import annotations

import math
import threading

import numpy as np
from numba import njit

from plant.drive import DriveCommand, DriveType
from plant.lugre.law import L_ALPHA, L_BETA5, L_SIGMA2_SQ, L_SIGMA5_SQ, L_VS
from plant.lugre import integrate
from plant.lugre.integrate import scratch, segment
from plant.multimode.segments import torque_integrals
from plant.multimode.stuck import stuck_propagate
from plant.randomness import NoiseExhausted, NoiseStream, normal
from plant.state import EVENT_FIELDS, X1, EventKind, IntervalResult, PlantState, SimOptions, Status

__all__ = ["advance", "interval_status", "undefined_message", "interval_kernel", "N_STATE", "VELOCITY_THRESHOLD"]

N_STATE = 8
VELOCITY_THRESHOLD = 1e-6     # rad/s: |x2| below it counts as stuck (mode 2) in traces and counts
A1, A2, A3, A4, A5, AKC, AU, ATH, AZ = range(9)
_T, _MODE, _FB, _COUNT, _PEAK, _IABS, _ISQ, _CHG, _DUR, _NEV, _NBRK, _NSTK, _NSUB, _STATUS, _NREC = range(15)
_SHEET = 15
_O_NOISE, _O_NEWTON, _O_SUB, _O_RSUB, _O_TOL, _O_MAXEV, _O_DIVERGE = range(7)
_OK, _CHATTER, _DIVERGED, _BAD_LEVEL = 0, 1, 2, 3
_LEVEL, _FLYBACK_END, _BREAKAWAY, _REGIME_END, _STICK, _REVERSAL, _REFLECTION = (int(k) for k in EventKind)
PRESLIDING = 1e-4             # s(v)² = 1 − exp(−(v/v_s)²) at or below it: a noisy sub-step may stretch
_MAX_STEPS = 2_000_000        # integrator steps per interval before ``chatter``


class _RecordFull(Exception):
    """The event buffer is full (the caller enlarges it and runs the interval again)."""


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
    S[_COUNT] += 1.0
    if S[_COUNT] > o[_O_MAXEV]:
        S[_STATUS] = _CHATTER
        return True
    return False


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
        X[AU], S[_FB] = -math.copysign(umax, X[A3]), 1.0
    else:
        X[AU], S[_FB] = 0.0, 0.0
    return True


@njit(cache=True)
def _mode_event(S, old, new):
    """Count a mode change; its event kind."""
    S[_MODE] = float(new)
    if old == 2:
        S[_NBRK] += 1.0
        return _BREAKAWAY
    if new == 2:
        S[_NSTK] += 1.0
        return _STICK
    S[_NBRK] += 1.0
    return _REVERSAL


@njit(cache=True)
def _noise_kick(X, h, quad, p, L, z, cursor, work):
    """The noise increments over a sub-step of h [s] (after the deterministic flow); w2's has
    the variance α²σ2²·quad, quad = ∫ s(v)² dt along the flow (plant.lugre.integrate.segment)."""
    g = L[L_ALPHA] * math.sqrt(L[L_SIGMA2_SQ])
    if g > 0.0:
        X[A2] += g * math.sqrt(quad) * normal(z, cursor)   # through the sliding part
    if p.sigma4_sq > 0.0:
        for i in range(work.shape[0]):
            work[i] = 0.0
        stuck_propagate(work, h, p, True, z, cursor)     # zero mean: only the (x1, x4) noise
        X[A1] += work[A1]
        X[A4] += work[A4]
    q5 = L[L_SIGMA5_SQ]
    if q5 > 0.0:
        b5 = L[L_BETA5]
        X[A5] += math.sqrt(q5 / (2.0 * b5) * (-math.expm1(-2.0 * b5 * h))) * normal(z, cursor)


@njit(cache=True)
def interval_kernel(x, mode, flyback, t0, duration, offsets, levels, bridge, prm, L, o, z, zpos, ev, out, tol):
    """Advance over [t0, t0 + duration) under (offsets, levels); out = [state (8), sheet]."""
    p = prm[0]
    S = out[N_STATE:]
    cursor = np.empty(1, dtype=np.int64)
    cursor[0] = zpos
    X = np.empty(9)
    X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU], X[ATH], X[AZ] = \
        x[0], x[1], x[2], x[3], x[4], p.coulomb, x[5], x[6], x[7]
    work = np.zeros(7)
    hbox = np.zeros(1)
    W, K = scratch()
    for i in range(_SHEET):
        S[i] = 0.0
    S[_T], S[_MODE], S[_FB] = t0, mode, 1.0 if flyback else 0.0
    S[_PEAK] = abs(X[A1])
    noisy = o[_O_NOISE] != 0.0
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
            h_end = t_seg_end - S[_T]
            h_fb = p.tau3 * math.log1p(abs(X[A3]) / p.u_max) if S[_FB] != 0.0 else math.inf
            h = min(h_end, h_fb)
            if noisy and -math.expm1(-(X[A2] / L[L_VS]) ** 2) > PRESLIDING:
                h = min(h, o[_O_SUB])
            x3, u = X[A3], X[AU]
            old = int(S[_MODE])
            advanced, new, peak, steps = segment(X, h, L, S[_PEAK], hbox, VELOCITY_THRESHOLD, old, 0.0, tol, W, K,
                                                 PRESLIDING if noisy else math.inf, o[_O_SUB])
            S[_PEAK] = peak
            S[_NSUB] += steps
            _torque_metrics(S, x3, u, advanced, bridge, p.u_max, p.tau3)
            if S[_NSUB] > _MAX_STEPS:
                S[_STATUS] = _CHATTER
                stop = True
                break
            full = advanced >= h
            if full and h == h_end:
                S[_T] = t_seg_end
            else:
                S[_T] += advanced
            if full and h == h_fb and h != h_end:
                X[A3] = 0.0
                X[AU] = 0.0
                S[_FB] = 0.0
                if _event(S, X, _FLYBACK_END, o, ev):
                    stop = True
                    break
            if noisy:
                _noise_kick(X, advanced, W[17], p, L, z, cursor, work)
                new = 3 if X[A2] > VELOCITY_THRESHOLD else (1 if X[A2] < -VELOCITY_THRESHOLD else 2)
            if new != old:
                if _event(S, X, _mode_event(S, old, new), o, ev):
                    stop = True
                    break
            if not (abs(X[A1]) <= o[_O_DIVERGE]):
                S[_STATUS] = _DIVERGED
                stop = True
                break
        if stop:
            break
    if S[_STATUS] == _OK:
        S[_T] = t0 + duration
    for i in range(7):
        out[i] = X[i] if i < 5 else (X[AU] if i == 5 else X[ATH])
    out[7] = X[AZ]
    return cursor[0]


_SCRATCH = threading.local()
_NO_EVENTS = np.empty((0, len(EVENT_FIELDS)))
_NO_NOISE = np.empty(0)


def advance(state: PlantState, command: DriveCommand, params, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """The pure interval step of the ``lugre`` family (as :func:`plant.multimode.interval.advance`).

    ``options.substep`` is the noisy sub-step; the other locator options are not used.

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
        raise ValueError(f"a lugre state has {N_STATE} entries (x1..x5, u, θ, z), got {x.shape[0]}")
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
                                        params.kernel_record(), params.law_vector(), o, z, pos, ev, out,
                                        integrate.NOISY_TOLERANCES if noisy else integrate.TOLERANCES)
            break
        except NoiseExhausted:
            z, pos = noise.grow(pos)
        except _RecordFull:
            ev = _SCRATCH.events = np.empty((4 * ev.shape[0], len(EVENT_FIELDS)))
        except ZeroDivisionError:
            return IntervalResult(state, Status.ERROR, undefined_message(state, params), abs(float(x[X1])),
                                  0.0, 0.0, 0.0, 0.0, 0, 0, 0, 0, None)
    if noisy:
        noise.consumed(pos_after)
    x_out = out[:N_STATE].copy()
    (t, mode, flyback, _, peak, iabs, isq, chg, dur, nev, nbrk, nstk, nsub, code, nrec) = out[N_STATE:].tolist()
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max}), got {command.segments!r}")
    x_out.flags.writeable = False
    new = PlantState(t, x_out, int(mode), flyback != 0.0)
    status, message = interval_status(int(code), new, options)
    events = None
    if record:
        n = int(nrec)
        events = {name: ev[:n, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, status, message, peak, iabs, isq, chg, dur, int(nev), int(nbrk), int(nstk),
                          int(nsub), events)


def undefined_message(state: PlantState, params) -> str:
    """Why an interval from ``state`` stopped on g(v) = 0: the friction levels k̄c·m + x5 and
    k̄s·m + x5 are clamped at 0 (SPEC §2; x5 far below −k̄c, or k̄c·m + x5 ≤ 0 while the shaft
    slides so fast that exp(−(v/v_s)²) underflows), where ż = v − σ0·|v|·z/g(v) (1995, eq. (2))
    is undefined: the bristles would have to follow a zero friction level infinitely fast."""
    return (f"LuGre law undefined in the interval from t={state.t:.6f} s: g(v) = 0, the effective friction "
            f"level clamped at 0 (k̄c = {params.coulomb:.4g}, x5 = {float(state.x[4]):.4g} ozf·in, "
            f"x2 = {float(state.x[1]):.3g} rad/s)")


def interval_status(code: int, state: PlantState, options: SimOptions) -> tuple[Status, str]:
    """The :class:`Status` and message of a kernel status code (for :func:`advance` and the
    compiled loop, plant.lugre.law_loop)."""
    if code == _OK:
        return Status.OK, ""
    if code == _CHATTER:
        return Status.CHATTER, f"integrator or event budget exhausted in one interval at t={state.t:.6f} s"
    return Status.DIVERGED, f"|x1| = {abs(state.x[X1]):.3g} rad at t={state.t:.6f} s"


# --- for compiled callers (plant.lugre.law_loop) ------------------------------------------------
SHEET_SIZE, STATUS_OK, NO_EVENTS = _SHEET, _OK, _NO_EVENTS
SHEET_T, SHEET_MODE, SHEET_FLYBACK, SHEET_PEAK = _T, _MODE, _FB, _PEAK
SHEET_ABS, SHEET_SQ, SHEET_CHARGE, SHEET_DURATION = _IABS, _ISQ, _CHG, _DUR
SHEET_EVENTS, SHEET_BREAKAWAYS, SHEET_SUBSTEPS, SHEET_STATUS = _NEV, _NBRK, _NSUB, _STATUS
