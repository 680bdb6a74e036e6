"""``stribeck``: Acker's shaft whose sliding friction falls with speed (SPEC §11).

Stuck mode and breakaway are Acker's (closed form); sliding, F = sign(x2)·[kc + (ks − kc)·
exp(−(|x2|/v_s)^δ) + b·|x2|] with kc = k̄c·m(θ) + x5, ks = k̄s·m(θ) + x5 and the
position-dependent factor m(θ) of :mod:`plant.ripple`. Not piecewise linear in motion: an
error-controlled Dormand–Prince 5(4) noise-free, stochastic Heun sub-steps with noise
(:mod:`plant.stribeck.moving`). The state carries the load angle θ after the shared six.

Modules: ``params`` (StribeckParams), ``law`` (the friction law), ``moving`` (modes 1 and 3),
``interval`` (the pure step, compiled whole), ``law_loop`` (the compiled closed loop of a
fixed linear law), ``reference`` (solve_ivp and Euler–Maruyama), ``disturbed`` (the
Ornstein–Uhlenbeck disturbance torque of SPEC §11: an eighth state entry d, used only when
``disturbance_torque_std`` > 0);
the Dormand–Prince tableau is shared (:mod:`plant.dopri`).
"""

from __future__ import annotations

import numpy as np

from plant.protocol import PlantFamily, register_family
from plant.ripple import THETA, ripple_factor
from plant.state import X5, PlantState
from plant.stribeck import disturbed, law_loop
from plant.stribeck.interval import N_STATE, advance
from plant.stribeck.params import StribeckParams

__all__ = ["Stribeck", "StribeckParams"]


@register_family("stribeck")
class Stribeck(PlantFamily):
    """Stribeck + viscous sliding friction, Acker's stuck mode; step = plant.stribeck.interval.advance."""

    Params = StribeckParams
    linear_law_loop = staticmethod(law_loop.run_law)
    compiled_law_loop = staticmethod(law_loop.run_compiled_law)
    compiled_loop_logs = True
    description = "Stribeck curve (friction falls from ks to kc with speed) plus viscous drag; error-controlled RK"
    # one of the scenarios this family contributes: name -> (field changes, one-line story)
    scenarios = {
        "stribeck": ({}, "Table 2-1's levels, but sliding friction falls from ks to kc over v_s = 4 mrad/s "
                         "(Stribeck curve) with light viscous drag"),
        "ripple": ({"friction_ripple": 0.2, "ripple_period": 2e-4},
                   "the stribeck scenario with ±20 % friction ripple every 200 µrad of travel "
                   "(a worn bearing's or gear mesh's periodic drag, a few ripples per pulse train)"),
    }

    def initial_state(self, params, x5):
        if params.disturbance_torque_std != 0.0:
            return disturbed.initial_state(params, x5)
        x = np.zeros(N_STATE)
        x[3] = params.command_velocity_initial
        x[X5] = x5
        x.flags.writeable = False
        return PlantState(0.0, x, 2, False)

    def step(self, state, command, params, noise, options, *, duration=None, record=False):
        if params.disturbance_torque_std != 0.0:
            return disturbed.advance(state, command, params, noise, options, duration=duration, record=record)
        return advance(state, command, params, noise, options, duration=duration, record=record)

    def truth(self, params, state):
        out = super().truth(params, state)
        theta = float(state.x[THETA])
        m = ripple_factor(theta, params.friction_ripple, 2.0 * np.pi / params.ripple_period, params.ripple_phase)
        x5 = out["x5"]
        out["ks_true"] = max(params.stiction * m + x5, 0.0)
        out["kc_true"] = max(params.coulomb * m + x5, 0.0)
        out["theta"] = theta
        if params.disturbance_torque_std != 0.0:
            out["disturbance_torque"] = float(state.x[disturbed.D]) if state.x.shape[0] > disturbed.D else 0.0
        return out
