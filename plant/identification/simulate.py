"""A log simulated from any plant family: what a real axis would record when playing a plan.

The axis has no reference motion: x4 ≡ 0 (``command_velocity_initial`` and its noise set to 0,
so y measures the shaft angle itself). Process noise (w2, and x5 drawn from its stationary law
and drifting while the shaft moves) and the sensor noise w1 ~ N(0, σ1²) are those of the
parameters (Table 2-1 by default). Randomness: ``SeedSequence(seed)`` spawns three children —
plant noise, sensor noise, x5(0).
"""

from __future__ import annotations

import numpy as np

from plant.identification.log import AxisLog
from plant.protocol import get_family
from plant.randomness import NoiseStream
from plant.state import SimOptions, Status

__all__ = ["simulate_log", "axis_params"]


def axis_params(params):
    """``params`` with no reference motion (x4 ≡ 0): the identification experiment's plant."""
    return params.replace(command_velocity_initial=0.0, command_velocity_std=0.0)


def simulate_log(plan: AxisLog, family: str, params, seed: int | None) -> tuple[AxisLog, dict[str, float]]:
    """Play ``plan`` on the family's plant; returns (the log with y, the truth at the start).

    ``seed=None`` is the noise-free plant (x5 = 0, no sensor noise). The truth holds the
    effective levels ``stiction`` = k̄s + x5(0) and ``coulomb`` = k̄c + x5(0) — what one
    experiment can identify (SPEC §2: identification is scored against the effective levels).

    Raises
    ------
    RuntimeError
        When the plant leaves ``ok`` (chatter, diverged).
    """
    fam = get_family(family)
    p = axis_params(params)
    if seed is None:
        noise, w1, x5, opts = None, np.zeros(plan.n), 0.0, SimOptions(noise=False)
    else:
        plant_ss, sensor_ss, x5_ss = np.random.SeedSequence(seed).spawn(3)
        noise = NoiseStream(np.random.default_rng(plant_ss))
        w1 = np.random.default_rng(sensor_ss).standard_normal(plan.n) * p.measurement_noise_std
        x5 = float(np.random.default_rng(x5_ss).standard_normal()) * p.correlated_friction_std
        opts = SimOptions(noise=True)
    state = fam.initial_state(p, x5)
    y = np.empty(plan.n)
    for n, cmd in enumerate(plan.commands):
        y[n] = fam.observe(p, state, w1[n])
        step = fam.step(state, cmd, p, noise, opts)
        if step.status is not Status.OK:
            raise RuntimeError(f"simulated log: sample {n}: plant status {step.status}: {step.message}")
        state = step.state
    truth = {"coulomb": max(p.coulomb + x5, 0.0), "stiction": max(p.stiction + x5, 0.0), "x5": x5}
    return plan.with_y(y), truth
