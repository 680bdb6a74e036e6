"""The response of the shaft to one switched-bridge torque pulse (section 3.2, 6.1).

Starting from rest (stuck, x3 = x4 = x5 = 0), the bridge applies sign·u_max for ``dt_u``
seconds, then is switched off: the flyback diodes apply −sign·u_max until the current is
zero, and u = 0 after that. The shaft breaks away when x3 passes k̄s and stops when its
velocity returns to zero with |x3| ≤ ks. Computed by the exact event-driven simulator
(:func:`plant.multimode.interval.advance`), noisy or not. The closed form that pulse
controllers assume is theirs, not the plant's: :mod:`controllers.models.acker`.
"""

from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass

import numpy as np

from plant.drive import DriveCommand, DriveType
from numba import njit

from plant.multimode.interval import (SHEET_FLYBACK, SHEET_MODE, SHEET_SIZE, SHEET_STATUS, SHEET_T, STATUS_OK,
                                      _NREC as _SHEET_NREC, _RecordFull, _event_scratch, advance, interval_kernel,
                                      kernel_inputs)
from plant.params import PlantParams
from plant.randomness import NoiseStream
from plant.state import N_STATE, X1, X3, X4, EventKind, SimOptions, Status, initial_state

_STICK = int(EventKind.STICK)

__all__ = ["PulseResponse", "pulse_response"]


@dataclass(frozen=True)
class PulseResponse:
    """Outcome of one pulse.

    Attributes
    ----------
    delta_c : float
        Net shaft motion [rad] (signed).
    t_breakaway : float or None
        First breakaway time [s]; None if the shaft never moves.
    t_current_zero : float
        Time the motor current returns to zero after switch-off [s].
    t_stop : float
        Time the shaft is stuck for good [s]; 0 if it never moved.
    """

    delta_c: float
    t_breakaway: float | None
    t_current_zero: float
    t_stop: float


_HORIZON_S = 1.0
_BREAKAWAY, _STICK, _FLYBACK_END = int(EventKind.BREAKAWAY), int(EventKind.STICK), int(EventKind.FLYBACK_END)


def pulse_response(params: PlantParams, dt_u: float, *, sign: int = 1, seed: int | None = None,
                   options: SimOptions | None = None) -> PulseResponse:
    """Simulate one pulse exactly; ``seed=None`` is noise-free.

    With a seed, friction noise w2 and x5's diffusion act (x4 stays 0 so x1 is the shaft
    angle); the pulse's random stream is ``numpy.random.default_rng(SeedSequence(seed))``.

    Raises
    ------
    ValueError
        If ``dt_u`` is negative, not finite, or ``sign`` is not ±1.
    """
    if not (type(dt_u) is float or isinstance(dt_u, (int, float))) or not (dt_u >= 0 and math.isfinite(dt_u)):
        raise ValueError(f"dt_u must be a finite number of seconds >= 0, got {dt_u!r}")
    if sign not in (1, -1):
        raise ValueError(f"sign must be +1 or -1, got {sign!r}")
    dt_u = float(dt_u)
    if dt_u == 0.0:
        return PulseResponse(0.0, None, 0.0, 0.0)
    return _simulate(params, dt_u, sign, seed, options)


def _simulate(params: PlantParams, dt_u: float, sign: int, seed: int | None,
              options: SimOptions | None) -> PulseResponse:
    """The pulse through the general event-driven simulator (noisy or not)."""
    noisy = seed is not None
    p = params.__dict__.get("_pulse_plant")
    if p is None:                       # x4 ≡ 0 here, so x1 is the shaft angle
        p = params.replace(command_velocity_std=0.0)
        object.__setattr__(params, "_pulse_plant", p)
    opts = options or SimOptions(noise=noisy)
    if not noisy:
        opts = dataclasses.replace(opts, noise=False)
    noise = NoiseStream.from_seed(seed, block=512) if noisy else None
    state = initial_state(p, x5=0.0, x4=0.0)
    level = sign * p.u_max
    times: dict[str, float] = {}

    def note(events: dict[str, np.ndarray]) -> None:
        for t, kind in zip(events["t"].tolist(), events["kind"].tolist()):
            if kind == _BREAKAWAY:
                times.setdefault("breakaway", t)
            elif kind == _STICK:
                times["stop"] = t
            elif kind == _FLYBACK_END and t > dt_u:
                times.setdefault("current_zero", t)

    step = advance(state, DriveCommand.hold(level, DriveType.BRIDGE), p, noise, opts, duration=dt_u, record=True)
    note(step.events)
    state = step.state
    off = DriveCommand.hold(0.0, DriveType.BRIDGE)
    t_fly = p.motor_time_constant * math.log1p(abs(state.x[X3]) / p.u_max)
    chunk = max(2.0 * t_fly, 1e-3)
    while step.status == Status.OK and (state.mode != 2 or state.flyback) and state.t < _HORIZON_S:
        step = advance(state, off, p, noise, opts, duration=chunk, record=True)
        note(step.events)
        state = step.state
    if step.status != Status.OK:
        raise RuntimeError(f"pulse simulation ended with status {step.status}: {step.message}")
    if state.mode != 2:
        raise RuntimeError(f"shaft still moving {_HORIZON_S} s after a {dt_u} s pulse")
    t_cz = times.get("current_zero", dt_u + t_fly)
    t_brk = times.get("breakaway")
    return PulseResponse(float(state.x[X1]), t_brk, t_cz, times.get("stop", 0.0) if t_brk is not None else 0.0)


# --- the noise-free pulse motion of PlantFamily.pulse_motion, compiled --------------------------

@njit(cache=True)
def _interval(xs, mode, flyback, t, h, level, offsets, levels, prm, o, TP, TL, BPh, BPw, BG, BC, z, ev, out, t_stop):
    """One noise-free interval of ``h`` at ``level``; (status, time of its last stick event or
    ``t_stop``), the new state and sheet in ``out``. ``offsets`` (= [0]) and ``levels`` are the
    caller's one-element command arrays."""
    levels[0] = level
    interval_kernel(xs, mode, flyback, t, h, offsets, levels, bool(True), prm, o, TP, TL, BPh, BPw, BG, BC, z, np.int64(0),
                    ev, out)                      # bool(), np.int64(): typed, not literal (docs/plant.md)
    S = out[N_STATE:]
    for i in range(int(S[_SHEET_NREC])):
        if ev[i, 6] == _STICK:
            t_stop = ev[i, 0]
    return int(S[SHEET_STATUS]), t_stop


@njit(cache=True)
def _pulse_motion(x0, mode, flyback, dt_u, level, tau, u_max, horizon, prm, o, TP, TL, BPh, BPw, BG, BC, z, ev, out):
    """The intervals of :meth:`plant.protocol.PlantFamily.pulse_motion` from the state (x0 with
    x4 = 0, mode, flyback) at t = 0: ``level`` for ``dt_u`` (if > 0), then level 0 in chunks of
    max(2τ·ln(1 + |x3|/u_max), 1 ms) while the shaft moves or the flyback lasts and t < ``horizon``.
    Returns (status code, Δx1, time of the last stick event (0 if none), final mode)."""
    xs = x0.copy()
    offsets, levels = np.zeros(1), np.empty(1)    # the command of every interval (one segment)
    xs[3] = 0.0                                   # x4 = 0: the shaft's own motion
    x1_0 = xs[0]
    t_stop = 0.0
    t = 0.0
    S = out[N_STATE:]
    if dt_u > 0:
        code, t_stop = _interval(xs, mode, flyback, t, dt_u, level, offsets, levels, prm, o, TP, TL, BPh, BPw, BG, BC,
                                 z, ev, out, t_stop)
        if code != STATUS_OK:
            return code, 0.0, t_stop, mode
        t, mode, flyback = S[SHEET_T], int(S[SHEET_MODE]), S[SHEET_FLYBACK] != 0.0
        for i in range(N_STATE):                  # the new state, in place
            xs[i] = out[i]
    chunk = max(2.0 * tau * math.log1p(abs(xs[2]) / u_max), 1e-3)
    while (mode != 2 or flyback) and t < horizon:
        code, t_stop = _interval(xs, mode, flyback, t, chunk, 0.0, offsets, levels, prm, o, TP, TL, BPh, BPw, BG, BC,
                                 z, ev, out, t_stop)
        if code != STATUS_OK:
            return code, 0.0, t_stop, mode
        t, mode, flyback = S[SHEET_T], int(S[SHEET_MODE]), S[SHEET_FLYBACK] != 0.0
        for i in range(N_STATE):                  # the new state, in place
            xs[i] = out[i]
    return STATUS_OK, xs[0] - x1_0, t_stop, mode


_NOISE_OFF = SimOptions(noise=False)
_NO_NORMALS = np.empty(0)


def pulse_motion(params: PlantParams, state, dt_u: float, sign: int, horizon: float) -> tuple[float, float] | None:
    """:meth:`plant.protocol.PlantFamily.pulse_motion` of this plant (no disturbance torque)
    in one compiled call: the same kernel on the same inputs, so the same numbers.
    ``params`` is already the quiet-command copy. None when the event buffer overflowed or the
    run failed (the caller then runs the generic path, which reports it)."""
    o, TP, TL, BPh, BPw, BG, BC = kernel_inputs(params, _NOISE_OFF, False)
    try:
        code, dx1, t_stop, mode = _pulse_motion(state.x, state.mode, state.flyback, dt_u, sign * params.u_max,
                                                params.motor_time_constant, params.u_max, horizon,
                                                params.kernel_record(), o, TP, TL, BPh, BPw, BG, BC, _NO_NORMALS,
                                                _event_scratch(), np.empty(N_STATE + SHEET_SIZE))
    except _RecordFull:
        return None
    if code != STATUS_OK or mode != 2:
        return None
    return dx1, t_stop


@njit(cache=True)
def _on_time(x0, mode, flyback, motion, level, dtu_max, tol, max_iterations, tau, u_max, horizon, prm, o, TP, TL, BPh,
             BPw, BG, BC, z, ev, out):
    """The Illinois regula falsi of :meth:`plant.protocol.PlantFamily.pulse_on_time` over
    :func:`_pulse_motion`; (ok, Δt_u, |Δc|, t_stop), ok False when a pulse run failed or did not
    end stuck (the caller then takes the generic path)."""
    code, dx, stop_hi, m = _pulse_motion(x0, mode, flyback, dtu_max, level, tau, u_max, horizon, prm, o, TP, TL, BPh,
                                         BPw, BG, BC, z, ev, out)
    if code != STATUS_OK or m != 2:
        return False, 0.0, 0.0, 0.0
    hi = dtu_max
    dc_hi = abs(dx)
    if dc_hi <= motion:
        return True, hi, dc_hi, stop_hi
    lo, f_lo, f_hi = 0.0, -motion, dc_hi - motion
    side = 0
    for _ in range(max_iterations):
        if hi - lo <= tol:
            break
        mid = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        if not lo < mid < hi:
            mid = 0.5 * (lo + hi)
        code, dx, stop, m = _pulse_motion(x0, mode, flyback, mid, level, tau, u_max, horizon, prm, o, TP, TL, BPh, BPw,
                                          BG, BC, z, ev, out)
        if code != STATUS_OK or m != 2:
            return False, 0.0, 0.0, 0.0
        f = abs(dx) - motion
        if f >= 0.0:
            hi, f_hi, dc_hi, stop_hi = mid, f, abs(dx), stop
            if side == 1:
                f_lo *= 0.5
            side = 1
        else:
            lo, f_lo = mid, f
            if side == -1:
                f_hi *= 0.5
            side = -1
    return True, hi, dc_hi, stop_hi


def pulse_on_time(params: PlantParams, state, motion: float, sign: int, dtu_max: float, tol: float,
                  max_iterations: int, horizon: float) -> tuple[float, float, float] | None:
    """:meth:`plant.protocol.PlantFamily.pulse_on_time` of this plant (no disturbance torque) in
    one compiled call: every pulse is :func:`pulse_motion`'s kernel on the same inputs and the
    root search does the generic one's arithmetic, so the same numbers, without ~8 µs of Python
    per trial pulse. ``params`` is already the quiet-command copy. None when a pulse run fails or
    the event buffer overflows (the caller then runs the generic path, which reports it)."""
    o, TP, TL, BPh, BPw, BG, BC = kernel_inputs(params, _NOISE_OFF, False)
    try:
        ok, dtu, dc, t_stop = _on_time(state.x, state.mode, state.flyback, motion, sign * params.u_max, dtu_max, tol,
                                       max_iterations, params.motor_time_constant, params.u_max, horizon,
                                       params.kernel_record(), o, TP, TL, BPh, BPw, BG, BC, _NO_NORMALS,
                                       _event_scratch(), np.empty(N_STATE + SHEET_SIZE))
    except _RecordFull:
        return None
    return (dtu, dc, t_stop) if ok else None
