"""The Python side of a family's compiled closed loop of a fixed linear law (``linear_law_loop``).

A family that offers the fast path writes one compiled ``chunk`` function — samples n0 ≤ n < n1
of sensor, compensator and dither (:mod:`plant.linear_drive`), its own interval kernel and the
scoring window's sums — with the argument layout below. This driver, shared by every family,
calls it over chunks of :data:`CHUNK` samples, extends the noise buffer when a chunk returns for
more normals (or an interval ran out inside the kernel), checks the wall-clock limit between
chunks and turns the outcome into the runner's values. The chunk is called from Python, so each
family's kernel stays a module-level, cached numba function.

``chunk(n0, n1, n_warm, sensor, x, x_view, bridge, sheet, A, B, C, D, cx, u_max, amp, freq,
phase, tau, prm, *family_args, z, zpos, margin, no_events, out, totals, x1_window, prog)``
returns a kernel status code, or :data:`NEED_NOISE`; ``prog`` receives (samples done, noise
position).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from plant.randomness import NoiseExhausted, NoiseStream
from plant.state import PlantState, SimOptions, Status

__all__ = ["run_chunks", "CHUNK", "NOISE_MARGIN", "NEED_NOISE", "TOTAL_FIELDS"]

CHUNK = 1000            # samples per compiled call (the wall-clock limit is checked between them)
NOISE_MARGIN = 1 << 15  # unread normals guaranteed before each interval (else back to Python)
NEED_NOISE = -1
# totals vector: the scoring window's sums, named as IntervalResult's fields
TOTAL_FIELDS = ("duration", "peak_abs_error", "int_abs_current", "int_sq_current", "supply_charge", "n_events",
                "n_breakaways", "n_substeps")
_N_FLOAT_TOTALS = 5     # the first five are floats, the counts after them integers


def run_chunks(chunk: Callable[..., int], family_args: tuple, law: Any, params: Any, options: SimOptions,
               state: PlantState, sensor: np.ndarray, n_warm: int, noise: NoiseStream | None, noisy: bool,
               deadline: float, *, n_state: int, sheet_size: int, no_events: np.ndarray, status_ok: int,
               interval_status: Callable[[int, PlantState, SimOptions], tuple[Status, str]],
               ) -> tuple[PlantState, dict[str, float], np.ndarray, Status, str]:
    """Run ``len(sensor)`` samples of ``law`` from ``state``; what the runner's Python loop computes.

    ``law`` has the attributes of ``controllers.law.LinearLaw`` (A, B, C, D, u_max,
    dither_amplitude, dither_frequency, dither_phase); ``sensor`` holds w1(n) [rad].
    Returns the final state, the scoring window's sums (:data:`TOTAL_FIELDS`), x1 at the
    window's sample instants (with the final one when the run completes), the status and its
    message. The run stops with status ``error`` when ``time.perf_counter()`` passes
    ``deadline`` (checked every :data:`CHUNK` samples).
    """
    n_samples = sensor.shape[0]
    prm = params.kernel_record()
    A, B, C, D = (np.ascontiguousarray(m, dtype=np.float64) for m in (law.A, law.B, law.C, law.D))
    cx = np.zeros(A.shape[0])
    x = np.array(state.x, dtype=np.float64)
    x_view = x.view()
    x_view.flags.writeable = False
    sheet = np.array([state.t, float(state.mode), 1.0 if state.flyback else 0.0])
    out = np.empty(n_state + sheet_size)
    totals = np.zeros(len(TOTAL_FIELDS))
    x1_window = np.empty(n_samples - n_warm + 1)
    prog = np.zeros(2, dtype=np.int64)
    if noisy:
        z, zpos = noise.window()
    else:
        z, zpos = np.empty(0), 0
    margin = NOISE_MARGIN if noisy else 0
    n, code = 0, status_ok
    while n < n_samples:
        stop = min(n + CHUNK, n_samples)
        try:
            code = chunk(n, stop, n_warm, sensor, x, x_view, False, sheet, A, B, C, D, cx, float(law.u_max),
                         float(law.dither_amplitude), float(law.dither_frequency), float(law.dither_phase),
                         params.sample_period, prm, *family_args, z, zpos, margin, no_events, out, totals,
                         x1_window, prog)
        except NoiseExhausted:        # one interval wanted more than the margin: extend, redo it
            code = NEED_NOISE
        n, zpos = int(prog[0]), int(prog[1])
        if code == NEED_NOISE:
            z, zpos = noise.grow(zpos)
            while z.shape[0] - zpos < NOISE_MARGIN:
                z, zpos = noise.grow(zpos)
            continue
        if code != status_ok:
            break
        if time.perf_counter() > deadline and n < n_samples:
            break
    if noisy:
        noise.consumed(zpos)
    x.flags.writeable = False
    final = PlantState(float(sheet[0]), x, int(sheet[1]), sheet[2] != 0.0)
    n_window = max(0, n - n_warm)
    if code != status_ok:
        status, message = interval_status(code, final, options)
    elif n < n_samples:
        status = Status.ERROR
        message = "time limit exceeded"   # completed by the runner
    else:
        status, message = Status.OK, ""
        x1_window[n_window] = final.x[0]
        n_window += 1
    sums = {name: (float(v) if i < _N_FLOAT_TOTALS else int(v)) for i, (name, v) in enumerate(zip(TOTAL_FIELDS, totals))}
    return final, sums, x1_window[:n_window], status, message
