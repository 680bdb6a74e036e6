"""Cancellation-free exponential remainders, shared by the closed forms and the kernels.

With x = β·h these are the building blocks of Φ(h) (3-20)–(3-22) and of the noise
covariance (4-8)::

    e1(x) = 1 − e^(−x)                      ≈ x
    e2(x) = e^(−x) − 1 + x                  ≈ x²/2
    e3(x) = 1 − x + x²/2 − e^(−x)           ≈ x³/6
    e4(x) = ∫₀ˣ (1 − e^(−s))² ds = x − E − E²/2,  E = e1(x)   ≈ x³/3

Below |x| = 0.5 the remainders are summed as Taylor series (stopped once the terms fall below
half an ulp of the sum), so each is accurate to a few ulp for any x (the direct formulas lose every digit for x → 0). Compiled with numba; the functions
are plain callables from Python too.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["e1", "e2", "e3", "e4"]

_CUTOFF = 0.5
_TERMS = 24
# The series stop once a term is below 2^-60 of the sum: |x| < 0.5 makes the terms shrink at
# least geometrically (ratio ≤ 0.5/(k+1)), so everything left adds < 2^-59 relative, below
# half an ulp — the sum is the one the full 22 terms give.
_NEGLIGIBLE = 2.0 ** -60


@njit(cache=True)
def e1(x):
    """1 − e^(−x)."""
    return -math.expm1(-x)


@njit(cache=True)
def e2(x):
    """e^(−x) − 1 + x."""
    if abs(x) >= _CUTOFF:
        return math.expm1(-x) + x
    term = x * x / 2.0
    total = 0.0
    for k in range(2, _TERMS):
        total += term
        if abs(term) <= _NEGLIGIBLE * abs(total):
            break
        term *= -x / (k + 1)
    return total


@njit(cache=True)
def e3(x):
    """1 − x + x²/2 − e^(−x)."""
    if abs(x) >= _CUTOFF:
        return -math.expm1(-x) - x + 0.5 * x * x
    term = x ** 3 / 6.0
    total = 0.0
    for k in range(3, _TERMS):
        total += term
        if abs(term) <= _NEGLIGIBLE * abs(total):
            break
        term *= -x / (k + 1)
    return total


@njit(cache=True)
def e4(y):
    """∫₀^y (1 − e^(−s))² ds = y − E − E²/2 with E = 1 − e^(−y), for y ≥ 0."""
    if y >= _CUTOFF:
        E = -math.expm1(-y)
        return y - E - 0.5 * E * E
    # Σ_{k≥2} (−1)^k (2^k − 2) y^(k+1)/(k+1)!
    total = 0.0
    fact = 6.0
    k = 2
    power = y ** 3
    while k < 40:
        term = (2.0 ** k - 2.0) * power / fact
        if k % 2 == 0:
            total += term
        else:
            total -= term
        if term <= 1e-17 * total:
            break
        k += 1
        power *= y
        fact *= k + 1
    return total
