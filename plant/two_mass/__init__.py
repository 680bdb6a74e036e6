"""``two-mass``: a compliant shaft — motor inertia J_m on a torsional spring and damper to the
load J, friction on the load (SPEC §11), simulated exactly between events.

x = [x1, x2, x3, x4, x5, u, φ, ω_m]: the shared six (SPEC §11; x1 and x2 are the load's) plus
the shaft twist φ = θ_m − θ_load [rad] and the motor velocity ω_m [rad/s].

Modules: ``params`` (the dataclass), ``modes`` (modal closed form, the first-root locator),
``motion`` (propagation, Φ(h), Q(h), the noise factor), ``bridge`` (noisy velocity zeros),
``interval`` (the compiled pure step), ``law_loop`` (the compiled closed loop of a fixed linear law).
"""

from __future__ import annotations

import numpy as np

from plant.protocol import PlantFamily, register_family
from plant.two_mass import law_loop
from plant.state import PlantState
from plant.two_mass.interval import N_X, advance
from plant.two_mass.params import TwoMassParams

__all__ = ["TwoMass", "TwoMassParams"]


@register_family("two-mass")
class TwoMass(PlantFamily):
    """The compliant-shaft plant; its step is :func:`plant.two_mass.interval.advance`."""

    Params = TwoMassParams
    linear_law_loop = staticmethod(law_loop.run_law)
    description = "compliant shaft: motor and load inertias on a torsional spring and damper, friction on the load"
    # 149 Hz, ζ = 0.029, J_m = J/10: mid-range of the 100-300 Hz first structural modes of
    # gimbal axes, lightly damped as bolted metal structures are (Jia et al., J. Nonlinear Dyn.
    # 2017, model a stabilized gimbal's structural resonance as this two-mass spring-damper).
    scenarios = {"compliant": ({"motor_inertia": 0.05, "shaft_stiffness": 4.0e4, "shaft_damping": 2.5},
                               "a compliant shaft: 149 Hz resonance, ζ = 0.029, rotor inertia J/10")}

    def initial_state(self, params, x5):
        """Load stuck at zero error, shaft relaxed and at rest, no current; x4, x5 as multimode."""
        x = np.zeros(N_X)
        x[3] = params.command_velocity_initial
        x[4] = x5
        x.flags.writeable = False
        return PlantState(0.0, x, 2, False)

    def step(self, state, command, params, noise, options, *, duration=None, record=False):
        return advance(state, command, params, noise, options, duration=duration, record=record)

    def truth(self, params, state):
        """The shared truth plus the shaft twist, the motor velocity and the shaft torque."""
        out = super().truth(params, state)
        x = state.x
        out["shaft_twist"] = float(x[6])
        out["motor_velocity"] = float(x[7])
        out["shaft_torque"] = float(params.shaft_stiffness * x[6] + params.shaft_damping * (x[7] - x[1]))
        return out
