"""Compile the plant's kernels (and compute the controllers' default designs) once in the process
that forks the cell processes.

Imported by the forkserver (``bench.isolation.PRELOAD``): a few sample intervals of the closed
loop, with and without noise, with a held level and with pulses, so that every cell process
starts with the numba kernels compiled (or loaded from numba's cache) instead of compiling
them inside its own wall-clock limit. Results do not depend on it.
"""

from __future__ import annotations

import numpy as np

from controllers.models.acker import pulse_response as model_pulse
from plant import pulse_response
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams
from plant.protocol import DEFAULT_FAMILY, get_family
from plant.randomness import NoiseStream
from plant.state import SimOptions


def warm() -> None:
    """Advance a few intervals of the default family through each kernel path (noise on/off,
    record on/off); the pulse through the simulator and the controllers' closed form."""
    family = get_family(DEFAULT_FAMILY)
    params = PlantParams()
    commands = [DriveCommand.hold(0.0, DriveType.LINEAR), DriveCommand.hold(0.5 * params.u_max, DriveType.LINEAR),
                DriveCommand(((0.0, params.u_max), (0.3 * params.sample_period, 0.0)), DriveType.BRIDGE)]
    for noise in (True, False):
        for record in (False, True):
            state = family.initial_state(params, 0.0)
            stream = NoiseStream(np.random.default_rng(0)) if noise else None
            for command in commands:
                state = family.step(state, command, params, stream, SimOptions(noise=noise), record=record).state
    model_pulse(params, 1.2e-3)                 # the closed form (pulse controllers' predictors)
    pulse_response(params, 1.2e-3)
    pulse_response(params, 1.2e-3, seed=0)


def warm_designs() -> None:
    """Reset every registered controller at its default options on Table 2-1: the designs they
    cache per process (e.g. the linear crossover search, ~0.3 s of python-control per plant and
    mode, cached on the plant fields it reads) are then in memory in every cell process forked
    from here, instead of being recomputed in each (issue 27: ~0.8 s per cell process that meets
    the linear-design controllers; ~1.4 s here, once per run). A cache hit returns what the
    computation would: no result changes."""
    from controllers import available_controllers

    params = PlantParams()
    for cls in available_controllers().values():
        try:
            cls().reset(params, np.random.default_rng(0))
        except Exception:  # noqa: BLE001 — a controller that cannot reset here designs in its cells
            pass


try:
    warm()
    warm_designs()
except Exception:  # a warm-up must never stop the cells; they compile on their own then
    pass
