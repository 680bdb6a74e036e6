"""pulse_response against closed forms, the SPEC reference values and solve_ivp with events."""

import math

import numpy as np
import pytest

from plant import PlantParams, pulse_response
from plant.drive import DriveType
from plant.multimode.reference import Schedule, event_driven
from plant.state import SimOptions

P0 = PlantParams()


def test_breakaway_time_is_the_exponential_crossing():
    r = pulse_response(P0, 1.5e-3)
    assert r.t_breakaway == pytest.approx(-P0.motor_time_constant * math.log(1 - P0.stiction / P0.u_max), abs=1e-12)


def test_reference_delta_c_at_1p5_ms():
    assert pulse_response(P0, 1.5e-3).delta_c * 1e6 == pytest.approx(4.8592, abs=5e-5)


@pytest.mark.parametrize("dt_u", [0.0, 1e-4, 5e-4, 0.887e-3])
def test_no_motion_below_breakaway(dt_u):
    r = pulse_response(P0, dt_u)
    assert r.delta_c == 0.0 and r.t_breakaway is None


@pytest.mark.parametrize("dt_u", [0.95e-3, 1.5e-3, 4e-3])
def test_sign_symmetry(dt_u):
    up, down = pulse_response(P0, dt_u, sign=1), pulse_response(P0, dt_u, sign=-1)
    assert down.delta_c == -up.delta_c and down.t_stop == up.t_stop


def test_current_zero_time_closed_form():
    dt_u = 2e-3
    tau3, U = P0.motor_time_constant, P0.u_max
    x3_off = U * (1 - math.exp(-dt_u / tau3))
    assert pulse_response(P0, dt_u).t_current_zero == pytest.approx(dt_u + tau3 * math.log(1 + x3_off / U), abs=1e-12)


PARAM_SETS = [P0, PlantParams(inertia=1.3, motor_time_constant=5e-3, stiction=2.8, coulomb=1.4),
              PlantParams(u_max=12.0, stiction=1.5, coulomb=1.4), PlantParams(coulomb=0.2, stiction=0.5)]


@pytest.mark.parametrize("params", PARAM_SETS)
@pytest.mark.parametrize("frac", [1.02, 1.2, 1.6, 2.5, 5.0])
def test_delta_c_matches_solve_ivp_with_events(params, frac):
    dt_u = frac * params.breakaway_time
    exact = pulse_response(params, dt_u)
    p = params.replace(command_velocity_initial=0.0, command_velocity_std=0.0)
    sched = Schedule(np.array([0.0, dt_u]), np.array([p.u_max, 0.0]), DriveType.BRIDGE, 2.0)
    ref = event_driven(p, sched, rtol=1e-13, atol=1e-22)
    assert ref["mode"] == 2
    assert exact.delta_c == pytest.approx(ref["final"][0], rel=1e-8)


def test_bad_arguments():
    with pytest.raises(ValueError, match="dt_u"):
        pulse_response(P0, -1e-3)
    with pytest.raises(ValueError, match="dt_u"):
        pulse_response(P0, math.nan)
    with pytest.raises(ValueError, match="sign"):
        pulse_response(P0, 1e-3, sign=2)


def test_hermite_peak_matches_dense_evaluation():
    """Interior extremum of the cubic Hermite interpolant vs a dense evaluation of the cubic."""
    from plant.multimode.segments import hermite_peak

    rng = np.random.default_rng(2)
    s = np.linspace(0, 1, 200001)
    for _ in range(200):
        h = 10 ** rng.uniform(-6, -3)
        ya, yb = rng.normal(0, 1e-6, 2)
        da, db = rng.normal(0, 1e-3, 2)
        c2 = 3 * (yb - ya) - (2 * da + db) * h
        c3 = -2 * (yb - ya) + (da + db) * h
        y = ya + da * h * s + c2 * s**2 + c3 * s**3
        dy = np.diff(y)
        turns = np.flatnonzero(np.sign(dy[1:]) != np.sign(dy[:-1])) + 1
        dense = np.abs(y[turns]).max() if turns.size else 0.0
        assert hermite_peak(h, ya, da, yb, db) == pytest.approx(dense, rel=1e-6, abs=1e-18)


@pytest.mark.parametrize("params", [PlantParams(), PlantParams(motor_time_constant=5e-3)])
def test_max_on_time_brings_the_current_back_to_zero_at_the_next_sample(params):
    # independent truth: the event-driven simulator's flyback-end time for that on-time
    from controllers.models.acker import max_on_time
    dt = max_on_time(params)
    assert 0 < dt < params.sample_period
    r = pulse_response(params, dt, options=SimOptions(noise=False))
    assert r.t_current_zero == pytest.approx(params.sample_period, abs=1e-12)
