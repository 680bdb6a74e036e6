"""The two-mass family's fast path: the closed loop of a fixed linear law, compiled whole.

plant.multimode.law_loop with this family's interval kernel (same structure, same order of
operations; the state has N_X = 8 entries).

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


import numpy as np
from numba import njit

from plant.linear_drive import compensator_step, square_wave_segments
from plant.law_driver import HAND_BACK, NEED_NOISE, NEED_ROOM, LawRun, run_chunks, run_law_chunks, CHUNK, TOTAL_FIELDS
from plant.law_step import check_command, delay_segments, log_events, quantize
from plant.two_mass.interval import _NREC as _LOG_NREC, _RecordFull
from plant.randomness import NoiseStream
from plant.state import PlantState, SimOptions, Status
from plant.two_mass.interval import N_X as N_STATE
from plant.two_mass.interval import (_FB, _IABS, _ISQ, _CHG, _DUR, _MODE, _NBRK, _NEV, _NO_EVENTS,
                                     _NSUB, _OK, _PEAK, _SHEET, _STATUS, _T, _message, _O_NOISE, _STATUS_OF,
                                     MOVE_SCRATCH, interval_k, plan)
from plant.two_mass.modes import NCORE
from plant.two_mass.motion import NX
from plant.two_mass.params import TwoMassParams

NO_EVENTS = _NO_EVENTS
SHEET_T, SHEET_MODE, SHEET_FLYBACK, SHEET_PEAK = _T, _MODE, _FB, _PEAK
SHEET_ABS, SHEET_SQ, SHEET_CHARGE, SHEET_DURATION = _IABS, _ISQ, _CHG, _DUR
SHEET_EVENTS, SHEET_BREAKAWAYS, SHEET_SUBSTEPS, SHEET_STATUS = _NEV, _NBRK, _NSUB, _STATUS
SHEET_SIZE, STATUS_OK = _SHEET, _OK


def interval_status(code, state, options):
    if code == _OK:
        return Status.OK, ""
    return _STATUS_OF[code], _message(code, state, options)

__all__ = ["run_law", "run_compiled_law", "CHUNK", "TOTAL_FIELDS"]

_NEED_NOISE = NEED_NOISE
_TDUR, _TPEAK, _TIABS, _TISQ, _TCHG, _TNEV, _TNBRK, _TNSUB = range(8)


@njit(cache=True)
def _chunk(n0, n1, n_warm, sensor, x, x_view, bridge, sheet, A, B, C, D, cx, u_max, amp, freq, phase, tau, prm, q, V,
           Vi, lam, o, TP, TL, BT, z, zpos, margin, ev, out, totals, x1_window, prog):
    """Samples n0 ≤ n < n1. ``prog`` gets (samples done, noise position); returns a kernel status
    code, or _NEED_NOISE when fewer than ``margin`` normals are left before an interval.
    """
    n_c = cx.shape[0]
    cxn = np.empty(n_c)
    n_max = int(2.0 * freq * tau) + 4 if amp != 0.0 else 1
    offs = np.empty(n_max)
    levs = np.empty(n_max)
    cursor, X, Xn = np.empty(1, dtype=np.int64), np.empty(NX), np.empty(NX)   # interval_k's scratch
    Cw, Fw, W = np.empty((5, NCORE), dtype=np.complex128), np.empty((3, NCORE)), np.empty(MOVE_SCRATCH)
    prog[0], prog[1] = n0, zpos
    for n in range(n0, n1):
        if z.shape[0] > 0 and z.shape[0] - zpos < margin:
            return _NEED_NOISE
        x1 = x[0]
        y = x1 + sensor[n]
        v = compensator_step(A, B, C, D, cx, cxn, y)
        level = min(max(-v, -u_max), u_max)
        k = square_wave_segments(n * tau, tau, level, amp, freq, phase, u_max, offs, levs)
        pos = interval_k(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, offs, levs, k, bridge, prm, q, V, Vi,
                         lam, o, TP, TL, BT, z, zpos, ev, out, cursor, X, Xn, Cw, Fw, W)
        S = out[N_STATE:]
        if n >= n_warm:
            x1_window[n - n_warm] = x1
            totals[_TDUR] += S[SHEET_DURATION]
            if S[SHEET_PEAK] > totals[_TPEAK]:
                totals[_TPEAK] = S[SHEET_PEAK]
            totals[_TIABS] += S[SHEET_ABS]
            totals[_TISQ] += S[SHEET_SQ]
            totals[_TCHG] += S[SHEET_CHARGE]
            totals[_TNEV] += S[SHEET_EVENTS]
            totals[_TNBRK] += S[SHEET_BREAKAWAYS]
            totals[_TNSUB] += S[SHEET_SUBSTEPS]
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


def run_law(law, params: TwoMassParams, options: SimOptions, state: PlantState, sensor: np.ndarray,
            n_warm: int, noise: NoiseStream | None, deadline: float
            ) -> tuple[PlantState, dict[str, float], np.ndarray, Status, str]:
    """:func:`plant.law_driver.run_chunks` around this family's compiled chunk."""
    noisy = options.noise and noise is not None
    q, V, Vi, lam, o, TP, TL, BT = plan(params, options)
    if not noisy:
        o = o.copy()
        o[_O_NOISE] = 0.0
        o.flags.writeable = False   # read-only like plan()'s: the kernels' one signature (docs/plant.md)
    return run_chunks(_chunk, (q, V, Vi, lam, o, TP, TL, BT), law, params, options, state, sensor, n_warm, noise, noisy, deadline,
                      n_state=N_STATE, sheet_size=SHEET_SIZE, no_events=NO_EVENTS, status_ok=STATUS_OK,
                      interval_status=interval_status)

def _law_chunk(step, s, p, s_back, bridge, u_max, quant, delay, pend_o, pend_l, offs, levs, now_o, now_l, carry_o,
               carry_l, n0, n1, n_warm, sensor, x, x_view, sheet, tau, prm, q, V, Vi, lam, o, TP, TL, BT, z, zpos,
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
    cursor, X, Xn = np.empty(1, dtype=np.int64), np.empty(NX), np.empty(NX)   # interval_k's scratch
    Cw, Fw, W = np.empty((5, NCORE), dtype=np.complex128), np.empty((3, NCORE)), np.empty(MOVE_SCRATCH)
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
            pos = interval_k(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, now_o, now_l, n_now, bridge, prm,
                             q, V, Vi, lam, o, TP, TL, BT, z, zpos, ev, out, cursor, X, Xn, Cw, Fw, W)
        else:
            n_carry = 0
            pos = interval_k(x_view, int(sheet[1]), sheet[2] != 0.0, sheet[0], tau, offs, levs, k, bridge, prm, q, V,
                             Vi, lam, o, TP, TL, BT, z, zpos, ev, out, cursor, X, Xn, Cw, Fw, W)
        S = out[N_STATE:]
        if logging:                         # ... and the interval's plant events (t, x1)
            log_events(xe, prog, ev, int(S[_LOG_NREC]))
        if n >= n_warm:
            x1_window[n - n_warm] = x1
            totals[_TDUR] += S[SHEET_DURATION]
            if S[SHEET_PEAK] > totals[_TPEAK]:
                totals[_TPEAK] = S[SHEET_PEAK]
            totals[_TIABS] += S[SHEET_ABS]
            totals[_TISQ] += S[SHEET_SQ]
            totals[_TCHG] += S[SHEET_CHARGE]
            totals[_TNEV] += S[SHEET_EVENTS]
            totals[_TNBRK] += S[SHEET_BREAKAWAYS]
            totals[_TNSUB] += S[SHEET_SUBSTEPS]
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
    q, V, Vi, lam, o, TP, TL, BT = plan(params, options)
    if not noisy:
        o = o.copy()
        o[_O_NOISE] = 0.0
        o.flags.writeable = False   # read-only like plan()'s: the kernels' one signature (docs/plant.md)
    return run_law_chunks(_law_chunk, (q, V, Vi, lam, o, TP, TL, BT), law, params, options, state, sensor, n_warm, noise, noisy,
                          deadline, n_state=N_STATE, sheet_size=SHEET_SIZE, no_events=NO_EVENTS, status_ok=STATUS_OK,
                          interval_status=interval_status, record_full=_RecordFull, **resume)
