"""Acker's pulse law as a controller assumes it: the closed-form response of the idealized plant.

This is the *model* a pulse controller carries (solnic's internal plant model, its braking
pair, grid posterior and noise model; section 6.1, (3-20)/(3-21)): the shaft of Table 2-1's
structure — rigid, Coulomb plus stiction, first-order motor lag, switched bridge with flyback —
evaluated in closed form with whatever parameters the controller believes. It is not the
simulator: the true plant of a scenario may be another family altogether, and controllers are
told only its nominal :class:`~plant.params.PlantParams`. On the idealized plant itself the
two agree to round-off (tests/test_acker_model.py checks this against the exact event-driven
simulator, :func:`plant.pulse_response`).

From rest (stuck, x3 = x4 = x5 = 0) the bridge applies sign·u_max for Δt_u, then the flyback
diodes −sign·u_max until the current is zero, then 0. The phases: stuck until x3 = k̄s
(t_b = −τ3·ln(1 − k̄s/u_max)), driven (reflecting while x3 > k̄s), flyback, coast
(ẋ2 = −α·k̄c).
"""

from __future__ import annotations

import math

from numba import njit

from controllers.base import ControllerDiverged
from plant.expfun import e1, e2
from plant import PulseResponse
from plant.params import PlantParams

__all__ = ["pulse_response", "max_on_time", "closed_form_kernel", "move_closed_form", "velocity_root"]


def pulse_response(params: PlantParams, dt_u: float, *, sign: int = 1, seed: int | None = None) -> PulseResponse:
    """The noise-free pulse of the model ``params`` in closed form (``seed`` must be None).

    The interface of :func:`plant.pulse_response`, so that a controller's predictor can take
    either (tests inject the simulator); raises ``RuntimeError`` when k̄c = 0 (the shaft
    coasts for ever).
    """
    if seed is not None:
        raise ValueError("the closed-form model is noise-free: seed must be None")
    if not isinstance(dt_u, (int, float)) or isinstance(dt_u, bool) or not (dt_u >= 0 and math.isfinite(dt_u)):
        raise ValueError(f"dt_u must be a finite number of seconds >= 0, got {dt_u!r}")
    if sign not in (1, -1):
        raise ValueError(f"sign must be +1 or -1, got {sign!r}")
    if dt_u == 0.0:
        return PulseResponse(0.0, None, 0.0, 0.0)
    return _closed_form(params, float(dt_u), sign)


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
        raise ControllerDiverged("the pulse model coasts for ever after the pulse: k̄c = 0")
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
