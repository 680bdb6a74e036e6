"""The braking pulse pair against the exact plant (controllers/solnic/braking.py).

Independent truth: the plant's event-driven simulator (:func:`plant.multimode.interval.advance`) under the
bridge command +u_max for Δt_u, −u_max to t_off, then off — noise-free for the landing point,
noisy (Monte-Carlo) for the scatter. x4 ≡ 0 and x5's diffusion off, so x1 is the shaft angle
and w2 the only noise.

Stated tolerances: noise-free Δc within 1e-9 relative and the stop within 1e-9 s (both are
closed forms of the same equations, exact to rounding; the simulator's events are exact to
1e-12 s). Monte-Carlo (600 pairs and 600 single pulses per case, SD ≈ 15–22 µrad): the single
pulse is the one whose noise-aware model mean equals the pair's measured mean; the two means
agree within 3 standard errors of their difference, and the pair's SD is below the single's
(by > 8 % where the brake removes most of the coast). The pair's noise model
(:func:`controllers.solnic.noise_model.braked_pulse_noise`, 2000 pairs, r_b = 1 as in
solnic-modern) with the noise-model test's tolerances: the mean within 3 standard errors + 6 %
of the SD, the variance within ±15 % (measured against 4000 pairs: variance ratio 1.00–1.07 for
x5 ∈ {0, −0.6}, Δt_u 1.5–3 ms; blocks of 1000 pairs scatter by ±8 % in SD, the tail is heavy).
"""

import math

import numpy as np
import pytest

from controllers.solnic.braking import brake_timing, braked_response
from controllers.solnic.noise_model import braked_pulse_noise, pulse_noise
from controllers.solnic.predictor import Predictor
from plant import PlantParams, pulse_response
from plant.drive import DriveCommand, DriveType
from plant.multimode.interval import advance
from plant.randomness import NoiseStream
from plant.state import X1, X2, EventKind, SimOptions, initial_state

BASE = PlantParams().replace(correlated_friction_std=0.0, command_velocity_std=0.0)
MARGIN = 0.75


def _friction(x5):
    return BASE.replace(stiction=BASE.stiction + x5, coulomb=BASE.coulomb + x5)


def _simulate(p, dt_u, t_off, seed=None, until=None):
    """(Δc, stop time, state at ``until``) of the pair through the exact plant."""
    noisy = seed is not None
    opts = SimOptions(noise=noisy)
    noise = NoiseStream.from_seed(seed, block=512) if noisy else None
    st = initial_state(p, x5=0.0, x4=0.0)
    U = p.u_max
    cmd = DriveCommand(((0.0, U), (dt_u, -U), (t_off, 0.0)), DriveType.BRIDGE)
    stop = math.nan
    r = advance(st, cmd, p, noise, opts, duration=until if until is not None else t_off + 1e-6, record=True)
    if until is not None:
        return None, None, r.state
    st = r.state
    off = DriveCommand.hold(0.0, DriveType.BRIDGE)
    for _ in range(200):
        kinds, times = r.events["kind"].tolist(), r.events["t"].tolist()
        for k, t in zip(kinds, times):
            if k == int(EventKind.STICK):
                stop = t
        if st.mode == 2 and not st.flyback:
            break
        r = advance(st, off, p, noise, opts, duration=1e-3, record=True)
        st = r.state
    assert st.mode == 2
    return float(st.x[X1]), stop, st


CASES = [(0.0, 2.0e-3), (0.0, 3.0e-3), (-0.6, 2.0e-3), (0.6, 3.0e-3)]


@pytest.mark.parametrize("x5,dtu", CASES)
def test_noise_free_pair_lands_where_predicted(x5, dtu):
    p = _friction(x5)
    t_off = brake_timing(p, dtu, MARGIN)
    assert t_off is not None
    dc, t_b, t_cz2, t_stop = braked_response(p, dtu, t_off)
    sim_dc, sim_stop, _ = _simulate(p, dtu, t_off)
    assert sim_dc == pytest.approx(dc, rel=1e-9)
    assert abs(sim_stop - t_stop) <= 1e-9
    single = pulse_response(p, dtu)
    assert t_stop < single.t_stop and dc < single.delta_c          # it does brake
    # the timing: the velocity left at the end of the reverse current is r_b SDs of the w2 spread
    _, _, st = _simulate(p, dtu, t_off, until=t_cz2)
    sd = math.sqrt(p.alpha**2 * p.sigma2_sq * (t_cz2 - t_b))
    assert st.x[X2] == pytest.approx(MARGIN * sd, rel=1e-7)


def test_no_brake_for_flyback_stops_or_without_friction_noise():
    assert brake_timing(BASE, 0.95e-3, MARGIN) is None                # stops during the flyback
    assert brake_timing(BASE.replace(friction_noise_psd=0.0), 3e-3, MARGIN) is None


def test_predictor_partials_hold_the_reverse_drive_fixed():
    p = _friction(0.0)
    pred = Predictor(p, brake_margin=MARGIN).predict(p.stiction, p.coulomb, 2.5e-3)
    assert pred.t_off is not None
    h = 1e-4
    up = braked_response(p.with_friction(p.stiction, p.coulomb + h), 2.5e-3, pred.t_off)
    assert pred.H_b[0] == pytest.approx((up[0] - pred.delta_c) / h, rel=1e-9)
    assert pred.t_current_zero > pulse_response(p, 2.5e-3).t_current_zero


def _single_dtu_with_mean(p, mean):
    lo, hi = 0.5e-3, 6e-3
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        r = pulse_response(p, mid)
        n = pulse_noise(BASE, p.stiction, p.coulomb, mid, r.t_breakaway, r.t_current_zero, r.t_stop)
        lo, hi = (mid, hi) if r.delta_c + n.bias < mean else (lo, mid)
    return lo


@pytest.mark.parametrize("x5,dtu,ratio", [(0.0, 3.0e-3, 0.92), (-0.6, 2.0e-3, 1.0)])
def test_pair_scatters_less_than_the_single_pulse_of_the_same_mean(x5, dtu, ratio):
    n = 600
    p = _friction(x5)
    t_off = brake_timing(p, dtu, MARGIN)
    pair = np.array([_simulate(p, dtu, t_off, seed=7000 + i)[0] for i in range(n)])
    dtu_1 = _single_dtu_with_mean(p, pair.mean())
    single = np.array([pulse_response(p, dtu_1, seed=9000 + i).delta_c for i in range(n)])
    se = math.sqrt((pair.var(ddof=1) + single.var(ddof=1)) / n)
    assert abs(pair.mean() - single.mean()) <= 3 * se, (pair.mean() * 1e6, single.mean() * 1e6)
    assert pair.std(ddof=1) < ratio * single.std(ddof=1), (pair.std() * 1e6, single.std() * 1e6)


@pytest.mark.parametrize("x5,dtu", [(0.0, 2.0e-3), (-0.6, 2.0e-3)])
def test_pair_noise_model_against_monte_carlo(x5, dtu):
    n = 2000
    p = _friction(x5)
    t_off = brake_timing(p, dtu, 1.0, min_ratio=1.5)
    dc, t_b, t_cz2, t_stop = braked_response(p, dtu, t_off)
    model = braked_pulse_noise(BASE, p.stiction, p.coulomb, dtu, t_b, t_cz2, t_stop)
    d = np.array([_simulate(p, dtu, t_off, seed=20000 + i)[0] for i in range(n)])
    sd = d.std(ddof=1)
    assert abs(dc + model.bias - d.mean()) <= 3.0 * sd / math.sqrt(n) + 0.06 * sd
    assert 0.85 <= model.variance / sd**2 <= 1.15, (math.sqrt(model.variance) * 1e6, sd * 1e6)


def test_timing_is_the_root_of_the_margin_condition():
    """t_off against scipy's brentq on g(t_off) = v(t_cz2) − r_b·√(s²(t_cz2 − t_b)), and the
    capped t_off against brentq on t_cz2(t_off) = 0.8 τs, over random plants and pulses."""
    from scipy.optimize import brentq

    from controllers.solnic.braking import _pair

    p = PlantParams()
    U, t3, a = p.u_max, p.motor_time_constant, p.alpha
    cap = 0.8 * p.sample_period
    rng = np.random.default_rng(11)
    roots = capped = 0
    for _ in range(300):
        ks = rng.uniform(0.3, 3.5)
        kc = rng.uniform(0.05, ks)
        dtu = rng.uniform(0.5e-3, 3.5e-3)
        margin = rng.uniform(0.5, 3.0)
        sigma2_sq = rng.choice([5e-5, 2e-4, 4e-4, 8e-4])
        q = p.replace(stiction=ks, coulomb=kc, friction_noise_psd=sigma2_sq)
        t_off = brake_timing(q, dtu, margin)
        if t_off is None:
            continue
        x3_on = -U * math.expm1(-dtu / t3)
        t_cz = dtu + t3 * math.log1p(x3_on / U)
        t_b = -t3 * math.log1p(-ks / U)
        s2 = a * a * q.sigma2_sq

        def t_cz2(t):
            x3 = -U + (x3_on + U) * math.exp(-(t - dtu) / t3)
            return t + t3 * math.log((U - x3) / U)

        t_cap = brentq(lambda t: t_cz2(t) - cap, t_cz, cap, xtol=1e-16)

        def g(t):
            r = _pair(dtu, t, U, t3, a, ks, kc)
            return r[4] - margin * math.sqrt(s2 * (r[2] - t_b))

        if g(t_cap) >= 0:
            capped += 1
            assert t_off == pytest.approx(t_cap, abs=1e-14)
        else:
            roots += 1
            ref = brentq(g, t_cz * (1 + 1e-15), t_cap, xtol=1e-16, rtol=1e-15)
            assert abs(t_off - ref) <= 1e-14
            assert g(t_off) > 0.0                  # the brake never exceeds the margin
    assert roots > 50 and capped > 20
