"""The plant-family protocol: what a plant provides to the closed loop, and the family registry.

A *family* is a kind of plant (Acker's exact multimode shaft, a compliant two-mass shaft, a
shaft with Stribeck or LuGre friction, …) with a parameter dataclass of its own: the fields of
:class:`~plant.params.PlantParams`, which every family and every controller's model share, plus
the family's own. In the style of Gymnasium's functional environments (``phys2d/cartpole.py``
and ``pendulum.py``: one protocol, parameters explicit) a family is a small stateless object:

``initial_state(params, x5)``
    The run's starting :class:`~plant.state.PlantState` (shaft stuck, no current, x4 from the
    parameters, x5 given: drawn by the runner from its stationary law).
``step(state, command, params, noise, options, *, record)`` (abstract)
    The pure interval step: the state one sample period later under ``command``, with the
    interval's exact integrals, status and (on request) event records — an
    :class:`~plant.state.IntervalResult`. The caller's objects are not changed (the noise
    stream's read position aside).
``observe(params, state, w1)``
    The sensor: y(n) from the state at the sample instant and the sensor noise w1(n) [rad],
    quantized to ``params.quantization`` (:mod:`plant.sensor`; an override must quantize too).
``delayed_step(state, pending, command, params, noise, options, *, record)``
    The closed loop's interval: the command path (compute delay ``params.command_delay``,
    :mod:`plant.delay`: the pending command holds until δ) around :meth:`step`. Returns the
    step and the pending command for the next interval; with δ = 0 it is :meth:`step`.
``truth(params, state)``
    The quantities a row and a trace report at a sample instant (:data:`TRUTH_FIELDS`: the
    state's meaning is shared by every family, SPEC §11) — the effective friction levels
    among them, against which identification is scored.
``pulse_motion(params, state, dt_u, sign)``
    The true plant's own noise-free response to one switched-bridge pulse from ``state``
    (command velocity held at 0): (net shaft motion [rad], time to stop [s]). Only a
    ``privileged`` bound (the oracle) uses it. The default runs :meth:`step`; a family may
    override it with a faster exact form.
``linear_law_loop``
    Optional fast path: a compiled closed loop of a fixed linear law (a
    :class:`plant.linear_drive.LawArrays`), bit-identical to calling :meth:`step` with the
    law's commands. ``None`` when the family has none; the runner then calls ``step``.
    It models the ideal sensor, no delay and no disturbance torque, so :meth:`law_loop` offers
    it only when ``quantization``, ``command_delay`` and ``disturbance_torque_std`` are 0.
``compiled_law_loop``
    Optional fast path for any controller that declares a compiled step
    (:mod:`plant.law_step`, ``controllers.law.CompiledLaw``): the family's compiled closed loop
    around that step, with the quantized sensor and the compute delay, bit-identical to calling
    :meth:`observe`, the controller's ``step`` and :meth:`delayed_step`; returns a
    :class:`plant.law_driver.LawRun`. :meth:`compiled_loop` offers it without a disturbance
    torque; a family whose disturbed plant has its own compiled loop overrides
    :meth:`compiled_loop` (and :meth:`law_loop`) to offer that one (multimode does).
``compiled_loop_logs``
    True when ``compiled_law_loop`` takes ``log`` (a :class:`plant.law_driver.X1Log`: t and x1 at
    every sample and plant event, for a run that keeps only those); otherwise such a run calls
    ``step`` from Python.

The runner, traces, series, metrics and the report reach a plant only through this protocol.
A family registers itself with :func:`register_family`; the built-in ones are listed in
:data:`BUILTIN_FAMILIES` (module paths, imported on first use), so that a new family is its
own folder plus one line there — or a plugin module that calls :func:`register_family`.
"""

from __future__ import annotations

import abc
import dataclasses
import importlib
import math
from typing import Any, Callable, ClassVar, NamedTuple

from plant.drive import DriveCommand, DriveType
from plant.delay import delay_command
from plant.params import PlantParams
from plant.randomness import NoiseStream
from plant.sensor import quantize
from plant.state import X1, X2, X3, X4, X5, U, EventKind, IntervalResult, PlantState, SimOptions, Status, initial_state

__all__ = ["PlantFamily", "TruePlant", "register_family", "get_family", "available_families",
           "DEFAULT_FAMILY", "BUILTIN_FAMILIES", "TRUTH_FIELDS", "model_of"]

# The family of a scenario that names none: Acker's idealized plant (SPEC §2-4).
DEFAULT_FAMILY = "multimode"
# Built-in families: name -> module that registers it when imported.
BUILTIN_FAMILIES: dict[str, str] = {
    "multimode": "plant.multimode",
    "two-mass": "plant.two_mass",
    "stribeck": "plant.stribeck",
    "lugre": "plant.lugre",
}
# What truth() returns for every family (a family may add keys of its own).
TRUTH_FIELDS = ("x1", "x2", "x3", "x4", "x5", "mode", "u", "ks_true", "kc_true")

_PULSE_HORIZON_S = 1.0


class PlantFamily(abc.ABC):
    """Base class of a plant family (see the module docstring).

    Subclasses set ``name`` (by :func:`register_family`), ``Params`` (a frozen dataclass whose
    fields include every :class:`PlantParams` field, usually a subclass of it) and
    ``description``, and implement :meth:`step`.
    """

    name: ClassVar[str] = ""
    Params: ClassVar[type] = PlantParams
    description: ClassVar[str] = ""
    linear_law_loop: ClassVar[Callable[..., Any] | None] = None
    compiled_law_loop: ClassVar[Callable[..., Any] | None] = None
    compiled_loop_logs: ClassVar[bool] = False
    # The family's reference simulators for a work-precision study (``bench.speed``), or None:
    # a namespace with exact_step, fixed_step, fixed_step_pulses, event_driven, Schedule,
    # schedule_from_commands (see plant/multimode/reference.py) and fixed_step_family(dt), a
    # PlantFamily stepping the same plant by Euler–Maruyama (plant/multimode/em_family.py).
    references: ClassVar[Any] = None
    # Built-in scenarios of this family: name -> (fields over Table 2-1, one-line description).
    scenarios: ClassVar[dict[str, tuple[dict[str, Any], str]]] = {}

    def initial_state(self, params: PlantParams, x5: float) -> PlantState:
        """Shaft stuck at zero error, no current, x4 = ``command_velocity_initial``, x5 given."""
        return initial_state(params, x5=x5)

    @abc.abstractmethod
    def step(self, state: PlantState, command: DriveCommand, params: PlantParams, noise: NoiseStream | None,
             options: SimOptions, *, duration: float | None = None, record: bool = False) -> IntervalResult:
        """One interval (default length ``params.sample_period``) under ``command``: the pure step."""
        raise NotImplementedError

    def observe(self, params: PlantParams, state: PlantState, w1: float) -> float:
        """y(n) = q·round((x1(n·τs) + w1(n))/q) [rad], q = ``params.quantization`` (SPEC §2, §11)."""
        return quantize(float(state.x[X1] + w1), params.quantization)

    def delayed_step(self, state: PlantState, pending: DriveCommand | None, command: DriveCommand,
                     params: PlantParams, noise: NoiseStream | None, options: SimOptions, *,
                     record: bool = False) -> tuple[IntervalResult, DriveCommand | None]:
        """One closed-loop interval with the compute delay δ = ``params.command_delay`` (SPEC §11).

        ``command`` (computed at the interval's start) takes effect δ later; ``pending`` (what
        the previous call returned, None at the first) holds until then (:mod:`plant.delay`).
        Returns (the interval's :class:`IntervalResult`, the pending command for the next
        interval). With δ = 0 this is ``step(state, command, ...)`` and the pending command None.
        """
        delay = params.command_delay
        if delay == 0.0:
            return self.step(state, command, params, noise, options, record=record), None
        in_force, pending = delay_command(command, pending, delay, params.sample_period)
        return self.step(state, in_force, params, noise, options, record=record), pending

    def law_loop(self, params: PlantParams) -> Callable[..., Any] | None:
        """:attr:`linear_law_loop` when it applies to ``params`` (ideal sensor, no delay), else None."""
        if params.quantization != 0.0 or params.command_delay != 0.0 or params.disturbance_torque_std != 0.0:
            return None
        return self.linear_law_loop

    def compiled_loop(self, params: PlantParams) -> Callable[..., Any] | None:
        """:attr:`compiled_law_loop` when it applies to ``params`` (no disturbance torque), else None."""
        if params.disturbance_torque_std != 0.0:
            return None
        return self.compiled_law_loop

    def truth(self, params: PlantParams, state: PlantState) -> dict[str, float]:
        """The state's shared meaning and the effective friction kc = k̄c + x5, ks = k̄s + x5 (≥ 0)."""
        x = state.x
        x5 = float(x[X5])
        return {"x1": float(x[X1]), "x2": float(x[X2]), "x3": float(x[X3]), "x4": float(x[X4]), "x5": x5,
                "mode": float(state.mode), "u": float(x[U]),
                "ks_true": max(params.stiction + x5, 0.0), "kc_true": max(params.coulomb + x5, 0.0)}

    def pulse_motion(self, params: PlantParams, state: PlantState, dt_u: float, sign: int) -> tuple[float, float]:
        """(Δx1 [rad], t_stop [s]) of one noise-free bridge pulse of ``dt_u`` seconds from ``state``.

        x4 is held at 0 (so Δx1 is the shaft's own motion) and the run goes on after the
        flyback until the shaft is stuck with no current, up to 1 s; t_stop is 0 when it never
        moved. Raises ``RuntimeError`` when the shaft still moves after 1 s or the plant
        leaves ``ok``.
        """
        p = _quiet_command(params)
        x = state.x.copy()
        x[X4] = 0.0
        x.flags.writeable = False
        s = state._replace(x=x, t=0.0)
        opts = SimOptions(noise=False)
        x1_0 = float(x[X1])
        t_stop = 0.0
        if dt_u > 0:
            step = self.step(s, DriveCommand.hold(sign * p.u_max, DriveType.BRIDGE), p, None, opts,
                             duration=dt_u, record=True)
            s, t_stop = _checked(step, t_stop)
        off = DriveCommand.hold(0.0, DriveType.BRIDGE)
        chunk = max(2.0 * p.motor_time_constant * math.log1p(abs(float(s.x[X3])) / p.u_max), 1e-3)
        while (s.mode != 2 or s.flyback) and s.t < _PULSE_HORIZON_S:
            s, t_stop = _checked(self.step(s, off, p, None, opts, duration=chunk, record=True), t_stop)
        if s.mode != 2:
            raise RuntimeError(f"shaft still moving {_PULSE_HORIZON_S} s after a {dt_u} s pulse")
        return float(s.x[X1]) - x1_0, t_stop

    def pulse_on_time(self, params: PlantParams, state: PlantState, motion: float, sign: int, dtu_max: float,
                      tol: float, max_iterations: int) -> tuple[float, float, float] | None:
        """(Δt_u, |Δc|, t_stop) of the shortest noise-free pulse with |Δc| ≥ ``motion`` [rad]
        (``dtu_max`` when none), or None when the family offers no fast path (the default).

        Optional, for speed only: the answer must be bit for bit the Illinois regula falsi on
        |Δc|(Δt_u) − motion over :meth:`pulse_motion` (start bracket [0, ``dtu_max``], the
        upper end returned once the bracket is narrower than ``tol`` or after
        ``max_iterations``), as ``controllers.oracle_pulse`` runs it.
        """
        return None

    def __repr__(self) -> str:
        return f"<plant family {self.name!r}>"


def _quiet_command(params: Any) -> Any:
    """``params`` with ``command_velocity_std = 0``, built once per parameter object and kept on it
    (the key :mod:`plant.multimode.pulse` uses; an oracle asks for it at every sample)."""
    if not params.command_velocity_std:
        return params
    cached = getattr(params, "__dict__", {}).get("_pulse_plant")
    if cached is None:
        cached = params.replace(command_velocity_std=0.0)
        try:
            object.__setattr__(params, "_pulse_plant", cached)
        except (AttributeError, TypeError):      # a parameter class without a __dict__: no cache
            pass
    return cached


def _checked(step: IntervalResult, t_stop: float) -> tuple[PlantState, float]:
    """The step's end state and the time of its last stick event (else ``t_stop``)."""
    if step.status is not Status.OK:
        raise RuntimeError(f"pulse simulation ended with status {step.status}: {step.message}")
    sticks = step.events["t"][step.events["kind"] == int(EventKind.STICK)]
    return step.state, (float(sticks[-1]) if sticks.size else t_stop)


class TruePlant(NamedTuple):
    """The true plant of a run, as a privileged bound receives it: the family and its parameters."""

    family: PlantFamily
    params: PlantParams

    def pulse_motion(self, state: PlantState, dt_u: float, sign: int) -> tuple[float, float]:
        return self.family.pulse_motion(self.params, state, dt_u, sign)

    def pulse_on_time(self, state: PlantState, motion: float, sign: int, dtu_max: float, tol: float,
                      max_iterations: int) -> tuple[float, float, float] | None:
        return self.family.pulse_on_time(self.params, state, motion, sign, dtu_max, tol, max_iterations)


_REGISTRY: dict[str, PlantFamily] = {}


def register_family(name: str) -> Callable[[type[PlantFamily]], type[PlantFamily]]:
    """Class decorator: register a :class:`PlantFamily` subclass under ``name`` (one instance)."""
    def deco(cls: type[PlantFamily]) -> type[PlantFamily]:
        if not (isinstance(name, str) and name and name.replace("-", "").replace("_", "").isalnum()):
            raise ValueError(f"plant family name must be letters, digits, '-' or '_', got {name!r}")
        if not (isinstance(cls, type) and issubclass(cls, PlantFamily)):
            raise TypeError(f"{cls!r} is not a PlantFamily subclass")
        if not (dataclasses.is_dataclass(cls.Params)
                and {f.name for f in dataclasses.fields(PlantParams)} <= {f.name for f in dataclasses.fields(cls.Params)}):
            raise TypeError(f"{cls.__name__}.Params must be a dataclass with every PlantParams field")
        existing = _REGISTRY.get(name)
        if existing is not None and type(existing).__qualname__ != cls.__qualname__:
            raise ValueError(f"plant family {name!r} is already registered ({type(existing).__qualname__})")
        cls.name = name
        _REGISTRY[name] = cls()
        return cls
    return deco


def get_family(name: str) -> PlantFamily:
    """The registered family ``name`` (built-ins are imported on first use).

    Raises
    ------
    ValueError
        For an unknown name, listing the known ones.
    """
    if name not in _REGISTRY and name in BUILTIN_FAMILIES:
        importlib.import_module(BUILTIN_FAMILIES[name])
    family = _REGISTRY.get(name)
    if family is None:
        raise ValueError(f"unknown plant family {name!r}; known: {available_families()}")
    return family


def available_families() -> list[str]:
    """Names of the built-in and the registered families, sorted."""
    return sorted(set(BUILTIN_FAMILIES) | set(_REGISTRY))


def model_of(params: Any) -> PlantParams:
    """The :class:`PlantParams` part of a family's parameters: what a controller is told by default."""
    if type(params) is PlantParams:
        return params
    return PlantParams(**{f.name: getattr(params, f.name) for f in dataclasses.fields(PlantParams)})
