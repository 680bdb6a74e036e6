"""Dormand–Prince 5(4) tableau and its quartic dense output (Dormand & Prince 1980; Shampine 1986).

The same coefficients as ``scipy.integrate.RK45``: the step is taken with the fifth-order
weights B (local extrapolation), the error estimated with E = B − B̂ (fourth order), and the
continuous extension y(t0 + θh) = y0 + h·Σ_i k_i·Σ_j P[i, j]·θ^(j+1) is fourth order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["C", "A", "B", "E", "P", "dense_coefficients", "dense_value"]

C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0])
A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [1 / 5, 0.0, 0.0, 0.0, 0.0],
    [3 / 40, 9 / 40, 0.0, 0.0, 0.0],
    [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656]])
B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84])
E = np.array([-71 / 57600, 0.0, 71 / 16695, -71 / 1920, 17253 / 339200, -22 / 525, 1 / 40])
P = np.array([
    [1.0, -8048581381 / 2820520608, 8663915743 / 2820520608, -12715105075 / 11282082432],
    [0.0, 0.0, 0.0, 0.0],
    [0.0, 131558114200 / 32700410799, -68118460800 / 10900136933, 87487479700 / 32700410799],
    [0.0, -1754552775 / 470086768, 14199869525 / 1410260304, -10690763975 / 1880347072],
    [0.0, 127303824393 / 49829197408, -318862633887 / 49829197408, 701980252875 / 199316789632],
    [0.0, -282668133 / 205662961, 2019193451 / 616988883, -1453857185 / 822651844],
    [0.0, 40617522 / 29380423, -110615467 / 29380423, 69997945 / 29380423]])
for _a in (C, A, B, E, P):
    _a.flags.writeable = False


@njit(cache=True)
def dense_coefficients(K, out):
    """out[j] = Σ_i K[i]·P[i, j] (j < 4) for one component's seven stage slopes K."""
    for j in range(4):
        acc = 0.0
        for i in range(7):
            acc += K[i] * P[i, j]
        out[j] = acc


@njit(cache=True)
def dense_value(y0, h, Qc, theta):
    """y(t0 + θh) = y0 + h·(Q0·θ + Q1·θ² + Q2·θ³ + Q3·θ⁴)."""
    return y0 + h * theta * (Qc[0] + theta * (Qc[1] + theta * (Qc[2] + theta * Qc[3])))
