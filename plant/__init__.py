"""The shared exact stochastic plant: a gimbal shaft with stiction and Coulomb friction.

Public API:

* :class:`PlantParams` (Table 2-1), :class:`DriveCommand`, :class:`DriveType`;
* the pure step :func:`advance` (one sample interval, compiled whole) with
  :class:`PlantState`, :func:`initial_state`, :class:`SimOptions`, :class:`IntervalResult`,
  :class:`Status`, :class:`EventKind` and the noise source :class:`NoiseStream`;
* :func:`pulse_response`, the response to one switched-bridge pulse.

Modules by idea: ``params``, ``drive``, ``state``, ``expfun`` (cancellation-free exponential
remainders), ``transition`` (Φ and the noise covariance as matrices: the test oracles'
counterpart), ``noise`` (the minimal factor (4-20)), ``segments`` (torque events and
integrals), ``stuck`` (mode 2), ``moving`` (modes 1 and 3), ``zero_velocity`` (the noisy
velocity-zero locators), ``interval`` (the driver), ``pulse``, ``reference`` (Euler–Maruyama
and ``solve_ivp`` reference simulators).
"""

from plant import _jit_cache

_jit_cache.refresh()

from plant.drive import DriveCommand, DriveType  # noqa: E402
from plant.interval import advance  # noqa: E402
from plant.params import PlantParams  # noqa: E402
from plant.pulse import PulseResponse, pulse_response  # noqa: E402
from plant.randomness import NoiseStream  # noqa: E402
from plant.state import EventKind, IntervalResult, PlantState, SimOptions, Status, initial_state  # noqa: E402

__all__ = [
    "PlantParams", "DriveCommand", "DriveType", "PulseResponse", "pulse_response",
    "PlantState", "SimOptions", "Status", "EventKind", "IntervalResult", "NoiseStream", "advance",
    "initial_state",
]
