"""The simulators the speed study times: the default plant family's exact step and its references.

The dissertation's claim is about multimode linearization, the exact method of Acker's plant,
which is the default family (:data:`plant.protocol.DEFAULT_FAMILY`); the study reaches it and
its fixed-step and ``solve_ivp`` references through the family protocol (``references``).
"""

from __future__ import annotations

from plant.protocol import DEFAULT_FAMILY, get_family

__all__ = ["EXACT_METHOD", "advance", "fixed_step", "fixed_step_pulses", "coupled_step_pulses", "event_driven", "Schedule",
           "schedule_from_commands", "fixed_step_family"]

_REFERENCES = get_family(DEFAULT_FAMILY).references
EXACT_METHOD = DEFAULT_FAMILY       # the exact simulator's label in speed.json
advance = _REFERENCES.exact_step
fixed_step = _REFERENCES.fixed_step
fixed_step_pulses = _REFERENCES.fixed_step_pulses
coupled_step_pulses = _REFERENCES.coupled_step_pulses
event_driven = _REFERENCES.event_driven
Schedule = _REFERENCES.Schedule
schedule_from_commands = _REFERENCES.schedule_from_commands
# A PlantFamily that steps the same plant by Euler–Maruyama at a fixed step: fixed_step_family(dt).
fixed_step_family = _REFERENCES.fixed_step_family
