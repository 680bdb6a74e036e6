"""The ``stribeck`` family against independent truth.

* Noise-free pulse trains and closed-loop replays against ``solve_ivp`` (Radau, rtol 1e-11,
  terminal events for breakaway, velocity zero and flyback end: plant.stribeck.reference): x1
  at every sample within 1e-8 of the run's largest |x1|, on five parameter sets each.
* Breakaway from rest at Acker's closed-form instant; the Coulomb limit (v_s → 0, b = 0)
  approaches the exact multimode plant's pulse response.
* With noise, the x1 statistics of a pulse train against a fine Euler–Maruyama reference
  (Monte-Carlo confidence intervals).
* Bad input names the field (and is exit 2 through a matrix file).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.runner import run_closed_loop
from controllers import make_controller
from controllers.base import Controller
from plant import DriveCommand, DriveType, PlantParams, SimOptions, pulse_response
from plant.protocol import get_family
from plant.randomness import NoiseStream
from plant.stribeck import StribeckParams
from plant.stribeck.reference import euler_maruyama, event_driven
from tests.cli_helpers import cli

FAMILY = get_family("stribeck")
QUIET = SimOptions(noise=False)

# Five parameter sets: the defaults, a steep curve with strong viscous drag, a slow
# sub-Gaussian curve, friction ripple (a period of 200 µrad, a few per pulse train) and
# another plant (inertia, motor lag, levels).
PARAMETER_SETS = {
    "defaults": {},
    "steep-viscous": {"stribeck_velocity": 1e-3, "viscous": 2.0},
    "slow-curve": {"stribeck_exponent": 0.7, "stribeck_velocity": 1e-2},
    "ripple": {"friction_ripple": 0.3, "ripple_period": 2e-4, "ripple_phase": 1.0, "stribeck_exponent": 1.5},
    "other-plant": {"inertia": 0.8, "motor_time_constant": 5e-3, "coulomb": 0.5, "stiction": 2.5, "viscous": 0.0},
}


def _pulse_train(params, n, seed):
    rng = np.random.default_rng(seed)
    cmds = []
    for _ in range(n):
        start, width = rng.uniform(0.0, 4e-3), rng.uniform(0.0, 4e-3)
        cmds.append(DriveCommand.pulse(start, width, float(rng.choice([-1.0, 1.0])) * params.u_max))
    return cmds


def _run_family(params, cmds, x5=0.1):
    state = FAMILY.initial_state(params, x5)
    x1 = []
    for cmd in cmds:
        res = FAMILY.step(state, cmd, params, None, QUIET)
        assert res.status.value == "ok", res.message
        state = res.state
        x1.append(state.x[0])
    return np.array(x1), state


def _check_train(name):
    p = StribeckParams(**PARAMETER_SETS[name])
    cmds = _pulse_train(p, 30, seed=3)
    x1, state = _run_family(p, cmds)
    ref, x_ref, mode_ref = event_driven(p, FAMILY.initial_state(p, 0.1).x, 2, cmds)
    scale = np.max(np.abs(ref))
    assert scale > 1e-5                                     # the train moves the shaft
    assert np.max(np.abs(x1 - ref)) <= 1e-8 * scale, (name, np.max(np.abs(x1 - ref)) / scale)
    assert state.mode == mode_ref


def test_pulse_train_matches_solve_ivp_defaults():
    _check_train("defaults")


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in PARAMETER_SETS if n != "defaults"])
def test_pulse_train_matches_solve_ivp(name):
    _check_train(name)


class _Recording(Controller):
    """Passes the inner controller's commands through and keeps them."""

    def __init__(self, inner: Controller) -> None:
        self.inner, self.commands = inner, []
        self.drive = inner.drive
        self.privileged = inner.privileged

    def reset(self, params, rng):
        self.inner.reset(params, rng)

    def observe_truth(self, state, plant):
        self.inner.observe_truth(state, plant)

    def step(self, y):
        cmd = self.inner.step(y)
        self.commands.append(cmd)
        return cmd


REPLAYS = [("pulse-width", "defaults"), ("linear", "steep-viscous"), ("solnic-modern", "slow-curve"),
           ("pulse-width", "ripple"), ("reset-pid", "other-plant")]


@pytest.mark.slow
@pytest.mark.parametrize("controller, name", REPLAYS)
def test_closed_loop_replay_matches_solve_ivp(controller, name):
    p = StribeckParams(**PARAMETER_SETS[name])
    rec = _Recording(make_controller(controller))
    run = run_closed_loop(p, rec, duration_s=2.0, warmup_s=0.5, seed=0, noise=False, record=True, family="stribeck")
    assert run.status == "ok", run.message
    ref, _, _ = event_driven(p, FAMILY.initial_state(p, 0.0).x, 2, rec.commands)
    x1 = np.asarray(run.samples["x1"])[1:]
    ref = ref[:len(x1)]
    scale = np.max(np.abs(ref))
    assert scale > 1e-6
    assert np.max(np.abs(x1 - ref)) <= 1e-8 * scale, (controller, name, np.max(np.abs(x1 - ref)) / scale)


def test_breakaway_at_the_closed_form_instant():
    p = StribeckParams().noise_free()
    x = FAMILY.initial_state(p, 0.0).x.copy()
    x[3] = 0.0
    x.flags.writeable = False
    state = FAMILY.initial_state(p, 0.0)._replace(x=x)
    res = FAMILY.step(state, DriveCommand.pulse(0.0, 1.5e-3, p.u_max), p, None, QUIET, record=True)
    t_brk = res.events["t"][res.events["kind"] == 3]
    # x3(t) = u_max·(1 − e^(−t/τ3)) = ks  ⇒  t = −τ3·ln(1 − ks/u_max)  (SPEC §2: 0.88745 ms)
    assert t_brk.size == 1 and abs(t_brk[0] + p.motor_time_constant * math.log1p(-p.stiction / p.u_max)) < 1e-15
    assert res.n_sticks == 1 and res.state.mode == 2


def test_coulomb_limit_approaches_the_multimode_plant():
    """v_s → 0 with b = 0: friction is ks at v = 0 and kc at any speed, Acker's law.

    Measured on the 1.5 ms pulse (Δc = 4.8592 µrad exact): relative error 0.121, 0.0323,
    0.0077, 0.0017 at v_s = 1e-4 ... 1e-7 rad/s, i.e. O(v_s^0.6) (the slide's first few µs,
    where v < v_s, shrink like that)."""
    exact = pulse_response(PlantParams(), 1.5e-3).delta_c
    errors = []
    for vs in (1e-4, 1e-5, 1e-6, 1e-7):
        p = StribeckParams(stribeck_velocity=vs, viscous=0.0).noise_free()
        delta, _ = FAMILY.pulse_motion(p, FAMILY.initial_state(p, 0.0), 1.5e-3, 1)
        errors.append(abs(delta - exact) / exact)
    assert all(b < a / 3.0 for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 3e-3, errors


def test_below_breakaway_nothing_moves_and_current_integrals_are_exact():
    p = StribeckParams().noise_free()
    x = np.zeros(7)
    x.flags.writeable = False
    state = FAMILY.initial_state(p, 0.0)._replace(x=x)
    res = FAMILY.step(state, DriveCommand.pulse(0.0, 0.8e-3, p.u_max), p, None, QUIET, record=True)
    assert res.state.x[0] == 0.0 and res.n_breakaways == 0
    tau, u, w = p.motor_time_constant, p.u_max, 0.8e-3
    x3w = u * -math.expm1(-w / tau)
    t_off = tau * math.log1p(x3w / u)                       # flyback: x3 = −u + (x3w + u)e^(−t/τ3) = 0
    on = u * w - u * tau * -math.expm1(-w / tau)
    off = -u * t_off + (x3w + u) * tau * -math.expm1(-t_off / tau)
    assert res.int_abs_current == pytest.approx(on + off, rel=1e-12)


def test_same_seed_same_bits():
    p = StribeckParams()
    cmds = _pulse_train(p, 20, seed=5)

    def run(seed):
        s, noise, out = FAMILY.initial_state(p, 0.05), NoiseStream.from_seed(seed), []
        for cmd in cmds:
            s = FAMILY.step(s, cmd, p, noise, SimOptions()).state
            out.append(s.x.copy())
        return np.array(out)

    a, b, c = run(4), run(4), run(5)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


@pytest.mark.slow
def test_noisy_statistics_against_fine_euler_maruyama():
    """Mean and sd of x1 after each interval of a pulse train, 3000 paths each.

    The friction noise is 10× Table 2-1's (σ2² = 4e-3) and τ5 = 10 s, so that every noise
    moves x1 by much more than the Monte-Carlo error: the noise-free x1 lies > 10 standard
    errors from the noisy mean (checked), so the comparison can fail."""
    p = StribeckParams(friction_noise_psd=4e-3, correlated_friction_tau=10.0)
    cmds = [DriveCommand.pulse(0.0, 2.0e-3, p.u_max), DriveCommand.pulse(0.0, 1.6e-3, -p.u_max),
            DriveCommand.pulse(1e-3, 2.5e-3, p.u_max), DriveCommand.hold(0.0, DriveType.BRIDGE)]
    n = 3000
    fam = np.empty((n, len(cmds)))
    for m in range(n):
        s, noise = FAMILY.initial_state(p, 0.0), NoiseStream.from_seed(10_000 + m)
        for i, cmd in enumerate(cmds):
            s = FAMILY.step(s, cmd, p, noise, SimOptions()).state
            fam[m, i] = s.x[0]
    em = euler_maruyama(p, FAMILY.initial_state(p, 0.0).x, 2, cmds, n, 2e-6, np.random.default_rng(7)).T
    quiet, _ = _run_family(p.noise_free(), cmds, x5=0.0)
    se = np.sqrt(fam.var(0) / n + em.var(0) / n)
    assert np.all(np.abs(fam.mean(0) - em.mean(0)) < 4.0 * se), (fam.mean(0), em.mean(0), se)
    assert np.all(np.abs(fam.std(0) / em.std(0) - 1.0) < 0.08), fam.std(0) / em.std(0)
    assert np.all(np.abs(quiet - em.mean(0)) > 10.0 * se)


@pytest.mark.parametrize("field, value", [
    ("stribeck_velocity", 0.0), ("stribeck_velocity", -1e-3), ("stribeck_exponent", 0.0),
    ("stribeck_exponent", -2.0), ("viscous", -0.1), ("friction_ripple", 1.0), ("friction_ripple", -1.5),
    ("ripple_period", 0.0), ("ripple_phase", float("nan")), ("viscous", "soft"),
])
def test_bad_input_names_the_field(field, value):
    with pytest.raises(ValueError, match=rf"^StribeckParams\.{field} "):
        StribeckParams(**{field: value})


@pytest.mark.slow
@pytest.mark.parametrize("field, value", [("stribeck_exponent", "-1.0"), ("stribeck_velocity", "-4e-3"),
                                          ("viscous", "-0.2"), ("friction_ripple", "1.2")])
def test_bad_input_is_exit_2_through_a_matrix_file(tmp_path, field, value):
    path = tmp_path / "m.toml"
    path.write_text('[matrix]\ncontrollers = ["linear"]\nscenarios = ["x"]\nseeds = [0]\nduration_s = 1\n'
                    f'warmup_s = 0.2\n\n[scenarios.x]\nbase = "thesis"\nplant = "stribeck"\n{field} = {value}\n')
    proc = cli("run", "--matrix", path, "--out", tmp_path / "out")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and field in lines[0] and str(path) in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out").exists()


@pytest.mark.parametrize("controller", ["linear", "dithered"])
def test_compiled_linear_law_loop_is_bit_identical(controller):
    p = StribeckParams()
    runs = [run_closed_loop(p, make_controller(controller), duration_s=3.0, warmup_s=1.0, seed=2,
                            family="stribeck", compiled=compiled) for compiled in (True, False)]
    assert runs[0].status == runs[1].status == "ok"
    assert runs[0].summary == runs[1].summary
    timing = {"runtime_s", "realtime_factor"}
    assert {k: v for k, v in runs[0].metrics.items() if k not in timing} == \
        {k: v for k, v in runs[1].metrics.items() if k not in timing}
