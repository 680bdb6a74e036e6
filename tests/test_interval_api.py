"""The pure interval step's contract: inputs untouched, one compiled signature for any state."""

import pickle

import numpy as np

from plant import PlantParams
from plant.drive import DriveCommand, DriveType
from plant.multimode.interval import advance, interval_kernel
from plant.state import PlantState, SimOptions, initial_state


def test_a_writable_or_unpickled_state_gives_the_same_step_and_no_second_compilation():
    p = PlantParams()
    opts = SimOptions(noise=False)
    cmd = DriveCommand.pulse(0.0, 1.3e-3, p.u_max)
    s = initial_state(p, x5=0.0)
    ref = advance(s, cmd, p, None, opts)
    n_signatures = len(interval_kernel.signatures)
    writable = PlantState(s.t, np.array(s.x), s.mode, s.flyback)
    unpickled = pickle.loads(pickle.dumps(s))
    for other in (writable, unpickled):
        before = other.x.copy()
        got = advance(other, cmd, p, None, opts)
        np.testing.assert_array_equal(got.state.x, ref.state.x)
        np.testing.assert_array_equal(other.x, before)          # the caller's state is not touched
    # advance copies the frozen vector into a writable one, the kernels' one signature (docs/plant.md):
    # a read-only vector would otherwise be a second numba specialisation (seconds of compile)
    assert len(interval_kernel.signatures) == n_signatures
    assert [sig[0].mutable for sig in interval_kernel.signatures] == [True]
    assert ref.state.x[0] != s.x[0]                            # the pulse moved the shaft
