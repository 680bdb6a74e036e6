"""The controller's internal plant model: pulse predictions and their quasipartials.

The solnic controller predicts the outcome of one corrective pulse by running its own plant
model "faster than real time" (section 5.2, modification 1). The model is the plant's own
noise-free pulse response, :func:`plant.pulse_response`, evaluated with the *estimated*
friction ``params.replace(stiction=k̂s, coulomb=k̂c)``. It starts from rest (x3 = x4 = x5 = 0),
applies ±u_max for Δt_u on the switched bridge, then flyback, then 0.

Returned per pulse:

* Δc_p, the predicted shaft motion [rad], and t_nominal = t_stop [s];
* the quasipartials (first-order partial differences, modification 2) of Δc_p and t_nominal
  with respect to k̂c and k̂s, at constant Δt_u: H_b (5-2) and H_tb (5-12). Both are ordered
  (k̂c, k̂s), the order of the state of the friction filter and of P_b (5-5).

The plant's shaft error is x1 = c − r, so the real x1 also drifts by −x4·t during a pulse; the
pulse response (and so Δc_p) is the shaft motion Δc only.

Compiled: with the plant's own model (no ``response_fn`` injected) one numba call
(:func:`_predict_kernel`) does the brake timing, the base response and both partial
differences; the Python path below is the same arithmetic step by step, kept for injected
models, and the two agree to the bit (``tests/test_solnic_predictor.py``). The controller asks
for a prediction at every sample with that sample's k̂ (the joint filter moves k̂ at every
sample), so a cache rarely hits and the per-call cost is what counts.

Choice left open by the text: the step of the partial differences. We use a forward step of
``fd_step`` [ozf·in] and fall back to a backward step where the forward one would leave the
valid parameter set (k̂c ≤ k̂s < u_max) or would cross the motion/no-motion discontinuity of Δc
(Δc drops abruptly from Δc_min to 0 as k̂s rises past the peak torque, section 5.3).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from typing import Any, Callable, NamedTuple

import numpy as np
from numba import njit

from controllers.base import ControllerDiverged, EstimateOutOfRange
from controllers.solnic.braking import _pair, _timing
from plant.params import PlantParams
from controllers.models.acker import closed_form_kernel

__all__ = ["PulsePrediction", "Predictor", "peak_torque"]

ResponseFn = Callable[..., Any]
LAZY = object()     # a conditional() memo entry made by a compiled sample: computed when first read


def peak_torque(params: PlantParams, dt_u: float) -> float:
    """Largest motor torque of a pulse from rest, x3(Δt_u) = u_max·(1 − e^(−β3Δt_u)) [ozf·in].

    The shaft can only break away if k̂s is below this value (the constraint of section 5.3).
    """
    if dt_u <= 0:
        return 0.0
    return -params.u_max * math.expm1(-dt_u / params.motor_time_constant)


class PulsePrediction(NamedTuple):
    """Prediction of one pulse of ``sign``·u_max for ``dt_u`` with estimates (k̂c, k̂s).

    Attributes
    ----------
    dt_u : float
        On-time Δt_u [s].
    sign : int
        +1 or −1, the direction of the drive.
    delta_c : float
        Δc_p, signed predicted shaft motion [rad]; 0 when the model predicts no breakaway.
    t_nominal : float
        Predicted time from pulse start until the shaft is stuck again (t_stop) [s].
    t_breakaway : float or None
        Predicted breakaway time [s].
    t_current_zero : float
        Time at which the flyback has brought the motor current back to 0 [s].
    H_b : numpy.ndarray
        (∂Δc_p/∂k̂c, ∂Δc_p/∂k̂s) [rad per ozf·in], signed like ``delta_c`` (5-2).
    H_tb : numpy.ndarray
        (∂t_nominal/∂k̂c, ∂t_nominal/∂k̂s) [s per ozf·in] (5-12).
    peak_torque : float
        x3 at switch-off [ozf·in], the largest torque the pulse applies.
    t_off : float or None
        With a braking pulse (:mod:`controllers.solnic.braking`): the end of the reverse drive
        [s from the pulse start]; ``t_current_zero`` is then the pair's t_cz2. None: single.
    """

    dt_u: float
    sign: int
    delta_c: float
    t_nominal: float
    t_breakaway: float | None
    t_current_zero: float
    H_b: np.ndarray
    H_tb: np.ndarray
    peak_torque: float
    t_off: float | None = None

    @property
    def moves(self) -> bool:
        """True when the model predicts a breakaway."""
        return self.t_breakaway is not None and self.delta_c != 0.0

# -- the compiled path ------------------------------------------------------------------------
_OK, _INVALID, _COASTS = 0, 1, 2


@njit(cache=True)
def _valid(ks, kc, U):
    return 0.0 <= kc and kc <= ks and ks < U


@njit(cache=True)
def _response_kernel(ks, kc, dt_u, t_off, U, t3, a):
    """(Δc, t_b or −1, t_current_zero, t_stop, code) of a +u_max pulse, noise-free; ``t_off``
    < 0 is the single pulse (:func:`plant.pulse_response`), else the braking pair
    (:func:`controllers.solnic.braking.braked_response`). code 2: the shaft coasts for ever."""
    if t_off >= 0.0:
        dc, tb, tcz, ts, _, _ = _pair(dt_u, t_off, U, t3, a, ks, kc)
        return dc, tb, tcz, (ts if tb >= 0.0 else 0.0), _OK
    if dt_u == 0.0:
        return 0.0, -1.0, 0.0, 0.0, _OK
    dc, tb, tcz, ts = closed_form_kernel(dt_u, U, t3, a, ks, kc)
    if tb < 0.0:
        return 0.0, -1.0, tcz, 0.0, _OK
    if ts == math.inf:
        return dc, tb, tcz, ts, _COASTS
    return dc, tb, tcz, ts, _OK


@njit(cache=True)
def _partial_kernel(ks, kc, dt_u, t_off, which, b_dc, b_tb, b_ts, h, U, t3, a):
    """(∂Δc, ∂t_stop, model runs, code) by a forward, else backward, step (Predictor._partial)."""
    runs = 0
    for i in range(2):
        step = h if i == 0 else -h
        kcp, ksp = kc, ks
        if which == 0:
            kcp = kc + step
        else:
            ksp = ks + step
        if not _valid(ksp, kcp, U):
            continue
        dc, tb, _, ts, code = _response_kernel(ksp, kcp, dt_u, t_off, U, t3, a)
        runs += 1
        if code != _OK:
            return 0.0, 0.0, runs, code
        if (tb >= 0.0) != (b_tb >= 0.0):
            continue
        return (dc - b_dc) / step, (ts - b_ts) / step, runs, _OK
    return 0.0, 0.0, runs, _OK


@njit(cache=True)
def _predict_kernel(ks, kc, dt_u, U, t3, a, h, brake, margin, s2, cap, min_ratio):
    """One prediction (Predictor.predict, sign +1): (code, runs, Δc, t_b, t_cz, t_stop,
    ∂Δc/∂kc, ∂Δc/∂ks, ∂t/∂kc, ∂t/∂ks, t_off or −1)."""
    nan = math.nan
    ok = _valid(ks, kc, U)
    t_off = -1.0
    if brake and ok:
        t_off = _timing(dt_u, U, t3, a, ks, kc, s2, margin, cap, min_ratio)
    if not ok:
        return _INVALID, 0, nan, nan, nan, nan, nan, nan, nan, nan, t_off
    dc, tb, tcz, ts, code = _response_kernel(ks, kc, dt_u, t_off, U, t3, a)
    runs = 1
    if code != _OK:
        return code, runs, nan, nan, nan, nan, nan, nan, nan, nan, t_off
    d0, t0, n, code = _partial_kernel(ks, kc, dt_u, t_off, 0, dc, tb, ts, h, U, t3, a)
    runs += n
    if code != _OK:
        return code, runs, nan, nan, nan, nan, nan, nan, nan, nan, t_off
    d1, t1, n, code = _partial_kernel(ks, kc, dt_u, t_off, 1, dc, tb, ts, h, U, t3, a)
    runs += n
    return code, runs, dc, tb, tcz, ts, d0, d1, t0, t1, t_off


@njit(cache=True)
def _conditional_kernel(ks, kc, dt_u, U, t3, a, h, brake, margin, s2, cap, min_ratio, shrink):
    """Predictor.conditional (sign +1): the prediction, or the one with k̂s just below the peak
    torque when it predicts no motion; also returns the (k̂s, k̂c) used and the runs of both."""
    r = _predict_kernel(ks, kc, dt_u, U, t3, a, h, brake, margin, s2, cap, min_ratio)
    if r[0] == _OK and not (r[3] >= 0.0 and r[2] != 0.0):
        peak = -U * math.expm1(-dt_u / t3) if dt_u > 0 else 0.0
        ks_c = peak * (1.0 - shrink)
        if ks_c > 0:
            kc_c = min(kc, ks_c)
            r2 = _predict_kernel(ks_c, kc_c, dt_u, U, t3, a, h, brake, margin, s2, cap, min_ratio)
            return r2, ks_c, kc_c, r[1]
    return r, ks, kc, 0


def _check(sign: int, dt_u: float) -> None:
    """The arguments every prediction checks (ValueError naming the argument)."""
    if sign not in (1, -1):
        raise ValueError(f"sign must be +1 or -1, got {sign!r}")
    if not (dt_u >= 0 and math.isfinite(dt_u)):
        raise ValueError(f"dt_u must be a finite number >= 0, got {dt_u!r}")


class Predictor:
    """Pulse predictions from the estimated plant, with per-(k̂s, k̂c, Δt_u) caching.

    Parameters
    ----------
    params : PlantParams
        The nominal plant; only its friction fields are replaced by the estimates.
    fd_step : float
        Step of the partial differences [ozf·in].
    response_fn : callable, optional
        ``response_fn(params, dt_u, *, sign=1, seed=None)`` with the interface of
        :func:`plant.pulse_response` (the default). Injected for unit tests.
    cache_size : int
        Number of noise-free pulse responses kept.
    brake_margin : float or None
        Braking pulses (:mod:`controllers.solnic.braking`) with this margin r_b; None (the
        default) predicts single pulses; ``brake_min_ratio`` as in
        :func:`controllers.solnic.braking.brake_timing`. The reverse drive is timed from the estimates and
        held fixed in the quasipartials (the plant's friction differs, the command does not).
    """

    def __init__(self, params: PlantParams, *, fd_step: float = 1e-4,
                 response_fn: ResponseFn | None = None, cache_size: int = 8192,
                 brake_margin: float | None = None, brake_min_ratio: float = 0.0) -> None:
        self.brake_margin = brake_margin
        self.brake_min_ratio = float(brake_min_ratio)
        if not (fd_step > 0 and math.isfinite(fd_step)):
            raise ValueError(f"fd_step must be a finite positive number, got {fd_step!r}")
        self._compiled = response_fn is None       # the plant's own model: the compiled path
        if response_fn is None:
            from controllers.models.acker import pulse_response as response_fn  # the model it assumes
        self.params = params
        self.fd_step = float(fd_step)
        self._response = response_fn
        self._cache: OrderedDict[tuple[float, float, float], tuple[float, float | None, float, float]] = OrderedDict()
        self._cache_size = int(cache_size)
        self.n_model_runs = 0
        self.memo_clears = 0                        # times conditional()'s memo was cleared
        self._constants = (float(params.u_max), float(params.motor_time_constant), float(params.alpha),
                           self.fd_step)
        # brake_timing's defaults: s² = α²σ2² and t_cz2 capped at 0.8 τs
        self._brake_constants = (params.alpha**2 * params.sigma2_sq, 0.8 * params.sample_period,
                                 self.brake_min_ratio)

    # -- the noise-free model ------------------------------------------------------------
    def valid(self, ks: float, kc: float) -> bool:
        """Whether (k̂s, k̂c) make a valid plant: 0 ≤ k̂c ≤ k̂s < u_max."""
        return 0.0 <= kc <= ks < self.params.u_max

    def brake_off(self, ks: float, kc: float, dt_u: float) -> float | None:
        """t_off of the braking pulse for (k̂s, k̂c, Δt_u), or None (no brake, or braking off)."""
        if self.brake_margin is None or not self.valid(ks, kc):
            return None
        from controllers.solnic.braking import brake_timing
        return brake_timing(self.params.with_friction(ks, kc), dt_u, self.brake_margin,
                            min_ratio=self.brake_min_ratio)

    def response(self, ks: float, kc: float, dt_u: float,
                 t_off: float | None = None) -> tuple[float, float | None, float, float]:
        """(Δc, t_breakaway, t_current_zero, t_stop) of a +u_max pulse, noise-free, cached;
        with ``t_off`` the braking pair (:func:`controllers.solnic.braking.braked_response`)."""
        if t_off is not None:
            key = (float(ks), float(kc), float(dt_u), float(t_off))
            hit = self._cache.get(key)
            if hit is None:
                if not self.valid(ks, kc):
                    raise EstimateOutOfRange(f"estimates outside 0 <= kc <= ks < u_max: ks={ks!r}, kc={kc!r}")
                from controllers.solnic.braking import braked_response
                hit = braked_response(self.params.with_friction(ks, kc), dt_u, t_off)
                self.n_model_runs += 1
                self._cache[key] = hit
                if len(self._cache) > self._cache_size:
                    self._cache.popitem(last=False)
            return hit
        key = (float(ks), float(kc), float(dt_u))
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        if not self.valid(ks, kc):
            raise EstimateOutOfRange(f"estimates outside 0 <= kc <= ks < u_max: ks={ks!r}, kc={kc!r}")
        est = self.params.with_friction(ks, kc)
        r = self._response(est, float(dt_u), sign=1, seed=None)
        self.n_model_runs += 1
        out = (float(r.delta_c), None if r.t_breakaway is None else float(r.t_breakaway),
               float(r.t_current_zero), float(r.t_stop))
        self._cache[key] = out
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return out

    # -- prediction with quasipartials ---------------------------------------------------
    def _partial(self, ks: float, kc: float, dt_u: float, which: int,
                 base: tuple[float, float | None, float, float],
                 t_off: float | None = None) -> tuple[float, float]:
        """Partial differences of (Δc, t_stop) w.r.t. k̂c (which=0) or k̂s (which=1)."""
        moved = base[1] is not None
        h = self.fd_step
        for step in (h, -h):                     # forward first, as in the text; then backward
            k = [kc, ks]
            k[which] += step
            if not self.valid(k[1], k[0]):
                continue
            pert = self.response(k[1], k[0], dt_u, t_off)
            if (pert[1] is not None) != moved:   # crossed the Δc_min → 0 discontinuity
                continue
            return (pert[0] - base[0]) / step, (pert[3] - base[3]) / step
        return 0.0, 0.0

    def predict(self, ks: float, kc: float, dt_u: float, sign: int = 1) -> PulsePrediction:
        """Δc_p, t_nominal and the quasipartials H_b (5-2), H_tb (5-12) for one pulse."""
        _check(sign, dt_u)
        if self._compiled:
            r = _predict_kernel(float(ks), float(kc), float(dt_u), *self._constants, *self._brake_args())
            return self._prediction(r, ks, kc, dt_u, sign)
        return self._predict_python(ks, kc, dt_u, sign)

    def _brake_args(self) -> tuple[bool, float, float, float, float]:
        margin = self.brake_margin
        return (margin is not None, 0.0 if margin is None else float(margin), *self._brake_constants)

    def _prediction(self, r: tuple, ks: float, kc: float, dt_u: float, sign: int) -> PulsePrediction:
        """A :class:`PulsePrediction` from a :func:`_predict_kernel` result, or its error."""
        code, runs, dc, tb, tcz, ts, d0, d1, t0, t1, t_off = r
        self.n_model_runs += runs
        if code == _INVALID:
            raise EstimateOutOfRange(f"estimates outside 0 <= kc <= ks < u_max: ks={ks!r}, kc={kc!r}")
        if code == _COASTS:
            raise ControllerDiverged("the pulse model coasts for ever after the pulse: k̄c = 0")
        return PulsePrediction(float(dt_u), sign, sign * dc, ts, None if tb < 0.0 else tb, tcz,
                               np.array((sign * d0, sign * d1)), np.array((t0, t1)),
                               peak_torque(self.params, dt_u), None if t_off < 0.0 else t_off)

    def _predict_python(self, ks: float, kc: float, dt_u: float, sign: int) -> PulsePrediction:
        """:meth:`predict` step by step through :meth:`response` (the injected model)."""
        t_off = self.brake_off(ks, kc, dt_u)
        base = self.response(ks, kc, dt_u, t_off)
        dc_kc, t_kc = self._partial(ks, kc, dt_u, 0, base, t_off)
        dc_ks, t_ks = self._partial(ks, kc, dt_u, 1, base, t_off)
        return PulsePrediction(
            dt_u=float(dt_u), sign=sign, delta_c=sign * base[0], t_nominal=base[3],
            t_breakaway=base[1], t_current_zero=base[2],
            H_b=sign * np.array([dc_kc, dc_ks]), H_tb=np.array([t_kc, t_ks]),
            peak_torque=peak_torque(self.params, dt_u), t_off=t_off)

    def conditional(self, ks: float, kc: float, dt_u: float, sign: int = 1,
                    shrink: float = 1e-6) -> PulsePrediction:
        """Δc_p,cond (5-6): the prediction given that the shaft does move.

        When the model with k̂s predicts a breakaway this is :meth:`predict`. Otherwise the
        motion, if any, happens with a stiction just below the peak torque, so we predict
        with k̂s' = peak·(1 − shrink) (and k̂c' = min(k̂c, k̂s')): Δc_min of that Δt_u.
        """
        key = (float(ks), float(kc), float(dt_u), sign, shrink, self.brake_margin)
        memo = self.__dict__.setdefault("_conditional_memo", {})
        hit = memo.get(key)
        if hit is not None:
            if hit is LAZY:                   # memoised by a compiled sample: its value, uncounted
                hit = memo[key] = self._uncounted(ks, kc, dt_u, sign, shrink)
            return hit
        if self._compiled:
            _check(sign, dt_u)
            r, ks_u, kc_u, runs = _conditional_kernel(float(ks), float(kc), float(dt_u), *self._constants,
                                                      *self._brake_args(), float(shrink))
            self.n_model_runs += runs
            pred = self._prediction(r, ks if ks_u == ks else ks_u, kc if kc_u == kc else kc_u, dt_u, sign)
        else:
            pred = self.predict(ks, kc, dt_u, sign)
            if not pred.moves:
                ks_c = pred.peak_torque * (1.0 - shrink)
                if ks_c > 0:
                    pred = self.predict(ks_c, min(kc, ks_c), dt_u, sign)
        if len(memo) > 256:
            memo.clear()
            self.memo_clears += 1
        memo[key] = pred
        return pred

    def _uncounted(self, ks: float, kc: float, dt_u: float, sign: int, shrink: float) -> PulsePrediction:
        """The compiled path of :meth:`conditional`, without touching the model-run count."""
        runs = self.n_model_runs
        try:
            r, ks_u, kc_u, _ = _conditional_kernel(float(ks), float(kc), float(dt_u), *self._constants,
                                                   *self._brake_args(), float(shrink))
            return self._prediction(r, ks if ks_u == ks else ks_u, kc if kc_u == kc else kc_u, dt_u, sign)
        finally:
            self.n_model_runs = runs

    def conditional_peek(self, ks: float, kc: float, dt_u: float) -> PulsePrediction | None:
        """:meth:`conditional` (sign +1, default shrink) without its side effects on the memo
        and the model-run count; None where it would raise (or with an injected model)."""
        key = (float(ks), float(kc), float(dt_u), 1, 1e-6, self.brake_margin)
        hit = self.__dict__.get("_conditional_memo", {}).get(key)
        if (hit is not None and hit is not LAZY) or not self._compiled or not (dt_u >= 0 and math.isfinite(dt_u)):
            return hit
        try:
            return self._uncounted(ks, kc, dt_u, 1, 1e-6)
        except (EstimateOutOfRange, ControllerDiverged):
            return None

    def predicted_motion(self, ks: float, kc: float, dt_u: float) -> float:
        """|Δc_p| only (no partials), for cost curves."""
        if dt_u <= 0:
            return 0.0
        return abs(self.response(ks, kc, dt_u, self.brake_off(ks, kc, dt_u))[0])
