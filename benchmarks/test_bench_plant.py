"""The plant's hot paths: one pulse, and one sample interval of each drive.

Targets (issue #10): noise-free ``pulse_response`` ≤ 5 µs median; one interval is one compiled call. Each body also checks its result
against a closed form or the SPEC's reference value, so ``make test`` exercises it for real.
"""

import numpy as np
import pytest

from plant import DriveCommand, DriveType, NoiseStream, SimOptions, Status, advance, initial_state, pulse_response
from plant.state import X1, X3

PULSE_S = 1.3e-3           # a typical solnic correction (section 7.3: 1.26–1.43 ms)


def test_pulse_response_noise_free(benchmark, params):
    result = benchmark(pulse_response, params, 1.5e-3)
    assert result.delta_c == pytest.approx(4.8592e-6, rel=1e-4)       # SPEC §2 reference value
    assert result.t_breakaway == pytest.approx(params.breakaway_time, abs=1e-12)


def _interval(params, command, rng, noise):
    """One sample interval from a stuck shaft with no current, metrics on (as in a run)."""
    state = initial_state(params, x5=0.0)
    return advance(state, command, params, rng, SimOptions(noise=noise))


@pytest.mark.parametrize("noise", [False, True], ids=["noise-free", "noisy"])
def test_interval_bridge_pulse(benchmark, params, noise):
    rng = NoiseStream.from_seed(7) if noise else None
    command = DriveCommand.pulse(2e-3, PULSE_S, params.u_max)
    step = benchmark(_interval, params, command, rng, noise)
    assert step.status == Status.OK, step.message
    state = step.state
    assert state.mode == 2 and state.x[X3] == 0.0       # flyback over, shaft stuck again by 10 ms
    assert state.x[X1] > 0.0                            # moved forward past the ramp's 0.3 µrad


@pytest.mark.parametrize("noise", [False, True], ids=["noise-free", "noisy"])
def test_interval_linear_hold(benchmark, params, noise):
    rng = NoiseStream.from_seed(8) if noise else None
    command = DriveCommand.hold(3.0, DriveType.LINEAR)    # above stiction: breaks away in the interval
    step = benchmark(_interval, params, command, rng, noise)
    assert step.status == Status.OK, step.message
    # x3 follows the first-order lag toward the held level: x3(τs) = u·(1 − e^(−τs/τ3)).
    assert step.state.x[X3] == pytest.approx(3.0 * -np.expm1(-params.sample_period / params.motor_time_constant),
                                        rel=1e-12)



@pytest.mark.parametrize("method", ["numpy", "compiled"])
def test_noise_stream_normals(benchmark, method):
    """32 768 unit normals, as one NoiseStream refill draws them: numpy's
    ``Generator.standard_normal`` against plant.pcg64_normals (issue 27: 7.8 → 2.0 ns a normal on
    the 2-core machine). The compiled block must be numpy's, bit for bit, from the same state."""
    from plant.pcg64_normals import draw_into
    out = np.empty(32_768)
    rng = np.random.default_rng(np.random.SeedSequence(3))
    draw = (lambda: rng.standard_normal(out=out)) if method == "numpy" else (lambda: draw_into(rng, out))
    benchmark(draw)
    twin = np.random.default_rng()
    twin.bit_generator.state = rng.bit_generator.state
    draw()
    assert np.array_equal(out.view(np.uint64), twin.standard_normal(32_768).view(np.uint64))
    assert twin.bit_generator.state == rng.bit_generator.state
