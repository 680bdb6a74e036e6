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
from numba import njit

from controllers._fma import cubic_invert, cubic_predict, rls_update
from controllers.base import Controller, register
from controllers.law import CompiledLaw, law_command
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


# ---------------------------------------------------------------------------- the compiled step
# The controller's whole state is the float64 array s (counts are whole floats), its constants p.
# A stuck segment is a block of _SEG entries: its running sums (n, Σt, Σy, Σt², Σty), its prior
# (flag, t, x̂1(t), variance) and the sums of its "clean" samples (taken before any trigger
# decision: n, Σt, Σy, Σt², Σty).
_SN, _SST, _SSY, _SSTT, _SSTY, _SHP, _SPT, _SPL, _SPV, _SCN, _SCST, _SCSY, _SCSTT, _SCSTY = range(14)
_SEG = 14
(_N, _SXX, _SXY, _HAS_PREV, _HAS_PULSE, _P_T, _P_SIGN, _P_WIDTH, _P_PRED, _VAR_PRED, _DPHASE, _PULSES, _SIGNIFICANT,
 _NO_MOTION, _INVERSIONS, _LAST_DC, _X1, _X4, _WIDTH, _FLOOR, _HAS_LAST, _L_W, _L_DC, _MODEL_N) = range(24)
_THETA = 24                  # θ (4), then P (4 × 4, row-major)
_PMAT = _THETA + 4
_CUR = _PMAT + 16            # the current segment, then the one before the last pulse
_PREV = _CUR + _SEG
_N_STATE = _PREV + _SEG
(_O_STEP, _O_W0, _O_GROWTH, _O_WMAX, _O_DITHER, _O_LAMBDA, _O_MIN_MODEL, _O_OVERSHOOT, _O_STARTUP, _O_MIN_SEG,
 _O_CHANGE, _O_TS, _O_SIGMA2, _O_FORGET, _O_UMAX, _O_VAR_FLOOR, _O_TWO) = range(17)
_N_PARAMS = 17


@njit(cache=True)
def _py_max(a, b):
    # Python's max(a, b): a unless b > a
    return b if b > a else a


@njit(cache=True)
def _py_min(a, b):
    # Python's min(a, b): a unless b < a
    return b if b < a else a


@njit(cache=True)
def _centred(s, c, two):
    """(Σ(t − t̄)², Σ(t − t̄)(y − ȳ)) of the sums (n, Σt, Σy, Σt², Σty) at s[c:c+5] ((0, 0) below two
    samples). ``two`` = 2.0 arrives at run time so that (Σt)² is libm's pow(Σt, 2.0), as Python's
    ``**`` computes it (a constant 2 would become Σt·Σt, which glibc's pow does not always equal)."""
    n = s[c]
    if n < 2.0:
        return 0.0, 0.0
    return s[c + 3] - math.pow(s[c + 1], two) / n, s[c + 4] - s[c + 1] * s[c + 2] / n


@njit(cache=True)
def _level(s, g, t, slope, sigma2):
    """x̂1(t) [rad] and its variance from segment g's samples and its prior."""
    mean, var = math.nan, math.inf
    n = s[g + _SN]
    if n > 0.0:                      # ȳ + slope·(t − t̄), σ1²/n
        mean, var = s[g + _SSY] / n + slope * (t - s[g + _SST] / n), sigma2 / n
    if s[g + _SHP] != 0.0:
        var0 = s[g + _SPV]
        prior = s[g + _SPL] + slope * (t - s[g + _SPT])
        if not math.isfinite(mean):
            return prior, var0
        w = var0 / (var0 + var)      # precision-weighted combination
        return prior + w * (mean - prior), var0 * var / (var0 + var)
    return mean, var


@njit(cache=True)
def _predict(s, width):
    return cubic_predict(s[_THETA], s[_THETA + 1], s[_THETA + 2], s[_THETA + 3], width, _MS, _URAD)


@njit(cache=True)
def _close_segment(s, p, slope):
    """Pool the finished segment's slope sums and evaluate the previous pulse from the samples
    alone (the prior is not used twice); the current segment becomes the previous one."""
    sxx, sxy = _centred(s, _CUR + _SCN, p[_O_TWO])
    s[_SXX] += sxx
    s[_SXY] += sxy
    a, b = _CUR, _PREV
    if s[_HAS_PULSE] != 0.0 and s[_HAS_PREV] != 0.0 and s[b + _SN] > 0.0 and s[a + _SN] > 0.0:
        sign, width, predicted = s[_P_SIGN], s[_P_WIDTH], s[_P_PRED]
        na, nb = s[a + _SN], s[b + _SN]
        dc = sign * (s[a + _SSY] / na - s[b + _SSY] / nb - slope * (s[a + _SST] / na - s[b + _SST] / nb))
        var_e = p[_O_SIGMA2] * (1.0 / na + 1.0 / nb)
        s[_LAST_DC] = dc
        if s[_SIGNIFICANT] == 0.0 and dc < 2.0 * math.sqrt(var_e):
            s[_NO_MOTION] += 1.0                     # start-up: no motion yet, widen
            s[_FLOOR] = _py_max(s[_FLOOR], width)
        else:
            s[_SIGNIFICANT] += 1.0
            v = width / _MS                          # PulseModelRls.update
            phi = np.array([1.0, v, v * v, v * v * v])
            P = s[_PMAT:_PMAT + 16].copy().reshape((4, 4))
            P2, theta = rls_update(P, s[_THETA:_THETA + 4].copy(), phi, dc / _URAD, p[_O_LAMBDA])
            for i in range(4):
                s[_THETA + i] = theta[i]
                for j in range(4):
                    s[_PMAT + 4 * i + j] = P2[i, j]
            s[_MODEL_N] += 1.0
            s[_HAS_LAST], s[_L_W], s[_L_DC] = 1.0, width, dc
            if s[_INVERSIONS] != 0.0:                # spread of Δc about the model
                resid = math.pow(dc - predicted, p[_O_TWO]) - var_e
                s[_VAR_PRED] += 0.05 * (_py_max(resid, 0.0) - s[_VAR_PRED])
                s[_VAR_PRED] = _py_max(s[_VAR_PRED], p[_O_VAR_FLOOR])
    for i in range(_SEG):
        s[_PREV + i] = s[_CUR + i]
        s[_CUR + i] = 0.0
    s[_HAS_PREV] = 1.0


@njit(cache=True)
def _next_width(s, p):
    """The next pulse's width [s]: the inverted model, or the start-up rule; dithered."""
    step, change, w_max = p[_O_STEP], p[_O_CHANGE], p[_O_WMAX]
    lo_limit = 0.2 * p[_O_W0]
    width = s[_WIDTH]
    if s[_SIGNIFICANT] >= p[_O_MIN_MODEL]:
        # one pulse changes the width by at most ``max_width_change`` (model glitches)
        w = cubic_invert(s[_THETA], s[_THETA + 1], s[_THETA + 2], s[_THETA + 3], step,
                         _py_max(lo_limit, width / (1 + change)), _py_min(w_max, width * (1 + change)), _MS, _URAD, 60)
        if w == w:
            s[_INVERSIONS] += 1.0
            width = w
        else:   # the target is outside the bracket: move to its edge towards the target
            width *= (1 + change) if _predict(s, width) < step else 1 / (1 + change)
    elif s[_HAS_LAST] == 0.0:          # before the model: grow after no motion, else w ← w·√(Δ/Δc)
        if width <= s[_FLOOR]:
            width = s[_FLOOR] * p[_O_GROWTH]
    elif s[_L_DC] > 0:
        width = s[_L_W] * _py_min(_py_max(math.sqrt(step / s[_L_DC]), 0.9), 1.1)
    width = _py_min(_py_max(width, lo_limit), w_max)
    s[_WIDTH] = width
    s[_DPHASE] = (s[_DPHASE] + 1.0) % 3.0
    return _py_min(width * (1.0 + p[_O_DITHER] * (s[_DPHASE] - 1.0)), w_max)


@njit(cache=True)
def _pulse_width_step(s, p, y, offs, levs):
    """:class:`PulseWidthController`'s step (:data:`plant.law_step.STEP_SIGNATURE`): add y(n) to
    the stuck segment; the hold of 0, or a ±u_max pulse of the next width from the sample instant."""
    t = s[_N] * p[_O_TS]
    s[_N] += 1.0
    s[_SXX] *= p[_O_FORGET]
    s[_SXY] *= p[_O_FORGET]
    g = _CUR
    early = t < p[_O_STARTUP]
    offs[0], levs[0] = 0.0, 0.0
    if math.isfinite(y):   # samples before the first trigger decision enter the slope
        if s[g + _SN] < p[_O_MIN_SEG] or early:
            s[g + _SCN] += 1.0
            s[g + _SCST] += t
            s[g + _SCSY] += y
            s[g + _SCSTT] += t * t
            s[g + _SCSTY] += t * y
        s[g + _SN] += 1.0
        s[g + _SST] += t
        s[g + _SSY] += y
        s[g + _SSTT] += t * t
        s[g + _SSTY] += t * y
    if s[g + _SN] == 0.0:
        return 1
    sxx, sxy = _centred(s, g + _SCN, p[_O_TWO])
    den = s[_SXX] + sxx
    slope = (s[_SXY] + sxy) / den if den > 0 else 0.0
    sigma2 = p[_O_SIGMA2]
    s[_X4] = -slope
    s[_X1] = _level(s, g, t, slope, sigma2)[0]
    if early or s[g + _SN] < p[_O_MIN_SEG]:
        return 1
    ts = p[_O_TS]
    pe, var_p = _level(s, g, t + ts, slope, sigma2)
    step = p[_O_STEP]
    away = pe * slope > 0 or slope == 0.0
    due = abs(pe) >= 0.5 * step and away
    overshoot = abs(pe) >= p[_O_OVERSHOOT] * step and abs(pe) >= 3.0 * math.sqrt(var_p)
    if not (due or overshoot):
        return 1
    sign = -1.0 if pe > 0 else 1.0
    _close_segment(s, p, slope)
    width = _next_width(s, p)
    level_now, var_now = _level(s, _PREV, t, slope, sigma2)
    predicted = _predict(s, width) if s[_INVERSIONS] != 0.0 else step
    s[_CUR + _SHP], s[_CUR + _SPT] = 1.0, t
    s[_CUR + _SPL], s[_CUR + _SPV] = level_now + sign * predicted, var_now + s[_VAR_PRED]
    s[_HAS_PULSE], s[_P_T], s[_P_SIGN], s[_P_WIDTH], s[_P_PRED] = 1.0, t, sign, width, predicted
    s[_PULSES] += 1.0
    levs[0] = sign * p[_O_UMAX]            # DriveCommand.pulse(0, width, ±u_max)
    offs[1], levs[1] = width, 0.0
    return 2


@register("pulse-width")
class PulseWidthController(Controller):
    """Adaptive pulse-width control on the switched bridge (Yang & Tomizuka 1988).

    Options: :class:`PulseWidthOptions`. Knob: ``target_step`` [rad]. Counter: ``pulses``.

    The whole step is :func:`_pulse_width_step`, one compiled function over the state array
    ``s`` (the ``compiled_law`` hook): ``step`` calls it, and so does the runner's compiled loop,
    in the same order of floating-point operations as the Python form it replaces (whose rows
    tests/test_pulse_width_compiled.py compares bit for bit).
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
        sigma = max(params.measurement_noise_std, 1e-12)
        p = np.empty(_N_PARAMS)
        p[_O_STEP], p[_O_W0], p[_O_GROWTH], p[_O_WMAX] = o.target_step, o.initial_width, o.width_growth, o.max_width
        p[_O_DITHER], p[_O_LAMBDA], p[_O_MIN_MODEL] = o.width_dither, o.forgetting, o.min_model_pulses
        p[_O_OVERSHOOT], p[_O_STARTUP], p[_O_MIN_SEG] = o.overshoot_factor, o.startup_s, o.min_segment_samples
        p[_O_CHANGE], p[_O_TS], p[_O_SIGMA2] = o.max_width_change, ts, sigma ** 2
        p[_O_FORGET], p[_O_UMAX] = math.exp(-ts / o.slope_memory_s), params.u_max
        p[_O_VAR_FLOOR], p[_O_TWO] = (0.05 * o.target_step) ** 2, 2.0
        s = np.zeros(_N_STATE)
        s[_VAR_PRED] = o.target_step ** 2            # spread of Δc about the model [rad²]
        s[_WIDTH] = o.initial_width
        s[_LAST_DC] = math.nan
        s[_PMAT:_PMAT + 16] = (np.eye(4) * 1e6).ravel()   # PulseModelRls's prior
        self._s, self._p = s, p
        self._offs, self._levs = np.zeros(2), np.zeros(2)
        self._pulse_times: list[float] = []

    def step(self, y: float) -> DriveCommand:
        """Add y(n) to the stuck segment; fire a ±u_max pulse when the error is due
        (:func:`_pulse_width_step`)."""
        k = _pulse_width_step(self._s, self._p, y, self._offs, self._levs)
        if k == 1:
            return _OFF
        self._pulse_times.append(self._s[_P_T])
        return law_command(k, self._offs, self._levs, DriveType.BRIDGE)

    def compiled_law(self) -> CompiledLaw | None:
        """The compiled step on this controller's own arrays (None before ``reset``)."""
        if not hasattr(self, "_s"):
            return None
        return CompiledLaw(_pulse_width_step, self._s, self._p, DriveType.BRIDGE, 2)

    # the state, read from the array
    width = property(lambda self: float(self._s[_WIDTH]), doc="The width before dither [s].")
    width_floor = property(lambda self: float(self._s[_FLOOR]), doc="Widest pulse without motion [s].")
    x1_hat = property(lambda self: float(self._s[_X1]), doc="x̂1 at the last sample [rad].")
    x4_hat = property(lambda self: float(self._s[_X4]), doc="x̂4 [rad/s].")
    last_dc = property(lambda self: float(self._s[_LAST_DC]), doc="The last measured Δc [rad].")

    @property
    def counts(self) -> dict[str, int]:
        """pulses, significant, no_motion, model_inversions."""
        s = self._s
        return dict(pulses=int(s[_PULSES]), significant=int(s[_SIGNIFICANT]), no_motion=int(s[_NO_MOTION]),
                    model_inversions=int(s[_INVERSIONS]))

    @property
    def model(self) -> PulseModelRls:
        """The identified Δc(w) model (a copy of the state's θ and P)."""
        m = PulseModelRls(self.options.forgetting)
        m.theta = self._s[_THETA:_THETA + 4]
        m.P = self._s[_PMAT:_PMAT + 16].reshape((4, 4)).copy()
        m.n = int(self._s[_MODEL_N])
        return m

    # ------------------------------------------------------------------ reporting
    def internals(self) -> dict[str, float]:
        return {"x1_hat": self.x1_hat, "x4_hat": self.x4_hat, "width": self.width,
                "dc_measured": self.last_dc}

    def event_times(self) -> dict[str, np.ndarray]:
        return {"pulse": np.asarray(getattr(self, "_pulse_times", []), dtype=float)}

    def summary(self) -> dict[str, Any]:
        if not hasattr(self, "_s"):
            return {"target_step": self.options.target_step}
        out: dict[str, Any] = {"target_step": self.options.target_step, "width": self.width,
                               "width_floor": self.width_floor, "x4_hat": self.x4_hat,
                               "model_dc_at_width": self.model.predict(self.width)}
        out.update(self.counts)
        return out
