"""Adaptive pulse-width control, ``pulse-width`` (a peer; SPEC §10).

Source: S. Yang and M. Tomizuka, "Adaptive pulse width control for precise positioning under
the influence of stiction and Coulomb friction", ASME J. Dynamic Systems, Measurement, and
Control 110 (1988) 221–227: fixed-amplitude force pulses whose width is adapted online from the
measured displacement, so that each pulse moves the axis by a chosen step. The closest modern
twin of solnic, without its plant model.

Design rule, on the switched bridge (±u_max pulses, then flyback):

* **Stuck-mode position estimate from the measurements alone.** Between pulses the shaft
  sticks and y(n) = c_k − r(t) + w1 with r advancing at x4: every stuck segment k is a line of
  common slope −x4. The slope x̂4 is the pooled within-segment least-squares slope of the
  segments' first ``min_segment_samples`` samples (exponential forgetting, ``slope_memory_s``):
  only samples taken before any trigger decision, because a segment ends when its last samples
  happen to lie low, which would bias the slope. The current segment's level combines its
  sample mean with the prior x̂1(t_p) + sign·Δc_model of the pulse that started it (precision
  weighted), so x̂1(t) = level − x̂4·(t − t_p). No friction model is used.
* **Trigger.** At sample n the error predicted for the next sample, p = x̂1(t_n + τs), is
  corrected by a pulse towards zero when it drifts away from zero past half the target step,
  |p| ≥ Δ/2, or lies beyond ``overshoot_factor``·Δ (and 3 standard deviations) whatever its
  drift. The pulse starts at the sample instant.
* **Measured displacement.** When the next pulse is due, the samples of the segments before
  and after the previous pulse alone give its displacement
  Δc_e = ȳ_a − ȳ_b + x̂4·(t̄_a − t̄_b) (in the pulse's direction) and its variance
  σ1²·(1/n_a + 1/n_b); the model's prediction is not used twice.
* **Displacement-versus-width model, identified online.** Δc(w) = θ0 + θ1·v + θ2·v² + θ3·v³,
  v = w/1 ms, by recursive least squares with forgetting λ (``forgetting``) over every pulse
  after the first one that moved (:class:`PulseModelRls`). It is inverted for the target step
  Δ by bisection on its increasing branch within ±``max_width_change`` of the last width; the
  widths cycle through (1 − δ, 1, 1 + δ)× the inverse (``width_dither`` δ) so that the model
  stays identifiable. Start-up: the width grows by ``width_growth`` until a pulse moves the
  shaft significantly (z ≥ 2); then, before ``min_model_pulses`` such pulses, it follows
  the square-root rule w ← w·√(Δ/Δc_e) (clipped to ±10 %) of a pulse against Coulomb
  friction (Δc ∝ w², Yang & Tomizuka's model).

Knob: the target step Δ [rad]. The default is chosen by the sweep in docs/tuning.md (thesis
scenario, seeds 0–4 only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from controllers._fma import cubic_invert, cubic_predict, rls_update
from controllers.base import Controller, register
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

__all__ = ["PulseWidthOptions", "PulseWidthController", "PulseModelRls"]

_MS = 1e-3
_URAD = 1e-6
_OFF = DriveCommand.hold(0.0, DriveType.BRIDGE)   # immutable: one shared "off" command


class PulseModelRls:
    """Recursive least squares for Δc(w) = θ·[1, v, v², v³], v = w/1 ms, Δc in µrad.

    θ(k) = θ(k−1) + K·(Δc − φᵀθ(k−1)),  K = Pφ/(λ + φᵀPφ),  P ← (P − KφᵀP)/λ.
    """

    def __init__(self, forgetting: float = 0.995, prior_variance: float = 1e6) -> None:
        self.lam = forgetting
        self.theta = np.zeros(4)
        self.P = np.eye(4) * prior_variance
        self.n = 0

    @property
    def theta(self) -> np.ndarray:
        """θ [µrad] (a copy; assign to change it)."""
        return self._theta.copy()

    @theta.setter
    def theta(self, value: np.ndarray) -> None:
        self._theta = np.array(value, dtype=float)
        self._t = tuple(float(v) for v in self._theta)

    @staticmethod
    def features(width: float) -> np.ndarray:
        v = width / _MS
        return np.array([1.0, v, v * v, v * v * v])

    def update(self, width: float, delta_c: float) -> None:
        """Add one pulse: width [s], displacement [rad]."""
        phi = self.features(width)
        # compiled: the numpy operations of the class docstring, rounded as numpy does here
        self.P, self.theta = rls_update(np.ascontiguousarray(self.P, dtype=float), self._theta, phi,
                                        delta_c / _URAD, float(self.lam))
        self.n += 1

    def predict(self, width: float) -> float:
        """Model displacement [rad] of a pulse of ``width`` [s].

        ``float(features(width) @ θ) · 1e−6``, evaluated by a compiled kernel that rounds as
        numpy's dot does here (:mod:`controllers._fma`).
        """
        t0, t1, t2, t3 = self._t
        return cubic_predict(t0, t1, t2, t3, width, _MS, _URAD)

    def invert(self, target: float, lo: float, hi: float) -> float | None:
        """Width in [lo, hi] [s] whose model displacement is ``target`` [rad] on an increasing
        branch (60 bisections of :meth:`predict`, compiled), or None when the model does not
        bracket it."""
        t0, t1, t2, t3 = self._t
        w = cubic_invert(t0, t1, t2, t3, target, lo, hi, _MS, _URAD, 60)
        return None if w != w else w


@dataclass(frozen=True)
class PulseWidthOptions:
    """Options of :class:`PulseWidthController`.

    Attributes
    ----------
    target_step : float
        Δ, the displacement each correction aims for [rad], > 0.
    initial_width : float
        First pulse width [s] (a guess below breakaway is fine), > 0.
    width_growth : float
        Factor applied to the width after a pulse without significant motion [–], > 1.
    max_width : float
        Longest pulse [s]; its current must be back to zero within one sample (checked at reset).
    width_dither : float
        δ, relative width excitation [–], in [0, 0.5).
    forgetting : float
        RLS forgetting factor λ per pulse [–], in (0, 1].
    min_model_pulses : int
        Significant pulses before the RLS model is inverted [–], ≥ 4.
    overshoot_factor : float
        Correct an error drifting towards zero only beyond this × Δ [–], ≥ 1.
    slope_memory_s : float
        Time constant of the pooled slope's forgetting [s], > 0.
    startup_s : float
        No pulse before this time [s] (first slope estimate), ≥ 0.
    min_segment_samples : int
        Samples of the current stuck segment before a pulse [–], ≥ 2.
    max_width_change : float
        Largest relative width change from one pulse to the next [–], > 0.
    """

    target_step: float = 3e-6
    initial_width: float = 1.0e-3
    width_growth: float = 1.1
    max_width: float = 4e-3
    width_dither: float = 0.05
    forgetting: float = 0.995
    min_model_pulses: int = 8
    overshoot_factor: float = 1.5
    slope_memory_s: float = 100.0
    startup_s: float = 0.5
    min_segment_samples: int = 5
    max_width_change: float = 0.1

    def __post_init__(self) -> None:
        def number(name: str) -> float:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {v!r}")
            return float(v)

        for name in ("target_step", "initial_width", "max_width", "slope_memory_s"):
            if not number(name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not number("width_growth") > 1:
            raise ValueError(f"width_growth must be > 1, got {self.width_growth!r}")
        if not 0 <= number("width_dither") < 0.5:
            raise ValueError(f"width_dither must be in [0, 0.5), got {self.width_dither!r}")
        if not 0 < number("forgetting") <= 1:
            raise ValueError(f"forgetting must be in (0, 1], got {self.forgetting!r}")
        if not number("overshoot_factor") >= 1:
            raise ValueError(f"overshoot_factor must be >= 1, got {self.overshoot_factor!r}")
        if not number("max_width_change") > 0:
            raise ValueError(f"max_width_change must be > 0, got {self.max_width_change!r}")
        if not number("startup_s") >= 0:
            raise ValueError(f"startup_s must be >= 0, got {self.startup_s!r}")
        for name, least in (("min_model_pulses", 4), ("min_segment_samples", 2)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < least:
                raise ValueError(f"{name} must be an integer >= {least}, got {v!r}")
        if self.initial_width > self.max_width:
            raise ValueError(f"initial_width must be <= max_width ({self.max_width!r}), "
                             f"got {self.initial_width!r}")


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


@register("pulse-width")
class PulseWidthController(Controller):
    """Adaptive pulse-width control on the switched bridge (Yang & Tomizuka 1988).

    Options: :class:`PulseWidthOptions`. Knob: ``target_step`` [rad]. Counter: ``pulses``.
    """

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
