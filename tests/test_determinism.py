"""Same seed → bit-identical trajectories (in the manner of Gymnasium's check_step_determinism)."""

import numpy as np

from bench.runner import run_closed_loop
from controllers import make_controller
from plant import PlantParams, pulse_response


def test_pulse_response_is_deterministic_per_seed():
    p = PlantParams()
    a = [pulse_response(p, 1.3e-3, seed=s).delta_c for s in range(5)]
    b = [pulse_response(p, 1.3e-3, seed=s).delta_c for s in range(5)]
    assert a == b and len(set(a)) == 5


def test_closed_loop_is_bit_identical_for_the_same_seed():
    p = PlantParams()
    runs = [run_closed_loop(p, make_controller("solnic"), duration_s=3.0, seed=s, record=True) for s in (5, 5, 6)]
    first, again, other = runs
    for key in ("x1", "x2", "x3", "y", "u"):
        assert np.array_equal(first.samples[key], again.samples[key])
    assert np.array_equal(first.events["t"], again.events["t"])
    assert first.metrics["peak_error_rad"] == again.metrics["peak_error_rad"]
    assert not np.array_equal(first.samples["y"], other.samples["y"])


def test_zero_length_stuck_step_at_breakaway():
    """Stuck exactly at ks with the torque still rising breaks away after a zero-length step;
    its covariance is exactly 0 (this once divided by zero)."""
    from plant import DriveCommand, DriveType, NoiseStream, PlantState, advance, initial_state
    from plant.state import X3

    p = PlantParams()
    x = initial_state(p, x5=0.0).x.copy()
    x[X3] = p.stiction
    step = advance(PlantState(0.0, x, 2, False), DriveCommand.hold(p.u_max, DriveType.LINEAR), p,
                   NoiseStream.from_seed(0))
    assert step.status == "ok", step.message
    assert np.all(np.isfinite(step.state.x)) and step.state.mode == 3
