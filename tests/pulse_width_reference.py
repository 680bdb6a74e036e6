"""``pulse-width`` as it was before its step became one compiled function: the reference its
compiled step is compared with, bit for bit (tests/test_pulse_width_compiled.py). A verbatim copy of
the per-sample Python of controllers/pulse_width.py at revision 9dbb447 (not registered)."""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Any

import numpy as np

from controllers.base import Controller
from controllers.pulse_width import PulseModelRls, PulseWidthOptions
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

_OFF = DriveCommand.hold(0.0, DriveType.BRIDGE)


class _Segment:
    """Running sums of one stuck segment's samples (t [s], y [rad]); ``clean`` holds the sums of
    the samples taken before any trigger decision (for the unbiased slope)."""

    __slots__ = ("n", "st", "sy", "stt", "sty", "prior", "clean")

    def __init__(self) -> None:
        self.n, self.st, self.sy, self.stt, self.sty = 0, 0.0, 0.0, 0.0, 0.0
        self.prior: tuple[float, float, float] | None = None   # (t, x̂1(t), variance)
        self.clean: _Segment | None = None

    def add(self, t: float, y: float, clean: bool = False) -> None:
        if clean:
            if self.clean is None:
                self.clean = _Segment()
            self.clean.add(t, y)
        self.n += 1
        self.st += t
        self.sy += y
        self.stt += t * t
        self.sty += t * y

    @property
    def t_mean(self) -> float:
        return self.st / self.n

    @property
    def y_mean(self) -> float:
        return self.sy / self.n

    def centred(self) -> tuple[float, float]:
        """(Σ(t − t̄)², Σ(t − t̄)(y − ȳ))."""
        if self.n < 2:
            return 0.0, 0.0
        return self.stt - self.st ** 2 / self.n, self.sty - self.st * self.sy / self.n


class PythonPulseWidth(Controller):
    """The Python form of ``pulse-width`` before its step was compiled (the reference of its rows)."""

    drive = DriveType.BRIDGE
    description = "Adaptive pulse-width control, RLS width model (Yang & Tomizuka 1988)"
    Options = PulseWidthOptions
    presets = MappingProxyType({"default": PulseWidthOptions()})
    knobs = MappingProxyType({"target_step": (1.5e-6, 2e-6, 3e-6, 4e-6, 6e-6)})
    counter = "pulses"

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Check the width limit for ``params`` and start with no knowledge of the plant."""
        o = self.options
        tau3, ts = params.motor_time_constant, params.sample_period
        t_zero = o.max_width + tau3 * math.log(2.0 - math.exp(-o.max_width / tau3))
        if not t_zero < ts:   # current back to zero in flyback within one sample
            raise ValueError(f"max_width must let the current return to zero within one sample "
                             f"period ({ts!r} s); got {o.max_width!r} s")
        self.params = params
        self._ts = ts
        self._sigma = max(params.measurement_noise_std, 1e-12)
        self._sigma2 = self._sigma ** 2
        self._forget_slope = math.exp(-ts / o.slope_memory_s)
        self.model = PulseModelRls(o.forgetting)
        self.width = o.initial_width
        self.width_floor = 0.0
        self._n = 0
        self._seg = _Segment()
        self._prev: _Segment | None = None          # segment before the last pulse
        self._pulse: tuple[float, int, float, float] | None = None  # (t, sign, width, Δc_p)
        self._var_pred = o.target_step ** 2          # spread of Δc about the model [rad²]
        self._sxx, self._sxy = 0.0, 0.0
        self._dither_phase = 0
        self._pulse_times: list[float] = []
        self.counts = dict(pulses=0, significant=0, no_motion=0, model_inversions=0)
        self.last_dc = math.nan
        self.x1_hat = 0.0
        self.x4_hat = 0.0

    # ------------------------------------------------------------------ estimates
    def _slope(self) -> float:
        sxx, sxy = self._seg.clean.centred() if self._seg.clean is not None else (0.0, 0.0)
        den = self._sxx + sxx
        return (self._sxy + sxy) / den if den > 0 else 0.0

    def _level(self, seg: _Segment, t: float, slope: float) -> tuple[float, float]:
        """x̂1(t) [rad] and its variance from the segment's samples and its prior."""
        mean, var = math.nan, math.inf
        n = seg.n
        if n > 0:   # seg.y_mean + slope·(t − seg.t_mean), σ1²/n
            mean, var = seg.sy / n + slope * (t - seg.st / n), self._sigma2 / n
        prior = seg.prior
        if prior is not None:
            t0, level0, var0 = prior
            prior = level0 + slope * (t - t0)
            if not math.isfinite(mean):
                return prior, var0
            w = var0 / (var0 + var)                    # precision-weighted combination
            return prior + w * (mean - prior), var0 * var / (var0 + var)
        return mean, var

    # ------------------------------------------------------------------ per sample
    def step(self, y: float) -> DriveCommand:
        """Add y(n) to the stuck segment; fire a ±u_max pulse when the error is due."""
        o = self.options
        t = self._n * self._ts
        self._n += 1
        self._sxx *= self._forget_slope
        self._sxy *= self._forget_slope
        seg = self._seg
        early = t < o.startup_s
        if math.isfinite(y):   # samples before the first trigger decision enter the slope
            seg.add(t, y, clean=seg.n < o.min_segment_samples or early)
        if seg.n == 0:
            return _OFF
        slope = self._slope()
        self.x4_hat = -slope
        self.x1_hat, _ = self._level(seg, t, slope)
        if early or seg.n < o.min_segment_samples:
            return _OFF
        p, var_p = self._level(seg, t + self._ts, slope)
        step = o.target_step
        away = p * slope > 0 or slope == 0.0
        due = abs(p) >= 0.5 * step and away
        overshoot = abs(p) >= o.overshoot_factor * step and abs(p) >= 3.0 * math.sqrt(var_p)
        if not (due or overshoot):
            return _OFF
        sign = -1 if p > 0 else 1
        self._close_segment(slope)
        width = self._next_width()
        level_now, var_now = self._level(self._prev, t, slope)
        predicted = self.model.predict(width) if self.counts["model_inversions"] else step
        self._seg.prior = (t, level_now + sign * predicted, var_now + self._var_pred)
        self._pulse = (t, sign, width, predicted)
        self._pulse_times.append(t)
        self.counts["pulses"] += 1
        return DriveCommand.pulse(0.0, width, sign * self.params.u_max)

    def _close_segment(self, slope: float) -> None:
        """Pool the finished segment's slope sums and evaluate the previous pulse from the
        samples alone (the prior is not used twice)."""
        seg = self._seg
        sxx, sxy = seg.clean.centred() if seg.clean is not None else (0.0, 0.0)
        self._sxx += sxx
        self._sxy += sxy
        if self._pulse is not None and self._prev is not None and self._prev.n > 0 and seg.n > 0:
            _, sign, width, predicted = self._pulse
            a, b = seg, self._prev
            dc = sign * (a.y_mean - b.y_mean - slope * (a.t_mean - b.t_mean))
            var_e = self._sigma2 * (1.0 / a.n + 1.0 / b.n)
            self.last_dc = dc
            if self.counts["significant"] == 0 and dc < 2.0 * math.sqrt(var_e):
                self.counts["no_motion"] += 1          # start-up: no motion yet, widen
                self.width_floor = max(self.width_floor, width)
            else:
                self.counts["significant"] += 1
                self.model.update(width, dc)
                self._last_motion = (width, dc)
                if self.counts["model_inversions"]:   # spread of Δc about the model
                    resid = (dc - predicted) ** 2 - var_e
                    self._var_pred += 0.05 * (max(resid, 0.0) - self._var_pred)
                    self._var_pred = max(self._var_pred, (0.05 * self.options.target_step) ** 2)
        self._prev = seg
        self._seg = _Segment()

    def _next_width(self) -> float:
        o = self.options
        lo_limit = 0.2 * o.initial_width
        if self.counts["significant"] >= o.min_model_pulses:
            # one pulse changes the width by at most ``max_width_change`` (model glitches)
            w = self.model.invert(o.target_step, max(lo_limit, self.width / (1 + o.max_width_change)),
                                  min(o.max_width, self.width * (1 + o.max_width_change)))
            if w is not None:
                self.counts["model_inversions"] += 1
                self.width = w
            else:   # the target is outside the bracket: move to its edge towards the target
                up = self.model.predict(self.width) < o.target_step
                self.width *= (1 + o.max_width_change) if up else 1 / (1 + o.max_width_change)
        else:
            self._scalar_rule()
        self.width = min(max(self.width, lo_limit), o.max_width)
        self._dither_phase = (self._dither_phase + 1) % 3
        return min(self.width * (1.0 + o.width_dither * (self._dither_phase - 1)), o.max_width)

    def _scalar_rule(self) -> None:
        """Before the model: grow after no motion, else w ← w·√(Δ/Δc) (Δc ∝ w², clipped)."""
        o = self.options
        last = getattr(self, "_last_motion", None)
        if last is None:
            if self.width <= self.width_floor:
                self.width = self.width_floor * o.width_growth
            return
        w, dc = last
        if dc > 0:
            self.width = w * min(max(math.sqrt(o.target_step / dc), 0.9), 1.1)

    # ------------------------------------------------------------------ reporting
    def internals(self) -> dict[str, float]:
        return {"x1_hat": self.x1_hat, "x4_hat": self.x4_hat, "width": self.width,
                "dc_measured": self.last_dc}

    def event_times(self) -> dict[str, np.ndarray]:
        return {"pulse": np.asarray(getattr(self, "_pulse_times", []), dtype=float)}

    def summary(self) -> dict[str, Any]:
        if not hasattr(self, "model"):
            return {"target_step": self.options.target_step}
        out: dict[str, Any] = {"target_step": self.options.target_step, "width": self.width,
                               "width_floor": self.width_floor, "x4_hat": self.x4_hat,
                               "model_dc_at_width": self.model.predict(self.width)}
        out.update(self.counts)
        return out
