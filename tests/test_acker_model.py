"""The controllers' model (Acker's closed-form pulse law) against the plant it models.

:mod:`controllers.models.acker` is what a pulse controller assumes; :func:`plant.pulse_response`
runs the exact event-driven simulator. They are two independent exact computations of the same
idealized plant: they must agree to round-off, event times included, on parameter sets the
model was not written for — and the model must be only a model: it knows no noise.
"""

import numpy as np
import pytest

from controllers.models.acker import max_on_time, pulse_response as model_pulse
from plant import PlantParams, pulse_response

PARAM_SETS = [PlantParams(), PlantParams(inertia=1.3, motor_time_constant=5e-3, stiction=2.8, coulomb=1.4),
              PlantParams(u_max=12.0, stiction=1.5, coulomb=1.4), PlantParams(coulomb=0.2, stiction=0.5),
              PlantParams(inertia=0.2, motor_time_constant=12e-3, u_max=30.0, stiction=4.0, coulomb=1.0)]


@pytest.mark.parametrize("params", PARAM_SETS)
def test_closed_form_model_equals_the_exact_simulator(params):
    for frac in np.linspace(1.0001, 8.0, 40):
        dt_u = frac * params.breakaway_time
        a, b = model_pulse(params, dt_u), pulse_response(params, dt_u)
        assert a.delta_c == pytest.approx(b.delta_c, rel=1e-11)
        assert a.t_stop == pytest.approx(b.t_stop, abs=1e-12)
        assert a.t_current_zero == pytest.approx(b.t_current_zero, abs=1e-12)
        assert a.t_breakaway == pytest.approx(b.t_breakaway, abs=1e-12)
    for sign in (1, -1):
        below = model_pulse(params, 0.999 * params.breakaway_time, sign=sign)
        assert below.delta_c == 0.0 and below.t_breakaway is None


def test_the_model_is_noise_free_and_checks_its_arguments():
    p = PlantParams()
    with pytest.raises(ValueError, match="seed"):
        model_pulse(p, 1e-3, seed=0)
    with pytest.raises(ValueError, match="dt_u"):
        model_pulse(p, -1e-3)
    with pytest.raises(ValueError, match="sign"):
        model_pulse(p, 1e-3, sign=0)
    with pytest.raises(RuntimeError, match="coasts"):  # ControllerDiverged is a RuntimeError
        model_pulse(p.replace(coulomb=0.0), 2e-3)


@pytest.mark.parametrize("params", PARAM_SETS)
def test_max_on_time_lets_the_simulated_current_reach_zero_at_the_next_sample(params):
    """t_cz(Δt_u,max) = τs on the simulator's own flyback (the model's bridge constraint)."""
    r = pulse_response(params.replace(stiction=params.u_max * 0.999, coulomb=0.0), max_on_time(params))
    assert r.t_current_zero == pytest.approx(params.sample_period, abs=1e-12)
