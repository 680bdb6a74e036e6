"""A Gymnasium environment of any scenario: ``solnic-bench/StickSlip-v0`` (docs/gym.md).

One ``step`` is one sample interval of the scenario's true plant, through the same
:class:`bench.runner.PlantLoop` the bench runner steps (the family's ``observe`` and
``delayed_step``, SPEC §2, §11), so a policy trained here meets in a matrix cell the plant it
trained on, sample for sample:

* observation: the last N measured samples y [rad], oldest first, zeros before the first
  (:class:`controllers.policy.MeasurementWindow`, shared with the policy adapter);
* action: the drive command (:func:`controllers.policy.command_of`): a level in ±u_max [ozf·in]
  for the linear amplifier, a signed pulse width in ±τs [s] for the switched bridge;
* reward of the interval [n·τs, (n+1)·τs): −(w_e·|x1((n+1)·τs)| + w_i·(1/Δt)∫|x3| dt), the true
  error at the next sample [rad] and the interval's exact mean |current| [ozf·in] (the summands
  of ``mean_abs_current``, SPEC §3), weights ``error_weight`` [1/rad] and ``current_weight``
  [1/(ozf·in)];
* ``reset(seed=s)``: the plant noise, sensor noise, x5(0) and a scenario's mismatch drawn from
  ``SeedSequence(s)`` exactly as the matrix cell with seed s draws them; without a seed the run
  seed is drawn from the environment's own generator (Gymnasium's ``np_random``);
* terminated when the plant leaves ``ok`` (status in ``info``); truncated after ``max_steps``
  (default: the scenario's duration).

``info`` carries the family's truth at the new instant (``x1``…``x5``, ``mode``, ``u``,
``ks_true``, ``kc_true`` and the family's own), ``t``, ``y``, ``seed`` and the interval's
``int_abs_current``, ``peak_abs_error`` and ``status``.

Gymnasium ≥ 1.0 discovers no plugins (its entry-point plugin system was removed): importing this
module registers the id, or ``gymnasium.make("bench.gym_env:solnic-bench/StickSlip-v0")`` imports it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from bench.matrix import load_matrix
from bench.runner import PlantLoop
from bench.scenarios import Scenario, builtin_scenarios
from controllers.policy import MeasurementWindow, action_bounds, command_of
from plant.drive import DriveType
from plant.protocol import get_family
from plant.state import X1, SimOptions, Status

__all__ = ["StickSlipEnv", "ENV_ID", "register_envs"]

ENV_ID = "solnic-bench/StickSlip-v0"


class StickSlipEnv(gymnasium.Env):
    """The closed loop of one scenario with the controller left open (module docstring).

    Parameters
    ----------
    scenario : str or Scenario
        A built-in scenario name (``solnic-bench list``), a scenario of ``matrix`` by name, or a
        :class:`~bench.scenarios.Scenario`.
    matrix : str or Path, optional
        A matrix file whose scenarios (custom ones, with its run length) ``scenario`` names.
    drive : str
        ``"linear"`` (amplifier) or ``"bridge"`` (switched bridge, SPEC §2).
    window : int
        N ≥ 1 measured samples observed.
    error_weight, current_weight : float
        w_e ≥ 0 [1/rad], w_i ≥ 0 [1/(ozf·in)] of the reward. Defaults 1e4 (100 µrad costs 1)
        and 0.01.
    max_steps : int, optional
        Episode length in samples; default the scenario's ``duration_s``/τs.
    noise : bool
        False switches off every noise source, as in :func:`bench.runner.run_closed_loop`.
    """

    metadata = {"render_modes": []}

    def __init__(self, scenario: str | Scenario = "thesis", drive: str = DriveType.LINEAR.value, window: int = 1,
                 error_weight: float = 1e4, current_weight: float = 0.01, max_steps: int | None = None,
                 noise: bool = True, matrix: str | Path | None = None) -> None:
        if isinstance(scenario, str):
            if matrix is not None:
                known = {sc.name: sc for sc in load_matrix(matrix, check_resets=False).scenarios}
                where = f"in {matrix}"
            else:
                known, where = builtin_scenarios(), "built-in"
            if scenario not in known:
                raise ValueError(f"scenario: unknown {scenario!r}; {where}: {sorted(known)}")
            scenario = known[scenario]
        if not isinstance(scenario, Scenario):
            raise ValueError(f"scenario must be a built-in name or a Scenario, got {type(scenario).__name__}")
        try:
            self.drive = DriveType(drive)
        except ValueError:
            raise ValueError(f"drive must be one of {[d.value for d in DriveType]}, got {drive!r}") from None
        for name, w in (("error_weight", error_weight), ("current_weight", current_weight)):
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not (math.isfinite(w) and w >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {w!r}")
        tau = scenario.params.sample_period
        if max_steps is None:
            max_steps = int(round(scenario.duration_s / tau))
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f"max_steps must be an integer >= 1, got {max_steps!r}")
        self.scenario = scenario
        self.model = scenario.model_params()     # what a controller (or a policy's reset) is told
        self.family = get_family(scenario.family)
        self.error_weight, self.current_weight = float(error_weight), float(current_weight)
        self.max_steps = max_steps
        self.noise = bool(noise)
        self._window = MeasurementWindow(window)   # validates window
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(window,), dtype=np.float64)
        low, high = action_bounds(self.drive, scenario.params)
        self.action_space = spaces.Box(low, high, shape=(1,), dtype=np.float64)
        self.loop: PlantLoop | None = None
        self.seed_used: int | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start the run with ``seed`` (the matrix cell's noise for that seed); returns (obs, info)."""
        super().reset(seed=seed)
        if seed is None:
            seed = int(self.np_random.integers(0, 2**63 - 1))
        self.seed_used = seed
        truth, _ = self.scenario.realise(seed)
        self._params = truth
        self.loop = PlantLoop(self.family, truth, seed=seed, n_measurements=self.max_steps + 1, noise=self.noise,
                              options=SimOptions(noise=self.noise))
        self._ended = False
        self._window.reset()
        y = self.loop.measure()
        return self._window.push(y), self._info(y)

    def step(self, action: Any):
        """One sample interval under ``action``; returns (obs, reward, terminated, truncated, info)."""
        if self.loop is None:
            raise RuntimeError("call reset() before step()")
        if self.loop.n >= self.max_steps or self._ended:
            raise RuntimeError("the episode has ended (plant status or max_steps): call reset()")
        interval = self.loop.advance(command_of(action, self.drive, self._params))
        y = self.loop.measure()
        mean_abs_current = interval.int_abs_current / interval.duration if interval.duration > 0 else 0.0
        reward = -(self.error_weight * abs(float(self.loop.state.x[X1])) + self.current_weight * mean_abs_current)
        terminated = interval.status is not Status.OK
        self._ended = terminated
        truncated = self.loop.n >= self.max_steps and not terminated
        info = self._info(y)
        info.update(status=str(interval.status), message=interval.message,
                    int_abs_current=float(interval.int_abs_current), peak_abs_error=float(interval.peak_abs_error))
        return self._window.push(y), float(reward), terminated, truncated, info

    def _info(self, y: float) -> dict[str, Any]:
        return {"t": float(self.loop.state.t), "y": float(y), "seed": self.seed_used, **self.loop.truth()}


def register_envs() -> None:
    """Register :data:`ENV_ID` with Gymnasium (once)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point=StickSlipEnv)


register_envs()
