"""The Euler–Maruyama plant behind the family seam (plant.multimode.em_family, issue 27).

Truth: the exact family's step (closed forms, checked elsewhere against expm and solve_ivp).
Noise-free, Euler's global error is O(h): on a linear-stage sequence (no edges, no events at
grid-dependent times) the x1 error falls ten-fold per decade of h. A step of the wrong size,
a dropped drive segment or a wrong noise scaling fails these tests.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.exact import fixed_step, fixed_step_family, schedule_from_commands
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams
from plant.protocol import DEFAULT_FAMILY, get_family
from plant.randomness import NoiseStream
from plant.state import X1, SimOptions, Status

P = PlantParams()
QUIET = SimOptions(noise=False)


def _linear_commands() -> list[DriveCommand]:
    levels = [0.9, 0.9, -0.2, 0.0, -0.95, -0.95, 0.3, 0.0, 0.0, 0.0]
    return [DriveCommand.hold(v * P.u_max, DriveType.LINEAR) for v in levels]


def _pulse_commands() -> list[DriveCommand]:
    out = []
    for k in range(12):
        sign = 1.0 if k % 4 < 2 else -1.0
        out.append(DriveCommand(((0.0, sign * P.u_max), (1.2e-3, 0.0)), DriveType.BRIDGE) if k % 2 == 0
                   else DriveCommand(((0.0, 0.0),), DriveType.BRIDGE))
    return out


def _run(family, commands, noise=None, options=QUIET):
    state = family.initial_state(P, 0.0)
    xs, peak = [float(state.x[X1])], 0.0
    for c in commands:
        r = family.step(state, c, P, noise, options)
        assert r.status is Status.OK
        state = r.state
        xs.append(float(state.x[X1]))
        peak = max(peak, r.peak_abs_error)
    return np.array(xs), peak, state


def test_em_family_converges_to_the_exact_plant_at_order_one():
    exact, _, _ = _run(get_family(DEFAULT_FAMILY), _linear_commands())
    scale = np.max(np.abs(exact))
    assert scale > 1e-2                                   # the sequence moves the shaft (rad)
    err = {h: np.max(np.abs(_run(fixed_step_family(h), _linear_commands())[0] - exact)) for h in (1e-4, 1e-5, 1e-6)}
    for coarse, fine in ((1e-4, 1e-5), (1e-5, 1e-6)):
        order = math.log10(err[coarse] / err[fine])
        assert 0.8 <= order <= 1.2, (coarse, fine, err)   # Euler: global error O(h)
    assert err[1e-6] < 5e-5 * scale                        # measured 1.5e-5 relative


def test_em_family_applies_the_pulse_edges_of_a_bridge_command():
    exact, peak_exact, final_exact = _run(get_family(DEFAULT_FAMILY), _pulse_commands())
    moves = np.abs(np.diff(exact))
    assert moves.max() > 5e-7                             # the pulses move the shaft
    errs = []
    for h in (1e-4, 1e-5, 1e-6):
        x, peak, final = _run(fixed_step_family(h), _pulse_commands())
        errs.append(np.max(np.abs(x - exact)) / np.max(np.abs(exact)))
        assert final.mode == final_exact.mode == 2 and not final.flyback
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 2e-4                                 # measured 4.3e-5 at h = 1 µs


def test_em_family_noisy_step_is_the_reference_em_on_the_same_normals():
    """Through the seam, the noisy step reads 3 normals per step from the run's stream in the
    reference simulator's order: the same path as fixed_step fed the same generator."""
    h, seed = 1e-5, 12345
    commands = _linear_commands()[:5]
    family = fixed_step_family(h)
    noise = NoiseStream.from_seed(seed)
    x_seam, _, _ = _run(family, commands, noise, SimOptions())
    sched = schedule_from_commands(commands, P.sample_period)
    ref = fixed_step(P, sched, h, rng=np.random.default_rng(np.random.SeedSequence(seed)),
                     sample_every=P.sample_period)
    np.testing.assert_allclose(x_seam, ref.x1_samples[:, 0], rtol=1e-12, atol=1e-15)
    assert np.max(np.abs(x_seam - _run(family, commands)[0])) > 1e-7     # the noise mattered


def test_em_family_rounds_its_step_to_fill_the_interval_and_rejects_bad_input():
    fam = fixed_step_family(3e-5)
    assert fam.effective_step(0.01) == pytest.approx(0.01 / 333)
    with pytest.raises(ValueError, match="dt"):
        fixed_step_family(0.0)
    with pytest.raises(ValueError, match="disturbance_torque_std"):
        fam.step(fam.initial_state(P, 0.0), _linear_commands()[0], P.replace(disturbance_torque_std=0.01),
                 None, QUIET)
