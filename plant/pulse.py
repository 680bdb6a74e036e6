"""The response of the shaft to one switched-bridge torque pulse (section 3.2, 6.1).

Starting from rest (stuck, x3 = x4 = x5 = 0), the bridge applies sign·u_max for ``dt_u``
seconds, then is switched off: the flyback diodes apply −sign·u_max until the current is
zero, and u = 0 after that. The shaft breaks away when x3 passes k̄s and stops when its
velocity returns to zero with |x3| ≤ ks. This is the controller's "internal plant model"
and the figure every solnic correction is built from.
"""

from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass

import numpy as np
from numba import njit

from plant.drive import DriveCommand, DriveType
from plant.expfun import e1, e2
from plant.interval import advance
from plant.params import PlantParams
from plant.randomness import NoiseStream
from plant.state import X1, X3, EventKind, SimOptions, Status, initial_state

__all__ = ["PulseResponse", "pulse_response", "max_on_time", "closed_form_kernel", "move_closed_form",
           "velocity_root"]


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


def max_on_time(params: PlantParams) -> float:
    """Largest bridge on-time Δt_u [s] whose current is back to zero within one sample period.

    From rest, x3 rises for Δt and then flies back towards −u_max until it crosses zero at
    t_cz(Δt) = Δt + τ3·ln(2 − e^(−Δt/τ3)), which increases with Δt; bisection for t_cz = τs.
    """
    tau, ts = params.motor_time_constant, params.sample_period
    lo, hi = 0.0, ts
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if mid + tau * math.log(2.0 - math.exp(-mid / tau)) < ts:
            lo = mid
        else:
            hi = mid
    return lo


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
    if seed is None and options is None:
        return _closed_form(params, dt_u, sign)
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


@njit(cache=True)
def move_closed_form(x1, x2, x3, u, kc, tau, t3, a):
    """Mode-3 motion under constant u for tau seconds (closed form of (3-20)/(3-21), x4 = x5 = 0)."""
    y = tau / t3
    g = x3 - u
    return (x1 + x2 * tau + a * ((u - kc) * tau * tau / 2.0 + g * t3 * t3 * e2(y)),
            x2 + a * ((u - kc) * tau + g * t3 * e1(y)),
            u + g * math.exp(-y))


@njit(cache=True)
def closed_form_kernel(dt_u, U, t3, a, ks, kc):
    """(Δc for sign +1, t_breakaway or −1, t_current_zero, t_stop) of a noise-free pulse.

    The compiled core of :func:`pulse_response` without noise (scalars in: Δt_u [s], u_max
    [ozf·in], τ3 [s], α [1/(ozf·in·s²)], k_s, k_c [ozf·in]); callable from other numba kernels
    (the solnic predictor, its grid posterior and noise model). k_c = 0 returns Δc = nan and
    t_stop = inf: the shaft coasts for ever.
    """
    x3_on = U * e1(dt_u / t3)
    t_cz = dt_u + t3 * math.log1p(x3_on / U)
    t_b = -t3 * math.log1p(-ks / U)
    if not dt_u > t_b:
        return 0.0, -1.0, t_cz, 0.0
    x1, x2, x3 = move_closed_form(0.0, 0.0, ks, U, kc, dt_u - t_b, t3, a)             # driven, reflecting
    t = dt_u
    t_r = t3 * math.log((x3 + U) / (ks + U)) if x3 > ks else 0.0          # flyback down to ks
    x1, x2, _ = move_closed_form(x1, x2, x3, -U, kc, t_r, t3, a)
    x3 = ks                                                                # exactly at stiction
    t += t_r
    t_f = t3 * math.log1p(x3 / U)                                          # to current zero
    v_end = move_closed_form(x1, x2, x3, -U, kc, t_f, t3, a)[1]
    if v_end <= 0.0:
        tau = velocity_root(x1, x2, x3, -U, kc, t_f, t3, a)
        x1 = move_closed_form(x1, x2, x3, -U, kc, tau, t3, a)[0]
        return x1, t_b, t_cz, t + tau
    x1, x2, _ = move_closed_form(x1, x2, x3, -U, kc, t_f, t3, a)
    t += t_f
    if kc <= 0.0:
        return math.nan, t_b, t_cz, math.inf                               # coasts for ever
    tau = x2 / (a * kc)                                                    # coast: ẋ2 = −α·k̄c
    return x1 + x2 * x2 / (2.0 * a * kc), t_b, t_cz, t + tau


def _closed_form(params: PlantParams, dt_u: float, sign: int) -> PulseResponse:
    """Noise-free pulse by its closed-form phases: stuck, driven, flyback, coasting.

    Breakaway, the end of the reflection regime, the flyback end and the final stop on the
    coast (ẋ2 = −α·k̄c) are explicit; only a stop during flyback needs a scalar root of the
    closed-form velocity, found by safeguarded Newton to ~1e-15 s. Compiled: this is the
    solnic predictor's inner call.
    """
    p = params
    dc, t_b, t_cz, t_stop = closed_form_kernel(dt_u, p.u_max, p.motor_time_constant, p.alpha, p.stiction,
                                                p.coulomb)
    if t_b < 0.0:
        return PulseResponse(0.0, None, t_cz, 0.0)
    if t_stop == math.inf:
        raise RuntimeError("shaft coasts for ever after the pulse: k̄c = 0")
    return PulseResponse(sign * dc, t_b, t_cz, t_stop)


@njit(cache=True)
def velocity_root(x1, x2, x3, u, kc, h, t3, a):
    """First zero of the closed-form velocity on (0, h], given x2 > 0 at 0 and ≤ 0 at h."""
    # x2 rises while x3 > kc and falls after: the zero lies after x3 = kc.
    lo = t3 * math.log((x3 - u) / (kc - u)) if x3 > kc else 0.0
    hi = h
    tau = 0.5 * (lo + hi)
    for _ in range(200):
        _, v, x3t = move_closed_form(x1, x2, x3, u, kc, tau, t3, a)
        if v == 0.0:
            return tau
        if v > 0.0:
            lo = tau
        else:
            hi = tau
        if hi - lo <= 1e-15:
            return hi
        slope = a * (x3t - kc)
        newton = tau - v / slope if slope != 0.0 else math.nan
        tau = newton if lo < newton < hi else 0.5 * (lo + hi)
    return tau
