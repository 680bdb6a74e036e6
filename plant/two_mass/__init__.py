"""``two-mass``: a compliant shaft — motor inertia J_m on a torsional spring and damper to the
load J, friction on the load (SPEC §11), simulated exactly between events.

x = [x1, x2, x3, x4, x5, u, φ, ω_m]: the shared six (SPEC §11; x1 and x2 are the load's) plus
the shaft twist φ = θ_m − θ_load [rad] and the motor velocity ω_m [rad/s].

Modules: ``params`` (the dataclass), ``modes`` (modal closed form, the first-root locator),
``motion`` (propagation, Φ(h), Q(h), the noise factor), ``bridge`` (noisy velocity zeros),
``interval`` (the compiled pure step), ``law_loop`` (the compiled closed loop of a fixed linear law),
``disturbed`` (the Ornstein–Uhlenbeck disturbance torque on the load, SPEC §11: a ninth state
entry d, used only when ``disturbance_torque_std`` > 0).
"""

from __future__ import annotations

import math

import numpy as np

from plant.drive import DriveCommand, DriveType
from plant.protocol import PlantFamily, _checked, register_family
from plant.state import SimOptions
from plant.two_mass import disturbed, law_loop
from plant.state import PlantState
from plant.two_mass.interval import N_X, advance
from plant.two_mass.params import TwoMassParams

__all__ = ["TwoMass", "TwoMassParams"]

_PULSE_HORIZON_S = 1.0


@register_family("two-mass")
class TwoMass(PlantFamily):
    """The compliant-shaft plant; its step is :func:`plant.two_mass.interval.advance`."""

    Params = TwoMassParams
    linear_law_loop = staticmethod(law_loop.run_law)
    compiled_law_loop = staticmethod(law_loop.run_compiled_law)
    compiled_loop_logs = True
    description = "compliant shaft: motor and load inertias on a torsional spring and damper, friction on the load"
    # 149 Hz, ζ = 0.029, J_m = J/10: mid-range of the 100-300 Hz first structural modes of
    # gimbal axes, lightly damped as bolted metal structures are (Jia et al., J. Nonlinear Dyn.
    # 2017, model a stabilized gimbal's structural resonance as this two-mass spring-damper).
    scenarios = {"compliant": ({"motor_inertia": 0.05, "shaft_stiffness": 4.0e4, "shaft_damping": 2.5},
                               "a compliant shaft: 149 Hz resonance, ζ = 0.029, rotor inertia J/10")}

    def initial_state(self, params, x5):
        """Load stuck at zero error, shaft relaxed and at rest, no current; x4, x5 as multimode;
        with the disturbance torque on, d(0) = 0 as a ninth entry."""
        if params.disturbance_torque_std != 0.0:
            return disturbed.initial_state(params, x5)
        x = np.zeros(N_X)
        x[3] = params.command_velocity_initial
        x[4] = x5
        x.flags.writeable = False
        return PlantState(0.0, x, 2, False)

    def step(self, state, command, params, noise, options, *, duration=None, record=False):
        if params.disturbance_torque_std != 0.0:
            return disturbed.advance(state, command, params, noise, options, duration=duration, record=record)
        return advance(state, command, params, noise, options, duration=duration, record=record)

    def pulse_motion(self, params, state, dt_u, sign):
        """As :meth:`PlantFamily.pulse_motion`, but the run goes on until the load is stuck with
        no current *and* the ringing shaft can no longer break it loose: with x3 = u = 0 the
        rotor's energy E = ½J_m·ω_m² + ½k·φ² does not grow while the load is stuck, and
        |T| ≤ √(2E)·(√k + c/√J_m), so once that bound is below ks no breakaway can follow
        (below ks − |d| with a disturbance torque d, which decays noise-free).
        """
        p = params.replace(command_velocity_std=0.0) if params.command_velocity_std else params
        x = state.x.copy()
        x[3] = 0.0
        x.flags.writeable = False
        s = state._replace(x=x, t=0.0)
        opts = SimOptions(noise=False)
        x1_0 = float(x[0])
        t_stop = 0.0
        if dt_u > 0:
            step = self.step(s, DriveCommand.hold(sign * p.u_max, DriveType.BRIDGE), p, None, opts,
                             duration=dt_u, record=True)
            s, t_stop = _checked(step, t_stop)
        off = DriveCommand.hold(0.0, DriveType.BRIDGE)
        chunk = max(2.0 * p.motor_time_constant * math.log1p(abs(float(s.x[2])) / p.u_max), 1e-3)
        k, c, Jm = p.shaft_stiffness, p.shaft_damping, p.motor_inertia
        ks = max(p.stiction + float(s.x[4]), 0.0)

        def settled(s):
            if s.mode != 2 or s.flyback or s.x[2] != 0.0:
                return False
            energy = 0.5 * Jm * s.x[7] ** 2 + 0.5 * k * s.x[6] ** 2
            d = abs(float(s.x[disturbed.D])) if s.x.shape[0] > disturbed.D else 0.0
            return math.sqrt(2.0 * energy) * (math.sqrt(k) + c / math.sqrt(Jm)) < ks - d
        while not settled(s) and s.t < _PULSE_HORIZON_S:
            s, t_stop = _checked(self.step(s, off, p, None, opts, duration=chunk, record=True), t_stop)
        if s.mode != 2:
            raise RuntimeError(f"load still moving {_PULSE_HORIZON_S} s after a {dt_u} s pulse")
        return float(s.x[0]) - x1_0, t_stop

    def truth(self, params, state):
        """The shared truth plus the shaft twist, the motor velocity and the shaft torque."""
        out = super().truth(params, state)
        x = state.x
        out["shaft_twist"] = float(x[6])
        out["motor_velocity"] = float(x[7])
        out["shaft_torque"] = float(params.shaft_stiffness * x[6] + params.shaft_damping * (x[7] - x[1]))
        if params.disturbance_torque_std != 0.0:
            out["disturbance_torque"] = float(x[disturbed.D]) if x.shape[0] > disturbed.D else 0.0
        return out
