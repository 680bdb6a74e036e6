"""A controller whose whole step is a fixed linear law: the runner may compile its loop.

A :class:`LinearLaw` says: at every sample instant n·τs, with y(n) the measurement,

    v(n) = C·x(n) + D·y(n),    x(n+1) = A·x(n) + B·y(n)                  (the realization of C(z))
    u(t) = clip(−v(n) + A_d·sq(f_d·t + φ), ±u_max),   t ∈ [n·τs, (n+1)·τs)  (LINEAR drive)

with sq(θ) = +1 for frac(θ) < ½ and −1 otherwise (no dither when A_d = 0). A controller that
returns one from :meth:`Controller.linear_law` promises that its ``step`` computes exactly
this, with :func:`plant.linear_drive.compensator_step` and
:func:`plant.linear_drive.square_wave_segments` (the same compiled code the fast path runs). The
runner then runs the closed loop in one compiled call (the plant family's ``linear_law_loop``,
e.g. :mod:`plant.multimode.law_loop`) instead of calling ``step`` at every sample, with
bit-identical results (tested); the controller's own state is not advanced then, only
its ``summary`` is read afterwards.

A :class:`CompiledLaw` is the general form (the ``compiled_law`` hook): any per-sample work
written as one numba function ``k = step(s, p, y, offs, levs)`` over a float64 state array
``s`` (advanced in place) and a float64 parameter array ``p``, writing the drive command's k
segments (:mod:`plant.law_step` has the contract, including how a step hands a sample back
to Python). The controller's Python ``step`` calls the same function on the same arrays and
turns the segments into a :class:`~plant.drive.DriveCommand` with :func:`law_command`, so the
two paths are bit-identical by construction and the controller's state after a compiled run
is its own (``summary`` and ``internals`` read ``s``). The runner runs such a controller in the
family's ``compiled_law_loop`` — with the quantized sensor and the compute delay — when nothing
is recorded. A :class:`LinearLaw` becomes one by :meth:`LinearLaw.compiled` (how a linear law
runs on a plant with a quantized sensor or a delay).

To declare one: write the step as ``@njit(cache=True)`` (compiled, or loaded from numba's
cache, at its first call: importing the controller costs nothing), keep the controller's state
in ``s`` (scalars at fixed indices), and return ``CompiledLaw(step, s, p, drive, max_segments)``
from ``compiled_law()`` after ``reset`` (which compiles it for :data:`STEP_SIGNATURE`);
``step`` in Python is then ``law_command(step(s, p, y, offs, levs), offs, levs, drive)``.
Examples: :mod:`controllers.reset_pid`, :mod:`controllers.friction_ff_pid`,
:mod:`controllers.observer_pid`; tests/test_compiled_law.py has a minimal one that hands samples
back.
"""

from __future__ import annotations

import itertools
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

try:    # numba's wrapper-address helper (semi-internal; numba 0.59-0.68 have it)
    from numba.experimental.function_type import _get_wrapper_address
except ImportError:     # pragma: no cover - a numba without it: the dispatcher itself (same rows, slower entry)
    _get_wrapper_address = None

from plant.drive import DriveCommand, DriveType
from plant.law_step import STEP_SIGNATURE, STEP_TYPE
from plant.linear_drive import square_wave_segments

__all__ = ["LinearLaw", "CompiledLaw", "law_command", "StepAddress", "step_address", "register_owner", "owner_of",
           "STEP_SIGNATURE"]


@dataclass(frozen=True)
class LinearLaw:
    """A single-input single-output compensator plus an optional square-wave dither.

    Attributes
    ----------
    A, B, C, D : ndarray
        Realization of C(z): shapes (n, n), (n, 1), (1, n), (1, 1); y in rad, v in ozf·in.
    u_max : float
        Clip bound [ozf·in].
    dither_amplitude, dither_frequency, dither_phase : float
        A_d [ozf·in] (0: none), f_d [Hz], φ [cycles].
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    u_max: float
    dither_amplitude: float = 0.0
    dither_frequency: float = 1.0
    dither_phase: float = 0.0

    def compiled(self, sample_period: float) -> "CompiledLaw":
        """The same law as a :class:`CompiledLaw` (τs = ``sample_period`` [s]): the compensator
        of :func:`plant.linear_drive.compensator_step` and the dither of
        :func:`~plant.linear_drive.square_wave_segments` in the same order of operations, the
        sample count n in ``s[0]`` (t = n·τs)."""
        A, B, C, D = (np.asarray(m, dtype=np.float64) for m in (self.A, self.B, self.C, self.D))
        n = A.shape[0]
        p = np.concatenate(([float(n), float(self.u_max), float(self.dither_amplitude),
                             float(self.dither_frequency), float(self.dither_phase), float(sample_period)],
                            A.ravel(), B.ravel(), C.ravel(), D.ravel()))
        m = int(2.0 * self.dither_frequency * sample_period) + 4 if self.dither_amplitude != 0.0 else 1
        return CompiledLaw(linear_law_step, np.zeros(1 + 2 * n), p, DriveType.LINEAR, m)


@dataclass(frozen=True)
class CompiledLaw:
    """A controller's per-sample work as one compiled function (see the module docstring).

    Attributes
    ----------
    step : numba dispatcher
        Compiles for :data:`plant.law_step.STEP_SIGNATURE` (done here if not yet):
        ``k = step(s, p, y [rad], offs [s], levs [ozf·in])``.
    state : ndarray
        ``s``, float64, C-contiguous, writable: the controller's own state (advanced in place).
    params : ndarray
        ``p``, float64, C-contiguous (not written).
    drive : DriveType
        The power stage of every command.
    max_segments : int
        Room for this many segments in ``offs``/``levs`` (≥ 1).
    truth : bool
        The step reads the true plant state (a privileged bound's, never a real controller's:
        the runner refuses it for a class without ``privileged = True``). The compiled loop
        then passes ``p`` followed by the true state at the sample instant, ``x`` (the
        family's state entries) then (t [s], mode, flyback 0/1): the step finds them at
        ``p[len(params):]``, the sheet as ``p[-3:]``, updated by the loop before every call
        (:func:`plant.law_driver.run_law_chunks`). Default False: ``p`` is ``params``.
    """

    step: Any
    state: np.ndarray
    params: np.ndarray
    drive: DriveType
    max_segments: int = 1
    truth: bool = False

    def __post_init__(self) -> None:
        for name in ("state", "params"):
            a = getattr(self, name)
            if not (isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 1 and a.flags.c_contiguous
                    and a.flags.writeable):
                raise ValueError(f"CompiledLaw.{name} must be a writable C-contiguous 1-d float64 array")
        if not isinstance(self.drive, DriveType):
            raise ValueError(f"CompiledLaw.drive must be a DriveType, got {self.drive!r}")
        if isinstance(self.max_segments, bool) or not isinstance(self.max_segments, int) or self.max_segments < 1:
            raise ValueError(f"CompiledLaw.max_segments must be an integer >= 1, got {self.max_segments!r}")
        if not isinstance(self.truth, bool):
            raise ValueError(f"CompiledLaw.truth must be true or false, got {self.truth!r}")
        if STEP_SIGNATURE.args not in getattr(self.step, "signatures", ()):
            try:                          # compiled (or loaded from numba's cache) when first needed
                self.step.compile(STEP_SIGNATURE)
            except Exception as exc:
                raise ValueError(f"CompiledLaw.step must be a numba function that compiles for "
                                 f"plant.law_step.STEP_SIGNATURE: {exc}") from None


def law_command(k: int, offs: np.ndarray, levs: np.ndarray, drive: DriveType) -> DriveCommand:
    """The :class:`DriveCommand` of a step's k segments (raising what ``DriveCommand`` raises
    for a command the compiled loop hands back)."""
    if k == 1 and offs[0] == 0.0:
        return DriveCommand.hold(levs[0], drive)
    return DriveCommand(tuple((float(offs[i]), float(levs[i])) for i in range(k)), drive)


@njit(cache=True)
def linear_law_step(s, p, y, offs, levs):
    """:class:`LinearLaw` as a compiled step: p = (n, u_max, A_d, f_d, φ, τs, A, B, C, D)
    (A row-major), s = (sample count, x, scratch for x')."""
    n = int(p[0])
    u_max, amp, freq, phase, tau = p[1], p[2], p[3], p[4], p[5]
    a0, b0, c0, d0 = 6, 6 + n * n, 6 + n * n + n, 6 + n * n + 2 * n
    v = p[d0] * y                               # compensator_step: D·y, then the C·x terms in order
    for j in range(n):
        v += p[c0 + j] * s[1 + j]
    for i in range(n):                          # each row B·y + (the A·x terms in order)
        acc = p[a0 + i * n] * s[1]
        for j in range(1, n):
            acc += p[a0 + i * n + j] * s[1 + j]
        s[1 + n + i] = p[b0 + i] * y + acc
    for i in range(n):
        s[1 + i] = s[1 + n + i]
    level = min(max(-v, -u_max), u_max)
    k = square_wave_segments(s[0] * tau, tau, level, amp, freq, phase, u_max, offs, levs)
    s[0] += 1.0
    return k


class StepAddress:
    """A compiled step as the address of its C wrapper, typed :data:`plant.law_step.STEP_TYPE`
    (numba's wrapper-address protocol): what the compiled loop receives instead of the
    dispatcher. A dispatcher passed as a first-class function is typed, and its address looked
    up, at every entry into the loop (~50 µs on the loaded 2-core machine, i.e. per hand-back);
    the address object costs ~5 µs. Called through the address, an exception inside the step
    cannot propagate: the call returns 0, the hand-back. Calling it from Python calls the
    dispatcher."""

    _numba_type_ = STEP_TYPE

    def __init__(self, dispatcher) -> None:
        dispatcher.compile(STEP_SIGNATURE)
        self.dispatcher = dispatcher
        self.signatures = [STEP_SIGNATURE.args]
        self._address = _get_wrapper_address(dispatcher, STEP_SIGNATURE)

    def __wrapper_address__(self) -> int:
        return self._address

    def __call__(self, s, p, y, offs, levs):
        return self.dispatcher(s, p, y, offs, levs)


def step_address(dispatcher):
    """``dispatcher`` as a :class:`StepAddress` for a step that hands samples back often, or the
    dispatcher itself when this numba has no wrapper-address helper (the compiled loop then types
    it at every entry: same rows, ~50 µs more per hand-back)."""
    return dispatcher if _get_wrapper_address is None else StepAddress(dispatcher)


_OWNERS: "weakref.WeakValueDictionary[int, object]" = weakref.WeakValueDictionary()
_KEYS = itertools.count(1)       # next() is atomic under the GIL: threads get distinct keys


def register_owner(controller) -> float:
    """A key (exact in float64) under which :func:`owner_of` finds ``controller`` (held weakly):
    what a compiled step keeps in ``p`` to run the controller's Python sample from inside the
    loop through numba's ``objmode`` (solnic's idle steps, oracle-pulse's firing samples)."""
    key = next(_KEYS)
    _OWNERS[key] = controller
    return float(key)


def owner_of(key: float):
    """The controller registered under ``key`` (:func:`register_owner`), or None when it is gone."""
    return _OWNERS.get(int(key))
