"""The controller protocol and the name registry.

A controller is a small class (STYLE §2): ``reset(params, rng)`` once per run, then
``step(y)`` once per sample instant. ``step`` receives the measurement y(n) = x1(n·τs) + w1(n)
[rad] and returns the :class:`~plant.drive.DriveCommand` for the interval up to the next sample.
"""

from __future__ import annotations

import abc
from typing import Any, Callable, ClassVar, TypeVar

import numpy as np

from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

__all__ = ["Controller", "register", "get_controller", "available_controllers", "make_controller"]


class Controller(abc.ABC):
    """Base class of every controller.

    Subclasses set ``name`` and ``drive`` and implement :meth:`reset` and :meth:`step`.
    Constructor keyword arguments are the controller's options; they must be validated in
    ``__init__`` and raise ``ValueError`` naming the option.
    """

    name: ClassVar[str] = ""
    drive: ClassVar[DriveType] = DriveType.LINEAR
    description: ClassVar[str] = ""

    @abc.abstractmethod
    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Start a new run on a plant with ``params``; ``rng`` is the controller's own stream."""
        raise NotImplementedError

    @abc.abstractmethod
    def step(self, y: float) -> DriveCommand:
        """Consume y(n) [rad] and return the drive command for [n·τs, (n+1)·τs)."""
        raise NotImplementedError

    def internals(self) -> dict[str, float]:
        """Scalar internals for traces (logged under ``controller/<key>``). Default: none."""
        return {}

    def summary(self) -> dict[str, Any]:
        """Design or end-of-run facts for the results table (e.g. crossover, margins)."""
        return {}


_C = TypeVar("_C", bound=type[Controller])
_REGISTRY: dict[str, type[Controller]] = {}


def register(name: str) -> Callable[[_C], _C]:
    """Class decorator: register a controller class under ``name``."""

    def deco(cls: _C) -> _C:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise ValueError(f"controller name {name!r} is already registered")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return deco


def _load_builtin() -> None:
    # Importing the package registers the built-in controllers.
    import controllers  # noqa: F401


def available_controllers() -> dict[str, type[Controller]]:
    """Registered controllers by name, sorted."""
    _load_builtin()
    return dict(sorted(_REGISTRY.items()))


def get_controller(name: str) -> type[Controller]:
    """The class registered as ``name``; ``ValueError`` lists the known names otherwise."""
    _load_builtin()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown controller {name!r}; registered: {sorted(_REGISTRY)}") from None


def make_controller(name: str, **options: Any) -> Controller:
    """Instantiate a registered controller with options."""
    return get_controller(name)(**options)
