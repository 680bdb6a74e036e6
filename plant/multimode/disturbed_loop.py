"""The compiled closed loops on the disturbed multimode plant (SPEC §11).

:mod:`plant.multimode.law_loop`'s two chunks with the disturbed interval kernel
(:mod:`plant.multimode.disturbed_jit`) in place of the plain one: the same sensor (quantized),
compensator or compiled controller step (:mod:`plant.law_step`), dither segments
(:mod:`plant.linear_drive`), compute delay and window sums in the same order, the plant noise read
from the same stream at the same positions, so the results are bit-identical to the runner's
Python loop calling :func:`plant.multimode.disturbed.advance` (tests/test_disturbed_jit.py,
tests/test_compiled_law.py). The state has seven entries (d last). :func:`run_law` (a fixed
linear law, ideal sensor, no delay) is driven by :func:`plant.law_driver.run_chunks`,
:func:`run_compiled_law` (any compiled step, with the x1 log) by
:func:`plant.law_driver.run_law_chunks`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from plant.law_driver import HAND_BACK, NEED_NOISE, NEED_ROOM, LawRun, run_chunks, run_law_chunks
from plant.law_step import check_command, delay_segments, log_events, quantize
from plant.linear_drive import compensator_step, square_wave_segments
from plant.multimode import disturbed_jit
from plant.multimode.disturbed import N_X
# the kernel's work-sheet positions (after the N_X state entries of ``out``)
from plant.multimode.disturbed_jit import (SHEET_ABS as _IABSS, SHEET_BREAKAWAYS as _NBRKS,
                                           SHEET_CHARGE as _CHGS, SHEET_DURATION as _DURS, SHEET_EVENTS as _NEVS,
                                           SHEET_FLYBACK as _FB, SHEET_MODE as _MODE, SHEET_PEAK as _PEAKS,
                                           SHEET_SQ as _ISQS, SHEET_STATUS as _STATUS, SHEET_SUBSTEPS as _NSUBS,
                                           SHEET_T as _T, STATUS_OK as _OK, _NREC as _LOG_NREC, RecordFull)
from plant.params import PlantParams
from plant.randomness import NoiseStream
from plant.state import PlantState, SimOptions, Status

__all__ = ["run_law", "run_compiled_law"]

_DUR, _PEAK, _IABS, _ISQ, _CHG, _NEV, _NBRK, _NSUB = range(8)     # plant.law_driver.TOTAL_FIELDS


@njit(cache=True)
def _chunk(n0, n1, n_warm, sensor, x, x_view, bridge, sheet, A, B, C, D, cx, u_max, amp, freq, phase, tau, prm, ov,
           recs, rds, FB, IB, z, zpos, margin, ev, out, totals, x1_window, prog):
    """Samples n0 ≤ n < n1 (the layout of :mod:`plant.law_driver`); a kernel status code or NEED_NOISE."""
    n_c = cx.shape[0]
    cxn = np.empty(n_c)
    n_max = int(2.0 * freq * tau) + 4 if amp != 0.0 else 1
    offs = np.empty(n_max)
    levs = np.empty(n_max)
    work = np.empty(disturbed_jit.WORK_SIZE)
    cursor = np.empty(1, np.int64)
    prog[0], prog[1] = n0, zpos
    for n in range(n0, n1):
        if z.shape[0] > 0 and z.shape[0] - zpos < margin:
            return NEED_NOISE
        x1 = x[0]
        y = x1 + sensor[n]
        v = compensator_step(A, B, C, D, cx, cxn, y)
        level = min(max(-v, -u_max), u_max)
        k = square_wave_segments(n * tau, tau, level, amp, freq, phase, u_max, offs, levs)
        pos = disturbed_jit.interval_k(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, offs, levs, k, bridge,
                                       ov, recs, rds, FB, IB, z, zpos, ev, out, work, cursor)
        S = out[N_X:]
        if n >= n_warm:
            x1_window[n - n_warm] = x1
            totals[_DUR] += S[_DURS]
            if S[_PEAKS] > totals[_PEAK]:
                totals[_PEAK] = S[_PEAKS]
            totals[_IABS] += S[_IABSS]
            totals[_ISQ] += S[_ISQS]
            totals[_CHG] += S[_CHGS]
            totals[_NEV] += S[_NEVS]
            totals[_NBRK] += S[_NBRKS]
            totals[_NSUB] += S[_NSUBS]
        for i in range(N_X):
            x[i] = out[i]
        sheet[0], sheet[1], sheet[2] = S[_T], S[_MODE], S[_FB]
        for i in range(n_c):
            cx[i] = cxn[i]
        zpos = pos
        prog[0], prog[1] = n + 1, zpos
        if S[_STATUS] != _OK:
            return int(S[_STATUS])
    return _OK


def _status(code: int, state: PlantState, options: SimOptions) -> tuple[Status, str]:
    if code == 1:
        return Status.CHATTER, f"more than {options.max_events} events in one interval at t={state.t:.6f} s"
    return Status.DIVERGED, f"|x1| = {abs(state.x[0]):.3g} rad at t={state.t:.6f} s"


def _seven(state: PlantState) -> PlantState:
    """``state`` with d = 0 appended when it has the plain plant's six entries."""
    if state.x.shape[0] >= N_X:
        return state
    x = np.zeros(N_X)
    x[:state.x.shape[0]] = state.x
    return PlantState(state.t, x, state.mode, state.flyback)


def _inputs(params: PlantParams, options: SimOptions, noisy: bool) -> tuple:
    """The kernel's (ov, recs, rds, FB, IB), the noise switched off in ``ov`` when not ``noisy``
    (as :func:`plant.multimode.disturbed.advance` does)."""
    ov, *K = disturbed_jit.kernel_inputs(params, options)
    if not noisy and ov[0] != 0.0:
        ov = ov.copy()
        ov[0] = 0.0
    return (ov, *K)


def run_law(law, params: PlantParams, options: SimOptions, state: PlantState, sensor: np.ndarray,
            n_warm: int, noise: NoiseStream | None, deadline: float
            ) -> tuple[PlantState, dict[str, float], np.ndarray, Status, str]:
    """:func:`plant.law_driver.run_chunks` around the disturbed chunk."""
    noisy = options.noise and noise is not None
    return run_chunks(_chunk, _inputs(params, options, noisy), law, params, options, _seven(state), sensor, n_warm, noise, noisy,
                      deadline, n_state=N_X, sheet_size=disturbed_jit.SHEET_SIZE, no_events=_NO_EVENTS, status_ok=_OK,
                      interval_status=_status)


_NO_EVENTS = np.empty((0, 7))


def _law_chunk(step, s, p, s_back, bridge, u_max, quant, delay, pend_o, pend_l, offs, levs, now_o, now_l, carry_o,
               carry_l, n0, n1, n_warm, sensor, x, x_view, sheet, tau, prm, ov, recs, rds, FB, IB, z, zpos, margin, ev,
               out, totals, x1_window, prog, xs, xe):
    """Samples n0 ≤ n < n1 of a compiled controller step (:func:`plant.law_driver.run_law_chunks`):
    :func:`plant.multimode.law_loop._law_chunk` with the disturbed kernel. Per sample, in the
    runner's order: y(n) = quantize(x1 + w1(n)); the step; the delay; the interval; the x1 log;
    the window sums; the state. Returns a kernel status code, NEED_NOISE, NEED_ROOM or HAND_BACK
    (``s`` restored, the sample not done)."""
    n_s = s.shape[0]
    logging = xs.shape[0] > 0
    work = np.empty(disturbed_jit.WORK_SIZE)
    cursor = np.empty(1, np.int64)
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
            pos = disturbed_jit.interval_k(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, now_o, now_l, n_now,
                                           bridge, ov, recs, rds, FB, IB, z, zpos, ev, out, work, cursor)
        else:
            n_carry = 0
            pos = disturbed_jit.interval_k(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, offs, levs, k,
                                           bridge, ov, recs, rds, FB, IB, z, zpos, ev, out, work, cursor)
        S = out[N_X:]
        if logging:                         # ... and the interval's plant events (t, x1)
            log_events(xe, prog, ev, int(S[_LOG_NREC]))
        if n >= n_warm:
            x1_window[n - n_warm] = x1
            totals[_DUR] += S[_DURS]
            if S[_PEAKS] > totals[_PEAK]:
                totals[_PEAK] = S[_PEAKS]
            totals[_IABS] += S[_IABSS]
            totals[_ISQ] += S[_ISQS]
            totals[_CHG] += S[_CHGS]
            totals[_NEV] += S[_NEVS]
            totals[_NBRK] += S[_NBRKS]
            totals[_NSUB] += S[_NSUBS]
        for i in range(N_X):
            x[i] = out[i]
        sheet[0], sheet[1], sheet[2] = S[_T], S[_MODE], S[_FB]
        for i in range(n_carry):
            pend_o[i], pend_l[i] = carry_o[i], carry_l[i]
        if delay != 0.0:
            prog[2] = n_carry
        zpos = pos
        prog[0], prog[1] = n + 1, zpos
        if S[_STATUS] != _OK:
            return int(S[_STATUS])
    return _OK


def run_compiled_law(law, params: PlantParams, options: SimOptions, state: PlantState, sensor: np.ndarray,
                     n_warm: int, noise: NoiseStream | None, deadline: float, **resume) -> LawRun:
    """:func:`plant.law_driver.run_law_chunks` around the disturbed chunk of a compiled step (the
    quantized sensor, the compute delay and the x1 log included); ``resume`` as
    :func:`plant.multimode.law_loop.run_compiled_law`'s."""
    noisy = options.noise and noise is not None
    return run_law_chunks(_law_chunk, _inputs(params, options, noisy), law, params, options, _seven(state), sensor,
                          n_warm, noise, noisy, deadline, n_state=N_X, sheet_size=disturbed_jit.SHEET_SIZE,
                          no_events=_NO_EVENTS, status_ok=_OK, interval_status=_status, record_full=RecordFull,
                          **resume)
