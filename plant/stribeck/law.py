"""The sliding-friction law of the ``stribeck`` family (SPEC §11), compiled.

F(v) = sign(v)·[kc + (ks − kc)·exp(−(|v|/v_s)^δ) + b·|v|]   (Armstrong-Hélouvry 1991, eq. 2.5;
Canudas de Wit et al. 1995, g(v) with δ = 2, plus viscous b·v), with the effective levels
kc = k̄c·m(θ) + x5 and ks = k̄s·m(θ) + x5 clamped at ≥ 0 (SPEC §2, §11).

Law vector L (``StribeckParams.law_vector``): the slots below.
"""

from __future__ import annotations

import math

from numba import njit

from plant.ripple import ripple_factor

__all__ = ["effective_levels", "sliding_magnitude", "acceleration"]

(L_ALPHA, L_BETA3, L_BETA4, L_BETA5, L_KC, L_KS, L_VS, L_DELTA, L_B, L_RIPPLE, L_WAVENUMBER, L_PHASE,
 L_SIGMA2_SQ, L_SIGMA5_SQ) = range(14)


@njit(cache=True)
def effective_levels(theta, x5, L):
    """(kc, ks) [ozf·in] at load angle θ [rad] and correlated friction x5 [ozf·in]."""
    m = ripple_factor(theta, L[L_RIPPLE], L[L_WAVENUMBER], L[L_PHASE])
    return max(L[L_KC] * m + x5, 0.0), max(L[L_KS] * m + x5, 0.0)


@njit(cache=True)
def sliding_magnitude(speed, kc, ks, vs, delta, b):
    """|F| at speed |v| [rad/s]: kc + (ks − kc)·exp(−(|v|/v_s)^δ) + b·|v| [ozf·in]."""
    r = speed / vs
    if delta == 2.0:
        e = math.exp(-r * r)
    else:
        e = math.exp(-(r ** delta))
    return kc + (ks - kc) * e + b * speed


@njit(cache=True)
def acceleration(s, v, x3, x5, theta, L):
    """ẋ2 = α·(x3 − s·F) in the moving mode of direction s = ±1 [rad/s²]."""
    kc, ks = effective_levels(theta, x5, L)
    return L[L_ALPHA] * (x3 - s * sliding_magnitude(abs(v), kc, ks, L[L_VS], L[L_DELTA], L[L_B]))
