"""State-transition matrices Φ(h) and process-noise covariances of the three modes.

Augmented state vector, as in (3-5)::

    X = [x1, x2, x3, x4, x5, x6, u]
        x1 = c − r, error [rad]          x2 = ċ, shaft velocity [rad/s]
        x3 motor torque [ozf·in]          x4 = ṙ, commanded velocity [rad/s]
        x5 correlated friction [ozf·in]   x6 = k̄c, mean Coulomb friction [ozf·in]
        u drive level [ozf·in]

Between events the plant obeys Ẋ = F_i X + W (4-2) with F_1, F_2, F_3 of (3-7)–(3-9):
mode 1 (moving, x2 < 0) has ẋ2 = α(x3 + x5 + x6), mode 3 (x2 > 0) has
ẋ2 = α(x3 − x5 − x6), mode 2 (stuck) has x2 ≡ 0 and x5 frozen.

x6 = k̄c is the constant coordinate that makes the affine drift linear; the simulator keeps
k̄c as a parameter and builds this vector only inside its kernels (plant.multimode.moving).

``phi`` evaluates the closed forms (3-20)–(3-22) with cancellation-free helpers, so every
entry is accurate to a few ulp for any h. ``process_noise`` evaluates (4-8),
Q(h) = ∫₀ʰ Φ(v) Qc Φ(v)ᵀ dv, by Gauss–Legendre quadrature. The noise enters only through the
x2, x4 and x5 columns of Φ, whose entries are polynomials in v times exponentials in the slow
rates β4, β5 (β3 never appears), so an 8-node rule on panels with β·Δ ≤ 0.25 is exact to
round-off (the truncation term is below (0.25)^16/16! ≈ 1e-23). Van Loan's method is the
independent oracle in the tests.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from plant.gauss_legendre import nodes_weights
from plant.expfun import e1, e2, e3
from plant.params import PlantParams

__all__ = [
    "X1", "X2", "X3", "X4", "X5", "X6", "U", "N_STATE",
    "phi", "drift_matrix", "noise_intensity", "process_noise",
    "e1", "e2", "e3",
]

X1, X2, X3, X4, X5, X6, U = range(7)
N_STATE = 7

def drift_matrix(mode: int, params: PlantParams) -> np.ndarray:
    """F_i of (3-7)–(3-9); mode 2 uses x2's clamp (row 2 zero) instead of −∞."""
    a, b3, b4, b5 = params.alpha, params.beta3, params.beta4, params.beta5
    F = np.zeros((N_STATE, N_STATE))
    F[X1, X2], F[X1, X4] = 1.0, -1.0
    F[X3, X3], F[X3, U] = -b3, b3
    F[X4, X4] = -b4
    if mode == 2:
        F[X1, X2] = 0.0  # x2 ≡ 0 while stuck
        return F
    _check_mode(mode)
    s = 1.0 if mode == 1 else -1.0
    F[X2, X3], F[X2, X5], F[X2, X6] = a, s * a, s * a
    F[X5, X5] = -b5
    return F


def _check_mode(mode: int) -> None:
    if mode not in (1, 2, 3):
        raise ValueError(f"mode must be 1, 2 or 3, got {mode!r}")


def phi(mode: int, h: float, params: PlantParams) -> np.ndarray:
    """Closed-form state-transition matrix Φ_i(h) = expm(F_i·h), (3-20)–(3-22)."""
    _check_mode(mode)
    a, b3, b4, b5 = params.alpha, params.beta3, params.beta4, params.beta5
    P = np.eye(N_STATE)
    y3 = b3 * h
    P[X3, X3] = math.exp(-y3)                 # q33
    P[X3, U] = e1(y3)                         # q37
    P[X4, X4] = math.exp(-b4 * h)             # q44
    P[X1, X4] = -e1(b4 * h) / b4              # q14
    if mode == 2:
        P[X2, X2] = 0.0                       # (3-22): x2 clamped to 0, x5 frozen
        return P
    s = 1.0 if mode == 1 else -1.0            # (3-21): mode 3 flips the friction terms
    y5 = b5 * h
    P[X1, X2] = h
    P[X1, X3] = a * e2(y3) / b3**2            # q13
    P[X2, X3] = a * e1(y3) / b3               # q23
    P[X1, U] = a * e3(y3) / b3**2             # q17
    P[X2, U] = a * e2(y3) / b3                # q27
    P[X5, X5] = math.exp(-y5)                 # q55
    P[X1, X5] = s * a * e2(y5) / b5**2        # q15
    P[X2, X5] = s * a * e1(y5) / b5           # q25
    P[X1, X6] = s * a * h * h / 2.0
    P[X2, X6] = s * a * h
    return P


def noise_intensity(mode: int, params: PlantParams) -> np.ndarray:
    """Continuous white-noise intensity Q of (4-7); mode 2 keeps only w4 (4-11)."""
    _check_mode(mode)
    Qc = np.zeros((N_STATE, N_STATE))
    Qc[X4, X4] = params.sigma4_sq
    if mode != 2:
        Qc[X2, X2] = params.alpha**2 * params.sigma2_sq
        Qc[X5, X5] = params.sigma5_sq
    return Qc


_GL_NODES, _GL_WEIGHTS = nodes_weights(8)      # constants: no LAPACK (plant.gauss_legendre)
_PANEL_RATE = 0.25


def process_noise(mode: int, h: float, params: PlantParams) -> np.ndarray:
    """COV[N(n)] = ∫₀ʰ Φ(v) Q Φ(v)ᵀ dv  (4-8), exact to round-off (see module docstring)."""
    return _process_noise_cached(mode, float(h), params).copy()


@lru_cache(maxsize=4096)
def _process_noise_cached(mode: int, h: float, params: PlantParams) -> np.ndarray:
    _check_mode(mode)
    if h <= 0:
        return np.zeros((N_STATE, N_STATE))
    Qc = noise_intensity(mode, params)
    cols = [j for j in (X2, X4, X5) if Qc[j, j] > 0]
    C = np.zeros((N_STATE, N_STATE))
    if not cols:
        return C
    rate = max(params.beta4, params.beta5 if mode != 2 else 0.0)
    panels = max(1, math.ceil(rate * h / _PANEL_RATE))
    width = h / panels
    for p in range(panels):
        lo = p * width
        for node, weight in zip(_GL_NODES, _GL_WEIGHTS):
            v = lo + 0.5 * width * (node + 1.0)
            Pv = phi(mode, v, params)
            for j in cols:
                col = Pv[:, j]
                C += (0.5 * width * weight * Qc[j, j]) * np.outer(col, col)
    return C
