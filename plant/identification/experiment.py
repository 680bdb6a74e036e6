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
* **torque holds on a ladder of levels** (linear drive: u steps to a fraction of the ramp peak,
  holds for ``hold_time``, then 0; bridge: none, it has one level): the laws differ most here.
  Below k̄s the multimode, Stribeck and two-mass shafts do not move at all, while a LuGre shaft
  deflects elastically on its bristles (u/σ0, 3–25 µrad) and springs back when u returns to 0;
  just below k̄s a compliant shaft's ringing (the step excites the resonance, f_r above the
  sample rate) lifts the load's torque past k̄s and it breaks away where a rigid shaft stays
  stuck (the slow ramp does not ring: it shows k̄s itself); above k̄s the hold is a constant-torque
  run, accelerating at (u − k̄c)/J for a rigid Coulomb shaft but slower when friction depends on
  speed (Stribeck curve, viscous b·v). Several levels because the plan cannot know k̄s in
  advance; ``holds`` repeats per level and direction average the friction noise of the slides.

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
    holds : int
        Torque holds per ladder level and direction (0: no holds, the plan of the first
        release). Linear drive only: a bridge has no intermediate level.
    doublets : int
        Torque doublets per width and direction (linear drive only; default 0, the default plan
        unchanged): +``max_torque`` for a width, −``max_torque`` for the same width, then 0, each
        followed by a rest — the sharp torque reversal excites a compliant shaft's mode (issue 25's
        eleventh session: on dev axes the moves of the most Fisher information in k_sh per second
        of the plan, docs/axis.md "Eleventh session: auto — the shaft").
    reversals : int
        Slow reversals per ladder level and direction (linear drive only; default 0, the default plan
        unchanged): a kick of +``max_torque`` for 2.5 ms (to break away) then +level for ``hold_time``,
        a kick of −``max_torque`` for 2.5 ms then −level for ``hold_time``, then 0 and a 0.8-s rest;
        levels 0.35, 0.45 and 0.55 of the ramp peak (≈ 1–1.2 k̄c for k̄c = 0.35–0.55·peak). A slide
        held just above k̄c runs at the speeds where a Stribeck curve and viscous friction act, and
        the reversal passes through zero speed (issue 25's twelfth session: on dev stribeck axes the
        moves of the most separation from multimode per second, docs/axis.md "Twelfth session").
    hold_time : float
        Seconds each hold lasts [s]: long enough for the elastic and creeping responses and for
        a slide's speed-dependent friction to show, short enough that a slide at the top level
        stays well inside ``max_angle`` (the angle grows like hold_time²).
    """

    drive: str = "linear"
    sample_period: float = 0.01
    max_torque: float = 20.0
    ramp_fraction: float = 0.15
    ramp_time: float = 0.15
    repeats: int = 6
    rest: float = 0.4
    max_angle: float = 0.2
    holds: int = 2
    hold_time: float = 0.15
    doublets: int = 0
    reversals: int = 0

    def __post_init__(self) -> None:
        if self.drive not in ("linear", "bridge"):
            raise ValueError(f"ExperimentOptions.drive must be 'linear' or 'bridge', got {self.drive!r}")
        for name, lo, hi in (("sample_period", 1e-5, 1.0), ("max_torque", 1e-6, 1e6), ("ramp_time", 0.02, 100.0),
                             ("rest", 0.05, 100.0), ("max_angle", 1e-9, 100.0),
                             ("hold_time", 0.02, 10.0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"ExperimentOptions.{name} must be in [{lo}, {hi}], got {v!r}")
        if not (0 < self.ramp_fraction <= 1):
            raise ValueError(f"ExperimentOptions.ramp_fraction must be in (0, 1], got {self.ramp_fraction!r}")
        if not (isinstance(self.repeats, int) and 1 <= self.repeats <= 100):
            raise ValueError(f"ExperimentOptions.repeats must be an integer in [1, 100], got {self.repeats!r}")
        if not (isinstance(self.holds, int) and not isinstance(self.holds, bool) and 0 <= self.holds <= 100):
            raise ValueError(f"ExperimentOptions.holds must be an integer in [0, 100], got {self.holds!r}")
        if not (isinstance(self.doublets, int) and not isinstance(self.doublets, bool) and 0 <= self.doublets <= 100):
            raise ValueError(f"ExperimentOptions.doublets must be an integer in [0, 100], got {self.doublets!r}")
        if not (isinstance(self.reversals, int) and not isinstance(self.reversals, bool) and 0 <= self.reversals <= 100):
            raise ValueError(f"ExperimentOptions.reversals must be an integer in [0, 100], got {self.reversals!r}")
        if self.reversals and self.drive != "linear":
            raise ValueError("ExperimentOptions.reversals needs the linear drive (a bridge has one level)")
        if self.reversals and _REVERSAL_KICK >= self.sample_period:
            raise ValueError(f"ExperimentOptions.reversals needs sample_period > {_REVERSAL_KICK!r} s "
                             f"(a kick lies in one interval), got {self.sample_period!r}")
        if self.doublets and self.drive != "linear":
            raise ValueError("ExperimentOptions.doublets needs the linear drive (a bridge has no reversal within a pulse)")
        if self.doublets and 2 * max(_DOUBLET_WIDTHS) >= self.sample_period:
            raise ValueError(f"ExperimentOptions.doublets needs sample_period > {2 * max(_DOUBLET_WIDTHS)!r} s "
                             f"(a doublet lies in one interval), got {self.sample_period!r}")


# Pulse widths [s] (short moves: the friction noise grows like the move's duration^1.5). The
# linear drive pulses at max_torque and at half of it (two onsets separate k̄s from τ3).
_LINEAR_WIDTHS = ((1.0, (0.0012, 0.0016, 0.002, 0.0025)), (0.5, (0.0025, 0.003, 0.004)))
_BRIDGE_WIDTHS = ((1.0, (0.001, 0.0015, 0.002, 0.003)),)
# Hold levels as fractions of the ramp peak (ramp_fraction·max_torque ≈ 1.2–1.5 k̄s, so the
# ladder spans ≈ 0.25–1.4 k̄s: elastic, near-breakaway and constant-torque runs).
_HOLD_LEVELS = (0.2, 0.35, 0.45, 0.55, 0.65, 0.75, 0.85, 0.95)
# Doublet widths [s] (``doublets``): +max_torque for w, −max_torque for w, then 0, in one sample interval.
_DOUBLET_WIDTHS = (0.002, 0.0025)
# Slow reversals (``reversals``): levels as fractions of the ramp peak, the kick's width [s] at max_torque.
_REVERSAL_LEVELS = (0.35, 0.45, 0.55)
_REVERSAL_KICK = 0.0025
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
        n_hold = max(int(round(o.hold_time / tau)), 1)
        for _ in range(o.holds):
            for fraction in _HOLD_LEVELS:
                for sign in (1, -1):
                    cmds += [_hold(sign * fraction * peak, drive)] * n_hold + rest * 2
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
    for width in _DOUBLET_WIDTHS if o.doublets else ():
        for _ in range(o.doublets):
            for sign in (1, -1):
                level = sign * o.max_torque
                cmds += [DriveCommand(((0.0, level), (width, -level), (2 * width, 0.0)), drive)] + rest
    for fraction in _REVERSAL_LEVELS if o.reversals else ():
        n_hold = max(int(round(o.hold_time / tau)), 1)
        for _ in range(o.reversals):
            for sign in (1, -1):
                for s in (sign, -sign):
                    level = s * fraction * peak
                    cmds += [DriveCommand(((0.0, s * o.max_torque), (_REVERSAL_KICK, level)), drive)]
                    cmds += [_hold(level, drive)] * (n_hold - 1)
                cmds += rest * 2
    cmds += [_hold(0.0, drive)] * int(round(1.0 / tau))
    text = (f"solnic-bench identification plan ({o.drive} drive): play u at each t, record y.\n"
            + "\n".join(" ".join(WHY.split()).split(" * ")) + "\n"
            + ("**torque doublets** (+max_torque for w, then -max_torque for w, w = 2 and 2.5 ms, "
               f"{o.doublets} per width and direction): the sharp reversal excites a compliant shaft's mode.\n"
               if o.doublets else "")
            + ("**slow reversals** (+max_torque for 2.5 ms then +level for the hold time, the same with -, "
               f"levels 0.35, 0.45, 0.55 of the ramp peak, {o.reversals} per level and direction): slides just "
               "above Coulomb friction, where a speed-dependent law acts.\n" if o.reversals else "")
            + f"Abort (u = 0) if |y - y(0)| > max_angle = {o.max_angle!r} rad.\n"
            + f"max_angle = {o.max_angle!r}\nmax_torque = {o.max_torque!r}")
    return AxisLog(o.drive, tau, o.max_torque, tuple(cmds), None, text)
