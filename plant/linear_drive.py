"""The drive signal of a fixed linear law on a linear amplifier: compensator and square-wave dither.

A controller that describes its step as a fixed linear law (:class:`controllers.law.LinearLaw`)
computes, at every sample instant n·τs with measurement y(n),

    v(n) = C·x(n) + D·y(n),    x(n+1) = A·x(n) + B·y(n)                  (the realization of C(z))
    u(t) = clip(−v(n) + A_d·sq(f_d·t + φ), ±u_max),   t ∈ [n·τs, (n+1)·τs)

These compiled functions are that computation, once: the controllers call them at every step,
and a family's compiled closed loop (``PlantFamily.linear_law_loop``) calls the same code, so
the two paths give the same bits.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["compensator_step", "square_wave_segments", "EDGE_TOL_S"]

EDGE_TOL_S = 1e-12   # switches closer than this to an interval edge are merged into it
_EDGE_TOL_S = EDGE_TOL_S


@njit(cache=True)
def compensator_step(A, B, C, D, x, x_next, y):
    """v = C·x + D·y [ozf·in] and x_next = A·x + B·y (written in place); returns v.

    The order of the floating-point operations is fixed: D·y first, then the C·x terms in
    order; each row B·y plus (the A·x terms in order).
    """
    n = x.shape[0]
    v = D[0, 0] * y
    for j in range(n):
        v += C[0, j] * x[j]
    for i in range(n):
        acc = A[i, 0] * x[0]
        for j in range(1, n):
            acc += A[i, j] * x[j]
        x_next[i] = B[i, 0] * y + acc
    return v


@njit(cache=True)
def square_wave_segments(t0, duration, base, amplitude, frequency_hz, phase, limit, offs, levs):
    """Segments of clip(base + A·sq(f·t + φ), ±limit) on [t0, t0 + duration) into (offs, levs).

    t0, duration [s]; base, amplitude A, limit [ozf·in]; frequency_hz f [Hz]; phase φ
    [cycles]. sq(θ) = +1 for frac(θ) < ½, else −1; no dither when A = 0. Edges closer than
    1e-12 s to the interval's ends merge into them, and each segment's level is read at its
    midpoint (immune to round-off at the edges). Returns the number of segments written.
    """
    if amplitude == 0.0:
        offs[0] = 0.0
        levs[0] = min(max(base, -limit), limit)
        return 1
    high = min(max(base + amplitude, -limit), limit)
    low = min(max(base - amplitude, -limit), limit)
    cycles0 = frequency_hz * t0 + phase
    k = math.floor(2.0 * cycles0) + 1
    n_seg = 0
    a = 0.0
    last = math.nan
    have_last = False
    off = (0.5 * k - cycles0) / frequency_hz
    done = False
    while not done:
        if off < duration - _EDGE_TOL_S:
            if not (off > _EDGE_TOL_S):
                k += 1
                off = (0.5 * k - cycles0) / frequency_hz
                continue
            b = off
            k += 1
            off = (0.5 * k - cycles0) / frequency_hz
        else:
            b = duration
            done = True
        theta = cycles0 + frequency_hz * 0.5 * (a + b)
        level = high if theta - math.floor(theta) < 0.5 else low
        if not have_last or level != last:
            offs[n_seg] = a
            levs[n_seg] = level
            n_seg += 1
            last = level
            have_last = True
        a = b
    return n_seg
