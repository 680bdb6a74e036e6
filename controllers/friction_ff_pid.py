"""PID with static friction feedforward, ``friction-ff-pid``: the deployed baseline (issue 24).

What an industrial servo ships: a PID at the linear design's crossover plus a *static* friction
map fed forward, its levels read off the friction model the engineer was given (here the
``PlantParams`` handed to ``reset`` — the nominal model, never the truth).

Sources of the design rules:

* B. Armstrong-Hélouvry, P. Dupont and C. Canudas de Wit, "A survey of models, analysis tools
  and compensation methods for the control of machines with friction", Automatica 30(7) (1994)
  1083–1138: model-based feedforward of a static friction map, its sign taken from the
  *desired* velocity (not the measured one, which is noisy near zero), the Stribeck curve
  between the static and the Coulomb level, and a deadband near zero (velocity and error)
  against the hunting an over-compensating feedforward causes; compensation at a fraction
  of the modelled level (under-compensation) for the same reason.
* The Stribeck shape g(v) = k̄c + (k̄s − k̄c)·exp(−(v/v_s)²) of C. Canudas de Wit, H. Olsson,
  K. J. Åström and P. Lischinsky, IEEE TAC 40(3) (1995) 419–425 (the ``stribeck``/``lugre``
  families' own law, SPEC §11).
* The PID: :func:`controllers.linear.design_linear` with ``integral=True`` — the ``linear``
  rule (SPEC §4: highest crossover the sample rate allows, phase margin 45°, gain margin
  ≥ 6 dB; 48.4 rad/s for Table 2-1), integral corner ωz = 0.1·ωc, realised with an explicit
  integrator and conditional integration while clipped (:class:`controllers.pid.PidRealisation`).

The feedforward (:func:`friction_feedforward`), with v_r the reference velocity and e the
measured error y = c − r [rad]:

    s = sign(v_r)            if |v_r| ≥ v_min, but 0 if s·e > e_db (the axis is ahead)   (1)
    s = −sign(e)             if |v_r| < v_min and |e| > e_db, else 0                      (2)
    u_ff = κ · s · g(|v_r|),  g(v) = k̄c + (k̄s − k̄c)·exp(−(v/v_s)²)                      (3)

with v_s = 0 meaning Acker's model (g(0) = k̄s, g(v > 0) = k̄c). v_r is the model's commanded
velocity x4(0) (``command_velocity_initial``: a servo's trajectory generator knows it), refined
by the stuck-sample average x̂4 of ``reset-pid``; e_db = ``error_deadband``·σ̄1, σ̄1 the model's
sensor noise. u = clip(u_pid + u_ff, ±u_max) on the linear amplifier.

Knob: the compensation fraction κ [–] (``compensation``). Default κ = 1.75 (1.75·k̄c = 2.45 ozf·in fed forward for
Acker's model, above k̄s = 2.1), the lowest mean peak of the sweep in
docs/tuning.md (thesis, tuning seeds 0–4 only; re-swept 2026-11-28, when it moved from 1.5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numba import njit

from controllers.base import register
from controllers.pid import P_NWIN, S_UFF, S_V, S_X4, pid_hold, pid_observe, pid_proportional
from controllers.reset_pid import PidFrictionOptions, _PidFrictionBase
from plant.drive import DriveCommand
from plant.params import PlantParams

__all__ = ["FrictionFfPidOptions", "FrictionFfPidController", "stribeck_level", "friction_feedforward"]


def stribeck_level(v: float, coulomb: float, stiction: float, stribeck_velocity: float) -> float:
    """g(|v|) = k̄c + (k̄s − k̄c)·exp(−(|v|/v_s)²) [ozf·in]  (3); v_s = 0 is the step of Acker's
    model (k̄s at v = 0, k̄c otherwise)."""
    v = abs(v)
    if stribeck_velocity == 0.0:
        return stiction if v == 0.0 else coulomb
    return coulomb + (stiction - coulomb) * math.exp(-(v / stribeck_velocity) ** 2)


def friction_feedforward(v_ref: float, e: float, *, coulomb: float, stiction: float,
                         stribeck_velocity: float, compensation: float, min_velocity: float,
                         error_deadband: float) -> float:
    """u_ff [ozf·in] of (1)–(3) for reference velocity ``v_ref`` [rad/s] and error ``e`` [rad]
    (what the compiled step computes: :func:`_feedforward`)."""
    return _feedforward(v_ref, e, coulomb, stiction, stribeck_velocity, compensation, min_velocity, error_deadband,
                        2.0)


@njit(cache=True)
def _feedforward(v_ref, e, coulomb, stiction, stribeck_velocity, compensation, min_velocity, error_deadband, two):
    """(1)–(3) compiled. ``two`` = 2.0 comes in at run time so that (v/v_s)² is libm's
    pow(v/v_s, 2.0), as Python's ``**`` computes it (a constant 2 would become v·v, which glibc's
    pow does not always equal)."""
    if abs(v_ref) >= min_velocity:
        s = math.copysign(1.0, v_ref)
        if s * e > error_deadband:        # the axis is ahead of the reference: withhold  (1)
            return 0.0
    elif abs(e) > error_deadband:         # reference at rest: push toward e = 0  (2)
        s = -math.copysign(1.0, e)
    else:
        return 0.0
    v = abs(v_ref)                        # g(|v_r|)  (3)
    if stribeck_velocity == 0.0:
        g = stiction if v == 0.0 else coulomb
    else:
        g = coulomb + (stiction - coulomb) * math.exp(-math.pow(v / stribeck_velocity, two))
    return compensation * s * g


# friction-ff-pid's own entries of s and p (after controllers.pid.PidLayout's shared ones)
_FS_SIGN_CHANGES = 0
_FP_COULOMB, _FP_STICTION, _FP_VS, _FP_KAPPA, _FP_VMIN, _FP_EDB, _FP_TWO = range(7)
_FS0, _FP0 = S_V + 1, P_NWIN + 1


@njit(cache=True)
def _friction_ff_pid_step(s, p, y, offs, levs):
    """:class:`FrictionFfPidController`'s step: slope and x̂4, u_ff of (1)–(3), the PID, the level."""
    pid_observe(s, p, y)
    u_ff = _feedforward(s[S_X4], y, p[_FP0 + _FP_COULOMB], p[_FP0 + _FP_STICTION], p[_FP0 + _FP_VS],
                        p[_FP0 + _FP_KAPPA], p[_FP0 + _FP_VMIN], p[_FP0 + _FP_EDB], p[_FP0 + _FP_TWO])
    prev = s[S_UFF]
    if (u_ff > 0.0) != (prev > 0.0) or (u_ff < 0.0) != (prev < 0.0):
        s[_FS0 + _FS_SIGN_CHANGES] += 1.0
    s[S_UFF] = u_ff
    offs[0] = 0.0
    levs[0] = pid_hold(s, p, pid_proportional(s, p, y), u_ff)
    return 1


@dataclass(frozen=True)
class FrictionFfPidOptions(PidFrictionOptions):
    """Options of :class:`FrictionFfPidController`: :class:`PidFrictionOptions` (the PID and the
    x̂4 average; ``feedforward_min_velocity`` is v_min of (1)) plus

    Attributes
    ----------
    compensation : float
        κ, the fed-forward fraction of the modelled friction level [–], in [0, 2]. The knob.
    stribeck_velocity : float
        v_s of (3) [rad/s], ≥ 0; 0 is Acker's model (the model told has no Stribeck curve).
    error_deadband : float
        e_db in units of the model's sensor noise σ̄1 [–], ≥ 0.
    """

    compensation: float = 1.75
    stribeck_velocity: float = 0.0
    error_deadband: float = 3.0

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, upper in (("compensation", 2.0), ("stribeck_velocity", math.inf), ("error_deadband", math.inf)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 <= v <= upper):
                rng = f"[0, {upper:g}]" if math.isfinite(upper) else ">= 0 and finite"
                raise ValueError(f"{name} must be a number in {rng}, got {v!r}")


@register("friction-ff-pid")
class FrictionFfPidController(_PidFrictionBase):
    """PID at the linear design's crossover plus static Coulomb/Stribeck friction feedforward
    from the told model (Armstrong-Hélouvry, Dupont & Canudas de Wit 1994). Options:
    :class:`FrictionFfPidOptions`. Knob: ``compensation`` κ. Counter: ``sign_changes`` of the
    feedforward."""

    description = "PID + static friction feedforward from the model (Armstrong-Hélouvry et al. 1994)"
    Options = FrictionFfPidOptions
    presets = MappingProxyType({"default": FrictionFfPidOptions()})
    knobs = MappingProxyType({"compensation": (0.0, 0.5, 1.0, 1.5, 2.0)})
    counter = "sign_changes"

    _compiled_step = staticmethod(_friction_ff_pid_step)
    _n_own_state, _n_own_params = 1, 7

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Design the PID for the model ``params``; x̂4 starts at its commanded velocity."""
        super().reset(params, rng)
        o = self.options
        self.x4_hat = params.command_velocity_initial
        p, i = self._p, self._own_p
        p[i(_FP_COULOMB)], p[i(_FP_STICTION)], p[i(_FP_VS)] = params.coulomb, params.stiction, o.stribeck_velocity
        p[i(_FP_KAPPA)], p[i(_FP_VMIN)] = o.compensation, o.feedforward_min_velocity
        p[i(_FP_EDB)], p[i(_FP_TWO)] = o.error_deadband * params.measurement_noise_std, 2.0

    def step(self, y: float) -> DriveCommand:
        """u(n) = clip(−(v + q) + u_ff), u_ff of (1)–(3) (:func:`_friction_ff_pid_step`)."""
        return super().step(y)

    def internals(self) -> dict[str, float]:
        return {"u_linear": self._level, "integrator": -self.pid.q, "feedforward": self._u_ff,
                "x4_hat": self.x4_hat, "stuck": float(self.stuck)}

    def summary(self) -> dict[str, Any]:
        if not hasattr(self, "design"):
            return {}
        out = self.design.summary()
        out.update(compensation=self.options.compensation,
                   sign_changes=int(self._s[self._own(_FS_SIGN_CHANGES)]), x4_hat=self.x4_hat)
        return out
