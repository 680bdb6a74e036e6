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
    from plant.drive import DriveCommand, DriveType
    from plant.multimode import advance, initial_state
    from plant.transition import X3

    p = PlantParams()
    rng = np.random.default_rng(0)
    state = initial_state(p, x5=0.0)
    state.X[X3] = p.stiction
    state, status, message = advance(state, DriveCommand.hold(p.u_max, DriveType.LINEAR), p.sample_period, p, rng)
    assert status == "ok", message
    assert np.all(np.isfinite(state.X)) and state.mode == 3
