"""The quantized sensor: an encoder of resolution q on the measured error (SPEC §11).

    y(n) = q·round((x1(nτs) + w1(n))/q)   [rad]

The rounding rule: ties go up (toward +∞), y = q·⌊v/q + ½⌋ with the ratio r = v/q rounded
exactly (k = ⌊r⌋, then k + 1 when r − k ≥ ½; r − ⌊r⌋ is exact in floating point, so no
r just below a half is pushed over it the way a computed r + 0.5 can be). This is a mid-tread
quantizer whose decision thresholds (k + ½)·q are fixed lines, each belonging to the level
above: shifting the input by a whole step shifts the output by exactly that step, as for a
physical encoder's code boundaries. numpy's ``round`` (half to even) is not shift-invariant in
this sense: 0.5·q and 1.5·q would go to 0 and 2q. With measurement noise a tie has probability
zero; noise-free runs can meet one.

q = 0 is the ideal sensor of section 2: the value passes through unchanged.
"""

from __future__ import annotations

import math

__all__ = ["quantize"]


def quantize(value: float, step: float) -> float:
    """``value`` [rad] on a grid of ``step`` [rad] (ties up); ``step`` = 0 returns ``value``."""
    if step == 0.0:
        return value
    ratio = value / step
    if not math.isfinite(ratio):        # a step far below the value's resolution: nothing to round
        return value
    level = math.floor(ratio)
    if ratio - level >= 0.5:
        level += 1
    return level * step
