"""The cost of one correction cycle, (6-1)–(6-5), and the calibration of a_c.

For a pulse of on-time Δt_u predicting the motion Δc_p::

    C1 = √(Δc_p² + VAR(Δc_p) + VAR[x̂1])                         (6-1)  [rad]
    Q  = (u_max/β3)·(β3Δt_u − 1 + e^(−β3Δt_u))                   (6-2), SPEC §9  [ozf·in·s]
    T  = |Δc_p| / |x̂4|                                           (6-3)  [s]
    C2 = a_c·Q/T                                                 (6-4)
    J  = C1 + C2                                                 (6-5)

Q is the on-phase charge in torque-equivalent units (the text's (6-2) drops the 1/β3 factor),
so Q/T is an average current [ozf·in] and a_c is in rad per ozf·in. The text neglects both
variances in (6-1) ("negligible ... neglected for the examples run"); so does the default here.
A pulse that does not move the shaft has T = 0 and J = +inf.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

from scipy.optimize import brentq, minimize_scalar

from plant.params import PlantParams

__all__ = ["charge", "cycle_period", "CycleCost", "cycle_cost", "cost_curve",
           "calibrate_error_cost", "ErrorCostCalibration", "optimal_increment", "optimal_dtu",
           "peak_error_of_cycle"]


def charge(dt_u: float, u_max: float, beta3: float) -> float:
    """On-phase charge Q = (u_max/β3)(β3Δt_u − 1 + e^(−β3Δt_u)) [ozf·in·s]  (6-2), SPEC §9."""
    if dt_u <= 0:
        return 0.0
    x = beta3 * dt_u
    return (u_max / beta3) * (x + math.expm1(-x))


def cycle_period(delta_c: float, x4: float) -> float:
    """T = |Δc_p|/|x̂4| [s]  (6-3); inf when x̂4 = 0."""
    if x4 == 0:
        return math.inf
    return abs(delta_c) / abs(x4)


def peak_error_of_cycle(delta_c: float) -> float:
    """Noise-free peak |x1| of a steady cycle of motion Δc, triggered at x1 = ∓Δc/2 (6.1).

    The error reaches Δc/2 on the trigger side; on the far side the correction lands at
    +Δc/2 less the drift x4·t during the motion, so the peak is |Δc|/2.
    """
    return abs(delta_c) / 2.0


@dataclass(frozen=True)
class CycleCost:
    """The terms of (6-1)–(6-5) for one pulse size."""

    dt_u: float
    delta_c: float
    error_cost: float      # C1 [rad]
    charge: float          # Q [ozf·in·s]
    period: float          # T [s]
    effort_cost: float     # C2 [rad]
    total: float           # J [rad]


def cycle_cost(dt_u: float, delta_c: float, x4: float, a_c: float, params: PlantParams,
               var_delta_c: float = 0.0, var_x1: float = 0.0) -> CycleCost:
    """J = C1 + a_c·Q/T for one pulse size  (6-1)–(6-5)."""
    q = charge(dt_u, params.u_max, params.beta3)
    if delta_c == 0.0 or dt_u <= 0:
        return CycleCost(dt_u, delta_c, math.inf, q, 0.0, math.inf, math.inf)
    c1 = math.sqrt(delta_c**2 + var_delta_c + var_x1)                    # (6-1)
    period = cycle_period(delta_c, x4)                                   # (6-3)
    c2 = a_c * q / period if math.isfinite(period) else 0.0              # (6-4)
    return CycleCost(dt_u, delta_c, c1, q, period, c2, c1 + c2)          # (6-5)


def cost_curve(motion: Callable[[float], float], params: PlantParams, x4: float,
               a_c: float) -> Callable[[float], float]:
    """J(Δt_u) for a motion model ``motion(Δt_u) -> |Δc_p|`` (variances neglected)."""

    def J(dt_u: float) -> float:
        dc = motion(dt_u) if dt_u > 0 else 0.0
        return cycle_cost(dt_u, dc, x4, a_c, params).total

    return J


def _true_motion(params: PlantParams, response_fn=None) -> Callable[[float], float]:
    if response_fn is None:
        from controllers.models.acker import pulse_response as response_fn
    cache: dict[float, float] = {}

    def motion(dt_u: float) -> float:
        if dt_u <= 0:
            return 0.0
        if dt_u not in cache:
            cache[dt_u] = abs(float(response_fn(params, float(dt_u), sign=1, seed=None).delta_c))
        return cache[dt_u]

    return motion


def optimal_dtu(params: PlantParams, a_c: float, x4: float | None = None, response_fn=None,
                upper: float | None = None) -> float:
    """The Δt_u minimising the noise-free cost curve of the true plant [s] (bounded Brent)."""
    x4 = params.command_velocity_initial if x4 is None else x4
    motion = _true_motion(params, response_fn)
    J = cost_curve(motion, params, x4, a_c)
    lo = params.breakaway_time * (1.0 + 1e-9)
    hi = upper if upper is not None else 10.0 * params.breakaway_time
    # bracket coarsely first: the curve can have local bumps near breakaway
    grid = [lo + (hi - lo) * i / 400 for i in range(1, 401)]
    best = min(grid, key=J)
    step = (hi - lo) / 400
    res = minimize_scalar(J, bounds=(max(lo, best - step), min(hi, best + step)),
                          method="bounded", options={"xatol": 1e-12})
    return float(res.x)


def optimal_increment(params: PlantParams, dtu_opt: float, a_ratio: float = 2.0,
                      response_fn=None) -> float:
    """The Δt_u,inc at which Δc(opt + inc)/Δc(opt − inc) = a_ratio, the fixed point of (6-9) [s].

    This is the "properly adjusted" increment against which section 7.3's "four times too
    large" initial value is measured.
    """
    motion = _true_motion(params, response_fn)
    hi = dtu_opt - params.breakaway_time      # opt − inc must still move the shaft
    f = lambda inc: motion(dtu_opt + inc) / max(motion(dtu_opt - inc), 1e-300) - a_ratio
    return float(brentq(f, 1e-9, hi * (1 - 1e-9), xtol=1e-15))


@dataclass(frozen=True)
class ErrorCostCalibration:
    """Result of :func:`calibrate_error_cost`."""

    a_c: float                # [rad per ozf·in]
    dtu_opt: float            # optimal medium Δt_u [s]
    delta_c: float            # its Δc [rad]
    peak_error: float         # its noise-free peak error [rad]
    dtu_inc: float            # the increment with Δc_large/Δc_small = 2 [s]
    x4: float                 # drift rate used [rad/s]


def calibrate_error_cost(params: PlantParams | None = None, target_peak: float = 1.4e-6,
                         x4: float | None = None, response_fn=None) -> ErrorCostCalibration:
    """The a_c for which the optimal medium correction has a noise-free peak error ``target_peak``.

    With true parameters, no noise and drift x4 (default: ``command_velocity_initial``,
    30 µrad/s), a cycle of motion Δc has peak error Δc/2 (:func:`peak_error_of_cycle`). So the
    target fixes Δc* = 2·target and Δt_u* with Δc(Δt_u*) = Δc*. Stationarity of
    J = Δc + a_c·Q·x4/Δc at Δt_u* gives, with Δc' and Q' the derivatives in Δt_u::

        Δc'·(1 − a_c Q x4/Δc²) + a_c x4 Q'/Δc = 0
        ⇒  a_c = Δc'·Δc² / (x4·(Q·Δc' − Q'·Δc))

    The result is checked to be the global minimum of the cost curve.
    """
    params = PlantParams() if params is None else params
    x4 = params.command_velocity_initial if x4 is None else float(x4)
    motion = _true_motion(params, response_fn)
    target_dc = 2.0 * target_peak
    tb = params.breakaway_time
    hi = tb * 1.01
    while motion(hi) < target_dc:
        hi *= 1.2
        if hi > 1.0:
            raise ValueError(f"target_peak {target_peak!r} is out of reach")
    lo = tb * (1 + 1e-9)
    if motion(lo) >= target_dc:
        raise ValueError(f"target_peak {target_peak!r} is below the smallest motion Δc_min/2")
    dtu = brentq(lambda d: motion(d) - target_dc, lo, hi, xtol=1e-15, rtol=1e-14)
    h = 1e-8
    dc = motion(dtu)
    d_dc = (motion(dtu + h) - motion(dtu - h)) / (2 * h)
    q = charge(dtu, params.u_max, params.beta3)
    d_q = (charge(dtu + h, params.u_max, params.beta3) - charge(dtu - h, params.u_max, params.beta3)) / (2 * h)
    denom = x4 * (q * d_dc - d_q * dc)
    if not denom > 0:
        raise ValueError(f"no positive a_c makes target_peak {target_peak!r} stationary")
    a_c = d_dc * dc**2 / denom
    opt = optimal_dtu(params, a_c, x4, response_fn, upper=max(4 * dtu, 3 * tb))
    if abs(opt - dtu) > 1e-3 * dtu:
        raise ValueError(f"target_peak {target_peak!r}: stationary point {dtu!r} s is not the "
                         f"global minimum of the cost ({opt!r} s)")
    inc = optimal_increment(params, dtu, 2.0, response_fn)
    return ErrorCostCalibration(a_c=float(a_c), dtu_opt=float(dtu), delta_c=float(dc),
                                peak_error=peak_error_of_cycle(dc), dtu_inc=inc, x4=x4)
