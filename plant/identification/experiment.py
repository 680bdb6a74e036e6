"""The identification experiment: the excitation a user plays on the axis at τs.

Why each part is there (also the plan's header and ``solnic-bench experiment --help``):

* **rests** (u = 0, shaft stuck): the spread of y about its mean while nothing moves is the
  measurement noise σ1, and each rest's mean is the start angle of the next move;
* **slow torque ramps both ways** (linear drive: u rises at a constant rate to a peak, then 0;
  bridge: pulses whose width grows by small steps, since a bridge cannot ramp its torque): the
  shaft breaks away where the torque passes the stiction level k̄s; the slide that follows
  (net torque x3 − k̄c on J) weighs the Coulomb level k̄c against the inertia;
* **pulse trains of several widths both ways** (each pulse followed by a rest long enough to
  stick): the net motion per pulse against its width is the pulse law (section 3.2). Its onset
  width is set by k̄s and the motor lag τ3 (x3 = u·(1 − e^(−t/τ3))), its slope by J and k̄c;
  repeats average the friction noise; both directions expose an asymmetry.

The plan alternates directions so that the shaft wanders little; the player must still stop
(u = 0) when |y − y(0)| exceeds ``max_angle`` (written in the header): an open-loop plan cannot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from plant.drive import DriveCommand, DriveType
from plant.identification.log import AxisLog

__all__ = ["ExperimentOptions", "design_experiment", "WHY"]

WHY = __doc__.split("Why each part is there (also the plan's header and ``solnic-bench experiment --help``):")[1] \
    .split("The plan alternates")[0].strip()


@dataclass(frozen=True)
class ExperimentOptions:
    """What the plan may do.

    Attributes
    ----------
    drive : {"linear", "bridge"}
    sample_period : float
        τs [s], the rate the axis is sampled and driven at.
    max_torque : float
        Largest |u| of the linear drive [ozf·in]; its pulses use it, its ramps peak at
        ``ramp_fraction`` of it. For the bridge: the supply level u_max [ozf·in].
    ramp_fraction : float
        Ramp peak / max_torque, in (0, 1]; set it to about 1.2× the stiction level you expect.
    ramp_time : float
        Time [s] a ramp takes from 0 to its peak: slow against τ3 (the lag r·τ3 is modelled),
        fast enough that the slide after breakaway stays short (its angle grows with the time
        the torque spends above k̄s, and the friction noise with the slide's duration^1.5).
    repeats : int
        Pulses per width and direction (the plan's length grows with it).
    rest : float
        Rest after every move [s], long enough for the shaft to stick and the current to decay.
    max_angle : float
        |y − y(0)| [rad] at which the player must abort (written into the plan).
    """

    drive: str = "linear"
    sample_period: float = 0.01
    max_torque: float = 20.0
    ramp_fraction: float = 0.15
    ramp_time: float = 0.15
    repeats: int = 6
    rest: float = 0.4
    max_angle: float = 0.2

    def __post_init__(self) -> None:
        if self.drive not in ("linear", "bridge"):
            raise ValueError(f"ExperimentOptions.drive must be 'linear' or 'bridge', got {self.drive!r}")
        for name, lo, hi in (("sample_period", 1e-5, 1.0), ("max_torque", 1e-6, 1e6), ("ramp_time", 0.02, 100.0),
                             ("rest", 0.05, 100.0), ("max_angle", 1e-9, 100.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"ExperimentOptions.{name} must be in [{lo}, {hi}], got {v!r}")
        if not (0 < self.ramp_fraction <= 1):
            raise ValueError(f"ExperimentOptions.ramp_fraction must be in (0, 1], got {self.ramp_fraction!r}")
        if not (isinstance(self.repeats, int) and 1 <= self.repeats <= 100):
            raise ValueError(f"ExperimentOptions.repeats must be an integer in [1, 100], got {self.repeats!r}")


# Pulse widths [s] (short moves: the friction noise grows like the move's duration^1.5). The
# linear drive pulses at max_torque and at half of it (two onsets separate k̄s from τ3).
_LINEAR_WIDTHS = ((1.0, (0.0012, 0.0016, 0.002, 0.0025)), (0.5, (0.0025, 0.003, 0.004)))
_BRIDGE_WIDTHS = ((1.0, (0.001, 0.0015, 0.002, 0.003)),)
_BRIDGE_RAMP = tuple(round(0.0004 + 0.0001 * k, 6) for k in range(13))   # 0.4 … 1.6 ms


def _hold(level: float, drive: DriveType) -> DriveCommand:
    return DriveCommand.hold(level, drive)


def _pulse(width: float, level: float, tau: float, drive: DriveType) -> list[DriveCommand]:
    """A pulse of ``width`` s from a sample instant (may span several intervals)."""
    out = []
    left = width
    while left > 0:
        if left >= tau:
            out.append(_hold(level, drive))
        else:
            out.append(DriveCommand(((0.0, level), (left, 0.0)), drive))
        left = round(left - tau, 12)
    return out


def design_experiment(options: ExperimentOptions = ExperimentOptions()) -> AxisLog:
    """The plan (an :class:`AxisLog` without ``y``) for ``options``; see the module docstring."""
    o = options
    tau = o.sample_period
    drive = DriveType(o.drive)
    rest = [_hold(0.0, drive)] * max(int(round(o.rest / tau)), 1)
    cmds: list[DriveCommand] = [_hold(0.0, drive)] * int(round(2.0 / tau))     # 2 s: σ1 and the start angle
    if drive is DriveType.LINEAR:
        peak = o.ramp_fraction * o.max_torque
        n_ramp = max(int(round(o.ramp_time / tau)), 2)
        for sign in (1, -1, 1, -1):
            cmds += [_hold(sign * peak * (k + 1) / n_ramp, drive) for k in range(n_ramp)]
            cmds += rest * 3
        widths = _LINEAR_WIDTHS
    else:
        for width in _BRIDGE_RAMP:
            for sign in (1, -1):
                cmds += _pulse(width, sign * o.max_torque, tau, drive) + rest
        widths = _BRIDGE_WIDTHS
    for fraction, group in widths:
        for width in group:
            for _ in range(o.repeats):
                for sign in (1, -1):
                    cmds += _pulse(width, sign * fraction * o.max_torque, tau, drive) + rest
    cmds += [_hold(0.0, drive)] * int(round(1.0 / tau))
    text = (f"solnic-bench identification plan ({o.drive} drive): play u at each t, record y.\n"
            + "\n".join(" ".join(WHY.split()).split(" * ")) + "\n"
            + f"Abort (u = 0) if |y - y(0)| > max_angle = {o.max_angle!r} rad.\n"
            + f"max_angle = {o.max_angle!r}\nmax_torque = {o.max_torque!r}")
    return AxisLog(o.drive, tau, o.max_torque, tuple(cmds), None, text)
