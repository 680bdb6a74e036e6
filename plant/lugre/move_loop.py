"""One move of the identification's noise-free model in one compiled call (issue 25, fifth session).

:class:`plant.identification.fit._Model` plays each move of a log from rest, sample by sample,
through the family's step. For lugre that step is :func:`plant.lugre.interval.advance`: the
compiled interval kernel plus ≈ 16 µs of Python per sample (argument checks, the state object).
:func:`play_move` calls the very same kernel, with the same arguments in the same order, in one
compiled loop over the move's samples, with the fit's settle test (a settled shaft is frozen).
Noise-free only (no noise stream, no event record). Predictions are bit-identical to the Python
loop over ``advance`` (tests/test_identify_speed.py). Additive: nothing else calls it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from plant.lugre.interval import (N_STATE, NO_EVENTS, SHEET_EVENTS, SHEET_FLYBACK, SHEET_MODE, SHEET_SIZE,
                                  SHEET_STATUS, SHEET_SUBSTEPS, SHEET_T, STATUS_OK, interval_kernel)

__all__ = ["play_move", "prepare"]

_BAD_LEVEL = 3    # plant.lugre.interval's status code of a bad bridge level

_NO_NOISE = np.empty(0)


@njit(cache=True)
def _play(x, tau, offs, levs, starts, bridge, prm, L, o, tol, z, ev, last, sigma0, ring, settled, x1):
    """x1[k] = the angle after sample k of the move from state ``x`` (mode 2, no flyback, t = 0);
    returns (kernel status code, samples done, the kernel's events and integrator steps summed).
    After sample ``last`` (u = 0 from there) the shaft is frozen once |z| + |x3|/σ0 + |x2|·ring ≤
    ``settled`` (plant.identification.fit)."""
    out = np.empty(N_STATE + SHEET_SIZE)
    mode, flyback, t = 2, False, 0.0
    n = x1.shape[0]
    k = 0
    n_ev, n_sub = 0.0, 0.0
    while k < n:
        interval_kernel(x, mode, flyback, t, tau, offs[starts[k]:starts[k + 1]].copy(),
                        levs[starts[k]:starts[k + 1]].copy(), bridge, prm, L, o, z, 0, ev, out, tol)
        n_ev += out[N_STATE + SHEET_EVENTS]
        n_sub += out[N_STATE + SHEET_SUBSTEPS]
        code = int(out[N_STATE + SHEET_STATUS])
        if code != STATUS_OK:
            return code, k, n_ev, n_sub
        x = out[:N_STATE].copy()
        t = out[N_STATE + SHEET_T]
        mode = int(out[N_STATE + SHEET_MODE])
        flyback = out[N_STATE + SHEET_FLYBACK] != 0.0
        x1[k] = x[0]
        k += 1
        if k <= last:
            continue
        if abs(x[7]) + abs(x[2]) / sigma0 + abs(x[1]) * ring <= settled:
            x1[k:] = x[0]
            break
    return STATUS_OK, k, n_ev, n_sub


def prepare(commands) -> tuple:
    """A move's commands as the kernel reads them: (offsets, levels, first segment per sample, bridge)."""
    offs = np.concatenate([c.arrays()[0] for c in commands])
    levs = np.concatenate([c.arrays()[1] for c in commands])
    starts = np.cumsum([0] + [len(c.segments) for c in commands]).astype(np.int64)
    return offs, levs, starts, commands[0].drive.value == "bridge"


def play_move(x0, prepared, params, options, tolerances, last: int, ring: float,
              settled: float) -> tuple[np.ndarray | None, tuple[int, int, int]]:
    """(x1, work): the move's angles x1 after each of its commands (``prepared`` = :func:`prepare`)
    from the state ``x0`` (t = 0, mode 2), or None when the plant leaves ``ok`` (the kernel's
    status, or g(v) = 0: ZeroDivisionError, where ``advance`` returns ``Status.ERROR``); ``work``
    = (samples stepped, events, integrator steps), the counts ``advance`` reports per interval,
    summed (zeros after a ZeroDivisionError, whose counts are lost with the kernel's frame).

    ``options``: the noise is off whatever they say (as ``advance`` without a noise stream).

    Raises
    ------
    ValueError
        A bridge level other than 0 and ±u_max (as ``advance``).
    """
    offs, levs, starts, bridge = prepared
    o = options.kernel_vector().copy()
    o[0] = 0.0
    x1 = np.empty(starts.shape[0] - 1)
    try:
        code, k, n_ev, n_sub = _play(np.asarray(x0, dtype=np.float64).copy(), params.sample_period, offs, levs, starts, bridge,
                        params.kernel_record(), params.law_vector(), o, tolerances, _NO_NOISE, NO_EVENTS, last,
                        params.bristle_stiffness, ring, settled, x1)
    except ZeroDivisionError:
        return None, (0, 0, 0)
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max})")
    return (x1 if code == STATUS_OK else None), (k + (code != STATUS_OK), int(n_ev), int(n_sub))
