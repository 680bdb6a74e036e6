"""Closed-form facts about one constant-drive segment: torque events, exact integrals, peaks.

Within a segment the drive level u is constant, so the motor torque is deterministic:
x3(τ) = u + (x3₀ − u)·e^(−β3·τ). Every torque event (breakaway, flyback end, the end of the
reflection regime) is therefore a closed-form time, and every current metric an exact
integral (SPEC §3). Compiled with numba; callable from Python as well.
"""

from __future__ import annotations

import math

from numba import njit

from plant.expfun import e1

__all__ = ["torque_crossing_time", "torque_integrals", "torque_integrals_given", "hermite_peak"]


@njit(cache=True, _nrt=False)
def torque_crossing_time(x3, u, level, tau3):
    """Time for x3(τ) = u + (x3 − u)e^(−τ/τ3) to reach ``level``; ``inf`` if it never does.

    x3 moves monotonically from x3 toward u, so ``level`` is reached once iff it lies strictly
    between them. Starting exactly at ``level`` is not a future crossing (the torque leaves it).
    """
    gap0 = x3 - u
    gap1 = level - u
    if gap0 == 0.0 or gap1 == 0.0 or (gap0 > 0) != (gap1 > 0):
        return math.inf
    if abs(gap0) >= abs(gap1) * 1e300:
        return math.inf
    ratio = gap0 / gap1
    if ratio <= 1.0:
        return math.inf
    return tau3 * math.log(ratio)


@njit(cache=True, _nrt=False)
def torque_integrals(x3, u, h, tau3):
    """Exact (∫x3 dτ, ∫|x3| dτ, ∫x3² dτ) over [0, h]."""
    if h <= 0:
        return 0.0, 0.0, 0.0
    b3 = 1.0 / tau3
    return torque_integrals_given(x3, u, h, tau3, e1(b3 * h) * tau3,     # ∫ e^(−β3τ)
                                  e1(2 * b3 * h) * tau3 / 2.0)          # ∫ e^(−2β3τ)


@njit(cache=True, _nrt=False)
def torque_integrals_given(x3, u, h, tau3, f1, f2):
    """:func:`torque_integrals` (h > 0) with its f1 = e1(h/τ3)·τ3 and f2 = e1(2h/τ3)·τ3/2 given
    (a caller that keeps them for a repeated width)."""
    b3 = 1.0 / tau3
    g = x3 - u
    integral = u * h + g * f1
    square = u * u * h + 2 * u * g * f1 + g * g * f2
    t0 = torque_crossing_time(x3, u, 0.0, tau3)
    if t0 < h:
        first = u * t0 + g * e1(b3 * t0) * tau3
        absolute = abs(first) + abs(integral - first)
    else:
        absolute = abs(integral)
    return integral, absolute, square


@njit(cache=True, _nrt=False)
def hermite_peak(h, ya, da, yb, db):
    """Largest |y| at interior critical points of the cubic Hermite interpolant on [0, h].

    Used for the peak of x1 inside a noisy sub-step, where x1 is C¹ with slope ẋ1 = x2 − x4
    known at both ends. Returns 0 when the cubic has no interior extremum.
    """
    if h <= 0:
        return 0.0
    c2 = 3 * (yb - ya) - (2 * da + db) * h
    c3 = -2 * (yb - ya) + (da + db) * h
    A, B, C = 3 * c3, 2 * c2, da * h
    best = 0.0
    r0 = r1 = 0.0           # the roots in scalars: nothing allocated (plant.multimode.interval's
    nr = 0                  # fast path is compiled without reference counting)
    if A == 0.0:
        if B != 0.0:
            r0 = -C / B
            nr = 1
    else:
        disc = B * B - 4 * A * C
        if disc >= 0:
            sq = math.sqrt(disc)
            q = -0.5 * (B + math.copysign(sq, B))
            if q != 0.0:
                r0, r1 = q / A, C / q
                nr = 2
    for i in range(nr):
        s = r0 if i == 0 else r1
        if 0.0 < s < 1.0:
            v = abs(ya + da * h * s + c2 * s * s + c3 * s ** 3)
            if v > best:
                best = v
    return best
