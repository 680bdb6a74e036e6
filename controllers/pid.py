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

Compiled step (``controllers.law.CompiledLaw``). The peers keep their whole per-sample state in
one float64 array s and their constants in p, laid out by :class:`PidLayout` (the shared PID,
slope and x̂4 entries first, each controller's own after them, the slope window last), and
step with compiled functions built from :func:`pid_observe`, :func:`pid_proportional` and
:func:`pid_hold`, which do in the same order the float operations of :class:`SlopeEstimator`,
:meth:`PidRealisation.proportional` (its fused kernels), :meth:`PidRealisation.integrate` and the
peers' conditional integration, so that ``step`` from Python and the runner's compiled loop give
the same bits as before.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from controllers._fma import lead_step1, lead_step2, window_push_dot
from controllers.linear import LinearDesign, _cascade_ss

__all__ = ["PidRealisation", "SlopeEstimator", "PidLayout", "pid_observe", "pid_proportional", "pid_hold",
           "py_max", "py_min"]


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
        self._store, self._iq = np.zeros(1), 0
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

    @property
    def q(self) -> float:
        """The integrator q(n) [ozf·in] (in a controller's state array once :meth:`bind` ran)."""
        return float(self._store[self._iq])

    @q.setter
    def q(self, value: float) -> None:
        self._store[self._iq] = value

    def bind(self, store: np.ndarray, index: int) -> None:
        """Keep q in ``store[index]`` (a compiled step's state array), starting from the current q."""
        store[index] = self.q
        self._store, self._iq = store, index

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


# --------------------------------------------------------------------------- the compiled step's pieces

# s: the shared state entries
S_X0, S_X1, S_VPREV, S_Q, S_X4, S_STUCK, S_N, S_LEVEL, S_UFF, S_COUNT, S_V = range(11)
# p: the shared constants (P_NLEAD = 0: v is computed outside and stored in s[S_V])
(P_NLEAD, P_C0, P_C1, P_D, P_A00, P_A01, P_A10, P_A11, P_B0, P_B1, P_G, P_STICK, P_ALPHA, P_UMAX,
 P_NWIN) = range(15)


class PidLayout:
    """The arrays (s, p) of a PID peer: the shared entries (``S_*``, ``P_*`` of this module), then
    ``n_own_state`` / ``n_own_params`` of the controller's own from :attr:`own_s` / :attr:`own_p`,
    then the slope window (N samples, oldest first) and its weights w (slope = Σ w_k·y_k)."""

    def __init__(self, pid: PidRealisation, slope: SlopeEstimator, stick_velocity: float, alpha_ref: float,
                 u_max: float, n_own_state: int, n_own_params: int) -> None:
        n = slope.n
        self.own_s, self.own_p = S_V + 1, P_NWIN + 1
        self.s = np.zeros(self.own_s + n_own_state + n)
        self.p = np.zeros(self.own_p + n_own_params + n)
        p = self.p
        consts = getattr(pid, "_consts", None)
        n_lead = pid.A.shape[0]
        if consts is not None and n_lead == 1:
            p[P_NLEAD] = 1.0
            p[P_C0], p[P_D], p[P_A00], p[P_B0] = consts
        elif consts is not None and n_lead == 2:
            p[P_NLEAD] = 2.0
            p[[P_C0, P_C1, P_D, P_A00, P_A01, P_A10, P_A11, P_B0, P_B1]] = consts
        p[P_G], p[P_STICK], p[P_ALPHA], p[P_UMAX], p[P_NWIN] = pid.g, stick_velocity, alpha_ref, u_max, float(n)
        p[p.shape[0] - n:] = slope._w
        self.compiled = p[P_NLEAD] != 0.0   # more lead states: numpy's products, not compiled


@njit(cache=True)
def py_max(a, b):
    """Python's ``max(a, b)`` (a unless b > a: NaN-propagating as Python's is)."""
    return b if b > a else a


@njit(cache=True)
def py_min(a, b):
    """Python's ``min(a, b)`` (a unless b < a)."""
    return b if b < a else a


@njit(cache=True)
def pid_observe(s, p, y):
    """:meth:`SlopeEstimator.update` with y(n), then the stick test and the x̂4 average
    (``_PidFrictionBase._observe``); returns ẏ̂ (NaN until the window is full)."""
    n = int(p[P_NWIN])
    ns, npr = s.shape[0], p.shape[0]
    ydot = window_push_dot(s[ns - n:], p[npr - n:], y)
    if s[S_COUNT] < n:
        s[S_COUNT] += 1.0
        if s[S_COUNT] < n:
            ydot = math.nan
    x4 = s[S_X4]
    stuck = math.isfinite(ydot) and abs(ydot + x4) < p[P_STICK]
    s[S_STUCK] = 1.0 if stuck else 0.0
    if stuck:
        s[S_X4] = x4 + p[P_ALPHA] * (-ydot - x4)
    return ydot


@njit(cache=True)
def pid_proportional(s, p, e):
    """:meth:`PidRealisation.proportional`: v(n) of the lead path, its state advanced."""
    nl = p[P_NLEAD]
    if nl == 1.0:
        v, x0 = lead_step1(s[S_X0], e, p[P_C0], p[P_D], p[P_A00], p[P_B0])
        s[S_X0] = x0
        return v
    if nl == 2.0:
        v, x0, x1 = lead_step2(s[S_X0], s[S_X1], e, p[P_C0], p[P_C1], p[P_D], p[P_A00], p[P_A01], p[P_A10],
                               p[P_A11], p[P_B0], p[P_B1])
        s[S_X0], s[S_X1] = x0, x1
        return v
    return s[S_V]    # computed outside (PidRealisation's numpy form)


@njit(cache=True)
def pid_hold(s, p, v, extra):
    """u = clip(−(v + q) + extra, ±u_max) with q integrated (Tustin) only when not clipped;
    returns the level (``_PidFrictionBase._hold``)."""
    q_before = s[S_Q]
    q = q_before + p[P_G] * (v + s[S_VPREV])
    s[S_VPREV] = v
    u = -(v + q) + extra
    u_max = p[P_UMAX]
    if abs(u) > u_max:
        q = q_before
        u = -(v + q_before) + extra
    s[S_Q] = q
    level = py_min(py_max(u, -u_max), u_max)
    s[S_LEVEL] = level
    s[S_N] += 1.0
    return level
