"""Sizes, the Δt_u optimiser (6-9), (6-10), and the trigger."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from controllers.solnic.cost import calibrate_error_cost, cost_curve
from controllers.solnic.strategy import (LARGE, MEDIUM, SMALL, STARTUP_RAISE, STARTUP_SETTLE,
                                         SizeSchedule, increment_update, optimise_cost_curve,
                                         parabola_step, plan_trigger)
from plant import PlantParams, pulse_response


def test_parabola_step_is_the_vertex_of_the_fitted_parabola():
    x = np.array([-1.0, 0.0, 1.0])
    J = np.array([7.3, 6.1, 6.6])
    a, b, _ = np.polyfit(x, J, 2)
    inc = 80e-6
    assert parabola_step(*J, inc) == pytest.approx(-b / (2 * a) * inc, rel=1e-12)


def test_parabola_step_constraints():
    inc = 80e-6
    assert parabola_step(10.0, 9.0, 8.5, inc) == inc             # vertex 1.5·inc away: limited
    assert parabola_step(5.0, 7.0, 6.0, inc) == -inc             # concave: full step downhill
    assert parabola_step(6.0, 7.0, 5.0, inc) == inc
    assert parabola_step(math.inf, math.inf, math.inf, inc) == inc
    assert parabola_step(math.inf, 8.0, 7.0, inc) == inc
    assert parabola_step(math.inf, 7.0, 8.0, inc) == 0.0


def test_increment_update():
    assert increment_update(1.0, 2.0) == 1.0
    assert increment_update(1.0, 2.5) == pytest.approx(1 - 0.3 * 0.5)      # (6-9)
    assert increment_update(1.0, 1.5) == pytest.approx(1 + 0.3 * 0.5)
    assert increment_update(1.0, 30.0) == 0.5                              # clipped, never < 0
    assert increment_update(1.0, math.inf) == 1.0


def test_optimiser_converges_on_the_deterministic_cost_curve():
    """From Δt_u,opt = 0 and a 4× increment to the true optimum, as tested in section 6.2."""
    P = PlantParams()
    cal = calibrate_error_cost(P)
    motion = lambda d: abs(pulse_response(P, d).delta_c) if d > 0 else 0.0
    J = cost_curve(motion, P, P.command_velocity_initial, cal.a_c)
    truth = minimize_scalar(J, bounds=(0.95e-3, 2.5e-3), method="bounded", options={"xatol": 1e-10}).x
    hist = optimise_cost_curve(J, motion, 0.0, 4 * cal.dtu_inc, rounds=30)
    assert hist[-1].dtu_opt == pytest.approx(truth, rel=1e-2)
    assert hist[-1].dc_ratio == pytest.approx(2.0, rel=1e-2)
    assert abs(hist[-1].dtu_opt - hist[-2].dtu_opt) < 1e-4 * truth       # settled


def test_schedule_normal_sets_and_startup():
    s = SizeSchedule(dtu_opt=0.0, dtu_inc=0.3e-3)
    assert s.size == STARTUP_RAISE
    assert s.next_dtu() == pytest.approx(0.3e-3)
    s.launched(s.next_dtu())
    s.evaluated(False, STARTUP_RAISE, 0.3e-3)
    assert s.next_dtu() == pytest.approx(0.6e-3)                   # raised again
    s.launched(0.6e-3)
    s.evaluated(True, STARTUP_RAISE, 0.6e-3)
    assert s.size == STARTUP_SETTLE
    assert s.next_dtu() == pytest.approx(0.45e-3)                  # lowered by less
    s.evaluated(False, STARTUP_SETTLE, 0.45e-3)
    assert s.next_dtu() == pytest.approx(0.525e-3)
    s.evaluated(True, STARTUP_SETTLE, 0.525e-3)
    assert (s.size, s.dtu_opt) == (SMALL, 0.525e-3)
    sizes = []
    for _ in range(12):
        sizes.append(s.size)
        s.launched(s.next_dtu())
    assert sizes == [SMALL] * 4 + [MEDIUM] * 4 + [LARGE] * 4 and s.set_complete
    s.reoptimise(7.0, 6.0, 7.5, 2.0)
    assert s.size == SMALL and not s.set_complete
    s.evaluated(False, SMALL, s.normal_dtu(SMALL))                  # insignificant: start-up
    assert s.size == STARTUP_RAISE and s.next_dtu() == pytest.approx(s.dtu_opt + s.dtu_inc)


def test_trigger_inside_the_interval_at_the_predicted_crossing():
    # x̂1 = −1.0 µrad falling at 30 µrad/s reaches −Δc/2 = −1.4 µrad after 13.33 ms... too late
    assert plan_trigger(-1.0e-6, 30e-6, 0.1e-6, 2.8e-6, horizon=0.01, earliest=0.0, duration=2.5e-3) is None
    # from −1.3 µrad it is 3.33 ms away and the pulse (2.5 ms) fits
    tr = plan_trigger(-1.3e-6, 30e-6, 0.1e-6, 2.8e-6, horizon=0.01, earliest=0.0, duration=2.5e-3)
    assert tr.sign == 1 and tr.offset == pytest.approx(0.1e-6 / 30e-6) and not tr.overshoot
    # 8 ms away: the pulse would not be over before the next sample, so wait
    assert plan_trigger(-1.16e-6, 30e-6, 0.1e-6, 2.8e-6, horizon=0.01, earliest=0.0, duration=2.5e-3) is None
    # already past: now
    assert plan_trigger(-2e-6, 30e-6, 0.1e-6, 2.8e-6, horizon=0.01, earliest=0.0, duration=2.5e-3).offset == 0.0


def test_trigger_is_unsymmetrical():
    kw = dict(horizon=0.01, earliest=0.0, duration=2.5e-3)
    assert plan_trigger(+3.0e-6, 30e-6, 0.1e-6, 2.8e-6, **kw) is None       # drift will fix it
    tr = plan_trigger(+4.3e-6, 30e-6, 0.1e-6, 2.8e-6, **kw)                  # beyond 1.5·Δc_p
    assert tr.sign == -1 and tr.overshoot
    # drift direction unknown: symmetric test at Δc_p/2
    tr = plan_trigger(+1.5e-6, 1e-6, 1e-6, 2.8e-6, **kw)
    assert tr.sign == -1 and tr.offset == 0.0
