"""Controllers stepped by one compiled function (the ``compiled_law`` hook) in the families' compiled loops.

The reference is the runner's Python loop — ``observe``, the controller's ``step``, then
``delayed_step`` at every sample. The compiled loop (``PlantFamily.compiled_law_loop``) must
give every metric and the summary bit for bit, on every family, with the quantized sensor and
the compute delay, and when a step hands a sample back to Python mid-run. The compiled sensor and
delay are compared with :func:`plant.sensor.quantize` and :func:`plant.delay.delay_command`
(whose own hand-computed cases are in tests/test_sensor_delay.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from controllers.base import Controller
from controllers.law import CompiledLaw, law_command
from plant.delay import delay_command
from plant.drive import DriveCommand, DriveType
from plant.law_step import delay_segments, quantize
from plant.protocol import get_family
from plant.sensor import quantize as quantize_py

RUNTIME = ("runtime_s", "realtime_factor")


def _row(r):
    return r.status, r.message, {k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.summary


def _run(name_or_controller, scenario, seed, *, duration=3.0, noise=True, **kw):
    sc = builtin_scenarios()[scenario]
    c = make_controller(name_or_controller) if isinstance(name_or_controller, str) else name_or_controller
    calls = []
    step = c.step
    c.step = lambda y: calls.append(1) or step(y)          # counts the Python steps
    r = run_closed_loop(sc.params, c, duration_s=duration, warmup_s=1.0, seed=seed, noise=noise, family=sc.family,
                        model=sc.model, **kw)
    return r, len(calls), c


@pytest.mark.parametrize("name, scenario, seed, noise, options", [
    ("friction-ff-pid", "thesis", 0, True, {}),
    ("observer-pid", "thesis", 1, True, {}),
    ("reset-pid", "thesis", 2, True, {}),
    ("reset-pid", "thesis", 3, False, {"crossover": 10.0}),                  # one lead state
    ("friction-ff-pid", "stribeck", 4, True, {"stribeck_velocity": 4e-3}),    # (v/v_s)² through libm's pow
    ("observer-pid", "compliant", 5, True, {}),
    ("reset-pid", "lugre", 6, True, {}),
    ("friction-ff-pid", "ripple", 7, True, {}),
    ("observer-pid", "quantized", 8, True, {}),
    ("reset-pid", "delayed", 9, True, {}),
    ("friction-ff-pid", "delayed", 10, True, {}),
    ("linear", "quantized", 11, True, {}),
    ("linear", "delayed", 12, True, {}),
    ("dithered", "delayed", 13, True, {}),
    ("dithered", "quantized", 14, True, {}),
    ("pulse-width", "disturbed", 15, True, {}),                  # the disturbed plant's compiled loop
    ("reset-pid", "disturbed", 16, True, {}),
    ("observer-pid", "disturbed", 17, True, {}),
    ("friction-ff-pid", "disturbed", 18, True, {}),
    ("linear", "disturbed", 19, False, {}),
])
def test_compiled_rows_are_the_python_rows(name, scenario, seed, noise, options):
    c = make_controller(name, **options)
    compiled, n_python_steps, c = _run(c, scenario, seed, noise=noise)
    recorded, n_recorded_steps, _ = _run(make_controller(name, **options), scenario, seed, noise=noise, record=True)
    python, _, _ = _run(make_controller(name, **options), scenario, seed, noise=noise, compiled=False)
    assert n_python_steps == 0 and n_recorded_steps == 300       # the compiled loop really ran
    assert compiled.status == "ok"
    assert _row(compiled) == _row(recorded) == _row(python)      # every metric and the summary, exactly


def test_the_state_after_a_compiled_run_is_the_controllers_own():
    """The compiled loop advances the controller's own arrays: its readable state afterwards is
    what stepping it from Python leaves."""
    a, _, ca = _run("observer-pid", "thesis", 3)
    b, _, cb = _run("observer-pid", "thesis", 3, compiled=False)
    assert ca.internals() == cb.internals() and ca._n == cb._n == 300


# --- a step that hands samples back ------------------------------------------------------------

@njit(cache=True)
def _handing_step(s, p, y, offs, levs):
    """u = clip(−K·y) then half of it from mid-interval; hands sample p[1] back until s[1] says
    Python has taken it; from sample p[2] on the level is NaN (the Python path raises)."""
    n = s[0]
    if n == p[1] and s[1] == 0.0:
        return 0
    if n == p[1] + 1.0:
        s[1] = 0.0                           # back to compiled
    s[0] = n + 1.0
    level = min(max(-p[0] * y, -p[3]), p[3])
    if n >= p[2]:
        level = math.nan
    offs[0], levs[0] = 0.0, level
    offs[1], levs[1] = p[4], 0.5 * level
    return 2


class _Handing(Controller):
    """A proportional law whose compiled step hands one sample back (test only, not registered)."""

    name = "handing"

    def __init__(self, hand_at: float, nan_from: float = math.inf) -> None:
        super().__init__()
        self.hand_at, self.nan_from = hand_at, nan_from

    def reset(self, params, rng):
        self._s = np.zeros(2)
        self._p = np.array([400.0, self.hand_at, self.nan_from, params.u_max, 0.5 * params.sample_period])
        self._offs, self._levs = np.zeros(2), np.zeros(2)

    def step(self, y):
        k = _handing_step(self._s, self._p, y, self._offs, self._levs)
        if k == 0:                           # what the compiled step cannot do: done here
            self._s[1] = 1.0
            k = _handing_step(self._s, self._p, y, self._offs, self._levs)
        return law_command(k, self._offs, self._levs, DriveType.LINEAR)

    def compiled_law(self):
        return CompiledLaw(_handing_step, self._s, self._p, DriveType.LINEAR, 2)


@pytest.mark.parametrize("scenario, hand_at", [("thesis", 137.0), ("delayed", 137.0), ("quantized", 0.0),
                                                ("stribeck", 299.0), ("compliant", 50.0), ("disturbed", 137.0)])
def test_a_sample_handed_back_is_done_in_python_and_the_loop_resumes_compiled(scenario, hand_at):
    compiled, n_python, c = _run(_Handing(hand_at=hand_at), scenario, 2)
    python, n_all, _ = _run(_Handing(hand_at=hand_at), scenario, 2, compiled=False)
    assert n_python == 1 and n_all == 300 and c._s[0] == 300     # one sample in Python, the rest compiled
    assert compiled.status == "ok" and _row(compiled) == _row(python)


def test_a_command_python_rejects_ends_both_paths_with_the_same_error():
    compiled, n_python, _ = _run(_Handing(hand_at=-1.0, nan_from=200.0), "delayed", 1)
    python, _, _ = _run(_Handing(hand_at=-1.0, nan_from=200.0), "delayed", 1, compiled=False)
    assert n_python == 1                                          # handed back at the NaN, which raises
    assert compiled.status == "error" and "finite" in compiled.message
    assert _row(compiled)[:2] == _row(python)[:2]


@njit(cache=True)
def _pulse_step(s, p, y, offs, levs):
    """Every p[2]-th sample a bridge pulse of width min(p[0]·|y|, p[1]) [s] towards zero, else off."""
    n = s[0]
    s[0] = n + 1.0
    w = min(p[0] * abs(y), p[1])
    offs[0], levs[0] = 0.0, 0.0
    if n % p[2] != 0.0 or not w > 0.0:
        return 1
    levs[0] = -p[3] if y > 0 else p[3]
    offs[1], levs[1] = w, 0.0
    return 2


class _Pulses(Controller):
    """Bridge pulses from a compiled step (test only, not registered)."""

    name = "pulses"
    drive = DriveType.BRIDGE

    def reset(self, params, rng):
        self._s, self._p = np.zeros(1), np.array([40.0, 2e-3, 5.0, params.u_max])
        self._offs, self._levs = np.zeros(2), np.zeros(2)

    def step(self, y):
        return law_command(_pulse_step(self._s, self._p, y, self._offs, self._levs), self._offs, self._levs,
                           DriveType.BRIDGE)

    def compiled_law(self):
        return CompiledLaw(_pulse_step, self._s, self._p, DriveType.BRIDGE, 2)


@pytest.mark.parametrize("scenario", ["thesis", "delayed", "lugre"])
def test_bridge_pulses_from_a_compiled_step_are_the_python_rows(scenario):
    compiled, n_python, _ = _run(_Pulses(), scenario, 4)
    python, _, _ = _run(_Pulses(), scenario, 4, compiled=False)
    assert n_python == 0 and compiled.status == "ok"
    assert compiled.metrics["n_events"] > 100                    # pulses and flybacks happened
    assert _row(compiled) == _row(python)


# --- the compiled sensor and delay ---------------------------------------------------------------

def test_compiled_quantizer_is_the_sensors_bit_for_bit():
    rng = np.random.default_rng(0)
    q = 1e-6
    values = np.concatenate([rng.normal(0, 1e-4, 20000), (np.arange(-50, 50) + 0.5) * q,   # ties
                             rng.normal(0, 1e-4, 200) * 1e12, [0.0, -0.0, 1e300, -1e300, 5e-324]])
    for step in (q, 7.3e-7, 1e-300, 0.0):
        got = np.array([quantize(v, step) for v in values])
        want = np.array([quantize_py(float(v), step) for v in values])
        assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))


def test_compiled_delay_is_delay_command_over_a_random_command_sequence():
    rng = np.random.default_rng(1)
    period = 0.01
    for delay in (1e-3, 2e-3, 5e-3, 9.9e-3):
        pending = None
        p_o, p_l, n_p = np.zeros(12), np.zeros(12), 1
        for _ in range(400):
            k = int(rng.integers(1, 5))
            offs = np.concatenate([[0.0], np.sort(rng.uniform(0, period, k - 1))])
            levs = rng.choice([-3.0, 0.0, 1.5, 3.0], k)
            if len(set(offs)) < k:
                continue
            cmd = DriveCommand(tuple(zip(offs, levs)), DriveType.LINEAR)
            now, pending = delay_command(cmd, pending, delay, period)
            now_o, now_l, c_o, c_l = (np.zeros(12) for _ in range(4))
            n_now, n_c = delay_segments(offs, levs, k, p_o, p_l, n_p, delay, period, now_o, now_l, c_o, c_l)
            assert tuple(zip(now_o[:n_now], now_l[:n_now])) == now.segments
            assert tuple(zip(c_o[:n_c], c_l[:n_c])) == pending.segments
            p_o[:n_c], p_l[:n_c], n_p = c_o[:n_c], c_l[:n_c], n_c


def test_compiled_law_checks_its_fields():
    s, p = np.zeros(2), np.zeros(5)
    with pytest.raises(ValueError, match="state"):
        CompiledLaw(_handing_step, np.zeros(2, dtype=np.float32), p, DriveType.LINEAR)
    with pytest.raises(ValueError, match="max_segments"):
        CompiledLaw(_handing_step, s, p, DriveType.LINEAR, 0)
    for wrong in (njit(lambda s, p: 1), lambda s, p, y, o, l: 1):
        with pytest.raises(ValueError, match="STEP_SIGNATURE"):
            CompiledLaw(wrong, s, p, DriveType.LINEAR)
    with pytest.raises(ValueError, match="drive"):
        CompiledLaw(_handing_step, s, p, "linear")


def test_the_compiled_loop_with_a_disturbance_torque_is_the_disturbed_plants():
    from plant.multimode import disturbed_loop
    fam = get_family("multimode")
    sc = builtin_scenarios()
    for name in ("thesis", "quantized", "delayed"):
        assert fam.compiled_loop(sc[name].params) is fam.compiled_law_loop is not None
    assert fam.compiled_loop(sc["disturbed"].params) is disturbed_loop.run_compiled_law


def test_time_limit_stops_the_compiled_law_loop():
    r, n_python, _ = _run("reset-pid", "delayed", 0, duration=50.0, time_limit_s=1e-9)
    assert n_python == 0
    assert r.status == "error" and r.message.startswith("time limit of 1e-09 s exceeded at t = ")
    assert 1.0 <= r.simulated_s <= 20.0       # within the first chunks of 1000 samples (10 s)


def test_a_lead_path_outside_the_compiled_kernels_is_fed_in_and_not_compiled():
    """More than two lead states (no design of the registered ranges has them) use numpy's
    product outside the compiled step: the same law to rounding, and no compiled loop."""
    from controllers.pid import P_NLEAD
    P = builtin_scenarios()["thesis"].params
    a, b = make_controller("reset-pid"), make_controller("reset-pid")
    for c in (a, b):
        c.reset(P, np.random.default_rng(0))
    b._layout.compiled, b._p[P_NLEAD] = False, 0.0
    b.pid.proportional = b.pid.__class__.proportional.__get__(b.pid)    # the numpy form
    assert b.compiled_law() is None and a.compiled_law() is not None
    y = np.random.default_rng(1).normal(0, 2e-5, 400)
    ua = [a.step(v).segments[0][1] for v in y]
    ub = [b.step(v).segments[0][1] for v in y]
    np.testing.assert_allclose(ub, ua, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name, scenario, seed", [
    ("observer-pid", "thesis", 21), ("reset-pid", "delayed", 22), ("friction-ff-pid", "stribeck", 23),
    ("pulse-width", "disturbed", 24),
])
def test_an_interval_that_runs_out_of_noise_is_undone_and_redone(monkeypatch, name, scenario, seed):
    """The compiled law loop's ``NoiseExhausted`` branch: with a 64-normal block and no margin,
    every interval that reaches the end of the buffer runs off it; the loop restores the controller's state,
    grows the buffer and redoes the interval. The rows must be the Python loop's (whose noise
    comes in 8192-normal blocks: the stream's normals do not depend on the blocking)."""
    import bench.runner as runner
    import plant.law_driver as driver
    from plant.randomness import NoiseExhausted, NoiseStream

    python, _, _ = _run(make_controller(name), scenario, seed, compiled=False)
    exhausted = []
    wrapped: dict = {}
    specialised = driver._specialised

    def counting(chunk, args):
        fn = specialised(chunk, args)
        if fn not in wrapped:
            def call(*a, _fn=fn):
                try:
                    return _fn(*a)
                except NoiseExhausted:
                    exhausted.append(1)
                    raise
            wrapped[fn] = call
        return wrapped[fn]

    monkeypatch.setattr(driver, "_LAST", {})
    monkeypatch.setattr(driver, "_specialised", counting)
    monkeypatch.setattr(driver, "NOISE_MARGIN", 0)
    monkeypatch.setattr(runner, "NoiseStream", lambda rng: NoiseStream(rng, block=64))
    compiled, n_python_steps, _ = _run(make_controller(name), scenario, seed)
    assert n_python_steps == 0 and len(exhausted) >= 3            # the compiled loop ran and redid intervals
    assert _row(compiled) == _row(python)


@pytest.mark.parametrize("name, seed", [("pulse-width", 22), ("reset-pid", 23)])
def test_two_mass_compiled_loop_with_a_delay_and_a_quantizer_is_the_python_loop(name, seed):
    """The two-mass compiled loop hands its kernel the delayed segments by count (no per-sample
    copies): compliant with a 2 ms compute delay and a 1 µrad quantizer, compiled against the
    runner's Python loop, every metric and the summary bit for bit."""
    import dataclasses
    sc = builtin_scenarios()["compliant"]
    params = dataclasses.replace(sc.params, command_delay=2e-3, quantization=1e-6)
    rows = []
    for compiled in (True, False):
        c = make_controller(name)
        calls = []
        step = c.step
        c.step = lambda y: calls.append(1) or step(y)
        r = run_closed_loop(params, c, duration_s=3.0, warmup_s=1.0, seed=seed, family=sc.family, model=sc.model,
                            compiled=compiled)
        rows.append((_row(r), len(calls)))
    (fast, n_fast), (python, n_python) = rows
    assert n_fast == 0 and n_python == 300          # the compiled loop really ran, the reference did not
    assert fast[0] == "ok" and fast == python
