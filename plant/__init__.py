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

from plant.drive import DriveCommand, DriveType  # noqa: E402
from plant.params import PlantParams  # noqa: E402
from plant.multimode.pulse import PulseResponse, pulse_response  # noqa: E402
from plant.multimode.interval import advance  # noqa: E402
from plant.protocol import PlantFamily, available_families, get_family, register_family  # noqa: E402
from plant.randomness import NoiseStream  # noqa: E402
from plant.state import EventKind, IntervalResult, PlantState, SimOptions, Status, initial_state  # noqa: E402

__all__ = [
    "PlantParams", "DriveCommand", "DriveType", "PulseResponse", "pulse_response",
    "PlantState", "SimOptions", "Status", "EventKind", "IntervalResult", "NoiseStream", "advance",
    "initial_state", "PlantFamily", "get_family", "register_family", "available_families",
]
