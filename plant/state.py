"""The plant's state, the simulator's options, and what one sample interval returns.

State vector (3-5), without the constant x6 = k̄c, which is a parameter::

    x = [x1, x2, x3, x4, x5, u]
        x1 = c − r, error [rad]          x2 = ċ, shaft velocity [rad/s]
        x3 motor torque ∝ current [ozf·in]
        x4 = ṙ, commanded velocity [rad/s]
        x5 correlated friction noise [ozf·in]
        u  drive level in force [ozf·in]

plus the mode (1 moving backward, 2 stuck, 3 moving forward, as in the matrices (3-7)–(3-9))
and whether the flyback diodes conduct.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from plant.params import PlantParams

__all__ = ["X1", "X2", "X3", "X4", "X5", "U", "N_STATE", "PlantState", "initial_state", "SimOptions",
           "Status", "EventKind", "EventRecords", "IntervalResult", "EVENT_FIELDS"]

X1, X2, X3, X4, X5, U = range(6)
N_STATE = 6


class PlantState(NamedTuple):
    """Plant state at time ``t`` [s]: ``x`` as above (read-only), the mode, and flyback."""

    t: float
    x: np.ndarray
    mode: int = 2
    flyback: bool = False

    @property
    def error(self) -> float:
        """x1 = c − r [rad]."""
        return float(self.x[X1])


def initial_state(params: PlantParams, x5: float = 0.0, x4: float | None = None) -> PlantState:
    """Shaft stuck at zero error, no current, x4 = ``command_velocity_initial`` unless given."""
    x = np.zeros(N_STATE)
    x[X4] = params.command_velocity_initial if x4 is None else x4
    x[X5] = x5
    x.flags.writeable = False
    return PlantState(0.0, x, 2, False)


class Status(str, enum.Enum):
    """How an interval (and a run) ended (STYLE §8)."""

    OK = "ok"
    CHATTER = "chatter"
    DIVERGED = "diverged"
    ERROR = "error"

    def __str__(self) -> str:
        return self.value


class EventKind(enum.IntEnum):
    """What happened at a plant event; set by the code that found it."""

    LEVEL = 1          # a new command segment starts
    FLYBACK_END = 2    # x3 reached 0 with the diodes conducting (section 4.5)
    BREAKAWAY = 3      # |x3| reached ks while stuck
    REGIME_END = 4     # the torque in the direction of motion fell to ks: reflection ends
    STICK = 5          # velocity zero with |x3| ≤ ks: the shaft sticks
    REVERSAL = 6       # velocity zero with the torque beyond ks the other way
    REFLECTION = 7     # velocity zero with the torque still beyond ks forward


EVENT_FIELDS = ("t", "x1", "x2", "x3", "mode", "u", "kind")


@dataclass(frozen=True)
class SimOptions:
    """How the exact simulator treats noise and velocity zeros.

    Attributes
    ----------
    noise : bool
        Draw the process noise (w2, w4, w5). Off gives the deterministic plant.
    zero_velocity : {"bridge", "newton"}
        Locator of a noisy velocity zero: exact Gaussian sub-steps with the Brownian-bridge
        crossing test and bridge bisection (SPEC §2), or the seed's method (4-38), Z held
        fixed and Newton on the velocity.
    substep : float
        Gaussian sub-step inside noisy moving segments near a velocity zero [s]; the first
        rung of the step ladder h·2^k (plant.multimode.zero_velocity): longer rungs are used only when
        the mean velocity stays 8.5σ of the step's noise away from 0 (crossing probability
        ≤ 6e-17 per step).
    reflect_substep : float
        Sub-step while zero crossings are reflected, at zero velocity [s]. The reflected x2 is
        exact at any step; its push L enters x1 as ½·L·h, whose bias shrinks like √h. Rungs
        up to ``substep`` are used while the bound on that x1 error per unit time is no larger
        than this sub-step's at zero velocity (``ladder_thresholds``).
    bisection_tol : float
        Width [s] at which bridge bisection stops (≤ 1 µs by SPEC). At 1 µs the position
        error it leaves is |x2|·1 µs ≈ 1e-9 rad, a thousandth of the smallest corrections.
    max_events : int
        Events plus sub-steps allowed in one interval before it ends as ``chatter``.
    diverge_error : float
        |x1| [rad] beyond which the run ends as ``diverged``.
    """

    noise: bool = True
    zero_velocity: str = "bridge"
    substep: float = 1e-4
    reflect_substep: float = 1e-5
    bisection_tol: float = 1e-6
    max_events: int = 200_000
    diverge_error: float = 1.0

    def __post_init__(self) -> None:
        if self.zero_velocity not in ("bridge", "newton"):
            raise ValueError(f"SimOptions.zero_velocity must be 'bridge' or 'newton', got {self.zero_velocity!r}")
        if not (0 < self.substep <= 1e-2):
            raise ValueError(f"SimOptions.substep must be in (0, 0.01] s, got {self.substep!r}")
        if not (0 < self.reflect_substep <= 1e-2):
            raise ValueError(f"SimOptions.reflect_substep must be in (0, 0.01] s, got {self.reflect_substep!r}")
        if not (0 < self.bisection_tol <= 1e-6):
            raise ValueError(f"SimOptions.bisection_tol must be in (0, 1e-6] s, got {self.bisection_tol!r}")
        if not (1 <= self.max_events <= 10**9):
            raise ValueError(f"SimOptions.max_events must be in [1, 1e9], got {self.max_events!r}")
        if not (self.diverge_error > 0 and math.isfinite(self.diverge_error)):
            raise ValueError(f"SimOptions.diverge_error must be a finite positive angle, got {self.diverge_error!r}")

    def kernel_vector(self) -> np.ndarray:
        """The options as the compiled interval reads them (see plant.multimode.interval)."""
        vec = self.__dict__.get("_vector")
        if vec is None:
            vec = np.array([1.0 if self.noise else 0.0, 1.0 if self.zero_velocity == "newton" else 0.0,
                            self.substep, self.reflect_substep, self.bisection_tol, float(self.max_events),
                            self.diverge_error])
            vec.flags.writeable = False
            object.__setattr__(self, "_vector", vec)
        return vec


EventRecords = dict  # field name (EVENT_FIELDS) → ndarray, one entry per event


class IntervalResult(NamedTuple):
    """What :func:`plant.multimode.interval.advance` returns for one interval.

    Attributes
    ----------
    state : PlantState
        Where the interval (or the run, if ``status`` is not ok) ended.
    status, message : Status, str
    peak_abs_error : float
        Exact max |x1| over the continuous trajectory of the interval [rad], including its
        start and end points.
    int_abs_current, int_sq_current : float
        ∫|x3| dt [ozf·in·s] and ∫x3² dt [ozf²·in²·s], exact.
    supply_charge : float
        Net charge drawn from the supply [ozf·in·s]: the bridge draws i while on and returns
        it in flyback; a linear stage draws |i|.
    duration : float
        Time integrated [s] (the interval length unless the run stopped inside it).
    n_events, n_breakaways, n_sticks, n_substeps : int
        Plant events (level changes, flyback ends, breakaways, regime ends, velocity zeros),
        breakaways from rest or reversals, sticks, Gaussian sub-steps.
    events : dict of ndarray or None
        With ``record=True``: one entry per event, fields :data:`EVENT_FIELDS` (``kind`` is
        an :class:`EventKind` value).
    """

    state: PlantState
    status: Status
    message: str
    peak_abs_error: float
    int_abs_current: float
    int_sq_current: float
    supply_charge: float
    duration: float
    n_events: int
    n_breakaways: int
    n_sticks: int
    n_substeps: int
    events: EventRecords | None = None
