"""Noise-free motion of the two-mass plant between events, and Φ(h), Q(h) from it (compiled).

Kernel vector layout (the multimode kernels' first seven slots, so their stuck propagation,
torque integrals and sub-step peak apply unchanged)::

    X = [x1, x2, x3, x4, x5, kc, u, φ, ω_m]

kc the Coulomb level in force (k̄c, or −x5 when k̄c + x5 < 0, as plant.multimode), u the drive.
``propagate`` is exact (plant.two_mass.modes): x3 by its closed form, the core modally, x1 by
the integral of x2 − x4, x4 by its mean decay; stuck, x1 and x4 as (3-22). Φ(h) is the matrix
of this linear map (columns from unit vectors); Q(h) = ∫₀ʰ Φ(v)·Qc·Φ(v)ᵀ dv (4-8) with
Qc = diag(α²σ2² on x2, σ4² on x4, σ5² on x5) while moving — Gauss–Legendre (8 nodes) on panels
with ρ·width ≤ 0.125, ρ the largest |λ|: the integrand is a sum of e^((λ_i+λ_j)v) terms, so
the rule is exact to round-off (truncation below 0.25^16/16! ≈ 1e-23 relative).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.gauss_legendre import nodes_weights
from plant.two_mass.modes import M_STUCK, NCORE, _div_k, _small, _tiny, phi1_e, phi2_e

A1, A2, A3, A4, A5, AKC, AU, PHI, WM = range(9)
NX = 9
# The noisy block of X (rows of the noise factor): x1, x2, x4, x5, φ, ω_m.
NB = np.array([A1, A2, A4, A5, PHI, WM])
NNB = 6
_GL_X, _GL_W = nodes_weights(8)      # constants: no LAPACK (plant.gauss_legendre)


@njit(cache=True)
def mode_row(mode):
    """Decomposition row of a mode (1 → 0, 3 → 1, 2 → 2)."""
    return 0 if mode == 1 else (1 if mode == 3 else M_STUCK)


@njit(cache=True)
def start_coords(X, mode, p, q, Vi, W0, B0):
    """Modal coordinates w = V⁻¹z and b̃ = V⁻¹b of the segment starting at X; returns n."""
    r = mode_row(mode)
    z = np.empty(NCORE)
    b = np.zeros(NCORE)
    if mode == 2:
        n = 3
        z[0], z[1], z[2] = X[PHI], X[WM], X[A3]
        b[2] = p.beta3 * X[AU]
    else:
        n = 5
        s = 1.0 if mode == 3 else -1.0
        z[0], z[1], z[2], z[3], z[4] = X[A2], X[PHI], X[WM], X[A3], X[A5]
        b[0] = -s * p.alpha * X[AKC]
        b[3] = p.beta3 * X[AU]
    for i in range(n):
        acc = 0j
        acc2 = 0j
        for j in range(n):
            acc += Vi[r, i, j] * z[j]
            acc2 += Vi[r, i, j] * b[j]
        W0[i] = acc
        B0[i] = acc2
    return n


@njit(cache=True)
def propagate(X, mode, t, p, q, V, Vi, lam, Xout):
    """Xout = the noise-free state t seconds after X in ``mode`` (exact)."""
    C = np.empty((4, NCORE), dtype=np.complex128)
    F = np.empty((2, NCORE))
    propagate_w(X, mode, t, p, V, Vi, lam, Xout, C, F)


@njit(cache=True, _nrt=False)
def _start_coords_w(X, mode, p, Vi, C, F):
    """:func:`start_coords` into C[0] (w), C[1] (b̃) with F[0], F[1] for z and b; returns n."""
    r = mode_row(mode)
    for j in range(NCORE):
        F[1, j] = 0.0
    if mode == 2:
        n = 3
        F[0, 0], F[0, 1], F[0, 2] = X[PHI], X[WM], X[A3]
        F[1, 2] = p.beta3 * X[AU]
    else:
        n = 5
        s = 1.0 if mode == 3 else -1.0
        F[0, 0], F[0, 1], F[0, 2], F[0, 3], F[0, 4] = X[A2], X[PHI], X[WM], X[A3], X[A5]
        F[1, 0] = -s * p.alpha * X[AKC]
        F[1, 3] = p.beta3 * X[AU]
    for i in range(n):
        acc = 0j
        acc2 = 0j
        for j in range(n):
            acc += Vi[r, i, j] * F[0, j]
            acc2 += Vi[r, i, j] * F[1, j]
        C[0, i] = acc
        C[1, i] = acc2
    return n


@njit(cache=True, _nrt=False)
def _state_from_coords(X, mode, t, p, V, r, n, Xout, C):
    """The end state of :func:`propagate_w` / :func:`_propagate_g` from the propagated modal
    coordinates C[2], C[3] (rows back through V) and the decoupled x3, x4, x1 closed forms."""
    _state_from_coords_e(X, mode, p, V, r, n, Xout, C, math.exp(-p.beta3 * t), -math.expm1(-p.beta4 * t))


@njit(cache=True, _nrt=False)
def _state_from_coords_e(X, mode, p, V, r, n, Xout, C, e3, E4):
    """:func:`_state_from_coords` with its two scalar exponentials given: e3 = e^(−β3·t),
    E4 = −expm1(−β4·t) (the same values, computed once per t by the callers that build Φ and Q)."""
    b4 = p.beta4
    for j in range(NX):
        Xout[j] = X[j]
    Xout[A3] = X[AU] + (X[A3] - X[AU]) * e3
    Xout[A4] = X[A4] * (1.0 - E4)
    if mode == 2:
        Xout[A1] = X[A1] - X[A4] * E4 / b4
        Xout[A2] = 0.0
        Xout[PHI] = _row_w(V, r, 0, C, 2, n)
        Xout[WM] = _row_w(V, r, 1, C, 2, n)
    else:
        Xout[A2] = _row_w(V, r, 0, C, 2, n)
        Xout[PHI] = _row_w(V, r, 1, C, 2, n)
        Xout[WM] = _row_w(V, r, 2, C, 2, n)
        Xout[A5] = _row_w(V, r, 4, C, 2, n)
        Xout[A1] = X[A1] + _row_w(V, r, 0, C, 3, n) - X[A4] * E4 / b4


@njit(cache=True, _nrt=False)
def propagate_w(X, mode, t, p, V, Vi, lam, Xout, C, F):
    """:func:`propagate` with scratch C (4 × NCORE complex) and F (2 × NCORE): the same
    operations, allocation-free and compiled without reference counting."""
    n = _start_coords_w(X, mode, p, Vi, C, F)
    _propagate_c(X, mode, t, p, V, lam, Xout, C, n)


@njit(cache=True, _nrt=False)
def rotor_after(X, t, V, lam, C, Xout):
    """Stuck load: Xout[PHI], Xout[WM] after t from X, its start coordinates already in C[0], C[1]
    (:func:`_start_coords_w` of X in mode 2): the two rows of :func:`_propagate_c` the stuck
    segment keeps (x1, x3, x4 are plant.multimode.stuck's), by the same operations — only e^x and
    φ1 enter them (φ2 and the scalar exponentials go to rows nobody reads here)."""
    r = M_STUCK
    for i in range(3):
        x = lam[r, i] * t
        e = np.exp(x)
        f1 = phi1_e(x, e)
        C[2, i] = e * C[0, i] + t * f1 * C[1, i]
    Xout[PHI] = _row_w(V, r, 0, C, 2, 3)
    Xout[WM] = _row_w(V, r, 1, C, 2, 3)


@njit(cache=True, _nrt=False)
def _propagate_c(X, mode, t, p, V, lam, Xout, C, n):
    """:func:`propagate_w` with X's start coordinates already in C[0], C[1] (n of them, from
    :func:`_start_coords_w` of this X and mode)."""
    r = mode_row(mode)
    for i in range(n):
        x = lam[r, i] * t
        e = np.exp(x)
        f1 = phi1_e(x, e)
        C[2, i] = e * C[0, i] + t * f1 * C[1, i]
        C[3, i] = t * f1 * C[0, i] + t * t * phi2_e(x, e) * C[1, i]
    _state_from_coords(X, mode, t, p, V, r, n, Xout, C)


@njit(cache=True, _nrt=False)
def _modal_factors(mode, t, lam, G, k):
    """G[0, k], G[1, k], G[2, k] = e^x, φ1(x), φ2(x) at x = λ_i·t for the modes of ``mode``: what
    :func:`propagate_w` computes for every column of Φ(t) and every source of Q alike.

    The series of φ1 and φ2 (|x| < ½) of all modes are summed side by side, a term of each per
    pass (G[3, k], G[4, k] hold the running terms): each series takes the steps of
    :func:`plant.two_mass.modes.phi1_e` / ``phi2_e`` in its own order and stops where they stop,
    so the values are theirs; the interleaving only lets the independent divisions overlap."""
    r = mode_row(mode)
    n = 3 if mode == 2 else 5
    act = 0
    for i in range(n):
        x = lam[r, i] * t
        e = np.exp(x)
        G[0, k, i] = e
        if _small(x):
            G[1, k, i] = 1.0 + 0j
            G[3, k, i] = 1.0 + 0j
            G[2, k, i] = 0.5 + 0j
            G[4, k, i] = 0.5 + 0j
            act |= (1 << i) | (1 << (8 + i))
        else:
            G[1, k, i] = phi1_e(x, e)
            G[2, k, i] = phi2_e(x, e)
    for kk in range(2, 32):
        if act == 0:
            break
        for i in range(n):
            if kk < 30 and act & (1 << i):              # φ1: k = 2 … 29
                term = _div_k(G[3, k, i] * (lam[r, i] * t), kk)
                total = G[1, k, i] + term
                G[3, k, i] = term
                G[1, k, i] = total
                if _tiny(term, total):
                    act &= ~(1 << i)
            if kk >= 3 and act & (1 << (8 + i)):        # φ2: k = 3 … 31
                term = _div_k(G[4, k, i] * (lam[r, i] * t), kk)
                total = G[2, k, i] + term
                G[4, k, i] = term
                G[2, k, i] = total
                if _tiny(term, total):
                    act &= ~(1 << (8 + i))
        if kk == 29:
            act &= ~0xFF                                # φ1's series ends at k = 29
    return


@njit(cache=True, _nrt=False)
def _propagate_g(X, mode, t, p, V, Vi, lam, Xout, C, F, G, k):
    """:func:`propagate_w` with e^x, φ1(x), φ2(x) read from G[:, k] (:func:`_modal_factors` at
    the same t): the same operations on the same values."""
    r = mode_row(mode)
    n = _start_coords_w(X, mode, p, Vi, C, F)
    for i in range(n):
        f1 = G[1, k, i]
        C[2, i] = G[0, k, i] * C[0, i] + t * f1 * C[1, i]
        C[3, i] = t * f1 * C[0, i] + t * t * G[2, k, i] * C[1, i]
    _state_from_coords(X, mode, t, p, V, r, n, Xout, C)


@njit(cache=True, _nrt=False, inline="always")
def _row_w(V, r, k, C, c, n):
    """Re Σ_i V[r, k, i]·C[c, i]: the real part of numba's complex sum (componentwise from 0j)
    of its complex products (real part a.real·b.real − a.imag·b.imag, CPython's _Py_c_prod),
    without the imaginary parts nobody reads: the same operations on the same values."""
    acc = 0.0
    for i in range(n):
        v = V[r, k, i]
        w = C[c, i]
        acc += v.real * w.real - v.imag * w.imag
    return acc


@njit(cache=True)
def _row(V, r, k, w, n):
    acc = 0j
    for i in range(n):
        acc += V[r, k, i] * w[i]
    return acc.real


@njit(cache=True)
def unit_coords(mode, p, Vi, U):
    """U[j, 0], U[j, 1] = w, b̃ (:func:`_start_coords_w`) of the unit vector e_j, j < NX: the
    start coordinates every column of Φ and every noise source of Q begin with, independent of
    the width, so :func:`transition_u` and :func:`process_noise_u` compute them once."""
    E = np.zeros(NX)
    C = np.empty((4, NCORE), dtype=np.complex128)
    F = np.empty((2, NCORE))
    for j in range(NX):
        E[j] = 1.0
        n = _start_coords_w(E, mode, p, Vi, C, F)
        for i in range(n):
            U[j, 0, i] = C[0, i]
            U[j, 1, i] = C[1, i]
        E[j] = 0.0


@njit(cache=True, _nrt=False, inline="always")
def _unit_column(E, j, mode, t, p, V, U, G, k, e3, E4, Xout, C):
    """:func:`_propagate_g` of the unit vector E = e_j with its start coordinates read from U[j]
    and e^(−β3·t), −expm1(−β4·t) given: the same operations on the same values."""
    r = mode_row(mode)
    n = 3 if mode == 2 else 5
    for i in range(n):
        f1 = G[1, k, i]
        C[2, i] = G[0, k, i] * U[j, 0, i] + t * f1 * U[j, 1, i]
        C[3, i] = t * f1 * U[j, 0, i] + t * t * G[2, k, i] * U[j, 1, i]
    _state_from_coords_e(E, mode, p, V, r, n, Xout, C, e3, E4)


@njit(cache=True)
def transition(mode, h, p, q, V, Vi, lam, P):
    """P = Φ(h) (9 × 9) of ``mode``, the matrix of :func:`propagate`."""
    U = np.empty((NX, 2, NCORE), dtype=np.complex128)
    unit_coords(mode, p, Vi, U)
    transition_u(mode, h, p, V, lam, U, P)


@njit(cache=True)
def transition_u(mode, h, p, V, lam, U, P):
    """:func:`transition` with the unit start coordinates U (:func:`unit_coords` of ``mode``)."""
    _transition_k(mode, h, p, V, lam, U, P, np.zeros(NX), np.empty(NX), np.empty((4, NCORE), dtype=np.complex128),
                  np.empty((5, 1, NCORE), dtype=np.complex128))


@njit(cache=True, _nrt=False)
def _transition_k(mode, h, p, V, lam, U, P, E, col, C, G):
    """:func:`transition_u`'s work in the caller's scratch (E zeros), compiled without reference
    counting (the per-column calls counted their array arguments: ~90 atomic operations)."""
    _modal_factors(mode, h, lam, G, 0)
    e3 = math.exp(-p.beta3 * h)
    E4 = -math.expm1(-p.beta4 * h)
    for j in range(NX):
        E[j] = 1.0
        _unit_column(E, j, mode, h, p, V, U, G, 0, e3, E4, col, C)
        for i in range(NX):
            P[i, j] = col[i]
        E[j] = 0.0


@njit(cache=True)
def process_noise(mode, h, p, q, V, Vi, lam, Q):
    """Q (6 × 6 on NB) = COV of the noise over h while moving (module docstring); stuck: w4 only."""
    U = np.empty((NX, 2, NCORE), dtype=np.complex128)
    unit_coords(mode, p, Vi, U)
    process_noise_u(mode, h, p, V, lam, U, Q)


@njit(cache=True)
def process_noise_u(mode, h, p, V, lam, U, Q):
    """:func:`process_noise` with the unit start coordinates U (:func:`unit_coords` of ``mode``);
    e^(λt), φ1, φ2 and the two scalar exponentials once per Gauss–Legendre node."""
    for i in range(NNB):
        for j in range(NNB):
            Q[i, j] = 0.0
    if h <= 0.0:
        return
    r = mode_row(mode)
    rho = p.beta4
    for i in range(NCORE):
        rho = max(rho, abs(lam[r, i]))
    panels = max(1, int(math.ceil(rho * h / 0.125)))
    _noise_k(mode, h, p, V, lam, U, Q, panels, np.zeros(NX), np.empty(NX), np.empty((4, NCORE), dtype=np.complex128),
             np.empty((5, panels * 8, NCORE), dtype=np.complex128), np.empty(panels * 8), np.empty(panels * 8))


@njit(cache=True, _nrt=False)
def _noise_k(mode, h, p, V, lam, U, Q, panels, E, col, C, G, e3, E4):
    """:func:`process_noise_u`'s Gauss–Legendre sum (Q zeroed, ``panels`` panels) in the caller's
    scratch, compiled without reference counting (its node loop counted ~200 atomic operations)."""
    width = h / panels
    for pn in range(panels):
        lo = pn * width
        for k in range(8):
            v = lo + 0.5 * width * (_GL_X[k] + 1.0)
            _modal_factors(mode, v, lam, G, pn * 8 + k)
            e3[pn * 8 + k] = math.exp(-p.beta3 * v)
            E4[pn * 8 + k] = -math.expm1(-p.beta4 * v)
    srcs = (A2, A4, A5)
    for s_i in range(3):
        j = srcs[s_i]
        if mode == 2 and j != A4:
            continue
        if j == A2:
            qj = p.alpha * p.alpha * p.sigma2_sq
        elif j == A4:
            qj = p.sigma4_sq
        else:
            qj = p.sigma5_sq
        if qj == 0.0:
            continue
        for pn in range(panels):
            lo = pn * width
            for k in range(8):
                v = lo + 0.5 * width * (_GL_X[k] + 1.0)
                E[j] = 1.0
                _unit_column(E, j, mode, v, p, V, U, G, pn * 8 + k, e3[pn * 8 + k], E4[pn * 8 + k], col, C)
                E[j] = 0.0
                wk = 0.5 * width * _GL_W[k] * qj
                for a in range(NNB):
                    ca = col[NB[a]]
                    for b in range(NNB):
                        Q[a, b] += wk * ca * col[NB[b]]
    for a in range(NNB):
        for b in range(a + 1, NNB):
            Q[a, b] = Q[b, a] = 0.5 * (Q[a, b] + Q[b, a])


@njit(cache=True)
def psd_factor(Q, L):
    """Lower factor L·Lᵀ = Q of a PSD matrix in diagonally scaled coordinates (as (4-20)–(4-34)):
    zero rows and rank-deficient directions give zero columns."""
    n = Q.shape[0]
    d = np.empty(n)
    for i in range(n):
        d[i] = math.sqrt(Q[i, i]) if Q[i, i] > 0.0 else 0.0
    for i in range(n):
        for j in range(n):
            L[i, j] = 0.0
    for j in range(n):
        if d[j] == 0.0:
            continue
        acc = 1.0
        for k in range(j):
            acc -= L[j, k] * L[j, k]
        if acc <= 1e-14:
            continue
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
