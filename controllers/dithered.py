"""Dithered linear controller, ``dithered`` (SPEC §4, section 2.3).

The :mod:`controllers.linear` design plus a square-wave dither at the drive input:

    u(t) = clip(−C(z)·y(n) + A_d·sq(f_d·t + φ), ±u_max),   t ∈ [n·τs, (n+1)·τs)

where sq(θ) = +1 for frac(θ) < ½ and −1 otherwise. The command is a list of (offset, level)
segments, so the dither switches inside the sample interval and f_d may exceed the 50 Hz
Nyquist rate. The phase φ is drawn once per run from the controller's own generator.
Inequality (2-6) still holds for dither slower than the bandwidth limit ωb; only
f_d above ωb/(2π) can break it, paying with motor current (mean |x3|, rms x3).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from controllers.base import register
from controllers.law import LinearLaw
from plant.linear_drive import square_wave_segments as _segments_into
from controllers.linear import LinearController, LinearOptions
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

__all__ = ["DitheredController", "DitheredOptions", "square_wave_segments", "DEFAULT_DITHER_AMPLITUDE",
           "DEFAULT_DITHER_FREQUENCY_HZ"]

# Defaults measured with the dither sweep on Table 2-1 (bench/tuning.py, docs/tuning.md):
# the lowest mean peak error above ωc and the Nyquist rate, 62 µrad vs 1233 µrad undithered,
# at a mean |x3| of 1.12 vs 0.82 ozf·in.
DEFAULT_DITHER_AMPLITUDE = 18.0  # ozf·in
DEFAULT_DITHER_FREQUENCY_HZ = 250.0  # Hz



def square_wave_segments(t0: float, duration: float, base: float, amplitude: float,
                         frequency_hz: float, phase: float, limit: float) -> tuple:
    """(offset, level) segments of clip(base + A·sq(f·t + φ), ±limit) on [t0, t0 + duration).

    Parameters
    ----------
    t0, duration : float
        Interval start and length [s].
    base : float
        Level held over the interval [ozf·in].
    amplitude, frequency_hz, phase : float
        A [ozf·in], f [Hz] and φ [cycles] of the square wave.
    limit : float
        Clip bound u_max [ozf·in].

    The compiled :func:`plant.linear_drive.square_wave_segments` (the code the compiled closed
    loop runs), as a tuple.
    """
    n_max = int(2.0 * frequency_hz * duration) + 4 if amplitude != 0.0 else 1
    offs, levs = np.empty(n_max), np.empty(n_max)
    k = _segments_into(float(t0), float(duration), float(base), float(amplitude), float(frequency_hz),
                       float(phase), float(limit), offs, levs)
    return tuple(zip(offs[:k].tolist(), levs[:k].tolist()))


@dataclass(frozen=True)
class DitheredOptions(LinearOptions):
    """Options of :class:`DitheredController`: those of :class:`LinearOptions` plus the dither.

    Attributes
    ----------
    dither_amplitude : float
        A_d ≥ 0 [ozf·in]; must stay below u_max (checked at ``reset``). Default 18.
    dither_frequency : float
        f_d > 0 [Hz]. Default 250.
    random_phase : bool
        Draw φ ~ U[0, 1) at reset from the controller's generator; otherwise φ = 0.
    """

    dither_amplitude: float = DEFAULT_DITHER_AMPLITUDE
    dither_frequency: float = DEFAULT_DITHER_FREQUENCY_HZ
    random_phase: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("dither_amplitude", "dither_frequency"):
            value = getattr(self, name)
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value)):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if self.dither_amplitude < 0:
            raise ValueError(f"dither_amplitude must be >= 0 ozf·in, got {self.dither_amplitude!r}")
        if self.dither_frequency <= 0:
            raise ValueError(f"dither_frequency must be > 0 Hz, got {self.dither_frequency!r}")
        if not isinstance(self.random_phase, bool):
            raise ValueError(f"random_phase must be a bool, got {self.random_phase!r}")


_DITHER_DEFAULTS = DitheredOptions()


@register("dithered")
class DitheredController(LinearController):
    """Linear lead/lag controller plus square-wave dither at the drive input.

    Options: :class:`DitheredOptions`. Presets: ``"default"`` and ``"below-nyquist"``
    (A_d = 8 ozf·in at 125 Hz, the best cell of the sweep below 250 Hz).

    Knobs: ``dither_amplitude`` [ozf·in] and ``dither_frequency`` [Hz], over the grid of the
    recorded sweep (:mod:`bench.tuning`, docs/tuning.md). The defaults (A_d = 18 ozf·in,
    f_d = 250 Hz) are the lowest peak error among the frequencies above the crossover and the
    Nyquist rate (SPEC §4).
    """

    description = "Lead/lag linear controller plus square-wave dither at the drive input"
    family = "dithered"   # its own family in the claims and the report, not "linear"
    Options = DitheredOptions
    presets = MappingProxyType({
        "default": _DITHER_DEFAULTS,
        "below-nyquist": dataclasses.replace(_DITHER_DEFAULTS, dither_amplitude=8.0,
                                             dither_frequency=125.0),
    })
    knobs = MappingProxyType({"dither_amplitude": (2.0, 4.0, 8.0, 12.0, 16.0, 18.0),
                              "dither_frequency": (25.0, 125.0, 250.0, 500.0)})

    def __init__(self, options: Any = None, /, *, preset: str | None = None, **fields: Any) -> None:
        super().__init__(options, preset=preset, **fields)
        self._phase = 0.0

    @property
    def dither_amplitude(self) -> float:
        """A_d [ozf·in]."""
        return float(self.options.dither_amplitude)

    @property
    def dither_frequency(self) -> float:
        """f_d [Hz]."""
        return float(self.options.dither_frequency)

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Design, zero the state, and draw the dither phase."""
        if self.dither_amplitude >= params.u_max:
            raise ValueError(f"dither_amplitude must be < u_max ({params.u_max!r}), "
                             f"got {self.dither_amplitude!r}")
        super().reset(params, rng)
        self._tau_s = params.sample_period
        self._n = 0
        self._phase = float(rng.random()) if self.options.random_phase else 0.0
        self._dither = (self.dither_amplitude, self.dither_frequency)

    def step(self, y: float) -> DriveCommand:
        """Linear level −C(z)·y(n) plus the dither over [n·τs, (n+1)·τs)."""
        base = self.control_level(y)
        amplitude, frequency = self._dither
        segments = square_wave_segments(self._n * self._tau_s, self._tau_s, base, amplitude, frequency,
                                         self._phase, self._u_max)
        self._n += 1
        return DriveCommand(segments, DriveType.LINEAR)

    def linear_law(self) -> LinearLaw | None:
        """The law of :meth:`step`: the linear law plus the dither (None for a subclass that
        overrides ``step``)."""
        if self.design is None or type(self).step is not DitheredController.step:
            return None
        amplitude, frequency = self._dither
        return LinearLaw(*self.design.state_space, u_max=self._u_max, dither_amplitude=amplitude,
                         dither_frequency=frequency, dither_phase=self._phase)

    def summary(self) -> dict[str, Any]:
        out = super().summary()
        if out:
            out.update(dither_amplitude=self.dither_amplitude,
                       dither_frequency_hz=self.dither_frequency,
                       dither_above_crossover=2 * math.pi * self.dither_frequency
                       > out["crossover_rad_s"])
        return out
