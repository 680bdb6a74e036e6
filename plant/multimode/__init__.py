"""``multimode``: Acker's idealized plant, simulated exactly by multimode linearization (ch. 3-4).

A rigid shaft of inertia J with Coulomb friction and stiction, a first-order motor lag, the
commanded velocity x4 and the correlated friction x5 (SPEC §2). Between events the system is
linear and time-invariant, so the state jumps from event to event with X⁺ = Φ(h)·X + N.

Modules by idea: ``expfun`` is shared (:mod:`plant.expfun`); ``transition`` (Φ and the noise
covariance as matrices: the test oracles' counterpart), ``noise`` (the minimal factor (4-20)),
``segments`` (torque events and integrals), ``stuck`` (mode 2), ``moving`` (modes 1 and 3),
``zero_velocity`` (the noisy velocity-zero locators), ``crossing`` (the bridge crossing decision
from a table of log Φ), ``bridge_loop`` (the sub-step loop the interval runs), ``interval`` (the
pure step, compiled whole), ``law_loop`` (the compiled closed loop of a fixed linear law), ``pulse`` (one pulse's
response), ``reference`` (Euler–Maruyama and ``solve_ivp`` reference simulators), ``em_family`` (the
Euler–Maruyama reference behind the family seam, for closed-loop comparisons), ``disturbed``
(the Ornstein–Uhlenbeck disturbance torque of SPEC §11: a seventh state entry d, used only when
``disturbance_torque_std`` > 0; compiled in ``disturbed_jit``, its closed loops in ``disturbed_loop``).
"""

from __future__ import annotations

from types import SimpleNamespace

from plant import protocol
from plant.multimode import disturbed, disturbed_loop, law_loop, pulse, reference
from plant.multimode.em_family import FixedStepFamily
from plant.multimode.interval import advance
from plant.params import PlantParams
from plant.protocol import PlantFamily, register_family

__all__ = ["Multimode"]


@register_family("multimode")
class Multimode(PlantFamily):
    """The exact multimode plant; its step is :func:`plant.multimode.interval.advance`."""

    Params = PlantParams
    description = "Acker's shaft: Coulomb friction and stiction, exact multimode linearization (ch. 3-4)"
    linear_law_loop = staticmethod(law_loop.run_law)
    compiled_law_loop = staticmethod(law_loop.run_compiled_law)
    compiled_loop_logs = True
    references = SimpleNamespace(exact_step=advance, fixed_step=reference.fixed_step,
                                 fixed_step_pulses=reference.fixed_step_pulses,
                                 coupled_step_pulses=reference.coupled_step_pulses, event_driven=reference.event_driven,
                                 Schedule=reference.Schedule, schedule_from_commands=reference.schedule_from_commands,
                                 fixed_step_family=FixedStepFamily)

    def initial_state(self, params, x5):
        """As :meth:`PlantFamily.initial_state`; with the disturbance torque on, d(0) = 0 as well."""
        if params.disturbance_torque_std != 0.0:
            return disturbed.initial_state(params, x5)
        return super().initial_state(params, x5)

    def law_loop(self, params):
        """As :meth:`PlantFamily.law_loop`; with the disturbance torque on (ideal sensor, no delay),
        the disturbed plant's own compiled loop (:mod:`plant.multimode.disturbed_loop`)."""
        if params.disturbance_torque_std != 0.0 and params.quantization == 0.0 and params.command_delay == 0.0:
            return disturbed_loop.run_law
        return super().law_loop(params)

    def compiled_loop(self, params):
        """As :meth:`PlantFamily.compiled_loop`; with the disturbance torque on, the disturbed
        plant's compiled loop of a controller step (:func:`plant.multimode.disturbed_loop.run_compiled_law`:
        sensor, delay and x1 log as the plain one's)."""
        if params.disturbance_torque_std != 0.0:
            return disturbed_loop.run_compiled_law
        return super().compiled_loop(params)

    def step(self, state, command, params, noise, options, *, duration=None, record=False):
        if params.disturbance_torque_std != 0.0:
            return disturbed.advance(state, command, params, noise, options, duration=duration, record=record)
        return advance(state, command, params, noise, options, duration=duration, record=record)

    def pulse_motion(self, params, state, dt_u, sign):
        """As :meth:`PlantFamily.pulse_motion`, with the intervals run in compiled code when there
        is no disturbance torque (:func:`plant.multimode.pulse.pulse_motion`: the same kernel on
        the same inputs, so the same numbers, without ~20 µs of Python per interval)."""
        if params.disturbance_torque_std == 0.0:
            fast = pulse.pulse_motion(protocol._quiet_command(params), state, dt_u, sign, protocol._PULSE_HORIZON_S)
            if fast is not None:
                return fast
        return super().pulse_motion(params, state, dt_u, sign)

    def pulse_on_time(self, params, state, motion, sign, dtu_max, tol, max_iterations):
        """As :meth:`PlantFamily.pulse_on_time`: the whole search compiled when there is no
        disturbance torque (:func:`plant.multimode.pulse.pulse_on_time`), else None."""
        if params.disturbance_torque_std == 0.0:
            return pulse.pulse_on_time(protocol._quiet_command(params), state, motion, sign, dtu_max, tol,
                                       max_iterations, protocol._PULSE_HORIZON_S)
        return None

    def truth(self, params, state):
        """The shared truth; with the disturbance torque on, d [ozf·in] as ``disturbance_torque``."""
        out = super().truth(params, state)
        if params.disturbance_torque_std != 0.0:
            out["disturbance_torque"] = float(state.x[disturbed.D]) if state.x.shape[0] > disturbed.D else 0.0
        return out
