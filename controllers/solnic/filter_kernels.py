"""Compiled per-sample steps of :class:`~controllers.solnic.joint_filter.JointFilter`.

The joint EKF runs a time update and a measurement update at every sample (10⁴ per 100 s);
written with numpy on 5×5 arrays each cost ≈ 7–10 µs of dispatch, as one compiled call
≈ 0.5 µs. Both work in place on the state z (n,) and the covariance P (n, n), n ≥ 2, with
(x1, x4) in the first two places.

Round-off. :func:`joint_predict` forms Φ·P and P·Φ' with Φ = [[1, φ12], [0, φ22]] as
``fma(φ12, p_1j, p_0j)`` (one rounding) and ``φ22·p_1j``: these are the products numpy's
``Phi @ P[:2, :]`` returns through OpenBLAS's FMA (Haswell/Zen) dgemm kernel, so on such a
machine the kernel reproduces the numpy formulation bit for bit (checked over 10⁴ samples of
closed loop); with a different BLAS kernel numpy itself would differ at round-off, the kernel
does not (``llvm.fma`` is exact IEEE everywhere). Φ·x̂ (a gemv in numpy, no FMA) and the
update's products are single multiplications and additions in numpy's order; numba does not
contract them (no fastmath), so they are bit-identical too.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["fma", "joint_predict", "joint_update"]


@intrinsic
def fma(typingctx, a, b, c):
    """a·b + c with one rounding (``llvm.fma.f64``), float64 only."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


@njit(cache=True)
def joint_predict(z, P, f12, f22, q11, q14, q44):
    """In place: z[:2] ← Φ z[:2]; P ← F P F' + diag-block(Q), F = blockdiag(Φ, I).

    Φ = [[1, f12], [0, f22]] (3-22) and Q = [[q11, q14], [q14, q44]] (4-11) of
    :func:`~controllers.solnic.mode2_filter.mode2_transition`; the other states are constant.
    """
    z0 = z[0]
    z1 = z[1]
    z[0] = z0 + f12 * z1
    z[1] = f22 * z1
    n = P.shape[0]
    for j in range(n):                      # rows: Φ P[:2, :]
        a = P[0, j]
        b = P[1, j]
        P[0, j] = fma(f12, b, a)
        P[1, j] = f22 * b
    for i in range(n):                      # columns: P[:, :2] Φ'
        a = P[i, 0]
        b = P[i, 1]
        P[i, 0] = fma(f12, b, a)
        P[i, 1] = f22 * b
    P[0, 0] += q11
    P[0, 1] += q14
    P[1, 0] += q14
    P[1, 1] += q44


@njit(cache=True)
def joint_update(z, P, R, y):
    """In place: the Kalman update with y = x1 + w1, VAR[w1] = R [rad²]; returns y − x̂1.

    K = P[:, 0]/(P11 + R), z ← z + K(y − x̂1), P ← P − K P[0, :], then P ← (P + P')/2.
    """
    n = z.shape[0]
    innovation = y - z[0]
    col = np.empty(n)
    for i in range(n):
        col[i] = P[i, 0]
    S = col[0] + R
    for i in range(n):
        k = col[i] / S
        z[i] += k * innovation
        for j in range(n):
            P[i, j] -= k * col[j]
    for i in range(n):
        for j in range(i, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s
    return innovation
