"""The compiled closed loop of a fixed linear law on the disturbed multimode plant (SPEC §11).

:mod:`plant.multimode.law_loop`'s chunk with the disturbed interval kernel
(:mod:`plant.multimode.disturbed_jit`) in place of the plain one: the same sensor, compensator,
dither segments (:mod:`plant.linear_drive`) and window sums in the same order, the plant noise read
from the same stream at the same positions, so the results are bit-identical to the runner's
Python loop calling :func:`plant.multimode.disturbed.advance` (tests/test_disturbed_jit.py).
The state has seven entries (d last); :func:`plant.law_driver.run_chunks` drives the chunks.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from plant.law_driver import NEED_NOISE, run_chunks
from plant.linear_drive import compensator_step, square_wave_segments
from plant.multimode import disturbed_jit
from plant.multimode.disturbed import N_X
# the kernel's work-sheet positions (after the N_X state entries of ``out``)
from plant.multimode.disturbed_jit import (SHEET_ABS as _IABSS, SHEET_BREAKAWAYS as _NBRKS,
                                           SHEET_CHARGE as _CHGS, SHEET_DURATION as _DURS, SHEET_EVENTS as _NEVS,
                                           SHEET_FLYBACK as _FB, SHEET_MODE as _MODE, SHEET_PEAK as _PEAKS,
                                           SHEET_SQ as _ISQS, SHEET_STATUS as _STATUS, SHEET_SUBSTEPS as _NSUBS,
                                           SHEET_T as _T, STATUS_OK as _OK)
from plant.params import PlantParams
from plant.randomness import NoiseStream
from plant.state import PlantState, SimOptions, Status

__all__ = ["run_law"]

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


def run_law(law, params: PlantParams, options: SimOptions, state: PlantState, sensor: np.ndarray,
            n_warm: int, noise: NoiseStream | None, deadline: float
            ) -> tuple[PlantState, dict[str, float], np.ndarray, Status, str]:
    """:func:`plant.law_driver.run_chunks` around the disturbed chunk."""
    noisy = options.noise and noise is not None
    ov, *K = disturbed_jit.kernel_inputs(params, options)
    if not noisy and ov[0] != 0.0:
        ov = ov.copy()
        ov[0] = 0.0
    if state.x.shape[0] < N_X:              # a 6-entry start state: d = 0
        x = np.zeros(N_X)
        x[:state.x.shape[0]] = state.x
        state = PlantState(state.t, x, state.mode, state.flyback)
    return run_chunks(_chunk, (ov, *K), law, params, options, state, sensor, n_warm, noise, noisy, deadline,
                      n_state=N_X, sheet_size=disturbed_jit.SHEET_SIZE, no_events=_NO_EVENTS, status_ok=_OK,
                      interval_status=_status)


_NO_EVENTS = np.empty((0, 7))
