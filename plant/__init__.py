"""The plant: families of exact or error-controlled simulators behind one protocol.

Public API:

* :class:`PlantParams` (Table 2-1), :class:`DriveCommand`, :class:`DriveType`;
* the family protocol (:mod:`plant.protocol`): :class:`PlantFamily`, :func:`get_family`,
  :func:`register_family`, :func:`available_families`;
* Acker's exact plant, the ``multimode`` family (:mod:`plant.multimode`): the pure step
  :func:`advance` (one sample interval, compiled whole) with :class:`PlantState`,
  :func:`initial_state`, :class:`SimOptions`, :class:`IntervalResult`, :class:`Status`,
  :class:`EventKind` and the noise source :class:`NoiseStream`; :func:`pulse_response`, the
  response to one switched-bridge pulse.

Shared by every family: ``params``, ``drive``, ``state``, ``randomness``, ``expfun``
(cancellation-free exponential remainders), ``linear_drive`` (the drive signal of a fixed
linear law), ``protocol``. Each family lives in its own folder.
"""

from plant import _jit_cache

_jit_cache.refresh()

# The names below load on first use (PEP 562): ``import plant.params`` (what a controller's
# registry needs) does not compile-load numba and scipy; ``plant.advance`` does.
_EXPORTS = {
    "plant.drive": ("DriveCommand", "DriveType"),
    "plant.params": ("PlantParams",),
    "plant.multimode.pulse": ("PulseResponse", "pulse_response"),
    "plant.multimode.interval": ("advance",),
    "plant.protocol": ("PlantFamily", "available_families", "get_family", "register_family"),
    "plant.randomness": ("NoiseStream",),
    "plant.state": ("EventKind", "IntervalResult", "PlantState", "SimOptions", "Status", "initial_state"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str) -> object:
    """Import the submodule that defines ``name`` on first access (PEP 562)."""
    if name not in _WHERE:
        raise AttributeError(f"module 'plant' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value
    return value


__all__ = [
    "PlantParams", "DriveCommand", "DriveType", "PulseResponse", "pulse_response",
    "PlantState", "SimOptions", "Status", "EventKind", "IntervalResult", "NoiseStream", "advance",
    "initial_state", "PlantFamily", "get_family", "register_family", "available_families",
]
