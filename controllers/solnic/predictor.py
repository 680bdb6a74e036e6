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

Choice left open by the text: the step of the partial differences. We use a forward step of
``fd_step`` [ozf·in] and fall back to a backward step where the forward one would leave the
valid parameter set (k̂c ≤ k̂s < u_max) or would cross the motion/no-motion discontinuity of Δc
(Δc drops abruptly from Δc_min to 0 as k̂s rises past the peak torque, section 5.3).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from plant.params import PlantParams

__all__ = ["PulsePrediction", "Predictor", "peak_torque"]

ResponseFn = Callable[..., Any]


def peak_torque(params: PlantParams, dt_u: float) -> float:
    """Largest motor torque of a pulse from rest, x3(Δt_u) = u_max·(1 − e^(−β3Δt_u)) [ozf·in].

    The shaft can only break away if k̂s is below this value (the constraint of section 5.3).
    """
    if dt_u <= 0:
        return 0.0
    return -params.u_max * math.expm1(-dt_u / params.motor_time_constant)


@dataclass(frozen=True)
class PulsePrediction:
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
        if response_fn is None:
            from plant import pulse_response as response_fn  # the plant's exact model
        self.params = params
        self.fd_step = float(fd_step)
        self._response = response_fn
        self._cache: OrderedDict[tuple[float, float, float], tuple[float, float | None, float, float]] = OrderedDict()
        self._cache_size = int(cache_size)
        self.n_model_runs = 0

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
                    raise ValueError(f"estimates outside 0 <= kc <= ks < u_max: ks={ks!r}, kc={kc!r}")
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
            raise ValueError(f"estimates outside 0 <= kc <= ks < u_max: ks={ks!r}, kc={kc!r}")
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
        if sign not in (1, -1):
            raise ValueError(f"sign must be +1 or -1, got {sign!r}")
        if not (dt_u >= 0 and math.isfinite(dt_u)):
            raise ValueError(f"dt_u must be a finite number >= 0, got {dt_u!r}")
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
            return hit
        pred = self.predict(ks, kc, dt_u, sign)
        if not pred.moves:
            ks_c = pred.peak_torque * (1.0 - shrink)
            if ks_c > 0:
                pred = self.predict(ks_c, min(kc, ks_c), dt_u, sign)
        if len(memo) > 256:
            memo.clear()
        memo[key] = pred
        return pred

    def predicted_motion(self, ks: float, kc: float, dt_u: float) -> float:
        """|Δc_p| only (no partials), for cost curves."""
        if dt_u <= 0:
            return 0.0
        return abs(self.response(ks, kc, dt_u, self.brake_off(ks, kc, dt_u))[0])
