"""Compiled per-sample kernels of the PID and pulse-width peers, with exact fused multiply–add.

numpy's small products here go through OpenBLAS, whose SkylakeX kernels (the ones it picks on
this AMD EPYC with ``OPENBLAS_CORETYPE`` unset) accumulate with fused multiply–adds: a dot product ``c @ x`` is
``s = 0; s = fma(c_k, x_k, s)`` for k = 0, 1, …, and a 2 × 2 (1 × 1) matrix–vector product row
is ``fma(a_i0, x0, fma(a_i1, x1, 0))``. Python 3.11 has no ``math.fma``, so straight-line float
code cannot reproduce those bits; these kernels call LLVM's ``llvm.fma.f64`` (a correctly
rounded fma, in hardware or libm) in the same order, so the numbers are those of the numpy
expressions they replace here (whole recorded closed-loop runs compared bit for bit;
tests/test_peer_kernels.py checks the fma against exact rational arithmetic and the kernels
against the numpy forms to 1e−12), at ~0.3 µs per call instead of ~3 µs of small numpy
operations. Under another kernel (``OPENBLAS_CORETYPE=Haswell``, as this machine's shell sets it)
the numpy forms round differently (a 2-vector ``c @ x`` differed on 6584 of 20 000 random
steps); these kernels give the same numbers everywhere (docs/results.md, "Reproducibility across
machines").
"""

from __future__ import annotations

import math

import numba
import numpy as np

from plant.fixed_linalg import fma as _fma    # llvm.fma.f64, one rounding: the plant's intrinsic

__all__ = ["fma", "lead_step1", "lead_step2", "cubic_predict", "cubic_invert", "rls_update", "window_push_dot"]


@numba.njit(cache=True)
def fma(a: float, b: float, c: float) -> float:
    """a·b + c with one rounding."""
    return _fma(a, b, c)


@numba.njit(cache=True)
def lead_step1(x0, e, c0, d, a00, b0):
    """One-state lead path: (v, x0') = (C·x + D·e, A·x + B·e) as numpy computes them."""
    v = _fma(c0, x0, 0.0) + d * e
    return v, _fma(a00, x0, 0.0) + b0 * e


@numba.njit(cache=True)
def lead_step2(x0, x1, e, c0, c1, d, a00, a01, a10, a11, b0, b1):
    """Two-state lead path: (v, x0', x1') = (C·x + D·e, A·x + B·e) as numpy computes them."""
    v = _fma(c1, x1, _fma(c0, x0, 0.0)) + d * e
    n0 = _fma(a00, x0, _fma(a01, x1, 0.0)) + b0 * e
    n1 = _fma(a10, x0, _fma(a11, x1, 0.0)) + b1 * e
    return v, n0, n1


@numba.njit(cache=True)
def _cubic(t0, t1, t2, t3, v):
    # [1, v, v², v³] @ θ as OpenBLAS's dot: s = fma(f_k, θ_k, s) from s = 0
    vv = v * v
    return _fma(vv * v, t3, _fma(vv, t2, _fma(v, t1, _fma(1.0, t0, 0.0))))


@numba.njit(cache=True)
def cubic_predict(t0, t1, t2, t3, width, width_unit, out_unit):
    """θ·[1, v, v², v³]·out_unit with v = width/width_unit."""
    return _cubic(t0, t1, t2, t3, width / width_unit) * out_unit


@numba.njit(cache=True)
def cubic_invert(t0, t1, t2, t3, target, lo, hi, width_unit, out_unit, iterations):
    """Bisection for the width in [lo, hi] whose prediction is ``target`` on an increasing
    branch; NaN when the prediction does not bracket it (see PulseModelRls.invert)."""
    f_lo = _cubic(t0, t1, t2, t3, lo / width_unit) * out_unit - target
    f_hi = _cubic(t0, t1, t2, t3, hi / width_unit) * out_unit - target
    if not (f_lo < 0 < f_hi):
        return math.nan
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if _cubic(t0, t1, t2, t3, mid / width_unit) * out_unit < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@numba.njit(cache=True)
def _dot4(a, b):
    # OpenBLAS dot: s = fma(a_k, b_k, s) from s = 0
    return _fma(a[3], b[3], _fma(a[2], b[2], _fma(a[1], b[1], _fma(a[0], b[0], 0.0))))


@numba.njit(cache=True)
def rls_update(P, theta, phi, target, lam):
    """One step of :class:`controllers.pulse_width.PulseModelRls` on 4 × 4 ``P``; returns
    (P', θ') as new arrays, in this order of operations (numpy's rounding on the machine it was
    written for; numpy 2.4's ``P @ φ`` rounds differently, so tests check this order, not numpy):

    ``Pφ = P @ φ`` (4 × 4 product rows summed (P_i0·φ0 + P_i2·φ2) + (P_i1·φ1 + P_i3·φ3), unfused),
    ``K = Pφ / (λ + φ @ Pφ)``, ``θ' = θ + K·(target − φ @ θ)``, ``P₁ = (P − K Pφᵀ)/λ``,
    ``P' = 0.5·(P₁ + P₁ᵀ)``.
    """
    Pphi = np.empty(4)
    for i in range(4):
        Pphi[i] = (P[i, 0] * phi[0] + P[i, 2] * phi[2]) + (P[i, 1] * phi[1] + P[i, 3] * phi[3])
    den = lam + _dot4(phi, Pphi)
    K = np.empty(4)
    for i in range(4):
        K[i] = Pphi[i] / den
    innov = target - _dot4(phi, theta)
    theta_new = np.empty(4)
    for i in range(4):
        theta_new[i] = theta[i] + K[i] * innov
    P1 = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            P1[i, j] = (P[i, j] - K[i] * Pphi[j]) / lam
    P2 = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            P2[i, j] = 0.5 * (P1[i, j] + P1[j, i])
    return P2, theta_new


@numba.njit(cache=True)
def window_push_dot(buf, w, y):
    """Shift ``buf`` one place towards index 0, put ``y`` last, and return ``w @ buf`` rounded
    as numpy's dot does here (s = fma(w_k, buf_k, s) from s = 0)."""
    n = buf.shape[0]
    for i in range(n - 1):
        buf[i] = buf[i + 1]
    buf[n - 1] = y
    s = 0.0
    for i in range(n):
        s = _fma(w[i], buf[i], s)
    return s
