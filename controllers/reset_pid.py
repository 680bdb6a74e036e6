"""Reset PID with Coulomb feedforward, ``reset-pid`` (a peer; SPEC §10).

Source: B. Beerens, A. Bisoffi, L. Zaccarian, W. P. M. H. Heemels, H. Nijmeijer and
N. van de Wouw, "Reset integral control for improved settling of PID-based motion systems with
friction", Automatica 107 (2019) 483–492: a PID whose integrator state is reset to zero when
the axis sticks with the integrator pushing it away from the set-point, which removes the
integrator's unwinding through the stiction band (the cause of hunting) and the overshoot it
brings.

Design rule (the same sample rate and crossover rules as ``linear``):

* C(z) = K·I(z)·Π lead_i(z) from :func:`controllers.linear.design_linear` with
  ``integral=True``: crossover ωc (default the highest feasible, 48.4 rad/s for Table 2-1,
  where the 6 dB gain margin — the sample rate — binds), phase margin 45°, integral corner
  ωz = 0.1·ωc. Realised with an explicit integrator q (:class:`controllers.pid.PidRealisation`):
  u_pid = −(v + q).
* Stick detection from measurements only: the shaft velocity estimate x̂2 = ẏ̂ + x̂4 (ẏ̂ the
  least-squares slope of the last N samples) is below ``stick_velocity``.
* Reset law (after Beerens et al.): q := 0 (i) when the measured error crosses zero by more than
  ``crossing_band`` (the integrator must not carry the slip past the set-point) and (ii) at a
  sample where the axis sticks and the integrator's torque −q pushes away from zero error
  (q·e < 0), so that it need not unwind through the stiction band.
* Coulomb feedforward in the reference's direction: u_ff = k̄c·sign(x̂4) once |x̂4| exceeds
  ``feedforward_min_velocity``; x̂4 is the exponentially averaged −ẏ̂ over stuck samples (the
  error moves at −x4 while the shaft sticks). k̄c is the nominal Coulomb level of the plant
  parameters (the only friction knowledge the controller has).
* u = clip(u_pid + u_ff, ±u_max) on the linear amplifier; the integrator does not integrate
  while the command is clipped (conditional integration).

Knob: the crossover ωc [rad/s]. Default chosen by the sweep in docs/tuning.md (thesis scenario,
seeds 0–4 only).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from numba import njit

from controllers.base import Controller, register
from controllers.law import CompiledLaw, law_command
from controllers.linear import LinearDesign, design_linear
from controllers.pid import (P_NWIN, S_LEVEL, S_N, S_Q, S_STUCK, S_UFF, S_V, S_VPREV, S_X4, PidLayout,
                             PidRealisation, SlopeEstimator, pid_hold, pid_observe, pid_proportional)
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

__all__ = ["ResetPidOptions", "ResetPidController", "PidFrictionOptions"]

_RS0, _RP0 = S_V + 1, P_NWIN + 1   # the first own entries of s and p (controllers.pid.PidLayout)

_LINEAR = DriveType.LINEAR


def _positive(name: str, value: Any, *, allow_none: bool = False, upper: float = math.inf) -> None:
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if not 0 < value < upper:
        bound = f"(0, {upper:g})" if math.isfinite(upper) else "> 0"
        raise ValueError(f"{name} must be in {bound}, got {value!r}")


@dataclass(frozen=True)
class PidFrictionOptions:
    """Options shared by the PID peers.

    Attributes
    ----------
    crossover : float or None
        Gain crossover ωc [rad/s] of the ``integral=True`` linear design; None is the highest
        feasible one (:func:`controllers.linear.highest_crossover`).
    phase_margin_deg : float
        Phase margin at ωc [deg], in (0, 90).
    integral_corner_fraction : float
        Integral corner ωz/ωc [–], in (0, 1).
    velocity_window : int
        N, samples of the least-squares slope ẏ̂ [–], ≥ 2.
    stick_velocity : float
        Stuck when |ẏ̂ + x̂4| is below this [rad/s].
    reference_velocity_tau : float
        Time constant of the x̂4 average over stuck samples [s].
    feedforward_min_velocity : float
        Coulomb feedforward only once |x̂4| exceeds this [rad/s].
    coulomb_feedforward : bool
        Add k̄c·sign(x̂4).
    """

    crossover: float | None = None
    phase_margin_deg: float = 45.0
    integral_corner_fraction: float = 0.1
    velocity_window: int = 10
    stick_velocity: float = 5e-4
    reference_velocity_tau: float = 10.0
    feedforward_min_velocity: float = 15e-6
    coulomb_feedforward: bool = True

    def __post_init__(self) -> None:
        _positive("crossover", self.crossover, allow_none=True)
        _positive("phase_margin_deg", self.phase_margin_deg, upper=90.0)
        _positive("integral_corner_fraction", self.integral_corner_fraction, upper=1.0)
        if isinstance(self.velocity_window, bool) or not isinstance(self.velocity_window, int) \
                or self.velocity_window < 2:
            raise ValueError(f"velocity_window must be an integer >= 2, got {self.velocity_window!r}")
        _positive("stick_velocity", self.stick_velocity)
        _positive("reference_velocity_tau", self.reference_velocity_tau)
        _positive("feedforward_min_velocity", self.feedforward_min_velocity)
        if not isinstance(self.coulomb_feedforward, bool):
            raise ValueError(f"coulomb_feedforward must be a bool, got {self.coulomb_feedforward!r}")

    def design(self, params: PlantParams) -> LinearDesign:
        """The ``integral=True`` lead design for ``params`` (cached)."""
        return design_linear(params, self.crossover, integral=True,
                             phase_margin_deg=self.phase_margin_deg,
                             lag_corner_fraction=self.integral_corner_fraction)


@dataclass(frozen=True)
class ResetPidOptions(PidFrictionOptions):
    """Options of :class:`ResetPidController`: :class:`PidFrictionOptions` plus

    Attributes
    ----------
    reset : bool
        Apply the reset law (False: the same PID with feedforward, never reset).
    reset_on_crossing : bool
        Reset when the measured error changes sign by more than ``crossing_band``.
    reset_on_stick : bool
        Reset when the axis sticks with q·e < 0.
    crossing_band : float
        Smallest |y(n) − y(n−1)| [rad] of a sign change that counts as a crossing (measurement
        noise alone does not reset).
    """

    reset: bool = True
    reset_on_crossing: bool = True
    reset_on_stick: bool = True
    crossing_band: float = 20e-6

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("reset", "reset_on_crossing", "reset_on_stick"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be a bool, got {getattr(self, name)!r}")
        if isinstance(self.crossing_band, bool) or not isinstance(self.crossing_band, (int, float)) \
                or not (math.isfinite(self.crossing_band) and self.crossing_band >= 0):
            raise ValueError(f"crossing_band must be a finite number >= 0, got {self.crossing_band!r}")


class _PidFrictionBase(Controller):
    """PID realisation, slope estimate, stick detection, x̂4 and the Coulomb feedforward.

    The per-sample state lives in the array ``self._s`` laid out by
    :class:`controllers.pid.PidLayout`; a subclass sets ``_compiled_step`` (a numba step of
    the form :data:`plant.law_step.STEP_SIGNATURE`), the sizes ``_n_own_state`` / ``_n_own_params`` of its
    own entries, and fills its own parameters in ``reset``. ``step`` calls that function, which is
    also what :meth:`compiled_law` hands the runner.
    """

    drive = DriveType.LINEAR
    _compiled_step: Any = None
    _n_own_state = 0
    _n_own_params = 0

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        o = self.options
        self.params = params
        self.design = o.design(params)
        self.pid = PidRealisation(self.design)
        self.slope = SlopeEstimator(o.velocity_window, params.sample_period)
        self._layout = PidLayout(self.pid, self.slope, o.stick_velocity, params.sample_period / o.reference_velocity_tau,
                                 params.u_max, self._n_own_state, self._n_own_params)
        self._s, self._p = self._layout.s, self._layout.p
        self.pid.bind(self._s, S_Q)
        self._offs, self._levs = np.zeros(1), np.zeros(1)

    # the shared state, read from the array
    x4_hat = property(lambda self: float(self._s[S_X4]), lambda self, v: self._s.__setitem__(S_X4, v),
                      doc="x̂4 [rad/s], the stuck-sample average of −ẏ̂.")
    stuck = property(lambda self: bool(self._s[S_STUCK]), doc="Stuck at the last sample.")
    _level = property(lambda self: float(self._s[S_LEVEL]), doc="The last commanded level [ozf·in].")
    _u_ff = property(lambda self: float(self._s[S_UFF]), doc="The last feedforward [ozf·in].")
    _n = property(lambda self: int(self._s[S_N]), doc="Samples stepped.")

    def _own(self, i: int) -> int:
        """Index in s of the controller's own entry i."""
        return self._layout.own_s + i

    def _own_p(self, i: int) -> int:
        """Index in p of the controller's own constant i."""
        return self._layout.own_p + i

    def step(self, y: float) -> DriveCommand:
        """The compiled step on this controller's arrays (see the subclass's docstring)."""
        s = self._s
        if not self._layout.compiled:      # more than two lead states: numpy's form, outside
            s[S_V] = self.pid.proportional(y)
        return law_command(self._compiled_step(s, self._p, y, self._offs, self._levs), self._offs, self._levs,
                           _LINEAR)

    def compiled_law(self) -> CompiledLaw | None:
        """The compiled step on this controller's own arrays (None before ``reset``, or for a
        lead path of more than two states)."""
        layout = getattr(self, "_layout", None)
        if layout is None or not layout.compiled:
            return None
        return CompiledLaw(self._compiled_step, self._s, self._p, _LINEAR, 1)


@njit(cache=True)
def _coulomb_feedforward(s, p, on, min_velocity, coulomb):
    """k̄c·sign(x̂4) once |x̂4| > v_min (``on``: the option), else 0."""
    x4 = s[S_X4]
    if on and abs(x4) > min_velocity:
        return math.copysign(coulomb, x4)
    return 0.0


# reset-pid's own entries of s and p
_RS_YPREV, _RS_RESETS = range(2)
_RP_RESET, _RP_ON_CROSSING, _RP_ON_STICK, _RP_BAND, _RP_FF, _RP_FF_MIN, _RP_COULOMB = range(7)

@njit(cache=True)
def _reset_pid_step(s, p, y, offs, levs):
    """:class:`ResetPidController`'s step: slope, x̂4, PID, reset law, feedforward, held level."""
    pid_observe(s, p, y)
    v = pid_proportional(s, p, y)
    y_prev = s[_RS0 + _RS_YPREV]
    crossed = p[_RP0 + _RP_ON_CROSSING] != 0.0 and y * y_prev < 0.0 and abs(y - y_prev) > p[_RP0 + _RP_BAND]
    if p[_RP0 + _RP_RESET] != 0.0 and ((p[_RP0 + _RP_ON_STICK] != 0.0 and s[S_STUCK] != 0.0 and s[S_Q] * y < 0.0)
                                       or crossed):
        s[S_Q] = 0.0                     # the integrator pushes away from e = 0
        s[S_VPREV] = 0.0
        s[_RS0 + _RS_RESETS] += 1.0
    s[_RS0 + _RS_YPREV] = y
    u_ff = _coulomb_feedforward(s, p, p[_RP0 + _RP_FF] != 0.0, p[_RP0 + _RP_FF_MIN], p[_RP0 + _RP_COULOMB])
    s[S_UFF] = u_ff
    offs[0] = 0.0
    levs[0] = pid_hold(s, p, v, u_ff)
    return 1


@register("reset-pid")
class ResetPidController(_PidFrictionBase):
    """PID with integrator reset on detected stick and Coulomb feedforward (Beerens et al. 2019).

    Options: :class:`ResetPidOptions`; presets ``"default"`` and ``"no-reset"`` (the same PID
    and feedforward without the reset law, for comparison). Knob: ``crossover`` [rad/s].
    Counter: ``resets``.
    """

    description = "Reset PID with Coulomb feedforward (Beerens et al. 2019)"
    Options = ResetPidOptions
    presets = MappingProxyType({
        "default": ResetPidOptions(),
        "no-reset": dataclasses.replace(ResetPidOptions(), reset=False),
    })
    knobs = MappingProxyType({"crossover": (10.0, 20.0, 30.0, 40.0, 48.0)})
    counter = "resets"

    _compiled_step = staticmethod(_reset_pid_step)
    _n_own_state, _n_own_params = 2, 7

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Design for ``params`` and zero every state."""
        super().reset(params, rng)
        o = self.options
        p, i = self._p, self._own_p
        p[i(_RP_RESET)], p[i(_RP_ON_CROSSING)], p[i(_RP_ON_STICK)] = o.reset, o.reset_on_crossing, o.reset_on_stick
        p[i(_RP_BAND)], p[i(_RP_FF)], p[i(_RP_FF_MIN)] = o.crossing_band, o.coulomb_feedforward, o.feedforward_min_velocity
        p[i(_RP_COULOMB)] = params.coulomb
        self._reset_times: list[float] = []

    def step(self, y: float) -> DriveCommand:
        """u(n) = clip(−(v + q) + k̄c·sign(x̂4)), with q := 0 on a stick where q·e < 0 or at a
        crossing (:func:`_reset_pid_step`); the reset instants are kept for :meth:`event_times`
        (complete for runs stepped from Python, i.e. recorded ones)."""
        t = self._n * self.params.sample_period
        resets = self._s[self._own(_RS_RESETS)]
        cmd = super().step(y)
        if self._s[self._own(_RS_RESETS)] != resets:
            self._reset_times.append(t)
        return cmd

    def internals(self) -> dict[str, float]:
        return {"u_linear": self._level, "integrator": -self.pid.q, "feedforward": self._u_ff,
                "x4_hat": self.x4_hat, "stuck": float(self.stuck)}

    def event_times(self) -> dict[str, np.ndarray]:
        return {"reset": np.asarray(getattr(self, "_reset_times", []), dtype=float)}

    def summary(self) -> dict[str, Any]:
        if not hasattr(self, "design"):
            return {}
        out = self.design.summary()
        out.update(resets=int(self._s[self._own(_RS_RESETS)]), reset_law=self.options.reset,
                   x4_hat=self.x4_hat)
        return out
