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
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from plant.randomness import NoiseExhausted, NoiseStream
from plant.state import EVENT_FIELDS, PlantState, SimOptions, Status

__all__ = ["run_chunks", "run_law_chunks", "LawRun", "X1Log", "CHUNK", "NOISE_MARGIN", "NEED_NOISE", "NEED_ROOM",
           "HAND_BACK", "TOTAL_FIELDS"]

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
    x_view = x.view()     # writable, as every caller of the interval kernels passes it (docs/plant.md)
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


# --------------------------------------------------------------------------- a compiled controller step

HAND_BACK = -2   # the chunk's code: the controller's step handed the current sample back to Python
NEED_ROOM = -3   # the chunk's code: the x1 log's event rows must grow before the next interval
_NO_LOG = np.empty((0, 2))


class X1Log:
    """t [s] and x1 [rad] at every sample instant and every plant event of one run: what a
    recorded run's samples and events give ``bench.series.phase_peaks``, without the rest.

    ``samples`` (one row per sample instant, (t, x1) before the step), ``events`` (one row per
    plant event, in time order; grown on demand) and ``scratch``, the interval kernels' event
    records (:data:`plant.state.EVENT_FIELDS` columns). The compiled loop writes them
    (:func:`run_law_chunks`), the runner's Python loop with :meth:`sample` and :meth:`add_events`.
    """

    def __init__(self, n_samples: int) -> None:
        self.samples = np.empty((n_samples, 2))
        self.n_samples = 0
        self.events = np.empty((8192, 2))
        self.n_events = 0
        self.scratch = np.empty((4096, len(EVENT_FIELDS)))

    def sample(self, n: int, t: float, x1: float) -> None:
        self.samples[n, 0], self.samples[n, 1] = t, x1
        self.n_samples = n + 1

    def room(self, k: int) -> None:
        """At least ``k`` free event rows."""
        if self.events.shape[0] - self.n_events < k:
            grown = np.empty((max(2 * self.events.shape[0], self.n_events + k), 2))
            grown[:self.n_events] = self.events[:self.n_events]
            self.events = grown

    def add_events(self, t: np.ndarray, x1: np.ndarray) -> None:
        k = len(t)
        self.room(k)
        self.events[self.n_events:self.n_events + k, 0] = t
        self.events[self.n_events:self.n_events + k, 1] = x1
        self.n_events += k

    def arrays(self) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """(samples, events) as ``{"t": ..., "x1": ...}`` arrays."""
        s, e = self.samples[:self.n_samples], self.events[:self.n_events]
        return ({"t": s[:, 0].copy(), "x1": s[:, 1].copy()}, {"t": e[:, 0].copy(), "x1": e[:, 1].copy()})
_SPECIALISED: dict[tuple, Callable[..., int]] = {}


def _specialised(py_chunk: Callable[..., int], args: tuple) -> Callable[..., int]:
    """``py_chunk`` compiled (cache=True) for these arguments with the first one, the step, typed
    as the first-class function :data:`plant.law_step.STEP_TYPE`: one machine-code loop for every
    controller, loaded from numba's cache in a fresh process (a step passed as a dispatcher would
    specialise the loop on each function and miss the cache every time)."""
    import numba

    from plant.law_step import STEP_TYPE
    sig = (STEP_TYPE, *(numba.typeof(a) for a in args[1:]))
    key = (py_chunk, sig)
    fn = _SPECIALISED.get(key)
    if fn is None:
        fn = _SPECIALISED[key] = numba.njit(sig, cache=True)(py_chunk)
    return fn


@dataclass
class LawRun:
    """What :func:`run_law_chunks` returns to the runner.

    ``state`` is the plant state after ``n_done`` samples; ``sums`` the scoring window's sums
    (:data:`TOTAL_FIELDS`) so far (x1 at the window's sample instants is written into the
    caller's array). ``handed_back``: the controller handed sample ``n_done`` back; the runner
    does it in Python and may resume here. ``pending`` is the compute delay's carry-over
    (offsets, levels), or None without a delay.
    """

    state: PlantState
    sums: dict[str, float]
    status: Status
    message: str
    n_done: int
    handed_back: bool
    pending: tuple[np.ndarray, np.ndarray] | None


_LAST: dict[Callable[..., int], Callable[..., int]] = {}


def run_law_chunks(chunk: Callable[..., int], family_args: tuple, law: Any, params: Any, options: SimOptions,
                   state: PlantState, sensor: np.ndarray, n_warm: int, noise: NoiseStream | None, noisy: bool,
                   deadline: float, *, n_state: int, sheet_size: int, no_events: np.ndarray, status_ok: int,
                   interval_status: Callable[[int, PlantState, SimOptions], tuple[Status, str]],
                   n0: int = 0, sums: dict[str, float] | None = None, x1_window: np.ndarray | None = None,
                   pending: tuple[np.ndarray, np.ndarray] | None = None, log: X1Log | None = None,
                   record_full: type[BaseException] | tuple = ()) -> LawRun:
    """Run samples ``n0`` ≤ n < ``len(sensor)`` of a compiled controller step ``law`` from ``state``.

    ``law`` has the attributes of ``controllers.law.CompiledLaw`` (step, state, params, drive,
    max_segments); its ``state`` is advanced in place. ``chunk`` is a family's plain Python
    chunk function with the argument layout

    ``chunk(step, s, p, s_back, bridge, u_max, quant, delay, pend_o, pend_l, offs, levs, now_o,
    now_l, carry_o, carry_l, n0, n1, n_warm, sensor, x, x_view, sheet, tau, prm, *family_args, z,
    zpos, margin, ev, out, totals, x1_window, prog, xs, xe)``

    (``prog``: samples done, noise position, pending segments, events logged); it returns a kernel
    status code, :data:`NEED_NOISE`, :data:`NEED_ROOM` or :data:`HAND_BACK`. With ``log``
    (:class:`X1Log`) the chunk writes t and x1 of every sample and plant event into it (the
    kernel records events into ``log.scratch``, raising ``record_full``, the family's exception,
    when one interval has more: the sample is then undone and redone with a larger scratch). Sensor (quantized when ``params.quantization`` > 0)
    and compute delay (``params.command_delay``) as :meth:`plant.protocol.PlantFamily.observe`
    and ``delayed_step`` do them. The wall-clock limit as in :func:`run_chunks`.

    A run resumed at ``n0`` > 0 (after a sample done in Python) continues the window ``sums``
    (:data:`TOTAL_FIELDS`), writes x1 into ``x1_window`` at index n − ``n_warm`` (the caller's
    array, length ``len(sensor) − n_warm + 1``; the final x1 is the caller's to add) and starts
    from the delay's carry-over ``pending`` (None: nothing commanded yet, the hold of 0).

    A ``law`` with ``truth`` set (a privileged bound's; the runner checks that) gets as ``p`` its
    ``params`` followed by the plant state and the sheet (t, mode, flyback) the chunk advances in
    place: the chunk's ``x`` and ``sheet`` are views into that tail, so the step reads the true
    state at every sample instant without a change to any family's chunk.
    """
    n_samples = sensor.shape[0]
    prm = params.kernel_record()
    s = law.state
    s_back = s.copy()
    m = int(law.max_segments)
    offs, levs = np.zeros(m), np.zeros(m)
    w = 2 * m + 2
    pend_o, pend_l, now_o, now_l, carry_o, carry_l = (np.zeros(w) for _ in range(6))
    prog = np.zeros(4, dtype=np.int64)
    if pending is None:
        prog[2] = 1   # before the first command: the hold of 0 (plant.delay)
    else:
        k = pending[0].shape[0]
        if k > w:
            pend_o, pend_l, now_o, now_l, carry_o, carry_l = (np.zeros(k + w) for _ in range(6))
        pend_o[:k], pend_l[:k] = pending
        prog[2] = k
    bridge = law.drive.value == "bridge"
    x = np.array(state.x, dtype=np.float64)
    sheet = np.array([state.t, float(state.mode), 1.0 if state.flyback else 0.0])
    p = law.params
    if getattr(law, "truth", False):   # a privileged step reads the truth: x and the sheet live in p's tail
        m, k = p.shape[0], x.shape[0]
        p = np.concatenate((p, x, sheet))
        x, sheet = p[m:m + k], p[m + k:]
    x_view = x.view()     # writable, as every caller of the interval kernels passes it (docs/plant.md)
    out = np.empty(n_state + sheet_size)
    totals = np.zeros(len(TOTAL_FIELDS))
    if sums is not None:
        totals[:] = [sums[name] for name in TOTAL_FIELDS]
    if x1_window is None:
        x1_window = np.empty(n_samples - n_warm + 1)
    if noisy:
        z, zpos = noise.window()
    else:
        z, zpos = np.empty(0), 0
    margin = NOISE_MARGIN if noisy else 0
    if log is not None:
        xs, xe, no_events = log.samples, log.events, log.scratch
        prog[3] = log.n_events
    else:
        xs = xe = _NO_LOG
    head = (law.step, s, p, s_back, bridge, float(params.u_max), float(params.quantization),
            float(params.command_delay), pend_o, pend_l, offs, levs, now_o, now_l, carry_o, carry_l)
    fn = _LAST.get(chunk)
    n, code = n0, status_ok
    while n < n_samples:
        stop = min(n + CHUNK, n_samples)
        args = (*head, n, stop, n_warm, sensor, x, x_view, sheet, params.sample_period, prm, *family_args, z, zpos,
                margin, no_events, out, totals, x1_window, prog, xs, xe)
        if fn is None:
            fn = _LAST[chunk] = _specialised(chunk, args)
        try:
            code = fn(*args)
        except NoiseExhausted:        # one interval wanted more than the margin: undo its step, extend, redo
            s[:] = s_back
            code = NEED_NOISE
        except record_full:           # one interval had more events than the log's scratch: undo, enlarge, redo
            s[:] = s_back
            log.scratch = no_events = np.empty((4 * no_events.shape[0], no_events.shape[1]))
            code = NEED_ROOM
        except TypeError:             # other argument types than the last call's: compile (or load) for them
            if fn is _specialised(chunk, args):
                raise
            fn = None
            continue
        n, zpos = int(prog[0]), int(prog[1])
        if log is not None:
            log.n_events = int(prog[3])
            log.n_samples = max(log.n_samples, n)
        if code == NEED_ROOM:
            log.room(no_events.shape[0])
            xe = log.events
            continue
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
    if x.base is not None:
        x = x.copy()                  # the truth's view into p: the final state owns its entries
    x.flags.writeable = False
    final = PlantState(float(sheet[0]), x, int(sheet[1]), sheet[2] != 0.0)
    handed_back = code == HAND_BACK
    if handed_back:
        status, message = Status.OK, ""
    elif code != status_ok:
        status, message = interval_status(code, final, options)
    elif n < n_samples:
        status = Status.ERROR
        message = "time limit exceeded"   # completed by the runner
    else:
        status, message = Status.OK, ""
    sums = {name: (float(v) if i < _N_FLOAT_TOTALS else int(v)) for i, (name, v) in enumerate(zip(TOTAL_FIELDS, totals))}
    k = int(prog[2])
    pend = (pend_o[:k].copy(), pend_l[:k].copy()) if params.command_delay != 0.0 and n > 0 else None
    return LawRun(final, sums, status, message, n, handed_back, pend)
