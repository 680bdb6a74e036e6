"""The stribeck family's fast path: the closed loop of a fixed linear law, compiled whole.

The multimode family's loop (plant.multimode.law_loop) around this family's interval kernel
(plant.stribeck.interval); everything else — the compensator, the dither, the window sums,
the noise positions, the chunking — is the same code in the same order, so the results are
bit-identical to the runner's Python loop over ``step`` (tests/test_stribeck.py).


For a controller that describes its step as a fixed linear law (``controllers.law.LinearLaw``,
read here by its attributes), the loop of the runner — sensor, compensator, dither segments,
the interval kernel, the scoring window's sums — runs inside one numba function over chunks of
:data:`CHUNK` samples. The compensator and the dither are :mod:`plant.linear_drive`'s compiled
functions, the very code the controllers' ``step`` calls; the window sums are the runner's
(``bench.metrics.WindowTotals.add``) in the same order; the plant noise is read from the same
stream at the same positions. So the results are bit-identical to the Python loop
(tests/test_compiled_loop.py). Between chunks Python checks the wall-clock limit and extends
the noise buffer.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import njit

from plant.linear_drive import compensator_step, square_wave_segments
from plant.multimode.interval import (NO_EVENTS, SHEET_ABS, SHEET_BREAKAWAYS, SHEET_CHARGE, SHEET_DURATION, SHEET_EVENTS,
                                      SHEET_FLYBACK, SHEET_MODE, SHEET_PEAK, SHEET_SQ, SHEET_STATUS,
                                      SHEET_SUBSTEPS, SHEET_T, STATUS_OK, interval_status)
from plant.stribeck.interval import _SHEET as SHEET_SIZE, N_STATE, interval_kernel
from plant.params import PlantParams
from plant.randomness import NoiseExhausted, NoiseStream
from plant.state import PlantState, SimOptions, Status

__all__ = ["run_law", "CHUNK", "TOTAL_FIELDS"]

CHUNK = 1000            # samples per compiled call (the wall-clock limit is checked between them)
NOISE_MARGIN = 1 << 15  # unread normals guaranteed before each interval (else back to Python)
_NEED_NOISE = -1

# totals vector: the scoring window's sums, named as IntervalResult's fields
TOTAL_FIELDS = ("duration", "peak_abs_error", "int_abs_current", "int_sq_current", "supply_charge", "n_events",
                "n_breakaways", "n_substeps")
_DUR, _PEAK, _IABS, _ISQ, _CHG, _NEV, _NBRK, _NSUB = range(8)


@njit(cache=True)
def _chunk(n0, n1, n_warm, sensor, x, x_view, bridge, sheet, A, B, C, D, cx, u_max, amp, freq, phase, tau, prm, L, o,
           z, zpos, margin, ev, out, totals, x1_window, prog):
    """Samples n0 ≤ n < n1. ``prog`` gets (samples done, noise position); returns a kernel status
    code, or _NEED_NOISE when fewer than ``margin`` normals are left before an interval.
    """
    n_c = cx.shape[0]
    cxn = np.empty(n_c)
    n_max = int(2.0 * freq * tau) + 4 if amp != 0.0 else 1
    offs = np.empty(n_max)
    levs = np.empty(n_max)
    prog[0], prog[1] = n0, zpos
    for n in range(n0, n1):
        if z.shape[0] > 0 and z.shape[0] - zpos < margin:
            return _NEED_NOISE
        x1 = x[0]
        y = x1 + sensor[n]
        v = compensator_step(A, B, C, D, cx, cxn, y)
        level = min(max(-v, -u_max), u_max)
        k = square_wave_segments(n * tau, tau, level, amp, freq, phase, u_max, offs, levs)
        pos = interval_kernel(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, offs[:k].copy(),
                              levs[:k].copy(), bridge, prm, L, o, z, zpos, ev, out)
        S = out[N_STATE:]
        if n >= n_warm:
            x1_window[n - n_warm] = x1
            totals[_DUR] += S[SHEET_DURATION]
            if S[SHEET_PEAK] > totals[_PEAK]:
                totals[_PEAK] = S[SHEET_PEAK]
            totals[_IABS] += S[SHEET_ABS]
            totals[_ISQ] += S[SHEET_SQ]
            totals[_CHG] += S[SHEET_CHARGE]
            totals[_NEV] += S[SHEET_EVENTS]
            totals[_NBRK] += S[SHEET_BREAKAWAYS]
            totals[_NSUB] += S[SHEET_SUBSTEPS]
        for i in range(N_STATE):
            x[i] = out[i]
        sheet[0], sheet[1], sheet[2] = S[SHEET_T], S[SHEET_MODE], S[SHEET_FLYBACK]
        for i in range(n_c):
            cx[i] = cxn[i]
        zpos = pos
        prog[0], prog[1] = n + 1, zpos
        if S[SHEET_STATUS] != STATUS_OK:
            return int(S[SHEET_STATUS])
    return STATUS_OK


def run_law(law, params: PlantParams, options: SimOptions, state: PlantState, sensor: np.ndarray,
            n_warm: int, noise: NoiseStream | None, deadline: float
            ) -> tuple[PlantState, dict[str, float], np.ndarray, Status, str]:
    """Run ``len(sensor)`` samples of ``law`` from ``state``; what the runner's Python loop computes.

    ``law`` has the attributes of ``controllers.law.LinearLaw`` (A, B, C, D, u_max,
    dither_amplitude, dither_frequency, dither_phase); ``sensor`` holds w1(n) [rad].
    Returns the final state, the scoring window's sums (:data:`TOTAL_FIELDS`), x1 at the window's sample instants
    (with the final one when the run completes), the status and its message. The run stops with
    status ``error`` when ``time.perf_counter()`` passes ``deadline`` (checked every
    :data:`CHUNK` samples).
    """
    n_samples = sensor.shape[0]
    noisy = options.noise and noise is not None
    o = options.kernel_vector().copy()
    if not noisy:
        o[0] = 0.0
    prm = params.kernel_record()
    L = params.law_vector()
    A, B, C, D = (np.ascontiguousarray(m, dtype=np.float64) for m in (law.A, law.B, law.C, law.D))
    cx = np.zeros(A.shape[0])
    x = np.array(state.x, dtype=np.float64)
    x_view = x.view()
    x_view.flags.writeable = False
    sheet = np.array([state.t, float(state.mode), 1.0 if state.flyback else 0.0])
    out = np.empty(N_STATE + SHEET_SIZE)
    totals = np.zeros(8)
    x1_window = np.empty(n_samples - n_warm + 1)
    prog = np.zeros(2, dtype=np.int64)
    if noisy:
        z, zpos = noise.window()
    else:
        z, zpos = np.empty(0), 0
    margin = NOISE_MARGIN if noisy else 0
    n, code = 0, STATUS_OK
    while n < n_samples:
        stop = min(n + CHUNK, n_samples)
        try:
            code = _chunk(n, stop, n_warm, sensor, x, x_view, False, sheet, A, B, C, D, cx, float(law.u_max),
                          float(law.dither_amplitude), float(law.dither_frequency), float(law.dither_phase),
                          params.sample_period, prm, L, o, z, zpos, margin, NO_EVENTS, out,
                          totals, x1_window, prog)
        except NoiseExhausted:        # one interval wanted more than the margin: extend, redo it
            code = _NEED_NOISE
        n, zpos = int(prog[0]), int(prog[1])
        if code == _NEED_NOISE:
            z, zpos = noise.grow(zpos)
            while z.shape[0] - zpos < NOISE_MARGIN:
                z, zpos = noise.grow(zpos)
            continue
        if code != STATUS_OK:
            break
        if time.perf_counter() > deadline and n < n_samples:
            break
    if noisy:
        noise.consumed(zpos)
    x.flags.writeable = False
    final = PlantState(float(sheet[0]), x, int(sheet[1]), sheet[2] != 0.0)
    n_window = max(0, n - n_warm)
    if code != STATUS_OK:
        status, message = interval_status(code, final, options)
    elif n < n_samples:
        status = Status.ERROR
        message = "time limit exceeded"   # completed by the runner
    else:
        status, message = Status.OK, ""
        x1_window[n_window] = final.x[0]
        n_window += 1
    sums = {name: (float(v) if i < _NEV else int(v)) for i, (name, v) in enumerate(zip(TOTAL_FIELDS, totals))}
    return final, sums, x1_window[:n_window], status, message
