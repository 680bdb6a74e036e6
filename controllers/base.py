"""The controller protocol (v2) and the name registry.

A controller is a small class (STYLE §2): ``reset(params, rng)`` once per run, then
``step(y)`` once per sample instant. ``step`` receives the measurement y(n) = x1(n·τs) + w1(n)
[rad] and returns the :class:`~plant.drive.DriveCommand` for the interval up to the next sample.

Options are a frozen dataclass named by the class attribute ``Options`` (named fields, units in
its docstring, ``__post_init__`` raising ``ValueError`` that names the field). A controller is
built as ``Cls()``, ``Cls(preset="name")``, ``Cls(options)`` or with field overrides
``Cls(preset="name", a_c=1e-4)``; :func:`resolve_options` checks every override's name and
type, so a matrix variant with an unknown or ill-typed option is a user error naming it.

Optional hooks (class attributes and methods with neutral defaults) replace every place where
``bench/`` or ``reports/`` would otherwise know a controller by name:

``family``
    The design family the claims scorecard groups by (defaults to the registered name).
``counter``
    The key of :meth:`summary` that counts the controller's discrete actions ("pulses",
    "resets"); ``""`` if none.
``knobs``
    The documented tuning knob(s): option field → the values a frontier sweep visits.
``event_times`` / ``report_series``
    Labelled event instants and extra per-sample series for traces and the report.
``privileged`` / ``observe_truth``
    Only for bounds (e.g. an oracle) that are not real controllers: the runner hands them the
    true plant state and the true plant before every ``step``. Real controllers never see
    either: ``reset(params, rng)`` gives every controller the scenario's *model*, the nominal
    :class:`~plant.params.PlantParams` it is told, which need not be the truth.
``linear_law``
    A controller whose step is a fixed linear law (plus square-wave dither) may describe it
    (:class:`controllers.law.LinearLaw`); the runner then compiles the whole loop.
``compiled_law``
    A controller whose per-sample work is one numba function over a state array may declare
    it (:class:`controllers.law.CompiledLaw`); its ``step`` calls the same function, and the
    runner runs the whole loop compiled when nothing is recorded (also on a quantized sensor
    and with a compute delay). A ``linear_law`` runs this way where its own loop does not apply.
"""

from __future__ import annotations

import abc
import dataclasses
import types
import typing
from typing import Any, Callable, ClassVar, Mapping, TypeVar

import numpy as np

from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

__all__ = ["Controller", "register", "get_controller", "available_controllers", "make_controller",
           "resolve_options", "ControllerDiverged", "EstimateOutOfRange"]


class ControllerDiverged(RuntimeError):
    """A controller's own state left the range where its law is defined (e.g. an identified
    Coulomb level driven to 0, so its pulse model coasts for ever). Raised from ``step``; the
    runner ends the run with status ``diverged`` and this message (SPEC §3), not ``error``."""


class EstimateOutOfRange(ControllerDiverged, ValueError):
    """An estimate outside its valid range (also a ``ValueError`` for direct callers)."""


class Controller(abc.ABC):
    """Base class of every controller.

    Subclasses set ``drive``, an ``Options`` dataclass (or leave it ``None`` for a controller
    without options) and implement :meth:`reset` and :meth:`step`. ``register(name)`` sets
    ``name`` (and ``family`` when the class does not set it).
    """

    name: ClassVar[str] = ""
    family: ClassVar[str] = ""
    drive: ClassVar[DriveType] = DriveType.LINEAR
    description: ClassVar[str] = ""
    Options: ClassVar[type | None] = None
    presets: ClassVar[Mapping[str, Any]] = types.MappingProxyType({})
    knobs: ClassVar[Mapping[str, tuple]] = types.MappingProxyType({})
    counter: ClassVar[str] = ""
    privileged: ClassVar[bool] = False

    def __init__(self, options: Any = None, /, *, preset: str | None = None, **fields: Any) -> None:
        self.options = resolve_options(type(self), options, preset, fields)

    @abc.abstractmethod
    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Start a new run on a plant whose model is ``params`` (what the controller is told,
        not necessarily the truth); ``rng`` is the controller's own stream."""
        raise NotImplementedError

    @abc.abstractmethod
    def step(self, y: float) -> DriveCommand:
        """Consume y(n) [rad] and return the drive command for [n·τs, (n+1)·τs)."""
        raise NotImplementedError

    def internals(self) -> dict[str, float]:
        """Scalar internals for traces (logged under ``controller/<key>``). Default: none."""
        return {}

    def summary(self) -> dict[str, Any]:
        """Design or end-of-run facts for the results table (e.g. crossover, margins, pulses)."""
        return {}

    def event_times(self) -> dict[str, np.ndarray]:
        """Labelled instants [s] of the controller's discrete actions (e.g. ``{"pulse": t}``)."""
        return {}

    def report_series(self, t: np.ndarray, warmup_s: float) -> dict[str, np.ndarray]:
        """Extra series sampled at the sample instants ``t`` [s] for the report's figures."""
        return {}

    def linear_law(self) -> Any:
        """After :meth:`reset`: a :class:`~controllers.law.LinearLaw` if ``step`` computes exactly
        that law (then the runner may run it compiled, without calling ``step``), else None."""
        return None

    def compiled_law(self) -> Any:
        """After :meth:`reset`: a :class:`~controllers.law.CompiledLaw` whose step is the one
        ``step`` calls on the same state array (then the runner may run the loop compiled, the
        state advancing in place), else None (the runner compiles a :meth:`linear_law` itself)."""
        return None

    def observe_truth(self, state: Any, plant: Any) -> None:
        """Privileged hook: the true :class:`~plant.state.PlantState` before each ``step``, and
        the true plant (:class:`plant.protocol.TruePlant`: its family and parameters, with the
        family's own noise-free ``pulse_motion``).

        Called by the runner only when ``privileged`` is True (bounds, never real controllers);
        ``reset`` receives the model like every controller's.
        """
        raise NotImplementedError(f"controller {self.name!r} is not privileged")


def _check_type(owner: str, key: str, value: Any, hint: Any) -> Any:
    """``value`` converted to the field type ``hint``, or ``ValueError`` naming ``key``."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _check_type(owner, key, value, a)
            except ValueError as exc:
                errors.append(str(exc))
        if len(errors) == 1:   # Optional[X]: X's own message ("must be a number, got ...")
            raise ValueError(errors[0])
        raise ValueError(f"option {key!r} of {owner!r}: {value!r} has the wrong type ({hint})")
    if origin is typing.Literal:
        if value in args:
            return value
        raise ValueError(f"option {key!r} of {owner!r} must be one of {list(args)}, got {value!r}")
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ValueError(f"option {key!r} of {owner!r} must be a list, got {value!r}")
        item = args[0] if args else Any
        return tuple(_check_type(owner, key, v, item) for v in value)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"option {key!r} of {owner!r} must be a number, got {value!r}")
        return float(value)
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"option {key!r} of {owner!r} must be an integer, got {value!r}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ValueError(f"option {key!r} of {owner!r} must be true or false, got {value!r}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ValueError(f"option {key!r} of {owner!r} must be a string, got {value!r}")
        return value
    return value


def resolve_options(cls: type[Controller], options: Any = None, preset: str | None = None,
                    fields: Mapping[str, Any] | None = None) -> Any:
    """The options of ``cls``: defaults, a preset or an instance, with checked field overrides.

    Raises ``ValueError`` naming an unknown preset, an unknown field or an ill-typed value; the
    dataclass's own ``__post_init__`` validates the values.
    """
    fields = dict(fields or {})
    owner = cls.name or cls.__name__
    O = cls.Options
    if O is None:
        if options is not None or preset is not None or fields:
            given = sorted(fields) + (["preset"] if preset is not None else [])
            raise ValueError(f"controller {owner!r} takes no options; got {given}")
        return None
    if options is not None and preset is not None:
        raise ValueError(f"controller {owner!r}: give an options object or a preset, not both")
    if preset is not None:
        if preset not in cls.presets:
            raise ValueError(f"unknown preset {preset!r} of {owner!r}; presets: {sorted(cls.presets)}")
        base = cls.presets[preset]
    elif options is not None:
        if not isinstance(options, O):
            raise ValueError(f"options of {owner!r} must be a {O.__name__}, got {type(options).__name__}")
        base = options
    else:
        base = O()
    hints = typing.get_type_hints(O)
    names = {f.name for f in dataclasses.fields(O) if f.init}
    converted = {}
    for key, value in fields.items():
        if key not in names:
            raise ValueError(f"unknown option {key!r} of {owner!r}; options: {sorted(names)}")
        converted[key] = _check_type(owner, key, value, hints[key])
    return dataclasses.replace(base, **converted)


_C = TypeVar("_C", bound=type[Controller])
_REGISTRY: dict[str, type[Controller]] = {}


def register(name: str) -> Callable[[_C], _C]:
    """Class decorator: register a controller class under ``name``."""

    def deco(cls: _C) -> _C:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise ValueError(f"controller name {name!r} is already registered")
        cls.name = name
        if not cls.__dict__.get("family"):   # a subclass keeps its parent's family
            parent = next((b.family for b in cls.__mro__[1:] if getattr(b, "family", "")), "")
            cls.family = parent or name
        _REGISTRY[name] = cls
        return cls

    return deco


def available_controllers() -> dict[str, type[Controller]]:
    """Registered controllers by name, sorted. (The built-ins are registered by the package's
    ``__init__``, which Python runs before this module whenever ``controllers.base`` is imported.)"""
    return dict(sorted(_REGISTRY.items()))


def get_controller(name: str) -> type[Controller]:
    """The class registered as ``name``; ``ValueError`` lists the known names otherwise."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown controller {name!r}; registered: {sorted(_REGISTRY)}") from None


def make_controller(name: str, **options: Any) -> Controller:
    """Instantiate a registered controller with options (``preset=`` and field overrides)."""
    return get_controller(name)(**options)
