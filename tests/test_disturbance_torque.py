"""The Ornstein–Uhlenbeck disturbance torque d on the load (SPEC §11, plant.multimode.disturbed).

* Φ(h) and the noise covariance of each mode against ``scipy.linalg.expm`` and Van Loan's
  construction (and, for a long step where Van Loan cancels, ``quad_vec`` of Φ·Qc·Φᵀ), with the
  drift matrix written out here from the equations, not taken from the module.
* With ``disturbance_torque_std`` = 0 (τd set or not) the family is the multimode plant bit for bit.
* A held shaft broken loose by d alone: breakaway time and Δc (mean, 95th percentile) against a
  fine Euler–Maruyama simulation written here, within Monte-Carlo confidence limits.
* Bad input names the field; through a matrix file, ``file:line: key``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg

from bench.matrix import MatrixError, load_matrix
from plant import DriveCommand, DriveType, PlantParams
from plant.multimode import disturbed, disturbed_loop
from plant.multimode.interval import advance as multimode_advance
from plant.params import as_definition
from plant.protocol import get_family
from plant.randomness import NoiseStream
from plant.state import EventKind, PlantState, SimOptions
from tests.cli_helpers import cli

_P = PlantParams(disturbance_torque_std=0.3, disturbance_torque_tau=0.02)


def _drift(p: PlantParams, mode: int) -> tuple[np.ndarray, np.ndarray]:
    """A, Qc on [x1, x2, x3, x4, x5, d, kc, u] from SPEC §2 and §11 (independent of the module)."""
    a = 1.0 / p.inertia
    A = np.zeros((8, 8))
    Qc = np.zeros((8, 8))
    A[0, 3] = -1.0                                   # ẋ1 = x2 − x4
    A[2, 2], A[2, 7] = -1.0 / p.motor_time_constant, 1.0 / p.motor_time_constant
    A[3, 3] = -1.0 / p.command_velocity_tau
    A[5, 5] = -1.0 / p.disturbance_torque_tau
    Qc[3, 3] = 2.0 * p.command_velocity_std ** 2 / p.command_velocity_tau
    Qc[5, 5] = 2.0 * p.disturbance_torque_std ** 2 / p.disturbance_torque_tau
    if mode != 2:
        f = 1.0 if mode == 3 else -1.0               # direction of motion: friction opposes it
        A[0, 1] = 1.0
        A[1, 2], A[1, 5] = a, a                      # x3 and d drive the load
        A[1, 4], A[1, 6] = -f * a, -f * a            # kc + x5 oppose the motion
        A[4, 4] = -1.0 / p.correlated_friction_tau
        Qc[1, 1] = a * a * p.friction_noise_psd
        Qc[4, 4] = 2.0 * p.correlated_friction_std ** 2 / p.correlated_friction_tau
    return A, Qc


@pytest.mark.parametrize("mode", [1, 2, 3])
def test_transition_and_covariance_are_expm_and_van_loan(mode):
    A, Qc = _drift(_P, mode)
    n = 8
    for h in (1e-6, 1e-4, 3e-3, 0.01):
        step = disturbed.transition(_P, mode, h)
        np.testing.assert_allclose(step.phi, scipy.linalg.expm(A * h), rtol=1e-12, atol=1e-15)
        M = np.zeros((2 * n, 2 * n))
        M[:n, :n], M[:n, n:], M[n:, n:] = -A, Qc, A.T
        F = scipy.linalg.expm(M * h)
        Q = F[n:, n:].T @ F[:n, n:]
        scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q))) + 1e-300
        assert np.max(np.abs(step.Q - Q) / scale) < 1e-9, h
        # the minimal factor reproduces the covariance
        f = step.factor
        np.testing.assert_allclose(f.A @ f.A.T, step.Q, rtol=1e-9, atol=1e-12 * np.abs(step.Q).max())
    h = 0.7      # long step: Van Loan cancels there, so integrate Φ·Qc·Φᵀ directly
    Q, _ = scipy.integrate.quad_vec(lambda v: (lambda E: E @ Qc @ E.T)(scipy.linalg.expm(A * v)), 0.0, h,
                                    epsrel=1e-12, epsabs=0.0, points=[0.02, 0.1])
    step = disturbed.transition(_P, mode, h)
    scale = np.sqrt(np.outer(np.diag(Q), np.diag(Q))) + 1e-300
    assert np.max(np.abs(step.Q - Q) / scale) < 1e-9
    np.testing.assert_allclose(step.phi, scipy.linalg.expm(A * h), rtol=1e-11, atol=1e-14)


def _pulse_train(family, p, x0, n, seed, drive=DriveType.BRIDGE):
    ns = NoiseStream.from_seed(seed)
    s = PlantState(0.0, x0, 2, False)
    out = []
    for k in range(n):
        lvl = (p.u_max if k % 7 == 0 else -p.u_max if k % 7 == 3 else 0.0)
        r = (family.step if family else lambda *a, **k: multimode_advance(*a, **k))(
            s, DriveCommand.hold(lvl, drive), p, ns, SimOptions(), record=True)
        out.append((r.state.t, r.state.x.tobytes(), r.peak_abs_error, r.int_abs_current, r.n_events, r.n_substeps))
        s = r.state
    return out


def test_zero_std_is_the_multimode_plant_bit_for_bit():
    table = PlantParams()
    for quiet in (PlantParams(disturbance_torque_tau=0.02), PlantParams(disturbance_torque_std=0.0)):
        fam = get_family("multimode")
        x0 = fam.initial_state(quiet, 0.1).x
        assert x0.shape == (6,)
        assert _pulse_train(fam, quiet, x0, 120, 3) == _pulse_train(None, table, x0, 120, 3)
        assert fam.law_loop(quiet) is fam.linear_law_loop
    assert as_definition(table) == as_definition(PlantParams(disturbance_torque_std=0.0))
    assert "disturbance_torque_std" not in as_definition(table)
    fam = get_family("multimode")
    assert fam.initial_state(_P, 0.0).x.shape == (7,)
    # the disturbed plant has its own compiled law loop (ideal sensor, no delay only)
    assert fam.law_loop(_P) is disturbed_loop.run_law
    assert fam.law_loop(PlantParams(disturbance_torque_std=0.3, disturbance_torque_tau=0.02, quantization=1e-6)) is None


def _held_shaft(std=0.5, tau=0.02):
    return PlantParams(disturbance_torque_std=std, disturbance_torque_tau=tau, friction_noise_psd=0.0,
                       correlated_friction_std=0.0, command_velocity_std=0.0, command_velocity_initial=0.0,
                       measurement_noise_std=0.0)


_U = 1.35     # held torque: below k̄c (1.4), so the shaft stops again; d must exceed ks − u = 0.75


def _exact_breakaways(p, n, horizon):
    """(breakaway time, Δc to the first stick) of n seeds of the exact plant; nan if beyond horizon."""
    fam = get_family("multimode")
    cmd = DriveCommand.hold(_U, DriveType.LINEAR)
    T, DC = np.full(n, np.nan), np.full(n, np.nan)
    for seed in range(n):
        ns = NoiseStream.from_seed(10_000 + seed)
        x = np.array([0.0, 0.0, _U, 0.0, 0.0, _U, 0.0])
        x.flags.writeable = False
        s = PlantState(0.0, x, 2, False)
        tb = x1b = None
        while s.t < horizon:
            r = fam.step(s, cmd, p, ns, SimOptions(), duration=0.05, record=True)
            ev = r.events
            if tb is None:
                k = np.flatnonzero(ev["kind"] == int(EventKind.BREAKAWAY))
                if k.size:
                    tb, x1b = ev["t"][k[0]], ev["x1"][k[0]]
                    ev = {key: v[k[0]:] for key, v in ev.items()}
            if tb is not None:
                k = np.flatnonzero(ev["kind"] == int(EventKind.STICK))
                if k.size:
                    if ev["t"][k[0]] <= horizon:
                        T[seed], DC[seed] = tb, ev["x1"][k[0]] - x1b
                    break
            assert r.status.value == "ok"
            s = r.state
    return T, DC


def _euler_maruyama(p, n, horizon, dt, seed, corrected=False):
    """The same experiment on a fine grid: d by its exact OU step, x2 and x1 by Euler; the stuck
    shaft breaks away at the first grid point with |u + d| > ks, sticks at the first grid point
    where x2 has reached 0 with |u + d| ≤ ks (reflected while u + d still exceeds ks forward).
    ``corrected``: the breakaway barrier moved in by 0.5826·(d's step deviation), the continuity
    correction of a discretely monitored barrier (Broadie, Glasserman & Kou, Math. Finance 7(4),
    1997), which removes the grid's O(√dt) lateness."""
    rng = np.random.default_rng(seed)
    a, kc, ks = 1.0 / p.inertia, p.coulomb, p.stiction
    tau, sd = p.disturbance_torque_tau, p.disturbance_torque_std
    rho = math.exp(-dt / tau)
    kick = sd * math.sqrt(1.0 - rho * rho)
    shift = 0.5826 * kick if corrected else 0.0
    d = np.zeros(n)
    x1 = np.zeros(n)
    x2 = np.zeros(n)
    moving = np.zeros(n)           # 0 stuck, ±1 moving forward/backward
    T, DC, x1b = np.full(n, np.nan), np.full(n, np.nan), np.zeros(n)
    broke = np.zeros(n, bool)
    done = np.zeros(n, bool)
    for k in range(1, int(round(horizon / dt)) + 1):
        t = k * dt
        m = moving != 0
        x1 += x2 * dt
        x2 += np.where(m, a * (_U + d - moving * kc) * dt, 0.0)
        d = rho * d + kick * rng.standard_normal(n)
        g = _U + d
        start = (~m) & (~done) & (np.abs(g) > ks - shift) & (~broke)
        if start.any():
            T[start], x1b[start], broke[start] = t, x1[start], True
            moving[start] = np.sign(g[start])
        crossed = m & (moving * x2 <= 0.0)
        if crossed.any():
            x2[crossed] = 0.0
            fwd = crossed & (moving * g > ks)                      # reflected
            rev = crossed & (-moving * g > ks)
            moving[rev] = -moving[rev]
            stick = crossed & ~fwd & ~rev
            DC[stick] = x1[stick] - x1b[stick]
            moving[stick] = 0.0
            done |= stick
        if done.all():
            break
    T[~done] = np.nan
    return T, DC


def _compare(mine, ref, what, bias):
    """Mean within 4 standard errors (plus a stated discretization bias of the reference), and
    the 95th percentile by the two-sample quantile test: the fraction of the reference below
    ours is 0.95 within 4 binomial standard errors."""
    mine, ref = mine[np.isfinite(mine)], ref[np.isfinite(ref)]
    se = math.sqrt(mine.var(ddof=1) / mine.size + ref.var(ddof=1) / ref.size)
    assert abs(mine.mean() - ref.mean()) <= 4.0 * se + bias * abs(ref.mean()), (what, mine.mean(), ref.mean(), se)
    q = np.percentile(mine, 95)
    frac = np.mean(ref <= q)
    band = 4.0 * math.sqrt(0.95 * 0.05 * (1.0 / mine.size + 1.0 / ref.size))
    assert abs(frac - 0.95) <= band + bias, (what, q, np.percentile(ref, 95), frac, band)
    return mine.mean(), ref.mean(), q, np.percentile(ref, 95)


def _breakaway_statistics(n_exact, n_ref, dt):
    """Held at u = 1.35 ozf·in, d of sd 0.5 ozf·in and τd = 20 ms: the shaft breaks loose when d
    exceeds 0.75 and slides until d has decayed; seeds up to 1.5 s."""
    p = _held_shaft()
    horizon = 1.5
    T, DC = _exact_breakaways(p, n_exact, horizon)
    assert np.isfinite(T).mean() > 0.8            # most seeds break loose and stop within the horizon
    Tr, DCr = _euler_maruyama(p, n_ref, horizon, dt, 7)
    # the grid sees a passage only at its points: it breaks away late by ≈ 0.58·σ_d·√(2·dt/τd)
    # of torque (Siegmund): ≈ 0.009 ozf·in of the 0.75 gap at 10 µs, ~3 % on the mean time (allowed: 4 %),
    # ~6 % at 50 µs (allowed: 8 %)
    bias = 0.04 if dt <= 1e-5 else 0.08
    return _compare(T, Tr, "breakaway time", bias), _compare(DC, DCr, "Δc", bias)


def test_disturbed_breakaway_statistics_match_euler_maruyama_lean():
    _breakaway_statistics(16, 800, 5e-5)


@pytest.mark.slow
def test_disturbed_breakaway_statistics_match_euler_maruyama():
    _breakaway_statistics(400, 4000, 1e-5)


@pytest.mark.slow
def test_disturbed_breakaway_is_unbiased_against_corrected_euler_maruyama():
    """Issue 22's suspected early breakaway (a 200-seed probe: 82.5 ± 6.1 ms against EM's 95.4 ±
    1.6 ms), decided with 8000 exact paths against 16000 Euler–Maruyama paths at 20 µs whose
    barrier carries the continuity correction (no O(√dt) lateness left; 1 % allowed for the
    rest). Measured once (10000 exact, 20000 EM per step): exact mean 90.7 ± 1.0 ms, p95 277 ±
    5 ms; plain EM 97.2 / 95.6 / 93.7 ± 0.7 ms at 40 / 20 / 10 µs, 90.4 ± 1.6 ms extrapolated in
    √dt to 0; corrected EM 90.9 ± 0.7 ms at 40 µs. No bias: the probe was a fluctuation measured
    against the grid's late reference. A 10 % early bias fails this test (4 SE ≈ 6 %)."""
    p = _held_shaft()
    T, DC = _exact_breakaways(p, 8000, 1.5)
    Tr, DCr = _euler_maruyama(p, 16000, 1.5, 2e-5, 11, corrected=True)
    _compare(T, Tr, "breakaway time", 0.01)
    _compare(DC, DCr, "Δc", 0.01)


@pytest.mark.parametrize("fields, name", [
    ({"disturbance_torque_std": -0.1, "disturbance_torque_tau": 0.02}, "disturbance_torque_std"),
    ({"disturbance_torque_std": 0.3}, "disturbance_torque_tau"),
    ({"disturbance_torque_std": 0.3, "disturbance_torque_tau": -1.0}, "disturbance_torque_tau"),
    ({"disturbance_torque_std": float("nan"), "disturbance_torque_tau": 0.02}, "disturbance_torque_std"),
])
def test_bad_disturbance_names_the_field(fields, name):
    with pytest.raises(ValueError, match=rf"^PlantParams\.{name} "):
        PlantParams(**fields)


@pytest.mark.parametrize("family", ["two-mass", "stribeck", "lugre"])
def test_every_family_takes_the_disturbance_and_names_a_bad_field(family):
    Params = get_family(family).Params
    p = Params(disturbance_torque_std=0.3, disturbance_torque_tau=0.02)
    assert get_family(family).initial_state(p, 0.0).x.shape[0] == \
        get_family(family).initial_state(Params(), 0.0).x.shape[0] + 1      # d rides along
    for fields, name in [({"disturbance_torque_std": -0.1, "disturbance_torque_tau": 0.02}, "disturbance_torque_std"),
                         ({"disturbance_torque_std": 0.3}, "disturbance_torque_tau"),
                         ({"disturbance_torque_std": 0.3, "disturbance_torque_tau": -1.0}, "disturbance_torque_tau")]:
        with pytest.raises(ValueError, match=rf"^\w*Params\.{name} "):    # the field, by name
            Params(**fields)


_BAD = """[matrix]
controllers = ["linear"]
scenarios = ["x"]
seeds = [0]

[scenarios.x]
base = "disturbed"
disturbance_torque_std = -0.5
"""


def test_bad_disturbance_in_a_matrix_names_file_line_and_key(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(_BAD)
    with pytest.raises(MatrixError) as info:
        load_matrix(path, check_resets=False)
    assert str(info.value).startswith(f"{path}:8: scenarios.x.disturbance_torque_std: "), str(info.value)
    for family in ("two-mass", "stribeck", "lugre"):
        path.write_text(_BAD.replace("base = \"disturbed\"", f"base = \"disturbed\"\nplant = \"{family}\""))
        with pytest.raises(MatrixError) as info:
            load_matrix(path, check_resets=False)
        assert str(info.value).startswith(f"{path}:9: scenarios.x.disturbance_torque_std: "), str(info.value)


@pytest.mark.slow
def test_bad_disturbance_is_exit_2_through_the_cli(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(_BAD.replace("disturbance_torque_std = -0.5", "disturbance_torque_tau = 0.0"))
    proc = cli("run", "--matrix", path, "--out", tmp_path / "out")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}:8: scenarios.x.disturbance_torque_tau:" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out").exists()


def test_noise_free_breakaway_is_the_root_of_the_decaying_disturbance():
    """Noise off (as the oracle's own pulse law runs it): the stuck shaft breaks away when
    x3(t) + d(t) = ks, x3 = u + (x3(0) − u)·e^(−t/τ3), d = d(0)·e^(−t/τd) — the root from brentq
    (it used to end in an AttributeError: the bisection drew noise without a stream)."""
    import scipy.optimize

    p = _held_shaft(std=0.5, tau=0.02)
    u, d0 = 2.5, -0.5
    x = np.array([0.0, 0.0, 0.0, 0.0, 0.0, u, d0])
    x.flags.writeable = False
    s = PlantState(0.0, x, 2, False)
    opts = SimOptions(noise=False)
    r = get_family("multimode").step(s, DriveCommand.hold(u, DriveType.LINEAR), p, None, opts,
                                     duration=0.05, record=True)
    k = np.flatnonzero(r.events["kind"] == int(EventKind.BREAKAWAY))
    tau3 = p.motor_time_constant
    g = lambda t: u * (1 - math.exp(-t / tau3)) + d0 * math.exp(-t / 0.02) - p.stiction
    t_true = scipy.optimize.brentq(g, 0.0, 0.05, xtol=1e-15)
    assert k.size and abs(r.events["t"][k[0]] - t_true) <= max(opts.bisection_tol, 1e-12)
