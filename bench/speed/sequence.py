"""The command sequence every contestant replays: a registered controller's recorded commands
(or a synthetic pulse train) and the replay window cut from them (module doc of
:mod:`bench.speed`, item 1)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from plant.drive import DriveCommand, DriveType
from bench.exact import Schedule, advance, schedule_from_commands
from plant.params import PlantParams
from plant.state import X1, X2, X3, X4, X5, PlantState, SimOptions, Status, initial_state

__all__ = ["record_commands", "synthetic_pulse_train"]


_SYNTHETIC_WIDTH_S = 1.3e-3

_SYNTHETIC_EVERY = 6          # sample intervals between synthetic pulses (60 ms)


def record_commands(params: PlantParams, controller_name: str, duration_s: float, *,
                    seed: int = 0) -> tuple[list[DriveCommand], str, str]:
    """Run a registered controller closed loop, noise-free, and record its commands.

    Returns
    -------
    (commands, status, message)
        ``status`` is the run's status; on anything but ``ok`` the list may be short.
    """
    from bench.runner import run_closed_loop
    from controllers import make_controller

    recorder = _recording_class()(make_controller(controller_name))
    result = run_closed_loop(params, recorder, duration_s=duration_s, seed=seed, noise=False)
    return recorder.commands, result.status, result.message


@functools.cache
def _recording_class() -> type:
    """A controller wrapper that keeps every command (built lazily: controllers import slowly)."""
    from controllers.base import Controller

    class Recording(Controller):
        """Wraps a controller and keeps every command it returns."""

        def __init__(self, inner: Controller) -> None:
            self.inner = inner
            self.commands: list[DriveCommand] = []

        def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
            self.commands.clear()
            self.inner.reset(params, rng)

        def step(self, y: float) -> DriveCommand:
            command = self.inner.step(y)
            self.commands.append(command)
            return command

        def internals(self) -> dict[str, float]:
            return self.inner.internals()

        def summary(self) -> dict[str, Any]:
            return self.inner.summary()

    return Recording


def synthetic_pulse_train(params: PlantParams, duration_s: float) -> list[DriveCommand]:
    """Open-loop stand-in: 1.3 ms pulses of alternating sign every 60 ms, off otherwise."""
    n = int(round(duration_s / params.sample_period))
    off = DriveCommand(((0.0, 0.0),), DriveType.BRIDGE)
    out, sign = [], 1.0
    for k in range(n):
        if k % _SYNTHETIC_EVERY == 0:
            out.append(DriveCommand(((0.0, sign * params.u_max), (_SYNTHETIC_WIDTH_S, 0.0)), DriveType.BRIDGE))
            sign = -sign
        else:
            out.append(off)
    return out


@dataclass
class _Sequence:
    """A replay window: commands, start state and the pulse bookkeeping of the Δc metric."""

    name: str
    source: str
    commands: list[DriveCommand]
    state0: PlantState
    params: PlantParams
    recorded_at_s: float = 0.0                       # where the window starts in the recording
    schedule: Schedule = field(init=False)
    sample_times: np.ndarray = field(init=False)
    pulse_bounds: np.ndarray = field(init=False)     # sample indices: pulse k spans [b_k, b_{k+1}]

    def __post_init__(self) -> None:
        tau = self.params.sample_period
        self.schedule = schedule_from_commands(self.commands, tau, t0=self.state0.t)
        self.sample_times = self.state0.t + np.arange(len(self.commands) + 1) * tau
        bridge = self.commands[0].drive is DriveType.BRIDGE      # held linear levels are not pulses
        pulses = [k for k, c in enumerate(self.commands) if bridge and any(level != 0.0 for _, level in c.segments)]
        self.pulse_bounds = np.array(pulses + [len(self.commands)], dtype=int)

    @property
    def duration(self) -> float:
        return len(self.commands) * self.params.sample_period

    @property
    def x0(self) -> np.ndarray:
        X = self.state0.x
        return np.array([X[X1], X[X2], X[X3], X[X4], X[X5], float(self.state0.mode)])

    @property
    def n_pulses(self) -> int:
        return len(self.pulse_bounds) - 1

    def command_motion(self) -> np.ndarray:
        """r(t) − r(t0) at the sample instants, noise-free: x4 decays with τ4 [rad]."""
        p = self.params
        x4 = self.state0.x[X4]
        return x4 * p.command_velocity_tau * -np.expm1(-(self.sample_times - self.state0.t) / p.command_velocity_tau)


def _window(params: PlantParams, commands: list[DriveCommand], window_s: float, name: str,
            source: str) -> _Sequence:
    """The last ``window_s`` of ``commands``, from the first clean start at or after its nominal start.

    Every contestant starts from (x1..x5, mode) alone, without the bridge's flyback flag, so on
    the bridge a clean start is a sample instant where the exact noise-free state is stuck with
    zero current; on the linear amplifier any sample instant is clean.
    """
    tau = params.sample_period
    n_window = int(round(window_s / tau))
    start = max(0, len(commands) - n_window)
    state = initial_state(params, x5=0.0)
    opts = SimOptions(noise=False)
    bridge = commands[0].drive is DriveType.BRIDGE
    for k in range(len(commands)):
        if k >= start and (not bridge or (state.mode == 2 and not state.flyback and state.x[X3] == 0.0)):
            # The plant is time-invariant; starting the clock at 0 keeps the rounding of absolute
            # time (ulp(45 s) ≈ 7e-15 s) out of every contestant's event times.
            rebased = PlantState(0.0, state.x, state.mode, state.flyback)
            return _Sequence(name, source, commands[k:], rebased, params, k * tau)
        step = advance(state, commands[k], params, None, opts)
        state, status, message = step.state, step.status, step.message
        if status != Status.OK:
            raise RuntimeError(f"exact replay of the recorded sequence failed: {status}: {message}")
    raise RuntimeError("no sample instant with the shaft stuck and no current in the window")
