"""``lugre``: Acker's shaft with the LuGre friction law (Canudas de Wit et al. 1995; SPEC §11).

The bristle state z gives pre-sliding compliance, frictional lag, drift and the Stribeck
curve from one law; there is no separate stuck mode. The bristles ring at √(σ0/J) (225 Hz by
default); at the accuracy required the step is accuracy-bound, so an explicit Dormand–Prince
5(4) with error control integrates it (:mod:`plant.lugre.integrate` says why). The state
carries θ (index 6) and z (index 7) after the shared six.

Modules: ``params`` (LuGreParams), ``law`` (right-hand side and Jacobian), ``integrate``
(the integrator), ``interval`` (the pure step, compiled whole), ``law_loop`` (the compiled closed loop of a
fixed linear law), ``reference`` (solve_ivp), ``disturbed`` (the Ornstein–Uhlenbeck
disturbance torque of SPEC §11: a ninth state entry d, used only when
``disturbance_torque_std`` > 0).
"""

from __future__ import annotations

import numpy as np

from plant.lugre import disturbed, law_loop
from plant.lugre.interval import N_STATE, advance
from plant.lugre.params import LuGreParams
from plant.protocol import PlantFamily, register_family
from plant.ripple import THETA, ripple_factor
from plant.state import X4, X5, PlantState

__all__ = ["LuGre", "LuGreParams", "Z"]

Z = 7        # state index of the bristle deflection z [rad]


@register_family("lugre")
class LuGre(PlantFamily):
    """LuGre friction (bristle state), no stuck mode; step = plant.lugre.interval.advance."""

    Params = LuGreParams
    linear_law_loop = staticmethod(law_loop.run_law)
    compiled_law_loop = staticmethod(law_loop.run_compiled_law)
    compiled_loop_logs = True
    description = "LuGre dynamic friction (Canudas de Wit et al. 1995): pre-sliding, lag, Stribeck; error-controlled RK"
    scenarios = {
        "lugre": ({}, "Table 2-1's levels in the LuGre law: 2.1 µrad of bristle compliance at breakaway, "
                      "frictional lag and a Stribeck curve over v_s = 4 mrad/s"),
    }

    def initial_state(self, params, x5):
        if params.disturbance_torque_std != 0.0:
            return disturbed.initial_state(params, x5)
        x = np.zeros(N_STATE)
        x[X4] = params.command_velocity_initial
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
        out["z"] = float(state.x[Z])
        if params.disturbance_torque_std != 0.0:
            out["disturbance_torque"] = float(state.x[disturbed.D]) if state.x.shape[0] > disturbed.D else 0.0
        return out
