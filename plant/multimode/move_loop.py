"""One move of the identification's noise-free multimode model in one compiled call (issue 25).

:class:`plant.identification.fit._Model` plays each move of a log from rest, sample by sample,
through the family's step: for multimode :func:`plant.multimode.interval.advance`, the compiled
interval kernel plus ≈ 16 µs of Python per sample. :func:`play_move` calls the very same kernel,
with the same arguments in the same order, in one compiled loop over the move's samples, with the
fit's settle test (a stuck shaft at rest, its torque inside the stiction band, is frozen).
Noise-free, no disturbance torque, no event record. Predictions are bit-identical to the Python
loop over ``advance`` (tests/test_identify_speed.py); as :mod:`plant.lugre.move_loop` for lugre.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from plant.multimode.interval import (_BAD_LEVEL, _FB, _MODE, _NEV, _NO_EVENTS, _NO_NOISE, _NSUB, _OK, _SHEET,
                                      _STATUS, _T, _plan, interval_kernel)
from plant.state import N_STATE

__all__ = ["play_move", "prepare"]


@njit(cache=True)
def _play(x, tau, offs, levs, starts, bridge, prm, o, TP, TL, BPh, BPw, BG, BC, z, ev, last, stiction, x1):
    """x1[k] = the angle after sample k of the move from state ``x`` (mode 2, no flyback, t = 0);
    returns (kernel status code, samples done, the kernel's events and sub-steps summed). After
    sample ``last`` (u = 0 from there) the shaft is frozen once it is stuck (mode 2, no flyback)
    with x2 = 0 and |x3| ≤ k̄s (plant.identification.fit)."""
    out = np.empty(N_STATE + _SHEET)
    mode, flyback, t = np.int64(2), bool(False), 0.0    # typed, not literal: one kernel signature
    n = x1.shape[0]
    k = 0
    n_ev, n_sub = 0.0, 0.0
    while k < n:
        interval_kernel(x, mode, flyback, t, tau, offs[starts[k]:starts[k + 1]].copy(),
                        levs[starts[k]:starts[k + 1]].copy(), bridge, prm, o, TP, TL, BPh, BPw, BG, BC, z, np.int64(0), ev,
                        out)
        n_ev += out[N_STATE + _NEV]
        n_sub += out[N_STATE + _NSUB]
        code = int(out[N_STATE + _STATUS])
        if code != _OK:
            return code, k, n_ev, n_sub
        x = out[:N_STATE].copy()
        t = out[N_STATE + _T]
        mode = int(out[N_STATE + _MODE])
        flyback = out[N_STATE + _FB] != 0.0
        x1[k] = x[0]
        k += 1
        if k <= last:
            continue
        if mode == 2 and not flyback and abs(x[2]) <= stiction and x[1] == 0.0:
            x1[k:] = x[0]
            break
    return _OK, k, n_ev, n_sub


def prepare(commands) -> tuple:
    """A move's commands as the kernel reads them: (offsets, levels, first segment per sample, bridge)."""
    offs = np.concatenate([c.arrays()[0] for c in commands])
    levs = np.concatenate([c.arrays()[1] for c in commands])
    starts = np.cumsum([0] + [len(c.segments) for c in commands]).astype(np.int64)
    return offs, levs, starts, commands[0].drive.value == "bridge"


def play_move(x0, prepared, params, options, last: int) -> tuple[np.ndarray | None, tuple[int, int, int]]:
    """(x1, work): the move's angles x1 after each of its commands (``prepared`` = :func:`prepare`)
    from the state ``x0`` (t = 0, mode 2, no flyback), or None when the plant leaves ``ok``;
    ``work`` = (samples stepped, events, sub-steps), the counts ``advance`` reports per interval,
    summed. ``options``: noise off whatever they say (as ``advance`` without a noise stream).

    Raises
    ------
    ValueError
        A bridge level other than 0 and ±u_max (as ``advance``).
    """
    offs, levs, starts, bridge = prepared
    o, TP, TL, BPh, BPw, BG, BC = _plan(params, options, False)
    x1 = np.empty(starts.shape[0] - 1)
    code, k, n_ev, n_sub = _play(np.array(x0, dtype=np.float64), params.sample_period, offs, levs, starts, bridge,
                                 params.kernel_record(), o, TP, TL, BPh, BPw, BG, BC, _NO_NOISE, _NO_EVENTS, last,
                                 params.stiction, x1)
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max})")
    return (x1 if code == _OK else None), (k + (code != _OK), int(n_ev), int(n_sub))
