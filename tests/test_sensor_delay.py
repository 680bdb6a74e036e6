"""The quantized sensor and the compute delay (SPEC §11), options of every family's I/O path.

* The quantizer rounds to the grid with ties up, shift-invariant; q = 0 passes y unchanged.
* In a closed loop y(n) is the hand-quantized x1(nτs) + w1(n), w1 drawn from the run's sensor
  stream, and the controller is told q through its model.
* A delayed torque step on the linear amplifier is the undelayed closed form shifted by δ:
  breakaway at t0 − τ3·ln(1 − ks/u) with t0 = kτs + δ (to 1e-12 s), x1 at the samples
  against ``solve_ivp`` (rtol 1e-12) of the moving shaft.
* Delayed bridge pulses, one of them cut by the sample boundary and carried over, equal the
  undelayed run of the hand-shifted command sequence.
* With both options off the runner is the plain loop y = x1 + w1 → step(command), bit for bit,
  and the cell definitions (hashes) of the existing scenarios are those computed before the
  options existed.
* Bad values: ValueError naming the field and the range; from a matrix file, exit 2 naming
  file:line:key.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from bench.matrix import MatrixError, builtin_matrix_path, load_matrix
from bench.runner import run_closed_loop, spawn_streams
from bench.scenarios import builtin_scenarios
from controllers.base import Controller, make_controller
from plant import DriveCommand, DriveType, PlantParams
from plant.delay import delay_command
from plant.protocol import get_family
from plant.randomness import NoiseStream
from plant.sensor import quantize
from plant.state import EventKind, SimOptions, X1
from tests.cli_helpers import cli

TAU = 0.01


class _Script(Controller):
    """Plays a fixed list of commands (the last one repeats) and records every y it is given."""

    description = "test script"

    def __init__(self, commands, drive=DriveType.LINEAR):
        self.commands = list(commands)
        self.drive = drive
        self.seen_y: list[float] = []
        self.told: list[PlantParams] = []

    def reset(self, params, rng):
        self.told.append(params)
        self.seen_y.clear()

    def step(self, y):
        n = len(self.seen_y)
        self.seen_y.append(y)
        return self.commands[min(n, len(self.commands) - 1)]


# --- the quantizer ----------------------------------------------------------------------------

@pytest.mark.parametrize("value, step, want", [
    (2.4e-6, 1e-6, 2e-6), (2.6e-6, 1e-6, 3e-6), (-2.4e-6, 1e-6, -2e-6), (-2.6e-6, 1e-6, -3e-6),
    (0.5, 1.0, 1.0), (1.5, 1.0, 2.0), (2.5, 1.0, 3.0),                 # ties up (half-even: 0, 2, 2)
    (-0.5, 1.0, 0.0), (-1.5, 1.0, -1.0), (-2.5, 1.0, -2.0),
    (0.49999999999999994, 1.0, 0.0),      # just below a half: floor(v + 0.5) would give 1
    (0.375, 0.25, 0.5), (0.0, 1e-6, 0.0),
])
def test_quantize_rounds_to_the_grid_with_ties_up(value, step, want):
    assert quantize(value, step) == want


def test_quantize_is_shift_invariant_and_off_at_zero():
    """q·k shifts the output by q·k (exact with q a power of 2); |y − v| ≤ q/2; q = 0 is identity."""
    q = 2.0**-20
    rng = np.random.default_rng(1)
    for v in rng.uniform(-1e-3, 1e-3, 2000):
        y = quantize(v, q)
        assert abs(y - v) <= q / 2 and (y / q).is_integer()
        for k in (-7, 3, 1000):
            assert quantize(v + k * q, q) == y + k * q
    for k in range(-4, 5):                       # exact ties: always the level above
        assert quantize((k + 0.5) * q, q) == (k + 1) * q
    for v in (1.2345e-6, -3.3e-7, 0.0, -0.0, 1e300):
        assert quantize(v, 0.0) is v
    assert quantize(1e-6, 5e-324) == 1e-6        # v/q overflows: a grid finer than v's resolution


def test_the_closed_loop_sees_hand_quantized_measurements():
    """y(n) = q·⌊(x1(nτs) + w1(n))/q + ½⌋ with w1 from the seed's sensor stream; the model says q."""
    q, seed, n = 1e-6, 5, 300
    p = PlantParams(quantization=q)
    ctl = _Script([DriveCommand.hold(0.0)] * 100 + [DriveCommand.hold(2.5)] * 3 + [DriveCommand.hold(0.0)])
    res = run_closed_loop(p, ctl, duration_s=n * TAU, seed=seed, record=True)
    assert res.status == "ok", res.message
    w1 = spawn_streams(seed)["sensor"].standard_normal(n) * p.measurement_noise_std
    x1 = res.samples["x1"][:n]
    want = q * np.floor((x1 + w1) / q + 0.5)
    np.testing.assert_allclose(ctl.seen_y, want, rtol=0, atol=1e-21)
    np.testing.assert_array_equal(res.samples["y"][:n], ctl.seen_y)
    assert np.ptp(x1) > 20 * q                   # the shaft moved across many levels
    assert len(set(ctl.seen_y)) > 10 and ctl.told == [p]


# --- the compute delay: the interval's commands -------------------------------------------------

def test_delay_command_splits_and_carries_by_hand():
    L, B = DriveType.LINEAR, DriveType.BRIDGE
    now, pend = delay_command(DriveCommand.hold(3.0, L), None, 0.002, TAU)
    assert now.segments == ((0.0, 0.0), (0.002, 3.0)) and pend.segments == ((0.0, 3.0),)
    now, pend = delay_command(DriveCommand.hold(5.0, L), pend, 0.002, TAU)
    assert now.segments == ((0.0, 3.0), (0.002, 5.0)) and pend.segments == ((0.0, 5.0),)
    now, pend = delay_command(DriveCommand.hold(5.0, L), pend, 0.002, TAU)
    assert now.segments == ((0.0, 5.0),)                                 # a held level: no event at δ
    # a bridge pulse at 7.5 ms for 1.2 ms, delayed 2 ms: on at 9.5 ms, cut at 10 ms, off at 0.7 ms
    now, pend = delay_command(DriveCommand.pulse(0.0075, 0.0012, 20.0), None, 0.002, TAU)
    assert now.segments == ((0.0, 0.0), (0.0095, 20.0)) and now.drive is B
    assert pend.segments[0] == (0.0, 20.0) and pend.segments[1][1] == 0.0
    assert pend.segments[1][0] == pytest.approx(0.0007, abs=1e-17)
    now, pend = delay_command(DriveCommand.pulse(0.001, 0.0012, -20.0), pend, 0.002, TAU)
    assert [lv for _, lv in now.segments] == [20.0, 0.0, -20.0, 0.0]
    np.testing.assert_allclose([o for o, _ in now.segments], [0.0, 0.0007, 0.003, 0.0042], rtol=0, atol=1e-17)
    assert pend.segments == ((0.0, 0.0),)
    # a whole pulse pushed into the next interval
    now, pend = delay_command(DriveCommand.pulse(0.007, 0.0012, 20.0), pend, 0.003, TAU)
    assert now.segments == ((0.0, 0.0),) and pend.segments[0] == (0.0, 20.0)
    assert pend.segments[1][0] == pytest.approx(0.0012, abs=1e-17)
    with pytest.raises(ValueError, match="command_delay"):
        delay_command(DriveCommand.hold(1.0, L), pend, 0.003, TAU)
    with pytest.raises(ValueError, match="beyond the sample interval's end"):   # as without a delay
        delay_command(DriveCommand.pulse(0.009, 0.0012, 20.0), None, 0.002, TAU)


def _noise_free(**changes):
    return PlantParams().noise_free().replace(command_velocity_initial=0.0, **changes)


@pytest.mark.parametrize("delay", [0.0, 0.002, 0.0075, 0.00999])
def test_a_delayed_torque_step_is_the_closed_form_shifted_by_the_delay(delay):
    """Linear amplifier: 0 for two samples, then u = 2.5 ozf·in, acting from t0 = 2τs + δ.

    Truth: x3 = u(1 − e^{−(t−t0)/τ3}); the shaft breaks away when x3 = k̄s, at
    t_b = t0 − τ3·ln(1 − k̄s/u), and then (x2 > 0 throughout) J·ẍ1 = x3 − k̄c, integrated by
    ``solve_ivp`` (DOP853, rtol 1e-12) from (0, 0, k̄s) at t_b.
    """
    u, k, n = 2.5, 2, 14
    p = _noise_free(command_delay=delay)
    ctl = _Script([DriveCommand.hold(0.0)] * k + [DriveCommand.hold(u)])
    res = run_closed_loop(p, ctl, duration_s=n * TAU, noise=False, record=True)
    assert res.status == "ok", res.message
    t0 = k * TAU + delay
    t_b = t0 - p.motor_time_constant * math.log1p(-p.stiction / u)
    kinds, times = res.events["kind"], res.events["t"]
    brk = times[kinds == int(EventKind.BREAKAWAY)]
    assert brk.size == 1 and abs(brk[0] - t_b) <= 1e-12
    level = times[kinds == int(EventKind.LEVEL)]
    assert level.size == (1 if delay else 0)            # a new level at a sample instant is no event
    assert np.all(np.abs(level - t0) <= 1e-15)

    def rhs(t, z):
        x3 = u * -math.expm1(-(t - t0) / p.motor_time_constant)
        return [z[1], (x3 - p.coulomb) / p.inertia]

    t_samples = res.samples["t"]
    after = t_samples > t_b
    sol = solve_ivp(rhs, (t_b, t_samples[-1]), [0.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-18,
                    t_eval=t_samples[after])
    assert sol.success
    assert np.all(res.samples["x1"][~after] == 0.0)
    np.testing.assert_allclose(res.samples["x1"][after], sol.y[0], rtol=1e-9, atol=1e-18)
    assert after.sum() >= 8
    # the motor torque at each sample: the level in force since t0
    x3_want = np.where(t_samples > t0, u * -np.expm1(-(t_samples - t0) / p.motor_time_constant), 0.0)
    np.testing.assert_allclose(res.samples["x3"], x3_want, rtol=1e-12, atol=1e-15)


def _pulse_script(shifted: bool):
    """Bridge pulses: as commanded (with δ = 2 ms to come) or as they act (hand-shifted, δ = 0)."""
    B, off = DriveType.BRIDGE, DriveCommand.hold(0.0, DriveType.BRIDGE)
    cmds = [off] * 16
    if not shifted:
        cmds[1] = DriveCommand.pulse(0.0075, 0.0012, 20.0)       # acts 19.5-20.7 ms: across 20 ms
        cmds[5] = DriveCommand.pulse(0.0, 0.0015, -20.0)         # acts 52.0-53.5 ms
        cmds[8] = DriveCommand.pulse(0.0079, 0.0015, 20.0)       # acts 89.9-91.4 ms: across 90 ms
        cmds[11] = DriveCommand(((0.0, 0.0), (0.009, -20.0)), B)  # a pulse the controller itself
        cmds[12] = DriveCommand(((0.0, -20.0), (0.0005, 0.0)), B)  # continues: acts 121.0-122.5 ms
    else:
        cmds[1] = DriveCommand(((0.0, 0.0), (0.0095, 20.0)), B)
        cmds[2] = DriveCommand(((0.0, 20.0), (0.0007, 0.0)), B)
        cmds[5] = DriveCommand(((0.0, 0.0), (0.002, -20.0), (0.0035, 0.0)), B)
        cmds[8] = DriveCommand(((0.0, 0.0), (0.0099, 20.0)), B)
        cmds[9] = DriveCommand(((0.0, 20.0), (0.0014, 0.0)), B)
        cmds[12] = DriveCommand(((0.0, 0.0), (0.001, -20.0), (0.0025, 0.0)), B)
    return _Script(cmds, B)


def test_delayed_bridge_pulses_are_the_hand_shifted_sequence():
    delayed = run_closed_loop(_noise_free(command_delay=0.002), _pulse_script(False), duration_s=0.16,
                              noise=False, record=True)
    by_hand = run_closed_loop(_noise_free(), _pulse_script(True), duration_s=0.16, noise=False, record=True)
    assert delayed.status == by_hand.status == "ok"
    for key in ("x1", "x2", "x3", "u", "mode"):
        np.testing.assert_allclose(delayed.samples[key], by_hand.samples[key], rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(delayed.events["kind"], by_hand.events["kind"])
    np.testing.assert_allclose(delayed.events["t"], by_hand.events["t"], rtol=0, atol=1e-14)
    assert (delayed.events["kind"] == int(EventKind.BREAKAWAY)).sum() >= 4    # every pulse moved the shaft
    assert np.ptp(delayed.samples["x1"]) > 1e-6


def test_a_delay_never_takes_the_compiled_path_and_changes_a_linear_law():
    """The linear law's own compiled loop has no delay or quantizer: the runner takes the
    compiled-law loop instead (tests/test_compiled_law.py; same numbers either way), and the
    delayed linear design really is another closed loop."""
    fam = get_family("multimode")
    assert fam.law_loop(PlantParams()) is fam.linear_law_loop is not None
    assert fam.law_loop(PlantParams(command_delay=1e-3)) is None
    assert fam.law_loop(PlantParams(quantization=1e-7)) is None
    for p in (PlantParams(command_delay=2e-3), PlantParams(quantization=1e-6)):
        runs = [run_closed_loop(p, make_controller("linear"), duration_s=3.0, warmup_s=1.0, seed=2,
                                compiled=c).metrics for c in (True, False)]
        for key, value in runs[0].items():
            if key not in ("runtime_s", "realtime_factor"):
                assert value == runs[1][key] or (value != value and runs[1][key] != runs[1][key]), key
    base = run_closed_loop(PlantParams(), make_controller("linear"), duration_s=3.0, warmup_s=1.0, seed=2)
    late = run_closed_loop(PlantParams(command_delay=2e-3), make_controller("linear"), duration_s=3.0,
                           warmup_s=1.0, seed=2)
    assert base.metrics["peak_error_rad"] != late.metrics["peak_error_rad"]


# --- off means before ---------------------------------------------------------------------------

def _plain_loop(params, controller, duration_s, seed):
    """The loop without the I/O options: y = x1 + w1, the command acts at once (SPEC §2)."""
    fam = get_family("multimode")
    streams = spawn_streams(seed)
    x5 = streams["initial"].normal(0.0, params.correlated_friction_std)
    state = fam.initial_state(params, x5)
    noise = NoiseStream(streams["plant"])
    n = int(round(duration_s / params.sample_period))
    w1 = streams["sensor"].standard_normal(n) * params.measurement_noise_std
    controller.reset(params, streams["controller"])
    x1, events = [], []
    for i in range(n):
        x1.append(state.x[X1])
        step = fam.step(state, controller.step(float(state.x[X1] + w1[i])), params, noise, SimOptions(),
                        record=True)
        events.append(step.events["t"])
        state = step.state
    return np.array(x1), np.concatenate(events)


@pytest.mark.parametrize("name", ["solnic", "pulse-width", "reset-pid", "linear"])
def test_options_off_are_the_plain_loop_bit_for_bit(name):
    p = PlantParams(quantization=0.0, command_delay=0.0)
    assert p == PlantParams()
    res = run_closed_loop(p, make_controller(name), duration_s=3.0, seed=4, record=True)
    x1, ev_t = _plain_loop(PlantParams(), make_controller(name), 3.0, 4)
    assert res.status == "ok"
    np.testing.assert_array_equal(res.samples["x1"], x1)
    np.testing.assert_array_equal(res.events["t"], ev_t)
    same = run_closed_loop(PlantParams(), make_controller(name), duration_s=3.0, seed=4)
    fast = run_closed_loop(p, make_controller(name), duration_s=3.0, seed=4)
    for key in same.metrics:
        if key not in ("runtime_s", "realtime_factor"):
            assert same.metrics[key] == fast.metrics[key], key


# definition_hash of default-matrix cells computed on main at 70df26c, before the options existed
_HASHES_BEFORE = {
    "linear__thesis__s3": "5d602b0062580b56181855a13be872ffce107f16f261d137ae2045597ee99fb5",
    "linear__quiet-friction__s3": "a4faf1f4ca9c5d7c65b32d4821a49d4dda4ef85c6a7994264fcdf68142749108",
    "linear__ratio-2__s3": "c7e0e2018791280682bf35939d795249a2cdfcb5407f2fe5a479a91700337060",
    "solnic-high__thesis__s3": "83672d1bbb40a0748b8227b10650b3667bd13281941c7eff764d0ba884e46b4e",
    "pulse-width__ratio-2__s3": "4c206227cfcd002927819e832c9d712738bcf9c999d17ba13b177e603ad36537",
}


def test_existing_cells_keep_their_definitions_and_new_ones_name_the_option():
    cells = {c.cell_id: c for c in load_matrix(builtin_matrix_path(), check_resets=False).cells()}
    for cell_id, digest in _HASHES_BEFORE.items():
        assert cells[cell_id].definition_hash == digest, cell_id
    built = builtin_scenarios()
    for name in ("thesis", "quiet-friction", "ratio-2", "mismatch"):
        plant = built[name].definition()["plant"]
        assert "quantization" not in plant and "command_delay" not in plant
    assert built["quantized"].definition()["plant"]["quantization"] == 1e-6
    assert built["delayed"].definition()["plant"]["command_delay"] == 2e-3


def test_the_new_builtins_tell_the_controllers_what_the_story_says():
    built = builtin_scenarios()
    q, d, m = built["quantized"], built["delayed"], built["mismatch"]
    assert q.model_params().quantization == 1e-6 and q.params == PlantParams(quantization=1e-6)
    assert d.model_params().command_delay == 2e-3 < d.params.sample_period
    assert m.model_params() == PlantParams() and dict(m.mismatch) == {
        "coulomb": 0.2, "stiction": 0.2, "inertia": 0.2, "motor_time_constant": 0.2}
    truth, factors = m.realise(0)
    assert sorted(factors) == ["coulomb", "inertia", "motor_time_constant", "stiction"]
    assert truth.inertia == 0.5 * factors["inertia"] and truth.coulomb == 1.4 * factors["coulomb"]
    for s in (q, d, m):
        assert s.description and (s.duration_s, s.warmup_s) == (100.0, 20.0)


# --- bad input -----------------------------------------------------------------------------------

@pytest.mark.parametrize("changes, match", [
    ({"quantization": -1e-9}, r"PlantParams\.quantization must be >= 0 rad"),
    ({"quantization": math.nan}, r"PlantParams\.quantization must be finite and >= 0 rad"),
    ({"quantization": math.inf}, r"PlantParams\.quantization must be finite"),
    ({"command_delay": -1e-6}, r"PlantParams\.command_delay must be in \[0, sample_period = 0\.01\) s"),
    ({"command_delay": 0.01}, r"PlantParams\.command_delay must be in \[0, sample_period = 0\.01\) s"),
    ({"command_delay": 0.003, "sample_period": 0.002}, r"PlantParams\.command_delay must be in \[0, sample_period = 0\.002\)"),
    ({"command_delay": math.nan}, r"PlantParams\.command_delay must be finite and in \[0, sample_period\) s"),
])
def test_bad_options_name_the_field_and_the_range(changes, match):
    with pytest.raises(ValueError, match=match):
        PlantParams(**changes)


_BAD = """[matrix]
controllers = ["linear"]
scenarios = ["x"]
seeds = [0]

[scenarios.x]
base = "thesis"
{body}
"""


@pytest.mark.parametrize("body, key, line", [
    ("quantization = -1e-6", "scenarios.x.quantization", 8),
    ("quantization = nan", "scenarios.x.quantization", 8),
    ("command_delay = 0.01", "scenarios.x.command_delay", 8),
    ("command_delay = -0.002", "scenarios.x.command_delay", 8),
    ("[scenarios.x.model]\ncommand_delay = 0.5", "scenarios.x.model.command_delay", 9),
])
def test_bad_options_in_a_matrix_name_file_line_and_key(tmp_path, body, key, line):
    path = tmp_path / "m.toml"
    path.write_text(_BAD.format(body=body))
    with pytest.raises(MatrixError) as info:
        load_matrix(path, check_resets=False)
    field = key.rsplit(".", 1)[1]
    assert str(info.value).startswith(f"{path}:{line}: {key}: ") and field in str(info.value), str(info.value)


@pytest.mark.parametrize("body, key", [("command_delay = 0.0125", "scenarios.x.command_delay"),
                                       ("quantization = -1e-6", "scenarios.x.quantization")])
def test_bad_options_are_exit_2_through_the_cli(tmp_path, body, key):
    path = tmp_path / "m.toml"
    path.write_text(_BAD.format(body=body))
    proc = cli("run", "--matrix", path, "--out", tmp_path / "out")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].find(f"{path}:8: {key}:") >= 0, proc.stderr
    assert "must be" in lines[0] and "Traceback" not in proc.stderr and not (tmp_path / "out").exists()
