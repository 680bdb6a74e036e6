"""Modes 1 and 3 of the ``stribeck`` family: the shaft slides under the Stribeck law.

Within one constant-drive segment the linear part is exact: x3(t) = u + (x3₀ − u)·e^(−β3·t)
and, noise-free, x4(t) = x4₀·e^(−β4·t), x5(t) = x5₀·e^(−β5·t). What is left is the pair
y = (v, D), v = x2 and D = ∫v dt (the load's displacement in the segment):

    v̇ = α·(x3(t) − s·F(|v|; kc(θ₀ + D, x5(t)), ks(…)))      Ḋ = v        (s = ±1, the mode)

and x1 = x1₀ + D − x4₀·τ4·(1 − e^(−β4·t)), θ = θ₀ + D.

Noise-free (:func:`rk_segment`): Dormand–Prince 5(4) (plant.dopri), order 5 with
local extrapolation, error control per step on the RMS of e_i/(ATOL_i + RTOL·max|y_i|) with
RTOL = 1e-10, ATOL = (1e-13 rad/s, 1e-17 rad). Velocity zero is found on the quartic dense
output (sign changes at θ = ¼, ½, ¾, 1), by bisection to round-off, and then polished by
Newton steps on a fresh RK step to the root (to the integrator's accuracy, not the
interpolant's). The peak |x1| is taken at the dense output's roots of ẋ1 = v − x4.

With noise (:func:`noisy_segment`): fixed sub-steps. v by the stochastic Heun scheme
(predictor v + a·h + g·ΔW, corrector with the mean drift; Kloeden & Platen 1992, (15.1.1)
for additive noise g = α·σ2: weak order 2 away from v = 0), D by the trapezoid of the same
stages, x3 exact, (x1, x4) and x5 by their exact Gaussian transitions. A velocity zero in a
sub-step is detected by the sign change or the Brownian-bridge crossing probability
exp(−2·v_a·v_b/(g²·h)), located by bridge bisection to ``bisection_tol`` (SPEC §2), where the
switching table applies; in the reflection regime (s·x3 > ks) the end value is reflected.
The crossing treatment makes the scheme weak order 1 overall (tests/test_stribeck.py checks
it against a fine Euler–Maruyama reference).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.multimode.segments import hermite_peak
from plant.multimode.stuck import stuck_propagate
from plant.randomness import normal, uniform_below
from plant.dopri import A, B, C, E, dense_coefficients, dense_value
from plant.stribeck.law import L_ALPHA, L_BETA3, L_BETA4, L_BETA5, L_SIGMA2_SQ, L_SIGMA5_SQ, acceleration, \
    effective_levels

__all__ = ["rk_segment", "noisy_segment", "RTOL", "ATOL_V", "ATOL_D", "ATH"]

A1, A2, A3, A4, A5, AKC, AU, ATH = range(8)
RTOL = 1e-10
ATOL_V = 1e-13      # rad/s
ATOL_D = 1e-17      # rad
_H0 = 1e-7          # first trial step from rest [s]


@njit(cache=True)
def _rhs(t, v, D, s, u, x30, x50, th0, L):
    x3 = u + (x30 - u) * math.exp(-L[L_BETA3] * t)
    x5 = x50 * math.exp(-L[L_BETA5] * t)
    return acceleration(s, v, x3, x5, th0 + D, L)


@njit(cache=True)
def _dopri_step(t, v, D, f1, h, s, u, x30, x50, th0, L, Kv, KD):
    """One Dormand–Prince step of size h from (t, v, D) with v̇(t) = f1: (v⁺, D⁺, err_v, err_D).

    Fills Kv, KD with the seven stage slopes (the seventh at the new point, FSAL)."""
    Kv[0] = f1
    KD[0] = v
    for i in range(1, 6):
        dv = 0.0
        dD = 0.0
        for j in range(i):
            dv += A[i, j] * Kv[j]
            dD += A[i, j] * KD[j]
        vi = v + h * dv
        Di = D + h * dD
        Kv[i] = _rhs(t + C[i] * h, vi, Di, s, u, x30, x50, th0, L)
        KD[i] = vi
    vn = v
    Dn = D
    for i in range(6):
        vn += h * B[i] * Kv[i]
        Dn += h * B[i] * KD[i]
    Kv[6] = _rhs(t + h, vn, Dn, s, u, x30, x50, th0, L)
    KD[6] = vn
    ev = 0.0
    eD = 0.0
    for i in range(7):
        ev += E[i] * Kv[i]
        eD += E[i] * KD[i]
    return vn, Dn, h * ev, h * eD


@njit(cache=True)
def _x1_dense(theta, t, h, x10, D, QD, x40, L):
    tt = t + theta * h
    return x10 + dense_value(D, h, QD, theta) - x40 * (-math.expm1(-L[L_BETA4] * tt)) / L[L_BETA4]


@njit(cache=True)
def _x1_slope(theta, t, h, v, Qv, x40, L):
    return dense_value(v, h, Qv, theta) - x40 * math.exp(-L[L_BETA4] * (t + theta * h))


@njit(cache=True)
def _peak_on_step(peak, t, h, theta_end, v, D, Qv, QD, x10, x40, L):
    """Largest |x1| on the dense output over θ ∈ [0, θ_end] (ends and interior extrema)."""
    prev_th = 0.0
    prev_sl = _x1_slope(0.0, t, h, v, Qv, x40, L)
    for k in range(1, 5):
        th = theta_end * k / 4.0
        peak = max(peak, abs(_x1_dense(th, t, h, x10, D, QD, x40, L)))
        sl = _x1_slope(th, t, h, v, Qv, x40, L)
        if (sl > 0.0) != (prev_sl > 0.0) and sl != 0.0 and prev_sl != 0.0:
            lo, hi, slo = prev_th, th, prev_sl
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                sm = _x1_slope(mid, t, h, v, Qv, x40, L)
                if (sm > 0.0) == (slo > 0.0):
                    lo, slo = mid, sm
                else:
                    hi = mid
                if hi - lo <= 1e-15:
                    break
            peak = max(peak, abs(_x1_dense(0.5 * (lo + hi), t, h, x10, D, QD, x40, L)))
        prev_th, prev_sl = th, sl
    return peak


@njit(cache=True)
def rk_segment(X, s, H, L, peak, hbox):
    """Slide noise-free for up to H [s] (constant u): (advanced, stopped, peak, steps).

    On a stop X holds the state at the velocity zero with x2 set to 0; else at H. ``hbox[0]``
    carries the step size from one call to the next.
    """
    u, x30, x40, x50, th0, x10 = X[AU], X[A3], X[A4], X[A5], X[ATH], X[A1]
    Kv = np.empty(7)
    KD = np.empty(7)
    Qv = np.empty(4)
    QD = np.empty(4)
    v = X[A2]
    D = 0.0
    t = 0.0
    f1 = _rhs(0.0, v, D, s, u, x30, x50, th0, L)
    # from rest (breakaway, reversal) the slide starts like t² (or t^(1 + 1/(1 − δ))-ish for δ < 1,
    # where the law is not smooth at v = 0): start small and let the controller grow the step
    h = hbox[0] if hbox[0] > 0.0 and v != 0.0 else _H0
    steps = 0
    stopped = False
    while t < H:
        last = h >= H - t
        hh = H - t if last else h
        vn, Dn, ev, eD = _dopri_step(t, v, D, f1, hh, s, u, x30, x50, th0, L, Kv, KD)
        sv = ATOL_V + RTOL * max(abs(v), abs(vn))
        sD = ATOL_D + RTOL * max(abs(D), abs(Dn))
        err = math.sqrt(0.5 * ((ev / sv) ** 2 + (eD / sD) ** 2))
        steps += 1
        if not err <= 1.0:
            h = hh * max(0.2, 0.9 * err ** -0.2) if math.isfinite(err) else 0.2 * hh
            if steps > 100_000:
                break
            continue
        dense_coefficients(Kv, Qv)
        dense_coefficients(KD, QD)
        # velocity zero on the dense output: the first quarter point where s·v ≤ 0
        th_lo = 0.0
        th_hi = -1.0
        for k in range(1, 5):
            th = k / 4.0
            vk = vn if k == 4 else dense_value(v, hh, Qv, th)
            if s * vk <= 0.0:
                th_hi = th
                break
            th_lo = th
        if th_hi > 0.0:
            lo, hi = th_lo, th_hi
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                if s * dense_value(v, hh, Qv, mid) > 0.0:
                    lo = mid
                else:
                    hi = mid
                if hi - lo <= 2e-16:
                    break
            hc = hi * hh
            # polish on the integrator itself: Newton on v(t + hc) = 0
            Kv2 = np.empty(7)
            KD2 = np.empty(7)
            vc, Dc, _, _ = _dopri_step(t, v, D, f1, hc, s, u, x30, x50, th0, L, Kv2, KD2)
            for _ in range(3):
                slope = Kv2[6]
                if slope == 0.0 or vc == 0.0:
                    break
                hn = hc - vc / slope
                if not (0.0 < hn <= hh):
                    break
                hc = hn
                vc, Dc, _, _ = _dopri_step(t, v, D, f1, hc, s, u, x30, x50, th0, L, Kv2, KD2)
            peak = _peak_on_step(peak, t, hh, min(hc / hh, 1.0), v, D, Qv, QD, x10, x40, L)
            t += hc
            D = Dc
            v = 0.0
            stopped = True
            break
        peak = _peak_on_step(peak, t, hh, 1.0, v, D, Qv, QD, x10, x40, L)
        t = H if last else t + hh
        v, D, f1 = vn, Dn, Kv[6]
        fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2))
        if not last:
            h = hh * fac
    hbox[0] = h
    b3, b4, b5 = L[L_BETA3], L[L_BETA4], L[L_BETA5]
    X[A1] = x10 + D - x40 * (-math.expm1(-b4 * t)) / b4
    X[A2] = v
    X[A3] = u + (x30 - u) * math.exp(-b3 * t)
    X[A4] = x40 * math.exp(-b4 * t)
    X[A5] = x50 * math.exp(-b5 * t)
    X[ATH] = th0 + D
    peak = max(peak, abs(X[A1]))
    return t, stopped, peak, steps


@njit(cache=True)
def _ou5(x5, h, L, z, cursor):
    """x5 over h while sliding: exact Ornstein–Uhlenbeck transition (rate β5, intensity σ5²)."""
    b5, q5 = L[L_BETA5], L[L_SIGMA5_SQ]
    e = math.exp(-b5 * h)
    x5n = x5 * e
    if q5 > 0.0:
        x5n += math.sqrt(q5 / (2.0 * b5) * (-math.expm1(-2.0 * b5 * h))) * normal(z, cursor)
    return x5n


@njit(cache=True)
def _move_linear(X, h, dD, vn, p, L, z, cursor):
    """Advance x1, x3, x4 (exact, with the x4 noise), x5, then add the displacement dD."""
    stuck_propagate(X, h, p, True, z, cursor)       # x1 −= ∫x4, x4 OU, x3 exact
    X[A5] = _ou5(X[A5], h, L, z, cursor)
    X[A1] += dD
    X[ATH] += dD
    X[A2] = vn


@njit(cache=True)
def noisy_segment(X, s, H, p, L, sub, rsub, tol, z, cursor, peak, budget):
    """Slide with noise for up to H [s] (constant u): (advanced, stopped, peak, sub-steps).

    On a stop (a velocity zero that is not reflected) X holds the state there with x2 = 0.
    """
    g = L[L_ALPHA] * math.sqrt(L[L_SIGMA2_SQ])
    g2 = g * g
    t = 0.0
    n = 0
    while t < H and n < budget:
        x3, u, v, x5, th = X[A3], X[AU], X[A2], X[A5], X[ATH]
        kc, ks = effective_levels(th, x5, L)
        reflecting = s * x3 > ks or (s * x3 == ks and s * u > ks)
        h = min(rsub if reflecting else sub, H - t)
        n += 1
        a0 = acceleration(s, v, x3, x5, th, L)
        dW = math.sqrt(h) * normal(z, cursor) if g > 0.0 else 0.0
        x3n = u + (x3 - u) * math.exp(-L[L_BETA3] * h)
        x5m = x5 * math.exp(-L[L_BETA5] * h)               # the drift's x5 at the end (mean)
        vt = v + a0 * h + g * dW
        a1 = acceleration(s, vt, x3n, x5m, th + v * h, L)
        vn = v + 0.5 * (a0 + a1) * h + g * dW
        crossed = s * vn <= 0.0
        if not crossed and g > 0.0 and v * vn < 25.0 * g2 * h:   # else P(cross) < e^-50
            crossed = uniform_below(z, cursor, math.exp(-2.0 * v * vn / (g2 * h)))
        x1a, sa = X[A1], v - X[A4]
        dD = 0.5 * (v + vt) * h                              # Heun's D: trapezoid of its stages
        if crossed and reflecting:
            vn = s * abs(vn)                                 # reflected at v = 0 (SPEC §2)
            dD = 0.5 * (v + vn) * h
            crossed = False
        if not crossed:
            _move_linear(X, h, dD, vn, p, L, z, cursor)
            peak = max(peak, abs(X[A1]), hermite_peak(h, x1a, sa, X[A1], vn - X[A4]))
            t += h
            continue
        # bridge bisection for the first zero in (0, h]
        lo, hi, va, vb = 0.0, h, v, vn
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            vm = 0.5 * (va + vb)
            if g > 0.0:
                vm += 0.5 * g * math.sqrt(hi - lo) * normal(z, cursor)
            if s * vm <= 0.0:
                hi, vb = mid, vm
                continue
            if g > 0.0 and va * vm < 25.0 * g2 * (mid - lo) and \
                    uniform_below(z, cursor, math.exp(-2.0 * va * vm / (g2 * (mid - lo)))):
                hi, vb = mid, vm
                continue
            lo, va = mid, vm
        tc = 0.5 * (lo + hi)
        dD = 0.5 * (v + va) * lo + 0.5 * va * (tc - lo)
        _move_linear(X, tc, dD, 0.0, p, L, z, cursor)
        peak = max(peak, abs(X[A1]), hermite_peak(tc, x1a, sa, X[A1], -X[A4]))
        return t + tc, True, peak, n
    return t, False, peak, n
