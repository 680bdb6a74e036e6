"""The two-mass family (SPEC §11) against independent truth.

* Φ(h) and the noise covariance against ``scipy.linalg.expm`` of the drift matrix written here
  from the equations, and Van Loan's method;
* noise-free pulse trains (bridge) and level sequences (linear amplifier) on five parameter
  sets, and closed-loop command replays, against ``solve_ivp`` (DOP853, rtol 1e-13) with
  events (tests/two_mass_reference.py): event times within 1e-12 s, x1 at the samples within
  1e-10 of the run's peak |x1|;
* a lightly damped shaft whose torque grazes ks between two coarse steps: a naive sign test
  on the grid sees nothing, the locator finds the first crossing (and solve_ivp confirms it);
* noisy stuck-breakaway and pulse statistics against a fine Euler–Maruyama reference;
* the stiff-shaft limit approaches the multimode plant;
* bad parameters: ValueError naming the field; exit 2 from a matrix file.
"""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

sys.path.insert(0, str(Path(__file__).resolve().parent))
from two_mass_reference import reference_interval  # noqa: E402

from plant.drive import DriveCommand, DriveType  # noqa: E402
from plant.protocol import get_family  # noqa: E402
from plant.randomness import NoiseStream  # noqa: E402
from plant.state import EventKind, PlantState, SimOptions, Status  # noqa: E402
from plant.two_mass.params import TwoMassParams  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
FAM = get_family("two-mass")
QUIET = SimOptions(noise=False)
KIND = {int(EventKind.BREAKAWAY): "breakaway", int(EventKind.STICK): "stick",
        int(EventKind.REVERSAL): "reversal", int(EventKind.FLYBACK_END): "flyback_end",
        int(EventKind.REFLECTION): "reflection"}


def shaft(freq_hz: float, zeta: float, ratio: float, **kw) -> TwoMassParams:
    """Table 2-1 with a shaft of the given free resonance, damping ratio and J_m = ratio·J."""
    J = kw.pop("inertia", 0.5)
    Jm = ratio * J
    mu = 1.0 / J + 1.0 / Jm
    w = 2 * math.pi * freq_hz
    p = TwoMassParams(inertia=J, motor_inertia=Jm, shaft_stiffness=w * w / mu, shaft_damping=2 * zeta * w / mu, **kw)
    assert p.damping_ratio == pytest.approx(zeta)
    return p


# Five shafts: the compliant scenario's, a lightly damped one (ζ = 0.01), a stiff one, a soft one
# with a heavy rotor, a nearly undamped one (ζ = 0.003), and ks close to kc.
PARAMS = {
    "compliant": TwoMassParams(),
    "light-250Hz": shaft(250.0, 0.01, 0.2),
    "stiff-300Hz": shaft(300.0, 0.05, 0.05),
    "soft-100Hz": shaft(100.0, 0.02, 0.5),
    "undamped-200Hz": shaft(200.0, 0.003, 0.1, stiction=1.6),
}


# --- parameters -------------------------------------------------------------------------------

@pytest.mark.parametrize("field, value, match", [
    ("motor_inertia", 0.0, r"TwoMassParams\.motor_inertia must be a finite number > 0"),
    ("motor_inertia", -1.0, r"TwoMassParams\.motor_inertia must be a finite number > 0"),
    ("shaft_stiffness", 0.0, r"TwoMassParams\.shaft_stiffness must be a finite number > 0"),
    ("shaft_stiffness", math.inf, r"TwoMassParams\.shaft_stiffness must be a finite number > 0"),
    ("shaft_damping", -0.1, r"TwoMassParams\.shaft_damping must be a finite number >= 0"),
    ("inertia", 0.0, r"PlantParams\.inertia must be > 0"),
])
def test_bad_parameters_name_the_field(field, value, match):
    with pytest.raises(ValueError, match=match):
        TwoMassParams(**{field: value})


def test_bad_parameter_in_a_matrix_file_exits_2_naming_the_field(tmp_path):
    matrix = tmp_path / "m.toml"
    matrix.write_text(textwrap.dedent("""
        [matrix]
        controllers = ["linear"]
        scenarios = ["bad"]
        seeds = [0]
        duration_s = 1
        warmup_s = 0

        [scenarios.bad]
        base = "thesis"
        plant = "two-mass"
        shaft_damping = -1.0
    """))
    proc = subprocess.run([sys.executable, "-m", "reports.cli", "run", "--matrix", str(matrix), "--out",
                           str(tmp_path / "out"), "--no-traces"], capture_output=True, text=True, cwd=ROOT,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 2, proc.stdout + proc.stderr
    err = proc.stdout + proc.stderr
    assert "shaft_damping" in err and "Traceback" not in err
    assert len([ln for ln in proc.stderr.splitlines() if ln.strip()]) == 1, proc.stderr
    assert not (tmp_path / "out" / "results.csv").exists()


def test_compliant_scenario_is_built_in_and_lightly_damped():
    from bench.scenarios import builtin_scenarios

    sc = builtin_scenarios()["compliant"]
    p = sc.params
    assert sc.family == "two-mass" and isinstance(p, TwoMassParams)
    assert 100.0 <= p.resonance / (2 * math.pi) <= 300.0
    assert 0.02 <= p.damping_ratio <= 0.05
    assert p.inertia == 0.5 and p.motor_inertia == pytest.approx(0.1 * p.inertia)


# --- Φ(h) and Q(h) ----------------------------------------------------------------------------

def drift(mode: int, p: TwoMassParams) -> np.ndarray:
    """F of X = [x1, x2, x3, x4, x5, kc, u, φ, ω_m] from SPEC §11's equations (stuck: x2, x5 clamped)."""
    a, Jm, k, c = 1 / p.inertia, p.motor_inertia, p.shaft_stiffness, p.shaft_damping
    F = np.zeros((9, 9))
    F[0, 1], F[0, 3] = 1.0, -1.0
    F[2, 2], F[2, 6] = -1 / p.motor_time_constant, 1 / p.motor_time_constant
    F[3, 3] = -1 / p.command_velocity_tau
    F[7, 8], F[7, 1] = 1.0, -1.0
    F[8, 2], F[8, 7], F[8, 8], F[8, 1] = 1 / Jm, -k / Jm, -c / Jm, c / Jm
    if mode == 2:
        F[0, 1] = F[7, 1] = F[8, 1] = 0.0
        return F
    s = 1.0 if mode == 3 else -1.0
    F[1, 7], F[1, 8], F[1, 1], F[1, 4], F[1, 5] = a * k, a * c, -a * c, -s * a, -s * a
    F[4, 4] = -1 / p.correlated_friction_tau
    return F


def van_loan(F: np.ndarray, Qc: np.ndarray, h: float) -> np.ndarray:
    n = F.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -F, Qc, F.T
    E = expm(M * h)
    Phi = E[n:, n:].T
    return Phi @ E[:n, n:]


@pytest.mark.parametrize("name", ["compliant", "light-250Hz", "stiff-300Hz"])
@pytest.mark.parametrize("mode", [1, 2, 3])
@pytest.mark.parametrize("h", [1e-5, 1e-4, 1.3e-3, 1e-2])
def test_transition_and_noise_against_expm_and_van_loan(name, mode, h):
    from plant.two_mass.interval import plan
    from plant.two_mass.motion import NB, process_noise, transition

    p = PARAMS[name]
    q, V, Vi, lam, *_ = plan(p, SimOptions())
    prm = p.kernel_record()[0]
    P = np.empty((9, 9))
    transition(mode, h, prm, q, V, Vi, lam, P)
    F = drift(mode, p)
    E = expm(F * h)
    if mode == 2:
        E[1, 1] = 0.0      # x2 clamped to 0 while stuck (3-22)
    scale = np.maximum(np.abs(E).max(axis=1, keepdims=True), 1e-300)
    assert np.max(np.abs(P - E) / scale) < 1e-11
    Q = np.empty((6, 6))
    process_noise(mode, h, prm, q, V, Vi, lam, Q)
    Qc = np.zeros((9, 9))
    Qc[3, 3] = p.sigma4_sq
    if mode != 2:
        Qc[1, 1] = p.alpha ** 2 * p.sigma2_sq
        Qc[4, 4] = p.sigma5_sq
    Qv = van_loan(F, Qc, h)[np.ix_(NB, NB)]
    d = np.sqrt(np.maximum(np.diag(Qv), 1e-300))
    corr_err = np.abs(Q - Qv) / np.outer(d, d)            # relative to the standard deviations
    assert np.max(corr_err[np.outer(d, d) > 0]) < 1e-8


# --- noise-free runs against solve_ivp --------------------------------------------------------

def _compare_run(p, commands, bridge, x0=None):
    """Run ``commands`` (one per interval) through the family and the reference; the worst
    event-time difference [s] and x1 difference relative to the run's peak |x1|."""
    p = p.noise_free()
    s = FAM.initial_state(p, 0.0) if x0 is None else x0
    y = [s.x[0], s.x[1], s.x[2], s.x[3], s.x[6], s.x[7]]
    mode, fb = s.mode, s.flyback
    worst_t, worst_x, peak, n_events = 0.0, 0.0, 0.0, 0
    for cmd in commands:
        r = FAM.step(s, cmd, p, None, QUIET, record=True)
        assert r.status is Status.OK, r.message
        y, mode, fb, ev = reference_interval(p, y, mode, fb, list(cmd.segments), bridge, p.sample_period, t0=s.t)
        mine = [(t, KIND[k]) for t, k in zip(r.events["t"], r.events["kind"]) if k in KIND]
        assert [k for _, k in mine] == [k for _, k in ev], (s.t, mine, ev)
        for (a, _), (b, _) in zip(mine, ev):
            worst_t = max(worst_t, abs(a - b))
        n_events += len(ev)
        s = r.state
        assert s.mode == mode
        peak = max(peak, abs(y[0]), r.peak_abs_error)
        worst_x = max(worst_x, abs(s.x[0] - y[0]))
    return worst_t, worst_x / peak, n_events


def _pulse_train(p, n, seed):
    rng = np.random.default_rng(seed)
    cmds = []
    for k in range(n):
        if k % 3 == 0:
            w = rng.uniform(2e-4, 0.006)
            start = rng.uniform(0.0, p.sample_period - w - 1e-4)
            cmds.append(DriveCommand.pulse(start, w, rng.choice([-1.0, 1.0]) * p.u_max))
        else:
            cmds.append(DriveCommand.hold(0.0, DriveType.BRIDGE))
    return cmds


@pytest.mark.parametrize("name", sorted(PARAMS))
def test_pulse_trains_match_solve_ivp(name):
    p = PARAMS[name]
    dt, dx, n = _compare_run(p, _pulse_train(p, 24, seed=len(name)), True)
    assert n >= 8
    assert dt <= 1e-12
    assert dx <= 1e-10


@pytest.mark.parametrize("name", ["compliant", "light-250Hz", "soft-100Hz"])
def test_linear_amplifier_levels_match_solve_ivp(name):
    p = PARAMS[name]
    rng = np.random.default_rng(7)
    cmds = []
    for k in range(20):
        lv = rng.uniform(-6.0, 6.0) if k % 4 != 3 else 0.0
        cmds.append(DriveCommand(((0.0, lv), (rng.uniform(1e-3, 9e-3), -0.5 * lv)), DriveType.LINEAR))
    dt, dx, n = _compare_run(p, cmds, False)
    assert n >= 4
    assert dt <= 1e-12
    assert dx <= 1e-10


class _Spy:
    """A family wrapper that records every command the closed loop sends."""

    def __init__(self):
        from plant.protocol import PlantFamily

        outer = self
        self.commands = []

        class Spy(PlantFamily):
            Params = TwoMassParams
            name = "spy"

            def initial_state(self, params, x5):
                return FAM.initial_state(params, x5)

            def step(self, state, command, params, noise, options, *, duration=None, record=False):
                outer.commands.append(command)
                return FAM.step(state, command, params, noise, options, duration=duration, record=record)

            def truth(self, params, state):
                return FAM.truth(params, state)

        self.family = Spy()


@pytest.mark.slow
@pytest.mark.parametrize("controller, name", [("pulse-width", "compliant"), ("linear", "light-250Hz"),
                                              ("solnic-modern", "stiff-300Hz")])
def test_closed_loop_replay_matches_solve_ivp(controller, name):
    from bench.runner import run_closed_loop
    from controllers import make_controller

    p = PARAMS[name].replace(command_velocity_initial=1e-3)    # a ramp the loop must follow
    spy = _Spy()
    res = run_closed_loop(p, make_controller(controller), duration_s=3.0, warmup_s=0.0, seed=0, noise=False,
                          family=spy.family, compiled=False)
    assert res.status == "ok", res.message
    cmds = spy.commands
    bridge = cmds[0].drive is DriveType.BRIDGE
    dt, dx, n = _compare_run(p, cmds, bridge)
    assert n >= 2, "the replay should move the load"
    assert dt <= 1e-12
    assert dx <= 1e-10


# --- the first root of a grazing oscillation --------------------------------------------------

def test_locator_finds_a_grazing_breakaway_between_coarse_steps():
    """ζ = 0.01: during and after a 1.5 ms pulse the stuck load feels a ringing shaft torque.
    Stiction is set just below the torque's highest peak (found on a fine solve_ivp grid), so T
    exceeds ks only for a few µs: a sign test on a 0.5 ms grid (and at the interval's end) sees T < ks
    everywhere, the locator finds the crossing, solve_ivp with a fine max_step agrees."""
    base = shaft(200.0, 0.01, 0.1, stiction=19.0, coulomb=1.4).noise_free()
    k, c = base.shaft_stiffness, base.shaft_damping

    def rhs(t, y):            # stuck load: y = [x3, φ, ω_m], pulse of u_max for 1.5 ms then flyback
        u = base.u_max if t < 1.5e-3 else (-base.u_max if y[0] > 0 else 0.0)
        T = k * y[1] + c * y[2]
        return [(u - y[0]) / base.motor_time_constant, y[2], (y[0] - T) / base.motor_inertia]

    t_fb = 1.5e-3 + base.motor_time_constant * math.log1p(
        (base.u_max * -math.expm1(-1.5e-3 / base.motor_time_constant)) / base.u_max)
    grid = np.linspace(0, 0.01, 200001)
    sol1 = solve_ivp(rhs, (0, 1.5e-3), [0, 0, 0], method="DOP853", rtol=1e-13, atol=1e-18, dense_output=True)
    sol2 = solve_ivp(rhs, (1.5e-3, t_fb), sol1.y[:, -1], method="DOP853", rtol=1e-13, atol=1e-18, dense_output=True)
    y3 = sol2.y[:, -1].copy()
    y3[0] = 0.0
    sol3 = solve_ivp(lambda t, y: [0.0, y[2], (-(k * y[1] + c * y[2])) / base.motor_inertia], (t_fb, 0.01), y3,
                     method="DOP853", rtol=1e-13, atol=1e-18, dense_output=True)

    def torque(t):
        y = sol1.sol(t) if t <= 1.5e-3 else (sol2.sol(t) if t <= t_fb else sol3.sol(t))
        return k * y[1] + c * y[2]

    T = np.array([torque(t) for t in grid])
    i2 = int(np.argmax(T))                          # the highest peak: the first crossing
    t_peak = grid[i2]
    ks = T[i2] * (1 - 2e-6)                         # the torque exceeds ks for a few µs only
    assert -ks < T.min() and np.sum(T > ks) < 200   # never below −ks; above ks for < 10 µs
    p = base.replace(stiction=float(ks))
    coarse = np.arange(0.0, 0.01 + 1e-12, 5e-4)
    assert all(torque(t) < ks for t in coarse), "the coarse grid must not see the excursion"
    assert not np.any((coarse[:-1] < t_peak) & (t_peak < coarse[:-1] + 1e-9))
    s = FAM.initial_state(p, 0.0)
    r = FAM.step(s, DriveCommand.pulse(0.0, 1.5e-3, p.u_max), p, None, QUIET, record=True)
    brk = r.events["t"][r.events["kind"] == int(EventKind.BREAKAWAY)]
    assert brk.size >= 1
    # the reference: solve_ivp's sign test on a fine max_step, from the same construction
    y, mode, fb, ev = reference_interval(p, [0, 0, 0, p.command_velocity_initial, 0, 0], 2, False,
                                         list(DriveCommand.pulse(0.0, 1.5e-3, p.u_max).segments), True,
                                         p.sample_period, max_step=2e-6)
    ref_brk = [t for t, kind in ev if kind == "breakaway"]
    assert abs(brk[0] - ref_brk[0]) <= 1e-12
    assert abs(brk[0] - t_peak) < 2e-5             # at the grazing peak, not a later one
    assert brk[0] - 1e-9 > max(coarse[coarse < brk[0]])


# --- noisy statistics against Euler–Maruyama --------------------------------------------------

def _em_pulse(p, dt_u, n_paths, h, horizon, rng):
    """Euler–Maruyama of the two-mass plant from rest under one bridge pulse of dt_u seconds
    (then flyback to x3 = 0, then off), x4 = x5 = 0: per path the first breakaway time, the
    last stick time, Δx1 and the final mode. The switching table of SPEC §2 with the shaft
    torque; a velocity zero is a sign change of x2 over a step or, with both ends on one side,
    a Brownian-bridge crossing drawn with probability exp(−2·v_a·v_b/(σ_v²·h)) (without it EM's
    stop time converges only like √h)."""
    J, Jm, k, c = p.inertia, p.motor_inertia, p.shaft_stiffness, p.shaft_damping
    kc, ks, tau3 = p.coulomb, p.stiction, p.motor_time_constant
    sv = math.sqrt(p.sigma2_sq) / J
    n = n_paths
    x1, x2, x3, phi, wm = (np.zeros(n) for _ in range(5))
    mode = np.full(n, 2)
    t_brk = np.full(n, np.nan)
    t_stick = np.zeros(n)
    x3_done = np.zeros(n, dtype=bool)
    for i in range(int(round(horizon / h))):
        t = i * h
        if t < dt_u:
            u = np.full(n, p.u_max)
        else:
            u = np.where(x3_done, 0.0, -p.u_max)
        T = k * phi + c * (wm - x2)
        up = (mode == 2) & (T > ks)
        dn = (mode == 2) & (T < -ks)
        t_brk[(up | dn) & np.isnan(t_brk)] = t
        mode = np.where(up, 3, np.where(dn, 1, mode))
        moving = mode != 2
        s = np.where(mode == 3, 1.0, -1.0)
        x2n = np.where(moving, x2 + h * (T - s * kc) / J + sv * math.sqrt(h) * rng.standard_normal(n), 0.0)
        va, vb = s * x2, s * x2n
        bridge = np.exp(-2.0 * np.maximum(va, 0.0) * np.maximum(vb, 0.0) / (sv * sv * h))
        cross = moving & ((vb <= 0) | (rng.random(n) < bridge))   # sign change or a bridge crossing
        stick = cross & (np.abs(T) <= ks)
        rev = cross & (-s * T > ks)
        refl = cross & (s * T > ks)                                 # reflected at 0 (mirror)
        x2n = np.where(refl, s * np.abs(x2n), np.where(cross, 0.0, x2n))
        mode = np.where(stick, 2, np.where(rev, np.where(mode == 3, 1, 3), mode))
        t_stick = np.where(stick, t + h, t_stick)
        wm = wm + h * (x3 - T) / Jm             # semi-implicit (symplectic) Euler: velocities
        x1 = x1 + h * x2n                       # first, then positions with the new ones, so the
        phi = phi + h * (wm - x2n)              # lightly damped shaft does not gain energy
        x3 = x3 + h * (u - x3) / tau3
        if t + h >= dt_u:
            ended = ~x3_done & (x3 <= 0.0)
            x3 = np.where(ended | x3_done, 0.0, x3)
            x3_done |= ended
        x2 = x2n
    return t_brk, t_stick, x1, mode


@pytest.mark.slow
def test_noisy_pulse_statistics_match_euler_maruyama():
    """Table 2-1's friction noise, x4 = x5 = 0: a 2 ms pulse from rest. While the
    load is stuck the shaft torque is deterministic (the rotor carries no noise), so the first
    breakaway time is deterministic in both simulators; Δc, the stop time and the number of
    breakaways are random. Exact (this family) vs Euler–Maruyama (h = 2 µs): means within
    4.5 combined standard errors plus the EM bias allowance, 95th percentiles within their
    bootstrap 99 % intervals."""
    p = TwoMassParams(command_velocity_std=0.0, correlated_friction_std=0.0,
                      command_velocity_initial=0.0)
    n = 600
    horizon = 0.05
    dt_u = 2e-3
    opts = SimOptions(noise=True)
    dc, tstop, tbrk = [], [], []
    stream = NoiseStream.from_seed(12345)
    for i in range(n):
        s = FAM.initial_state(p, 0.0)
        t_first = math.nan
        last_stick = 0.0
        r = FAM.step(s, DriveCommand.pulse(0.0, dt_u, p.u_max), p, stream, opts, duration=0.01, record=True)
        events = [r.events]
        s = r.state
        for _ in range(int(horizon / 0.01) - 1):
            r = FAM.step(s, DriveCommand.hold(0.0, DriveType.BRIDGE), p, stream, opts, duration=0.01, record=True)
            events.append(r.events)
            s = r.state
        t = np.concatenate([e["t"] for e in events])
        kind = np.concatenate([e["kind"] for e in events])
        b = t[kind == int(EventKind.BREAKAWAY)]
        st = t[kind == int(EventKind.STICK)]
        assert s.mode == 2, "the load must be stuck at the horizon"
        tbrk.append(b[0])
        tstop.append(st[-1])
        dc.append(s.x[0])
    rng = np.random.default_rng(99)
    em_brk, em_stop, em_dc, em_mode = _em_pulse(p, dt_u, n, 2e-6, horizon, rng)
    assert np.all(em_mode == 2)
    dc, tstop, tbrk = map(np.asarray, (dc, tstop, tbrk))
    # the first breakaway: deterministic, identical up to EM's step
    assert np.ptp(tbrk) < 1e-12
    assert abs(tbrk[0] - np.mean(em_brk)) < 4e-6
    print(f"breakaway {tbrk[0]:.9f} s (EM {np.mean(em_brk):.9f}); Δc mean {dc.mean():.4e} (EM {em_dc.mean():.4e}), "
          f"p95 {np.percentile(dc, 95):.4e} (EM {np.percentile(em_dc, 95):.4e}); stop mean {tstop.mean():.5f} s "
          f"(EM {em_stop.mean():.5f}), p95 {np.percentile(tstop, 95):.5f} (EM {np.percentile(em_stop, 95):.5f})")
    for exact, em, bias in ((dc, em_dc, 0.02 * np.mean(np.abs(dc))), (tstop, em_stop, 2e-5)):
        se = math.sqrt(exact.var(ddof=1) / n + em.var(ddof=1) / n)
        assert abs(exact.mean() - em.mean()) < 4.5 * se + bias, (exact.mean(), em.mean(), se)
        boot = np.random.default_rng(5)
        qa = [np.percentile(exact[boot.integers(0, n, n)], 95) for _ in range(400)]
        qb = [np.percentile(em[boot.integers(0, n, n)], 95) for _ in range(400)]
        diff = np.array(qa) - np.array(qb)
        lo, hi = np.percentile(diff, [0.5, 99.5])
        assert lo - bias <= 0.0 <= hi + bias, (np.percentile(exact, 95), np.percentile(em, 95))


# --- the stiff limit --------------------------------------------------------------------------

def test_stiff_shaft_approaches_the_multimode_plant():
    """k_sh → ∞ with J_m = ε·J, ζ fixed: the breakaway time and Δc of a 3 ms pulse from rest
    approach the multimode plant's with the load inertia J + J_m, the error falling with ε."""
    mm = get_family("multimode")
    errs = []
    for eps in (0.1, 0.01, 0.001):
        p = shaft(150.0 / eps, 0.05, eps).noise_free()
        ref = mm.Params(inertia=p.inertia + p.motor_inertia).noise_free()
        a = FAM.pulse_motion(p, FAM.initial_state(p, 0.0), 3e-3, +1)
        b = mm.pulse_motion(ref, mm.initial_state(ref, 0.0), 3e-3, +1)
        r2 = FAM.step(FAM.initial_state(p, 0.0), DriveCommand.pulse(0.0, 3e-3, p.u_max), p, None, QUIET, record=True)
        r1 = mm.step(mm.initial_state(ref, 0.0), DriveCommand.pulse(0.0, 3e-3, ref.u_max), ref, None, QUIET,
                     record=True)
        tb2 = r2.events["t"][r2.events["kind"] == int(EventKind.BREAKAWAY)][0]
        tb1 = r1.events["t"][r1.events["kind"] == int(EventKind.BREAKAWAY)][0]
        errs.append((abs(a[0] - b[0]) / abs(b[0]), abs(tb2 - tb1)))
    print("stiff limit (relative Δc error, breakaway-time error [s]) at ε = 0.1, 0.01, 0.001:", errs)
    assert errs[-1][0] < 1e-5 and errs[-1][1] < 1e-8          # measured: 5.6e-7 and 1.4e-10 s
    assert errs[0][0] > errs[1][0] > errs[2][0] and errs[0][1] > errs[1][1] > errs[2][1]


# --- the compiled linear-law loop -------------------------------------------------------------

@pytest.mark.parametrize("controller", ["linear", "dithered"])
def test_compiled_law_loop_is_bit_identical_to_the_step_loop(controller):
    from bench.runner import run_closed_loop
    from bench.scenarios import builtin_scenarios
    from controllers import make_controller

    sc = builtin_scenarios()["compliant"]
    runs = [run_closed_loop(sc.params, make_controller(controller), duration_s=8.0, warmup_s=2.0, seed=3,
                            family=sc.family, compiled=c) for c in (True, False)]
    a, b = ({k: v for k, v in r.metrics.items() if k not in ("runtime_s", "realtime_factor")} for r in runs)
    assert runs[0].status == runs[1].status == "ok"
    assert a == b
    assert a["n_events"] > 0 or controller == "linear"


def test_pulse_motion_waits_for_the_ringing_shaft():
    """The oracle's pulse response: Δc equals a long noise-free run's final x1 (the shaft's
    ringing may break the stuck load loose again), and the stop time is its last stick."""
    from plant.protocol import PlantFamily

    p = PARAMS["compliant"].noise_free().replace(command_velocity_initial=0.0)
    early = 0
    for dt_u in (2.2e-3, 3e-3, 5e-3):
        dc, t_stop = FAM.pulse_motion(p, FAM.initial_state(p, 0.0), dt_u, +1)
        s = FAM.initial_state(p, 0.0)
        r = FAM.step(s, DriveCommand.pulse(0.0, dt_u, p.u_max), p, None, QUIET, duration=0.5, record=True)
        sticks = r.events["t"][r.events["kind"] == int(EventKind.STICK)]
        assert r.state.mode == 2
        assert dc == pytest.approx(r.state.x[0], rel=1e-9, abs=1e-15)
        assert t_stop == pytest.approx(sticks[-1], abs=1e-12)
        early += PlantFamily.pulse_motion(FAM, p, FAM.initial_state(p, 0.0), dt_u, +1)[1] < t_stop - 1e-3
    assert early >= 1, "the generic first-stop rule should stop too early on this shaft"
