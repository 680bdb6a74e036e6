"""Locating a velocity zero in a noisy moving segment (SPEC §2, section 4.5).

Two locators, both compiled:

* **bridge** (default): advance in exact Gaussian sub-steps X⁺ = Φ(h)X + N, their widths taken
  from a ladder h·2^k (:func:`ladder_thresholds`: long far from a zero, the fixed sub-step near
  one); a zero crossing of x2 inside a sub-step is a sign change or, with both ends on one side,
  happens with the Brownian-bridge probability exp(−2·v_a·v_b/(α²σ2²·h)); it is located by
  bridge bisection, each midpoint drawn from its Gaussian law given both ends (Matheron's rule:
  X_m = X_m,free + G·(X_b − X_b,free), G = Q(w/2)·Φ(w/2)ᵀ·Q(w)⁻¹), accepted in proportion to
  the probability that the halves contain a crossing, so the located time has the exact law of
  the first crossing of the bridge. It stops at ``bisection_tol`` (≤ 1 µs).
* **newton**: the seed's method (4-38): the noise sample Z of the whole segment is held fixed
  and Newton runs on the velocity g ← g − v(g)/a(g), with a bracketing fallback.

While the torque in the direction of motion still exceeds ks a crossing is reflected (the
shaft cannot stick and friction cannot reverse it). Sub-steps there add the Skorokhod push:
the bridge minimum of x2 is drawn exactly, m = ½(v_a + v_b − √((v_b − v_a)² − 2α²σ2²h·ln U)),
x2 is lifted by max(0, −m), and x1 receives the push for half the sub-step.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numba.np.arrayobj import reshape_unchecked

from plant.fixed_linalg import gemv_lanes
from plant.multimode.moving import (NOISY_BLOCK, chol_psd, mean_path, mean_velocity, noise_factor_moving, phi_moving,
                          q_moving, substep_peak, velocity_extremum_time)
from plant.multimode.crossing import crossed as _crossed    # the crossing decision (table of log Φ)
from plant.randomness import ZPOS, NoiseExhausted, normal, uniform, uniform_below

__all__ = ["newton_segment", "substep_tables", "bisection_tables", "ladder_thresholds", "LADDER",
           "FAR_SIGMAS", "hitting_midpoint"]

A1, A2, A3, A4, A5, AKC, AU = range(7)


@njit(cache=True, _nrt=False, inline="always")
def _square(v, n):
    """The n × n C-ordered view of the contiguous n² floats ``v``: ``v.reshape((n, n))`` built in
    place (numba's ``reshape_unchecked``), without the runtime call and reference counts of
    ``reshape``, so the bisection runs without numba's runtime (issue 27)."""
    f = v.itemsize
    return reshape_unchecked(v, (n, n), (n * f, f))


@njit(cache=True, _nrt=False, inline="always")
def _copy(dst, src):
    """dst[:] = src element by element (a slice assignment needs numba's runtime, which the
    interval's fast path, plant.multimode.interval._fast_span, is compiled without)."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@njit(cache=True, _nrt=False)
def _cross_prob(va, vb, h, sig_v2):
    """Probability that a Brownian bridge of x2 from va to vb over h crosses 0."""
    if (va > 0) != (vb > 0) or va == 0.0 or vb == 0.0:
        return 1.0
    return math.exp(-2.0 * va * vb / (sig_v2 * h))


@njit(cache=True, _nrt=False)
def _bridge_law(mode, w, p, Ph, Pw, G, C, V):
    """The law of the midpoint X(w/2) of a sub-step of width w given both its ends.

    On the noisy block (x1, x2, x4, x5), with Q_h = COV[N(w/2)], Q_w = COV[N(w)] and Φ_h the
    block of Φ(w/2): G = Q_h·Φ_hᵀ·Q_w⁻¹ and, given X_a and X_b,

        X_m ~ N(Φ(w/2)·X_a + G·(X_b − Φ(w)·X_a),  Σ = Q_h − G·Φ_h·Q_h)

    (Gaussian conditioning; the deterministic coordinates follow Φ(w/2)·X_a). Fills Ph = Φ(w/2),
    Pw = Φ(w), G, and C with √Σ_22 in C[0, 0], the regression of (x1, x4, x5) on x2 in
    C[1:, 0] and the Cholesky factor of their conditional covariance in C[1:, 1:], so that the
    bisection draws x2 alone first.

    Q_w⁻¹ is applied through the Cholesky factor of the diagonally scaled Q_w; a direction
    without noise (a zero row, e.g. x4 when σ4 = 0) gets a zero column of G, which is the
    least-squares solution there. ``V`` is scratch space of ≥ 116 floats.
    """
    phi_moving(mode, w / 2, p, Ph)
    phi_moving(mode, w, p, Pw)
    Q1 = _square(V[0:16], 4)
    Qw = _square(V[16:32], 4)
    Lw = _square(V[32:48], 4)
    M = _square(V[48:64], 4)
    S = _square(V[64:80], 4)
    R = _square(V[80:96], 4)
    Lc = _square(V[96:112], 4)
    q_moving(mode, w / 2, p, Q1)
    q_moving(mode, w, p, Qw)
    # M = Q1·P2ᵀ with P2 the noisy block of Φ(w/2)
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for k in range(4):
                acc += Q1[i, k] * Ph[NOISY_BLOCK[j], NOISY_BLOCK[k]]
            M[i, j] = acc
    # Gᵀ = Qw⁻¹·Mᵀ, column by column, with Qw = Lw·Lwᵀ (zero columns of Lw: no noise there)
    chol_psd(Qw, Lw)
    for i in range(4):
        y = V[112:116]
        for r in range(4):
            if Lw[r, r] == 0.0:
                y[r] = 0.0          # no noise in this direction (its column of Lw is zero too)
                continue
            acc = M[i, r]
            for c in range(r):
                acc -= Lw[r, c] * y[c]
            y[r] = acc / Lw[r, r]
        for r in range(3, -1, -1):
            if Lw[r, r] == 0.0:
                G[i, r] = 0.0
                continue
            acc = y[r]
            for c in range(r + 1, 4):
                acc -= Lw[c, r] * G[i, c]
            G[i, r] = acc / Lw[r, r]
    # Σ = Q1 − G·P2·Q1 = Q1 − G·Mᵀ, symmetrised
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for k in range(4):
                acc += G[i, k] * M[j, k]
            S[i, j] = Q1[i, j] - acc
    for i in range(4):
        for j in range(i + 1, 4):
            S[i, j] = S[j, i] = 0.5 * (S[i, j] + S[j, i])
    for i in range(4):
        for j in range(4):
            C[i, j] = 0.0
    s22 = max(S[1, 1], 0.0)
    C[0, 0] = math.sqrt(s22)
    for a in range(3):
        ia = 0 if a == 0 else a + 1
        C[1 + a, 0] = S[ia, 1] / s22 if s22 > 0.0 else 0.0
    for a in range(4):
        for b in range(4):
            R[a, b] = 0.0
    for a in range(3):
        ia = 0 if a == 0 else a + 1
        for b in range(3):
            ib = 0 if b == 0 else b + 1
            R[a, b] = S[ia, ib] - C[1 + a, 0] * S[1, ib]
    chol_psd(R, Lc)
    for a in range(3):
        for b in range(3):
            C[1 + a, 1 + b] = Lc[a, b]


@njit(cache=True, _nrt=False)
def _phi_times(P, X, out):
    """out = P·X for a moving-mode Φ (3-20)/(3-21), without its structural zeros."""
    x1, x2, x3, x4, x5, kc, u = X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU]
    out[A1] = x1 + P[A1, A2] * x2 + P[A1, A3] * x3 + P[A1, A4] * x4 + P[A1, A5] * x5 + P[A1, AKC] * kc + P[A1, AU] * u
    out[A2] = x2 + P[A2, A3] * x3 + P[A2, A5] * x5 + P[A2, AKC] * kc + P[A2, AU] * u
    out[A3] = P[A3, A3] * x3 + P[A3, AU] * u
    out[A4] = P[A4, A4] * x4
    out[A5] = P[A5, A5] * x5
    out[AKC] = kc
    out[AU] = u


@njit(cache=True, _nrt=False)
def _bisect_level(Ph, Pw, G, C, Xa, Xb, Xm, Fb, half, sig_v2, z, cursor):
    """Draw the midpoint Xm of [Xa, Xb] (width 2·half) given a crossing inside; True if the
    first crossing lies in the left half. (Ph, Pw, G, C): the law of :func:`_bridge_law`;
    ``Fb`` is scratch for Φ(w)·Xa."""
    _phi_times(Ph, Xa, Xm)
    _phi_times(Pw, Xa, Fb)
    d0 = Xb[A1] - Fb[A1]
    d1 = Xb[A2] - Fb[A2]
    d2 = Xb[A4] - Fb[A4]
    d3 = Xb[A5] - Fb[A5]
    for q in range(4):
        Xm[NOISY_BLOCK[q]] += G[q, 0] * d0 + G[q, 1] * d1 + G[q, 2] * d2 + G[q, 3] * d3
    mean2 = Xm[A2]
    a, b = Xa[A2], Xb[A2]
    if (a > 0) != (b > 0) or a == 0.0 or b == 0.0:
        x2m = mean2 + C[0, 0] * normal(z, cursor)        # a sign change: both halves possible
    else:
        sgn = 1.0 if a > 0 else -1.0
        x2m = sgn * _hitting_midpoint(sgn * a, sgn * b, sgn * mean2, C[0, 0], sig_v2 * half, z, cursor)
    pl = _cross_prob(a, x2m, half, sig_v2)
    Xm[A2] = x2m
    i = cursor[ZPOS]                      # the next three normals, one bounds check (see _step)
    if i + 3 > z.shape[0]:
        raise NoiseExhausted()
    cursor[ZPOS] = i + 3
    z1, z2, z3 = z[i], z[i + 1], z[i + 2]
    dv = x2m - mean2
    Xm[A1] += C[1, 0] * dv + C[1, 1] * z1
    Xm[A4] += C[2, 0] * dv + C[2, 1] * z1 + C[2, 2] * z2
    Xm[A5] += C[3, 0] * dv + C[3, 1] * z1 + C[3, 2] * z2 + C[3, 3] * z3
    if pl >= 1.0:
        return True
    pr = _cross_prob(x2m, b, half, sig_v2)    # only p_any needs it: not evaluated when pl ≥ 1
    p_any = 1.0 - (1.0 - pl) * (1.0 - pr)
    return uniform_below(z, cursor, pl / p_any if p_any > 0.0 else 0.0)


@njit(cache=True, _nrt=False)
def _bisect(mode, Xa0, Xb0, h, tol, p, sig_v2, z, cursor, Xout, BPh, BPw, BG, BC, V):
    """Bridge bisection of a crossing known to lie in a sub-step of length h; (time, levels).

    At each level the midpoint is drawn from its law given both ends (:func:`_bridge_law`)
    conditioned on the sub-step containing a crossing: x2 first (:func:`_hitting_midpoint`,
    exact, acceptance ≥ ½), then the other coordinates given x2. The first crossing is in the
    left half with probability p_left/p_any.

    ``BPh, BPw, BG, BC`` tabulate the law for w = h/2^k (the regular sub-step, see
    plant.multimode.interval); levels beyond the table are computed here. ``V``: scratch, ≥ 274 floats.
    """
    m = 0 if mode == 1 else 1
    Xa = V[0:7]
    Xb = V[7:14]
    Xm = V[14:21]
    Ph = _square(V[21:70], 7)
    Pw = _square(V[70:119], 7)
    G = _square(V[119:135], 4)
    C = _square(V[135:151], 4)
    Vl = V[151:267]
    Fb = V[267:274]
    _copy(Xa, Xa0)
    _copy(Xb, Xb0)
    ta = 0.0
    w = h
    levels = 0
    while w > tol:
        half = w / 2
        if levels < BPh.shape[1]:
            left = _bisect_level(BPh[m, levels], BPw[m, levels], BG[m, levels], BC[m, levels], Xa, Xb, Xm, Fb,
                                 half, sig_v2, z, cursor)
        else:
            _bridge_law(mode, w, p, Ph, Pw, G, C, Vl)
            left = _bisect_level(Ph, Pw, G, C, Xa, Xb, Xm, Fb, half, sig_v2, z, cursor)
        if left:
            _copy(Xb, Xm)                  # the first crossing is in the left half
        else:
            ta += half
            _copy(Xa, Xm)
        w = half
        levels += 1
    _copy(Xout, Xb)
    return ta + w, levels


@njit(cache=True, _nrt=False)
def _log_ncdf(x):
    """log Φ(x) for the standard normal CDF, accurate far into the lower tail."""
    if x > -30.0:
        return math.log(0.5 * math.erfc(-x / math.sqrt(2.0)))
    return -0.5 * x * x - math.log(-x) - 0.5 * math.log(2.0 * math.pi) + math.log1p(-1.0 / (x * x))


@njit(cache=True, _nrt=False)
def _normal_above(alpha, z, cursor):
    """A unit normal conditioned to exceed ``alpha`` (Robert 1995's exponential proposal in the tail)."""
    if alpha < 0.45:
        while True:                              # plain rejection, acceptance ≥ P(Z > 0.45) ≈ 0.33
            x = normal(z, cursor)
            if x > alpha:
                return x
    lam = 0.5 * (alpha + math.sqrt(alpha * alpha + 4.0))
    while True:
        x = alpha - math.log(uniform(z, cursor)) / lam
        if uniform(z, cursor) < math.exp(-0.5 * (x - lam) ** 2):
            return x


@njit(cache=True, _nrt=False, inline="always")
def _exp_shift(d):
    """exp(d) for d = w − max(w…) ≤ 0: exactly 1.0 at d = ±0 (IEEE 754 and libm's exp(±0) = 1),
    so the largest weight's exp is not evaluated."""
    return 1.0 if d == 0.0 else math.exp(d)


@njit(cache=True, _nrt=False)
def _hitting_midpoint(a, b, mu, sd, s2h, z, cursor):
    """x2 at the midpoint of a sub-step with x2 = a > 0 and b > 0 at its ends, given a crossing.

    Unconditioned, the midpoint is N(μ, sd²) (:func:`_bridge_law`). Given it, the halves cross
    with p_l = e^(−k_l·m), p_r = e^(−k_r·m) for m > 0 (k = 2·end/(σ_v²·w/2), the bridge
    crossing probability) and surely for m ≤ 0, so the target density is
    f(m)·[1{m ≤ 0} + 1{m > 0}(p_l + p_r − p_l·p_r)]. It is sampled exactly from the
    proposal f(m)·[1{m ≤ 0} + 1{m > 0}(p_l + p_r)] — a mixture of three truncated normals,
    since f(m)·e^(−k·m) ∝ N(m; μ − k·sd², sd²) — accepted with (p_l + p_r − p_l·p_r)/(p_l + p_r) ≥ ½.
    """
    if not sd > 0.0:
        return mu
    v = sd * sd
    kl = 2.0 * a / s2h
    kr = 2.0 * b / s2h
    mul = mu - kl * v
    mur = mu - kr * v
    w0 = _log_ncdf(-mu / sd)
    w1 = -kl * mu + 0.5 * kl * kl * v + _log_ncdf(mul / sd)
    w2 = -kr * mu + 0.5 * kr * kr * v + _log_ncdf(mur / sd)
    top = max(w0, w1, w2)
    e0, e1, e2 = _exp_shift(w0 - top), _exp_shift(w1 - top), _exp_shift(w2 - top)
    total = e0 + e1 + e2
    while True:
        pick = uniform(z, cursor) * total
        if pick < e0:
            return mu - sd * _normal_above(mu / sd, z, cursor)           # m ≤ 0: always crosses
        centre = mul if pick < e0 + e1 else mur
        m = centre + sd * _normal_above(-centre / sd, z, cursor)         # m > 0
        pl = math.exp(-kl * m)
        pr = math.exp(-kr * m)
        accept = 1.0 - pl * pr / (pl + pr) if pl + pr > 0.0 else 1.0
        if uniform_below(z, cursor, accept):       # uniform(z, cursor) < accept, erfc only if needed
            return m


# The exact sampler of a bridge midpoint given a crossing, shared with plant.multimode.disturbed.
hitting_midpoint = _hitting_midpoint


@njit(cache=True)
def bisection_tables(p, sub, BPh, BPw, BG, BC):
    """Tabulate :func:`_bridge_law` for w = sub/2^k, k < BPh.shape[1], both moving modes."""
    V = np.zeros(116)
    for m in range(2):
        mode = 1 if m == 0 else 3
        w = sub
        for k in range(BPh.shape[1]):
            _bridge_law(mode, w, p, BPh[m, k], BPw[m, k], BG[m, k], BC[m, k], V)
            w = w / 2


# --- the step ladder ---------------------------------------------------------------------------

LADDER = 12
"""Rungs of the step ladder: widths h_j·2^k, k < LADDER (h_0 = substep, h_1 = reflect_substep)."""

FAR_SIGMAS = 8.5
"""K of the far-from-zero rule: a step is long only if its mean velocity stays K·σ away from 0."""


def _push_bound(kappa: float) -> float:
    """G(κ) = E[(|Z| − κ)⁺] = 2·(φ(κ) − κ·Φ(−κ)), Z a unit normal.

    For a driftless x2 = κ·σ_v·√h at the start of a reflecting step of width h the push is
    L_h = σ_v·√h·(S − κ)⁺ with S = sup of a standard Brownian motion on [0, 1] ~ |Z|, so
    E[L_h] = σ_v·√h·G(κ); a drift away from 0 only lowers it.
    """
    phi = math.exp(-0.5 * kappa * kappa) / math.sqrt(2.0 * math.pi)
    return 2.0 * (phi - kappa * 0.5 * math.erfc(kappa / math.sqrt(2.0)))


def ladder_thresholds(alpha: float, sigma2_sq: float, sigma5_sq: float, beta5: float, sub: float,
                      rsub: float) -> np.ndarray:
    """TH[j, k]: the least |mean velocity| [rad/s] over a step at which rung k of ladder j is used.

    j = 0 (looking for a velocity zero) and j = 1 (reflecting); rung k has width h = h_j·2^k,
    h_0 = ``sub``, h_1 = ``rsub`` [s]; rung 0 is always allowed (TH = −inf). Rung k > 0 is
    allowed when the mean velocity s·x̄2(τ) stays ≥ TH[j, k] for all τ in [0, h]:

    * **far from zero** (both ladders): TH = c(h) = K·(σ_v·√h + α·σ5·h^(3/2)·e^(β5·h)),
      K = :data:`FAR_SIGMAS`, σ_v² = α²σ2². The noise of x2 over the step is α·σ2·W2(τ), plus
      α·∫N5, N5 the x5 noise (an Ornstein–Uhlenbeck martingale ×e^(−β5τ), quadratic variation
      ≤ σ5²·h·e^(2β5h)). By the reflection principle P(min_τ α·σ2·W2 ≤ −K·σ_v√h) = 2Φ(−K) and
      P(sup_τ |N5| ≥ K·σ5·√h·e^(β5h)) ≤ 4Φ(−K), so the path touches 0 within the step with
      probability ≤ 6·Φ(−K) = 5.7e-17 (K = 8.5): a long step then equals the sub-steps in law
      up to that probability (the transition Φ(h)X + N is exact for any h).
    * **reflecting near zero** (j = 1, widths up to ``sub``): the Skorokhod push L_h of a step
      (the bridge minimum, exact) enters x1 as ½·L_h·h, whose error is at most ½·L_h·h since
      ∫₀ʰ L dτ ∈ [0, L_h·h]. The torque beyond ks makes the drift of s·x2 ≥ 0, so
      E[L_h | x2 = v] ≤ σ_v·√h·G(v/(σ_v√h)) with G(κ) = 2(φ(κ) − κΦ(−κ)). Rung k is allowed
      once this bound per unit time, ½·σ_v·√h·G(κ), is no larger than that of the reflect
      sub-step at zero velocity, ½·σ_v·√h_1·G(0): the expected x1 error rate never exceeds the
      worst case of today's fixed reflect sub-step (TH = smaller of this and c(h)).

    Beyond the regular sub-step ``sub`` a reflecting step must be far from zero (c(h)), so near
    zero no step is longer than the fixed sub-steps' Brownian-bridge approximations assume.
    """
    sig_v = alpha * math.sqrt(sigma2_sq)
    sig5 = math.sqrt(sigma5_sq)
    TH = np.empty((2, LADDER))
    for j, base in enumerate((sub, rsub)):
        TH[j, 0] = -math.inf
        for k in range(1, LADDER):
            h = base * 2.0**k
            far = FAR_SIGMAS * (sig_v * math.sqrt(h) + alpha * sig5 * h**1.5 * math.exp(beta5 * h))
            TH[j, k] = far
            if j == 1 and h <= sub * (1 + 1e-12) and sig_v > 0:
                target = _push_bound(0.0) / math.sqrt(2.0**k)    # G(κ) ≤ G(0)·√(h_1/h)
                lo, hi = 0.0, 40.0
                for _ in range(200):                             # G decreases in κ
                    mid = 0.5 * (lo + hi)
                    if _push_bound(mid) > target:
                        lo = mid
                    else:
                        hi = mid
                TH[j, k] = min(far, hi * sig_v * math.sqrt(h))
    return TH


@njit(cache=True)
def substep_tables(p, o_sub, o_rsub, TP, TL):
    """Φ and noise factors of the ladder widths h_j·2^k (j = 0 regular, 1 reflection), both modes.

    TP[m, j, k], TL[m, j, k], m = 0 for mode 1 and 1 for mode 3, k < TP.shape[2].
    """
    Q = np.empty((4, 4))
    for m in range(2):
        mode = 1 if m == 0 else 3
        for j in range(2):
            h = o_sub if j == 0 else o_rsub
            for k in range(TP.shape[2]):
                phi_moving(mode, h, p, TP[m, j, k])
                q_moving(mode, h, p, Q)
                chol_psd(Q, TL[m, j, k])
                h = h * 2.0


@njit(cache=True, _nrt=False, inline="always")
def _step(X, P, L, z, cursor, out):
    """out = P·X + N with the sparsity of Φ_1/Φ_3 (3-20)/(3-21); N = L·ζ on the noisy block.

    :func:`plant.multimode.moving.gaussian_step` without the structural zeros of Φ and of the lower
    triangular L.
    """
    x1, x2, x3, x4, x5, kc, u = X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU]
    # the stream's next four normals, as four calls of plant.randomness.normal would read them,
    # with one bounds check (NoiseExhausted makes the caller rerun the interval, so where
    # inside it the buffer ran out does not matter): 3× cheaper than four checked calls
    i = cursor[ZPOS]
    if i + 4 > z.shape[0]:
        raise NoiseExhausted()
    cursor[ZPOS] = i + 4
    z0, z1, z2, z3 = z[i], z[i + 1], z[i + 2], z[i + 3]
    out[A1] = (x1 + P[A1, A2] * x2 + P[A1, A3] * x3 + P[A1, A4] * x4 + P[A1, A5] * x5 + P[A1, AKC] * kc
               + P[A1, AU] * u + L[0, 0] * z0)
    out[A2] = (x2 + P[A2, A3] * x3 + P[A2, A5] * x5 + P[A2, AKC] * kc + P[A2, AU] * u
               + L[1, 0] * z0 + L[1, 1] * z1)
    out[A3] = P[A3, A3] * x3 + P[A3, AU] * u
    out[A4] = P[A4, A4] * x4 + L[2, 0] * z0 + L[2, 1] * z1 + L[2, 2] * z2
    out[A5] = P[A5, A5] * x5 + L[3, 0] * z0 + L[3, 1] * z1 + L[3, 2] * z2 + L[3, 3] * z3
    out[AKC] = kc
    out[AU] = u


@njit(cache=True, inline="always")
def _bridge_low(va, vb, h, sig_v2, z, cursor):
    """The bridge minimum m of s·x2 over a reflecting sub-step from va to vb (σ_v² = ``sig_v2``),
    drawn from one normal x, U = Φ(x): m = ½(va + vb − √((vb − va)² − 2σ_v²h·ln U)), or min(va, vb)
    when that is certain not to be below 0. m < 0 iff U < p = exp(e), e = −2·va·vb/(σ_v²h)
    (va, vb > 0); when x ≥ 0 (U ≥ ½) and p ≤ ½ the inversion is skipped, and so is exp itself
    when e < −0.7 (p < 0.497): p decides only this test (tests/test_kernel_equivalence.py checks
    it against the form that always computes p)."""
    both = va > 0.0 and vb > 0.0
    e = -2.0 * va * vb / (sig_v2 * h) if both else 0.0
    x = normal(z, cursor)
    if x >= 0.0 and both and (e < -0.7 or math.exp(e) <= 0.5):
        return min(va, vb)
    u = 0.5 * math.erfc(-x / math.sqrt(2.0))
    return 0.5 * (va + vb - math.sqrt((vb - va) ** 2 - 2.0 * sig_v2 * h * math.log(u)))


@njit(cache=True, _nrt=False)
def _mean_min(mode, X, p, h, t_ext):
    """min over τ in [0, h] of s·x̄2(τ), the mean velocity in the direction of motion.

    x̄2 has at most one extremum, at ``t_ext`` (:func:`plant.multimode.moving.velocity_extremum_time`).
    """
    s = 1.0 if mode == 3 else -1.0
    v = min(s * X[A2], s * mean_velocity(mode, h, X, p))
    if 0.0 < t_ext < h:
        v = min(v, s * mean_velocity(mode, t_ext, X, p))
    return v


@njit(cache=True)
def _fixed_z_velocity(mode, tau, X, p, zf):
    """x2(τ) of the sample path with the segment's noise vector held fixed (4-38)."""
    if tau <= 0.0:
        return X[A2]
    L = np.empty((4, 4))
    noise_factor_moving(mode, tau, p, L)
    v = mean_path(mode, tau, X, p)[1]
    return v + L[1, 0] * zf[0] + L[1, 1] * zf[1] + L[1, 2] * zf[2] + L[1, 3] * zf[3]


@njit(cache=True)
def newton_segment(X, mode, h, p, z, cursor, peak):
    """Section 4.5: hold Z fixed and iterate g ← g − v(g)/a(g) from the segment end (4-38).

    Advances X in place; returns (advanced [s], stopped, peak).
    """
    zf = np.empty(4)
    for i in range(4):
        zf[i] = normal(z, cursor)
    s = 1.0 if mode == 3 else -1.0
    g = h
    found = False
    if s * X[A2] <= 0.0:
        g, found = 0.0, True
    if not found:
        for _ in range(20):
            v = _fixed_z_velocity(mode, g, X, p, zf)
            x3g = mean_path(mode, g, X, p)[2]
            x5g = X[A5] * math.exp(-p.beta5 * g)
            accel = p.alpha * (x3g - s * (X[AKC] + x5g))
            if accel == 0.0:
                break
            step = v / accel
            if g == h and step <= 0:       # first correction positive in time: no zero before h
                break
            g_new = g - step
            if not (0.0 < g_new <= h):
                break
            if abs(g_new - g) < 1e-13:
                g, found = g_new, True
                break
            g = g_new
    if not found and s * _fixed_z_velocity(mode, h, X, p, zf) <= 0.0:
        # Newton left (0, h] although the fixed-Z path ends on the far side: bisect instead.
        lo, hi = min(1e-12, h / 2), h
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if s * _fixed_z_velocity(mode, mid, X, p, zf) > 0.0:
                lo = mid
            else:
                hi = mid
            if hi - lo <= 1e-15:
                break
        g, found = hi, True
    tau = g if found else h
    P = np.empty((7, 7))
    L = np.empty((4, 4))
    phi_moving(mode, tau, p, P)
    noise_factor_moving(mode, tau, p, L)
    Xb = np.empty(7)
    gemv_lanes(P, X, Xb)            # P @ X's bits on OpenBLAS Haswell, without BLAS (plant.fixed_linalg)
    for r in range(4):
        Xb[NOISY_BLOCK[r]] += L[r, 0] * zf[0] + L[r, 1] * zf[1] + L[r, 2] * zf[2] + L[r, 3] * zf[3]
    peak = substep_peak(X, Xb, tau, peak)
    X[:] = Xb
    if found:
        X[A2] = 0.0
    return tau, found, peak
