"""Reference implementations kept for bit-for-bit tests of the compiled kernels that replaced
them: each is the code as it was before an optimisation that must not change a single bit.

``absorbed_moments``: :func:`controllers.solnic.noise_model._absorbed_moments` with row arrays
for the tridiagonal matrix and separate factorisation, elimination and source loops (issue 27).
``step``: :func:`plant.multimode.zero_velocity._step` drawing its four normals by four checked
calls of :func:`plant.randomness.normal` (issue 27).
``bridge_low``: the reflecting sub-step's bridge minimum of the noisy moving segment, computing
p = exp(e) always (issue 27).
``bridge_segment``, ``crossed_exact``: the noisy moving segment's loop and its crossing decision
(exp and erfc always evaluated but for a far exponent) before
:func:`plant.multimode.bridge_loop.bridge_run` and :func:`plant.multimode.crossing.crossed`
replaced them (issue 27).
``hermite_peak``: :func:`plant.multimode.segments.hermite_peak` with its roots in an array
(issue 27).
``phi_moving_ref``, ``q_moving_ref``: :func:`plant.multimode.moving.phi_moving` and
:func:`~plant.multimode.moving.q_moving` evaluating every e-function where an entry uses it (e1(β3h) and
e2(β3h) twice, the x4 and x5 decays separately when β4·h = β5·h), before the shared evaluations and
:func:`~plant.multimode.moving.phi_q_moving` (issue 27).
``hitting_midpoint_ref``: :func:`plant.multimode.zero_velocity._hitting_midpoint` evaluating exp
of every weight (one of them exp(0) = 1) and its acceptance test as ``uniform(z, cursor) < accept``
(issue 27).
``bisect_level_ref``: one level of :func:`plant.multimode.zero_velocity._bisect`, evaluating the right
half's crossing probability also when the left half surely crosses (issue 27).
``grid_table``: :meth:`controllers.solnic.grid_posterior.FrictionGrid.table` in numpy (np.clip,
:func:`~controllers.solnic.grid_posterior.pulse_table`, np.gradient per lattice axis) (issue 27).
"""

import math

import numpy as np
from numba import njit

from controllers.solnic.noise_model import _PDE_SIGMAS, _v0, _x3
from plant.expfun import e1, e2, e3, e4
from plant.multimode.moving import (_GL4_W, _GL4_X, _PANEL_RATE, _SERIES_LIMIT, _fint, chol_psd, phi_moving, q_moving,
                                     substep_peak, velocity_extremum_time)
from plant.multimode.zero_velocity import (_bisect, _bridge_low, _copy, _cross_prob, _log_ncdf, _mean_min, _normal_above,
                                           _phi_times, _step)
from plant.multimode.moving import NOISY_BLOCK
from plant.randomness import ZPOS, NoiseExhausted
from plant.randomness import normal, uniform, uniform_below

A1, A2, A3, A4, A5, AKC, AU = range(7)


@njit(cache=True)
def step(X, P, L, z, cursor, out):
    x1, x2, x3, x4, x5, kc, u = X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU]
    z0 = normal(z, cursor)
    z1 = normal(z, cursor)
    z2 = normal(z, cursor)
    z3 = normal(z, cursor)
    out[A1] = (x1 + P[A1, A2] * x2 + P[A1, A3] * x3 + P[A1, A4] * x4 + P[A1, A5] * x5 + P[A1, AKC] * kc
               + P[A1, AU] * u + L[0, 0] * z0)
    out[A2] = (x2 + P[A2, A3] * x3 + P[A2, A5] * x5 + P[A2, AKC] * kc + P[A2, AU] * u
               + L[1, 0] * z0 + L[1, 1] * z1)
    out[A3] = P[A3, A3] * x3 + P[A3, AU] * u
    out[A4] = P[A4, A4] * x4 + L[2, 0] * z0 + L[2, 1] * z1 + L[2, 2] * z2
    out[A5] = P[A5, A5] * x5 + L[3, 0] * z0 + L[3, 1] * z1 + L[3, 2] * z2 + L[3, 3] * z3
    out[AKC] = kc
    out[AU] = u


@njit(cache=True)
def absorbed_moments(al, U, tau, s2, ks, kc, dt_u, t_b, t_cz, n_x, n_abs, n_refl):
    """(E[Δc], E[Δc²]) of a moving pulse from the backward equations (4)–(6) of the module
    docstring, solved on [t_b, t_cz] × [0, X] by Crank–Nicolson (two implicit Euler steps after
    each change of boundary condition), with the coasting polynomials (2) at t = t_cz and the
    unabsorbed Gaussian moments (7) at x = X."""
    x3_off = U * -math.expm1(-dt_u / tau)
    a = al * kc
    T = t_cz
    t_ks = dt_u + tau * math.log((x3_off + U) / (ks + U)) if x3_off > ks else dt_u
    t_ks = min(max(t_ks, t_b), T)
    t_kc = dt_u + tau * math.log((x3_off + U) / (kc + U)) if x3_off > kc else dt_u
    t_kc = min(max(t_kc, t_b), T)
    v_peak = max(_v0(t_kc, dt_u, t_b, al, U, tau, ks, kc, x3_off), 0.0)
    X = v_peak + _PDE_SIGMAS * math.sqrt(s2 * (T - t_b))
    dx = X / n_x
    D = 0.5 * s2 / (dx * dx)                      # diffusion over dx²
    c4, c3 = 1.0 / (4 * a * a), 5 * s2 / (6 * a**3)
    c2, c1 = 5 * s2 * s2 / (4 * a**4), 5 * s2**3 / (4 * a**5)
    n = n_x + 1
    x = np.empty(n)
    u1 = np.empty(n)
    u2 = np.empty(n)
    for i in range(n):
        xi = i * dx
        x[i] = xi
        u1[i] = xi * xi / (2 * a) + s2 * xi / (2 * a * a)
        u2[i] = ((c4 * xi + c3) * xi + c2) * xi * xi + c1 * xi
    r1 = np.empty(n)
    r2 = np.empty(n)
    lo = np.empty(n)
    di = np.empty(n)
    up = np.empty(n)
    cp = np.empty(n)
    dm = np.empty(n)
    M = 0.0                                       # ∫_t^T μ
    K = 0.0                                       # ∫_t^T μ(r)(T − r) dr
    for phase in range(2):
        t_hi, t_lo, m = (T, t_ks, n_abs) if phase == 0 else (t_ks, t_b, n_refl)
        if not t_hi > t_lo:
            continue
        h = (t_hi - t_lo) / m
        reflect = phase == 1
        mu_o = al * (_x3(t_hi, dt_u, U, tau, x3_off) - kc)
        for k in range(m):
            t_o = t_hi - k * h
            t_n = t_hi - (k + 1) * h
            mu_n = al * (_x3(t_n, dt_u, U, tau, x3_off) - kc)
            th = 1.0 if k < 2 else 0.5
            e = (1.0 - th) * h
            # explicit part: u + (1−θ)h(L u + f)
            ao, bo = D - 0.5 * mu_o / dx, D + 0.5 * mu_o / dx
            for i in range(1, n_x):
                r1[i] = u1[i] + e * (ao * u1[i - 1] - 2 * D * u1[i] + bo * u1[i + 1] + x[i]) + th * h * x[i]
                r2[i] = u2[i] + e * (ao * u2[i - 1] - 2 * D * u2[i] + bo * u2[i + 1] + 2 * x[i] * u1[i])
            an, bn = D - 0.5 * mu_n / dx, D + 0.5 * mu_n / dx
            for i in range(1, n_x):
                lo[i], di[i], up[i] = -th * h * an, 1.0 + 2 * th * h * D, -th * h * bn
            if reflect:                               # u_x(0) = 0: ghost u[-1] = u[1]
                r1[0] = u1[0] + e * (2 * D * (u1[1] - u1[0]))
                r2[0] = u2[0] + e * (2 * D * (u2[1] - u2[0]))
                lo[0], di[0], up[0] = 0.0, 1.0 + 2 * th * h * D, -2 * th * h * D
            else:                                     # absorbed: u(0) = 0
                r1[0] = r2[0] = 0.0
                lo[0], di[0], up[0] = 0.0, 1.0, 0.0
            # x = X: no absorption before T, Gaussian moments (7)
            M += 0.5 * h * (mu_o + mu_n)
            K += 0.5 * h * (mu_o * (T - t_o) + mu_n * (T - t_n))
            w = T - t_n
            y, vz = X + M, s2 * w
            EI = X * w + K
            EP1 = y * y / (2 * a) + s2 * y / (2 * a * a) + vz / (2 * a)
            Ez2 = y * y + vz
            Ez3 = y * (y * y + 3 * vz)
            Ez4 = y**4 + 6 * y * y * vz + 3 * vz * vz
            EP2 = c4 * Ez4 + c3 * Ez3 + c2 * Ez2 + c1 * y
            lo[n_x], di[n_x], up[n_x] = 0.0, 1.0, 0.0
            r1[n_x] = EI + EP1
            r2[n_x] = (EI * EI + s2 * w**3 / 3.0 + 2.0 * (EI * EP1 + 0.5 * s2 * w * w * (y / a + s2 / (2 * a * a)))
                       + EP2)
            # Thomas: factor once, solve u1, then u2 with the new u1 in its source
            cp[0] = up[0] / di[0]
            dm[0] = di[0]
            for i in range(1, n):
                dm[i] = di[i] - lo[i] * cp[i - 1]
                cp[i] = up[i] / dm[i]
            u1[0] = r1[0] / dm[0]
            for i in range(1, n):
                u1[i] = (r1[i] - lo[i] * u1[i - 1]) / dm[i]
            for i in range(n - 2, -1, -1):
                u1[i] -= cp[i] * u1[i + 1]
            for i in range(1, n_x):
                r2[i] += th * h * 2 * x[i] * u1[i]
            u2[0] = r2[0] / dm[0]
            for i in range(1, n):
                u2[i] = (r2[i] - lo[i] * u2[i - 1]) / dm[i]
            for i in range(n - 2, -1, -1):
                u2[i] -= cp[i] * u2[i + 1]
            mu_o = mu_n
    return u1[0], u2[0]


@njit(cache=True)
def bridge_low(va, vb, step, sig_v2, z, cursor):
    p_push = math.exp(-2.0 * va * vb / (sig_v2 * step)) if va > 0.0 and vb > 0.0 else 1.0
    x = normal(z, cursor)
    if x >= 0.0 and p_push <= 0.5:
        low = min(va, vb)
    else:
        u = 0.5 * math.erfc(-x / math.sqrt(2.0))
        low = 0.5 * (va + vb - math.sqrt((vb - va) ** 2 - 2.0 * sig_v2 * step * math.log(u)))
    return low


@njit(cache=True)
def hermite_peak(h, ya, da, yb, db):
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


def grid_table(grid, dt_u):
    """(Δc, t_stop, t_breakaway, cell spread²) at the valid points of ``grid`` (a
    :class:`~controllers.solnic.grid_posterior.FrictionGrid`), as ``FrictionGrid.table``
    computed them in numpy before its compiled kernel."""
    from controllers.solnic.grid_posterior import pulse_table

    ks = np.clip(grid.ks, 1e-6, grid.u_max * (1 - 1e-9))
    kc = np.clip(grid.kc, 1e-6, ks)
    dc, ts, tb = pulse_table(grid.params, float(dt_u), kc, ks, grid._need)
    table = dc.reshape(grid.n, grid.n)
    spread = np.zeros_like(table)
    for ax in (0, 1):
        step = np.abs(np.gradient(table, axis=ax))
        spread += step * step / 12.0
    spread = spread.ravel()
    i = grid._idx
    return dc[i], ts[i], tb[i], spread[i]


@njit(cache=True)
def crossed_exact(va, vb, h, sig_v2, z, cursor):
    """``pc >= 1.0 or uniform_below(z, cursor, pc)`` with pc the bridge crossing probability:
    the same decision from the same draws, without exp and erfc when the exponent is below −70
    (pc < 4e−31) and the normal above −11 (U = Φ(Z) > 1.9e−28 > pc: no crossing)."""
    if (va > 0) != (vb > 0) or va == 0.0 or vb == 0.0:
        return True
    e = -2.0 * va * vb / (sig_v2 * h)
    if e < -70.0:
        x = normal(z, cursor)
        if x > -11.0:
            return False
        return 0.5 * math.erfc(-x / math.sqrt(2.0)) < math.exp(e)
    pc = math.exp(e)
    return pc >= 1.0 or uniform_below(z, cursor, pc)


@njit(cache=True)
def bridge_segment(X, mode, h, reflect, o_sub, o_rsub, tol, p, TP, TL, TH, BPh, BPw, BG, BC, z, cursor, peak,
                   max_steps, W):
    """The noisy moving segment as ``plant.multimode.zero_velocity.bridge_segment`` computed it
    before :func:`plant.multimode.bridge_loop.bridge_run` replaced it (same arguments but the
    scratch views; returns (advanced, stopped, peak, sub-steps, chattered))."""
    s = 1.0 if mode == 3 else -1.0
    m = 0 if mode == 1 else 1
    j = 1 if reflect else 0
    base = o_rsub if reflect else o_sub
    sig_v2 = p.alpha * p.alpha * p.sigma2_sq
    nrung = TP.shape[2]
    no_tables = BPh[:, :0]
    Xb = W[0:7]
    Xc = W[7:14]
    P = W[14:63].reshape((7, 7))
    L = W[63:79].reshape((4, 4))
    Qtmp = W[79:95].reshape((4, 4))
    t = 0.0
    n = 0
    while h - t > 0.0:
        rem = h - t
        k = 0
        if nrung > 1 and s * X[A2] >= TH[j, 1] and base < rem:
            # the rung the start velocity allows, up to the first one reaching the segment end;
            # then the mean path over the width w actually used (TH grows with h: conservative)
            k = 1
            while k + 1 < nrung and s * X[A2] >= TH[j, k + 1] and base * 2.0**k < rem:
                k += 1
            if reflect:
                # the torque beyond ks keeps the mean drift of s·x2 ≥ −α·|x5|·β5·τ (x5's mean
                # decays while ks, kc hold x5's start value), so s·x̄2 ≥ s·x2 − α·|x5|·β5·w²/2
                while k > 0:
                    w = min(base * 2.0**k, rem)
                    if s * X[A2] - 0.5 * p.alpha * abs(X[A5]) * p.beta5 * w * w >= TH[j, k]:
                        break
                    k -= 1
            else:
                t_ext = velocity_extremum_time(mode, X, p)
                while k > 0 and _mean_min(mode, X, p, min(base * 2.0**k, rem), t_ext) < TH[j, k]:
                    k -= 1
        sub = base * 2.0**k
        # one fresh step to the segment's end when an admissible rung reaches it (any shorter
        # width is admissible too: c(h) and E[L_h] grow with h), or the last ≤ 1.5 sub-steps
        regular = not (rem <= sub or (k == 0 and rem <= 1.5 * sub))
        if regular:
            while k > 0 and 1.5 * sub >= rem:
                k -= 1
                sub = sub / 2.0
            step = sub
            _step(X, TP[m, j, k], TL[m, j, k], z, cursor, Xb)
        else:
            step = rem
            phi_moving(mode, step, p, P)
            q_moving(mode, step, p, Qtmp)
            chol_psd(Qtmp, L)
            _step(X, P, L, z, cursor, Xb)
        n += 1
        if n > max_steps:
            return t, False, peak, n, True
        if reflect:
            va, vb = s * X[A2], s * Xb[A2]
            low = _bridge_low(va, vb, step, sig_v2, z, cursor) if sig_v2 > 0 else min(va, vb)
            if low < 0.0:
                Xb[A2] += s * (-low)
                Xb[A1] += s * (-low) * step / 2.0
        else:
            if crossed_exact(X[A2], Xb[A2], step, sig_v2, z, cursor):
                if regular and k == 0:
                    tc, lv = _bisect(mode, X, Xb, step, tol, p, sig_v2, z, cursor, Xc, BPh, BPw, BG, BC, W[96:])
                else:
                    tc, lv = _bisect(mode, X, Xb, step, tol, p, sig_v2, z, cursor, Xc, no_tables, no_tables,
                                     BG[:, :0], BG[:, :0], W[96:])
                n += lv
                peak = substep_peak(X, Xc, tc, peak)
                _copy(X, Xc)
                X[A2] = 0.0
                return t + tc, True, peak, n, False
        peak = substep_peak(X, Xb, step, peak)
        _copy(X, Xb)
        t += step
    return h, False, peak, n, False


@njit(cache=True)
def phi_moving_ref(mode, h, p, P):
    """Φ_1 or Φ_3 of (3-20)/(3-21) into P (7 × 7, augmented vector)."""
    a, b3, b4, b5 = p.alpha, p.beta3, p.beta4, p.beta5
    for i in range(7):
        for j in range(7):
            P[i, j] = 1.0 if i == j else 0.0
    y3 = b3 * h
    y5 = b5 * h
    s = 1.0 if mode == 1 else -1.0
    P[A3, A3] = math.exp(-y3)                 # q33
    P[A3, AU] = e1(y3)                        # q37
    P[A4, A4] = math.exp(-b4 * h)             # q44
    P[A1, A4] = -e1(b4 * h) / b4              # q14
    P[A1, A2] = h
    P[A1, A3] = a * e2(y3) / (b3 * b3)        # q13
    P[A2, A3] = a * e1(y3) / b3               # q23
    P[A1, AU] = a * e3(y3) / (b3 * b3)        # q17
    P[A2, AU] = a * e2(y3) / b3               # q27
    P[A5, A5] = math.exp(-y5)                 # q55
    P[A1, A5] = s * a * e2(y5) / (b5 * b5)    # q15
    P[A2, A5] = s * a * e1(y5) / b5           # q25
    P[A1, AKC] = s * a * h * h / 2.0
    P[A2, AKC] = s * a * h


@njit(cache=True)
def _q_closed_ref(h, y4, y5, a, b4, b5, q2, q4, q5, s, Q):
    """The integrals of :func:`q_moving` in closed form (y = β·h < 0.5), e-functions of plant.expfun:

    w2: q2·[h³/3, h²/2; ·, h] on (x1, x2);
    w4: x1x1 q4·e4(y4)/β4³, x1x4 −q4·e1(y4)²/(2β4²), x4x4 q4·e1(2y4)/(2β4) (as in plant.multimode.stuck);
    w5: x1x1 q5·α²·F2(y5)/β5⁵, x1x2 q5·α²·F1(y5)/β5⁴, x1x5 q5·s·α·F0(y5)/β5³,
        x2x2 q5·α²·e4(y5)/β5³, x2x5 q5·s·α·e1(y5)²/(2β5²), x5x5 q5·e1(2y5)/(2β5),
    with F0, F1, F2 the integrals of e2·e^(−x), e2·e1, e2² (:func:`_fint`).
    """
    E4, E5 = e1(y4), e1(y5)
    Q[0, 0] = q2 * h * h * h / 3.0 + q4 * e4(y4) / b4 ** 3 + q5 * a * a * _fint(y5, 2) / b5 ** 5
    Q[0, 1] = Q[1, 0] = q2 * h * h / 2.0 + q5 * a * a * _fint(y5, 1) / b5 ** 4
    Q[1, 1] = q2 * h + q5 * a * a * e4(y5) / b5 ** 3
    Q[0, 2] = Q[2, 0] = -q4 * E4 * E4 / (2.0 * b4 * b4)
    Q[0, 3] = Q[3, 0] = q5 * s * a * _fint(y5, 0) / b5 ** 3
    Q[1, 2] = Q[2, 1] = 0.0
    Q[1, 3] = Q[3, 1] = q5 * s * a * E5 * E5 / (2.0 * b5 * b5)
    Q[2, 2] = q4 * e1(2.0 * y4) / (2.0 * b4)
    Q[2, 3] = Q[3, 2] = 0.0
    Q[3, 3] = q5 * e1(2.0 * y5) / (2.0 * b5)


@njit(cache=True)
def q_moving_ref(mode, h, p, Q):
    """Noisy 4 × 4 block (x1, x2, x4, x5) of COV[N] = ∫₀ʰ Φ(v) Q Φ(v)ᵀ dv  (4-8).

    The w2 column of Φ(v) is (v, 1, 0, 0) on the block, so its share is closed form:
    α²σ2²·[h³/3, h²/2; h²/2, h] on (x1, x2). The w4 and w5 columns, (−e1(β4v)/β4, 0, e^(−β4v), 0)
    and (s·α·e2(β5v)/β5², s·α·e1(β5v)/β5, 0, e^(−β5v)), are polynomials of degree ≤ 2 times a power
    series in β·v. For β·h < 0.5 their integrals are closed forms (:func:`_q_closed`); beyond,
    the products (degree ≤ 4) are integrated by 4-node Gauss–Legendre, exact through degree 7,
    on panels with β·Δ ≤ 1e-3: the first neglected term is below (2β·Δ)⁴·2e-7 ≈ 3e-18 of the
    entry, i.e. round-off (Van Loan is the test oracle).
    """
    a, b4, b5 = p.alpha, p.beta4, p.beta5
    q2, q4, q5 = a * a * p.sigma2_sq, p.sigma4_sq, p.sigma5_sq
    s = 1.0 if mode == 1 else -1.0
    y4, y5 = b4 * h, b5 * h
    if max(y4, y5) < _SERIES_LIMIT:
        _q_closed_ref(h, y4, y5, a, b4, b5, q2, q4, q5, s, Q)
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
def hitting_midpoint_ref(a, b, mu, sd, s2h, z, cursor):
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
    e0, e1, e2 = math.exp(w0 - top), math.exp(w1 - top), math.exp(w2 - top)
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
        if uniform(z, cursor) < accept:
            return m


@njit(cache=True)
def bisect_level_ref(Ph, Pw, G, C, Xa, Xb, Xm, Fb, half, sig_v2, z, cursor):
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
        x2m = sgn * hitting_midpoint_ref(sgn * a, sgn * b, sgn * mean2, C[0, 0], sig_v2 * half, z, cursor)
    pl = _cross_prob(a, x2m, half, sig_v2)
    pr = _cross_prob(x2m, b, half, sig_v2)
    p_any = 1.0 - (1.0 - pl) * (1.0 - pr)
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
    return uniform_below(z, cursor, pl / p_any if p_any > 0.0 else 0.0)
