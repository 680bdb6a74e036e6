"""Bias and variance of one pulse's motion Δc from the friction noise w2 (noise-aware model).

The text's internal model is noise-free, and (5-9) has no w2 term. While the shaft moves,
ẋ2 = α(x3 ∓ kc) + α·w2, so the velocity is v(t) = v0(t) + s·B(t) + L(t): the noise-free
velocity v0, a Brownian motion of intensity s² = α²σ2² [rad²/s³] and, while the torque
still exceeds ks (x3 > ks, the reflection rule of SPEC §2), the Skorokhod push L(t) ≥ 0 that
keeps v ≥ 0. Once x3 ≤ ks the first zero of v sticks the shaft. Δc = ∫ v dt up to the stop.

Derivation (times from breakaway t_b; t_cz the end of flyback, T1 = t_cz − t_b;
t_coast = t_stop − t_cz; a = α·k̂c the coasting deceleration):

1. **Up to t_cz** the perturbation is linear: δ(t) = s·B(t) + L(t), so with
   I1 = ∫ s·B dt:  VAR[I1] = s²T1³/3, VAR[δ(t_cz)] = s²T1 = V, COV[I1, δ] = s²T1²/2.
2. **Coasting** (x3 = 0, ẋ2 = −a + s·ẇ) from velocity x = v0(t_cz) + δ until the first zero:
   the area A solves the backward equations (s²/2)u'' − a·u' = −x·(order)·u_prev, u(0) = 0,
   whose polynomial solutions are

       E[A | x]  = x²/(2a) + s²x/(2a²)
       E[A² | x] = x⁴/(4a²) + 5s²x³/(6a³) + 5s⁴x²/(4a⁴) + 5s⁶x/(4a⁵)

   and the Gaussian moments of x give E[A], VAR[A]; COV[I1, A] = (T1/2)·V·E[∂E[A|x]/∂x]
   (Stein's lemma). VAR[Δc] = VAR[I1] + VAR[A] + 2·COV[I1, A].
3. **The push** adds E[∫ L dt]: L(t) = sup_{u≤t}(−v0(u) − s·B(u))⁺ while x3 > ks. For
   v0(u) ≈ b_eff·u (secant drift b_eff(t) = v0(t)/t of the driven phase) the running maximum
   of a Brownian motion with drift has P(L_t > m) = Φ((−m − bt)/(s√t)) +
   e^(−2bm/s²)·Φ((−m + bt)/(s√t)); E[L_t] is its integral over m. L stops growing at
   t_ks (x3 back to ks) and its value carries on to the stop: bias_push = ∫_{t_b}^{t_stop} E[L].

Formulas 1–3 linearise around the noise-free path up to t_cz and so assume that the shaft
cannot stop before the current is zero. That fails when the noise-free velocity at t_cz,
v0(t_cz), is not several standard deviations √V above zero — in particular when the noise-free
stop falls *during* the flyback, while the drive torque x3 is still decaying through k̂c. Then
the drift of the velocity toward zero, α(k̂c − x3(t)), is time-varying (it is even positive,
away from zero, while x3 > k̂c), paths are absorbed at v = 0 before t_cz, and the pulse's
velocity is comparable to the noise (Δt_u = 0.95 ms, x5 = 0: v0 ≤ 0.3 mrad/s against
s√T ≈ 0.9 mrad/s). The moments follow exactly from the backward (Feynman–Kac) equations of the
velocity process. With u_k(x, t) = E[(∫_t^τ v dr)^k | v(t) = x] (τ the stop) and the drift

    μ(t) = α·(x3(t) − k̂c),   x3 from (3-2) with u = +u_max on [0, Δt_u], −u_max to t_cz,

4. ∂u1/∂t + μ(t)·∂u1/∂x + (s²/2)·∂²u1/∂x² + x = 0,
5. ∂u2/∂t + μ(t)·∂u2/∂x + (s²/2)·∂²u2/∂x² + 2x·u1 = 0,
6. boundary at x = 0: reflecting, ∂u_k/∂x = 0, while x3 > k̂s (t_b ≤ t < t_ks, the Skorokhod
   push of 3 — here exact, not the secant bound); absorbing, u_k = 0, once x3 ≤ k̂s (the first
   zero sticks the shaft); terminal at t = t_cz (x3 = 0 from then on): the coasting
   polynomials of 2, u1 = E[A | x], u2 = E[A² | x];
7. far boundary x = X = max v0 + 6s√(t_cz − t_b), where no path is absorbed before t_cz: the
   Gaussian moments of the unabsorbed process, I = ∫_t^{t_cz} v, v(t_cz) = y + Z with
   y = X + ∫_t^{t_cz} μ, VAR[Z] = s²h, VAR[I] = s²h³/3, COV[I, Z] = s²h²/2 (h = t_cz − t):
   u1 = E[I] + E[E[A|y+Z]], u2 = E[I]² + s²h³/3 + 2(E[I]·E[E[A|y+Z]] + (s²h²/2)·E[∂E[A|x]/∂x]) +
   E[E[A²|y+Z]].

The shaft starts at v(t_b) = 0, so E[Δc] = u1(0, t_b) and E[Δc²] = u2(0, t_b); the bias is
u1(0, t_b) − Δc_p. (4)–(7) are solved backward from t_cz by Crank–Nicolson on 64 × (48 + 16)
points (two implicit Euler steps after each change of boundary condition, so the switch
absorbing → reflecting at t_ks does not ring), ~0.13 ms per call. Against a 400 × 500 grid,
over x5 ∈ [−0.8, 0.8] × Δt_u ∈ [0.5, 2.5] ms where it is used (r ≤ 0.75), the mean differs by
≤ 0.023 SD and the SD by ≤ 4.4 %, except for pulses that barely break away (on for < 20 µs
after t_b): their reflecting layer s√(t_ks − t_b) is thinner than the grid, and the mean is off
by up to 0.09 SD, the SD by up to 20 % (absolute: 0.03 µrad and 0.06 µrad on a motion of
~0.1 µrad). It is used with weight 1 when
r = v0(t_cz)/√V ≤ 0.25 (v0 continued past a flyback stop is negative), the coasting formulas
1–3 when r ≥ 0.75, linearly blended in between (the two agree within ~5 % there); in the
thesis closed loop r is 0.8–1.9 for 90 % of the planned pulses, so the solver runs rarely.
Formulas 1–3 stay the fast path: they are accurate to within the Monte-Carlo tolerance in the
tested cases, but the fine-grid solution shows that their push term (secant drift) understates
the bias of large pulses by 10–25 % (e.g. Δt_u = 2 ms, x5 = −0.6: 6.5 vs 8.1 µrad).

``tests/test_solnic_noise_model.py`` checks mean and variance against 2000 noisy
:func:`plant.pulse_response` draws in all 9 cases Δt_u ∈ {0.95, 1.2, 1.5} ms × x5 ∈ {−0.6, 0,
+0.6}, three of them flyback stops (before this solver: bias 0.49/0.43 µrad against measured
0.34/0.23, SD 0.93/0.93 against 0.71/0.52; now 0.35/0.23 and 0.73/0.54 µrad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from plant.gauss_legendre import nodes_weights
from plant.params import PlantParams
from controllers.models.acker import closed_form_kernel

__all__ = ["PulseNoise", "pulse_noise", "pulse_bias", "braked_pulse_noise", "velocity_std_after"]

_GL_X, _GL_W = nodes_weights(12)      # constants: no LAPACK (plant.gauss_legendre)
# the backward-equation solver: grid points in x, time steps after/before t_ks, domain width in
# standard deviations beyond the noise-free peak velocity, and the blend of r = v0(t_cz)/√V
_PDE_N_X, _PDE_N_ABS, _PDE_N_REFL, _PDE_SIGMAS = 64, 48, 16, 6.0
_PDE_BLEND = (0.25, 0.75)


@dataclass(frozen=True)
class PulseNoise:
    """Friction-noise moments of one pulse's Δc (positive-direction convention).

    Attributes
    ----------
    bias : float
        E[Δc] − Δc_p (noise-free) [rad], ≥ 0.
    variance : float
        VAR[Δc] [rad²].
    """

    bias: float
    variance: float


@njit(cache=True)
def _mean_running_max(b: float, s2: float, t: float) -> float:
    """E[sup_{u≤t}(s·B_u − b·u)⁺] for drift b ≥ 0 [rad/s], s² = ``s2``, in closed form.

    With P(M_t > m) = Φ((−m − bt)/(s√t)) + e^{−2bm/s²}·Φ((−m + bt)/(s√t)) (the reflection
    principle with drift), ∫₀^∞ P(M_t > m) dm integrates term by term (the second by parts, its
    exponent completing a square) to

        E[M_t] = s√t·(z·Φ(z) + φ(z)) + s²·erf(b√t / (s√2)) / (2b),   z = −b√t/s,

    which tends to s·√(2t/π) as b → 0 and to s²/(2b) as t → ∞.
    """
    if t <= 0 or s2 <= 0:
        return 0.0
    s = math.sqrt(s2)
    sd = s * math.sqrt(t)
    if b <= 0:
        return sd * math.sqrt(2.0 / math.pi)
    z = -b * math.sqrt(t) / s
    phi = math.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)
    cdf = 0.5 * math.erfc(-z / math.sqrt(2.0))
    return sd * (z * cdf + phi) + s2 * math.erf(-z / math.sqrt(2.0)) / (2.0 * b)


def velocity_std_after(params: PlantParams, moving_time: float) -> float:
    """√(α²σ2²·T) [rad/s]: the spread the noise adds to the velocity over ``moving_time``."""
    return math.sqrt(params.alpha**2 * params.sigma2_sq * max(moving_time, 0.0))


def braked_pulse_noise(params: PlantParams, ks: float, kc: float, dt_u: float, t_breakaway: float,
                       t_current_zero: float, t_stop: float) -> PulseNoise:
    """Bias and variance of Δc for a braking pulse pair (:mod:`controllers.solnic.braking`).

    Its timing leaves v(t_cz2) = r_b·√V (r_b ≥ 0.75) at the end of the reverse current, so the
    coasting formulas (1)–(3) apply with t_cz2 for t_cz and v(t_cz2) = α·k̂c·(t_stop − t_cz2)
    (the drift of the reverse drive does not enter the linear perturbation). The stop is a
    coast on k̂c, so t_stop > t_cz2; a pair without that falls back to :func:`pulse_noise`.
    """
    s2 = params.alpha**2 * params.sigma2_sq
    if t_breakaway is None or s2 <= 0 or not t_stop > t_breakaway:
        return PulseNoise(0.0, 0.0)
    if not (t_stop > t_current_zero and kc > 0):
        return pulse_noise(params, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop)
    al, U, tau = params.alpha, params.u_max, params.motor_time_constant
    b, v = _coasting_moments(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop,
                             U * -math.expm1(-dt_u / tau), _GL_X, _GL_W, al * kc * (t_stop - t_current_zero))
    return PulseNoise(b, v)


def pulse_noise(params: PlantParams, ks: float, kc: float, dt_u: float, t_breakaway: float | None,
                t_current_zero: float, t_stop: float) -> PulseNoise:
    """Bias and variance of Δc for a +u_max pulse of ``dt_u`` with friction (k̂s, k̂c).

    The noise-free times (from :func:`plant.pulse_response` with the same friction) locate
    the phases; see the module docstring for the derivation. (Compiled: it is called at every
    sample by the noise-aware planner.)
    """
    s2 = params.alpha**2 * params.sigma2_sq
    if t_breakaway is None or s2 <= 0 or not t_stop > t_breakaway:
        return PulseNoise(0.0, 0.0)
    bias, variance = _pulse_noise(params.alpha, params.u_max, params.motor_time_constant, s2, ks, kc, dt_u,
                                  t_breakaway, t_current_zero, t_stop, _GL_X, _GL_W)
    return PulseNoise(bias, variance)


def pulse_bias(params: PlantParams, ks: float, kc: float, dt_u: float, t_breakaway: float | None,
               t_current_zero: float, t_stop: float, braked: bool = False) -> float:
    """``(braked_pulse_noise if braked else pulse_noise)(...).bias`` without the variance (the
    backward solve for the mean only, :func:`_pulse_bias`): what a trigger test reads [rad]."""
    s2 = params.alpha**2 * params.sigma2_sq
    if t_breakaway is None or s2 <= 0 or not t_stop > t_breakaway:
        return 0.0
    al, U, tau = params.alpha, params.u_max, params.motor_time_constant
    if braked and t_stop > t_current_zero and kc > 0:
        return _coasting_moments(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop,
                                 U * -math.expm1(-dt_u / tau), _GL_X, _GL_W, al * kc * (t_stop - t_current_zero))[0]
    return _pulse_bias(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop, _GL_X, _GL_W)


@njit(cache=True)
def _x3(t, dt_u, U, tau, x3_off):
    if t <= dt_u:
        return U * -math.expm1(-t / tau)
    return -U + (x3_off + U) * math.exp(-(t - dt_u) / tau)


@njit(cache=True)
def _v0(t, dt_u, t_breakaway, al, U, tau, ks, kc, x3_off):
    """Noise-free velocity at time t ≥ t_b (driven, then flyback) [rad/s]."""
    w_on = min(t, dt_u) - t_breakaway
    v = al * ((U - kc) * w_on - (U - ks) * tau * -math.expm1(-w_on / tau)) if w_on > 0 else 0.0
    if t > dt_u:
        w = t - max(dt_u, t_breakaway)
        x_start = _x3(max(dt_u, t_breakaway), dt_u, U, tau, x3_off)
        v += al * ((-U - kc) * w + (x_start + U) * tau * -math.expm1(-w / tau))
    return v


@njit(cache=True)
def _pulse_noise(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop, gl_x, gl_w):
    """(bias, variance) of :func:`pulse_noise` for a moving pulse (t_stop > t_breakaway):
    the backward equations where the noise-free velocity at t_cz is within ``_PDE_BLEND[1]``
    standard deviations of zero (or negative: a stop during the flyback), the coasting formulas
    (1)–(3) beyond, linearly blended in between (module docstring)."""
    x3_off = U * -math.expm1(-dt_u / tau)
    if not kc > 0:
        return math.inf, math.inf
    T1 = t_current_zero - t_breakaway
    r = _v0(t_current_zero, dt_u, t_breakaway, al, U, tau, ks, kc, x3_off) / math.sqrt(s2 * T1)
    w = min(max((_PDE_BLEND[1] - r) / (_PDE_BLEND[1] - _PDE_BLEND[0]), 0.0), 1.0)
    bias = variance = 0.0
    if w > 0.0:
        m1, m2 = _absorbed_moments(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero,
                                   _PDE_N_X, _PDE_N_ABS, _PDE_N_REFL)
        dc0 = closed_form_kernel(dt_u, U, tau, al, ks, kc)[0]
        bias, variance = w * (m1 - dc0), w * (m2 - m1 * m1)
    if w < 1.0:
        b, v = _coasting_moments(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop,
                                 x3_off, gl_x, gl_w)
        bias += (1.0 - w) * b
        variance += (1.0 - w) * v
    return bias, max(variance, 0.0)


@njit(cache=True)
def _coasting_moments(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop, x3_off, gl_x, gl_w,
                      v_cz=math.nan):
    """(bias, variance) by (1)–(3): linear perturbation to t_cz, then coasting from v0(t_cz) + δ.

    ``v_cz`` overrides v0(t_cz) (a braking pulse pair: its t_cz2 and v(t_cz2),
    :mod:`controllers.solnic.braking`)."""
    t_f = min(t_current_zero, t_stop)
    T1 = t_f - t_breakaway
    V = s2 * T1
    a = al * kc
    x = _v0(t_f, dt_u, t_breakaway, al, U, tau, ks, kc, x3_off) if math.isnan(v_cz) else v_cz
    # Gaussian moments of x = v0(t_f) + δ, δ ~ N(0, V)
    E1, E2 = x, x * x + V
    E3, E4 = x**3 + 3 * x * V, x**4 + 6 * x * x * V + 3 * V * V
    EA = E2 / (2 * a) + s2 * E1 / (2 * a * a)
    EA2 = E4 / (4 * a * a) + 5 * s2 * E3 / (6 * a**3) + 5 * s2 * s2 * E2 / (4 * a**4) + 5 * s2**3 * E1 / (4 * a**5)
    A0 = x * x / (2 * a)
    var_A = EA2 - EA * EA
    cov = 0.5 * T1 * V * (E1 / a + s2 / (2 * a * a))
    variance = s2 * T1**3 / 3.0 + var_A + 2.0 * cov
    # the push while x3 > ks (reflection), carried to the stop
    t_ks = dt_u + tau * math.log((x3_off + U) / (ks + U)) if x3_off > ks else dt_u
    t_ks = min(max(t_ks, t_breakaway), t_stop)
    push = 0.0
    if t_ks > t_breakaway:
        half = 0.5 * (t_ks - t_breakaway)
        acc = 0.0
        for i in range(gl_x.shape[0]):                              # ∫ E[L] over [t_b, t_ks], Gauss-Legendre
            tn = t_breakaway + half * (gl_x[i] + 1.0)
            w = tn - t_breakaway
            acc += gl_w[i] * _mean_running_max(max(_v0(tn, dt_u, t_breakaway, al, U, tau, ks, kc, x3_off) / w, 1e-12),
                                               s2, w)
        push = half * acc
        L_end = _mean_running_max(max(_v0(t_ks, dt_u, t_breakaway, al, U, tau, ks, kc, x3_off) / (t_ks - t_breakaway),
                                      1e-12), s2, t_ks - t_breakaway)
        push += L_end * (t_stop - t_ks)                             # L frozen from t_ks to the stop
    return max(EA - A0, 0.0) + push, max(variance, 0.0)


@njit(cache=True)
def _absorbed_moments(al, U, tau, s2, ks, kc, dt_u, t_b, t_cz, n_x, n_abs, n_refl, second=True):
    """(E[Δc], E[Δc²]) of a moving pulse from the backward equations (4)–(6) of the module
    docstring, solved on [t_b, t_cz] × [0, X] by Crank–Nicolson (two implicit Euler steps after
    each change of boundary condition), with the coasting polynomials (2) at t = t_cz and the
    unabsorbed Gaussian moments (7) at x = X.

    The tridiagonal matrix of a time step is constant inside the domain, so it is held as three
    interior scalars and the boundary rows; the Thomas factorisation runs in the same loop as
    u1's forward elimination (two independent division chains). Every number is computed by the
    same operations as the row-array formulation it replaces (tests/test_solnic_noise_model.py
    compares the two bit for bit). With ``second`` False only u1 is solved (equation (5) reads
    u1, u1 never reads u2: the same u1 bits, about half the work; E[Δc²] is returned as NaN) —
    what the idle planner needs, the bias alone; with it u2 is solved one time step behind u1
    in the same loops (:func:`_both_moments`)."""
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
    D2 = 2 * D
    c4, c3 = 1.0 / (4 * a * a), 5 * s2 / (6 * a**3)
    c2, c1 = 5 * s2 * s2 / (4 * a**4), 5 * s2**3 / (4 * a**5)
    n = n_x + 1
    x = np.empty(n)
    u1 = np.empty(n)
    for i in range(n):
        xi = i * dx
        x[i] = xi
        u1[i] = xi * xi / (2 * a) + s2 * xi / (2 * a * a)
    if second:
        return _both_moments(al, U, tau, s2, kc, dt_u, x3_off, a, T, t_ks, t_b, X, dx, D, c4, c3, c2, c1,
                             n_x, n_abs, n_refl, x, u1)
    r1 = np.empty(n)
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
            thh = th * h
            # explicit part: u + (1−θ)h(L u + f)
            ao, bo = D - 0.5 * mu_o / dx, D + 0.5 * mu_o / dx
            _u1_rhs(r1, u1, x, n_x, D2, e, ao, bo, thh)
            an, bn = D - 0.5 * mu_n / dx, D + 0.5 * mu_n / dx
            lo_i, di_i, up_i = -th * h * an, 1.0 + 2 * th * h * D, -th * h * bn      # interior rows
            if reflect:                               # u_x(0) = 0: ghost u[-1] = u[1]
                r1[0] = u1[0] + e * (D2 * (u1[1] - u1[0]))
                di_0, up_0 = 1.0 + 2 * th * h * D, -2 * th * h * D
            else:                                     # absorbed: u(0) = 0
                r1[0] = 0.0
                di_0, up_0 = 1.0, 0.0
            # x = X: no absorption before T, Gaussian moments (7); its row is (0, 1, 0)
            M, K, w, y, vz, EI, EP1 = _top_row(M, K, h, mu_o, mu_n, T, t_o, t_n, X, s2, a)
            r1[n_x] = EI + EP1
            # Thomas: factor while eliminating u1
            cp[0] = up_0 / di_0
            dm[0] = di_0
            u1[0] = r1[0] / dm[0]
            for i in range(1, n_x):
                d = di_i - lo_i * cp[i - 1]
                dm[i] = d
                cp[i] = up_i / d
                u1[i] = (r1[i] - lo_i * u1[i - 1]) / d
            d = 1.0 - 0.0 * cp[n_x - 1]
            dm[n_x] = d
            cp[n_x] = 0.0 / d
            u1[n_x] = (r1[n_x] - 0.0 * u1[n_x - 1]) / d
            for i in range(n - 2, 0, -1):
                u1[i] -= cp[i] * u1[i + 1]
            u1[0] -= cp[0] * u1[1]
            mu_o = mu_n
    return u1[0], math.nan


@njit(cache=True)
def _u1_rhs(r1, u1, x, n_x, D2, e, ao, bo, thh):
    """The interior right-hand side of u1's time step: u1 + (1−θ)h(L u1 + x) + θh·x."""
    for i in range(1, n_x):
        r1[i] = u1[i] + e * (ao * u1[i - 1] - D2 * u1[i] + bo * u1[i + 1] + x[i]) + thh * x[i]


@njit(cache=True)
def _top_row(M, K, h, mu_o, mu_n, T, t_o, t_n, X, s2, a):
    """The x = X row's Gaussian moments (7) at the step's new time t_n (no absorption before T):
    the trapezoid sums M = ∫μ, K = ∫μ(T − r)dr advanced by one step, then (M, K, w = T − t_n,
    y = X + M, v = σ²w, E∫x, E[P1])."""
    M += 0.5 * h * (mu_o + mu_n)
    K += 0.5 * h * (mu_o * (T - t_o) + mu_n * (T - t_n))
    w = T - t_n
    y, vz = X + M, s2 * w
    EI = X * w + K
    EP1 = y * y / (2 * a) + s2 * y / (2 * a * a) + vz / (2 * a)
    return M, K, w, y, vz, EI, EP1


@njit(cache=True)
def _u2_rhs(r2, u2, u1_old, u1_new, x, n_x, D2, e, ao, bo, src, reflect, top):
    """The right-hand side of u2's time step: u2 + (1−θ)h(L u2 + 2x·u1_old) + θh·2x·u1_new (the
    source's implicit half added last, as the row-array formulation does), its boundary rows."""
    for i in range(1, n_x):
        r2[i] = u2[i] + e * (ao * u2[i - 1] - D2 * u2[i] + bo * u2[i + 1] + 2 * x[i] * u1_old[i])
        r2[i] += src * x[i] * u1_new[i]
    r2[0] = u2[0] + e * (D2 * (u2[1] - u2[0])) if reflect else 0.0
    r2[n_x] = top


@njit(cache=True)
def _both_moments(al, U, tau, s2, kc, dt_u, x3_off, a, T, t_ks, t_b, X, dx, D, c4, c3, c2, c1,
                  n_x, n_abs, n_refl, x, u1_end):
    """(u1, u2) at (0, t_b) for :func:`_absorbed_moments` (its set-up's values in): u1's time
    steps as in its mean-only loop, and u2's step j inside u1's step j + 1 — its right-hand side
    first, then its forward elimination in u1's (factoring) loop and its back substitution in
    u1's. u2's step j reads u1 before and after step j and step j's factorisation, all kept per
    step; so every number is the same operation on the same operands as solving u2 right after
    u1 in each step, but the two division chains run side by side."""
    D2 = 2 * D
    n = n_x + 1
    S = n_abs + n_refl
    u1 = np.empty((S + 1, n))                     # u1[j]: before time step j (u1[0] at t = T)
    u2 = np.empty(n)
    for i in range(n):
        u1[0, i] = u1_end[i]
        xi = x[i]
        u2[i] = ((c4 * xi + c3) * xi + c2) * xi * xi + c1 * xi
    cp = np.empty((S, n))
    dm = np.empty((S, n))
    # step j's explicit coefficients, lower diagonal, u2 source factor, boundary, top row of u2
    st_e, st_ao, st_bo = np.empty(S), np.empty(S), np.empty(S)
    st_lo, st_src, st_top = np.empty(S), np.empty(S), np.empty(S)
    st_refl = np.empty(S, np.bool_)
    r1 = np.empty(n)
    r2 = np.empty(n)
    M = 0.0
    K = 0.0
    j = 0
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
            thh = th * h
            ao, bo = D - 0.5 * mu_o / dx, D + 0.5 * mu_o / dx
            _u1_rhs(r1, u1[j], x, n_x, D2, e, ao, bo, thh)
            lag = j > 0
            q = j - 1                                 # u2's step in this one
            if lag:
                _u2_rhs(r2, u2, u1[q], u1[j], x, n_x, D2, st_e[q], st_ao[q], st_bo[q], st_src[q],
                        st_refl[q], st_top[q])
            an, bn = D - 0.5 * mu_n / dx, D + 0.5 * mu_n / dx
            lo_i, di_i, up_i = -th * h * an, 1.0 + 2 * th * h * D, -th * h * bn
            if reflect:
                r1[0] = u1[j, 0] + e * (D2 * (u1[j, 1] - u1[j, 0]))
                di_0, up_0 = 1.0 + 2 * th * h * D, -2 * th * h * D
            else:
                r1[0] = 0.0
                di_0, up_0 = 1.0, 0.0
            M, K, w, y, vz, EI, EP1 = _top_row(M, K, h, mu_o, mu_n, T, t_o, t_n, X, s2, a)
            r1[n_x] = EI + EP1
            Ez2 = y * y + vz
            Ez3 = y * (y * y + 3 * vz)
            Ez4 = y**4 + 6 * y * y * vz + 3 * vz * vz
            EP2 = c4 * Ez4 + c3 * Ez3 + c2 * Ez2 + c1 * y
            st_top[j] = (EI * EI + s2 * w**3 / 3.0
                         + 2.0 * (EI * EP1 + 0.5 * s2 * w * w * (y / a + s2 / (2 * a * a))) + EP2)
            st_e[j], st_ao[j], st_bo[j], st_lo[j], st_src[j], st_refl[j] = e, ao, bo, lo_i, th * h * 2, reflect
            # forward: factor and eliminate u1's step j; eliminate u2's step j − 1
            cp[j, 0] = up_0 / di_0
            dm[j, 0] = di_0
            u1[j + 1, 0] = r1[0] / dm[j, 0]
            if lag:
                lo_q = st_lo[q]
                u2[0] = r2[0] / dm[q, 0]
                for i in range(1, n_x):
                    d = di_i - lo_i * cp[j, i - 1]
                    dm[j, i] = d
                    cp[j, i] = up_i / d
                    u1[j + 1, i] = (r1[i] - lo_i * u1[j + 1, i - 1]) / d
                    u2[i] = (r2[i] - lo_q * u2[i - 1]) / dm[q, i]
                u2[n_x] = (r2[n_x] - 0.0 * u2[n_x - 1]) / dm[q, n_x]
            else:
                for i in range(1, n_x):
                    d = di_i - lo_i * cp[j, i - 1]
                    dm[j, i] = d
                    cp[j, i] = up_i / d
                    u1[j + 1, i] = (r1[i] - lo_i * u1[j + 1, i - 1]) / d
            d = 1.0 - 0.0 * cp[j, n_x - 1]
            dm[j, n_x] = d
            cp[j, n_x] = 0.0 / d
            u1[j + 1, n_x] = (r1[n_x] - 0.0 * u1[j + 1, n_x - 1]) / d
            # back substitution: u1's step j, u2's step j − 1
            if lag:
                for i in range(n - 2, 0, -1):
                    u1[j + 1, i] -= cp[j, i] * u1[j + 1, i + 1]
                    u2[i] -= cp[q, i] * u2[i + 1]
                u2[0] -= cp[q, 0] * u2[1]
            else:
                for i in range(n - 2, 0, -1):
                    u1[j + 1, i] -= cp[j, i] * u1[j + 1, i + 1]
            u1[j + 1, 0] -= cp[j, 0] * u1[j + 1, 1]
            mu_o = mu_n
            j += 1
    if j > 0:                                         # u2's last step, alone
        q = j - 1
        _u2_rhs(r2, u2, u1[q], u1[j], x, n_x, D2, st_e[q], st_ao[q], st_bo[q], st_src[q], st_refl[q], st_top[q])
        lo_q = st_lo[q]
        u2[0] = r2[0] / dm[q, 0]
        for i in range(1, n_x):
            u2[i] = (r2[i] - lo_q * u2[i - 1]) / dm[q, i]
        u2[n_x] = (r2[n_x] - 0.0 * u2[n_x - 1]) / dm[q, n_x]
        for i in range(n - 2, -1, -1):
            u2[i] -= cp[q, i] * u2[i + 1]
    return u1[j, 0], u2[0]


@njit(cache=True)
def _pulse_bias(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop, gl_x, gl_w):
    """The bias of :func:`_pulse_noise` alone (what the idle planner reads): the same operations
    in the same order for the mean, the backward solve without the second moment's equation (5)
    (``_absorbed_moments(..., second=False)``, about half of it). Bit for bit
    ``_pulse_noise(...)[0]`` (tests/test_solnic_noise_model.py)."""
    x3_off = U * -math.expm1(-dt_u / tau)
    if not kc > 0:
        return math.inf
    T1 = t_current_zero - t_breakaway
    r = _v0(t_current_zero, dt_u, t_breakaway, al, U, tau, ks, kc, x3_off) / math.sqrt(s2 * T1)
    w = min(max((_PDE_BLEND[1] - r) / (_PDE_BLEND[1] - _PDE_BLEND[0]), 0.0), 1.0)
    bias = 0.0
    if w > 0.0:
        m1 = _absorbed_moments(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero,
                               _PDE_N_X, _PDE_N_ABS, _PDE_N_REFL, False)[0]
        dc0 = closed_form_kernel(dt_u, U, tau, al, ks, kc)[0]
        bias = w * (m1 - dc0)
    if w < 1.0:
        b, v = _coasting_moments(al, U, tau, s2, ks, kc, dt_u, t_breakaway, t_current_zero, t_stop,
                                 x3_off, gl_x, gl_w)
        bias += (1.0 - w) * b
    return bias
