"""Compiled hot loop of the exact simulator: a noisy moving segment (numba).

This is the measured hot path (≈95 % of a noisy closed-loop run in pure Python): Gaussian
sub-steps through a moving segment, the Skorokhod reflection while the torque still breaks
stiction, the Brownian-bridge crossing test, and the bridge bisection. The mathematics is that
of :mod:`plant.multimode` (read its docstring); the closed forms are those of
:mod:`plant.transition`, re-stated here with scalar arithmetic for the compiler, and tested
against them. Random numbers come from the caller's ``numpy.random.Generator``, which numba
advances bit-identically to NumPy.

Parameter vector ``pv``: alpha, beta3, beta4, beta5, sigma2_sq, sigma4_sq, sigma5_sq.
Noisy block of the state: x1, x2, x4, x5 (indices 0, 1, 3, 4).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_IDX = np.array([0, 1, 3, 4])
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_MAX_TRIES = 200


@njit(cache=True)
def _e1(x):
    return -math.expm1(-x)


@njit(cache=True)
def _e2(x):
    if abs(x) >= 0.5:
        return math.expm1(-x) + x
    term = x * x / 2.0
    total = 0.0
    for k in range(2, 24):
        total += term
        term *= -x / (k + 1)
    return total


@njit(cache=True)
def _e3(x):
    if abs(x) >= 0.5:
        return -math.expm1(-x) - x + 0.5 * x * x
    term = x ** 3 / 6.0
    total = 0.0
    for k in range(3, 24):
        total += term
        term *= -x / (k + 1)
    return total


@njit(cache=True)
def phi_moving(mode, h, pv, P):
    """Φ_1 or Φ_3 of (3-20)/(3-21) into P (7 × 7)."""
    a, b3, b4, b5 = pv[0], pv[1], pv[2], pv[3]
    for i in range(7):
        for j in range(7):
            P[i, j] = 1.0 if i == j else 0.0
    y3 = b3 * h
    y5 = b5 * h
    s = 1.0 if mode == 1 else -1.0
    P[2, 2] = math.exp(-y3)
    P[2, 6] = _e1(y3)
    P[3, 3] = math.exp(-b4 * h)
    P[0, 3] = -_e1(b4 * h) / b4
    P[0, 1] = h
    P[0, 2] = a * _e2(y3) / (b3 * b3)
    P[1, 2] = a * _e1(y3) / b3
    P[0, 6] = a * _e3(y3) / (b3 * b3)
    P[1, 6] = a * _e2(y3) / b3
    P[4, 4] = math.exp(-y5)
    P[0, 4] = s * a * _e2(y5) / (b5 * b5)
    P[1, 4] = s * a * _e1(y5) / b5
    P[0, 5] = s * a * h * h / 2.0
    P[1, 5] = s * a * h


@njit(cache=True)
def q_moving(mode, h, pv, Q):
    """Noisy 4 × 4 block (x1, x2, x4, x5) of (4-8) by Gauss–Legendre (see plant.transition)."""
    a, b4, b5 = pv[0], pv[2], pv[3]
    q2, q4, q5 = a * a * pv[4], pv[5], pv[6]
    s = 1.0 if mode == 1 else -1.0
    for i in range(4):
        for j in range(4):
            Q[i, j] = 0.0
    rate = max(b4, b5)
    panels = max(1, int(math.ceil(rate * h / 0.25)))
    width = h / panels
    r = np.empty(4)
    for p in range(panels):
        lo = p * width
        for k in range(_GL_X.shape[0]):
            v = lo + 0.5 * width * (_GL_X[k] + 1.0)
            w = 0.5 * width * _GL_W[k]
            # x2 column (w2 enters x2 with gain α, already in q2)
            r[0], r[1], r[2], r[3] = v, 1.0, 0.0, 0.0
            for i in range(4):
                for j in range(4):
                    Q[i, j] += w * q2 * r[i] * r[j]
            # x4 column
            r[0], r[1], r[2], r[3] = -_e1(b4 * v) / b4, 0.0, math.exp(-b4 * v), 0.0
            for i in range(4):
                for j in range(4):
                    Q[i, j] += w * q4 * r[i] * r[j]
            # x5 column
            r[0] = s * a * _e2(b5 * v) / (b5 * b5)
            r[1] = s * a * _e1(b5 * v) / b5
            r[2], r[3] = 0.0, math.exp(-b5 * v)
            for i in range(4):
                for j in range(4):
                    Q[i, j] += w * q5 * r[i] * r[j]


@njit(cache=True)
def chol_psd(Q, L):
    """Lower factor L·Lᵀ = Q of a PSD 4 × 4, in scaled coordinates; zero pivots give zero columns."""
    n = Q.shape[0]
    d = np.empty(n)
    for i in range(n):
        d[i] = math.sqrt(Q[i, i]) if Q[i, i] > 0 else 0.0
    for i in range(n):
        for j in range(n):
            L[i, j] = 0.0
    for j in range(n):
        if d[j] == 0.0:
            continue
        acc = 1.0
        for k in range(j):
            acc -= L[j, k] * L[j, k]
        if acc <= 1e-15:
            continue                      # rank-deficient direction
        piv = math.sqrt(acc)
        L[j, j] = piv
        for i in range(j + 1, n):
            if d[i] == 0.0:
                continue
            acc2 = Q[i, j] / (d[i] * d[j])
            for k in range(j):
                acc2 -= L[i, k] * L[j, k]
            L[i, j] = acc2 / piv
    for i in range(n):
        for j in range(n):
            L[i, j] *= d[i]


@njit(cache=True)
def _step(X, P, L, rng, out):
    """out = P·X + [L·z on the noisy block]."""
    for i in range(7):
        acc = 0.0
        for j in range(7):
            acc += P[i, j] * X[j]
        out[i] = acc
    z0, z1, z2, z3 = rng.standard_normal(), rng.standard_normal(), rng.standard_normal(), rng.standard_normal()
    for r in range(4):
        out[_IDX[r]] += L[r, 0] * z0 + L[r, 1] * z1 + L[r, 2] * z2 + L[r, 3] * z3


@njit(cache=True)
def _hermite_peak(h, ya, da, yb, db):
    if h <= 0:
        return 0.0
    c2 = 3 * (yb - ya) - (2 * da + db) * h
    c3 = -2 * (yb - ya) + (da + db) * h
    A, B, C = 3 * c3, 2 * c2, da * h
    best = 0.0
    roots = np.empty(2)
    nr = 0
    if A == 0.0:
        if B != 0.0:
            roots[0] = -C / B
            nr = 1
    else:
        disc = B * B - 4 * A * C
        if disc >= 0:
            sq = math.sqrt(disc)
            q = -0.5 * (B + math.copysign(sq, B))
            if q != 0.0:
                roots[0], roots[1] = q / A, C / q
                nr = 2
    for i in range(nr):
        s = roots[i]
        if 0.0 < s < 1.0:
            v = abs(ya + da * h * s + c2 * s * s + c3 * s ** 3)
            if v > best:
                best = v
    return best


@njit(cache=True)
def _peak(Xa, Xb, h, peak):
    p = max(peak, abs(Xa[0]), abs(Xb[0]))
    da, db = Xa[1] - Xa[3], Xb[1] - Xb[3]
    if da * db < 0:
        p = max(p, _hermite_peak(h, Xa[0], da, Xb[0], db))
    return p


@njit(cache=True)
def _cross_prob(va, vb, h, sig_v2):
    if (va > 0) != (vb > 0) or va == 0.0 or vb == 0.0:
        return 1.0
    return math.exp(-2.0 * va * vb / (sig_v2 * h))


@njit(cache=True)
def _bridge_gain(mode, w, pv, G, Phalf, Lhalf):
    """Φ(w/2), factor of Q(w/2), and G = Q(w/2)·Φ(w/2)ᵀ·Q(w)⁻¹ on the noisy block."""
    half = w / 2
    phi_moving(mode, half, pv, Phalf)
    Q1 = np.empty((4, 4))
    Qw = np.empty((4, 4))
    q_moving(mode, half, pv, Q1)
    q_moving(mode, w, pv, Qw)
    chol_psd(Q1, Lhalf)
    P2 = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            P2[i, j] = Phalf[_IDX[i], _IDX[j]]
    d = np.empty(4)
    for i in range(4):
        d[i] = math.sqrt(Qw[i, i]) if Qw[i, i] > 0 else 1.0
    Qs = np.empty((4, 4))
    M = np.empty((4, 4))      # M = Q1·P2ᵀ scaled by columns
    for i in range(4):
        for j in range(4):
            Qs[i, j] = Qw[i, j] / (d[i] * d[j])
            acc = 0.0
            for k in range(4):
                acc += Q1[i, k] * P2[j, k]
            M[i, j] = acc / d[j]
    # G = M · Qs⁻¹ · D⁻¹  →  Gᵀ = D⁻¹ · solve(Qs, Mᵀ)
    Gt = np.linalg.lstsq(Qs, M.T.copy(), 1e-13)[0]
    for i in range(4):
        for j in range(4):
            G[i, j] = Gt[j, i] / d[j]


@njit(cache=True)
def _bisect(mode, Xa0, Xb0, h, tol, pv, sig_v2, rng, Xout):
    Xa = Xa0.copy()
    Xb = Xb0.copy()
    ta, tb = 0.0, h
    G = np.empty((4, 4))
    Ph = np.empty((7, 7))
    Lh = np.empty((4, 4))
    Xm_free = np.empty(7)
    Xb_free = np.empty(7)
    Xm = np.empty(7)
    levels = 0
    while tb - ta > tol:
        w = tb - ta
        half = w / 2
        _bridge_gain(mode, w, pv, G, Ph, Lh)
        pl, p_any = 1.0, 1.0
        for _ in range(_MAX_TRIES):
            _step(Xa, Ph, Lh, rng, Xm_free)
            _step(Xm_free, Ph, Lh, rng, Xb_free)
            for i in range(7):
                Xm[i] = Xm_free[i]
            for r in range(4):
                acc = 0.0
                for c in range(4):
                    acc += G[r, c] * (Xb[_IDX[c]] - Xb_free[_IDX[c]])
                Xm[_IDX[r]] += acc
            pl = _cross_prob(Xa[1], Xm[1], half, sig_v2)
            pr = _cross_prob(Xm[1], Xb[1], half, sig_v2)
            p_any = 1.0 - (1.0 - pl) * (1.0 - pr)
            if p_any >= 1.0 or rng.random() < p_any:
                break
        if pl >= 1.0 or rng.random() * p_any < pl:
            tb = ta + half
            Xb[:] = Xm
        else:
            ta = ta + half
            Xa[:] = Xm
        levels += 1
    Xout[:] = Xb
    return tb, levels


@njit(cache=True)
def moving_noisy(X, mode, h, reflect, sub, tol, pv, rng, peak, max_steps):
    """Advance a noisy moving segment in place.

    Returns (advanced [s], stopped, peak |x1|, sub-steps used, chattered). ``stopped``: the
    velocity reached zero at X (x2 set to 0) after ``advanced`` seconds.
    """
    s = 1.0 if mode == 3 else -1.0
    sig_v2 = pv[0] * pv[0] * pv[4]
    Psub = np.empty((7, 7))
    Lsub = np.empty((4, 4))
    Qtmp = np.empty((4, 4))
    phi_moving(mode, sub, pv, Psub)
    q_moving(mode, sub, pv, Qtmp)
    chol_psd(Qtmp, Lsub)
    P = np.empty((7, 7))
    L = np.empty((4, 4))
    Xb = np.empty(7)
    Xc = np.empty(7)
    t = 0.0
    n = 0
    while h - t > 0.0:
        rem = h - t
        if rem > 1.5 * sub:
            step = sub
            _step(X, Psub, Lsub, rng, Xb)
        else:
            step = rem
            phi_moving(mode, step, pv, P)
            q_moving(mode, step, pv, Qtmp)
            chol_psd(Qtmp, L)
            _step(X, P, L, rng, Xb)
        n += 1
        if n > max_steps:
            return t, False, peak, n, True
        if reflect:
            va, vb = s * X[1], s * Xb[1]
            if sig_v2 > 0:
                u = rng.random()
                low = 0.5 * (va + vb - math.sqrt((vb - va) ** 2 - 2.0 * sig_v2 * step * math.log(u)))
            else:
                low = min(va, vb)
            if low < 0.0:
                Xb[1] += s * (-low)
                Xb[0] += s * (-low) * step / 2.0
        else:
            p = _cross_prob(X[1], Xb[1], step, sig_v2)
            if p >= 1.0 or rng.random() < p:
                tc, lv = _bisect(mode, X, Xb, step, tol, pv, sig_v2, rng, Xc)
                n += lv
                peak = _peak(X, Xc, tc, peak)
                X[:] = Xc
                X[1] = 0.0
                return t + tc, True, peak, n, False
        peak = _peak(X, Xb, step, peak)
        X[:] = Xb
        t += step
    return h, False, peak, n, False
