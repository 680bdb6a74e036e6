"""Modified Kalman filter on the friction estimates (k̂c, k̂s), (5-1)–(5-18).

The state is k = (k̂c, k̂s) [ozf·in] with covariance P_b (5-5). The scalar "observation" of one
correction cycle is the measured motion Δc_e (5-13) with variance VAR[Δc_e] (5-14); the
prediction is Δc_p,cond (5-6) from the controller's plant model and the observation matrix is
the row of quasipartials H_b (5-2). The four modifications of section 5.2 are:

1. the prediction comes from the nonlinear model (not from H_b·k);
2. H_b holds quasipartials;
3. full-weight corrections but the covariance reduction is scaled by a = 0.5 (5-18);
4. nonlinear constraints (section 5.3):

   * motion occurred, so k̂s cannot exceed the largest torque applied in that cycle: when the
     corrected k̂s would, the quasipartial of k̂s is shrunk and the correction recomputed
     (halving it, at most ``max_shrinks`` times; a final clip is the last resort);
   * k̂s is never reduced below k̂c (it is raised to k̂c) and k̂c ≥ 0. Erratum/caveat: the
     text clips the estimate and leaves P_b as it was, so after a clip P_b describes an
     estimate the filter no longer holds (k̂s can sit pinned at k̂c with a P_b that says it
     is free). ``constraints="distribution"`` instead conditions N(k̂, P_b) on each
     half-plane (moment-matched truncated Gaussian: :meth:`FrictionFilter.condition`), which
     moves the mean inside and shrinks P_b along the constraint normal;
   * large corrections are limited without falsifying P by a fictitiously large variance in
     place of VAR[Δc_e] in (5-16), chosen so that no component moves by more than
     ``max_correction_fraction``·k̂s in one update.

Between updates the estimates drift with x5, which moves only while the shaft moves
(SPEC §2: x5 is frozen in mode 2). (5-15) with the σ5 block of (4-10): both k̂c and k̂s carry
the same x5, so COV[N] = σ5²·h_moving·[[1, 1], [1, 1]]. Φ = I: the decay e^(−h/τ5) of x5
would pull k toward the unknown mean k̄ and differs from 1 by ~h/τ5 ≈ 5e-6 per cycle.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controllers.solnic.filter_kernels import (friction_covariance, friction_gain,
                                                friction_update_clip, quadratic_form2)
from controllers.solnic.truncation import condition_half_plane

__all__ = ["FrictionFilter", "FrictionUpdate"]


@dataclass(frozen=True)
class FrictionUpdate:
    """What one call of :meth:`FrictionFilter.update` did."""

    residual: float          # Δc_e − Δc_p,cond [rad]
    innovation_var: float    # H P H' + R used [rad²]
    fictitious_var: float    # R actually used in (5-16) [rad²]
    shrinks: int             # number of k̂s-quasipartial reductions
    clipped: bool            # a final clip to a constraint was needed
    delta: tuple[float, float]   # applied change of (k̂c, k̂s)


class FrictionFilter:
    """(k̂c, k̂s) and P_b with the modified update (5-16)–(5-18).

    Parameters
    ----------
    kc0, ks0 : float
        Initial estimates [ozf·in].
    P0 : array_like
        Initial 2×2 covariance, order (k̂c, k̂s).
    u_max : float
        Upper bound for k̂s (a valid plant has k̂s < u_max).
    a : float
        Covariance-reduction weight of (5-18); 0.5 in the text.
    max_correction_fraction : float
        Largest change of either estimate in one update, as a fraction of k̂s (inf: no limit).
    max_shrinks : int
        How many times the k̂s quasipartial may be halved (section 5.3).
    """

    def __init__(self, kc0: float, ks0: float, P0, u_max: float, *, a: float = 0.5,
                 max_correction_fraction: float = 0.25, max_shrinks: int = 10,
                 constraints: str = "clip") -> None:
        if not 0 < a <= 1:
            raise ValueError(f"a must be in (0, 1], got {a!r}")
        if not max_correction_fraction > 0:
            raise ValueError(f"max_correction_fraction must be > 0, got {max_correction_fraction!r}")
        if not 0 <= kc0 <= ks0 < u_max:
            raise ValueError(f"need 0 <= kc0 <= ks0 < u_max, got kc0={kc0!r}, ks0={ks0!r}")
        self.k = np.array([kc0, ks0], dtype=float)
        self.P = np.array(P0, dtype=float).reshape(2, 2)
        self.u_max = float(u_max)
        self.a = float(a)
        self.max_correction_fraction = float(max_correction_fraction)
        self.max_shrinks = int(max_shrinks)
        if constraints not in ("clip", "distribution"):
            raise ValueError(f"constraints must be 'clip' or 'distribution', got {constraints!r}")
        self.constraints = constraints
        self.n_updates = 0

    @property
    def kc(self) -> float:
        return self.k.item(0)

    @property
    def ks(self) -> float:
        return self.k.item(1)

    def propagate(self, moving_time: float, sigma5_sq: float) -> None:
        """P = Φ P Φ' + COV[N] with Φ = I and the common x5 drift over ``moving_time``  (5-15)."""
        if moving_time > 0 and sigma5_sq > 0:
            self.P = self.P + sigma5_sq * moving_time

    def prob_no_motion(self, peak_torque: float) -> float:
        """Prob(Δc = 0) = Prob(ks ≥ peak torque) under k̂s ~ N(k̂s, P_ss)  (used in (5-9))."""
        sd = math.sqrt(max(self.P.item(1, 1), 0.0))
        if sd == 0:
            return 1.0 if self.ks >= peak_torque else 0.0
        return 0.5 * math.erfc((peak_torque - self.ks) / (sd * math.sqrt(2.0)))

    def motion_variance(self, H_b: np.ndarray) -> float:
        """H_b P_b H_b', the conditional variance of Δc_p (5-1), (5-10) [rad²]."""
        return quadratic_form2(np.asarray(H_b, dtype=float), self.P)

    def time_variance(self, H_tb: np.ndarray) -> float:
        """H_tb P_b H_tb' [s²], for t_max (5-11)."""
        return quadratic_form2(np.asarray(H_tb, dtype=float), self.P)

    def condition(self, c: np.ndarray, bound: float, always: bool = True) -> None:
        """Condition N(k̂, P_b) on c·k ≤ ``bound``: moment-matched truncated Gaussian.

        With z = c·k ~ N(m, v) and α = (bound − m)/√v, λ = φ(α)/Φ(α): E[z] = m − √v·λ,
        VAR[z] = v(1 − αλ − λ²); k̂ and P_b follow by the linear regression of k on z.

        Applied at every update (``always``, the default), the same constraint conditions the
        moment-matched Gaussian again each time and so counts its information more than once
        (the mean ratchets away from the bound). Conditioning only a mean that lies outside
        (``always=False``) avoids that, but measured worse: on thesis seed 100 the joint
        filter's k̂ then wandered and the run diverged (peak 2.1 mrad).
        """
        out = condition_half_plane(self.k, self.P, c, bound, always)
        if out is not None:
            self.k, self.P = out

    def _apply_distribution_constraints(self, peak_torque: float) -> None:
        """k_s ≤ peak torque (motion occurred), k_s ≥ k_c, k_c ≥ 0 as conditions on N(k̂, P_b)."""
        ks_cap = min(peak_torque, self.u_max) * (1.0 - 1e-6)
        self.condition(np.array([0.0, 1.0]), ks_cap)
        self.condition(np.array([1.0, -1.0]), 0.0)
        self.condition(np.array([-1.0, 0.0]), 0.0)
        # the truncated means lie inside each half-plane; a last guard for round-off only
        kc = min(max(self.k[0], 0.0), ks_cap)
        self.k = np.array([kc, min(max(self.k[1], kc), ks_cap)])

    def update(self, H_b, residual: float, meas_var: float, peak_torque: float) -> FrictionUpdate:
        """One modified-Kalman correction (5-16)–(5-18) with the section-5.3 constraints.

        Parameters
        ----------
        H_b : array_like
            Quasipartials (∂Δc/∂k̂c, ∂Δc/∂k̂s) of the motion in the *direction of the pulse*
            (the caller flips signs so that motion is positive).
        residual : float
            Δc_e − Δc_p,cond, in the same direction convention [rad].
        meas_var : float
            VAR[Δc_e] (5-14) [rad²].
        peak_torque : float
            The largest torque applied in the cycle; k̂s must not end above it.
        """
        H = np.array(H_b, dtype=float).reshape(2)
        h0, h1 = H.item(0), H.item(1)
        residual, meas_var = float(residual), float(meas_var)
        if not (math.isfinite(h0) and math.isfinite(h1) and math.isfinite(residual) and meas_var >= 0):
            raise ValueError("H_b, residual and meas_var must be finite, meas_var >= 0")
        ks_cap = min(peak_torque * (1.0 - 1e-6), self.u_max * (1.0 - 1e-9))
        limit = self.max_correction_fraction * max(self.ks, 1e-12)
        if self.constraints == "distribution":
            K0, K1, S, R_used = friction_gain(self.P, h0, h1, residual, meas_var, limit)
            before = self.k.copy()
            self.k = self.k + np.array([K0, K1]) * residual                 # (5-17)
            self.P = friction_covariance(self.P, K0, K1, h0, h1, self.a)    # (5-18)
            self._apply_distribution_constraints(peak_torque)
            self.n_updates += 1
            delta = (float(self.k[0] - before[0]), float(self.k[1] - before[1]))
            return FrictionUpdate(residual=residual, innovation_var=float(S),
                                  fictitious_var=float(R_used), shrinks=0, clipped=False, delta=delta)
        # shrink ∂Δc/∂k̂s while the raise of k̂s is fallacious, then (5-18) and the clips
        k_new, P_new, S, R_used, shrinks, clipped = friction_update_clip(
            self.k, self.P, H, residual, meas_var, self.a, limit, ks_cap, self.max_shrinks)
        delta = (float(k_new[0] - self.k[0]), float(k_new[1] - self.k[1]))
        self.k = k_new
        self.P = P_new
        self.n_updates += 1
        return FrictionUpdate(residual=residual, innovation_var=float(S),
                              fictitious_var=float(R_used), shrinks=int(shrinks), clipped=bool(clipped),
                              delta=delta)
