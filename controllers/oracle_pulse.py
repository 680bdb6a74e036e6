"""``oracle-pulse``: a BOUND, not a real controller — the floor of pulse control.

It reads what no real controller can: the true plant state and the true plant through the
privileged :meth:`~controllers.base.Controller.observe_truth` hook (the runner calls it only for
classes with ``privileged = True``), and the true pulse law — the true family's own noise-free
response to a pulse from the present state (``PlantFamily.pulse_motion``: on Acker's plant the
closed form with the true effective friction kc = k̄c + x5, ks = k̄s + x5, section 5.3; on any
other family its own law). It pulses on the same switched bridge (±u_max for Δt_u, then
flyback) as solnic.

Policy (band ``b`` [rad], the knob). While the shaft is stuck the error drifts as
ẋ1 = −x4. The oracle lets x1 drift across the whole band [−b, +b] and, at the exact instant
(inside the sample interval) the drift reaches the trailing edge −sign(x4)·b, fires the pulse
whose *noise-free* motion lands the shaft at ``landing_fraction``·b on the leading side, counting
the drift during the pulse (x1 after = x1 + Δc − x4·t_stop). With an exact pulse law this is
optimal for pulse control: the peak error is b and the time between pulses 2b/|x4| is the
longest any policy with peak b can have, so the current per second is the least. A noisy pulse
that lands beyond the leading edge is left to drift back (the peak has happened; a return pulse
could only risk a larger one); one short of the trailing edge is corrected at once. The friction noise w2 still
acts on every pulse, which is what makes this a floor *under each noise level*: nothing that
pulses can do better with less knowledge.

Speed (issue 27). The samples that only wait (the shaft moving, current on, or the drift not
yet at the trailing edge within this interval) are :func:`_oracle_step`, a compiled step that
reads the true state the compiled loop appends to its parameters (``CompiledLaw.truth``, which
the runner grants only to ``privileged`` classes). A sample that may fire runs
:meth:`OraclePulse.step` (after ``observe_truth`` with the true state from the loop), which does
the on-time search, from inside the loop through numba's ``objmode``
(:meth:`OraclePulse._sample_in_loop`): the loop is not left, which at a narrow band (~1000
pulses per 100 s) cost more than the Python loop it replaced. The first such sample of a run is
handed back (the runner's ``observe_truth`` hands over the true plant). Rows are those of the
Python loop bit for bit (tests/test_oracle_in_loop.py); a 100 s thesis cell takes about 0.55×
the CPU of the Python loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from numba import njit, objmode

from controllers.base import Controller, register
from controllers.law import CompiledLaw, owner_of, register_owner, step_address
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams
from controllers.models.acker import max_on_time
from plant.state import X1, X3, X4, PlantState

__all__ = ["OraclePulse", "OraclePulseOptions"]

_TOL_S = 1e-10        # on-time resolution [s]: |Δc| moves < 1e-11 rad
_MAX_ITERATIONS = 200
_FIT = 1.0 - 1e-9     # a segment must start strictly inside the interval
_OFF = DriveCommand.hold(0.0, DriveType.BRIDGE)   # immutable: one shared "off" command


@dataclass(frozen=True)
class OraclePulseOptions:
    """Options of the oracle bound.

    Attributes
    ----------
    band : float
        Half-width b of the error band [rad]; the peak error of a noise-free run is ≈ b.
    landing_fraction : float
        Where a pulse aims on the leading side, as a fraction of b, in (0, 1].
    """

    band: float = 4e-6
    landing_fraction: float = 1.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.band) and self.band > 0):
            raise ValueError(f"OraclePulseOptions.band must be > 0 rad, got {self.band!r}")
        if not (math.isfinite(self.landing_fraction) and 0 < self.landing_fraction <= 1):
            raise ValueError(f"OraclePulseOptions.landing_fraction must be in (0, 1], "
                             f"got {self.landing_fraction!r}")



def _on_time_for(motion: float, dtu_max: float, response) -> tuple[float, float, float]:
    """(Δt_u, |Δc|, t_stop) of the shortest pulse with |Δc| ≥ ``motion`` (``dtu_max`` if none).

    |Δc|(Δt_u) is 0 up to breakaway and increases after it; ``response(Δt_u)`` gives
    (|Δc|, t_stop). The root of |Δc| − motion by the Illinois regula falsi (a bracketing
    secant), stopped when the bracket is narrower than :data:`_TOL_S`; the upper end returned.
    """
    hi = dtu_max
    dc_hi, stop_hi = response(hi)
    if dc_hi <= motion:
        return hi, dc_hi, stop_hi
    lo, f_lo, f_hi = 0.0, -motion, dc_hi - motion
    side = 0
    for _ in range(_MAX_ITERATIONS):
        if hi - lo <= _TOL_S:
            break
        mid = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        if not lo < mid < hi:
            mid = 0.5 * (lo + hi)
        dc, stop = response(mid)
        f = dc - motion
        if f >= 0.0:
            hi, f_hi, dc_hi, stop_hi = mid, f, dc, stop
            if side == 1:
                f_lo *= 0.5
            side = 1
        else:
            lo, f_lo = mid, f
            if side == -1:
                f_hi *= 0.5
            side = -1
    return hi, dc_hi, stop_hi


# ---------------------------------------------------------------------------- the compiled step
# p = (H, b, τs, the owner's key) then, appended by the compiled loop (CompiledLaw.truth), the true
# state x at p[H:] and the sheet (t, mode, flyback) at p[-3:]. s is unused (the policy's memory is
# the Python object's: only samples that may fire reach it).
_P_HEAD, _P_BAND, _P_TS, _P_OWNER = range(4)
_N_P = 4
_MAX_SEGMENTS = 3     # a pulse inside the interval: off, on at the offset, off after Δt_u


def _python_sample(key, y, p, offs, levs):
    """Called from :func:`_in_loop` (numba ``objmode``): the firing sample of the oracle registered
    under ``key``, its command in (offs, levs); the segment count, or 0 to hand the sample back."""
    owner = owner_of(key)
    return 0 if owner is None else owner._sample_in_loop(y, p, offs, levs)


@njit(cache=True)
def _in_loop(p, y, offs, levs):
    """A sample that may fire: the Python step from inside the loop (0: handed back)."""
    with objmode(k="intp"):
        k = _python_sample(p[_P_OWNER], y, p, offs, levs)
    return k


@njit(cache=True)
def _oracle_step(s, p, y, offs, levs):
    """The samples of :meth:`OraclePulse.step` that only wait, compiled: 1 (the bridge off) when
    Python's step returns off before its on-time search, in the same arithmetic on the same true
    state; when it may fire, the Python step's command from inside the loop (:func:`_in_loop`)."""
    offs[0], levs[0] = 0.0, 0.0
    h = int(p[_P_HEAD])
    if p[-2] != 2.0 or p[-1] != 0.0 or p[h + X3] != 0.0:
        return 1                                # moving, in flyback or current on
    b = p[_P_BAND]
    x1, x4 = p[h + X1], p[h + X4]
    lead = 1.0 if x4 >= 0 else -1.0
    if lead * x1 > b:
        return 1
    if lead * x1 < -b:
        return _in_loop(p, y, offs, levs)
    if x4 != 0.0:
        offset = (x1 + lead * b) / x4
        if not 0.0 <= offset < p[_P_TS]:
            return 1
        return _in_loop(p, y, offs, levs)
    return 1


_ADDRESS: list[Any] = []


def _step_address() -> Any:
    """:func:`_oracle_step` as the address of its C wrapper (made once per process): the loop is
    entered once per pulse, ~5 µs instead of ~50 µs with a dispatcher (``StepAddress``)."""
    if not _ADDRESS:
        _ADDRESS.append(step_address(_oracle_step))
    return _ADDRESS[0]


@register("oracle-pulse")
class OraclePulse(Controller):
    """BOUND (privileged): pulses with the true state and the true pulse law; see the module."""

    family = "bound"
    drive = DriveType.BRIDGE
    description = "BOUND, not a controller: true state + true pulse law, optimal band pulsing"
    Options = OraclePulseOptions
    knobs = {"band": (0.5e-6, 1e-6, 2e-6, 4e-6, 8e-6, 16e-6, 32e-6)}
    counter = "pulses"
    privileged = True

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        self.params = params            # the model; the truth arrives with observe_truth
        self._truth = None
        self._plant = None
        self.dtu_max = max_on_time(params)
        self._t_stop_guess = 0.0
        self.pulses = 0
        self._last_dtu = 0.0
        self._in_loop = None            # (t, command or exception) of the last sample done inside the loop
        p = np.empty(_N_P)
        p[_P_HEAD], p[_P_BAND], p[_P_TS] = _N_P, self.options.band, params.sample_period
        p[_P_OWNER] = register_owner(self)
        self._law = CompiledLaw(_step_address(), np.zeros(1), p, DriveType.BRIDGE, _MAX_SEGMENTS, truth=True)

    def compiled_law(self) -> CompiledLaw | None:
        """The waiting samples compiled (:func:`_oracle_step`, reading the true state: ``truth``);
        a sample that may fire runs :meth:`step` from inside the loop (:meth:`_sample_in_loop`)."""
        return getattr(self, "_law", None)

    def _sample_in_loop(self, y: float, p: np.ndarray, offs: np.ndarray, levs: np.ndarray) -> int:
        """A sample that may fire, from inside the compiled loop: ``observe_truth`` with the true
        state in ``p``'s tail and the true plant the runner handed over, then :meth:`step`; its
        command into (offs, levs); returns the segment count. 0 hands the sample back: before the
        runner has handed over the true plant (the first such sample of a run), or where ``step``
        raised or its command does not fit — then the runner's ``step`` call returns (or raises)
        the outcome kept here, so ``step`` runs once per sample. A sample the loop redoes (its
        interval needed more noise or log room) gets the kept outcome again."""
        if self._plant is None:
            return 0
        t = float(p[-3])
        done = self._in_loop
        if done is not None and done[0] == t:
            outcome = done[1]
        else:
            h = int(p[_P_HEAD])
            x = np.array(p[h:-3])
            x.flags.writeable = False
            self.observe_truth(PlantState(t, x, int(p[-2]), p[-1] != 0.0), self._plant)
            try:
                outcome = self.step(y)
            except Exception as exc:   # noqa: BLE001 — raised again by the runner's step call
                outcome = exc
            self._in_loop = (t, outcome)
        if isinstance(outcome, BaseException):
            return 0
        o, v = outcome.arrays()
        k = o.shape[0]
        if k > offs.shape[0]:
            return 0
        offs[:k], levs[:k] = o, v
        return k

    def observe_truth(self, state: Any, plant: Any) -> None:
        if plant is not self._plant:
            self._plant = plant
            self.params = plant.params
            self.dtu_max = max_on_time(plant.params)
        self._truth = state

    def _dtu_for(self, state: Any, motion: float, sign: int) -> tuple[float, float, float]:
        """(Δt_u, |Δc|, t_stop) of the shortest true noise-free pulse from ``state`` with |Δc| ≥ ``motion``:
        the family's compiled search (``PlantFamily.pulse_on_time``) when it offers one, else
        :func:`_on_time_for` over ``pulse_motion`` (the same arithmetic)."""
        plant = self._plant
        fast = getattr(plant, "pulse_on_time", None)      # the same search, compiled by the family
        found = fast(state, motion, sign, self.dtu_max, _TOL_S, _MAX_ITERATIONS) if fast is not None else None
        if found is not None:
            return found

        def response(dtu: float) -> tuple[float, float]:
            dc, t_stop = plant.pulse_motion(state, dtu, sign)
            return abs(dc), t_stop

        return _on_time_for(motion, self.dtu_max, response)

    def step(self, y: float) -> DriveCommand:
        s = self._truth
        if s is None:
            raise RuntimeError("oracle-pulse needs observe_truth before step (privileged hook)")
        self._truth = None
        done = getattr(self, "_in_loop", None)
        if done is not None and done[0] == s.t:  # done inside the loop, then handed back: its outcome
            self._in_loop = None
            if isinstance(done[1], BaseException):
                raise done[1]
            return done[1]
        off = _OFF
        x = s.x
        if s.mode != 2 or s.flyback or x[X3] != 0.0:
            return off                          # wait until the shaft is stuck and current is zero
        ts = self.params.sample_period
        b = self.options.band
        x1, x4 = float(x[X1]), float(x[X4])
        lead = 1.0 if x4 >= 0 else -1.0         # x1 drifts towards −lead·b
        if lead * x1 > b:
            return off                          # overshot to the leading side: the drift brings it back,
                                                # and a return pulse could only risk a larger peak
        if lead * x1 < -b:
            offset = 0.0                        # beyond the trailing edge: correct at once
        elif x4 != 0.0:
            offset = (x1 + lead * b) / x4       # x1 − x4·τ = −lead·b
            if not 0.0 <= offset < ts:
                return off
        else:
            return off
        target = lead * self.options.landing_fraction * b
        t_stop = self._t_stop_guess
        for _ in range(2):                      # the drift during the pulse depends on Δt_u
            x1_fire = x1 - x4 * offset
            need = target - x1_fire + x4 * t_stop
            dtu, dc, t_stop = self._dtu_for(s, abs(need), 1 if need >= 0 else -1)
            if offset + dtu > _FIT * ts:
                offset = max(0.0, _FIT * ts - dtu)   # fire earlier so the on-time ends inside the interval
        if dc > 2.0 * abs(need) and abs(x1) <= b:
            return off                          # the smallest pulse would overshoot: keep drifting
        self._t_stop_guess = t_stop
        self.pulses += 1
        self._last_dtu = dtu
        return DriveCommand.pulse(offset, dtu, math.copysign(self.params.u_max, need))

    def internals(self) -> dict[str, float]:
        return {"dtu": self._last_dtu}

    def summary(self) -> dict[str, Any]:
        return {"pulses": getattr(self, "pulses", 0), "bound": True}
