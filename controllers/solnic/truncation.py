"""Condition a Gaussian on a half-plane, by moment matching (both solnic friction filters).

For x ~ N(μ, P) and the constraint c·x ≤ b: with s = c·x ~ N(m, v), m = c·μ, v = c'Pc,
α = (b − m)/√v and λ = φ(α)/Φ(α), the truncated s has E[s] = m − √v·λ and
VAR[s] = v(1 − αλ − λ²); μ and P follow by the linear regression of x on s. The matrix
algebra is compiled (:mod:`controllers.solnic.filter_kernels`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import log_ndtr

from controllers.solnic.filter_kernels import half_plane_apply, half_plane_moments

__all__ = ["condition_half_plane"]


def condition_half_plane(mean: np.ndarray, P: np.ndarray, c: np.ndarray, bound: float,
                         always: bool = True) -> tuple[np.ndarray, np.ndarray] | None:
    """(mean, P) of N(mean, P) conditioned on c·x ≤ ``bound``, or None when nothing changes.

    Nothing changes for a degenerate direction (c'Pc = 0), a bound more than 8 σ away, or — with
    ``always=False`` — a mean already inside the half-plane.
    """
    c = np.asarray(c, dtype=float)
    m, v = half_plane_moments(mean, P, c)
    if not v > 0:
        return None
    sd = math.sqrt(v)
    alpha = (bound - m) / sd
    if alpha > 8.0 or (alpha >= 0.0 and not always):     # no information, or mean inside
        return None
    lam = math.exp(-0.5 * alpha * alpha - 0.5 * math.log(2 * math.pi) - float(log_ndtr(alpha)))
    mean_s = m - sd * lam
    var_s = v * max(1.0 - alpha * lam - lam * lam, 1e-6)
    return half_plane_apply(mean, P, c, m, v, mean_s, var_s)
