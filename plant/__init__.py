"""The shared exact stochastic plant: a gimbal shaft with stiction and Coulomb friction.

Public API: :class:`PlantParams`, :class:`DriveCommand`, :class:`DriveType`,
:func:`pulse_response`, and the simulator pieces in :mod:`plant.multimode`
(:func:`~plant.multimode.advance`, :class:`~plant.multimode.PlantState`) with the stateful
wrapper :class:`~plant.simulator.Plant`.
"""

from plant.drive import DriveCommand, DriveType
from plant.multimode import Accumulator, PlantState, SimOptions, Status, advance, initial_state
from plant.params import PlantParams
from plant.pulse import PulseResponse, pulse_response

__all__ = [
    "PlantParams", "DriveCommand", "DriveType", "PulseResponse", "pulse_response",
    "PlantState", "SimOptions", "Status", "Accumulator", "advance", "initial_state",
]
