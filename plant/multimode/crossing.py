"""The Brownian-bridge crossing decision of a noisy sub-step, mostly without exp and erfc.

A sub-step whose velocity keeps its sign at both ends, va·vb > 0, crossed 0 with probability
pc = exp(e), e = −2·va·vb/(σ_v²·h); the kernel decides it from the next unit normal x of the
stream as U < pc with U = Φ(x) = ½·erfc(−x/√2) (plant.randomness.uniform_below). The decision is
a comparison, and Φ is increasing: with x in a cell [a_i, a_i+1) of a fixed grid,
log Φ(a_i) ≤ log Φ(x) < log Φ(a_i+1), so e below the cell's lower end decides "no crossing"
and e above its upper end "crossing", with neither exp nor erfc evaluated. Only an e inside
the cell (or x off the grid) pays for both, exactly as before. The table is widened by a
relative margin of 1e-9 on each side (the rounding of erfc, exp and the table itself is
~1e-16 relative), so a decided comparison is the one the floating-point form makes, and the
decision and the normals read are those of :func:`plant.multimode.zero_velocity._crossed`
(tests/test_bridge_loop.py checks both on random draws, at the grid points ±1 ulp and at the
cells' edges).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.randomness import normal, uniform_below

__all__ = ["crossed", "exp_below", "minimum_above_zero", "LOG_PHI_LO", "LOG_PHI_HI", "GRID_MIN", "GRID_STEP"]

GRID_MIN = -16.0
"""Left end a_0 of the grid of x [unit normals]; its right end is 0 (U < ½)."""
GRID_STEP = 1.0 / 64.0
"""Cell width of the grid of x."""
_MARGIN = 1e-9
_N = int(round(-GRID_MIN / GRID_STEP))


def _log_phi(a: float) -> float:
    return math.log(0.5 * math.erfc(-a / math.sqrt(2.0)))


# log Φ at the cells' ends, widened outward by the margin: cell i is [a_i, a_i + step).
_ENDS = np.array([_log_phi(GRID_MIN + i * GRID_STEP) for i in range(_N + 1)])
LOG_PHI_LO = _ENDS[:-1] - _MARGIN * np.maximum(1.0, np.abs(_ENDS[:-1]))
"""Lower bound of log Φ(x) on cell i, less the margin."""
LOG_PHI_HI = _ENDS[1:] + _MARGIN * np.maximum(1.0, np.abs(_ENDS[1:]))
"""Upper bound of log Φ(x) on cell i, plus the margin."""
LOG_PHI_LO.flags.writeable = False
LOG_PHI_HI.flags.writeable = False


@njit(cache=True, _nrt=False)
def exp_below(e, z, cursor):
    """``uniform_below(z, cursor, math.exp(e))`` for −745 < e < −1e-6 (so 0 < exp(e) < 1): the
    same decision from the same one normal, exp and erfc only when the grid cannot decide."""
    x = normal(z, cursor)
    if x >= 0.0:
        if e < -0.7:                    # pc < ½ ≤ U (uniform_below's sign rule)
            return False
    elif x > GRID_MIN:
        i = int((x - GRID_MIN) * (1.0 / GRID_STEP))
        if i < LOG_PHI_LO.shape[0]:
            if e < LOG_PHI_LO[i]:       # pc < Φ(x) = U
                return False
            if e > LOG_PHI_HI[i]:       # pc > U
                return True
    pc = math.exp(e)
    if x >= 0.0 and pc <= 0.5:
        return False
    if x < 0.0 and pc > 0.5:
        return True
    return 0.5 * math.erfc(-x / math.sqrt(2.0)) < pc


@njit(cache=True, _nrt=False, inline="always")
def crossed(va, vb, h, sig_v2, z, cursor):
    """``pc >= 1.0 or uniform_below(z, cursor, pc)`` with pc the bridge crossing probability of
    x2 from ``va`` to ``vb`` over ``h`` (σ_v² = ``sig_v2``): the decision and the normals read of
    :func:`plant.multimode.zero_velocity._crossed`, exp and erfc skipped where the grid of
    log Φ decides (module docstring)."""
    if (va > 0) != (vb > 0) or va == 0.0 or vb == 0.0:
        return True
    e = -2.0 * va * vb / (sig_v2 * h)
    if e < -70.0:
        x = normal(z, cursor)
        if x > -11.0:
            return False
        return 0.5 * math.erfc(-x / math.sqrt(2.0)) < math.exp(e)
    if e < -1e-6:                       # pc = exp(e) < 1 for sure: a normal is read
        return exp_below(e, z, cursor)
    pc = math.exp(e)
    return pc >= 1.0 or uniform_below(z, cursor, pc)


@njit(cache=True, _nrt=False, inline="always")
def minimum_above_zero(va, vb, c, x):
    """True when the reflecting sub-step's bridge minimum as
    :func:`plant.multimode.zero_velocity._bridge_low` computes it,
    ½·(va + vb − √((vb − va)² − c·ln U)) with U = Φ(x) = ½·erfc(−x/√2) and c = 2σ_v²h, is
    certainly not below 0 — decided without erfc and log, for va, vb > 0 and x on the grid.

    The sign is that of fl(va + vb) − fl(√D): no push iff the computed D ≤ fl(va + vb)². D adds two
    non-negative numbers, the same fl((vb − va)²) and |fl(c·ln U)| ≤ c·(−LOG_PHI_LO[i])·(1 + 3ε)
    (the table's lower end of log Φ on x's cell lies 1e-9 below it, far beyond the rounding of erfc
    and log), so D ≤ ((vb − va)² + c·(−LOG_PHI_LO[i]))·(1 + 6ε); the test below asks for a
    relative gap of 2e-12 instead, within the normal range of doubles. Otherwise (False) the
    caller evaluates the minimum as before.
    """
    if not (GRID_MIN < x < 0.0):
        return False
    i = int((x - GRID_MIN) * (1.0 / GRID_STEP))
    if i >= LOG_PHI_LO.shape[0]:
        return False
    bound = (vb - va) ** 2 + c * (-LOG_PHI_LO[i])
    s = va + vb
    ss = s * s
    return bound * (1.0 + 1e-12) < ss * (1.0 - 1e-12) and 1e-290 < bound and ss < 1e300
