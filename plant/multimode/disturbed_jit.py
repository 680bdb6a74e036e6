"""The disturbed plant's interval compiled whole: :mod:`plant.multimode.disturbed`'s algorithm in numba.

The same exact Gaussian sub-steps, step ladder, bridge crossing tests, Skorokhod push and bridge
bisection as the Python path (its docstring has the method), reading the plant noise from the
same :class:`~plant.randomness.NoiseStream` at the same positions. The arithmetic is the Python
path's, operation for operation, so the results are bit-identical (tests/test_disturbed_jit.py
compares whole pulse trains and closed loops, every field, on many seeds):

* scalar expressions are written in the same order (numba does not reassociate or fuse);
* no BLAS or LAPACK: every product, factor and eigen-decomposition is fixed-order code, so the
  rows are the same on every CPU whatever kernel OpenBLAS would pick (docs/results.md,
  "Reproducibility across machines"). The sub-step's Φ·Y and B·z keep the order of OpenBLAS's
  Haswell dgemv (:func:`plant.fixed_linalg.gemv_lanes`, four FMA lanes: the order the rows were
  first computed in, now for every size); the Cholesky factor, B·Bᵀ, the bridge law's products, the
  eigen-decompositions (cyclic Jacobi) and the hermitian pseudo-inverse are
  :mod:`plant.fixed_linalg`'s; the column-ordered factor products are :func:`_factor_add`'s
  plain sums. The Python path calls the same routines.

Transitions (Φ(h), Q(h), the minimal factor) and bridge laws are cached per (mode, h) in
direct-mapped tables kept with the plant's parameters (a pure function of them: a miss is
recomputed, never different).
"""

from __future__ import annotations

import math
import threading

import numpy as np
from numba import njit

from plant.expfun import e1, e2, e4
from plant.fixed_linalg import cholesky, eigh_jacobi, gemv_lanes as _gemv, gram, mat_mat, mat_mat_t, mat_vec, pinv_hermitian
from plant.fixed_linalg import fma as _fma
from plant.multimode.crossing import exp_below
from plant.multimode.moving import phi_moving, q_moving, substep_peak
from plant.multimode.segments import hermite_peak, torque_integrals, torque_integrals_given
from plant.multimode.zero_velocity import FAR_SIGMAS, LADDER, hitting_midpoint
from plant.randomness import NoiseExhausted, normal, uniform, uniform_below
from plant.state import EventKind

__all__ = ["interval_kernel", "interval_k", "kernel_inputs", "SHEET_SIZE", "WORK_SIZE"]

Y1, Y2, Y3, Y4, Y5, YD, YKC, YU = range(8)
_N = 8
_FROM7 = np.array([Y1, Y2, Y3, Y4, Y5, YKC, YU])
_BLOCK = np.array([Y1, Y2, Y4, Y5])
_DBLK = np.array([Y1, Y2, YD])
_D4 = np.array([0, 1, 3])

# disturbance and plant constants, as the Python path evaluates them (plant.multimode.disturbed)
(_TAUD, _BD, _SD2, _TAU3, _TAU5, _SIG2MOV, _ALPHA, _BETA3, _BETA4, _SIG4, _UMAX, _KS, _KC, _S2, _S5) = range(15)
# options
_O_NOISE, _O_SUB, _O_RSUB, _O_TOL, _O_MAXEV, _O_DIVERGE = range(6)
# work sheet (as plant.multimode.interval's, plus the just-broke flag)
(_T, _MODE, _FB, _COUNT, _PEAK, _IABS, _ISQ, _CHG, _DUR, _NEV, _NBRK, _NSTK, _NSUB, _STATUS, _NREC,
 _JUST) = range(16)
SHEET_SIZE = 16
_OK, _CHATTER, _DIVERGED, _BAD_LEVEL = 0, 1, 2, 3
# work-sheet positions for compiled callers (plant.multimode.disturbed_loop)
SHEET_T, SHEET_MODE, SHEET_FLYBACK, SHEET_PEAK, SHEET_ABS, SHEET_SQ = _T, _MODE, _FB, _PEAK, _IABS, _ISQ
SHEET_CHARGE, SHEET_DURATION, SHEET_EVENTS, SHEET_BREAKAWAYS, SHEET_SUBSTEPS = _CHG, _DUR, _NEV, _NBRK, _NSUB
SHEET_STATUS, STATUS_OK = _STATUS, _OK
_LEVEL, _FLYBACK_END, _BREAKAWAY, _REGIME_END, _STICK, _REVERSAL, _REFLECTION = (int(k) for k in EventKind)
_TOP = 2.0 ** (LADDER - 1)

_NT_BITS, _NB_BITS = 10, 8
_NT = 1 << _NT_BITS         # transition cache slots
_NB = 1 << _NB_BITS         # bridge-law cache slots
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)     # 2^64 / golden ratio, odd (_slot)

class RecordFull(Exception):
    """The event buffer is full (the caller enlarges it and runs the interval again)."""


@njit(cache=True)
def _closed_form(mode, h, rec, rd, dp, phi, Q):
    """disturbed._closed_form: Φ(h) and Q(h) into phi and Q (8 × 8); rec, rd: 1-element record arrays."""
    bd, sd2 = dp[_BD], dp[_SD2]
    for i in range(_N):
        for j in range(_N):
            phi[i, j] = 0.0
            Q[i, j] = 0.0
    if mode == 2:
        b3, b4, s4 = dp[_BETA3], dp[_BETA4], dp[_SIG4]
        y = b4 * h
        E = e1(y)
        for i in range(_N):
            phi[i, i] = 1.0
        phi[Y1, Y4] = -E / b4
        phi[Y4, Y4] = 1.0 - E
        phi[Y3, Y3] = math.exp(-b3 * h)
        phi[Y3, YU] = e1(b3 * h)
        phi[YD, YD] = math.exp(-bd * h)
        Q[Y1, Y1] = s4 * e4(y) / math.pow(b4, 3.0)
        Q[Y1, Y4] = Q[Y4, Y1] = -s4 * E * E / (2.0 * b4 * b4)
        Q[Y4, Y4] = s4 * E * (2.0 - E) / (2.0 * b4)
        Q[YD, YD] = sd2 * e1(2.0 * bd * h) / (2.0 * bd)
        return
    P7 = np.empty((7, 7))
    phi_moving(mode, h, rec[0], P7)
    for i in range(7):
        for j in range(7):
            phi[_FROM7[i], _FROM7[j]] = P7[i, j]
    a = dp[_ALPHA]
    phi[Y1, YD] = a * e2(bd * h) / (bd * bd)
    phi[Y2, YD] = a * e1(bd * h) / bd
    phi[YD, YD] = math.exp(-bd * h)
    Q4 = np.empty((4, 4))
    q_moving(mode, h, rec[0], Q4)
    for i in range(4):
        for j in range(4):
            Q[_BLOCK[i], _BLOCK[j]] = Q4[i, j]
    q_moving(1, h, rd[0], Q4)
    for i in range(3):
        for j in range(3):
            Q[_DBLK[i], _DBLK[j]] += Q4[_D4[i], _D4[j]]


@njit(cache=True)
def _noise_factor(Q, rows, Bflat):
    """plant.multimode.noise.noise_factor(Q): the non-zero rows and the factor of their block
    (:func:`plant.fixed_linalg.cholesky`, else the scaled eigen-factor by
    :func:`plant.fixed_linalg.eigh_jacobi`, flagged by returning −m); returns m."""
    m = 0
    for i in range(_N):
        nz = False
        for j in range(_N):
            if Q[i, j] != 0.0:
                nz = True
        if nz:
            rows[m] = i
            m += 1
    if m == 0:
        return 0
    D = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            D[i, j] = Q[rows[i], rows[j]]
    B = Bflat[:m * m].reshape((m, m))
    if cholesky(D, B):
        return m
    d = np.empty(m)
    for i in range(m):
        d[i] = math.sqrt(abs(D[i, i]))
        if d[i] == 0:
            d[i] = 1.0
    Ds = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            Ds[i, j] = D[i, j] / (d[i] * d[j])
    Sy = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            Sy[i, j] = 0.5 * (Ds[i, j] + Ds[j, i])
    lam, V = eigh_jacobi(Sy)
    for i in range(m):
        for j in range(m):
            B[i, j] = (V[i, j] * math.sqrt(max(lam[j], 0.0))) * d[i]
    return -m


# --- the caches --------------------------------------------------------------------------------

@njit(cache=True)
def _slot(mode, w, bits):
    """The slot of (mode, w) in a table of 2**bits: Fibonacci hashing (Knuth, TAOCP 3, 6.4) of
    all 53 mantissa bits, the exponent and the mode, top bits kept. The widths that end an
    interval (t_end − t) differ from the ladder's only in low mantissa bits whose last ones are
    zeros; a hash of the top 30 bits put them in one slot, and they evicted each other (6700
    misses per 100 s linear cell, against 338 distinct widths)."""
    fr, ex = math.frexp(w)
    key = (np.uint64(int(fr * 9007199254740992.0)) + (np.uint64(ex & 1023) << np.uint64(53))
           + np.uint64(mode << 1))
    return int((key * _GOLDEN) >> np.uint64(64 - bits))


@njit(cache=True, inline="always")
def _trans(mode, w, rec, rd, dp, TK, TPHI, TQ, TB, TROWS, TM):
    """Slot of (mode, w) in the transition cache, computed on a miss."""
    k = _slot(mode, w, _NT_BITS)
    if TK[k, 0] == mode and TK[k, 1] == w:
        return k
    _closed_form(mode, w, rec, rd, dp, TPHI[k], TQ[k])
    TM[k] = _noise_factor(TQ[k], TROWS[k], TB[k])
    TK[k, 0], TK[k, 1] = mode, w
    return k


@njit(cache=True)
def _bridge(mode, w, rec, rd, dp, TK, TPHI, TQ, TB, TROWS, TM, BK, BPH, BPW, BG, BBF, BNB, BCN):
    """Slot of (mode, w) in the bridge cache: disturbed._bridge_law (Matheron's rule)."""
    k = _slot(mode, w, _NB_BITS)
    if BK[k, 0] == mode and BK[k, 1] == w:
        return k
    kf = _trans(mode, w, rec, rd, dp, TK, TPHI, TQ, TB, TROWS, TM)
    Qw = TQ[kf].copy()
    BPW[k] = TPHI[kf]
    kh = _trans(mode, w / 2, rec, rd, dp, TK, TPHI, TQ, TB, TROWS, TM)
    Qh = TQ[kh].copy()
    Ph = TPHI[kh].copy()
    BPH[k] = Ph
    M = mat_mat_t(Qh, Ph)
    G = np.zeros((_N, _N))
    rows = np.empty(_N, np.int64)
    r = 0
    for i in range(_N):
        if Qw[i, i] > 0.0:
            rows[r] = i
            r += 1
    if r:
        sc = np.empty(r)
        for i in range(r):
            sc[i] = math.sqrt(Qw[rows[i], rows[i]])
        A = np.empty((r, r))
        for i in range(r):
            for j in range(r):
                A[i, j] = Qw[rows[i], rows[j]] / (sc[i] * sc[j])
        inv = pinv_hermitian(A, 1e-13)
        T1 = np.empty((_N, r))
        for i in range(_N):
            for j in range(r):
                T1[i, j] = M[i, rows[j]] / sc[j]
        T2 = mat_mat(T1, inv)
        for i in range(_N):
            for j in range(r):
                G[i, rows[j]] = T2[i, j] / sc[j]
    GM = mat_mat_t(G, M)
    S = np.empty((_N, _N))
    for i in range(_N):
        for j in range(_N):
            S[i, j] = Qh[i, j] - GM[i, j]
    Sy = np.empty((_N, _N))
    for i in range(_N):
        for j in range(_N):
            Sy[i, j] = 0.5 * (S[i, j] + S[j, i])
    lam, V = eigh_jacobi(Sy)
    top = 0.0
    for j in range(_N):
        top = max(top, lam[j])
    thr = 1e-14 * max(top, 1e-300)
    nb = 0
    for j in range(_N):
        if lam[j] > thr:
            nb += 1
    BbT = BBF[k, :_N * nb].reshape((nb, _N))       # Bᵀ: the Python path's B (V's columns), transposed
    c = 0
    for j in range(_N):
        if lam[j] > thr:
            sq = math.sqrt(max(lam[j], 0.0))
            for i in range(_N):
                BbT[c, i] = V[i, j] * sq
            c += 1
    BNB[k] = nb
    BG[k] = G
    BCN[k, 0] = BCN[k, 1] = -2
    BK[k, 0], BK[k, 1] = mode, w
    return k


@njit(cache=True)
def _conditional(k, v, e, BBF, BNB, BCV, BCK, BCF, BCN):
    """disturbed._conditional for bridge slot k and barrier variant v (cached): var, gain, factor."""
    if BCN[k, v] != -2:
        return
    nb = BNB[k]
    S = gram(BBF[k, :_N * nb].reshape((nb, _N)).T)
    Se = np.empty(_N)
    mat_vec(S, e, Se)
    var = 0.0
    for i in range(_N):
        var += e[i] * Se[i]
    BCV[k, v] = var
    if not var > 0.0:
        BCN[k, v] = -1
        return
    for i in range(_N):
        BCK[k, v, i] = Se[i] / var
    R = np.empty((_N, _N))
    for i in range(_N):
        for j in range(_N):
            R[i, j] = S[i, j] - Se[i] * Se[j] / var
    Sy = np.empty((_N, _N))
    for i in range(_N):
        for j in range(_N):
            Sy[i, j] = 0.5 * (R[i, j] + R[j, i])
    lam, V = eigh_jacobi(Sy)
    top = 0.0
    for j in range(_N):
        top = max(top, lam[j])
    thr = 1e-14 * max(top, 1e-300)
    nf = 0
    for j in range(_N):
        if lam[j] > thr:
            nf += 1
    FT = BCF[k, v, :_N * nf].reshape((nf, _N))     # Fᵀ: the Python path's F, transposed
    c = 0
    for j in range(_N):
        if lam[j] > thr:
            sq = math.sqrt(lam[j])
            for i in range(_N):
                FT[c, i] = V[i, j] * sq
            c += 1
    BCN[k, v] = nf


# --- one interval ------------------------------------------------------------------------------

@njit(cache=True)
def _normals(z, cursor, n):
    i = cursor[0]
    if i + n > z.shape[0]:
        raise NoiseExhausted()
    cursor[0] = i + n
    return z[i:i + n]


@njit(cache=True)
def _tick(S, n, ov):
    S[_COUNT] += n
    if S[_COUNT] > ov[_O_MAXEV]:
        S[_STATUS] = _CHATTER
        return True
    return False


@njit(cache=True)
def _event(S, Y, kind, ov, ev):
    S[_NEV] += 1.0
    if ev.shape[0] > 0:
        n = int(S[_NREC])
        if n >= ev.shape[0]:
            raise RecordFull()
        ev[n, 0] = S[_T]
        ev[n, 1] = Y[Y1]
        ev[n, 2] = Y[Y2]
        ev[n, 3] = Y[Y3]
        ev[n, 4] = S[_MODE]
        ev[n, 5] = Y[YU]
        ev[n, 6] = kind
        S[_NREC] = n + 1
    return _tick(S, 1.0, ov)


@njit(cache=True, inline="always")
def _torque(S, x3, u, h, bridge, dp):
    if h <= 0.0:
        return
    integral, absolute, square = torque_integrals(x3, u, h, dp[_TAU3])
    _add_torque(S, integral, absolute, square, u, h, bridge, dp)


@njit(cache=True, inline="always")
def _add_torque(S, integral, absolute, square, u, h, bridge, dp):
    S[_IABS] += absolute
    S[_ISQ] += square
    S[_CHG] += (u / dp[_UMAX]) * integral if bridge else absolute
    S[_DUR] += h


@njit(cache=True, inline="always")
def _decay_memo(w, tau3, lad):
    """exp(−w/τ3) and torque_integrals' f1 = e1(w/τ3)·τ3, f2 = e1(2w/τ3)·τ3/2 for the width w, the
    same expressions on the same doubles, kept for the last width in ``lad``'s memo (a sub-step's
    width repeats: the ladder's rungs); returns (decay, f1, f2)."""
    o = _MEMO
    if lad[o] != w:
        b3 = 1.0 / tau3
        lad[o + 1] = math.exp(-w / tau3)
        lad[o + 2] = e1(b3 * w) * tau3
        lad[o + 3] = e1(2 * b3 * w) * tau3 / 2.0
        lad[o] = w
    return lad[o + 1], lad[o + 2], lad[o + 3]


@njit(cache=True, inline="always")
def _torque_f(S, x3, u, h, bridge, dp, f1, f2):
    """:func:`_torque` with torque_integrals' f1 and f2 given (:func:`_decay_memo`):
    :func:`~plant.multimode.segments.torque_integrals_given`, the integrals' own operations."""
    if h <= 0.0:
        return
    integral, absolute, square = torque_integrals_given(x3, u, h, dp[_TAU3], f1, f2)
    _add_torque(S, integral, absolute, square, u, h, bridge, dp)


@njit(cache=True)
def _apply_level(Y, S, level, bridge, dp):
    umax = dp[_UMAX]
    if not bridge:
        Y[YU] = min(max(level, -umax), umax)
        S[_FB] = 0.0
        return True
    if level != 0.0 and abs(abs(level) - umax) > 1e-9 * umax:
        return False
    if level > 0:
        Y[YU], S[_FB] = umax, 0.0
    elif level < 0:
        Y[YU], S[_FB] = -umax, 0.0
    elif Y[Y3] != 0.0:
        Y[YU], S[_FB] = -math.copysign(umax, Y[Y3]), 1.0
    else:
        Y[YU], S[_FB] = 0.0, 0.0
    return True


@njit(cache=True)
def _cross_prob(va, vb, w, sig2):
    """disturbed._cross_prob. An exponent below :data:`_EXP_ZERO` gives 0.0 without calling exp:
    the value exp returns there (it underflows to +0 below ln 2⁻¹⁰⁷⁵ ≈ −745.13), but libm's
    underflow path (errno, the SVID wrapper) cost ~⅕ of a linear cell's CPU on the disturbed
    plant, where a sub-step far from its barrier has exponents of −10⁴ and below."""
    if vb <= 0.0 or va <= 0.0:
        return 1.0
    if sig2 <= 0.0 or not w > 0.0:
        return 0.0
    x = -2.0 * va * vb / (sig2 * w)
    if x < _EXP_ZERO:
        return 0.0
    return math.exp(x)


@njit(cache=True, inline="always")
def _cross_prob_far(va, vb, w, sig2):
    """:func:`_cross_prob` where only a value of exactly 1.0 matters (a sub-step on a far rung
    crosses only when the probability is ≥ 1): that value whenever it can be 1.0, else the
    stand-in 0.0 without calling exp — when the exponent is below −1, exp of it is below 1."""
    if vb <= 0.0 or va <= 0.0:
        return 1.0
    if sig2 <= 0.0 or not w > 0.0:
        return 0.0
    x = -2.0 * va * vb / (sig2 * w)
    if x < -1.0:
        return 0.0
    return _cross_prob(va, vb, w, sig2)


_EXP_ZERO = -746.0      # exp(x) == 0.0 for every double x < −745.1332191019412 (tests/test_disturbed_jit.py)


@njit(cache=True)
def _stuck_far(w, ks, ax3, ad, u, g, tau3, sig2, decay):
    """disturbed._stuck_far's far(w); ``decay`` = exp(−w/τ3) (a rung's from the table)."""
    x3max = max(ax3, abs(u + g * decay))
    return ks - x3max - ad > FAR_SIGMAS * math.sqrt(sig2 * w)


@njit(cache=True)
def _moving_far(w, v0, slope, curv, a, s2, sd2, s5, w3):
    """disturbed._moving_far's far(w); ``w3`` = w**3 (a rung's from the table)."""
    low = min(v0, v0 + slope * w - 0.5 * curv * w * w)
    sd = a * (math.sqrt(s2 * w) + math.sqrt(sd2 * w3 / 3.0) + math.sqrt(s5 * w3 / 3.0))
    return low > FAR_SIGMAS * sd


@njit(cache=True)
def _far(kind, w, c0, c1, c2, c3, c4, c5, c6, w3, decay):
    """far(w) of the stuck (kind 0) or moving rule, the rung's w**3 and exp(−w/τ3) given (scalars
    only: an array argument costs an atomic reference-count pair per call)."""
    if kind == 0:
        return _stuck_far(w, c0, c1, c2, c3, c4, c5, c6, decay)
    return _moving_far(w, c0, c1, c2, c3, c4, c5, c6, w3)


@njit(cache=True)
def _ladder_table(lad, sub, tau3):
    """The rungs' w**3 and exp(−w/τ3), w = sub·2^(LADDER−1), …, 2·sub (the same doubles as the
    Python path's powers and exponentials of the same widths), kept until ``sub`` changes."""
    if lad[0] == sub:
        return
    w = sub * _TOP
    j = 0
    while w > sub:
        lad[1 + j] = math.pow(w, 3.0)
        lad[1 + LADDER + j] = math.exp(-w / tau3)
        w /= 2.0
        j += 1
    lad[0] = sub


@njit(cache=True)
def _ladder_width(room, sub, kind, c0, c1, c2, c3, c4, c5, c6, lad):
    """disturbed._ladder_width: (width, far); (c0, …, c6) the rule's w-free terms (_stuck_far's
    ks, |x3|, |d|, u, x3 − u, τ3, σ² or _moving_far's), rung j's w**3 and exp(−w/τ3) from ``lad``."""
    w = sub * _TOP
    if sub < room <= w:
        if kind == 0:
            far = _far(kind, room, c0, c1, c2, c3, c4, c5, c6, 0.0, math.exp(-room / c5))
        else:
            far = _far(kind, room, c0, c1, c2, c3, c4, c5, c6, math.pow(room, 3.0), 0.0)
        if far:
            return room, True
    j = 0
    while w > sub:
        if w <= room and _far(kind, w, c0, c1, c2, c3, c4, c5, c6, lad[1 + j], lad[1 + LADDER + j]):
            return w, True
        w /= 2.0
        j += 1
    return min(sub, room), False


@njit(cache=True, inline="always")
def _edot(e, x):
    """e·x for a barrier functional e (entries 0 or ±1, at most two non-zero): numpy's ``e @ x``
    (OpenBLAS ddot sums an order-8 vector from the first entry, ``dot += y[i]·x[i]``; the products
    are exact, so the two non-zero terms give the same double in any order)."""
    acc = 0.0
    for i in range(e.shape[0]):
        acc += e[i] * x[i]
    return acc


@njit(cache=True, _nrt=True)
def _bridge_miss(mode, w, recs, rds, FB, IB):
    """:func:`_bridge` on the table views (a bridge-cache miss: the views are cut only here);
    reference counting on explicitly (it allocates), not inherited from its callers."""
    dp, TK, TPHI, TQ, TB, TROWS, TM = _trans_views(FB, IB)
    nb = _NB
    BK = FB[_OFF_BK:_OFF_BK + nb * 2].reshape((nb, 2))
    BPH = FB[_OFF_BPH:_OFF_BPH + nb * 64].reshape((nb, _N, _N))
    BPW = FB[_OFF_BPW:_OFF_BPW + nb * 64].reshape((nb, _N, _N))
    BG = FB[_OFF_BG:_OFF_BG + nb * 64].reshape((nb, _N, _N))
    BBF = FB[_OFF_BBF:_OFF_BBF + nb * 64].reshape((nb, 64))
    BNB = IB[_OFF_BNB:_OFF_BNB + nb]
    BCN = IB[_OFF_BCN:_OFF_BCN + nb * 2].reshape((nb, 2))
    return _bridge(mode, w, recs, rds, dp, TK, TPHI, TQ, TB, TROWS, TM, BK, BPH, BPW, BG, BBF, BNB, BCN)


@njit(cache=True, inline="always")
def _trans_views(FB, IB):
    """(dp, TK, TPHI, TQ, TB, TROWS, TM): the transition cache's views (a miss cuts only the
    tables it needs: each view costs a reshape call and an atomic reference-count pair)."""
    nt = _NT
    dp = FB[:_DP_LEN]
    TK = FB[_OFF_TK:_OFF_TK + nt * 2].reshape((nt, 2))
    TPHI = FB[_OFF_TPHI:_OFF_TPHI + nt * 64].reshape((nt, _N, _N))
    TQ = FB[_OFF_TQ:_OFF_TQ + nt * 64].reshape((nt, _N, _N))
    TB = FB[_OFF_TB:_OFF_TB + nt * 64].reshape((nt, 64))
    TROWS = IB[_OFF_TROWS:_OFF_TROWS + nt * 8].reshape((nt, _N))
    TM = IB[_OFF_TM:_OFF_TM + nt]
    return dp, TK, TPHI, TQ, TB, TROWS, TM


@njit(cache=True, _nrt=True)
def _conditional_miss(k, v, e, recs, rds, FB, IB):
    """:func:`_conditional` on the table views (a conditional-law miss), reference counting on."""
    nb = _NB
    BBF = FB[_OFF_BBF:_OFF_BBF + nb * 64].reshape((nb, 64))
    BCV = FB[_OFF_BCV:_OFF_BCV + nb * 2].reshape((nb, 2))
    BCK = FB[_OFF_BCK:_OFF_BCK + nb * 16].reshape((nb, 2, _N))
    BCF = FB[_OFF_BCF:_OFF_BCF + nb * 128].reshape((nb, 2, 64))
    BNB = IB[_OFF_BNB:_OFF_BNB + nb]
    BCN = IB[_OFF_BCN:_OFF_BCN + nb * 2].reshape((nb, 2))
    _conditional(k, v, e, BBF, BNB, BCV, BCK, BCF, BCN)


@njit(cache=True, _nrt=True)
def _factor_add(FB, o, nf, z, cursor, Ym, base):
    """Ym = base + Fᵀᵀ·ζ (nf unit normals) for the transposed factor Fᵀ = FB[o:o + 8·nf] (nf × 8):
    Ym[i] = base[i] + Σ_c Fᵀ[c, i]·ζ[c], c ascending (:func:`plant.fixed_linalg.mat_vec`'s order on F);
    ``base`` is Ym itself (Ym += …) or the bridge mean. Reference counting on (the view)."""
    pos = _take(z, cursor, nf)
    for i in range(_N):
        acc = 0.0
        for c in range(nf):
            acc += FB[o + c * _N + i] * z[pos + c]
        Ym[i] = base[i] + acc


@njit(cache=True, _nrt=False)
def _bisect(mode, e, v, c0, Ya0, Yb0, w, tol, sig2, noisy, z, cursor, S, recs, rds, FB, IB, out, R):
    """disturbed._bisect: the offset of the first crossing; the state there into ``out``.

    The cached bridge law and conditional law are read from the flat tables by offset, their
    builders called (with the table views they need) only on a miss; Φ·Y and G·(…) are
    :func:`_gemv_flat` (numpy's dgemv order, checked bit for bit) into scratch rows, e·Y is
    :func:`_edot`: per level no allocation and no reference count but the noise factor's
    column-ordered product (:func:`_factor_add`). Compiled without reference counting (R: the
    caller's 6 × 8 scratch); a miss goes to :func:`_bridge_miss` or :func:`_conditional_miss`."""
    t0 = 0.0
    Ya, Yb, Ym, mean, diff, tmp = R[0], R[1], R[2], R[3], R[4], R[5]
    for i in range(_N):
        Ya[i] = Ya0[i]
        Yb[i] = Yb0[i]
    while w > tol:
        k = _slot(mode, w, _NB_BITS)
        if not (FB[_OFF_BK + 2 * k] == mode and FB[_OFF_BK + 2 * k + 1] == w):
            k = _bridge_miss(mode, w, recs, rds, FB, IB)
        _gemv_flat(FB, _OFF_BPW + 64 * k, _N, Ya, 0, tmp)
        for i in range(_N):
            diff[i] = Yb[i] - tmp[i]
        _gemv_flat(FB, _OFF_BPH + 64 * k, _N, Ya, 0, mean)
        _gemv_flat(FB, _OFF_BG + 64 * k, _N, diff, 0, tmp)
        for i in range(_N):
            mean[i] = mean[i] + tmp[i]
        kv = 2 * k + v
        if IB[_OFF_BCN + kv] == -2:
            _conditional_miss(k, v, e, recs, rds, FB, IB)
        var = FB[_OFF_BCV + kv]
        mu = _edot(e, mean) + c0
        a = _edot(e, Ya) + c0
        b = _edot(e, Yb) + c0
        half = w / 2
        if not noisy:
            for i in range(_N):
                Ym[i] = mean[i]
            cm = _edot(e, Ym) + c0
        elif var > 0.0:
            sd = math.sqrt(var)
            if a > 0.0 and b > 0.0 and sig2 > 0.0:
                cm = hitting_midpoint(a, b, mu, sd, sig2 * half, z, cursor)
            else:
                cm = mu + sd * normal(z, cursor)
            dc = cm - mu
            for i in range(_N):
                Ym[i] = mean[i] + FB[_OFF_BCK + _N * kv + i] * dc
            nf = IB[_OFF_BCN + kv]
            if nf > 0:                                  # a column-ordered product, as numpy's
                _factor_add(FB, _OFF_BCF + 64 * kv, nf, z, cursor, Ym, Ym)
        else:
            nb = IB[_OFF_BNB + k]
            if nb:
                _factor_add(FB, _OFF_BBF + 64 * k, nb, z, cursor, Ym, mean)
            else:
                for i in range(_N):
                    Ym[i] = mean[i] + 0.0
            cm = _edot(e, Ym) + c0
        pl = _cross_prob(a, cm, half, sig2)
        pr = _cross_prob(cm, b, half, sig2)
        pc = 1.0 - (1.0 - pl) * (1.0 - pr)
        S[_NSUB] += 1.0
        if pl >= 1.0 or (pl > 0.0 and uniform(z, cursor) * pc < pl):
            for i in range(_N):
                Yb[i] = Ym[i]
        else:
            for i in range(_N):
                Ya[i] = Ym[i]
            t0 = t0 + half
        w = half
    for i in range(_N):
        out[i] = Yb[i]
    return t0 + w


@njit(cache=True)
def _breakaway(Y, S, g, ov, ev):
    Y[Y2] = 0.0
    S[_MODE] = 3.0 if g > 0 else 1.0
    S[_NBRK] += 1.0
    S[_JUST] = 1.0
    return _event(S, Y, _BREAKAWAY, ov, ev)


@njit(cache=True)
def _velocity_zero(Y, S, dirn, dp, ov, ev):
    g = Y[Y3] + Y[YD]
    ks = max(dp[_KS] + Y[Y5], 0.0)
    Y[Y2] = 0.0
    if dirn * g > ks:
        kind = _REFLECTION
    elif -dirn * g > ks:
        S[_MODE] = 1.0 if S[_MODE] == 3.0 else 3.0
        S[_NBRK] += 1.0
        kind = _REVERSAL
    else:
        S[_MODE] = 2.0
        S[_NSTK] += 1.0
        kind = _STICK
    return _event(S, Y, kind, ov, ev)


@njit(cache=True, inline="always")
def _take(z, cursor, n):
    """The read position of the next ``n`` unit normals of ``z`` (advances ``cursor``; _normals
    without the slice)."""
    i = cursor[0]
    if i + n > z.shape[0]:
        raise NoiseExhausted()
    cursor[0] = i + n
    return i


@njit(cache=True, inline="always")
def _gemv_flat(F, off, m, x, xoff, out):
    """out[:m] = A @ x[xoff:xoff + m] for the C-ordered m × m matrix A = F[off:off + m·m]
    (m in 1–5 or 8): :func:`_gemv`'s arithmetic, operation for operation, on flat indices (no
    array views: each view costs an atomic reference-count pair in the sub-step loop)."""
    m1 = m - (m & 3)
    r = m - m1
    for i in range(m):
        row = off + i * m
        y = 0.0
        if m1 > 0:
            a0 = a1 = a2 = a3 = 0.0
            for k in range(0, m1, 4):
                a0 = _fma(F[row + k], x[xoff + k], a0)
                a1 = _fma(F[row + k + 1], x[xoff + k + 1], a1)
                a2 = _fma(F[row + k + 2], x[xoff + k + 2], a2)
                a3 = _fma(F[row + k + 3], x[xoff + k + 3], a3)
            y = (a0 + a2) + (a1 + a3)
        if r == 1:
            y = _fma(F[row + m1], x[xoff + m1], y)
        elif r == 2:
            y = y + _fma(F[row + m1], x[xoff + m1], F[row + m1 + 1] * x[xoff + m1 + 1])
        elif r == 3:
            y = y + _fma(F[row + m1 + 2], x[xoff + m1 + 2],
                         _fma(F[row + m1], x[xoff + m1], F[row + m1 + 1] * x[xoff + m1 + 1]))
        out[i] = y


@njit(cache=True, _nrt=True)
def _trans_miss(mode, w, recs, rds, FB, IB):
    """_trans on the table views (a cache miss: the views are cut only here)."""
    dp, TK, TPHI, TQ, TB, TROWS, TM = _trans_views(FB, IB)
    return _trans(mode, w, recs, rds, dp, TK, TPHI, TQ, TB, TROWS, TM)


@njit(cache=True, _nrt=True)
def _noise_add(k, m, z, cursor, FB, IB, Yb, Yc):
    """Yb[rows] += factor · (m unit normals) for transition slot k (m = TM[k] ≠ 0)."""
    if m > 0 and (m <= 5 or m == 8):
        pos = _take(z, cursor, m)
        _gemv_flat(FB, _OFF_TB + k * 64, m, z, pos, Yc)
        add = Yc
    else:                                           # another size, or the eigen-factor (m < 0)
        m = abs(m)
        add = np.empty(m)
        B = FB[_OFF_TB + k * 64:_OFF_TB + k * 64 + m * m].reshape((m, m))
        _gemv(B, _normals(z, cursor, m), add)
    for i in range(m):
        Yb[IB[_OFF_TROWS + k * _N + i]] += add[i]


@njit(cache=True, inline="always")
def _width(Y, S, t_end, noisy, sig_d2, ov, dp, lad):
    """The sub-step's head (disturbed._segment up to the width): (breaks, g, mode, dirn, room,
    h_fb, ks, sig2, w, far, rungs, just). ``breaks``: a stuck shaft at (or past) stiction, g its
    x3 + d. Nothing is drawn; Y[YKC] is set (idempotent), the just-broke flag only read."""
    mode = int(S[_MODE])
    room = t_end - S[_T]
    x2, x3, x5, d, u = Y[Y2], Y[Y3], Y[Y5], Y[YD], Y[YU]
    tau3 = dp[_TAU3]
    h_fb = math.inf if S[_FB] == 0.0 else tau3 * math.log1p(abs(x3) / dp[_UMAX])
    room_fb = min(room, h_fb)
    ks = max(dp[_KS] + x5, 0.0)
    sub = ov[_O_SUB]
    g = 0.0
    just = False
    if mode == 2:
        dirn = 0.0
        g = x3 + d
        if abs(g) > ks:
            return True, g, mode, dirn, room, h_fb, ks, 0.0, 0.0, False, False, just
        sig2 = sig_d2
        if ks - abs(x3) - abs(d) > 0.0:
            w, far = _ladder_width(room_fb, sub, 0, ks, abs(x3), abs(d), u, x3 - u, tau3, sig2, lad)
        else:
            w, far = min(sub, room_fb), False
        rungs = False
    else:
        dirn = 1.0 if mode == 3 else -1.0
        kc = dp[_KC] if dp[_KC] + x5 >= 0.0 else -x5
        Y[YKC] = kc
        reflecting = dirn * (x3 + d) >= ks
        sig2 = dp[_SIG2MOV] if noisy else 0.0
        if S[_JUST] != 0.0:
            reflecting = True
            just = True
        if dirn * x2 > 0.0:
            a = dp[_ALPHA]
            slope = dirn * a * (x3 + d) - a * (kc + x5)
            curv = a * (abs(u - x3) / tau3 + abs(d) / dp[_TAUD] + abs(x5) / dp[_TAU5])
            w, far = _ladder_width(room_fb, sub, 1, dirn * x2, slope, curv, a, dp[_S2], dp[_SD2], dp[_S5], lad)
        else:
            w, far = min(sub, room_fb), False
        if reflecting and not far:
            w = min(ov[_O_RSUB], room_fb)
        rungs = reflecting and not far
    return False, g, mode, dirn, room, h_fb, ks, sig2, w, far, rungs, just


@njit(cache=True, inline="always")
def _decide(Y, Yb, e, mode, dirn, ks, sig2, w, far, rungs, z, cursor):
    """After the Gaussian step Y → Yb: the Skorokhod push of a reflected sub-step, else the
    crossing test (e, c0: the barrier functional; v: its variant). Returns (crossed, v, c0)."""
    crossed = False
    for i in range(_N):
        e[i] = 0.0
    c0 = 0.0
    v = 0
    if mode != 2 and rungs:
        va, vb = dirn * Y[Y2], dirn * Yb[Y2]
        if sig2 > 0.0:
            mm = 0.5 * (va + vb - math.sqrt(math.pow(vb - va, 2.0) - 2.0 * sig2 * w * math.log(uniform(z, cursor))))
        else:
            mm = min(va, vb)
        if mm < 0.0:
            Yb[Y2] -= dirn * mm
            Yb[Y1] -= dirn * mm * w / 2.0
    else:
        # on a far rung only a probability of exactly 1 decides (below, no uniform is drawn
        # then): _cross_prob_far gives the same decision, the same barrier (up ≥ dn) when it crosses
        if mode == 2:
            ga, gb = Y[Y3] + Y[YD], Yb[Y3] + Yb[YD]
            if far:
                up = _cross_prob_far(ks - ga, ks - gb, w, sig2)
                dn = _cross_prob_far(ks + ga, ks + gb, w, sig2)
            else:
                up = _cross_prob(ks - ga, ks - gb, w, sig2)
                dn = _cross_prob(ks + ga, ks + gb, w, sig2)
            sgn = -1.0 if up >= dn else 1.0
            e[Y3] = e[YD] = sgn
            prob = 1.0 - (1.0 - up) * (1.0 - dn)
            c0 = ks
            v = 0 if sgn < 0.0 else 1
        else:
            e[Y2] = dirn
            va, vb = dirn * Y[Y2], dirn * Yb[Y2]
            if far:
                prob = _cross_prob_far(va, vb, w, sig2)
            else:
                if va > 0.0 and vb > 0.0 and sig2 > 0.0 and w > 0.0:
                    ex = -2.0 * va * vb / (sig2 * w)     # _cross_prob's exponent, the same operations
                    if -745.0 < ex < -1e-6:              # 0 < prob < 1: the decision below, cheaper
                        return exp_below(ex, z, cursor), v, c0
                prob = _cross_prob(va, vb, w, sig2)
        # uniform_below: the decision uniform(z, cursor) < prob, the same draw, erfc only when needed
        if prob >= 1.0 or (prob > 0.0 and not far and uniform_below(z, cursor, prob)):
            crossed = True
    return crossed, v, c0


@njit(cache=True, inline="always")
def _finish(Y, S, Yb, w, crossed, mode, dirn, room, h_fb, t_end, bridge, dp, ov, ev, lad):
    """The sub-step's tail from Y to Yb over w: peak, then :func:`_finish_rest`."""
    if mode != 2:
        S[_PEAK] = substep_peak(Y, Yb, w, S[_PEAK])
    else:
        S[_PEAK] = max(S[_PEAK], abs(Y[Y1]), abs(Yb[Y1]))
    return _finish_rest(Y, S, Yb, w, crossed, mode, dirn, room, h_fb, t_end, bridge, dp, ov, ev, lad)


@njit(cache=True, inline="always")
def _finish_rest(Y, S, Yb, w, crossed, mode, dirn, room, h_fb, t_end, bridge, dp, ov, ev, lad):
    """Integrals, x3's closed form, the event (the peak is the caller's: a moving one needs
    the Hermite peak of :func:`_substep_peak`)."""
    x3, u = Y[Y3], Y[YU]
    decay, f1, f2 = _decay_memo(w, dp[_TAU3], lad)
    _torque_f(S, x3, u, w, bridge, dp, f1, f2)
    for i in range(_N):
        Y[i] = Yb[i]
    Y[Y3] = u + (x3 - u) * decay
    S[_T] += w
    if crossed:
        if mode == 2:
            return _breakaway(Y, S, Y[Y3] + Y[YD], ov, ev)
        return _velocity_zero(Y, S, dirn, dp, ov, ev)
    if w == h_fb and h_fb <= room:
        Y[Y3] = 0.0
        Y[YU] = 0.0
        S[_FB] = 0.0
        return _event(S, Y, _FLYBACK_END, ov, ev)
    if w == room:
        S[_T] = t_end
    return False


@njit(cache=True, _nrt=False)
def _segment(Y, S, t_end, bridge, noisy, sig_d2, ov, z, cursor, ev, dp, recs, rds, FB, IB, Yb, Yc, e, lad, R):
    """disturbed._segment: one sub-step (or to the next event); True when the interval must stop.
    The general path (cache misses, every noise factor, the bisection); :func:`_fast_segment`
    takes the common sub-steps."""
    breaks, g, mode, dirn, room, h_fb, ks, sig2, w, far, rungs, just = _width(Y, S, t_end, noisy, sig_d2, ov, dp, lad)
    if breaks:
        return _breakaway(Y, S, g, ov, ev)
    if just:
        S[_JUST] = 0.0
    k = _slot(mode, w, _NT_BITS)
    if not (FB[_OFF_TK + 2 * k] == mode and FB[_OFF_TK + 2 * k + 1] == w):
        k = _trans_miss(mode, w, recs, rds, FB, IB)
    _gemv_flat(FB, _OFF_TPHI + k * 64, _N, Y, 0, Yb)
    m = IB[_OFF_TM + k]
    if noisy and m:
        _noise_add(k, m, z, cursor, FB, IB, Yb, Yc)
    S[_NSUB] += 1.0
    if _tick(S, 1.0, ov):
        return True
    crossed, v, c0 = _decide(Y, Yb, e, mode, dirn, ks, sig2, w, far, rungs, z, cursor)
    if crossed:
        w = _bisect_flat(mode, e, v, c0, Y, Yb, w, ov[_O_TOL], sig2, noisy, z, cursor, S, recs, rds, FB, IB, Yc, R)
        for i in range(_N):
            Yb[i] = Yc[i]
        if S[_STATUS] != _OK:
            return True
    return _finish(Y, S, Yb, w, crossed, mode, dirn, room, h_fb, t_end, bridge, dp, ov, ev, lad)


@njit(cache=True, _nrt=False)
def _bisect_flat(mode, e, v, c0, Ya0, Yb0, w, tol, sig2, noisy, z, cursor, S, recs, rds, FB, IB, out, R):
    """_bisect (kept as the sub-step's entry to it)."""
    return _bisect(mode, e, v, c0, Ya0, Yb0, w, tol, sig2, noisy, z, cursor, S, recs, rds, FB, IB, out, R)


@njit(cache=True, _nrt=False)
def _fast_segment(Y, S, t_end, bridge, noisy, sig_d2, ov, z, cursor, ev, dp, FB, IB, Yb, Yc, e, lad, hold):
    """:func:`_segment` for a sub-step whose transition is cached with a Cholesky noise factor
    (or none), the same operations in the same order. Compiled without numba's reference counting
    (it allocates nothing), which otherwise costs tens of atomic increments per sub-step.
    Returns −1 before changing anything when it does not apply (the caller runs _segment), 0 or 1
    (the sub-step done; 1: stop), 2 when a crossing was drawn (Yb holds the end, e the barrier,
    hold[0:3] = (w, v, c0)): :func:`_tail` bisects and finishes it. Every function it calls must allocate nothing (numba compiles them without
    reference counting too, and refuses an allocation)."""
    breaks, g, mode, dirn, room, h_fb, ks, sig2, w, far, rungs, just = _width(Y, S, t_end, noisy, sig_d2, ov, dp, lad)
    if breaks:
        return 1 if _breakaway(Y, S, g, ov, ev) else 0
    k = _slot(mode, w, _NT_BITS)
    if not (FB[_OFF_TK + 2 * k] == mode and FB[_OFF_TK + 2 * k + 1] == w):
        return -1
    m = IB[_OFF_TM + k]
    if noisy and m != 0 and not (m > 0 and (m <= 5 or m == 8)):
        return -1
    if just:
        S[_JUST] = 0.0
    _gemv_flat(FB, _OFF_TPHI + k * 64, _N, Y, 0, Yb)
    if noisy and m:
        pos = _take(z, cursor, m)
        _gemv_flat(FB, _OFF_TB + k * 64, m, z, pos, Yc)
        for i in range(m):
            Yb[IB[_OFF_TROWS + k * _N + i]] += Yc[i]
    S[_NSUB] += 1.0
    if _tick(S, 1.0, ov):
        return 1
    crossed, v, c0 = _decide(Y, Yb, e, mode, dirn, ks, sig2, w, far, rungs, z, cursor)
    if crossed:
        hold[0], hold[1], hold[2] = w, v, c0
        return 2
    if mode != 2:
        S[_PEAK] = _substep_peak(Y, Yb, w, S[_PEAK])
    else:
        S[_PEAK] = max(S[_PEAK], abs(Y[Y1]), abs(Yb[Y1]))
    return 1 if _finish_rest(Y, S, Yb, w, False, mode, dirn, room, h_fb, t_end, bridge, dp, ov, ev, lad) else 0


@njit(cache=True)
def _substep_peak(Xa, Xb, h, peak):
    """plant.multimode.moving.substep_peak on this plant's Y (x1, x2, x4 at the same positions)
    through :func:`plant.multimode.segments.hermite_peak`."""
    pk = max(peak, abs(Xa[Y1]), abs(Xb[Y1]))
    da, db = Xa[Y2] - Xa[Y4], Xb[Y2] - Xb[Y4]
    if da * db < 0:
        pk = max(pk, hermite_peak(h, Xa[Y1], da, Xb[Y1], db))
    return pk


@njit(cache=True, _nrt=False)
def _tail(Y, S, t_end, bridge, noisy, sig_d2, ov, z, cursor, ev, dp, recs, rds, FB, IB, Yb, Yc, e, hold, crossed, lad, R):
    """The rest of a sub-step :func:`_fast_segment` left at a drawn crossing (``crossed``): the
    bisection and :func:`_finish`, with the mode, direction, room and flyback end recomputed from
    the unchanged Y and S."""
    mode = int(S[_MODE])
    dirn = 0.0 if mode == 2 else (1.0 if mode == 3 else -1.0)
    room = t_end - S[_T]
    h_fb = math.inf if S[_FB] == 0.0 else dp[_TAU3] * math.log1p(abs(Y[Y3]) / dp[_UMAX])
    sig2 = sig_d2 if mode == 2 else (dp[_SIG2MOV] if noisy else 0.0)
    w, v, c0 = hold[0], int(hold[1]), hold[2]
    if crossed:
        w = _bisect_flat(mode, e, v, c0, Y, Yb, w, ov[_O_TOL], sig2, noisy, z, cursor, S, recs, rds, FB, IB, Yc, R)
        for i in range(_N):
            Yb[i] = Yc[i]
        if S[_STATUS] != _OK:
            return True
    return _finish(Y, S, Yb, w, crossed, mode, dirn, room, h_fb, t_end, bridge, dp, ov, ev, lad)


# The caches and constants travel as two flat arrays (a tuple of twenty arrays cost ~25 µs of
# numba's argument typing per call); the miss handlers cut them into the named tables.
_DP_LEN = 15
_MEMO = 1 + 2 * LADDER        # the last width's decay and integrals (_decay_memo), after the ladder's
_LAD_LEN = _MEMO + 4          # the step ladder's table (_ladder_table) and the memo, last in FB
_LAYOUT_F = (("dp", _DP_LEN), ("TK", _NT * 2), ("TPHI", _NT * 64), ("TQ", _NT * 64), ("TB", _NT * 64),
             ("BK", _NB * 2), ("BPH", _NB * 64), ("BPW", _NB * 64), ("BG", _NB * 64), ("BBF", _NB * 64),
             ("BCV", _NB * 2), ("BCK", _NB * 16), ("BCF", _NB * 128), ("LAD", _LAD_LEN))
_LAYOUT_I = (("TROWS", _NT * 8), ("TM", _NT), ("BNB", _NB), ("BCN", _NB * 2))
_SIZE_F = sum(n for _, n in _LAYOUT_F)
_SIZE_I = sum(n for _, n in _LAYOUT_I)


def _offsets(layout):
    out, o = {}, 0
    for name, n in layout:
        out[name] = o
        o += n
    return out


_OFF_F, _OFF_I = _offsets(_LAYOUT_F), _offsets(_LAYOUT_I)
_OFF_TK, _OFF_TPHI, _OFF_TQ, _OFF_TB = _OFF_F["TK"], _OFF_F["TPHI"], _OFF_F["TQ"], _OFF_F["TB"]
_OFF_TROWS, _OFF_TM = _OFF_I["TROWS"], _OFF_I["TM"]
_OFF_BK, _OFF_BPH, _OFF_BPW, _OFF_BG = _OFF_F["BK"], _OFF_F["BPH"], _OFF_F["BPW"], _OFF_F["BG"]
_OFF_BBF, _OFF_BCV, _OFF_BCK, _OFF_BCF = _OFF_F["BBF"], _OFF_F["BCV"], _OFF_F["BCK"], _OFF_F["BCF"]
_OFF_BNB, _OFF_BCN = _OFF_I["BNB"], _OFF_I["BCN"]


@njit(cache=True)
def interval_kernel(x, mode, flyback, t0, duration, offsets, levels, bridge, ov, recs, rds, FB, IB, z, zpos, ev, out):
    """disturbed.advance over [t0, t0 + duration): ``out[:7]`` the new state, ``out[7:]`` the work
    sheet; returns the new read position in ``z`` (from ``zpos``). (recs, rds, FB, IB): kernel_inputs()."""
    return interval_k(x, mode, flyback, t0, duration, offsets, levels, offsets.shape[0], bridge, ov, recs, rds, FB, IB,
                      z, zpos, ev, out, np.empty(WORK_SIZE), np.empty(1, np.int64))


WORK_SIZE = 10 * _N + 3


@njit(cache=True, _nrt=False)
def interval_k(x, mode, flyback, t0, duration, offsets, levels, k, bridge, ov, recs, rds, FB, IB, z, zpos, ev, out,
               work, cursor):
    """:func:`interval_kernel` with the drive's first ``k`` segments of ``offsets``, ``levels``
    and the scratch ``work`` (WORK_SIZE floats) and ``cursor`` (one int64) of a compiled caller
    (nothing copied or allocated per interval).

    Compiled without numba's reference counting: it allocates nothing, and with it each call
    increfed and decrefed its thirteen array arguments (26 atomic operations per sample), and
    so did each layer of the rarer paths (:func:`_segment`, :func:`_tail`, :func:`_bisect`). These
    run without it too; only what allocates — a cache miss (:func:`_trans_miss`,
    :func:`_bridge_miss`, :func:`_conditional_miss`), an eigen-factor (:func:`_noise_add`), a
    column-ordered factor product (:func:`_factor_add`) — is compiled with reference counting, set
    explicitly (numba otherwise passes the caller's flag on to its callees)."""
    dp = FB[:_DP_LEN]
    noisy = ov[_O_NOISE] != 0.0
    sig_d2 = dp[_SD2] if noisy else 0.0
    S = out[7:]
    for i in range(SHEET_SIZE):
        S[i] = 0.0
    S[_T], S[_MODE], S[_FB] = t0, mode, 1.0 if flyback else 0.0
    cursor[0] = zpos
    Y = work[:_N]
    Y[Y1], Y[Y2], Y[Y3], Y[Y4], Y[Y5] = x[0], x[1], x[2], x[3], x[4]
    Y[YD] = x[6] if x.shape[0] > 6 else 0.0
    Y[YKC], Y[YU] = dp[_KC], x[5]
    Yb = work[_N:2 * _N]
    Yc = work[2 * _N:3 * _N]
    e = work[3 * _N:4 * _N]                         # set by each sub-step before use
    hold = work[4 * _N:4 * _N + 3]
    R = work[4 * _N + 3:WORK_SIZE].reshape((6, _N))     # the bisection's rows
    lad = FB[_SIZE_F - _LAD_LEN:]
    _ladder_table(lad, ov[_O_SUB], dp[_TAU3])
    stop = False
    for seg in range(k):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < k else duration)
        if not _apply_level(Y, S, levels[seg], bridge, dp):
            S[_STATUS] = _BAD_LEVEL
            break
        if seg > 0 and _event(S, Y, _LEVEL, ov, ev):
            break
        while S[_T] < t_seg_end:
            r = _fast_segment(Y, S, t_seg_end, bridge, noisy, sig_d2, ov, z, cursor, ev, dp, FB, IB, Yb, Yc, e, lad,
                              hold)
            if r == -1:
                stop = _segment(Y, S, t_seg_end, bridge, noisy, sig_d2, ov, z, cursor, ev, dp, recs, rds, FB, IB, Yb, Yc,
                                e, lad, R)
            elif r == 2:
                stop = _tail(Y, S, t_seg_end, bridge, noisy, sig_d2, ov, z, cursor, ev, dp, recs, rds, FB, IB, Yb, Yc, e,
                             hold, True, lad, R)
            else:
                stop = r == 1
            if stop or S[_STATUS] != _OK:
                stop = True
                break
            if not (abs(Y[Y1]) <= ov[_O_DIVERGE]):
                S[_STATUS] = _DIVERGED
                stop = True
                break
        if stop:
            break
    if S[_STATUS] == _OK:
        S[_T] = t0 + duration
    out[0], out[1], out[2], out[3], out[4], out[5], out[6] = Y[Y1], Y[Y2], Y[Y3], Y[Y4], Y[Y5], Y[YU], Y[YD]
    return cursor[0]


# --- Python side -------------------------------------------------------------------------------

_LOCAL = threading.local()


def _constants(params) -> np.ndarray:
    p = params
    dp = np.empty(15)
    dp[_TAUD] = p.disturbance_torque_tau
    dp[_BD] = 1.0 / p.disturbance_torque_tau
    dp[_SD2] = 2.0 * p.disturbance_torque_std ** 2 / p.disturbance_torque_tau
    dp[_TAU3] = p.motor_time_constant
    dp[_TAU5] = p.correlated_friction_tau
    dp[_SIG2MOV] = p.alpha ** 2 * p.sigma2_sq
    dp[_ALPHA] = p.alpha
    dp[_BETA3], dp[_BETA4], dp[_SIG4] = p.beta3, p.beta4, p.sigma4_sq
    dp[_UMAX], dp[_KS], dp[_KC] = p.u_max, p.stiction, p.coulomb
    dp[_S2], dp[_S5] = p.sigma2_sq, p.sigma5_sq
    dp.flags.writeable = False
    return dp


def kernel_inputs(params, options) -> tuple:
    """(options vector, recs, rds, FB, IB): interval_kernel's inputs after ``levels, bridge``. FB and
    IB hold the constants and this thread's cache tables for ``params`` (filled on use; a pure
    function of the parameters, so sharing them cannot change a result)."""
    last = getattr(_LOCAL, "last", None)
    if last is not None and last[0] is params:      # the same object as the last call: no hashing
        K = last[1]
    else:
        K = _tables_for(params)
        _LOCAL.last = (params, K)
    ov = options.__dict__.get("_disturbed_vector")
    if ov is None:
        ov = np.array([1.0 if options.noise else 0.0, options.substep, options.reflect_substep,
                       options.bisection_tol, float(options.max_events), options.diverge_error])
        ov.flags.writeable = False
        object.__setattr__(options, "_disturbed_vector", ov)
    return (ov, *K)


def _tables_for(params) -> tuple:
    """This thread's (recs, rds, FB, IB) for ``params`` (kernel_inputs)."""
    memo = getattr(_LOCAL, "memo", None)
    if memo is None:
        memo = _LOCAL.memo = {}
    K = memo.get(params)
    if K is None:
        if len(memo) > 8:
            memo.clear()
        recs = params.kernel_record()
        rds = recs.copy()
        rds[0]["beta5"] = 1.0 / params.disturbance_torque_tau
        rds[0]["sigma5_sq"] = 2.0 * params.disturbance_torque_std ** 2 / params.disturbance_torque_tau
        rds[0]["sigma2_sq"] = 0.0
        rds[0]["sigma4_sq"] = 0.0
        FB = np.zeros(_SIZE_F)
        FB[:_DP_LEN] = _constants(params)
        o = _DP_LEN
        for name, n in _LAYOUT_F[1:]:
            if name in ("TK", "BK"):
                FB[o:o + n] = -1.0              # empty slots
            o += n
        FB[_SIZE_F - _LAD_LEN + _MEMO] = np.nan     # no width memoized (NaN equals no width)
        IB = np.zeros(_SIZE_I, np.int64)
        o = 0
        for name, n in _LAYOUT_I:
            if name == "BCN":
                IB[o:o + n] = -2                # conditional laws not computed
            o += n
        K = memo[params] = (recs, rds, FB, IB)
    return K
