"""Drive commands: piecewise-constant levels within one sample interval.

At every sample instant a controller returns a :class:`DriveCommand` for the interval up to
the next sample. The command is a tuple of ``(offset_s, level)`` segments; the first starts at
offset 0, offsets increase strictly and lie inside ``[0, sample_period)`` (the plant rejects a
segment at or beyond the interval's end). A level holds until the next segment's offset or
the end of the interval.

Two drive types (SPEC §2 "Drives"):

* ``BRIDGE`` — switched bridge with flyback diodes (section 3.2). Levels are +u_max, 0 and
  −u_max. A commanded 0 while current flows applies u = −sign(x3)·u_max until x3 reaches 0.
* ``LINEAR`` — linear amplifier: u is the level clipped to ±u_max; no flyback.
"""

from __future__ import annotations

import enum
import math

import numpy as np

__all__ = ["DriveType", "DriveCommand"]


# The offsets of every zero-order hold (shared; the compiled plant only reads it).
_HOLD_OFFSETS = np.zeros(1)


class DriveType(str, enum.Enum):
    BRIDGE = "bridge"
    LINEAR = "linear"


class DriveCommand:
    """Piecewise-constant drive levels for one sample interval (immutable).

    Parameters
    ----------
    segments : sequence of (offset_s, level)
        Offsets [s] from the sample instant and commanded levels [ozf·in].
    drive : DriveType
        Which power stage realises the levels.

    Raises
    ------
    ValueError
        If there are no segments, the first offset is not 0, offsets do not increase, or a
        value is not finite.
    """

    __slots__ = ("segments", "drive", "_offsets", "_levels")

    def __init__(self, segments, drive: DriveType = DriveType.LINEAR) -> None:
        offsets, levels = [], []
        prev = -1.0
        for o, v in segments:
            o, v = float(o), float(v)
            if not offsets and o != 0.0:
                raise ValueError(f"DriveCommand.segments must start at offset 0, got {o!r}")
            if not (o > prev and o - o == 0.0 and v - v == 0.0):   # x - x == 0 only for finite x
                raise ValueError(f"DriveCommand.segments offsets must increase and levels be finite, "
                                 f"got ({o!r}, {v!r}) after offset {prev!r}")
            offsets.append(o)
            levels.append(v)
            prev = o
        if not offsets:
            raise ValueError("DriveCommand.segments must not be empty")
        self._set(tuple(zip(offsets, levels)), drive if type(drive) is DriveType else DriveType(drive))
        object.__setattr__(self, "_offsets", np.array(offsets))
        object.__setattr__(self, "_levels", np.array(levels))

    def _set(self, segs: tuple, drive: DriveType) -> None:
        object.__setattr__(self, "segments", segs)
        object.__setattr__(self, "drive", drive)
        object.__setattr__(self, "_offsets", None)
        object.__setattr__(self, "_levels", None)

    def __setattr__(self, name, value):
        raise AttributeError("DriveCommand is immutable")

    def __eq__(self, other) -> bool:
        return isinstance(other, DriveCommand) and self.segments == other.segments and self.drive is other.drive

    def __hash__(self) -> int:
        return hash((self.segments, self.drive))

    def __repr__(self) -> str:
        return f"DriveCommand(segments={self.segments!r}, drive={self.drive!r})"

    def __reduce__(self):
        return (DriveCommand, (self.segments, self.drive))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(offsets [s], levels) as float arrays, for the compiled plant."""
        if self._offsets is None:
            object.__setattr__(self, "_offsets", np.array([o for o, _ in self.segments]))
            object.__setattr__(self, "_levels", np.array([v for _, v in self.segments]))
        return self._offsets, self._levels

    @classmethod
    def hold(cls, level: float, drive: DriveType = DriveType.LINEAR) -> "DriveCommand":
        """One level for the whole interval (zero-order hold)."""
        level = float(level)
        if not math.isfinite(level):
            raise ValueError(f"DriveCommand level must be finite, got {level!r}")
        cmd = object.__new__(cls)
        _set = object.__setattr__
        _set(cmd, "segments", ((0.0, level),))
        _set(cmd, "drive", drive if type(drive) is DriveType else DriveType(drive))
        _set(cmd, "_offsets", _HOLD_OFFSETS)
        _set(cmd, "_levels", np.array((level,)))   # np.full costs 3x more at this size
        return cmd

    @classmethod
    def pulse(cls, start: float, duration: float, level: float) -> "DriveCommand":
        """A bridge pulse of ``level`` from ``start`` for ``duration`` seconds, then off."""
        if start < 0 or duration < 0:
            raise ValueError(f"pulse start and duration must be >= 0, got {start!r}, {duration!r}")
        if duration == 0:
            return cls(((0.0, 0.0),), DriveType.BRIDGE)
        if start == 0:
            segs = ((0.0, level), (duration, 0.0))
        else:
            segs = ((0.0, 0.0), (start, level), (start + duration, 0.0))
        return cls(segs, DriveType.BRIDGE)
