"""Lead/lag design on the discretized loop, and the linear controller in closed loop.

Oracles: a ZOH plant built here with scipy's expm, dense frequency grids, the closed-form
step response of 1/((τ3 s + 1) J s²), python-control's forced_response, and (2-1)/(2-6).
"""

from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest
import scipy.linalg

from controllers.base import get_controller
from controllers.linear import LAG_RATIO_CAP, LinearController, design_linear, highest_crossover
from plant.params import PlantParams

TABLE_2_1 = PlantParams()
RATIO_2 = PlantParams(stiction=2.8, coulomb=1.4)


def _zoh_plant(p: PlantParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact ZOH discretization of c'' = x3/J, x3' = (u − x3)/τ3 by the augmented expm."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0 / p.inertia], [0.0, 0.0, -1.0 / p.motor_time_constant]])
    B = np.array([0.0, 0.0, 1.0 / p.motor_time_constant])
    M = np.zeros((4, 4))
    M[:3, :3], M[:3, 3] = A, B
    E = scipy.linalg.expm(M * p.sample_period)
    return E[:3, :3], E[:3, 3], np.array([1.0, 0.0, 0.0])


def _loop_response(design, omega: np.ndarray) -> np.ndarray:
    """C(e^{jωτs})·Pd(e^{jωτs}) with Pd from :func:`_zoh_plant`, not from the design."""
    p = design.params
    Ad, Bd, Cd = _zoh_plant(p)
    z = np.exp(1j * omega * p.sample_period)
    # Cd (zI − Ad)⁻¹ Bd = [det(zI − Ad + Bd Cd) − det(zI − Ad)] / det(zI − Ad)
    den = np.poly(Ad)
    num = np.poly(Ad - np.outer(Bd, Cd)) - den
    pd = np.polyval(num, z) / np.polyval(den, z)
    comp = np.polyval(design.compensator.num[0][0], z) / np.polyval(design.compensator.den[0][0], z)
    return comp * pd


def _grid_margins(design, n: int = 40_000) -> tuple[float, list[float], list[float]]:
    """(worst phase margin [deg], gain crossovers, upper gain margins [dB]) on a dense grid."""
    nyq = math.pi / design.params.sample_period
    w = np.geomspace(1e-2, nyq * (1 - 1e-9), n)
    L = _loop_response(design, w)
    mag = np.abs(L)
    phase = np.unwrap(np.angle(L))
    k = np.flatnonzero(np.diff(np.sign(mag - 1.0)))
    crossings, pms = [], []
    for i in k:
        f = (1.0 - mag[i]) / (mag[i + 1] - mag[i])  # linear interpolation in the grid cell
        crossings.append(w[i] + f * (w[i + 1] - w[i]))
        ph = phase[i] + f * (phase[i + 1] - phase[i])
        pms.append(math.degrees((ph + 2 * math.pi) % (2 * math.pi) - math.pi))  # 180° + ∠L
    w_c = crossings[int(np.argmin(pms))]
    j = np.flatnonzero(np.diff(np.sign(np.sin(phase))) != 0)  # phase through ±180°
    gms = [-20 * math.log10(mag[i]) for i in j if w[i] > w_c and np.cos(phase[i]) < 0]
    return min(pms), crossings, gms


def _closed_loop_poles(design) -> np.ndarray:
    """Eigenvalues of the loop built from the expm plant and scipy's realization of C(z)."""
    import scipy.signal

    Ad, Bd, Cd = _zoh_plant(design.params)
    Ac, Bc, Cc, Dc = scipy.signal.tf2ss(design.compensator.num[0][0], design.compensator.den[0][0])
    # u = −(Cc xc + Dc c),  xc⁺ = Ac xc + Bc c,  c = Cd xp
    top = np.hstack([Ad - np.outer(Bd, Dc[0, 0] * Cd), -np.outer(Bd, Cc[0])])
    bottom = np.hstack([np.outer(Bc[:, 0], Cd), Ac])
    return np.linalg.eigvals(np.vstack([top, bottom]))


DESIGNS = [
    pytest.param(TABLE_2_1, {}, id="table-2-1"),
    pytest.param(RATIO_2, {}, id="ratio-2"),
    pytest.param(TABLE_2_1, {"crossover": 20.0, "lag_ratio": 2.0}, id="wc20-L2"),
    pytest.param(TABLE_2_1, {"crossover": 35.0, "lag_ratio": 24.0}, id="wc35-L24"),
    pytest.param(TABLE_2_1, {"integral": True}, id="integral"),
    pytest.param(PlantParams(inertia=2.0), {"phase_margin_deg": 55.0}, id="J2-pm55"),
]


@pytest.mark.parametrize("params, options", DESIGNS)
def test_phase_margin_on_dense_grid(params: PlantParams, options: dict) -> None:
    d = design_linear(params, **options)
    target = options.get("phase_margin_deg", 45.0)
    pm, crossings, gms = _grid_margins(d)
    assert pm >= target - 1e-3
    assert d.phase_margin_deg == pytest.approx(pm, abs=1e-3)
    assert d.crossover_rad_s == pytest.approx(d.crossover_target_rad_s, rel=1e-6)
    assert min(crossings, key=lambda w: abs(w - d.crossover_rad_s)) == pytest.approx(
        d.crossover_rad_s, rel=1e-4)
    assert min(gms) == pytest.approx(d.gain_margin_db, abs=0.01)
    poles = _closed_loop_poles(d)
    assert np.max(np.abs(poles)) < 1.0
    assert d.stable


@pytest.mark.parametrize("params, expected", [(TABLE_2_1, 6.0), (RATIO_2, 4.0)])
def test_lag_ratio_follows_bohacek_tuteur(params: PlantParams, expected: float) -> None:
    d = design_linear(params)
    assert d.lag_ratio == pytest.approx(expected, rel=1e-12)  # Lmax = 2ks/(ks − kc)  (2-1)
    lag = d.sections[0]
    dc = np.polyval(lag.num[0][0], 1.0) / np.polyval(lag.den[0][0], 1.0)
    hf = np.polyval(lag.num[0][0], -1.0) / np.polyval(lag.den[0][0], -1.0)
    assert dc == pytest.approx(expected, rel=1e-9)
    # the lag network costs little at ωc: its upper corner is a decade below
    z_c = np.exp(1j * d.crossover_rad_s * params.sample_period)
    lag_phase = np.degrees(np.angle(np.polyval(lag.num[0][0], z_c) / np.polyval(lag.den[0][0], z_c)))
    assert -7.0 < lag_phase < 0.0
    assert abs(hf) == pytest.approx(1.0, rel=1e-9)
    # static stiffness |C(1)| = K·L, below Jωc²·L  (2-5)
    s = d.summary()
    c1 = abs(np.polyval(d.compensator.num[0][0], 1.0) / np.polyval(d.compensator.den[0][0], 1.0))
    assert s["static_stiffness"] == pytest.approx(c1, rel=1e-9)
    assert c1 <= params.inertia * d.crossover_rad_s**2 * expected
    assert s["lag_ratio_limit"] == pytest.approx(expected)


def test_equal_friction_uses_the_cap_and_integral_is_infinite() -> None:
    flat = PlantParams(stiction=1.4, coulomb=1.4)
    assert design_linear(flat).lag_ratio == LAG_RATIO_CAP
    d = design_linear(TABLE_2_1, integral=True)
    assert math.isinf(d.lag_ratio) and math.isinf(d.static_stiffness)
    assert np.any(np.isclose(np.roots(d.compensator.den[0][0]), 1.0, atol=1e-12))


def test_bounds_in_summary() -> None:
    s = design_linear(TABLE_2_1).summary()
    w_c = s["crossover_rad_s"]
    assert s["bound_at_crossover_rad"] == pytest.approx((2.1 - 1.4) / (2 * 0.5 * w_c**2), rel=1e-6)
    assert s["bound_at_nyquist_rad"] == pytest.approx(7.09e-6, abs=0.005e-6)  # thesis: 7.09 µrad
    for key in ("crossover_rad_s", "phase_margin_deg", "gain_margin_db", "static_stiffness",
                "lag_ratio", "lag_ratio_limit", "bound_at_crossover_rad", "bound_at_nyquist_rad"):
        assert key in s


def test_zoh_plant_matches_continuous_step_at_samples() -> None:
    p = TABLE_2_1
    d = design_linear(p)
    n = np.arange(200)
    t = n * p.sample_period
    tau, J = p.motor_time_constant, p.inertia
    exact = (t**2 / 2 - tau * t + tau**2 * (-np.expm1(-t / tau))) / J  # c(t) for u = 1
    _, y = ct.step_response(d.plant, T=t)
    np.testing.assert_allclose(np.squeeze(y), exact, rtol=1e-9, atol=1e-15)


def test_default_crossover_is_the_highest_with_6db_gain_margin() -> None:
    d = design_linear(TABLE_2_1)
    _, _, gms = _grid_margins(d)
    assert min(gms) >= 6.0 - 1e-3
    assert d.lead_stages <= 2
    above = design_linear(TABLE_2_1, d.crossover_rad_s + 1.0)
    _, _, gms_above = _grid_margins(above)
    assert min(gms_above) < 6.0
    assert d.noise_drive_rms < 0.05 * TABLE_2_1.u_max


def test_controller_realization_matches_transfer_function() -> None:
    ctrl = LinearController()
    ctrl.reset(TABLE_2_1, np.random.default_rng(0))
    d = ctrl.design
    pulse = np.zeros(300)
    pulse[0] = 1e-5  # rad, small enough that no output clips
    u = np.array([ctrl.step(y).segments[0][1] for y in pulse])
    _, h = ct.impulse_response(d.compensator, T=np.arange(300) * TABLE_2_1.sample_period)
    expected = -np.squeeze(h) * TABLE_2_1.sample_period * 1e-5  # python-control scales by 1/dt
    np.testing.assert_allclose(u, expected, rtol=1e-9, atol=1e-12 * np.max(np.abs(expected)))


def test_controller_clips_and_reports() -> None:
    ctrl = LinearController()
    ctrl.reset(TABLE_2_1, np.random.default_rng(0))
    cmd = ctrl.step(1.0)  # 1 rad of error: far beyond u_max
    assert cmd.segments == ((0.0, -TABLE_2_1.u_max),)
    assert cmd.drive.value == "linear"
    assert ctrl.summary()["lag_ratio"] == pytest.approx(6.0)
    assert get_controller("linear") is LinearController


@pytest.mark.parametrize("kwargs, match", [
    ({"crossover": -1.0}, "crossover"),
    ({"crossover": math.nan}, "crossover"),
    ({"lag_ratio": 0.5}, "lag_ratio"),
    ({"lag_ratio": math.inf}, "lag_ratio"),
    ({"phase_margin_deg": 95.0}, "phase_margin_deg"),
    ({"integral": "yes"}, "integral"),
    ({"integral": True, "lag_ratio": 4.0}, "lag_ratio"),
    ({"lag_corner_fraction": 1.5}, "lag_corner_fraction"),
])
def test_controller_option_errors(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        LinearController(**kwargs)


def test_design_errors() -> None:
    with pytest.raises(ValueError, match="crossover"):
        design_linear(TABLE_2_1, crossover=400.0)  # above π/τs
    with pytest.raises(ValueError, match="lead"):
        design_linear(TABLE_2_1, crossover=100.0, max_lead_phase_deg=20.0)  # > 4 lead stages
    with pytest.raises(ValueError, match="max_lead_phase_deg"):
        design_linear(TABLE_2_1, crossover=30.0, max_lead_phase_deg=95.0)
    with pytest.raises(ValueError, match="no feasible crossover"):
        highest_crossover(TABLE_2_1, min_gain_margin_db=80.0)


# --- closed loop --------------------------------------------------------------------------------

def test_frictionless_ramp_matches_forced_response() -> None:
    from bench.runner import run_closed_loop

    p = PlantParams(stiction=0.0, coulomb=0.0).noise_free()
    ctrl = LinearController()
    res = run_closed_loop(p, ctrl, duration_s=4.0, seed=0, noise=False, record=True)
    assert res.status == "ok"
    d = ctrl.design
    t = np.arange(res.samples["t"].size) * p.sample_period
    np.testing.assert_allclose(res.samples["t"], t, rtol=0, atol=1e-9)
    # closed loop from python-control: continuous plant sampled with ZOH, compensator sections
    G = ct.ss([[0, 1, 0], [0, 0, 1 / p.inertia], [0, 0, -1 / p.motor_time_constant]],
              [[0], [0], [1 / p.motor_time_constant]], [[1, 0, 0]], [[0]])
    Pd = ct.sample_system(G, p.sample_period, method="zoh")
    C = ct.ss(ct.tf([d.gain], [1], p.sample_period))
    for sec in d.sections:
        C = C * ct.ss(sec)
    S = ct.feedback(ct.ss([], [], [], [[1.0]], p.sample_period), C * Pd)  # x1 = −S·r
    # r(t) = ∫x4: x4 decays with τ4 (ẋ4 = −x4/τ4), so r is the exact OU mean, not t·x4(0)
    r = p.command_velocity_initial * p.command_velocity_tau * -np.expm1(-t / p.command_velocity_tau)
    x1 = np.squeeze(ct.forced_response(S, T=t, U=-r).outputs)
    scale = np.max(np.abs(x1))
    assert scale > 1e-7
    np.testing.assert_allclose(res.samples["x1"], x1, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("noise", [False, True])
def test_table_2_1_ramp_peak_error_exceeds_bound(noise: bool) -> None:
    from bench.runner import run_closed_loop

    p = TABLE_2_1
    ctrl = LinearController()
    res = run_closed_loop(p, ctrl, duration_s=100.0, warmup_s=20.0, seed=0, noise=noise)
    assert res.status == "ok"
    assert res.metrics["n_stick_slip"] >= 1
    bound = p.classical_bound(ctrl.design.crossover_rad_s)  # (2-6) at the design's ωc
    ratio = res.metrics["peak_error_rad"] / bound
    print(f"noise={noise}: peak {res.metrics['peak_error_rad']:.4g} rad, "
          f"bound {bound:.4g} rad, ratio {ratio:.3f}")
    assert ratio >= 1.0


@pytest.mark.parametrize("n", [0, 1, 2, 3, 4])
def test_unrolled_compensator_step_is_the_state_space_recursion(n):
    """compensator_step(A, B, C, D) against the matrix recursion u = C·x + D·y, x⁺ = A·x + B·y."""
    from controllers.linear import compensator_step
    rng = np.random.default_rng(n)
    A, B, C, D = rng.normal(size=(n, n)) * 0.4, rng.normal(size=(n, 1)), rng.normal(size=(1, n)), rng.normal(size=(1, 1))
    law = compensator_step(A, B, C, D)
    x, xs = np.zeros(n), (0.0,) * n
    for y in rng.normal(size=50):
        u, xs = law(xs, float(y))
        u_ref = (C @ x + D[0] * y).item()
        x = A @ x + B[:, 0] * y
        assert u == pytest.approx(u_ref, rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(xs, x, rtol=1e-12, atol=1e-12)
