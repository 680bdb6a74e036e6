"""Shared pieces of the PID peers (``reset-pid``, ``observer-pid``): the PID realisation of the
``linear`` design with an explicit integrator, and a position-only velocity estimate.

PID realisation. ``design_linear(params, ωc, integral=True)`` gives C(z) = K · I(z) · Π lead_i(z)
with I the Tustin (prewarped at ωc) image of (s + ωz)/s = 1 + ωz/s. Realised as

    v(n) = K · Π lead_i(z) · e(n)                               (proportional + filtered derivative)
    q(n) = q(n−1) + g·(v(n) + v(n−1)),  g = ωz·tan(ωc·τs/2)/ωc   (Tustin of ωz/s, prewarped)
    u_pid(n) = −(v(n) + q(n))

so that, without resets, u_pid = −C(z)·e exactly (SISO sections commute); the integrator state q
[ozf·in] is explicit and can be reset. e is the measured error y [rad].

Velocity estimate. The least-squares slope of the last N measurements,
ẏ̂ = Σ(t−t̄)(y−ȳ)/Σ(t−t̄)², has standard deviation σ1·√(12/(N(N²−1)))/τs (55 µrad/s for N = 10
and Table 2-1). The shaft velocity is x2 = ẏ + x4, and while the shaft sticks ẏ = −x4: the
reference velocity x̂4 is the exponentially averaged −ẏ̂ over stuck samples.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from controllers._fma import lead_step1, lead_step2, window_push_dot
from controllers.linear import LinearDesign, _cascade_ss

__all__ = ["PidRealisation", "SlopeEstimator"]


@functools.lru_cache(maxsize=128)
def _lead_path(design: LinearDesign) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(A, B, C, D) of K·Π lead_i(z), B and C as vectors (cached per design object: the
    python-control realisation costs ~2 ms a run; the arrays are read-only)."""
    A, B, C, D = _cascade_ss(design.gain, design.sections[1:])
    B, C = B[:, 0].copy(), C[0].copy()
    for a in (A, B, C):
        a.flags.writeable = False
    return A, B, C, float(D[0, 0])


class PidRealisation:
    """u_pid = −C(z)·e of an ``integral=True`` :class:`~controllers.linear.LinearDesign`, with the
    integrator q [ozf·in] explicit (see the module docstring)."""

    def __init__(self, design: LinearDesign) -> None:
        if not design.integral:
            raise ValueError("PidRealisation needs an integral=True design")
        self.A, self.B, self.C, self.D = _lead_path(design)
        wc, ts = design.crossover_target_rad_s, design.params.sample_period
        self.g = design.lag_corner_rad_s * math.tan(wc * ts / 2.0) / wc
        self._x = np.zeros(self.A.shape[0])
        self.v_prev = 0.0
        self.q = 0.0
        n = self.A.shape[0]
        # compiled straight-line step for one or two lead states (the same bits as the numpy form)
        if n == 1:
            self._xs = (0.0,)
            self._consts = (float(self.C[0]), self.D, float(self.A[0, 0]), float(self.B[0]))
            self.proportional = self._proportional1
        elif n == 2:
            self._xs = (0.0, 0.0)
            self._consts = (float(self.C[0]), float(self.C[1]), self.D,
                            float(self.A[0, 0]), float(self.A[0, 1]), float(self.A[1, 0]),
                            float(self.A[1, 1]), float(self.B[0]), float(self.B[1]))
            self.proportional = self._proportional2

    def proportional(self, e: float) -> float:
        """Advance the lead path with e(n) [rad]; returns v(n) [ozf·in] (no integrator update).

        v(n) = C·x(n) + D·e(n), x(n+1) = A·x(n) + B·e(n). One or two lead states (every design
        of :func:`~controllers.linear.highest_crossover`) use a compiled kernel of
        :mod:`controllers._fma` that rounds as numpy does; more states use numpy.
        """
        v = float(self.C @ self._x) + self.D * e
        self._x = self.A @ self._x + self.B * e
        return v

    def _proportional1(self, e: float) -> float:
        v, x0 = lead_step1(self._xs[0], e, *self._consts)
        self._xs = (x0,)
        return v

    def _proportional2(self, e: float) -> float:
        x0, x1 = self._xs
        v, x0, x1 = lead_step2(x0, x1, e, *self._consts)
        self._xs = (x0, x1)
        return v

    @property
    def x(self) -> np.ndarray:
        """The lead-path state x(n) (a copy)."""
        return np.array(self._xs) if hasattr(self, "_xs") else self._x.copy()

    def integrate(self, v: float) -> float:
        """q(n) = q(n−1) + g·(v(n) + v(n−1)); returns q(n) [ozf·in]."""
        self.q += self.g * (v + self.v_prev)
        self.v_prev = v
        return self.q

    def reset_integrator(self) -> None:
        """q := 0 and forget v(n−1), so the next trapezoid starts afresh (a reset)."""
        self.q = 0.0
        self.v_prev = 0.0


class SlopeEstimator:
    """Least-squares slope ẏ̂ [rad/s] of the last ``n`` samples y(k) [rad] at period ``tau_s``."""

    def __init__(self, n: int, tau_s: float) -> None:
        if n < 2:
            raise ValueError(f"n must be >= 2 samples, got {n!r}")
        self.n, self.tau_s = n, tau_s
        k = np.arange(n) - (n - 1) / 2.0
        self._w = k / (float(k @ k) * tau_s)   # slope = Σ w_k y_k
        self._buf = np.zeros(n)                # the window, oldest first
        self._count = 0

    def update(self, y: float) -> float:
        """Add y(n); the slope over the window, NaN until it holds ``n`` samples.

        Σ w_k·y_k by a compiled kernel that rounds as ``w @ window`` does in numpy here.
        """
        s = window_push_dot(self._buf, self._w, float(y))
        if self._count < self.n:
            self._count += 1
            if self._count < self.n:
                return math.nan
        return s

    @property
    def std_per_sigma(self) -> float:
        """Slope standard deviation per unit measurement noise σ1 [1/s]."""
        return float(np.sqrt(self._w @ self._w))
