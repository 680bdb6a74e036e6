"""Drive commands: piecewise-constant levels within one sample interval.

At every sample instant a controller returns a :class:`DriveCommand` for the interval up to
the next sample. The command is a tuple of ``(offset_s, level)`` segments; the first starts at
offset 0, offsets increase strictly and lie inside ``[0, sample_period)``. A level holds until
the next segment's offset or the end of the interval.

Two drive types (SPEC §2 "Drives"):

* ``BRIDGE`` — switched bridge with flyback diodes (section 3.2). Levels are +u_max, 0 and
  −u_max. A commanded 0 while current flows applies u = −sign(x3)·u_max until x3 reaches 0.
* ``LINEAR`` — linear amplifier: u is the level clipped to ±u_max; no flyback.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

__all__ = ["DriveType", "DriveCommand"]


class DriveType(str, enum.Enum):
    BRIDGE = "bridge"
    LINEAR = "linear"


@dataclass(frozen=True)
class DriveCommand:
    """Piecewise-constant drive levels for one sample interval.

    Parameters
    ----------
    segments : tuple of (offset_s, level)
        Offsets [s] from the sample instant and commanded levels [ozf·in].
    drive : DriveType
        Which power stage realises the levels.
    """

    segments: tuple[tuple[float, float], ...]
    drive: DriveType = DriveType.LINEAR

    def __post_init__(self) -> None:
        segs = tuple((float(o), float(v)) for o, v in self.segments)
        if not segs:
            raise ValueError("DriveCommand.segments must not be empty")
        if segs[0][0] != 0.0:
            raise ValueError(f"DriveCommand.segments must start at offset 0, got {segs[0][0]!r}")
        prev = -1.0
        for o, v in segs:
            if not (o > prev and math.isfinite(o) and math.isfinite(v)):
                raise ValueError(f"DriveCommand.segments offsets must increase and levels be finite, "
                                 f"got ({o!r}, {v!r}) after offset {prev!r}")
            prev = o
        object.__setattr__(self, "segments", segs)
        if type(self.drive) is not DriveType:
            object.__setattr__(self, "drive", DriveType(self.drive))

    @classmethod
    def hold(cls, level: float, drive: DriveType = DriveType.LINEAR) -> "DriveCommand":
        """One level for the whole interval (zero-order hold)."""
        return cls(((0.0, float(level)),), drive)

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
