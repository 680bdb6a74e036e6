"""A controller whose whole step is a fixed linear law: the runner may compile its loop.

A :class:`LinearLaw` says: at every sample instant n·τs, with y(n) the measurement,

    v(n) = C·x(n) + D·y(n),    x(n+1) = A·x(n) + B·y(n)                  (the realization of C(z))
    u(t) = clip(−v(n) + A_d·sq(f_d·t + φ), ±u_max),   t ∈ [n·τs, (n+1)·τs)  (LINEAR drive)

with sq(θ) = +1 for frac(θ) < ½ and −1 otherwise (no dither when A_d = 0). A controller that
returns one from :meth:`Controller.linear_law` promises that its ``step`` computes exactly
this, with :func:`plant.linear_drive.compensator_step` and
:func:`plant.linear_drive.square_wave_segments` (the same compiled code the fast path runs). The
runner then runs the closed loop in one compiled call (the plant family's ``linear_law_loop``,
e.g. :mod:`plant.multimode.law_loop`) instead of calling ``step`` at every sample, with
bit-identical results (tested); the controller's own state is not advanced then, only
its ``summary`` is read afterwards.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LinearLaw"]


@dataclass(frozen=True)
class LinearLaw:
    """A single-input single-output compensator plus an optional square-wave dither.

    Attributes
    ----------
    A, B, C, D : ndarray
        Realization of C(z): shapes (n, n), (n, 1), (1, n), (1, 1); y in rad, v in ozf·in.
    u_max : float
        Clip bound [ozf·in].
    dither_amplitude, dither_frequency, dither_phase : float
        A_d [ozf·in] (0: none), f_d [Hz], φ [cycles].
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    u_max: float
    dither_amplitude: float = 0.0
    dither_frequency: float = 1.0
    dither_phase: float = 0.0
