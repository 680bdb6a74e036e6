"""Mode 2, the shaft stuck: Φ_2 (3-22) and its noise (4-11), in closed form.

While stuck, x2 ≡ 0 and x5 is frozen; x3 relaxes toward u; the error drifts with the
commanded velocity, ẋ1 = −x4, and x4 is an Ornstein–Uhlenbeck process (rate β4, intensity
σ4²). Over h, with y = β4·h and E = 1 − e^(−y)::

    x1⁺ = x1 − x4·E/β4 + n1        x4⁺ = x4·(1 − E) + n4        x3⁺ = u + (x3 − u)·e^(−β3·h)
    COV[n1, n4] = σ4²·[[e4(y)/β4³, −E²/(2β4²)], [·, E(2 − E)/(2β4)]]

the exact integral of (4-8) for mode 2 (e4 from plant.expfun). The pair is drawn with its
2 × 2 Cholesky factor and two unit normals, as the minimal factor (4-20) does. Breakaway,
|x3| = ks, is a closed-form time (plant.multimode.segments) because x3 is deterministic.
"""

from __future__ import annotations

import math

from numba import njit

from plant.expfun import e4
from plant.randomness import ZPOS, NoiseExhausted

__all__ = ["stuck_propagate"]

# Augmented-vector slots used by every kernel (see plant.multimode.moving): x1, x2, x3, x4, x5, kc, u.
A1, A2, A3, A4, A5, AKC, AU = range(7)


@njit(cache=True, _nrt=False)
def stuck_propagate(X, h, p, noisy, z, cursor):
    """Advance the stuck shaft by h [s] in place; draws two normals when σ4 > 0 and noisy."""
    b3, b4, s4 = p.beta3, p.beta4, p.sigma4_sq
    y = b4 * h
    E = -math.expm1(-y)
    x4 = X[A4]
    X[A1] -= x4 * E / b4                                  # q14
    X[A4] = x4 * (1.0 - E)                                # q44
    X[A3] = X[AU] + (X[A3] - X[AU]) * math.exp(-b3 * h)   # q33, q37
    if noisy and s4 > 0.0:
        c11 = s4 * e4(y) / b4 ** 3
        c14 = -s4 * E * E / (2.0 * b4 * b4)
        c44 = s4 * E * (2.0 - E) / (2.0 * b4)
        l11 = math.sqrt(max(c11, 0.0))
        l21 = c14 / l11 if l11 > 0.0 else 0.0      # zero-length step (breakaway at once)
        l22 = math.sqrt(max(c44 - l21 * l21, 0.0))
        i = cursor[ZPOS]                  # the next two normals, one bounds check (NoiseExhausted
        if i + 2 > z.shape[0]:            # makes the caller rerun the whole interval)
            raise NoiseExhausted()
        cursor[ZPOS] = i + 2
        z1, z2 = z[i], z[i + 1]
        X[A1] += l11 * z1
        X[A4] += l21 * z1 + l22 * z2
