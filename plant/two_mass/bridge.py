"""Bridge bisection of a noisy load-velocity zero inside one sub-step (two-mass plant).

As plant.multimode.zero_velocity, on the noisy block NB = (x1, x2, x4, x5, φ, ω_m): given both
ends X_a, X_b of a sub-step of width w, the midpoint is Gaussian (Matheron's rule)

    X_m ~ N(Φ(w/2)·X_a + G·(X_b − Φ(w)·X_a),  Σ = Q(w/2) − G·Φ_h·Q(w/2)),
    G = Q(w/2)·Φ_hᵀ·Q(w)⁺,   Φ_h the NB block of Φ(w/2),

with Q(w)⁺ the pseudo-inverse in diagonally scaled coordinates (directions below 1e-13 of
the largest eigenvalue carry no noise; the eigen-decomposition is
:func:`plant.fixed_linalg.eigh_jacobi`'s, not LAPACK's: the same bits on every CPU). x2 is drawn first from its law conditioned on the
sub-step containing a crossing (plant.multimode.zero_velocity._hitting_midpoint, exact), the
other coordinates given x2; the first crossing is in the left half with probability
p_left/p_any. Bisection stops at ``bisection_tol``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.fixed_linalg import eigh_jacobi
from plant.multimode.zero_velocity import _cross_prob, _hitting_midpoint
from plant.randomness import normal, uniform_below
from plant.two_mass.modes import NCORE
from plant.two_mass.motion import A2, NB, NNB, NX, process_noise_u, psd_factor, transition_u, unit_coords

__all__ = ["bridge_law", "bridge_tables", "bisect", "bisect_w", "bisect_fresh", "LAW_SIZE", "BISECT_SCRATCH"]

# Packed law: Φ(w/2) (81), Φ(w) (81), G (36), √Σ22 (1), regression on x2 (5), residual factor (25).
_PH, _PW, _G, _SD, _REG, _RES = 0, 81, 162, 198, 199, 204
LAW_SIZE = 229
_X2 = 1            # x2's index in NB


@njit(cache=True)
def _pinv_scaled(Q, out):
    n = Q.shape[0]
    d = np.empty(n)
    for i in range(n):
        d[i] = math.sqrt(Q[i, i]) if Q[i, i] > 0.0 else 0.0
    S = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            if d[i] > 0.0 and d[j] > 0.0:
                S[i, j] = Q[i, j] / (d[i] * d[j])
    lam, U = eigh_jacobi(S)
    top = max(lam.max(), 1e-300)
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for k in range(n):
                if lam[k] > 1e-13 * top:
                    acc += U[i, k] * U[j, k] / lam[k]
            out[i, j] = acc / (d[i] * d[j]) if d[i] > 0.0 and d[j] > 0.0 else 0.0


@njit(cache=True)
def bridge_law(mode, w, p, q, V, Vi, lam, law):
    """Fill the packed law (module docstring) of the midpoint of a sub-step of width w."""
    U = np.empty((NX, 2, NCORE), dtype=np.complex128)
    unit_coords(mode, p, Vi, U)
    Ph = law[_PH:_PW].reshape((NX, NX))
    Pw = law[_PW:_G].reshape((NX, NX))
    transition_u(mode, w / 2, p, V, lam, U, Ph)
    transition_u(mode, w, p, V, lam, U, Pw)
    Qh = np.empty((NNB, NNB))
    Qw = np.empty((NNB, NNB))
    process_noise_u(mode, w / 2, p, V, lam, U, Qh)
    process_noise_u(mode, w, p, V, lam, U, Qw)
    _law_from(Qh, Qw, law)


@njit(cache=True)
def _law_from(Qh, Qw, law):
    """The rest of the packed law from Φ(w/2), Φ(w) (already in ``law``), Q(w/2) and Q(w)."""
    Ph = law[_PH:_PW].reshape((NX, NX))
    G = law[_G:_SD].reshape((NNB, NNB))
    M = np.empty((NNB, NNB))
    for i in range(NNB):
        for j in range(NNB):
            acc = 0.0
            for k in range(NNB):
                acc += Qh[i, k] * Ph[NB[j], NB[k]]
            M[i, j] = acc
    Qi = np.empty((NNB, NNB))
    _pinv_scaled(Qw, Qi)
    for i in range(NNB):
        for j in range(NNB):
            acc = 0.0
            for k in range(NNB):
                acc += M[i, k] * Qi[k, j]
            G[i, j] = acc
    Sg = np.empty((NNB, NNB))
    for i in range(NNB):
        for j in range(NNB):
            acc = 0.0
            for k in range(NNB):
                acc += G[i, k] * M[j, k]
            Sg[i, j] = Qh[i, j] - acc
    for i in range(NNB):
        for j in range(i + 1, NNB):
            Sg[i, j] = Sg[j, i] = 0.5 * (Sg[i, j] + Sg[j, i])
    s22 = max(Sg[_X2, _X2], 0.0)
    law[_SD] = math.sqrt(s22)
    others = np.array([0, 2, 3, 4, 5])
    R = np.empty((5, 5))
    for a in range(5):
        law[_REG + a] = Sg[others[a], _X2] / s22 if s22 > 0.0 else 0.0
    for a in range(5):
        for b in range(5):
            R[a, b] = Sg[others[a], others[b]] - law[_REG + a] * Sg[_X2, others[b]]
    for a in range(5):
        for b in range(a + 1, 5):
            R[a, b] = R[b, a] = 0.5 * (R[a, b] + R[b, a])
    Lr = law[_RES:_RES + 25].reshape((5, 5))
    psd_factor(R, Lr)


@njit(cache=True)
def _tables(p, q, V, Vi, lam, sub, levels, BT):
    for m in range(2):
        mode = 1 if m == 0 else 3
        w = sub
        for k in range(levels):
            bridge_law(mode, w, p, q, V, Vi, lam, BT[m, k])
            w = w / 2


def bridge_tables(p, q, V, Vi, lam, sub: float, levels: int) -> np.ndarray:
    """BT[m, k] = the packed law for width sub/2^k, m = 0 (mode 1) or 1 (mode 3)."""
    BT = np.empty((2, levels, LAW_SIZE))
    _tables(p, q, V, Vi, lam, sub, levels, BT)
    return BT


@njit(cache=True, _nrt=False)
def _level(law, Xa, Xb, Xm, half, sig_v2, z, cursor, sc):
    """Draw the midpoint Xm given a crossing inside [Xa, Xb]; True if the first one is left.
    ``sc``: the caller's scratch (NX + NNB + 5 floats); allocation-free, compiled without
    reference counting (each call counted its eight array arguments and three allocations)."""
    Ph = law[_PH:_PW].reshape((NX, NX))
    Pw = law[_PW:_G].reshape((NX, NX))
    G = law[_G:_SD].reshape((NNB, NNB))
    Fb = sc[:NX]
    for i in range(NX):
        a1 = 0.0
        a2 = 0.0
        for j in range(NX):
            a1 += Ph[i, j] * Xa[j]
            a2 += Pw[i, j] * Xa[j]
        Xm[i] = a1
        Fb[i] = a2
    dlt = sc[NX:NX + NNB]
    for k in range(NNB):
        dlt[k] = Xb[NB[k]] - Fb[NB[k]]
    for i in range(NNB):
        acc = 0.0
        for k in range(NNB):
            acc += G[i, k] * dlt[k]
        Xm[NB[i]] += acc
    mean2 = Xm[A2]
    a, b = Xa[A2], Xb[A2]
    sd = law[_SD]
    if (a > 0) != (b > 0) or a == 0.0 or b == 0.0:
        x2m = mean2 + sd * normal(z, cursor)
    else:
        sgn = 1.0 if a > 0 else -1.0
        x2m = sgn * _hitting_midpoint(sgn * a, sgn * b, sgn * mean2, sd, sig_v2 * half, z, cursor)
    pl = _cross_prob(a, x2m, half, sig_v2)
    pr = _cross_prob(x2m, b, half, sig_v2)
    p_any = 1.0 - (1.0 - pl) * (1.0 - pr)
    Xm[A2] = x2m
    dv = x2m - mean2
    zeta = sc[NX + NNB:NX + NNB + 5]
    for i in range(5):
        zeta[i] = normal(z, cursor)
    others = (0, 2, 3, 4, 5)
    for a_ in range(5):
        acc = law[_REG + a_] * dv
        for b_ in range(a_ + 1):
            acc += law[_RES + 5 * a_ + b_] * zeta[b_]
        Xm[NB[others[a_]]] += acc
    if pl >= 1.0:
        return True
    return uniform_below(z, cursor, pl / p_any if p_any > 0.0 else 0.0)


@njit(cache=True)
def bisect(mode, Xa0, Xb0, h, tol, p, q, V, Vi, lam, sig_v2, z, cursor, Xout, table):
    """Bridge bisection of a crossing known to lie in a sub-step of length h; (time, levels).

    ``table`` holds the laws of widths h/2^k (empty for a sub-step of another width: computed).
    The plain form: the kernel runs :func:`bisect_w` and :func:`bisect_fresh`, which
    tests/test_two_mass_fast.py checks against it bit for bit.
    """
    Xa = Xa0.copy()
    Xb = Xb0.copy()
    Xm = np.empty(NX)
    law = np.empty(LAW_SIZE)
    sc = np.empty(NX + NNB + 5)                     # _level's scratch
    ta = 0.0
    w = h
    levels = 0
    while w > tol:
        half = w / 2
        if levels < table.shape[0]:
            left = _level(table[levels], Xa, Xb, Xm, half, sig_v2, z, cursor, sc)
        else:
            bridge_law(mode, w, p, q, V, Vi, lam, law)
            left = _level(law, Xa, Xb, Xm, half, sig_v2, z, cursor, sc)
        if left:
            Xb[:] = Xm
        else:
            ta += half
            Xa[:] = Xm
        w = half
        levels += 1
    Xout[:] = Xb
    return ta + w, levels


@njit(cache=True)
def bisect_fresh(mode, Xa0, Xb0, h, tol, p, V, Vi, lam, sig_v2, z, cursor, Xout, Pw0, Qw0):
    """:func:`bisect` of a sub-step of its own width h (no table), given its Φ(h) ``Pw0`` and
    Q(h) ``Qw0`` (the sub-step's own): each level's law needs Φ and Q at w and w/2, and the
    next level's w is this one's w/2 (the same bits, ``w / 2`` both times), so Φ(w) and Q(w) are
    carried from the level before instead of rebuilt — the laws :func:`bridge_law` fills, bit
    for bit, with half the matrices built (tests/test_two_mass_fast.py)."""
    U = np.empty((NX, 2, NCORE), dtype=np.complex128)
    unit_coords(mode, p, Vi, U)
    Xa = Xa0.copy()
    Xb = Xb0.copy()
    Xm = np.empty(NX)
    law = np.empty(LAW_SIZE)
    sc = np.empty(NX + NNB + 5)                     # _level's scratch
    Ph = law[_PH:_PW].reshape((NX, NX))
    Pw = law[_PW:_G].reshape((NX, NX))
    Qh = np.empty((NNB, NNB))
    Qw = Qw0.copy()
    Pw[:, :] = Pw0
    ta = 0.0
    w = h
    levels = 0
    while w > tol:
        half = w / 2
        if levels > 0:
            Pw[:, :] = Ph
            Qw[:, :] = Qh
        transition_u(mode, w / 2, p, V, lam, U, Ph)
        process_noise_u(mode, w / 2, p, V, lam, U, Qh)
        _law_from(Qh, Qw, law)
        left = _level(law, Xa, Xb, Xm, half, sig_v2, z, cursor, sc)
        if left:
            Xb[:] = Xm
        else:
            ta += half
            Xa[:] = Xm
        w = half
        levels += 1
    Xout[:] = Xb
    return ta + w, levels


BISECT_SCRATCH = 3 * NX + LAW_SIZE + NX + NNB + 5     # bisect_w's Wb: Xa, Xb, Xm, a law, _level's scratch


@njit(cache=True, _nrt=True)
def _bridge_law_rc(mode, w, p, q, V, Vi, lam, law):
    """:func:`bridge_law` with reference counting on (it allocates)."""
    bridge_law(mode, w, p, q, V, Vi, lam, law)


@njit(cache=True, _nrt=False)
def bisect_w(mode, Xa0, Xb0, h, tol, p, q, V, Vi, lam, sig_v2, z, cursor, Xout, table, Wb):
    """:func:`bisect` in the caller's scratch Wb (BISECT_SCRATCH floats), compiled without
    reference counting (each level's table view and _level call counted their arrays: ~60
    atomic operations per bisection); the same operations and draws."""
    Xa = Wb[:NX]
    Xb = Wb[NX:2 * NX]
    Xm = Wb[2 * NX:3 * NX]
    law = Wb[3 * NX:3 * NX + LAW_SIZE]
    sc = Wb[3 * NX + LAW_SIZE:BISECT_SCRATCH]
    for i in range(NX):
        Xa[i] = Xa0[i]
        Xb[i] = Xb0[i]
    ta = 0.0
    w = h
    levels = 0
    while w > tol:
        half = w / 2
        if levels < table.shape[0]:
            left = _level(table[levels], Xa, Xb, Xm, half, sig_v2, z, cursor, sc)
        else:
            _bridge_law_rc(mode, w, p, q, V, Vi, lam, law)
            left = _level(law, Xa, Xb, Xm, half, sig_v2, z, cursor, sc)
        if left:
            for i in range(NX):
                Xb[i] = Xm[i]
        else:
            ta += half
            for i in range(NX):
                Xa[i] = Xm[i]
        w = half
        levels += 1
    for i in range(NX):
        Xout[i] = Xb[i]
    return ta + w, levels
