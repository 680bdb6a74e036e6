"""Acker's plant stepped by Euler–Maruyama at a fixed step, behind the plant-family seam.

:class:`FixedStepFamily` is a :class:`~plant.protocol.PlantFamily` whose ``step`` advances the
multimode SDE (3-5) over one sample interval by the fixed-step reference discretisation of
:mod:`plant.multimode.reference` (``_em_chunk``: Euler–Maruyama with the mode logic checked once
per step; a drive edge takes effect at the first grid point at or after it). The closed loop
(:class:`bench.runner.PlantLoop`) steps it exactly as it steps the exact family, so a
controller's closed-loop statistics can be compared between the two (``bench.speed``, issue 27).

* **Step.** ``dt`` [s] is rounded so that a whole number n = round(τ/dt) of steps fills each
  interval of length τ (``effective_step``); n ≥ 1.
* **Noise.** 3 unit normals per step (w2, w4, w5 increments, scaled by √dt) are read in order
  from the run's :class:`~plant.randomness.NoiseStream`; the step consumes exactly 3n of them.
* **Interval results.** ``peak_abs_error`` is max |x1| over the interval's grid points (start
  included); ∫|x3|, ∫x3² and the supply charge are left-point rectangle sums (first order).
  Event counts are 0 (fixed-step has no events); ``n_substeps`` is n.
* **Not modelled:** the disturbance torque (``disturbance_torque_std`` > 0 raises ValueError).

Order: Euler's global error is O(dt) for the noise-free plant (``tests/test_em_family.py``
checks it against the exact family); the weak error with noise is measured, not assumed
(:mod:`bench.weak_coupled`).
"""

from __future__ import annotations

import math

import numpy as np

from plant.drive import DriveType
from plant.params import PlantParams
from plant.protocol import PlantFamily
from plant.state import N_STATE, X1, IntervalResult, PlantState, Status
from plant.multimode.reference import _em_chunk, _param_vector

__all__ = ["FixedStepFamily"]

_NO_NOISE = np.zeros((0, 1, 3))


class FixedStepFamily(PlantFamily):
    """The multimode plant by Euler–Maruyama at step ``dt`` [s] (module docstring). Not registered:
    pass the instance as ``family`` to :func:`bench.runner.run_closed_loop`."""

    Params = PlantParams
    description = "Acker's shaft by fixed-step Euler–Maruyama (reference discretisation, SPEC §2)"

    def __init__(self, dt: float) -> None:
        if not (isinstance(dt, (int, float)) and 0 < dt <= 1e-3 and math.isfinite(dt)):
            raise ValueError(f"FixedStepFamily.dt must be a step in (0, 1e-3] s, got {dt!r}")
        self.dt = float(dt)
        self.name = f"euler-maruyama(h={dt:g})"
        self._prm: tuple[int, np.ndarray] | None = None

    def effective_step(self, duration: float) -> float:
        """The step used on an interval of ``duration`` seconds: duration / round(duration/dt)."""
        return duration / max(1, round(duration / self.dt))

    def _params(self, params: PlantParams) -> np.ndarray:
        cached = self._prm
        if cached is None or cached[0] is not params:
            cached = self._prm = (params, _param_vector(params))
        return cached[1]

    def step(self, state, command, params, noise, options, *, duration=None, record=False):
        """One interval of ``duration`` (default τs) by Euler–Maruyama; see the module docstring."""
        if params.disturbance_torque_std != 0.0:
            raise ValueError("FixedStepFamily: disturbance_torque_std must be 0 (the disturbance torque "
                             "is not modelled by the fixed-step reference)")
        h = params.sample_period if duration is None else duration
        if not (h > 0 and math.isfinite(h)):
            raise ValueError(f"duration must be a finite positive number of seconds, got {duration!r}")
        offsets, levels = command.arrays()
        if offsets[-1] >= h:
            raise ValueError(f"DriveCommand segment at offset {offsets[-1]!r} s lies beyond the interval of {h!r} s")
        bridge = command.drive is DriveType.BRIDGE
        n = max(1, round(h / self.dt))
        dt = h / n
        x = state.x
        S = np.empty((1, 8))
        S[0, :6] = x[:6]
        S[0, 6] = float(state.mode)
        S[0, 7] = 0.0
        peak = np.array([abs(float(x[X1]))])
        acc = np.zeros((1, 3))
        if options.noise and noise is not None:
            need = 3 * n
            buf, pos = noise.window()
            while buf.shape[0] - pos < need:
                buf, pos = noise.grow(pos)
            z = buf[pos:pos + need].reshape(n, 1, 3)
            noise.consumed(pos + need)
        else:
            z = np.zeros((n, 1, 3))
        _em_chunk(S, n, 0.0, dt, offsets, levels, bridge, self._params(params), z, peak, acc)
        x_out = np.empty(N_STATE)
        x_out[:] = S[0, :6]
        x_out.flags.writeable = False
        mode = int(S[0, 6])
        flyback = bool(bridge and levels[int(S[0, 7])] == 0.0 and x_out[5] != 0.0)
        new = PlantState(state.t + h, x_out, mode, flyback)
        status, message = Status.OK, ""
        if not np.all(np.isfinite(x_out)) or abs(x_out[X1]) > options.diverge_error:
            status, message = Status.DIVERGED, f"|x1| beyond {options.diverge_error} rad or not finite at t={new.t:.6f} s"
        events = None
        if record:
            events = {k: np.empty(0) for k in ("t", "x1", "x2", "x3", "u")}
            events["mode"] = np.empty(0, dtype=np.int8)
            events["kind"] = np.empty(0, dtype=np.int8)
        return IntervalResult(new, status, message, float(peak[0]), float(acc[0, 0]), float(acc[0, 1]),
                              float(acc[0, 2]), h, 0, 0, 0, n, events)
