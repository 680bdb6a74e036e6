"""The cycle cost (6-1)–(6-5) and the calibration of a_c."""

import math

import pytest
from scipy.integrate import quad
from scipy.optimize import minimize_scalar

from controllers.solnic.cost import (calibrate_error_cost, charge, cost_curve, cycle_cost,
                                     cycle_period)
from controllers.solnic.options import A_C_HIGH_ERROR_COST, A_C_THESIS
from plant import PlantParams, pulse_response

P = PlantParams()


@pytest.mark.parametrize("dt_u", [1e-4, 1.36e-3, 5e-3])
def test_charge_is_the_integral_of_the_on_phase_current(dt_u):
    x3 = lambda t: P.u_max * (1 - math.exp(-t / P.motor_time_constant))
    ref, _ = quad(x3, 0.0, dt_u, epsabs=0, epsrel=1e-12)
    assert charge(dt_u, P.u_max, P.beta3) == pytest.approx(ref, rel=1e-10)


def test_cost_terms():
    c = cycle_cost(1.36e-3, 2.8e-6, 30e-6, 1.8e-4, P)
    assert c.period == pytest.approx(2.8e-6 / 30e-6)                                  # (6-3)
    assert c.effort_cost == pytest.approx(1.8e-4 * c.charge / c.period)               # (6-4)
    assert c.total == pytest.approx(2.8e-6 + c.effort_cost)                           # (6-5)
    assert cycle_cost(0.5e-3, 0.0, 30e-6, 1.8e-4, P).total == math.inf
    assert cycle_period(1e-6, 0.0) == math.inf


def _true_optimum(a_c):
    motion = lambda d: abs(pulse_response(P, d).delta_c)
    J = cost_curve(motion, P, P.command_velocity_initial, a_c)
    return minimize_scalar(J, bounds=(0.95e-3, 2.5e-3), method="bounded",
                           options={"xatol": 1e-10}).x


@pytest.mark.parametrize("target,preset", [(1.4e-6, A_C_THESIS),
                                           (0.1 * P.classical_bound(), A_C_HIGH_ERROR_COST)])
def test_calibrated_a_c_puts_the_optimum_at_the_target_peak(target, preset):
    cal = calibrate_error_cost(P, target_peak=target)
    assert cal.a_c == pytest.approx(preset, rel=1e-4)          # the number in the preset
    opt = _true_optimum(cal.a_c)                               # independent minimiser
    dc = pulse_response(P, opt).delta_c
    assert dc / 2 == pytest.approx(target, rel=2e-3)           # peak error of the medium size
    # the adjusted increment spreads the motions 2:1
    r = pulse_response(P, cal.dtu_opt + cal.dtu_inc).delta_c / pulse_response(P, cal.dtu_opt - cal.dtu_inc).delta_c
    assert r == pytest.approx(2.0, rel=1e-6)


def test_unreachable_targets_raise():
    with pytest.raises(ValueError, match="target_peak"):
        calibrate_error_cost(P, target_peak=1e-9)
