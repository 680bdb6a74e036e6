"""Modes 1 and 3, the shaft moving: Φ (3-20)/(3-21), the noise (4-8)/(4-10), the mean path.

Inside the kernels the state is the augmented vector of (3-5)::

    Xa = [x1, x2, x3, x4, x5, kc, u]

where slot 5 carries the Coulomb level kc as the constant coordinate that makes the affine
drift linear (it is the parameter k̄c, not plant state; should k̄c + x5 be negative at the start
of a moving segment, the segment runs with kc = −x5, i.e. an effective Coulomb level of 0 — a
4.7σ event for Table 2-1). Mode 3 (x2 > 0) has ẋ2 = α(x3 − x5 − kc) + α·w2, mode 1 the
mirror image with s = −1 → +1 (the matrices are right, the prose's order is not; SPEC §2).

With y3 = β3·τ, y5 = β5·τ and s = +1 in mode 1, −1 in mode 3, the mean path (3-20)/(3-21)::

    x1(τ) = x1 + τ·x2 − e1(β4τ)/β4·x4 + α·e2(y3)/β3²·x3 + α·e3(y3)/β3²·u
            + s·α·e2(y5)/β5²·x5 + s·α·τ²/2·kc
    x2(τ) = x2 + α·e1(y3)/β3·x3 + α·e2(y3)/β3·u + s·α·e1(y5)/β5·x5 + s·α·τ·kc
    x3(τ) = e^(−y3)·x3 + e1(y3)·u     x4(τ) = e^(−β4τ)·x4     x5(τ) = e^(−y5)·x5

The noise enters through the x2, x4 and x5 columns only, so its covariance lives on the block
(x1, x2, x4, x5); the w2 share is closed form and the w4, w5 shares are integrated by 4-node
Gauss–Legendre on panels with β·Δ ≤ 1e-3, exact to round-off because those columns are
polynomials in v times e^(−β4 v), e^(−β5 v) (:func:`q_moving`; plant.multimode.transition uses an 8-node
rule for the same integrals; Van Loan is the test oracle).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.fixed_linalg import gemv_lanes
from plant.gauss_legendre import nodes_weights
from plant.expfun import e1, e2, e3, e4
from plant.randomness import normal
from plant.multimode.segments import hermite_peak, torque_crossing_time

__all__ = ["phi_moving", "phi_q_moving", "q_moving", "chol_psd", "mean_path", "gaussian_step", "deterministic_move",
           "NOISY_BLOCK"]

A1, A2, A3, A4, A5, AKC, AU = range(7)
NOISY_BLOCK = np.array([A1, A2, A4, A5])
_GL4_X, _GL4_W = nodes_weights(4)          # constants: no LAPACK (plant.gauss_legendre)
_PANEL_RATE = 1e-3
_SERIES_LIMIT = 0.5
_BRENT_ITER = 200


@njit(cache=True, _nrt=False)   # allocation-free: no reference counts (interval._fast_span)
def phi_moving(mode, h, p, P):
    """Φ_1 or Φ_3 of (3-20)/(3-21) into P (7 × 7, augmented vector)."""
    ex4, E4, ex5, E5 = _decays(h, p.beta4, p.beta5)
    _phi_fill(mode, h, p, P, ex4, E4, ex5, E5)


@njit(cache=True, _nrt=False, inline="always")
def _decays(h, b4, b5):
    """(e^(−β4h), e1(β4h), e^(−β5h), e1(β5h)): the x4 and x5 decays that Φ and Q share. Each
    exp and expm1 is evaluated once; when β4·h and β5·h are the same number (Table 2-1 has
    β4 = β5) the x5 pair is the x4 pair, the same values the separate calls return."""
    y4 = b4 * h
    y5 = b5 * h
    ex4 = math.exp(-y4)
    E4 = e1(y4)
    if y5 == y4:
        return ex4, E4, ex4, E4
    return ex4, E4, math.exp(-y5), e1(y5)


@njit(cache=True, _nrt=False)
def _phi_fill(mode, h, p, P, ex4, E4, ex5, E5):
    """:func:`phi_moving` from the decays of :func:`_decays`; e1(β3h) and e2(β3h), which two
    entries each use, evaluated once."""
    a, b3, b4, b5 = p.alpha, p.beta3, p.beta4, p.beta5
    for i in range(7):
        for j in range(7):
            P[i, j] = 1.0 if i == j else 0.0
    y3 = b3 * h
    y5 = b5 * h
    s = 1.0 if mode == 1 else -1.0
    E3 = e1(y3)
    F3 = e2(y3)
    P[A3, A3] = math.exp(-y3)                 # q33
    P[A3, AU] = E3                            # q37
    P[A4, A4] = ex4                           # q44
    P[A1, A4] = -E4 / b4                      # q14
    P[A1, A2] = h
    P[A1, A3] = a * F3 / (b3 * b3)            # q13
    P[A2, A3] = a * E3 / b3                   # q23
    P[A1, AU] = a * e3(y3) / (b3 * b3)        # q17
    P[A2, AU] = a * F3 / b3                   # q27
    P[A5, A5] = ex5                           # q55
    P[A1, A5] = s * a * e2(y5) / (b5 * b5)    # q15
    P[A2, A5] = s * a * E5 / b5               # q25
    P[A1, AKC] = s * a * h * h / 2.0
    P[A2, AKC] = s * a * h


@njit(cache=True, _nrt=False)   # allocation-free: no reference counts (interval._fast_span)
def phi_q_moving(mode, h, p, P, Q):
    """:func:`phi_moving` into P and :func:`q_moving` into Q for one width h, the decays they
    share evaluated once: the same numbers as the two calls (a noisy segment's fresh last step)."""
    ex4, E4, ex5, E5 = _decays(h, p.beta4, p.beta5)
    _phi_fill(mode, h, p, P, ex4, E4, ex5, E5)
    _q_fill(mode, h, p, Q, E4, E5)


@njit(cache=True, _nrt=False)
def mean_path(mode, tau, X, p):
    """(x1, x2, x3, x4) of Φ(τ)·X by the scalar closed forms in the module docstring."""
    a, b3, b4, b5 = p.alpha, p.beta3, p.beta4, p.beta5
    s = 1.0 if mode == 1 else -1.0
    y3 = b3 * tau
    y5 = b5 * tau
    x1 = (X[A1] + tau * X[A2] - e1(b4 * tau) / b4 * X[A4] + a * e2(y3) / (b3 * b3) * X[A3]
          + a * e3(y3) / (b3 * b3) * X[AU] + s * a * e2(y5) / (b5 * b5) * X[A5] + s * a * tau * tau / 2.0 * X[AKC])
    x2 = (X[A2] + a * e1(y3) / b3 * X[A3] + a * e2(y3) / b3 * X[AU] + s * a * e1(y5) / b5 * X[A5]
          + s * a * tau * X[AKC])
    x3 = math.exp(-y3) * X[A3] + e1(y3) * X[AU]
    x4 = math.exp(-b4 * tau) * X[A4]
    return x1, x2, x3, x4


@njit(cache=True, _nrt=False)
def mean_velocity(mode, tau, X, p):
    """x2(τ) of Φ(τ)·X, the second line of the mean path in the module docstring."""
    a, b3, b5 = p.alpha, p.beta3, p.beta5
    s = 1.0 if mode == 1 else -1.0
    y3 = b3 * tau
    return (X[A2] + a * e1(y3) / b3 * X[A3] + a * e2(y3) / b3 * X[AU] + s * a * e1(b5 * tau) / b5 * X[A5]
            + s * a * tau * X[AKC])


@njit(cache=True, _nrt=False)
def _fint(y, kind):
    """F(y) = ∫₀^y f(x) dx for f = e2(x)·e^(−x) (kind 0), e2(x)·e1(x) (1), e2(x)² (2), |y| < 0.5.

    Taylor series of the integrands: the coefficient of x^m is (−1)^m·c_m/m! with
    c_m = 2^m − 1 − m (kind 0, m ≥ 2), 2 − 2^m + m (kind 1, m ≥ 2), 2^m − 2 − 2m (kind 2, m ≥ 3);
    the terms shrink by ≤ 2|y|/m ≤ 1/m, summed until below half an ulp (leading terms y³/6,
    y⁴/8, y⁵/20).
    """
    m0 = 3 if kind == 2 else 2
    fact = 2.0 if m0 == 2 else 6.0
    pw2 = 4.0 if m0 == 2 else 8.0
    ypow = y ** (m0 + 1)
    total = 0.0
    for m in range(m0, 80):
        if m > m0:
            fact *= m
            pw2 *= 2.0
            ypow *= y
        if kind == 0:
            c = pw2 - 1.0 - m
        elif kind == 1:
            c = 2.0 - pw2 + m
        else:
            c = pw2 - 2.0 - 2.0 * m
        term = c / fact * ypow / (m + 1)
        if m % 2 == 1:
            term = -term
        total += term
        if term != 0.0 and abs(term) <= 2.0 ** -60 * abs(total):
            break
    return total


@njit(cache=True, _nrt=False)   # allocation-free: no reference counts (interval._fast_span)
def _q_closed(h, y4, y5, a, b4, b5, q2, q4, q5, s, Q, E4, E5):
    """The integrals of :func:`q_moving` in closed form (y = β·h < 0.5), e-functions of plant.expfun:

    w2: q2·[h³/3, h²/2; ·, h] on (x1, x2);
    w4: x1x1 q4·e4(y4)/β4³, x1x4 −q4·e1(y4)²/(2β4²), x4x4 q4·e1(2y4)/(2β4) (as in plant.multimode.stuck);
    w5: x1x1 q5·α²·F2(y5)/β5⁵, x1x2 q5·α²·F1(y5)/β5⁴, x1x5 q5·s·α·F0(y5)/β5³,
        x2x2 q5·α²·e4(y5)/β5³, x2x5 q5·s·α·e1(y5)²/(2β5²), x5x5 q5·e1(2y5)/(2β5),
    with F0, F1, F2 the integrals of e2·e^(−x), e2·e1, e2² (:func:`_fint`); E4 = e1(y4) and
    E5 = e1(y5) come from the caller (:func:`_decays`).
    """
    same = y5 == y4             # then e4 and e1(2y) of x5 are those of x4 (one evaluation each)
    G4 = e4(y4)
    G5 = G4 if same else e4(y5)
    D4 = e1(2.0 * y4)
    D5 = D4 if same else e1(2.0 * y5)
    Q[0, 0] = q2 * h * h * h / 3.0 + q4 * G4 / b4 ** 3 + q5 * a * a * _fint(y5, 2) / b5 ** 5
    Q[0, 1] = Q[1, 0] = q2 * h * h / 2.0 + q5 * a * a * _fint(y5, 1) / b5 ** 4
    Q[1, 1] = q2 * h + q5 * a * a * G5 / b5 ** 3
    Q[0, 2] = Q[2, 0] = -q4 * E4 * E4 / (2.0 * b4 * b4)
    Q[0, 3] = Q[3, 0] = q5 * s * a * _fint(y5, 0) / b5 ** 3
    Q[1, 2] = Q[2, 1] = 0.0
    Q[1, 3] = Q[3, 1] = q5 * s * a * E5 * E5 / (2.0 * b5 * b5)
    Q[2, 2] = q4 * D4 / (2.0 * b4)
    Q[2, 3] = Q[3, 2] = 0.0
    Q[3, 3] = q5 * D5 / (2.0 * b5)


@njit(cache=True, _nrt=False)   # allocation-free: no reference counts (interval._fast_span)
def q_moving(mode, h, p, Q):
    """Noisy 4 × 4 block (x1, x2, x4, x5) of COV[N] = ∫₀ʰ Φ(v) Q Φ(v)ᵀ dv  (4-8).

    The w2 column of Φ(v) is (v, 1, 0, 0) on the block, so its share is closed form:
    α²σ2²·[h³/3, h²/2; h²/2, h] on (x1, x2). The w4 and w5 columns, (−e1(β4v)/β4, 0, e^(−β4v), 0)
    and (s·α·e2(β5v)/β5², s·α·e1(β5v)/β5, 0, e^(−β5v)), are polynomials of degree ≤ 2 times a power
    series in β·v. For β·h < 0.5 their integrals are closed forms (:func:`_q_closed`); beyond,
    the products (degree ≤ 4) are integrated by 4-node Gauss–Legendre, exact through degree 7,
    on panels with β·Δ ≤ 1e-3: the first neglected term is below (2β·Δ)⁴·2e-7 ≈ 3e-18 of the
    entry, i.e. round-off (Van Loan is the test oracle).
    """
    y4, y5 = p.beta4 * h, p.beta5 * h
    if max(y4, y5) < _SERIES_LIMIT:
        E4 = e1(y4)
        _q_fill(mode, h, p, Q, E4, E4 if y5 == y4 else e1(y5))
    else:
        _q_fill(mode, h, p, Q, 0.0, 0.0)


@njit(cache=True, _nrt=False)
def _q_fill(mode, h, p, Q, E4, E5):
    """:func:`q_moving`, with E4 = e1(β4h) and E5 = e1(β5h) given (used by the closed form only)."""
    a, b4, b5 = p.alpha, p.beta4, p.beta5
    q2, q4, q5 = a * a * p.sigma2_sq, p.sigma4_sq, p.sigma5_sq
    s = 1.0 if mode == 1 else -1.0
    y4, y5 = b4 * h, b5 * h
    if max(y4, y5) < _SERIES_LIMIT:
        _q_closed(h, y4, y5, a, b4, b5, q2, q4, q5, s, Q, E4, E5)
        return
    i11 = i12 = i14 = i15 = i22 = i25 = i44 = i55 = 0.0
    rate = max(b4, b5)
    panels = max(1, int(math.ceil(rate * h / _PANEL_RATE)))
    width = h / panels
    for pnl in range(panels):
        lo = pnl * width
        for k in range(_GL4_X.shape[0]):
            v = lo + 0.5 * width * (_GL4_X[k] + 1.0)
            w = 0.5 * width * _GL4_W[k]
            r1 = -e1(b4 * v) / b4            # x4 column: x1 and x4 rows
            r4 = math.exp(-b4 * v)
            c1 = s * a * e2(b5 * v) / (b5 * b5)   # x5 column: x1, x2 and x5 rows
            c2 = s * a * e1(b5 * v) / b5
            c5 = math.exp(-b5 * v)
            wq4, wq5 = w * q4, w * q5
            i11 += wq4 * r1 * r1 + wq5 * c1 * c1
            i14 += wq4 * r1 * r4
            i44 += wq4 * r4 * r4
            i12 += wq5 * c1 * c2
            i22 += wq5 * c2 * c2
            i15 += wq5 * c1 * c5
            i25 += wq5 * c2 * c5
            i55 += wq5 * c5 * c5
    Q[0, 0] = q2 * h * h * h / 3.0 + i11
    Q[0, 1] = Q[1, 0] = q2 * h * h / 2.0 + i12
    Q[1, 1] = q2 * h + i22
    Q[0, 2] = Q[2, 0] = i14
    Q[0, 3] = Q[3, 0] = i15
    Q[1, 2] = Q[2, 1] = 0.0
    Q[1, 3] = Q[3, 1] = i25
    Q[2, 2] = i44
    Q[2, 3] = Q[3, 2] = 0.0
    Q[3, 3] = i55


@njit(cache=True)
def _sqrt_pos(q):
    return math.sqrt(q) if q > 0 else 0.0


@njit(cache=True, _nrt=False)   # allocation-free: no reference counts (interval._fast_span)
def chol_psd(Q, L):
    """Lower factor L·Lᵀ = Q of a PSD 4 × 4 (4-29)–(4-34), in diagonally scaled coordinates;
    zero rows (4-28) and rank-deficient directions give zero columns."""
    d = (_sqrt_pos(Q[0, 0]), _sqrt_pos(Q[1, 1]), _sqrt_pos(Q[2, 2]), _sqrt_pos(Q[3, 3]))
    for i in range(4):
        for j in range(4):
            L[i, j] = 0.0
    for j in range(4):
        if d[j] == 0.0:
            continue
        acc = 1.0
        for k in range(j):
            acc -= L[j, k] * L[j, k]
        if acc <= 1e-15:
            continue
        piv = math.sqrt(acc)
        L[j, j] = piv
        for i in range(j + 1, 4):
            if d[i] == 0.0:
                continue
            acc2 = Q[i, j] / (d[i] * d[j])
            for k in range(j):
                acc2 -= L[i, k] * L[j, k]
            L[i, j] = acc2 / piv
    for i in range(4):
        for j in range(4):
            L[i, j] *= d[i]


@njit(cache=True)
def noise_factor_moving(mode, h, p, L):
    """L with L·Lᵀ = the noisy block of COV[N(h)]."""
    Q = np.empty((4, 4))
    q_moving(mode, h, p, Q)
    chol_psd(Q, L)


@njit(cache=True)
def gaussian_step(X, P, L, z, cursor, out):
    """out = P·X + N, N = L·ζ on the noisy block, ζ four unit normals of the stream."""
    for i in range(7):
        acc = 0.0
        for j in range(7):
            acc += P[i, j] * X[j]
        out[i] = acc
    z0 = normal(z, cursor)
    z1 = normal(z, cursor)
    z2 = normal(z, cursor)
    z3 = normal(z, cursor)
    for r in range(4):
        out[NOISY_BLOCK[r]] += L[r, 0] * z0 + L[r, 1] * z1 + L[r, 2] * z2 + L[r, 3] * z3


@njit(cache=True, _nrt=False, inline="always")
def substep_peak(Xa, Xb, h, peak):
    """max(peak, |x1| at both ends, the interior extremum of the cubic Hermite of x1)."""
    pk = max(peak, abs(Xa[A1]), abs(Xb[A1]))
    da, db = Xa[A2] - Xa[A4], Xb[A2] - Xb[A4]
    if da * db < 0:
        pk = max(pk, hermite_peak(h, Xa[A1], da, Xb[A1], db))
    return pk


# --- roots of the mean path -----------------------------------------------------------------

@njit(cache=True, _nrt=False)
def _mean_value(which, mode, tau, X, p):
    """which = 0: mean velocity x2(τ); which = 1: ẋ1 = x2(τ) − x4(τ)."""
    _, x2, _, x4 = mean_path(mode, tau, X, p)
    return x2 if which == 0 else x2 - x4


@njit(cache=True, _nrt=False)
def brent_mean(which, mode, X, p, a, b, fa, fb):
    """Brent's root of _mean_value on [a, b] with f(a)·f(b) ≤ 0, to ~1e-16 s (scipy's brentq)."""
    xtol, rtol = 1e-16, 8.9e-16
    xpre, xcur = a, b
    fpre, fcur = fa, fb
    xblk, fblk, spre, scur = 0.0, 0.0, 0.0, 0.0
    if fpre == 0.0:
        return xpre
    if fcur == 0.0:
        return xcur
    for _ in range(_BRENT_ITER):
        if fpre != 0.0 and fcur != 0.0 and (fpre < 0.0) != (fcur < 0.0):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = (xtol + rtol * abs(xcur)) / 2.0
        sbis = (xblk - xcur) / 2.0
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):
                spre, scur = scur, stry
            else:
                spre, scur = sbis, sbis
        else:
            spre, scur = sbis, sbis
        xpre, fpre = xcur, fcur
        if abs(scur) > delta:
            xcur += scur
        else:
            xcur += delta if sbis > 0 else -delta
        fcur = _mean_value(which, mode, xcur, X, p)
    return xcur


@njit(cache=True, _nrt=False)
def velocity_extremum_time(mode, X, p):
    """τ where ẋ2 ∝ x3(τ) ∓ kc changes sign (x2's only extremum), or inf."""
    s = -1.0 if mode == 1 else 1.0          # direction of motion
    kc = max(p.coulomb + X[A5], 0.0)
    return torque_crossing_time(X[A3], X[AU], s * kc, p.tau3)


@njit(cache=True, _nrt=False)
def first_mean_zero(mode, X, p, h):
    """First τ in (0, h] where the mean velocity reaches 0, or inf (exact to ~1e-15 s).

    ẋ2 ∝ x3(τ) − s·kc changes sign at most once (x3 is monotone), so x2 has one extremum;
    the root is bracketed on [0, t_ext] or [t_ext, h].
    """
    s = 1.0 if mode == 3 else -1.0
    if s * X[A2] <= 0.0:
        return 0.0          # at zero velocity below stiction: sticks at once
    t_ext = velocity_extremum_time(mode, X, p)
    lo, flo = 0.0, X[A2]
    for k in range(2):
        if k == 0:
            if not (0.0 < t_ext < h):
                continue
            hi = t_ext
        else:
            hi = h
        fhi = _mean_value(0, mode, hi, X, p)
        if s * fhi <= 0.0:
            return brent_mean(0, mode, X, p, lo, hi, flo, fhi)
        lo, flo = hi, fhi
    return math.inf


@njit(cache=True, _nrt=False)
def mean_x1_peak(mode, X, p, h):
    """Largest |x1| at the interior roots of ẋ1 = x2 − x4 of the mean path on (0, h)."""
    t_ext = velocity_extremum_time(mode, X, p)
    peak = 0.0
    lo = 0.0
    glo = X[A2] - X[A4]
    for k in range(2):
        if k == 0:
            if not (0.0 < t_ext < h):
                continue
            hi = t_ext
        else:
            hi = h
        ghi = _mean_value(1, mode, hi, X, p)
        if glo * ghi < 0.0:
            r = brent_mean(1, mode, X, p, lo, hi, glo, ghi)
            x1 = mean_path(mode, r, X, p)[0]
            peak = max(peak, abs(x1))
        lo, glo = hi, ghi
    return peak


@njit(cache=True)
def deterministic_move(mode, X, p, h, noisy, z, cursor, peak):
    """Advance a moving segment without white velocity noise by h in place; returns the peak.

    The path is the mean path; with noise on (σ2 = 0 here) the slow x4/x5 diffusions add one
    exact Gaussian jump, whose effect on x1 inside the segment is ~1e-15 rad, so the peak
    comes from the mean path's exact interior extrema and the end points.
    """
    peak = max(peak, abs(X[A1]), mean_x1_peak(mode, X, p, h))
    P = np.empty((7, 7))
    phi_moving(mode, h, p, P)
    Xn = np.empty(7)
    gemv_lanes(P, X, Xn)            # P @ X's bits on OpenBLAS Haswell, without BLAS (plant.fixed_linalg)
    if noisy:
        L = np.empty((4, 4))
        noise_factor_moving(mode, h, p, L)
        zz = np.empty(4)
        for i in range(4):
            zz[i] = normal(z, cursor)
        for r in range(4):
            Xn[NOISY_BLOCK[r]] += L[r, 0] * zz[0] + L[r, 1] * zz[1] + L[r, 2] * zz[2] + L[r, 3] * zz[3]
    X[:] = Xn
    return max(peak, abs(X[A1]))
