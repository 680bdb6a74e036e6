"""A consistent joint EKF on (x1, x4, k_c, k_s, d): solnic-modern's friction estimator.

The faithful design runs two filters: the mode-2 filter on (x̂1, x̂4), reset after each pulse
from the prediction Δc_p, and the friction filter on (k̂c, k̂s), updated from a Δc_e that is
computed from the already-reset mode-2 filter, so the prediction is used twice and the two
filters' errors are treated as independent although they are not (x̂4 absorbs a systematic
Δc error). Here one Gaussian carries all of it:

    z = (x1 [rad], x4 [rad/s], k_c [ozf·in], k_s [ozf·in], d [rad])

with d the (signed) motion of the last pulse. Between samples (x1, x4) follow the mode-2 model
(3-22), (4-11); k is constant except for the x5 drift while moving (5-15). At a pulse

    d = sign·(Δc_p(k̂) + b) + sign·H_b·(k − k̂) + n,   VAR[n] = v_w2 + Δc²·P(no motion)   (5-6), (5-9)

(b, v_w2 the friction-noise bias and variance of :mod:`controllers.solnic.noise_model`), d
replaces the previous motion state and x1 ← x1 + d. Every sample y = x1 + w1 then updates the
whole state, so k is identified from the samples through the correlation the pulse created —
the prediction enters once. Decisions: the posterior of d gives the significance test; "no
motion" is the pseudo-measurement d = 0 followed by the censored condition k_s ≥ peak torque;
constraints (k_s ≤ peak torque after motion, k_s ≥ k_c, k_c ≥ 0) condition the Gaussian on
half-planes (moment-matched truncation), never clip the mean.
"""

from __future__ import annotations

import math

import numpy as np

from controllers.solnic.filter_kernels import (joint_add_motion, joint_condition, joint_moved, joint_predict,
                                                joint_update, joint_valid, quadratic_form2)
from controllers.solnic.mode2_filter import mode2_transition

__all__ = ["JointFilter", "FrictionView"]

X1, X4, KC, KS, D = range(5)


class FrictionView:
    """The (k̂c, k̂s) block of a :class:`JointFilter` with the friction filter's read API."""

    def __init__(self, joint: "JointFilter") -> None:
        self._j = joint

    @property
    def kc(self) -> float:
        return self._j.z.item(KC)

    @property
    def ks(self) -> float:
        return self._j.z.item(KS)

    @property
    def P(self) -> np.ndarray:
        return self._j.P[KC:KS + 1, KC:KS + 1].copy()

    def prob_no_motion(self, peak_torque: float) -> float:
        """Prob(k_s ≥ peak torque) under the marginal of k_s."""
        sd = math.sqrt(max(self._j.P.item(KS, KS), 0.0))
        if sd == 0:
            return 1.0 if self.ks >= peak_torque else 0.0
        return 0.5 * math.erfc((peak_torque - self.ks) / (sd * math.sqrt(2.0)))

    def motion_variance(self, H_b: np.ndarray) -> float:
        """H_b P_kk H_b' [rad²] (5-1), (5-10)."""
        return quadratic_form2(np.asarray(H_b, dtype=float), self._j.P[KC:KS + 1, KC:KS + 1])

    def time_variance(self, H_tb: np.ndarray) -> float:
        """H_tb P_kk H_tb' [s²] for t_max (5-11)."""
        return quadratic_form2(np.asarray(H_tb, dtype=float), self._j.P[KC:KS + 1, KC:KS + 1])

    def propagate(self, moving_time: float, sigma5_sq: float) -> None:
        """P_kk += σ5²·T_m·[[1, 1], [1, 1]]: the common x5 drift while moving (5-15)."""
        if moving_time > 0 and sigma5_sq > 0:
            P, q = self._j.P, sigma5_sq * moving_time      # the block's four entries, each += q
            P[KC, KC] += q
            P[KC, KS] += q
            P[KS, KC] += q
            P[KS, KS] += q

    n_updates = property(lambda self: self._j.n_motion_updates)


class JointFilter:
    """Gaussian on (x1, x4, k_c, k_s, d) with the mode-2 filter's API for (x1, x4).

    Parameters
    ----------
    tau4, sigma4_sq, sigma1 : float
        τ4 [s], σ4² [rad²/s³], σ1 [rad] as in :class:`~controllers.solnic.mode2_filter.Mode2Filter`.
    x0, P0 : array_like
        Prior of (x1, x4) and its 2×2 covariance.
    k0, Pk0 : array_like
        Prior of (k_c, k_s) [ozf·in] and its 2×2 covariance.
    u_max : float
        Upper bound of k_s [ozf·in].
    """

    def __init__(self, tau4: float, sigma4_sq: float, sigma1: float, x0, P0, k0, Pk0,
                 u_max: float, t0: float = 0.0) -> None:
        if not (tau4 > 0 and sigma4_sq >= 0 and sigma1 > 0):
            raise ValueError("need tau4 > 0, sigma4_sq >= 0, sigma1 > 0")
        self.tau4, self.sigma4_sq, self.R = float(tau4), float(sigma4_sq), float(sigma1) ** 2
        self.z = np.zeros(5)
        self.z[:2] = np.asarray(x0, dtype=float).reshape(2)
        self.z[KC:KS + 1] = np.asarray(k0, dtype=float).reshape(2)
        self.P = np.zeros((5, 5))
        self.P[:2, :2] = np.asarray(P0, dtype=float).reshape(2, 2)
        self.P[KC:KS + 1, KC:KS + 1] = np.asarray(Pk0, dtype=float).reshape(2, 2)
        self.u_max = float(u_max)
        self.t = float(t0)
        self._cache: dict[float, tuple[float, float, float, float, float]] = {}
        self.friction = FrictionView(self)
        self.n_motion_updates = 0
        self.motion_prior = (math.nan, math.nan)
        self._snapshot: tuple[np.ndarray, np.ndarray, float] | None = None
        self._since: list[tuple[float, float]] = []      # samples since the last pulse

    # -- the mode-2 filter's API --------------------------------------------------------
    x1 = property(lambda self: self.z.item(X1))
    x4 = property(lambda self: self.z.item(X4))
    p11 = property(lambda self: self.P.item(X1, X1))
    p14 = property(lambda self: self.P.item(X1, X4))
    p44 = property(lambda self: self.P.item(X4, X4))

    @property
    def x(self) -> np.ndarray:
        return self.z[:2].copy()

    @property
    def P2(self) -> np.ndarray:
        return self.P[:2, :2].copy()

    def drift_std(self) -> float:
        return math.sqrt(max(self.P.item(X4, X4), 0.0))

    def predict(self, t: float) -> None:
        """(x1, x4) over t − self.t with Φ (3-22) and COV[N] (4-11); k and d constant."""
        h = t - self.t
        if h <= 0:
            if h < -1e-12:
                raise ValueError(f"cannot predict backwards: t={t!r} < filter time {self.t!r}")
            return
        hit = self._cache.get(h)
        if hit is None:
            Phi, Q = mode2_transition(h, self.tau4, self.sigma4_sq)
            hit = (float(Phi[0, 1]), float(Phi[1, 1]), float(Q[0, 0]), float(Q[0, 1]), float(Q[1, 1]))
            if len(self._cache) >= 256:
                self._cache.clear()
            self._cache[h] = hit
        joint_predict(self.z, self.P, *hit)
        self.t = float(t)

    def update(self, y: float) -> float:
        """y = x1 + w1: the whole state is corrected (k through its correlation with x1)."""
        y = float(y)
        if self._snapshot is not None:
            self._since.append((self.t, y))
        z = self.z
        innovation = joint_update(z, self.P, self.R, y)
        kc = z.item(KC)
        if not 0.0 <= kc <= z.item(KS) < self.u_max:  # the sample pushed k out of the valid set
            self._valid()
        return innovation

    def moments(self) -> tuple[float, float, float, float, float]:
        """(x̂1, x̂4, P11, P14, P44) as floats."""
        z, P = self.z, self.P
        return z.item(X1), z.item(X4), P.item(X1, X1), P.item(X1, X4), P.item(X4, X4)

    # -- pulses --------------------------------------------------------------------------
    def add_motion(self, sign: int, delta_c: float, H_b: np.ndarray, noise_var: float,
                   max_correction: float = math.inf) -> None:
        """A pulse: d = sign·(Δc + H_b(k − k̂)) + n replaces the old d; x1 ← x1 + d.

        ``max_correction`` [ozf·in] limits large corrections (section 5.3) the conservative
        way, by a fictitious extra variance of n: a residual of the whole Δc in d moves no
        component of k̂ by more than it (more variance only removes information).
        """
        self._snapshot = (self.z.copy(), self.P.copy(), self.t)
        self._since = []
        h = np.zeros(5)
        h[KC:KS + 1] = sign * np.asarray(H_b, dtype=float)
        # P[d, :] = P h, VAR[d] = h'P h + noise_var, at least max|P_kd,i|·|Δc|/max_correction
        # (|Δk_i| ≈ |P_kd,i|·|Δc|/VAR[d] ≤ max_correction); then x1 ← x1 + d: J P J' with
        # J = I + e_x1 e_d' (compiled, :func:`~controllers.solnic.filter_kernels.joint_add_motion`)
        var_d = joint_add_motion(self.z, self.P, h, float(sign * delta_c), float(noise_var),
                                 float(max_correction), abs(float(delta_c)))
        self.motion_prior = (self.z.item(D), var_d)

    @property
    def motion_mean(self) -> float:
        return float(self.z[D])

    @property
    def motion_var(self) -> float:
        return float(self.P[D, D])

    def motion_likelihood(self) -> tuple[float, float]:
        """(m, R): the samples' own evidence about d, its prior divided out (R = inf: none)."""
        prior_mean, prior_var = self.motion_prior
        post_var = self.motion_var
        if not (post_var > 0 and prior_var > 0):
            return math.nan, math.inf
        info = 1.0 / post_var - 1.0 / prior_var
        if not info > 1e-12 / post_var:
            return math.nan, math.inf
        R = 1.0 / info
        return R * (self.motion_mean / post_var - prior_mean / prior_var), R

    def no_motion(self, peak_torque: float, censor: bool = True) -> None:
        """The shaft did not move: the pulse is undone and its samples replayed without it.

        "No motion" is not the linear pseudo-measurement d = 0 (that would move k̂ along the
        quasipartials, an inference the linearisation cannot carry across the Δc → 0
        discontinuity); its information about k is the censored k_s ≥ peak torque, applied
        as a half-plane condition when ``censor``.
        """
        if self._snapshot is not None:
            t_now = self.t
            z, P, t0 = self._snapshot
            self.z, self.P, self.t = z.copy(), P.copy(), t0
            samples, self._snapshot, self._since = self._since, None, []
            for t_i, y_i in samples:
                self.predict(t_i)
                self.update(y_i)
            self.predict(t_now)
        self.P[D, :] = 0.0
        self.P[:, D] = 0.0
        self.z[D] = 0.0
        if censor:
            c = np.zeros(5)
            c[KS] = -1.0
            self.condition(c, -peak_torque)
        self._valid()

    def moved(self, peak_torque: float) -> None:
        """Motion occurred: k_s < peak torque, and always k_s ≥ k_c ≥ 0, on the distribution."""
        self.n_motion_updates += 1
        joint_moved(self.z, self.P, float(peak_torque), self.u_max)     # compiled: the two steps below
        # c = e_ks: self.condition(c, min(peak_torque, self.u_max) * (1.0 - 1e-6)); self._valid()

    def set_friction(self, mean, cov) -> None:
        """Replace the (k_c, k_s) block by an outside posterior (the grid's moments), with no
        correlation to (x1, x4, d): the samples then no longer update k here."""
        self.z[KC:KS + 1] = np.asarray(mean, dtype=float).reshape(2)
        self.P[KC:KS + 1, :] = 0.0
        self.P[:, KC:KS + 1] = 0.0
        self.P[KC:KS + 1, KC:KS + 1] = np.asarray(cov, dtype=float).reshape(2, 2)

    def _valid(self) -> None:
        """k_c ≤ k_s, k_c ≥ 0 and k_s < u_max as conditions on the distribution.

        Compiled (:func:`~controllers.solnic.filter_kernels.joint_valid`, one call): the
        conditions c·z ≤ b of :meth:`condition` with (c, b) = (e_ks, u_max(1 − 1e-6)),
        (e_kc − e_ks, 0), (−e_kc, 0) in this order, then the round-off guard on the means
        (the truncated means lie inside the half-planes) k_c ← min(max(k_c, 0), u_max(1 − 1e-6)),
        k_s ← min(max(k_s, k_c), u_max(1 − 1e-6)).
        """
        joint_valid(self.z, self.P, self.u_max)

    def condition(self, c: np.ndarray, bound: float, always: bool = True) -> None:
        """Condition the Gaussian on c·z ≤ ``bound`` (moment-matched truncation).

        With s = c·z ~ N(m, v), α = (bound − m)/√v, λ = φ(α)/Φ(α): E[s] = m − √v·λ,
        VAR[s] = v(1 − αλ − λ²); z and P follow by the regression of z on s.

        Applied at every update (``always``, the default), the same constraint conditions the
        moment-matched Gaussian again each time and so counts its information more than once
        (the mean ratchets away from the bound). Conditioning only a mean that lies outside
        (``always=False``) avoids that, but measured worse: on thesis seed 100 the joint
        filter's k̂ then wandered and the run diverged (peak 2.1 mrad).
        """
        # compiled (:func:`~controllers.solnic.filter_kernels.joint_condition`): the arithmetic of
        # :func:`~controllers.solnic.truncation.condition_half_plane`, z and P updated in place
        joint_condition(self.z, self.P, np.asarray(c, dtype=float), float(bound), bool(always))
