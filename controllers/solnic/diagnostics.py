"""Consistency diagnostics of the solnic estimators, computed from a recorded run.

NEES (normalised estimation error squared) of the mode-2 filter at the sample instants:
e = (x1 − x̂1, x4 − x̂4), NEES = e'P⁻¹e / 2, averaged over the scored samples at which the shaft
is stuck (mode 2, where the filter's model holds). A consistent filter gives ≈ 1; the scalar
x̂1 NEES is e1²/P11. The normalised innovation squared of Δc (residual² / (H P_b H' + R) of
each friction update) is the controller's ``dc_nis_mean`` summary.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

__all__ = ["mode2_nees"]


def mode2_nees(samples: Mapping[str, np.ndarray], internals: Mapping[str, np.ndarray],
               warmup_s: float = 0.0) -> dict[str, float]:
    """Mean NEES of (x̂1, x̂4) and of x̂1 alone over stuck samples with t ≥ ``warmup_s``."""
    t = np.asarray(samples["t"])
    n = min(len(t), len(internals["m2_x1"]))
    sel = (t[:n] >= warmup_s) & (np.asarray(samples["mode"][:n]) == 2)
    e1 = np.asarray(samples["x1"][:n])[sel] - np.asarray(internals["m2_x1"][:n])[sel]
    e4 = np.asarray(samples["x4"][:n])[sel] - np.asarray(internals["m2_x4"][:n])[sel]
    p11 = np.asarray(internals["m2_P11"][:n])[sel]
    p14 = np.asarray(internals["m2_P14"][:n])[sel]
    p44 = np.asarray(internals["m2_P44"][:n])[sel]
    det = p11 * p44 - p14 * p14
    ok = det > 0
    if not np.any(ok):
        return {"nees": math.nan, "nees_x1": math.nan, "rms_e1": math.nan, "n": 0}
    q = (p44 * e1**2 - 2 * p14 * e1 * e4 + p11 * e4**2)[ok] / det[ok]
    return {"nees": float(np.mean(q) / 2.0), "nees_x1": float(np.mean(e1[ok]**2 / p11[ok])),
            "rms_e1": float(np.sqrt(np.mean(e1**2))), "n": int(np.sum(ok))}
