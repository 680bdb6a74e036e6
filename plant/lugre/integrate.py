"""The LuGre system's integrator: Dormand–Prince 5(4) with error control (plant.dopri).

y = (v, z, D) of :mod:`plant.lugre.law`, x3, x4, x5 exact. Local error control on the RMS of
e_i/(ATOL_i + RTOL·max|y_i|), with the displacement's error measured against the step's own
increment (D accumulates over a segment): RTOL = 1e-10, ATOL = (1e-13 rad/s, 1e-18 rad,
1e-18 rad). Order 5 (local extrapolation), error estimate order 4.

Why explicit (issue 23 asked for an implicit scheme where stiff; measured at the default gimbal
parameters, α = 1/J = 2, σ0 = 1e6, σ1 = 707, σ2 = 0.2, kc = 1.4, ks = 2.1, v_s = 4e-3):

- Jacobian of (v, z) (tests/test_lugre.py checks these against finite differences of ``rhs``).
  Pre-sliding (v ≈ 0): the bristle oscillator, λ = −707 ± 1225i, |λ| = √(σ0/J) = 1414 /s, so
  Dormand–Prince's stability limit (|hλ| ≲ 3.3) is h ≲ 2.3 ms. Steady sliding at v ≫ v_s:
  λ = −σ0·|v|/g (bristles) and −α·σ2 = −0.4 /s; the fast one is 7.1e3 /s at 0.01 rad/s
  (h ≲ 0.46 ms), 2.1e4 at 0.03 (0.15 ms), 7.1e4 at 0.1 (46 µs).
- The step the accuracy needs (x1 to 1e-8 of its largest value: RTOL 1e-10) is 16 µs
  (accelerating under a full pulse) to 160 µs (noise-free closed loops: 10 ms / 62–85 steps).
  So the law is stiff only while sliding faster than ≈ 0.03–0.05 rad/s. A full 2 ms bridge pulse
  peaks at 4.8 mrad/s: its drive and coast steps follow the tolerance (126 and 201 steps at
  1e-10 against 21 and 112 at 1e-6, order-5 accuracy-bound). After a full 10 ms pulse
  (0.15 rad/s) the 20 ms coast takes 1165 steps at every tolerance from 1e-6 to 1e-10:
  stability-bound, there an L-stable implicit scheme would win.
- In the benchmark's closed loops the shaft rarely slides that fast. At sample instants the
  largest |λ| was 1675 /s for linear, 1421 for pulse-width and 2329 for solnic-modern (20 s,
  seed 0). Noise-free, rtol 1e-6 → 1e-10 multiplies their steps by 4.1, 4.0 and 3.5: mostly
  accuracy-bound.
- ROS3P (order 3, tried earlier) needed ~1900 steps per ms of sliding at this tolerance (20×
  Dormand–Prince). Not being L-stable with this non-normal Jacobian (∂v̇/∂z ≈ 2e7), it settled
  1e-6 off in coasting.

With noise (the scenarios) the flow runs at ``NOISY_TOLERANCES`` (RTOL 1e-6, ATOL ×1e4): the
noisy path's x1 stays within 7.4e-7 of its largest value against Radau on the five parameter
sets (every intensity 0, the noisy path taken), below 1 % of the spread Table 2-1's noise gives
x1 (tests/test_lugre.py), while at 1e-10 the noisy linear loop took 233 steps per sample for
nothing. Linear on ``lugre``: 45–51 steps per sample (seeds 0, 1; was 233 at a 0.1 ms noise
grid), bound by the bristle ringing and a restart at each noise-driven mode change.

The explicit step becomes stability-bound everywhere only for σ0 ≳ 1e9 ozf·in/rad. The step
then shrinks like 1/σ0, which the error control does by itself: slower, not wrong.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.dopri import A, B, C as C_NODES, E
from plant.lugre.law import C_P0, C_TH0, C_U, C_X30, C_X50, L_BETA3, L_BETA4, L_BETA5, L_VS, rhs
from plant.multimode.segments import hermite_peak

__all__ = ["rk_segment", "segment", "scratch", "TOLERANCES", "NOISY_TOLERANCES"]

# [RTOL, ATOL_v [rad/s], ATOL_z [rad], ATOL_D [rad]]
TOLERANCES = np.array([1e-10, 1e-13, 1e-18, 1e-18])
TOLERANCES.flags.writeable = False
# with noise on, 1e4 × looser: RTOL 1e-6 (module docstring, "With noise")
NOISY_TOLERANCES = TOLERANCES * 1e4
NOISY_TOLERANCES.flags.writeable = False
_H0 = 1e-6

A1, A2, A3, A4, A5, AKC, AU, ATH, AZ = range(9)


@njit(cache=True)
def _step(t, y, f1, h, C, L, K, yn, tmp):
    """One Dormand–Prince step: yn, K (7 × 3 stage slopes, K[6] at yn) and the error vector in K[7];
    ``tmp`` (3) is scratch."""
    K[0, 0], K[0, 1], K[0, 2] = f1[0], f1[1], f1[2]
    for i in range(1, 6):
        for c in range(3):
            acc = 0.0
            for j in range(i):
                acc += A[i, j] * K[j, c]
            tmp[c] = y[c] + h * acc
        K[i, 0], K[i, 1], K[i, 2], _ = rhs(t + C_NODES[i] * h, tmp[0], tmp[1], tmp[2], C, L)
    for c in range(3):
        acc = 0.0
        for i in range(6):
            acc += B[i] * K[i, c]
        yn[c] = y[c] + h * acc
    K[6, 0], K[6, 1], K[6, 2], _ = rhs(t + h, yn[0], yn[1], yn[2], C, L)
    for c in range(3):
        acc = 0.0
        for i in range(7):
            acc += E[i] * K[i, c]
        K[7, c] = h * acc


@njit(cache=True)
def _mode_of(v, vth):
    if v > vth:
        return 3
    if v < -vth:
        return 1
    return 2


@njit(cache=True)
def scratch():
    """The work arrays of :func:`segment` (allocate once, reuse for every segment)."""
    return np.empty(18), np.empty((8, 3))


@njit(cache=True)
def rk_segment(X, H, L, peak, hbox, vth, mode, spring_p0, tol):
    """Integrate noise-free for up to H [s] at constant u, stopping early where the mode (x2
    beyond ±vth) changes at a step end: (advanced, new mode, peak, steps)."""
    W, K = scratch()
    return segment(X, H, L, peak, hbox, vth, mode, spring_p0, tol, W, K, math.inf, math.inf)


@njit(cache=True)
def segment(X, H, L, peak, hbox, vth, mode, spring_p0, tol, W, K, eps, hcap):
    """:func:`rk_segment` with its work arrays (W, K) = :func:`scratch` passed in: the same
    arithmetic, without the allocations (the caller runs it many times per sample).

    With noise (``eps`` finite): W[17] = ∫ s(v)² dt over the advance (trapezoid on the step
    ends), s(v)² = 1 − exp(−(v/v_s)²) the sliding part of the contact through which w2 acts. A
    segment that starts in pre-sliding (s² ≤ eps) also stops at the first step end where
    s² > eps, and a step that gets there longer than ``hcap`` [s] is retaken 4× shorter, so
    the shaft leaves pre-sliding on the noise grid. ``eps = math.inf``: none of this arithmetic
    (the noise-free path)."""
    u, x30, x40, x50, th0, x10 = X[AU], X[A3], X[A4], X[A5], X[ATH], X[A1]
    C = W[0:5]
    C[C_U], C[C_X30], C[C_X50], C[C_TH0], C[C_P0] = u, x30, x50, th0, spring_p0
    y = W[5:8]
    y[0], y[1], y[2] = X[A2], X[AZ], 0.0
    yn = W[8:11]
    f1 = W[11:14]
    tmp = W[14:17]
    f1[0], f1[1], f1[2], _ = rhs(0.0, y[0], y[1], y[2], C, L)
    b4 = L[L_BETA4]
    t = 0.0
    h = hbox[0] if hbox[0] > 0.0 else _H0
    steps = 0
    new_mode = mode
    noisy = eps < math.inf
    inv_vs = 1.0 / L[L_VS]
    s2a = -math.expm1(-(y[0] * inv_vs) ** 2) if noisy else 0.0
    stretch = noisy and s2a <= eps
    quad, s2b = 0.0, 0.0
    while t < H:
        last = h >= H - t
        hh = H - t if last else h
        _step(t, y, f1, hh, C, L, K, yn, tmp)
        steps += 1
        acc = 0.0
        for c in range(3):
            if c < 2:
                sc = tol[1 + c] + tol[0] * max(abs(y[c]), abs(yn[c]))
            else:
                sc = tol[3] + tol[0] * hh * max(abs(y[0]), abs(yn[0]))
            acc += (K[7, c] / sc) ** 2
        err = math.sqrt(acc / 3.0)
        if not err <= 1.0:
            h = hh * max(0.2, 0.9 * err ** -0.2) if math.isfinite(err) else 0.2 * hh
            if steps > 5_000_000:
                break
            continue
        if noisy:
            s2b = -math.expm1(-(yn[0] * inv_vs) ** 2)
            if stretch and s2b > eps and hh > hcap:     # leaving pre-sliding: on the noise grid
                h = 0.25 * hh
                continue
        x1a = x10 + y[2] - x40 * (-math.expm1(-b4 * t)) / b4
        x1b = x10 + yn[2] - x40 * (-math.expm1(-b4 * (t + hh))) / b4
        peak = max(peak, abs(x1b),
                   hermite_peak(hh, x1a, y[0] - x40 * math.exp(-b4 * t), x1b, yn[0] - x40 * math.exp(-b4 * (t + hh))))
        t = H if last else t + hh
        y[0], y[1], y[2] = yn[0], yn[1], yn[2]
        f1[0], f1[1], f1[2] = K[6, 0], K[6, 1], K[6, 2]
        if not last:
            h = hh * (5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2)))
        new_mode = _mode_of(y[0], vth)
        if noisy:
            quad += 0.5 * hh * (s2a + s2b)
            s2a = s2b
            if stretch and s2b > eps:
                break
        if new_mode != mode:
            break
    W[17] = quad
    hbox[0] = h
    X[A1] = x10 + y[2] - x40 * (-math.expm1(-b4 * t)) / b4
    X[A2] = y[0]
    X[AZ] = y[1]
    X[A3] = u + (x30 - u) * math.exp(-L[L_BETA3] * t)
    X[A4] = x40 * math.exp(-b4 * t)
    X[A5] = x50 * math.exp(-L[L_BETA5] * t)
    X[ATH] = th0 + y[2]
    return t, new_mode, peak, steps
