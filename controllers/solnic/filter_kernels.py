"""Compiled algebra of the solnic filters: the joint EKF's per-sample steps, the friction
filter's update, the half-plane conditioning.

The joint EKF (:class:`~controllers.solnic.joint_filter.JointFilter`) runs a time update and a
measurement update at every sample (10⁴ per 100 s); written with numpy on 5×5 arrays each cost
≈ 7–10 µs of dispatch, as one compiled call ≈ 0.5 µs. :func:`joint_predict`,
:func:`joint_update` and :func:`joint_add_motion` work in place on the state z (n,) and the
covariance P (n, n), with (x1, x4) first and d last. The faithful friction filter
(:class:`~controllers.solnic.friction_filter.FrictionFilter`, (5-16)–(5-18)) and the
moment-matched half-plane condition (:mod:`controllers.solnic.truncation`) return new arrays.

Round-off: the kernels reproduce the numpy formulation they replace bit for bit on the machine
this was written on (OpenBLAS 0.3.31, Haswell/Zen kernels; checked on every internal of
60 closed-loop runs of 100 s): numpy's 2-term matrix products through that BLAS are one fused
multiply-add (``Phi @ P``: ``fma(φ12, p_1j, p_0j)``; the 2×2 forms listed above the friction
kernels), its dot products a chain of FMAs, its 5×5 gemv with the sparse h of a pulse and all
elementwise numpy operations single roundings in numpy's order; numba does not contract
``a*b + c`` by itself (no fastmath), and ``llvm.fma`` is exact IEEE everywhere. With another
BLAS kernel numpy itself would differ at round-off; the kernels would not.
"""

from __future__ import annotations

import math

import llvmlite.binding as llvm
import numpy as np
from numba import njit, types
from numba.extending import get_cython_function_address

from controllers._fma import fma          # a·b + c with one rounding (llvm.fma.f64)

__all__ = ["joint_predict", "joint_update", "quadratic_form2", "friction_gain",
           "friction_covariance", "friction_update_clip", "joint_add_motion", "half_plane_moments",
           "half_plane_apply", "joint_condition", "joint_valid", "joint_moved", "joint_launch"]


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
def _symmetrize(P):
    """P ← (P + P')/2 in place, element by element (numpy's ``0.5 * (P + P.T)``)."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i, n):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s


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
    _symmetrize(P)
    return innovation


# -- the faithful friction filter (2×2) -------------------------------------------------------
# numpy forms these 2-term products through OpenBLAS as (verified bit for bit on this machine):
#   A @ x  (gemv):  fma(A_i0, x_0, A_i1·x_1)        x @ A:  fma(x_1, A_1j, x_0·A_0j)
#   x @ y  (dot):   fma(x_1, y_1, x_0·y_0)          A @ B (gemm):  fma(A_i1, B_1j, A_i0·B_0j)


@njit(cache=True)
def quadratic_form2(H, P):
    """H P H' for H (2,) and P (2, 2): numpy's ``H @ P @ H``."""
    h0 = H[0]
    h1 = H[1]
    v0 = fma(h1, P[1, 0], h0 * P[0, 0])
    v1 = fma(h1, P[1, 1], h0 * P[0, 1])
    return fma(v1, h1, v0 * h0)


@njit(cache=True)
def friction_gain(P, h0, h1, residual, R, limit):
    """(K0, K1, S, R_used) of :meth:`FrictionFilter._gain` (5-16): R raised to the fictitious
    variance that caps every |Δk_i| at ``limit`` (inf: no cap)."""
    ph0 = fma(P[0, 0], h0, P[0, 1] * h1)             # P @ H
    ph1 = fma(P[1, 0], h0, P[1, 1] * h1)
    S0 = fma(h1, ph1, h0 * ph0)                      # H @ PH
    R_used = R
    if math.isfinite(limit):
        a0 = abs(ph0 * residual)
        a1 = abs(ph1 * residual)
        need = (a0 if a0 >= a1 else a1) / limit - S0
        if need > R:
            R_used = need
    S = S0 + R_used
    if not S > 0:
        return 0.0, 0.0, S0 + R, R_used
    return ph0 / S, ph1 / S, S, R_used


@njit(cache=True)
def friction_covariance(P, K0, K1, h0, h1, a):
    """(I − a·K H) P (5-18), symmetrised: a new (2, 2) array."""
    A00 = 1.0 - a * (K0 * h0)
    A01 = 0.0 - a * (K0 * h1)
    A10 = 0.0 - a * (K1 * h0)
    A11 = 1.0 - a * (K1 * h1)
    n00 = fma(A01, P[1, 0], A00 * P[0, 0])
    n01 = fma(A01, P[1, 1], A00 * P[0, 1])
    n10 = fma(A11, P[1, 0], A10 * P[0, 0])
    n11 = fma(A11, P[1, 1], A10 * P[0, 1])
    out = np.empty((2, 2))
    out[0, 0] = 0.5 * (n00 + n00)
    out[1, 1] = 0.5 * (n11 + n11)
    s = 0.5 * (n01 + n10)
    out[0, 1] = s
    out[1, 0] = s
    return out


@njit(cache=True)
def friction_update_clip(k, P, H, residual, R, a, limit, ks_cap, max_shrinks):
    """The text's update (5-16)–(5-18) with the section-5.3 shrinks and clips.

    Returns (k_new, P_new, S, R_used, shrinks, clipped); ``H`` is not modified.
    """
    h0 = H[0]
    h1 = H[1]
    shrinks = 0
    while True:
        K0, K1, S, R_used = friction_gain(P, h0, h1, residual, R, limit)
        kn0 = k[0] + K0 * residual                                  # (5-17)
        kn1 = k[1] + K1 * residual
        raising = K1 * residual > 0.0
        if kn1 <= ks_cap or not raising or shrinks >= max_shrinks or h1 == 0.0:
            break
        h1 *= 0.5                                                   # shrink ∂Δc/∂k̂s
        shrinks += 1
    P_new = friction_covariance(P, K0, K1, h0, h1, a)              # (5-18)
    clipped = False
    if kn1 > ks_cap:
        kn1 = ks_cap
        clipped = True
    if kn0 < 0.0:
        kn0 = 0.0
        clipped = True
    if kn1 < kn0:                                                   # k̂s not below k̂c
        kn1 = kn0
        clipped = True
    if kn0 > ks_cap:                                                # a valid plant model
        kn0 = ks_cap
        kn1 = ks_cap
        clipped = True
    k_new = np.empty(2)
    k_new[0] = kn0
    k_new[1] = kn1
    return k_new, P_new, S, R_used, shrinks, clipped


# -- pulses and half-plane conditions --------------------------------------------------------


@njit(cache=True)
def joint_add_motion(z, P, h, d_mean, noise_var, max_correction, abs_dc):
    """In place: d = h·z + d_mean − h·ẑ + n replaces z[4], then x1 ← x1 + d; returns VAR[d].

    P[4, :] = P h, VAR[d] = h'P h + ``noise_var`` (raised to max|(P h)_k|·``abs_dc``/
    ``max_correction`` when that is finite and > 0), then J P J' with J = I + e_0 e_4'
    and (P + P')/2. (P h: one rounding per product and per sum, as numpy's gemv here;
    h'(P h): a chain of fused multiply-adds, as its dot.)
    """
    n = z.shape[0]
    D = n - 1
    Ph = np.empty(n)
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += P[i, j] * h[j]
        Ph[i] = acc
    var = 0.0
    for i in range(n):
        var = fma(h[i], Ph[i], var)
    z[D] = d_mean
    for i in range(n):
        P[D, i] = Ph[i]
    for i in range(n):
        P[i, D] = Ph[i]
    var_d = var + noise_var
    if math.isfinite(max_correction) and max_correction > 0:
        big = 0.0
        for i in range(2, D):
            if abs(Ph[i]) > big:
                big = abs(Ph[i])
        need = big * abs_dc / max_correction
        if need > var_d:
            var_d = need
    P[D, D] = var_d
    z[0] += z[D]
    for j in range(n):
        P[0, j] += P[D, j]
    for i in range(n):
        P[i, 0] += P[i, D]
    _symmetrize(P)
    return var_d


@njit(cache=True)
def half_plane_moments(mean, P, c):
    """(c·mean, c'P c): the mean and variance of s = c·x.

    Sums in index order (c'P c as c·(P c)); with c's entries in {0, ±1}, as in every
    constraint here, every product is exact and the result equals numpy's whatever its order.
    """
    n = mean.shape[0]
    m = 0.0
    v = 0.0
    for i in range(n):
        m += c[i] * mean[i]
        pc = 0.0
        for j in range(n):
            pc += P[i, j] * c[j]
        v += c[i] * pc
    return m, v


@njit(cache=True)
def half_plane_apply(mean, P, c, m, v, mean_s, var_s):
    """New (mean, P) after s = c·x is given E[s] = ``mean_s``, VAR[s] = ``var_s``:
    mean + P c (mean_s − m)/v and P − (P c)(P c)'(v − var_s)/v², symmetrised."""
    n = mean.shape[0]
    Pc = np.empty(n)
    for i in range(n):
        pc = 0.0
        for j in range(n):
            pc += P[i, j] * c[j]
        Pc[i] = pc
    dm = mean_s - m
    shrink = v - var_s
    vv = v * v
    new_mean = np.empty(n)
    for i in range(n):
        new_mean[i] = mean[i] + Pc[i] * dm / v
    new_P = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            new_P[i, j] = P[i, j] - Pc[i] * Pc[j] * shrink / vv
    for i in range(n):
        for j in range(i, n):
            s = 0.5 * (new_P[i, j] + new_P[j, i])
            new_P[i, j] = s
            new_P[j, i] = s
    return new_mean, new_P


# -- the joint EKF's constraints as one compiled call -----------------------------------------
# log Φ(α) of scipy.special.log_ndtr (the same C function as the ufunc's double loop, through
# scipy's Cython export, registered with LLVM by name so that numba's cache can link it again).
# Its C signature is "double (double, int __pyx_skip_dispatch)" (a module-level cpdef function:
# the flag is unused; passed as 0, as numba-scipy declares these exports)
llvm.add_symbol("solnic_log_ndtr", get_cython_function_address("scipy.special.cython_special",
                                                                  "__pyx_fuse_1log_ndtr"))
_log_ndtr = types.ExternalFunction("solnic_log_ndtr", types.float64(types.float64, types.intc))
_HALF_LOG_2PI = 0.5 * math.log(2 * math.pi)     # as truncation.condition_half_plane forms it


@njit(cache=True)
def joint_condition(z, P, c, bound, always):
    """In place: :func:`controllers.solnic.truncation.condition_half_plane` on (z, P) (the same
    operations in the same order: λ = φ(α)/Φ(α) through ``log_ndtr``, the variance factor at
    least 1e-6); returns whether anything changed."""
    m, v = half_plane_moments(z, P, c)
    if not v > 0:
        return False
    sd = math.sqrt(v)
    alpha = (bound - m) / sd
    if alpha > 8.0 or (alpha >= 0.0 and not always):
        return False
    lam = math.exp(-0.5 * alpha * alpha - _HALF_LOG_2PI - _log_ndtr(alpha, 0))
    mean_s = m - sd * lam
    f = 1.0 - alpha * lam - lam * lam
    if 1e-6 > f:                                  # Python's max(f, 1e-6), a NaN kept
        f = 1e-6
    var_s = v * f
    new_mean, new_P = half_plane_apply(z, P, c, m, v, mean_s, var_s)
    z[:] = new_mean
    P[:, :] = new_P
    return True


@njit(cache=True)
def joint_valid(z, P, u_max):
    """In place: :meth:`JointFilter._valid <controllers.solnic.joint_filter.JointFilter._valid>`,
    k_s < u_max, k_c ≤ k_s, k_c ≥ 0 as conditions, then the round-off guard on the means
    (Python's min/max: the first argument unless the second is strictly beyond it)."""
    n = z.shape[0]
    cap = u_max * (1.0 - 1e-6)
    c = np.zeros(n)
    c[3] = 1.0
    joint_condition(z, P, c, cap, True)
    c = np.zeros(n)
    c[2] = 1.0
    c[3] = -1.0
    joint_condition(z, P, c, 0.0, True)            # k_c ≤ k_s
    c = np.zeros(n)
    c[2] = -1.0
    joint_condition(z, P, c, 0.0, True)            # k_c ≥ 0
    kc = z[2]
    if 0.0 > kc:
        kc = 0.0
    if cap < kc:
        kc = cap
    z[2] = kc
    ks = z[3]
    if kc > ks:
        ks = kc
    if cap < ks:
        ks = cap
    z[3] = ks


@njit(cache=True)
def joint_moved(z, P, peak_torque, u_max):
    """In place: :meth:`JointFilter.moved <controllers.solnic.joint_filter.JointFilter.moved>`'s
    k_s < peak torque (at most u_max), then :func:`joint_valid`."""
    c = np.zeros(z.shape[0])
    c[3] = 1.0
    top = peak_torque
    if u_max < top:
        top = u_max
    joint_condition(z, P, c, top * (1.0 - 1e-6), True)
    joint_valid(z, P, u_max)


@njit(cache=True)
def joint_launch(z, P, H_b, H_tb, peak_torque, sign, dc, dc_sq, noise_var, max_correction, moving, sigma5_sq, out):
    """In place: the joint EKF's part of a launch (SolnicController._launch without the grid),
    the Python steps' arithmetic in their order. First, on the k block before the pulse,
    ``out`` = (H_b P_kk H_b' (5-1), H_tb P_kk H_tb' (5-11), Prob(k_s ≥ peak torque)) —
    FrictionView.motion_variance, .time_variance, .prob_no_motion; then
    JointFilter.add_motion(sign, dc, H_b, noise_var + dc²·Prob, max_correction) (its
    VAR[d] in ``out[3]``) and FrictionView.propagate(moving, σ5²) (5-15). ``dc_sq`` is
    Python's ``dc**2`` (libm's pow, which need not round as dc·dc does)."""
    n = z.shape[0]
    Pk = P[2:4, 2:4]
    spread = quadratic_form2(H_b, Pk)
    t_var = quadratic_form2(H_tb, Pk)
    pks = P[3, 3]
    sd = math.sqrt(0.0 if 0.0 > pks else pks)      # max(P_ks,ks, 0), a NaN kept
    if sd == 0:
        p_zero = 1.0 if z[3] >= peak_torque else 0.0
    else:
        p_zero = 0.5 * math.erfc((peak_torque - z[3]) / (sd * math.sqrt(2.0)))
    h = np.zeros(n)
    h[2] = sign * H_b[0]
    h[3] = sign * H_b[1]
    var_d = joint_add_motion(z, P, h, sign * dc, noise_var + dc_sq * p_zero, max_correction, abs(dc))
    if moving > 0 and sigma5_sq > 0:
        q = sigma5_sq * moving
        P[2, 2] += q
        P[2, 3] += q
        P[3, 2] += q
        P[3, 3] += q
    out[0] = spread
    out[1] = t_var
    out[2] = p_zero
    out[3] = var_d
