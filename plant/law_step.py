"""A compiled controller step and what a compiled closed loop does around it: the sensor and the delay.

The interface (the ``compiled_law`` hook, :class:`controllers.law.CompiledLaw`). A controller
whose per-sample work is a numba function of a float64 state array ``s`` (its own state,
advanced in place) and a float64 parameter array ``p`` (read only) declares it:

    k = step(s, p, y, offs, levs)          (signature :data:`STEP_SIGNATURE`)

consumes the measurement y(n) [rad] and writes the drive command for [n·τs, (n+1)·τs) as k
segments: offsets ``offs[:k]`` [s] from the sample instant (the first 0, increasing, < τs) and
levels ``levs[:k]`` [ozf·in], as :class:`plant.drive.DriveCommand` holds them. A return k ≤ 0
(or a command the Python path would reject: non-finite, offsets out of order or ≥ τs, a bridge
level other than 0, ±u_max) *hands the sample back*: the compiled loop restores ``s`` to what
it was before the call and returns; the runner does that one sample by calling the
controller's Python ``step`` (which calls the same function, so it meets the same case: it may
do in Python what the compiled step cannot, or raise what the Python path raises) and then
resumes the compiled loop at the next sample. A hand-back costs one Python sample plus one
re-entry into the compiled loop, ~70 µs together (loaded 2-core machine: a hand-back every
sample in 100 still runs a 100 s thesis cell in 0.021 s against 0.014 s without, 0.075 s in
Python; every 10th is slower than the Python loop): for rare events, not for every sample.

A family's compiled loop receives ``step`` typed as :data:`STEP_TYPE` (a numba first-class
function: one compiled, cached loop serves every controller; the call goes through a pointer).

The sensor and the delay, compiled: :func:`quantize` is :func:`plant.sensor.quantize` and
:func:`delay_segments` is :func:`plant.delay.delay_command` on arrays, in the same order of
floating-point operations (tests/test_compiled_law.py compares them on random inputs).

numba's on-disk cache keys a function on its own file only; :mod:`plant._jit_cache` drops the
cached kernels of ``plant/`` (and ``controllers/``, for the steps' helpers) when any source file
of that package changed.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, types

__all__ = ["STEP_SIGNATURE", "STEP_TYPE", "quantize", "delay_segments", "check_command", "log_events"]

_ARRAY = types.float64[::1]
STEP_SIGNATURE = types.intp(_ARRAY, _ARRAY, types.float64, _ARRAY, _ARRAY)
STEP_TYPE = types.FunctionType(STEP_SIGNATURE)


@njit(cache=True)
def quantize(value, step):
    """:func:`plant.sensor.quantize`: ``value`` [rad] on a grid of ``step`` [rad], ties up.

    ⌊r⌋ is kept as a float (exact: the floor of a double is a double; no int64 overflow), so
    r − ⌊r⌋ and ⌊r⌋·q round as Python's int arithmetic does there.
    """
    if step == 0.0:
        return value
    ratio = value / step
    if not math.isfinite(ratio):
        return value
    level = np.floor(ratio) + 0.0    # + 0.0: ⌊−0.0⌋ is −0.0, Python's int 0 is +0
    if ratio - level >= 0.5:
        level += 1.0
    return level * step


@njit(cache=True)
def check_command(k, offs, levs, period, bridge, u_max):
    """True if the k segments are what ``DriveCommand`` and the family's step accept: k ≥ 1,
    first offset 0, offsets increasing and finite and < ``period``, levels finite (and 0 or
    ±u_max within 1e-9·u_max on a bridge, as the interval kernels require)."""
    if k < 1 or k > offs.shape[0] or offs[0] != 0.0:
        return False
    prev = -1.0
    for i in range(k):
        o, v = offs[i], levs[i]
        if not (o > prev and o - o == 0.0 and v - v == 0.0) or not o < period:
            return False
        if bridge and v != 0.0 and abs(abs(v) - u_max) > 1e-9 * u_max:   # the kernels' test
            return False
        prev = o
    return True


@njit(cache=True)
def _append(o_arr, l_arr, n, offset, level):
    # plant.delay._append on (o_arr, l_arr)[:n]; returns the new length
    if n > 0 and offset <= o_arr[n - 1]:
        n -= 1
    if n > 0 and l_arr[n - 1] == level:
        return n
    o_arr[n] = offset
    l_arr[n] = level
    return n + 1


@njit(cache=True)
def delay_segments(offs, levs, k, pend_o, pend_l, n_pend, delay, period, now_o, now_l, carry_o, carry_l):
    """:func:`plant.delay.delay_command`: the segments in force over this interval into
    (now_o, now_l) and the pending ones for the next into (carry_o, carry_l); returns their
    counts (n_now, n_carry). ``(pend_o, pend_l)[:n_pend]`` is the previous call's carry (at the
    first interval the hold of 0: ``[(0, 0)]``). The command must have passed :func:`check_command`.
    """
    n_now = 0
    for i in range(n_pend):
        if pend_o[i] < delay:
            n_now = _append(now_o, now_l, n_now, pend_o[i], pend_l[i])
    n_carry = 0
    for i in range(k):
        start = offs[i] + delay
        if start < period:
            n_now = _append(now_o, now_l, n_now, start, levs[i])
        else:
            if n_carry == 0:
                carry_o[0] = 0.0
                carry_l[0] = now_l[n_now - 1]
                n_carry = 1
            n_carry = _append(carry_o, carry_l, n_carry, start - period, levs[i])
    if n_carry == 0:
        carry_o[0] = 0.0
        carry_l[0] = now_l[n_now - 1]
        n_carry = 1
    return n_now, n_carry


@njit(cache=True)
def log_events(xe, prog, ev, k):
    """The x1 log of a compiled loop (:class:`plant.law_driver.X1Log`): append the interval's
    ``k`` plant events (t [s], x1 [rad]) of ``ev`` to ``xe`` at row ``prog[3]``, and advance it."""
    m = prog[3]
    for i in range(k):
        xe[m + i, 0], xe[m + i, 1] = ev[i, 0], ev[i, 1]
    prog[3] = m + k
