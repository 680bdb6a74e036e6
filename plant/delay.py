"""The compute delay: the command computed from y(n) takes effect at nτs + δ (SPEC §11).

The controller's command for sample n is a list of segments (oₖ, vₖ) on [0, τs) (a
:class:`~plant.drive.DriveCommand`). With a delay δ (0 < δ < τs) segment k starts at
nτs + δ + oₖ instead of nτs + oₖ, and whatever was in force holds until the first of them. So
the levels in force over the interval [nτs, (n+1)τs) are

* over [0, δ): the *pending* command — the part of the previous command that the delay pushed
  past the previous interval's end, re-timed to this interval (offsets in [0, δ));
* over [δ, τs): this command's segments shifted by δ; a segment that would start at or after
  τs is cut at the boundary and carried into the next interval's pending command, together
  with the level in force at the boundary.

Each interval is then one ordinary command, so every family simulates it exactly: δ is one
more segment boundary inside the interval. The pending command is a small explicit record the
closed loop carries from one interval to the next (:meth:`plant.protocol.PlantFamily.delayed_step`),
so the plant's step stays pure. Before the first command nothing was commanded: level 0 of the
first command's drive (the plant starts with no current).

Consecutive segments with the same level are merged (a bridge's 0 continues a flyback
either way), so a held level does not add a plant event at δ.
"""

from __future__ import annotations

from plant.drive import DriveCommand

__all__ = ["delay_command"]


def delay_command(command: DriveCommand, pending: DriveCommand | None, delay: float, period: float
                  ) -> tuple[DriveCommand, DriveCommand]:
    """(the command in force over this interval, the pending command for the next).

    Parameters
    ----------
    command : DriveCommand
        The controller's command for this sample (offsets from the sample instant [s]).
    pending : DriveCommand or None
        What the previous interval carried over (offsets < ``delay``); None before the first.
    delay, period : float
        δ and τs [s], 0 < δ < τs.

    Raises
    ------
    ValueError
        If ``command`` and ``pending`` use different drives (one interval has one power stage),
        or a segment of ``command`` starts at or beyond ``period`` (as the plant rejects it
        without a delay: a command covers one sample interval of the controller's time).
    """
    if pending is None:
        pending = DriveCommand.hold(0.0, command.drive)
    elif pending.drive is not command.drive:
        raise ValueError(f"command_delay: a {command.drive.value} command cannot follow a pending "
                         f"{pending.drive.value} command within one interval")
    now: list[tuple[float, float]] = []
    for offset, level in pending.segments:
        if offset < delay:
            _append(now, offset, level)
    carry: list[tuple[float, float]] = []
    for offset, level in command.segments:
        if not offset < period:
            raise ValueError(f"DriveCommand segment offset {offset!r} s is at or beyond the sample "
                             f"interval's end ({period!r} s)")
        start = offset + delay
        if start < period:
            _append(now, start, level)
        else:
            if not carry:
                carry.append((0.0, now[-1][1]))        # the level in force at the boundary
            _append(carry, start - period, level)
    if not carry:
        carry.append((0.0, now[-1][1]))
    return DriveCommand(now, command.drive), DriveCommand(carry, command.drive)


def _append(segments: list[tuple[float, float]], offset: float, level: float) -> None:
    """Add a segment; a start at the last one's replaces its level; an equal level is merged."""
    if segments and offset <= segments[-1][0]:
        segments.pop()
    if segments and segments[-1][1] == level:
        return
    segments.append((offset, level))
