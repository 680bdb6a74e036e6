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

When the noise-free stop falls before t_cz (a short pulse that sticks during flyback) the same
formulas are used with t_coast = 0 and the local deceleration a = α(k̂c − x3(t_stop)) when
that is positive (else α·k̂c). The mean is exact to first order in the push and the variance
ignores the push's own spread; ``tests/test_solnic_noise_model.py`` checks both against 2000
noisy :func:`plant.pulse_response` draws with stated tolerances.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from plant.params import PlantParams

__all__ = ["PulseNoise", "pulse_noise", "velocity_std_after"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(12)


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
    """(bias, variance) of :func:`pulse_noise` for a moving pulse (t_stop > t_breakaway)."""
    x3_off = U * -math.expm1(-dt_u / tau)
    t_f = min(t_current_zero, t_stop)
    T1 = t_f - t_breakaway
    V = s2 * T1
    if t_stop > t_current_zero:
        a = al * kc
        x = _v0(t_f, dt_u, t_breakaway, al, U, tau, ks, kc, x3_off)
    else:
        a = al * (kc - _x3(t_stop, dt_u, U, tau, x3_off))
        if not a > 0:
            a = al * kc
        x = 0.0
    if not a > 0:
        return math.inf, math.inf
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
