"""A policy as a controller: a callable observation → action run in any matrix.

A *policy* is what a reinforcement-learning library trains against the Gymnasium environment
(:mod:`bench.gym_env`, docs/gym.md): a callable from the observation to the action. This module
holds the two conventions the environment and the adapter share, so that a policy sees in a
matrix cell exactly what it saw in the environment:

observation
    The last N measured samples [y(n−N+1), …, y(n)] [rad] (position only, like every controller
    here), oldest first; before the run's first sample the window holds 0 (the run starts with the
    shaft stuck at zero error). :class:`MeasurementWindow`.
action
    The drive command for [n·τs, (n+1)·τs), :func:`command_of`. Linear amplifier: one level
    [ozf·in] held over the interval (the plant clips it to ±u_max, SPEC §2). Switched bridge: one
    *signed pulse width* w [s]: a pulse of ±u_max from the sample instant for |w| seconds
    (|w| ≥ τs: the whole interval), direction sign(w), off (flyback) after it; w = 0 is off.
    A policy may also return a :class:`~plant.drive.DriveCommand` of its drive as it is.

:func:`register_policy` registers a policy factory as a controller (call it in a plugin module
named by a matrix's ``plugins``, so that the policy's source enters the cell hashes);
:func:`policy_controller` wraps one policy object for a direct :func:`bench.runner.run_closed_loop`.
A policy with a ``reset(params, rng)`` method is reset with the model and the controller's
generator at the start of every run, like a controller.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, ClassVar

import numpy as np

from controllers.base import Controller, get_controller, register
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

__all__ = ["PolicyOptions", "PolicyController", "MeasurementWindow", "command_of", "action_bounds",
           "register_policy", "policy_controller"]

Policy = Callable[[np.ndarray], Any]


class MeasurementWindow:
    """The last ``size`` measurements, oldest first, zeros before the first (module docstring)."""

    def __init__(self, size: int) -> None:
        if isinstance(size, bool) or not isinstance(size, int) or size < 1:
            raise ValueError(f"window must be an integer >= 1, got {size!r}")
        self._buf = np.zeros(size)

    def reset(self) -> None:
        self._buf[:] = 0.0

    def push(self, y: float) -> np.ndarray:
        """Append y(n) [rad]; returns the window as a new array (the caller may keep it)."""
        buf = self._buf
        buf[:-1] = buf[1:]
        buf[-1] = y
        return buf.copy()


def action_bounds(drive: DriveType, params: PlantParams) -> tuple[float, float]:
    """The action's range: ±u_max [ozf·in] (linear) or ±τs [s] (bridge, signed pulse width)."""
    bound = params.u_max if DriveType(drive) is DriveType.LINEAR else params.sample_period
    return -bound, bound


def command_of(action: Any, drive: DriveType, params: PlantParams) -> DriveCommand:
    """The :class:`DriveCommand` of ``action`` (module docstring).

    Raises
    ------
    ValueError
        For an action that is not one finite number (or a DriveCommand of another drive).
    """
    if isinstance(action, DriveCommand):
        if action.drive is not drive:
            raise ValueError(f"policy returned a {action.drive.value} command for a {drive.value} drive")
        return action
    a = np.asarray(action, dtype=float)
    if a.size != 1 or not math.isfinite(float(a.reshape(-1)[0])):
        raise ValueError(f"action must be one finite number, got {action!r}")
    value = float(a.reshape(-1)[0])
    if drive is DriveType.LINEAR:
        return DriveCommand.hold(value, DriveType.LINEAR)
    width = abs(value)
    level = math.copysign(params.u_max, value)
    if width == 0.0:
        return DriveCommand.hold(0.0, DriveType.BRIDGE)
    if width >= params.sample_period:
        return DriveCommand.hold(level, DriveType.BRIDGE)
    return DriveCommand.pulse(0.0, width, level)


@dataclasses.dataclass(frozen=True)
class PolicyOptions:
    """Options of a policy controller.

    Attributes
    ----------
    window : int
        N ≥ 1, the number of recent measurements the policy observes. Default 1.
    """

    window: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.window, bool) or not isinstance(self.window, int) or self.window < 1:
            raise ValueError(f"window must be an integer >= 1, got {self.window!r}")


class PolicyController(Controller):
    """Runs a policy (observation → action) as a controller; see the module docstring.

    A subclass made by :func:`register_policy` or :func:`policy_controller` sets ``drive`` and
    ``make_policy`` (a factory called once per controller object: each cell gets a fresh policy).
    """

    Options = PolicyOptions
    family = "policy"
    make_policy: ClassVar[Callable[[], Policy] | None] = None

    def __init__(self, options: Any = None, /, *, preset: str | None = None, **fields: Any) -> None:
        super().__init__(options, preset=preset, **fields)
        factory = type(self).make_policy
        if factory is None:
            raise ValueError(f"{type(self).__name__} has no policy: use register_policy or policy_controller")
        self.policy = factory()
        self._window = MeasurementWindow(self.options.window)
        self._params: PlantParams | None = None

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        self._params = params
        self._window.reset()
        reset = getattr(self.policy, "reset", None)
        if callable(reset):
            reset(params, rng)

    def step(self, y: float) -> DriveCommand:
        """Push y(n) [rad] into the window and return the policy's action as a command."""
        return command_of(self.policy(self._window.push(y)), self.drive, self._params)

    def summary(self) -> dict[str, Any]:
        """The policy's own ``summary()`` when it has one (e.g. a wrapped controller's), else none."""
        summary = getattr(self.policy, "summary", None)
        return dict(summary()) if callable(summary) else {}


def _policy_class(name: str, make_policy: Callable[[], Policy], drive: str | DriveType, window: int,
                  description: str, module: str) -> type[PolicyController]:
    drive = DriveType(drive)
    PolicyOptions(window)   # validates the default
    options = dataclasses.make_dataclass(f"PolicyOptions_{name}", [("window", int, dataclasses.field(default=window))],
                                         bases=(PolicyOptions,), frozen=True)
    options.__doc__ = PolicyOptions.__doc__
    attrs = {"drive": drive, "Options": options, "make_policy": staticmethod(make_policy),
             "description": description or f"policy {name!r} ({drive.value} drive, window {window})",
             "__module__": module}
    return type(f"PolicyController_{name}", (PolicyController,), attrs)


def register_policy(name: str, make_policy: Callable[[], Policy], *, drive: str | DriveType = "linear",
                    window: int = 1, description: str = "") -> type[PolicyController]:
    """Register a controller ``name`` that runs the policy ``make_policy()`` with ``drive``.

    ``window`` is the default N (a matrix variant may set ``window``). The class belongs to the
    module of ``make_policy``, so a policy registered by a matrix plugin is a plugin controller:
    its source enters the config hashes of its cells (docs/matrices.md).
    """
    module = getattr(make_policy, "__module__", None) or __name__
    try:
        existing = get_controller(name)
    except ValueError:
        existing = None
    if (isinstance(existing, type) and issubclass(existing, PolicyController) and existing.make_policy is make_policy
            and existing.drive is DriveType(drive) and existing.Options().window == window):
        return existing     # the same registration again (a plugin imported twice)
    return register(name)(_policy_class(name, make_policy, drive, window, description, module))


def policy_controller(policy: Policy, *, drive: str | DriveType = "linear", window: int = 1) -> PolicyController:
    """A controller object (not registered) that runs ``policy`` itself, for a direct run."""
    cls = _policy_class("direct", lambda: policy, drive, window, "", __name__)
    return cls()
