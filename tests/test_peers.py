"""Today's peers against independent truth: the pulse-width RLS against the noise-free
``pulse_response``; the reset PID's realisation against python-control and its reset law on a
scripted stick and on a frictionless plant against the exact discrete closed form; the
disturbance observer against the closed-form response to a constant torque; hunting at a
stationary set-point."""

from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest
import scipy.linalg

from bench.runner import run_closed_loop
from controllers.base import make_controller
from controllers.observer_pid import DisturbanceObserver
from controllers.pulse_width import PulseModelRls
from plant import PlantParams
from plant.multimode.pulse import pulse_response

P = PlantParams()


# --------------------------------------------------------------------------- pulse-width

def test_rls_recovers_the_noise_free_pulse_curve_to_two_percent():
    widths = np.linspace(1.2e-3, 1.8e-3, 7)          # the excitation a run visits, cycled
    truth = {w: pulse_response(P, w).delta_c for w in widths}
    rls = PulseModelRls(forgetting=1.0)
    grid = np.linspace(1.2e-3, 1.8e-3, 61)
    exact = np.array([pulse_response(P, w).delta_c for w in grid])
    n_needed = None
    for k in range(40):
        w = widths[(3 * k) % len(widths)]
        rls.update(w, truth[w])
        err = np.max(np.abs(np.array([rls.predict(w) for w in grid]) / exact - 1))
        if err <= 0.02 and n_needed is None:
            n_needed = k + 1
    assert n_needed is not None and n_needed <= 12, n_needed
    # the inverse hits a target step on the true curve
    w = rls.invert(4e-6, 1.2e-3, 1.8e-3)
    assert pulse_response(P, w).delta_c == pytest.approx(4e-6, rel=0.02)


@pytest.fixture(scope="module")
def pulse_run():
    c = make_controller("pulse-width", target_step=4e-6)
    res = run_closed_loop(P, c, duration_s=15.0, warmup_s=5.0, seed=0, noise=False, record=True)
    return c, res


def test_pulse_width_identifies_the_plant_from_measurements_only(pulse_run):
    c, res = pulse_run
    assert res.status == "ok" and res.summary["pulses"] > 50
    assert c.x4_hat == pytest.approx(P.command_velocity_initial, rel=0.01)    # noise-free x4 = 30 µrad/s
    # the model at the operating width against the plant's own noise-free pulse
    w = c.width
    assert c.model.predict(w) == pytest.approx(pulse_response(P, w).delta_c, rel=0.03)
    assert pulse_response(P, w).delta_c == pytest.approx(4e-6, rel=0.1)
    # it corrects at ±Δ/2: the peak error is about half the step plus a sample's drift
    assert res.metrics["peak_error_rad"] < 4e-6


@pytest.mark.parametrize("kwargs, match", [
    ({"target_step": 0.0}, "target_step"), ({"width_growth": 1.0}, "width_growth"),
    ({"width_dither": 0.6}, "width_dither"), ({"forgetting": 1.5}, "forgetting"),
    ({"min_model_pulses": 2}, "min_model_pulses"), ({"initial_width": 5e-3}, "initial_width"),
])
def test_pulse_width_option_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_controller("pulse-width", **kwargs)


def test_pulse_width_max_width_is_checked_against_the_plant():
    c = make_controller("pulse-width", max_width=9e-3)
    with pytest.raises(ValueError, match="max_width"):
        c.reset(P, np.random.default_rng(0))


# --------------------------------------------------------------------------- reset-pid

def test_pid_realisation_is_the_integral_design():
    c = make_controller("reset-pid")
    c.reset(P, np.random.default_rng(0))
    e = np.random.default_rng(1).normal(size=300) * 1e-5
    u = []
    for x in e:                                       # the PID path only, no reset, no feedforward
        v = c.pid.proportional(x)
        u.append(-(v + c.pid.integrate(v)))
    _, ref = ct.forced_response(c.design.compensator, T=np.arange(e.size) * P.sample_period, U=e)
    np.testing.assert_allclose(u, -ref, rtol=0, atol=1e-12 * np.max(np.abs(ref)))


def test_reset_law_on_a_scripted_stick():
    """Stuck below the set-point (the integrator builds up the right way), then stuck above it:
    the integrator is reset at the first sample whose slope window is flat again, not before."""
    c = make_controller("reset-pid", reset_on_crossing=False, coulomb_feedforward=False)
    c.reset(P, np.random.default_rng(0))
    for _ in range(50):
        c.step(-1e-4)
    assert c.pid.q < 0 and c.event_times()["reset"].size == 0         # q·e > 0: no reset
    for _ in range(20):
        c.step(+1e-4)
    window = c.options.velocity_window
    np.testing.assert_allclose(c.event_times()["reset"], [(50 + window - 1) * P.sample_period])


def test_reset_on_crossing_needs_a_real_crossing():
    c = make_controller("reset-pid", reset_on_stick=False)
    c.reset(P, np.random.default_rng(0))
    for y in (-3e-6, 3e-6, -3e-6, 3e-6):               # measurement noise about zero
        c.step(y)
    assert c.event_times()["reset"].size == 0
    c.step(1e-4)                                       # same sign: no crossing
    assert c.event_times()["reset"].size == 0
    c.step(-1e-4)
    np.testing.assert_allclose(c.event_times()["reset"], [5 * P.sample_period])


def test_reset_pid_on_a_frictionless_plant_is_the_closed_form_between_resets():
    """Frictionless double integrator with motor lag, noise-free ramp: the run equals the exact
    ZOH discretization (expm) closed with the PID of python-control's sections, with q and
    v(n−1) zeroed at the reset instants the controller reports."""
    p = PlantParams(stiction=0.0, coulomb=0.0).noise_free()
    c = make_controller("reset-pid", stick_velocity=5e-5)
    res = run_closed_loop(p, c, duration_s=4.0, seed=0, noise=False, record=True)
    assert res.status == "ok"
    resets = set(np.round(c.event_times()["reset"] / p.sample_period).astype(int))
    assert resets, "the test needs resets to check the law"
    J, tau3, ts, x4 = p.inertia, p.motor_time_constant, p.sample_period, p.command_velocity_initial
    # state (x1, x2, x3, x4) with ẋ4 = −x4/τ4, input u (ZOH)
    F = np.array([[0, 1, 0, -1], [0, 0, 1 / J, 0], [0, 0, -1 / tau3, 0], [0, 0, 0, -1 / p.command_velocity_tau]])
    M = np.zeros((5, 5))
    M[:4, :4], M[2, 4] = F * ts, ts / tau3
    E = scipy.linalg.expm(M)
    Phi, Gam = E[:4, :4], E[:4, 4]
    d = c.design
    lead = ct.ss(ct.tf([d.gain], [1.0], ts))
    for sec in d.sections[1:]:
        lead = ct.series(lead, ct.ss(sec))
    A, B, C, D = (np.asarray(m, float) for m in (lead.A, lead.B, lead.C, lead.D))
    wc = d.crossover_target_rad_s
    g = d.lag_corner_rad_s * math.tan(wc * ts / 2) / wc
    x, xc, q, v_prev = np.array([0, 0, 0, x4]), np.zeros(A.shape[0]), 0.0, 0.0
    x1 = []
    for n in range(res.samples["x1"].size):
        y = x[0]
        x1.append(y)
        v = float((C @ xc).item() + D.item() * y)
        xc = A @ xc + B[:, 0] * y
        if n in resets:
            q, v_prev = 0.0, 0.0
        q += g * (v + v_prev)
        v_prev = v
        u = min(max(-(v + q), -p.u_max), p.u_max)
        x = Phi @ x + Gam * u
    scale = np.max(np.abs(x1))
    np.testing.assert_allclose(res.samples["x1"], x1, rtol=0, atol=1e-9 * scale)


def test_reset_pid_option_errors():
    for kwargs, match in (({"velocity_window": 1}, "velocity_window"), ({"crossover": -3.0}, "crossover"),
                          ({"crossing_band": -1.0}, "crossing_band"), ({"reset": "yes"}, "reset")):
        with pytest.raises(ValueError, match=match):
            make_controller("reset-pid", **kwargs)


# --------------------------------------------------------------------------- observer-pid

@pytest.mark.parametrize("bandwidth", [10.0, 40.0])
def test_observer_follows_a_constant_torque_at_its_bandwidth(bandwidth):
    """Constant disturbance torque d from rest on the frictionless inertia: y = −d·t²/(2J)
    exactly. The estimate's error modes are the designed poles, and d̂ follows the first-order
    response 1 − e^(−ωo·t) of the dominant pole within the fast poles' share."""
    ts, d = P.sample_period, 0.7
    obs = DisturbanceObserver(P.inertia, P.motor_time_constant, ts, bandwidth)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(obs.error_matrix).real), np.sort(obs.poles),
                               rtol=1e-9)
    n = np.arange(int(8 / (bandwidth * ts)) + 1)
    d_hat = []
    for k in n:
        d_hat.append(obs.disturbance)
        obs.update(-d * (k * ts) ** 2 / (2 * P.inertia), 0.0)
    d_hat = np.array(d_hat) / d
    # closed form of the estimation error: e_dᵀ M^n e_d = Σ r_i λ_i^n with the designed poles
    M = obs.error_matrix
    moments = [np.linalg.matrix_power(M, k)[2, 2] for k in range(3)]
    V = np.vander(obs.poles, 3, increasing=True).T
    r = np.linalg.solve(V, moments)
    closed = 1.0 - (r[None, :] * obs.poles[None, :] ** n[:, None]).sum(axis=1)
    np.testing.assert_allclose(d_hat, closed, rtol=0, atol=1e-9)
    # at the designed bandwidth: once the fast modes have died, the error decays as the
    # first-order mode e^(−ωo·t) of the dominant pole
    err = 1.0 - d_hat
    late = n >= int(4 / (bandwidth * ts))
    ratio = err[late][1:] / err[late][:-1]
    np.testing.assert_allclose(ratio, math.exp(-bandwidth * ts), rtol=2e-3)
    t63 = n[np.argmax(d_hat >= 1 - math.exp(-1))] * ts   # 1/ωo plus the fast poles' delay
    assert 1 / bandwidth <= t63 <= 2.5 / bandwidth + ts
    assert d_hat[-1] == pytest.approx(1.0, abs=2e-3)


def test_observer_pid_option_errors():
    with pytest.raises(ValueError, match="observer_bandwidth"):
        make_controller("observer-pid", observer_bandwidth=0.0)
    with pytest.raises(ValueError, match="initial_coulomb_factor"):
        make_controller("observer-pid", initial_coulomb_factor=-1.0)
    c = make_controller("observer-pid", observer_bandwidth=400.0)
    with pytest.raises(ValueError, match="observer_bandwidth"):
        c.reset(P, np.random.default_rng(0))


# --------------------------------------------------------------------------- hunting

@pytest.fixture(scope="module")
def hunting():
    """Stationary set-point, a 2 mrad set-point step, 40 s; stick-slip cycles after 10 s."""
    from bench.bound.run import _Observed

    p = PlantParams(command_velocity_std=0.0, command_velocity_initial=0.0)
    out = {}
    for label, name, kw in (("linear", "linear", {}), ("reset", "reset-pid", {}),
                            ("no-reset", "reset-pid", {"preset": "no-reset"})):
        r = run_closed_loop(p, _Observed(make_controller(name, **kw), 2e-3), duration_s=40.0,
                            warmup_s=10.0, seed=0, noise=True)
        assert r.status == "ok"
        out[label] = r.metrics["n_stick_slip"]
    return out


def test_the_reset_law_hunts_less_than_the_same_pid_without_it(hunting):
    print(hunting)
    assert hunting["reset"] < hunting["no-reset"]


@pytest.mark.xfail(strict=True, reason="not reproduced: at L = Lmax the linear controller settles "
                   "(0 stick-slip cycles after 10 s); reset-pid's pure integral still hunts "
                   "(8 stick-slip cycles in 30 s, seed 0) though fewer than without the reset (13)")
def test_reset_pid_hunts_less_than_linear(hunting):
    assert hunting["reset"] < hunting["linear"]
