"""The LuGre law for the compiled integrator: right-hand side, Jacobian and time derivative.

Canudas de Wit, Olsson, Åström & Lischinsky, IEEE TAC 40(3), 1995, eqs. (1)-(3) (SPEC §11)::

    ż = v − σ0·|v|·z/g(v)        g(v) = kc + (ks − kc)·exp(−(v/v_s)²)
    F = σ0·z + σ1·ż + σ2·v
    v̇ = α·(x3(t) + P(t, D) − F)   Ḋ = v

on y = (v, z, D), D the load's displacement in the segment; x3(t) = u + (x3₀ − u)·e^(−β3·t)
exactly, x5(t) = x5₀·e^(−β5·t) (noise-free), kc = k̄c·m(θ₀ + D) + x5, ks = k̄s·m(θ₀ + D) + x5.
P(t, D) = P₀ + K·(v_p·t − D) is an external spring pulled at v_p: zero for the gimbal
(K = 0), the spring–block of the 1995 paper's stick-slip example otherwise.

Law vector L (``LuGreParams.law_vector``) and segment constants C: the slots below. Where
g = 0 (both levels clamped to 0) the law is undefined; the parameters keep k̄c > 0 in practice.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["rhs"]

(L_ALPHA, L_BETA3, L_BETA4, L_BETA5, L_KC, L_KS, L_VS, L_S0, L_S1, L_S2, L_RIPPLE, L_WAVENUMBER, L_PHASE,
 L_SIGMA2_SQ, L_SIGMA5_SQ, L_SPRING, L_PULL) = range(17)
C_U, C_X30, C_X50, C_TH0, C_P0 = range(5)


@njit(cache=True)
def rhs(t, v, z, D, C, L):
    """(v̇, ż, Ḋ) at (t, y) and the friction F [ozf·in]."""
    alpha, s0, s1, s2 = L[L_ALPHA], L[L_S0], L[L_S1], L[L_S2]
    x3 = C[C_U] + (C[C_X30] - C[C_U]) * math.exp(-L[L_BETA3] * t)
    x5 = C[C_X50] * math.exp(-L[L_BETA5] * t)
    a = L[L_RIPPLE]
    m = 1.0 + a * math.sin(L[L_WAVENUMBER] * (C[C_TH0] + D) + L[L_PHASE]) if a != 0.0 else 1.0
    kc = max(L[L_KC] * m + x5, 0.0)
    ks = max(L[L_KS] * m + x5, 0.0)
    r = v / L[L_VS]
    g = kc + (ks - kc) * math.exp(-r * r)
    zdot = v - s0 * abs(v) * z / g
    F = s0 * z + s1 * zdot + s2 * v
    vdot = alpha * (x3 + C[C_P0] + L[L_SPRING] * (L[L_PULL] * t - D) - F)
    return vdot, zdot, v, F
