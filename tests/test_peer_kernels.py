"""The peers' per-sample fast paths against the plain forms they replace and against independent
truth: the compiled fused multiply–add against exact rational arithmetic; the straight-line
disturbance observer and the compiled PID lead path against their matrix forms; the slope window
against a least-squares fit; the compiled RLS cubic against numpy's polynomial and a plain
bisection; the oracle's compiled on-time bisection against ``pulse_response``."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from controllers._fma import fma
from controllers.linear import design_linear
from controllers.observer_pid import DisturbanceObserver
from controllers.oracle_pulse import OraclePulse
from controllers.pid import PidRealisation, SlopeEstimator
from controllers.pulse_width import PulseModelRls
from plant import PlantParams
from plant.multimode.pulse import pulse_response

P = PlantParams()


def test_fma_is_the_correctly_rounded_a_times_b_plus_c():
    rng = np.random.default_rng(1)
    a, b, c = (rng.standard_normal(400) * 10.0 ** rng.uniform(-8, 8, 400) for _ in range(3))
    for x, y, z in zip(a.tolist(), b.tolist(), c.tolist()):
        assert fma(x, y, z) == float(Fraction(x) * Fraction(y) + Fraction(z))
    # one rounding, not two: (1 + 2⁻³⁰)(1 − 2⁻³⁰) − 1 = −2⁻⁶⁰ exactly, lost by a*b + c
    e = 2.0 ** -30
    assert fma(1 + e, 1 - e, -1.0) == -(2.0 ** -60)
    assert (1 + e) * (1 - e) - 1.0 == 0.0


@pytest.mark.parametrize("bandwidth", [5.0, 160.0, 250.0])
def test_observer_update_is_the_matrix_form(bandwidth):
    obs = DisturbanceObserver(P.inertia, P.motor_time_constant, P.sample_period, bandwidth)
    rng = np.random.default_rng(2)
    z = np.zeros(4)
    for _ in range(300):
        y, u = float(rng.normal(0, 2e-5)), float(rng.normal(0, 1.0))
        z = obs.Phi @ z + obs.Gamma * u + obs.L * (y - z[0])
        obs.update(y, u)
        np.testing.assert_allclose(obs.z, z, rtol=1e-12, atol=1e-300)
    assert obs.disturbance == obs.z[3] and obs.velocity == obs.z[1]
    obs.disturbance = 0.25                       # the breakaway jump sets d̂ alone
    np.testing.assert_array_equal(obs.z, [z[0], z[1], z[2], 0.25])


@pytest.mark.parametrize("crossover", [10.0, 48.0])     # one and two lead stages
def test_pid_lead_path_is_the_state_space_form(crossover):
    design = design_linear(P, crossover, integral=True)
    pid = PidRealisation(design)
    n = pid.A.shape[0]
    assert n == (1 if crossover == 10.0 else 2)
    rng = np.random.default_rng(3)
    x = np.zeros(n)
    for _ in range(300):
        e = float(rng.normal(0, 1e-5))
        v = float(pid.C @ x) + pid.D * e
        x = pid.A @ x + pid.B * e
        assert pid.proportional(e) == pytest.approx(v, rel=1e-12, abs=1e-300)
        np.testing.assert_allclose(pid.x, x, rtol=1e-12, atol=1e-300)


def test_slope_window_is_the_least_squares_slope():
    ts, n = 0.01, 10
    est = SlopeEstimator(n, ts)
    rng = np.random.default_rng(4)
    ys = rng.normal(0, 1e-5, 40) + 3e-5 * ts * np.arange(40)
    for k, y in enumerate(ys):
        s = est.update(float(y))
        if k < n - 1:
            assert math.isnan(s)
        else:
            fit = np.polyfit(ts * np.arange(n), ys[k - n + 1:k + 1], 1)[0]
            assert s == pytest.approx(fit, rel=1e-9, abs=1e-15)


def test_rls_cubic_predict_and_invert():
    rng = np.random.default_rng(5)
    model = PulseModelRls()
    for _ in range(50):
        theta = np.array([rng.normal(0, 1), 1 + abs(rng.normal(0, 3)), abs(rng.normal(0, 2)),
                          abs(rng.normal(0, 0.3))])            # increasing on v > 0
        model.theta = theta
        w = float(rng.uniform(0.2e-3, 4e-3))
        assert model.predict(w) == pytest.approx(np.polyval(theta[::-1], w / 1e-3) * 1e-6, rel=1e-12)
        lo, hi = 0.5e-3, 3e-3
        target = float(rng.uniform(model.predict(lo), model.predict(hi)))
        got = model.invert(target, lo, hi)
        a, b = lo, hi                               # plain bisection on numpy's polynomial
        for _ in range(60):
            mid = 0.5 * (a + b)
            a, b = (mid, b) if np.polyval(theta[::-1], mid / 1e-3) * 1e-6 < target else (a, mid)
        assert got == pytest.approx(0.5 * (a + b), rel=1e-9)
        assert model.predict(got) == pytest.approx(target, rel=1e-9)
        assert model.invert(model.predict(hi) * 2, lo, hi) is None    # not bracketed


@pytest.mark.parametrize("motion", [0.5e-6, 3e-6, 20e-6, 1.0])
def test_oracle_on_time_root_brackets_the_true_pulse_law(motion):
    """The oracle's on-time search on the true family's noise-free response (x5 = 0.3 while
    stuck) against the plant's own pulse response with the effective friction (section 5.3)."""
    from plant.protocol import TruePlant, get_family
    from plant.state import initial_state
    oracle = OraclePulse()
    oracle.reset(P, np.random.default_rng(0))
    state = initial_state(P, x5=0.3)
    oracle.observe_truth(state, TruePlant(get_family("multimode"), P))
    dtu, dc, t_stop = oracle._dtu_for(state, motion, 1)
    law = P.replace(stiction=P.stiction + 0.3, coulomb=P.coulomb + 0.3, correlated_friction_std=0.0)
    r = pulse_response(law, dtu)
    # x5 decays as e^(−t/τ5) while the shaft moves (τ5 = 1000 s): ~1e-6 relative over a pulse
    assert dc == pytest.approx(r.delta_c, rel=5e-6)
    assert t_stop == pytest.approx(r.t_stop, rel=5e-6)
    if dtu < oracle.dtu_max:                       # the root's bracket is 1e-10 s wide
        below, _ = get_family("multimode").pulse_motion(P, state, dtu - 2e-10, 1)
        assert below < motion <= dc
    else:
        assert dc <= motion


def test_rls_update_is_the_recursion_in_its_stated_order():
    """The compiled RLS step against the recursion written out in plain Python floats in the
    order its docstring states (bit-identical), and against exact rational arithmetic of the
    same recursion (relative error ≤ 1e-6 on θ: the cubic's features span w … w³ with
    w ~ 1e-3, so P's condition number is ~1e12 and round-off is amplified; numpy's own
    ``P @ φ`` rounds differently from one numpy release to the next, 3e-9 apart on 2.4)."""
    rng = np.random.default_rng(6)
    model = PulseModelRls(forgetting=0.98)
    lam = model.lam
    P = [[float(v) for v in row] for row in model.P]
    theta = [float(v) for v in model.theta]
    Pq = [[Fraction(v) for v in row] for row in P]
    tq = [Fraction(v) for v in theta]
    for _ in range(40):
        w, dc = float(rng.uniform(0.5e-3, 3e-3)), float(rng.normal(3e-6, 1e-6))
        phi = [float(v) for v in PulseModelRls.features(w)]
        target = dc / 1e-6
        Pphi = [(P[i][0] * phi[0] + P[i][2] * phi[2]) + (P[i][1] * phi[1] + P[i][3] * phi[3]) for i in range(4)]
        den = lam + fma(phi[3], Pphi[3], fma(phi[2], Pphi[2], fma(phi[1], Pphi[1], fma(phi[0], Pphi[0], 0.0))))
        K = [Pphi[i] / den for i in range(4)]
        innov = target - fma(phi[3], theta[3], fma(phi[2], theta[2], fma(phi[1], theta[1], fma(phi[0], theta[0], 0.0))))
        theta = [theta[i] + K[i] * innov for i in range(4)]
        P1 = [[(P[i][j] - K[i] * Pphi[j]) / lam for j in range(4)] for i in range(4)]
        P = [[0.5 * (P1[i][j] + P1[j][i]) for j in range(4)] for i in range(4)]
        # exact
        fq = [Fraction(v) for v in phi]
        Pfq = [sum(Pq[i][j] * fq[j] for j in range(4)) for i in range(4)]
        Kq = [v / (Fraction(lam) + sum(fq[j] * Pfq[j] for j in range(4))) for v in Pfq]
        iq = Fraction(target) - sum(fq[j] * tq[j] for j in range(4))
        tq = [tq[i] + Kq[i] * iq for i in range(4)]
        P1q = [[(Pq[i][j] - Kq[i] * Pfq[j]) / Fraction(lam) for j in range(4)] for i in range(4)]
        Pq = [[(P1q[i][j] + P1q[j][i]) / 2 for j in range(4)] for i in range(4)]
        model.update(w, dc)
        assert model.theta.tolist() == theta
        assert model.P.tolist() == P
        exact = np.array([float(v) for v in tq])
        assert np.abs(model.theta - exact).max() <= 1e-6 * np.abs(exact).max()
    assert model.n == 40
