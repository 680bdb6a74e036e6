"""PID with position-only friction observer and adaptive Coulomb estimate, ``observer-pid``
(a peer; SPEC §10).

Sources: the classical disturbance observer (a Luenberger observer of the input-referred
disturbance torque, e.g. Ohnishi's DOB; here the position-only form with the torque model), and
B. Friedland and Y.-J. Park, "On adaptive friction compensation", IEEE Trans. Automatic Control
37(10) (1992) 1609–1612, for the adaptive Coulomb estimate k̂c driven by the observed friction
while the axis moves.

Model (from the measured error y = x1 + w1 [rad], the commanded level u [ozf·in] and the
nominal J, τ3 only — no friction model):

    ÿ = (x3 − d)/J,   ẋ3 = (u − x3)/τ3,   ḋ = 0

(ẋ4 ≈ 0, so the error obeys the shaft's equation; d [ozf·in] is the friction torque plus all
other disturbances). Discretized exactly with a zero-order hold (expm), x3 is a known state
driven by u; the observer on (y, ẏ, d) is

    ẑ(n+1) = Φ ẑ(n) + Γ u(n) + L·(y(n) − ŷ(n))

with L placed by Ackermann's formula so that the estimation error has the poles
{e^(−ωo·τs), e^(−3ωo·τs), e^(−4ωo·τs)}: the disturbance estimate follows a step in d with the
dominant first-order time constant 1/ωo (the observer bandwidth ωo, the knob).

Design rule:

* the PID of ``reset-pid`` (``design_linear(integral=True)``, the same crossover rules as
  ``linear``), without reset;
* disturbance-observer compensation, always: u = clip(u_pid + d̂, ±u_max) on the linear
  amplifier. While the axis sticks the observed "disturbance" is the friction reaction, so d̂
  follows the applied torque and the loop gains fast integral action: the static friction in
  the reference's direction is fed forward by the observer itself (a separate Coulomb
  feedforward would count it twice);
* stiction → Coulomb at breakaway: when the observer's velocity x̂2 = ẏ̂ + x̂4 (x̂4 the
  stuck-sample average of −ẏ̂ of the least-squares slope, as in ``reset-pid``) first exceeds
  ``stick_velocity``, the friction drops from the static level that d̂ holds to the Coulomb
  level, so d̂ := k̂c·sign(x̂2) (``breakaway_jump``);
* adaptive Coulomb estimate (after Friedland & Park): while moving,
  k̂c ← k̂c + (τs/τc)·(sign(x̂2)·d̂ − k̂c), starting from ``initial_coulomb_factor``·k̄c.

Knob: the observer bandwidth ωo [rad/s]. Default chosen by the sweep in docs/tuning.md
(thesis scenario, seeds 0–4 only).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
import scipy.linalg

from controllers.base import register
from controllers.reset_pid import PidFrictionOptions, _PidFrictionBase, _positive
from plant.drive import DriveCommand
from plant.params import PlantParams

__all__ = ["ObserverPidOptions", "ObserverPidController", "DisturbanceObserver"]


class DisturbanceObserver:
    """Position-only observer of (y, ẏ, x3, d) with the d-error dominant pole at e^(−ωo·τs).

    Parameters
    ----------
    inertia, motor_time_constant, sample_period : float
        J [ozf·in·s²], τ3 [s], τs [s] (nominal).
    bandwidth : float
        ωo [rad/s].
    fast_factors : tuple of float
        The other two error poles sit at e^(−k·ωo·τs) for these k.
    """

    def __init__(self, inertia: float, motor_time_constant: float, sample_period: float,
                 bandwidth: float, fast_factors: tuple[float, float] = (3.0, 4.0)) -> None:
        J, tau3, ts = inertia, motor_time_constant, sample_period
        # state (y, ẏ, x3, d), input u:  ÿ = (x3 − d)/J, ẋ3 = (u − x3)/τ3, ḋ = 0
        F = np.array([[0.0, 1.0, 0.0, 0.0],
                      [0.0, 0.0, 1.0 / J, -1.0 / J],
                      [0.0, 0.0, -1.0 / tau3, 0.0],
                      [0.0, 0.0, 0.0, 0.0]])
        G = np.array([0.0, 0.0, 1.0 / tau3, 0.0])
        M = np.zeros((5, 5))
        M[:4, :4], M[:4, 4] = F * ts, G * ts
        E = scipy.linalg.expm(M)                     # ZOH: [Φ Γ; 0 1] = expm([F G; 0 0]·τs)
        self.Phi, self.Gamma = E[:4, :4], E[:4, 4]
        idx = [0, 1, 3]                              # observed (y, ẏ, d); x3 is known
        A = self.Phi[np.ix_(idx, idx)]
        C = np.array([1.0, 0.0, 0.0])
        self.poles = np.exp(-np.array([1.0, *fast_factors]) * bandwidth * ts)
        L = _ackermann(A, C, self.poles)
        self.L = np.zeros(4)
        self.L[idx] = L
        self.error_matrix = A - np.outer(L, C)       # ε(n+1) = (A − L·C)·ε(n)
        self.z = np.zeros(4)

    @property
    def disturbance(self) -> float:
        """d̂ [ozf·in]."""
        return float(self.z[3])

    @property
    def velocity(self) -> float:
        """ẏ̂ [rad/s]."""
        return float(self.z[1])

    def update(self, y: float, u: float) -> None:
        """ẑ(n+1) = Φ ẑ(n) + Γ u(n) + L (y(n) − ŷ(n))."""
        innovation = y - self.z[0]
        self.z = self.Phi @ self.z + self.Gamma * u + self.L * innovation


def _ackermann(A: np.ndarray, C: np.ndarray, poles: np.ndarray) -> np.ndarray:
    """Observer gain L with eig(A − L·C) = poles (Ackermann's formula on the dual system)."""
    n = A.shape[0]
    coeffs = np.real(np.poly(poles))                 # s^n + a1 s^(n−1) + … + an
    phi = sum(c * np.linalg.matrix_power(A, n - k) for k, c in enumerate(coeffs))
    obs = np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(n)])
    return phi @ np.linalg.solve(obs, np.eye(n)[:, -1])


@dataclass(frozen=True)
class ObserverPidOptions(PidFrictionOptions):
    """Options of :class:`ObserverPidController`: :class:`PidFrictionOptions` plus

    Attributes
    ----------
    observer_bandwidth : float
        ωo [rad/s], the dominant pole of the disturbance estimate; in (0, π/τs) (checked at
        reset).
    coulomb_tau : float
        Time constant τc of the adaptive Coulomb estimate while moving [s].
    initial_coulomb_factor : float
        k̂c starts at this × the nominal k̄c [–], ≥ 0.
    breakaway_jump : bool
        Set d̂ := k̂c·sign(x̂2) when motion is first detected.

    The inherited ``coulomb_feedforward`` and ``feedforward_min_velocity`` are not used: the
    observer supplies the static level.
    """

    observer_bandwidth: float = 160.0
    coulomb_tau: float = 1.0
    initial_coulomb_factor: float = 0.5
    breakaway_jump: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        _positive("observer_bandwidth", self.observer_bandwidth)
        _positive("coulomb_tau", self.coulomb_tau)
        v = self.initial_coulomb_factor
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise ValueError(f"initial_coulomb_factor must be a finite number >= 0, got {v!r}")
        if not isinstance(self.breakaway_jump, bool):
            raise ValueError(f"breakaway_jump must be a bool, got {self.breakaway_jump!r}")


@register("observer-pid")
class ObserverPidController(_PidFrictionBase):
    """PID plus friction compensation from a position-only disturbance observer and an adaptive
    Coulomb estimate (Friedland & Park 1992). Options: :class:`ObserverPidOptions`. Knob:
    ``observer_bandwidth`` [rad/s]. Counter: ``breakaways`` (detected stick → slip, where d̂
    jumps to the Coulomb estimate). Its report series: k̂c against the true kc."""

    description = "PID + position-only disturbance observer + adaptive Coulomb (Friedland & Park 1992)"
    Options = ObserverPidOptions
    presets = MappingProxyType({
        "default": ObserverPidOptions(),
        "no-adaptation": dataclasses.replace(ObserverPidOptions(), coulomb_tau=1e9,
                                             initial_coulomb_factor=1.0),
    })
    counter = "breakaways"
    knobs = MappingProxyType({"observer_bandwidth": (5.0, 10.0, 20.0, 30.0, 50.0, 80.0, 120.0, 160.0,
                                                     250.0)})

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Design the PID and the observer for ``params``; k̂c from the nominal k̄c."""
        o = self.options
        if not o.observer_bandwidth < math.pi / params.sample_period:
            raise ValueError(f"observer_bandwidth must be < π/τs = {math.pi / params.sample_period:.4g} "
                             f"rad/s, got {o.observer_bandwidth!r}")
        super().reset(params, rng)
        self.observer = DisturbanceObserver(params.inertia, params.motor_time_constant,
                                            params.sample_period, o.observer_bandwidth)
        self.kc_hat = o.initial_coulomb_factor * params.coulomb
        self._alpha_kc = params.sample_period / o.coulomb_tau
        self._u_comp = 0.0
        self._moving_samples = 0
        self._breakaways = 0
        self._was_moving = False

    def step(self, y: float) -> DriveCommand:
        """u(n) = clip(u_pid + d̂); at breakaway d̂ := k̂c·sign(x̂2) (see module docstring)."""
        self._observe(y)
        obs = self.observer
        x2_hat = obs.velocity + self.x4_hat
        moving = abs(x2_hat) > self.options.stick_velocity
        if moving and not self._was_moving and self.options.breakaway_jump:
            obs.z[3] = math.copysign(self.kc_hat, x2_hat)    # static → Coulomb level at breakaway
            self._breakaways += 1
        if moving:
            self._moving_samples += 1
            # after Friedland & Park: k̂c follows the observed friction in the direction of motion
            self.kc_hat += self._alpha_kc * (math.copysign(obs.disturbance, x2_hat) - self.kc_hat)
            self.kc_hat = max(self.kc_hat, 0.0)
        self._was_moving = moving
        self._u_comp = obs.disturbance
        v = self.pid.proportional(y)
        cmd = self._hold(v, self._u_comp)
        obs.update(y, self._level)
        return cmd

    def internals(self) -> dict[str, float]:
        return {"u_linear": self._level, "integrator": -self.pid.q, "compensation": self._u_comp,
                "d_hat": self.observer.disturbance, "kc_hat": self.kc_hat, "x4_hat": self.x4_hat,
                "stuck": float(self.stuck)}

    def report_series(self, t: np.ndarray, warmup_s: float) -> dict[str, np.ndarray]:
        """No extra series: the figures use the recorded internals (k̂c → ``kc_hat_pct``)."""
        return {}

    def summary(self) -> dict[str, Any]:
        if not hasattr(self, "design"):
            return {}
        out = self.design.summary()
        out.update(observer_bandwidth=self.options.observer_bandwidth, kc_hat=self.kc_hat,
                   moving_samples=self._moving_samples, breakaways=self._breakaways)
        return out
