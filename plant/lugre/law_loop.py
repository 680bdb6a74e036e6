"""The lugre family's fast path: the closed loop of a fixed linear law, compiled whole.

The stribeck family's loop (plant.stribeck.law_loop) around this family's interval kernel
(plant.lugre.interval, with the integrator's tolerances as one more argument); the
compensator and the dither are :mod:`plant.linear_drive`'s compiled functions (the very code
the controllers' ``step`` calls), the window sums are the runner's
(``bench.metrics.WindowTotals.add``) in the same order and the plant noise is read at the same
positions, so the results are bit-identical to the runner's Python loop over ``step``
(tests/test_lugre.py). :func:`plant.law_driver.run_chunks` drives it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from plant.law_driver import HAND_BACK, NEED_NOISE, NEED_ROOM, LawRun, run_chunks, run_law_chunks
from plant.law_step import check_command, delay_segments, log_events, quantize
from plant.lugre.interval import _NREC as _LOG_NREC, _RecordFull
from plant.linear_drive import compensator_step, square_wave_segments
from plant.lugre import integrate
from plant.lugre.interval import (N_STATE, NO_EVENTS, SHEET_ABS, SHEET_BREAKAWAYS, SHEET_CHARGE, SHEET_DURATION,
                                  SHEET_EVENTS, SHEET_FLYBACK, SHEET_MODE, SHEET_PEAK, SHEET_SIZE, SHEET_SQ,
                                  SHEET_STATUS, SHEET_SUBSTEPS, SHEET_T, STATUS_OK, interval_kernel, interval_status)
from plant.randomness import NoiseStream
from plant.state import PlantState, SimOptions, Status

__all__ = ["run_law", "run_compiled_law"]

# totals vector: plant.law_driver.TOTAL_FIELDS
_DUR, _PEAK, _IABS, _ISQ, _CHG, _NEV, _NBRK, _NSUB = range(8)


@njit(cache=True)
def _chunk(n0, n1, n_warm, sensor, x, x_view, bridge, sheet, A, B, C, D, cx, u_max, amp, freq, phase, tau, prm, L, o,
           tol, z, zpos, margin, ev, out, totals, x1_window, prog):
    """Samples n0 ≤ n < n1. ``prog`` gets (samples done, noise position); returns a kernel status
    code, or NEED_NOISE when fewer than ``margin`` normals are left before an interval.
    """
    n_c = cx.shape[0]
    cxn = np.empty(n_c)
    n_max = int(2.0 * freq * tau) + 4 if amp != 0.0 else 1
    offs = np.empty(n_max)
    levs = np.empty(n_max)
    prog[0], prog[1] = n0, zpos
    for n in range(n0, n1):
        if z.shape[0] > 0 and z.shape[0] - zpos < margin:
            return NEED_NOISE
        x1 = x[0]
        y = x1 + sensor[n]
        v = compensator_step(A, B, C, D, cx, cxn, y)
        level = min(max(-v, -u_max), u_max)
        k = square_wave_segments(n * tau, tau, level, amp, freq, phase, u_max, offs, levs)
        pos = interval_kernel(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, offs[:k].copy(),
                              levs[:k].copy(), bridge, prm, L, o, z, zpos, ev, out, tol)
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


def run_law(law, params, options: SimOptions, state: PlantState, sensor: np.ndarray,
            n_warm: int, noise: NoiseStream | None, deadline: float
            ) -> tuple[PlantState, dict[str, float], np.ndarray, Status, str]:
    """:func:`plant.law_driver.run_chunks` around this family's compiled chunk."""
    noisy = options.noise and noise is not None
    o = options.kernel_vector().copy()
    if not noisy:
        o[0] = 0.0
    tol = integrate.NOISY_TOLERANCES if noisy else integrate.TOLERANCES
    return run_chunks(_chunk, (params.law_vector(), o, tol), law, params, options, state, sensor,
                      n_warm, noise, noisy, deadline, n_state=N_STATE, sheet_size=SHEET_SIZE, no_events=NO_EVENTS,
                      status_ok=STATUS_OK, interval_status=interval_status)

def _law_chunk(step, s, p, s_back, bridge, u_max, quant, delay, pend_o, pend_l, offs, levs, now_o, now_l, carry_o,
               carry_l, n0, n1, n_warm, sensor, x, x_view, sheet, tau, prm, L, o, tol, z, zpos,
               margin, ev, out, totals, x1_window, prog, xs, xe):
    """Samples n0 ≤ n < n1 of a compiled controller step (:func:`plant.law_driver.run_law_chunks`).

    Per sample, in the runner's order: y(n) = quantize(x1 + w1(n)) (``PlantFamily.observe``);
    the step; the delay (``delayed_step``); the interval kernel; the window sums; the state.
    ``prog`` gets (samples done, noise position, pending segments, events logged); returns a
    kernel status code, NEED_NOISE, NEED_ROOM (the x1 log ``xs``, ``xe`` needs room) or HAND_BACK
    with ``s`` restored (the sample is not done).
    """
    n_s = s.shape[0]
    logging = xs.shape[0] > 0
    prog[0], prog[1] = n0, zpos
    for n in range(n0, n1):
        if z.shape[0] > 0 and z.shape[0] - zpos < margin:
            return NEED_NOISE
        if logging and xe.shape[0] - prog[3] < ev.shape[0]:
            return NEED_ROOM
        x1 = x[0]
        if logging:                         # the x1 log (plant.law_driver.X1Log): the sample
            xs[n, 0], xs[n, 1] = sheet[0], x1
        y = quantize(x1 + sensor[n], quant)
        for i in range(n_s):
            s_back[i] = s[i]
        k = step(s, p, y, offs, levs)
        if not check_command(k, offs, levs, tau, bridge, u_max):
            for i in range(n_s):
                s[i] = s_back[i]
            return HAND_BACK
        n_pend = prog[2]
        if delay != 0.0:
            n_now, n_carry = delay_segments(offs, levs, k, pend_o, pend_l, n_pend, delay, tau, now_o, now_l,
                                            carry_o, carry_l)
            seg_o, seg_l = now_o[:n_now].copy(), now_l[:n_now].copy()
        else:
            n_carry = 0
            seg_o, seg_l = offs[:k].copy(), levs[:k].copy()
        pos = interval_kernel(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, seg_o, seg_l, bridge, prm, L, o, z,
                              zpos, ev, out, tol)
        S = out[N_STATE:]
        if logging:                         # ... and the interval's plant events (t, x1)
            log_events(xe, prog, ev, int(S[_LOG_NREC]))
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
        for i in range(n_carry):
            pend_o[i], pend_l[i] = carry_o[i], carry_l[i]
        if delay != 0.0:
            prog[2] = n_carry
        zpos = pos
        prog[0], prog[1] = n + 1, zpos
        if S[SHEET_STATUS] != STATUS_OK:
            return int(S[SHEET_STATUS])
    return STATUS_OK


def run_compiled_law(law, params, options: SimOptions, state: PlantState, sensor: np.ndarray, n_warm: int,
                     noise: NoiseStream | None, deadline: float, **resume) -> LawRun:
    """:func:`plant.law_driver.run_law_chunks` around this family's chunk (see
    plant.multimode.law_loop._law_chunk: the same loop around this family's kernel)."""
    noisy = options.noise and noise is not None
    o = options.kernel_vector().copy()
    if not noisy:
        o[0] = 0.0
    tol = integrate.NOISY_TOLERANCES if noisy else integrate.TOLERANCES
    return run_law_chunks(_law_chunk, (params.law_vector(), o, tol), law, params, options, state, sensor, n_warm, noise, noisy,
                          deadline, n_state=N_STATE, sheet_size=SHEET_SIZE, no_events=NO_EVENTS, status_ok=STATUS_OK,
                          interval_status=interval_status, record_full=_RecordFull, **resume)
