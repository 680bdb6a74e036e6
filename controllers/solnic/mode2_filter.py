"""Linear discrete Kalman filter on (x1, x4) while the shaft is stuck (mode 2), section 5.3.

Model in mode 2 (x2 ≡ 0)::

    ẋ1 = −x4                     x1 = c − r, shaft error [rad]
    ẋ4 = −x4/τ4 + w4             x4 = ṙ, commanded velocity [rad/s], E[w4 w4'] = σ4²·δ
    y(n) = x1(n·τs) + w1(n)      w1 ~ N(0, σ1²) [rad]

Over a step h the exact discretisation is x(t+h) = Φ(h) x(t) + N with (3-22) and (4-11)::

    Φ(h) = [[1, −τ4(1 − e^(−h/τ4))], [0, e^(−h/τ4)]]
    COV[N] = σ4² ∫₀ʰ g(v) g(v)' dv,   g(v) = (−τ4(1 − e^(−v/τ4)), e^(−v/τ4))

evaluated in closed form without cancellation. (The text's (4-11) keeps only the leading terms
and prints E11·h/3 for h³/3; SPEC §9.)

The filter is a plain textbook filter (predict, update). For (5-14) it also carries the
cross-covariance of its error with the error of one frozen earlier estimate x̂1(t_a) (a
"delayed state", :meth:`Mode2Filter.set_anchor`), so the variance of
Δc_e = x̂1(t_b) − x̂1(t_a) + x̂4(t_b)(t_b − t_a) is exact. What is solnic-specific lives in the
controller: samples are used only past t_max (5-11), and after each correction the estimate of
x1 and its variance are reset from the Δc prediction with :meth:`Mode2Filter.add_motion`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["Mode2Filter", "mode2_transition"]


def _e1(x: float) -> float:
    """1 − e^(−x) without cancellation."""
    return -math.expm1(-x)


def _f3(x: float) -> float:
    """x − 2(1 − e^(−x)) + (1 − e^(−2x))/2 = x³/3 − x⁴/4 + …, without cancellation."""
    if x < 0.1:
        # Σ_{n≥3} (−1)^(n+1) (2^(n−1) − 2) xⁿ / n!
        total, term = 0.0, x * x / 2.0          # term = xⁿ/n! at n = 2
        for n in range(3, 30):
            term *= x / n
            total += (-1) ** (n + 1) * (2.0 ** (n - 1) - 2.0) * term
            if abs(term) * 2.0 ** n < 1e-18 * abs(total):
                break
        return total
    return x - 2.0 * _e1(x) + _e1(2.0 * x) / 2.0


def mode2_transition(h: float, tau4: float, sigma4_sq: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ(h) (3-22) and the process-noise covariance (4-11) of (x1, x4) over h seconds."""
    if h < 0:
        raise ValueError(f"h must be >= 0, got {h!r}")
    b = 1.0 / tau4
    x = b * h
    e = _e1(x)
    Phi = np.array([[1.0, -tau4 * e], [0.0, 1.0 - e]])
    q11 = sigma4_sq * tau4**3 * _f3(x)                   # ≈ σ4² h³/3
    q14 = -sigma4_sq * tau4**2 * e * e / 2.0             # ≈ −σ4² h²/2
    q44 = sigma4_sq * tau4 * _e1(2.0 * x) / 2.0          # ≈ σ4² h
    Q = np.array([[q11, q14], [q14, q44]])
    return Phi, Q


class Mode2Filter:
    """Kalman filter on (x1, x4), time-stamped.

    The 2×2 algebra is written out in Python floats (a numpy 2×2 product costs ~1 µs, the
    filter runs at every sample); :attr:`x` and :attr:`P` return numpy copies.

    Parameters
    ----------
    tau4 : float
        τ4 [s].
    sigma4_sq : float
        σ4², intensity of w4 [rad²/s³].
    sigma1 : float
        σ1, measurement-noise std [rad].
    x0 : array_like
        Initial (x̂1 [rad], x̂4 [rad/s]).
    P0 : array_like
        Initial 2×2 covariance.
    t0 : float
        Time of the initial estimate [s].
    """

    def __init__(self, tau4: float, sigma4_sq: float, sigma1: float, x0, P0, t0: float = 0.0) -> None:
        if not tau4 > 0:
            raise ValueError(f"tau4 must be > 0, got {tau4!r}")
        if not sigma4_sq >= 0:
            raise ValueError(f"sigma4_sq must be >= 0, got {sigma4_sq!r}")
        if not sigma1 > 0:
            raise ValueError(f"sigma1 must be > 0, got {sigma1!r}")
        self.tau4 = float(tau4)
        self.sigma4_sq = float(sigma4_sq)
        self.R = float(sigma1) ** 2
        x = np.array(x0, dtype=float).reshape(2)
        P = np.array(P0, dtype=float).reshape(2, 2)
        self.x1, self.x4 = float(x[0]), float(x[1])
        self.p11, self.p14, self.p44 = float(P[0, 0]), float(0.5 * (P[0, 1] + P[1, 0])), float(P[1, 1])
        self.t = float(t0)
        self._cache: dict[float, tuple[float, float, float, float, float, float]] = {}
        self._anchor: tuple[float, float] | None = None   # COV[e(t), e1(t_a)]
        self.anchor_var = math.nan                  # VAR[e1(t_a)]
        self.anchor_t = math.nan
        self.motion_mean = math.nan                 # d̂, estimate of the last correction's Δc
        self.motion_var = math.nan                  # VAR[e_d]
        self._motion: tuple[float, float] | None = None   # COV[e(t), e_d]
        self.motion_prior = (math.nan, math.nan)    # (Δc_p,cond, its variance)

    # -- numpy views ------------------------------------------------------------------
    @property
    def x(self) -> np.ndarray:
        """(x̂1, x̂4) as a new array."""
        return np.array([self.x1, self.x4])

    @property
    def P(self) -> np.ndarray:
        """The 2×2 covariance as a new array."""
        return np.array([[self.p11, self.p14], [self.p14, self.p44]])

    @property
    def anchor_cov(self) -> np.ndarray | None:
        """COV[e(t), e1(t_a)], shape (2,), or None before :meth:`set_anchor`."""
        return None if self._anchor is None else np.array(self._anchor)

    @property
    def motion_cov(self) -> np.ndarray | None:
        """COV[e(t), e_d], shape (2,), or None before :meth:`add_motion`."""
        return None if self._motion is None else np.array(self._motion)

    # -- time update ------------------------------------------------------------------
    def _transition(self, h: float) -> tuple[float, float, float, float, float, float]:
        """(Φ12, Φ22, q11, q14, q44, 0) of :func:`mode2_transition`, memoised by h."""
        hit = self._cache.get(h)
        if hit is None:
            Phi, Q = mode2_transition(h, self.tau4, self.sigma4_sq)
            hit = (float(Phi[0, 1]), float(Phi[1, 1]), float(Q[0, 0]), float(Q[0, 1]), float(Q[1, 1]), 0.0)
            if len(self._cache) >= 256:
                self._cache.clear()
            self._cache[h] = hit
        return hit

    def _propagated(self, h: float) -> tuple[float, float, float, float, float]:
        f12, f22, q11, q14, q44, _ = self._transition(h)
        x1 = self.x1 + f12 * self.x4
        x4 = f22 * self.x4
        # Φ P Φ' + Q with Φ = [[1, f12], [0, f22]]
        a11 = self.p11 + f12 * self.p14
        a12 = self.p14 + f12 * self.p44
        p11 = a11 + f12 * a12 + q11
        p14 = f22 * a12 + q14
        p44 = f22 * f22 * self.p44 + q44
        return x1, x4, p11, p14, p44

    def predicted(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(x̂, P) propagated to time ``t`` ≥ self.t, without changing the filter."""
        h = t - self.t
        if h < -1e-12:
            raise ValueError(f"cannot predict backwards: t={t!r} < filter time {self.t!r}")
        if h <= 0:
            return self.x, self.P
        x1, x4, p11, p14, p44 = self._propagated(h)
        return np.array([x1, x4]), np.array([[p11, p14], [p14, p44]])

    def predict(self, t: float) -> None:
        """Time update to ``t``:  x̂ = Φx̂,  P = ΦPΦ' + COV[N]."""
        h = t - self.t
        if h < -1e-12:
            raise ValueError(f"cannot predict backwards: t={t!r} < filter time {self.t!r}")
        if h <= 0:
            return
        hit = self._cache.get(h)
        f12, f22, q11, q14, q44, _ = hit if hit is not None else self._transition(h)
        if self._anchor is not None:
            c0, c1 = self._anchor
            self._anchor = (c0 + f12 * c1, f22 * c1)
        if self._motion is not None:
            m0, m1 = self._motion
            self._motion = (m0 + f12 * m1, f22 * m1)
        # :meth:`_propagated` written out (this runs at every sample)
        x4, p14, p44 = self.x4, self.p14, self.p44
        self.x1 += f12 * x4
        self.x4 = f22 * x4
        a11 = self.p11 + f12 * p14
        a12 = p14 + f12 * p44
        self.p11 = a11 + f12 * a12 + q11
        self.p14 = f22 * a12 + q14
        self.p44 = f22 * f22 * p44 + q44
        self.t = float(t)

    def set_anchor(self) -> None:
        """Freeze x̂1 now as x̂1(t_a) and start tracking COV[e(t), e1(t_a)]."""
        self._anchor = (self.p11, self.p14)
        self.anchor_var = self.p11
        self.anchor_t = self.t

    def motion_variance(self, t_b: float | None = None) -> float:
        """Exact VAR of the error of Δc_e = x̂1(t_b) − x̂1(t_a) + x̂4(t_b)(t_b − t_a)  (5-14).

        With a = (1, t_b − t_a, −1) on (e1(t_b), e4(t_b), e1(t_a)): a'Σa, including the
        covariances of the current errors with the frozen one.
        """
        if self._anchor is None:
            raise ValueError("no anchor: call set_anchor() at the pulse start")
        dt = (self.t if t_b is None else t_b) - self.anchor_t
        c0, c1 = self._anchor
        return (self.p11 + 2 * dt * self.p14 + dt * dt * self.p44 + self.anchor_var
                - 2.0 * (c0 + dt * c1))

    def update(self, y: float) -> float:
        """Measurement update with y = x1 + w1 at the filter's time; returns the innovation."""
        innovation = float(y) - self.x1
        p11, p14, p44 = self.p11, self.p14, self.p44
        S = p11 + self.R
        k1, k4 = p11 / S, p14 / S
        if self._anchor is not None:                                      # (I − KH)·c
            c0, c1 = self._anchor
            self._anchor = (c0 - k1 * c0, c1 - k4 * c0)
        if self._motion is not None:                                      # augmented state d
            m0, m1 = self._motion
            k_d = m0 / S
            self.motion_mean += k_d * innovation
            self.motion_var -= k_d * m0
            self._motion = (m0 - k1 * m0, m1 - k4 * m0)
        self.x1 += k1 * innovation
        self.x4 += k4 * innovation
        self.p11 = p11 - k1 * p11
        self.p14 = p14 - k1 * p14
        self.p44 = p44 - k4 * p14
        return innovation

    def add_motion(self, delta_c: float, variance: float) -> None:
        """Reset after a correction: x̂1 += Δc_p,cond (5-6), VAR[x̂1] += (5-9).

        The motion's prediction error is independent of the errors in (x̂1, x̂4), so only
        P11 grows. The motion itself is also carried as an augmented constant state d with
        prior (Δc_p,cond, variance), so that :meth:`motion_likelihood` can return what the
        samples alone say about it.
        """
        if not variance >= 0:
            raise ValueError(f"variance must be >= 0, got {variance!r}")
        self.x1 += float(delta_c)
        self.p11 += float(variance)
        self.motion_mean = float(delta_c)
        self.motion_var = float(variance)
        self._motion = (float(variance), 0.0)
        self.motion_prior = (float(delta_c), float(variance))

    def motion_likelihood(self) -> tuple[float, float]:
        """(m, R): the samples' own Gaussian evidence about the last Δc, prior removed.

        The posterior of d is the product of the prior N(Δc_p, V) and the data likelihood
        N(m, R); so 1/R = 1/VAR[d] − 1/V and m/R = d̂/VAR[d] − Δc_p/V. R = inf when the
        samples carry no information (or the prior variance is zero).
        """
        prior_mean, prior_var = self.motion_prior
        if not (self.motion_var > 0 and prior_var > 0):
            return math.nan, math.inf
        info = 1.0 / self.motion_var - 1.0 / prior_var
        if not info > 1e-12 / self.motion_var:
            return math.nan, math.inf
        R = 1.0 / info
        return R * (self.motion_mean / self.motion_var - prior_mean / prior_var), R

    def moments(self) -> tuple[float, float, float, float, float]:
        """(x̂1, x̂4, P11, P14, P44) as floats."""
        return self.x1, self.x4, self.p11, self.p14, self.p44

    def drift_std(self) -> float:
        """√P44, the std of x̂4 [rad/s]."""
        return math.sqrt(max(self.p44, 0.0))
