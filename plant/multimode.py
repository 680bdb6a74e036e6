"""Exact event-driven simulation by multimode linearization (chapters 3 and 4).

Between events the plant is linear and time-invariant, so the state jumps from event to event
with X⁺ = Φ(h)·X + N, where Φ is the closed form (3-20)–(3-22) and N is Gaussian with
covariance (4-8), drawn with the minimal factor (4-20). The events are

* sample instants and command level changes (the caller's schedule);
* the end of flyback, x3 = 0 (closed form, section 4.5);
* breakaway, |x3| = ks while stuck (closed form: x3 is deterministic);
* the end of the reflection regime, when the torque in the direction of motion falls
  below ks (closed form);
* velocity zero in a moving mode.

Velocity zero (SPEC §2):

* noise-free, or σ2 = 0: the first root of the closed-form mean velocity, bracketed at the
  single extremum of x2 (x3 is monotone, so ẋ2 changes sign at most once) and polished
  with Brent's method to ~1e-15 s;
* ``zero_velocity="bridge"`` (default): exact Gaussian sub-steps; a crossing is a sign change
  or, with both ends on one side, happens with the Brownian-bridge probability
  exp(−2·v_a·v_b/(α²σ2²·h)); it is located by bridge bisection, each midpoint drawn from its
  Gaussian law given both ends (by Matheron's rule), rejected in proportion to the
  probability that the halves contain no crossing, so the located time has the exact law of
  the first crossing of the bridge;
* ``zero_velocity="newton"``: the seed's method (4-38): Z held fixed, Newton on the velocity.

While the torque in the direction of motion still exceeds ks, a zero crossing is reflected
(the shaft cannot stick and friction cannot reverse it). Sub-steps there add the Skorokhod
push: the bridge minimum of x2 is drawn exactly, m = ½(v_a + v_b − √((v_b − v_a)² −
2α²σ2²h·ln U)), and x2 is lifted by max(0, −m); x1 receives the push for half the sub-step.

The Coulomb and stiction levels are kc = k̄c + x5 and ks = k̄s + x5, clamped at 0. The clamp
of kc is applied per segment: should k̄c + x5 be negative at the start of a moving segment,
the segment runs with kc = 0 (a 4.7σ event for Table 2-1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import brentq

from plant.drive import DriveCommand, DriveType
from plant._kernels import chol_psd, moving_noisy, phi_moving, q_moving
from plant.noise import NoiseFactor, noise_factor
from plant.params import PlantParams
from plant.segments import hermite_peak, torque_crossing_time, torque_integrals
from plant.transition import U, X1, X2, X3, X4, X5, X6, N_STATE, e1, phi, process_noise

__all__ = ["PlantState", "SimOptions", "Accumulator", "Status", "advance", "initial_state"]

_NOISY_MOVING = np.array([X1, X2, X4, X5])


class Status:
    OK = "ok"
    CHATTER = "chatter"
    DIVERGED = "diverged"
    ERROR = "error"


@dataclass
class PlantState:
    """Plant state at time ``t`` [s]: X as in (3-5), the mode, and whether flyback is on."""

    t: float
    X: np.ndarray
    mode: int = 2
    flyback: bool = False

    def copy(self) -> "PlantState":
        return PlantState(self.t, self.X.copy(), self.mode, self.flyback)

    @property
    def error(self) -> float:
        return float(self.X[X1])


def initial_state(params: PlantParams, x5: float = 0.0, x4: float | None = None) -> PlantState:
    """Shaft stuck at zero error, no current, x4 = ``command_velocity_initial`` unless given."""
    X = np.zeros(N_STATE)
    X[X4] = params.command_velocity_initial if x4 is None else x4
    X[X5] = x5
    X[X6] = params.coulomb
    return PlantState(0.0, X, 2, False)


@dataclass(frozen=True)
class SimOptions:
    """How the exact simulator treats noise and velocity zeros.

    Attributes
    ----------
    noise : bool
        Draw the process noise (w2, w4, w5). Off gives the deterministic plant.
    zero_velocity : {"bridge", "newton"}
        Locator of a noisy velocity zero (see module docstring).
    substep : float
        Gaussian sub-step inside moving segments [s].
    reflect_substep : float
        Sub-step while zero crossings are reflected [s]. The reflected x2 is exact at any
        step; its push enters x1 as ½·L·h, whose bias shrinks like √h (see module docstring).
    bisection_tol : float
        Width [s] at which bridge bisection stops (≤ 1 µs by SPEC). At 1 µs the position
        error it leaves is |x2|·1 µs ≈ 1e-9 rad, a thousandth of the smallest corrections.
    max_events : int
        Events plus sub-steps allowed in one call before the run ends as ``chatter``.
    diverge_error : float
        |x1| [rad] beyond which the run ends as ``diverged``.
    """

    noise: bool = True
    zero_velocity: str = "bridge"
    substep: float = 1e-4
    reflect_substep: float = 1e-5
    bisection_tol: float = 1e-6
    max_events: int = 200_000
    diverge_error: float = 1.0

    def __post_init__(self) -> None:
        if self.zero_velocity not in ("bridge", "newton"):
            raise ValueError(f"SimOptions.zero_velocity must be 'bridge' or 'newton', got {self.zero_velocity!r}")
        if not (0 < self.substep <= 1e-2):
            raise ValueError(f"SimOptions.substep must be in (0, 0.01] s, got {self.substep!r}")
        if not (0 < self.reflect_substep <= 1e-2):
            raise ValueError(f"SimOptions.reflect_substep must be in (0, 0.01] s, got {self.reflect_substep!r}")
        if not (0 < self.bisection_tol <= 1e-6):
            raise ValueError(f"SimOptions.bisection_tol must be in (0, 1e-6] s, got {self.bisection_tol!r}")
        if self.max_events < 1:
            raise ValueError(f"SimOptions.max_events must be >= 1, got {self.max_events!r}")


@dataclass
class Accumulator:
    """Exact running integrals and counts for the metrics of SPEC §3 (only while ``active``,
    i.e. inside the scoring window)."""

    active: bool = True
    duration: float = 0.0
    peak_abs_error: float = 0.0
    int_abs_current: float = 0.0
    int_sq_current: float = 0.0
    supply_charge: float = 0.0
    n_events: int = 0
    n_breakaways: int = 0
    n_sticks: int = 0
    n_substeps: int = 0

    def merge_peak(self, value: float) -> None:
        if self.active and value > self.peak_abs_error:
            self.peak_abs_error = value


Recorder = Callable[[float, np.ndarray, int], None]


class _Run:
    """Mutable working set for one call of :func:`advance` (not part of the API)."""

    def __init__(self, state: PlantState, params: PlantParams, rng: np.random.Generator | None,
                 opts: SimOptions, acc: Accumulator, rec: Recorder | None, drive: DriveType) -> None:
        self.t = state.t
        self.X = state.X.copy()
        self.mode = state.mode
        self.flyback = state.flyback
        self.p = params
        self.rng = rng
        self.opts = opts
        self.acc = acc
        self.rec = rec
        self.drive = drive
        self.noisy = opts.noise and rng is not None
        self.sigma_v2 = params.alpha**2 * params.sigma2_sq   # diffusion of x2 [rad²/s³]
        self.count = 0
        self.cache = _cache_for(params)

    # --- friction levels -------------------------------------------------------------------
    def ks(self) -> float:
        return max(self.p.stiction + self.X[X5], 0.0)

    def kc(self) -> float:
        return max(self.p.coulomb + self.X[X5], 0.0)

    # --- bookkeeping -------------------------------------------------------------------------
    def tick(self) -> None:
        self.count += 1
        if self.count > self.opts.max_events:
            raise _Stop(Status.CHATTER, f"more than {self.opts.max_events} events in one interval at t={self.t:.6f} s")

    def event(self) -> None:
        if self.acc.active:
            self.acc.n_events += 1
        self.tick()
        if self.rec is not None:
            self.rec(self.t, self.X, self.mode)

    def torque_metrics(self, x3: float, u: float, h: float) -> None:
        if not self.acc.active or h <= 0:
            return
        integral, absolute, square = torque_integrals(x3, u, h, self.p.motor_time_constant)
        self.acc.int_abs_current += absolute
        self.acc.int_sq_current += square
        if self.drive is DriveType.BRIDGE:
            self.acc.supply_charge += (u / self.p.u_max) * integral   # on: draws i; flyback: returns it
        else:
            self.acc.supply_charge += absolute                          # linear stage draws |i|
        self.acc.duration += h

    def check_finite(self) -> None:
        x1 = self.X[X1]
        if not math.isfinite(x1) or abs(x1) > self.opts.diverge_error:
            raise _Stop(Status.DIVERGED, f"|x1| = {abs(x1):.3g} rad at t={self.t:.6f} s")


class _Stop(Exception):
    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


# --- cached per-h matrices ---------------------------------------------------------------

class _Cache:
    def __init__(self, params: PlantParams) -> None:
        self.p = params
        self.phis: dict[tuple[int, float], np.ndarray] = {}
        self.factors: dict[tuple[int, float], NoiseFactor] = {}
        self.b3_b4_s4 = (params.beta3, params.beta4, params.sigma4_sq)
        self.pv = np.array([params.alpha, params.beta3, params.beta4, params.beta5,
                            params.sigma2_sq, params.sigma4_sq, params.sigma5_sq])

    def phi(self, mode: int, h: float) -> np.ndarray:
        key = (mode, h)
        P = self.phis.get(key)
        if P is None:
            if mode == 2:
                P = phi(mode, h, self.p)
            else:                       # the same closed forms, compiled (tested equal)
                P = np.empty((N_STATE, N_STATE))
                phi_moving(mode, h, self.pv, P)
            if len(self.phis) < 20000:
                self.phis[key] = P
        return P

    def factor(self, mode: int, h: float) -> NoiseFactor:
        key = (mode, h)
        f = self.factors.get(key)
        if f is None:
            if mode == 2:
                f = noise_factor(process_noise(mode, h, self.p))
            else:                       # compiled quadrature of (4-8) and PSD Cholesky (tested equal)
                Q = np.empty((4, 4))
                L = np.empty((4, 4))
                q_moving(mode, h, self.pv, Q)
                chol_psd(Q, L)
                f = NoiseFactor(_NOISY_MOVING, L, N_STATE)
            if len(self.factors) < 20000:
                self.factors[key] = f
        return f


_CACHES: dict[PlantParams, _Cache] = {}


def _cache_for(params: PlantParams) -> _Cache:
    c = _CACHES.get(params)
    if c is None:
        if len(_CACHES) > 64:
            _CACHES.clear()
        c = _CACHES[params] = _Cache(params)
    return c


# --- the public pure step -------------------------------------------------------------------

def advance(state: PlantState, command: DriveCommand, duration: float, params: PlantParams,
            rng: np.random.Generator | None, *, options: SimOptions = SimOptions(),
            acc: Accumulator | None = None, recorder: Recorder | None = None,
            ) -> tuple[PlantState, str, str]:
    """Advance the plant over one command interval of ``duration`` seconds.

    Parameters
    ----------
    state : PlantState
        Start state; not modified.
    command : DriveCommand
        Levels for [t, t + duration); segment offsets beyond ``duration`` are ignored.
    rng : numpy.random.Generator or None
        Plant-noise stream. ``None`` (or ``options.noise=False``) runs noise-free.
    acc : Accumulator, optional
        Receives the exact metric integrals of the interval.
    recorder : callable(t, X, mode), optional
        Called at every event.

    Returns
    -------
    (new_state, status, message)
        ``status`` is one of ``ok``, ``chatter``, ``diverged``; the state is where the run
        stopped.
    """
    if not (duration > 0 and math.isfinite(duration)):
        raise ValueError(f"duration must be a finite positive number of seconds, got {duration!r}")
    acc = acc if acc is not None else Accumulator()
    run = _Run(state, params, rng, options, acc, recorder, command.drive)
    t_start = state.t
    segs = command.segments
    try:
        for k, (offset, level) in enumerate(segs):
            if offset >= duration:
                break
            t_seg_end = t_start + (segs[k + 1][0] if k + 1 < len(segs) and segs[k + 1][0] < duration else duration)
            _apply_level(run, level)
            if k > 0:
                run.event()
            while run.t < t_seg_end:
                if run.mode == 2:
                    _stuck(run, t_seg_end)
                else:
                    _moving(run, t_seg_end)
                run.check_finite()
    except _Stop as stop:
        return PlantState(run.t, run.X, run.mode, run.flyback), stop.status, stop.message
    run.t = t_start + duration
    return PlantState(run.t, run.X, run.mode, run.flyback), Status.OK, ""


def _apply_level(run: _Run, level: float) -> None:
    U_ = run.p.u_max
    if run.drive is DriveType.LINEAR:
        run.X[U] = min(max(level, -U_), U_)
        run.flyback = False
        return
    if level != 0.0 and not math.isclose(abs(level), U_, rel_tol=1e-9):
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({U_}), got {level!r}")
    if level > 0:
        run.X[U], run.flyback = U_, False
    elif level < 0:
        run.X[U], run.flyback = -U_, False
    elif run.X[X3] != 0.0:
        run.X[U], run.flyback = -math.copysign(U_, run.X[X3]), True   # diodes conduct
    else:
        run.X[U], run.flyback = 0.0, False


def _flyback_time(run: _Run) -> float:
    if not run.flyback:
        return math.inf
    return run.p.motor_time_constant * math.log1p(abs(run.X[X3]) / run.p.u_max)


def _end_flyback(run: _Run) -> None:
    run.X[X3] = 0.0
    run.X[U] = 0.0
    run.flyback = False


# --- mode 2: stuck ------------------------------------------------------------------------

def _stuck(run: _Run, t_end: float) -> None:
    p = run.p
    x3, u = run.X[X3], run.X[U]
    ks = run.ks()
    h_end = t_end - run.t
    h_fb = _flyback_time(run)
    if -ks < u < ks and -ks <= x3 <= ks:
        h_up = h_dn = math.inf          # x3 heads to u inside (−ks, ks): no breakaway possible
    else:
        h_up = torque_crossing_time(x3, u, ks, p.motor_time_constant)
        h_dn = torque_crossing_time(x3, u, -ks, p.motor_time_constant)
    if x3 > ks or (x3 == ks and u > ks):
        h_up = 0.0      # already at (or past) stiction and rising: breaks away now
    elif x3 < -ks or (x3 == -ks and u < -ks):
        h_dn = 0.0
    h = min(h_end, h_fb, h_up, h_dn)
    x1_before = run.X[X1]
    run.torque_metrics(x3, u, h)
    _stuck_propagate(run, h)
    run.acc.merge_peak(max(abs(x1_before), abs(run.X[X1])))   # x1 is monotone while stuck
    if h == h_end:
        run.t = t_end
        return
    run.t += h
    if h == h_fb:
        _end_flyback(run)
    else:
        run.X[X3] = ks if h == h_up else -ks
        run.X[X2] = 0.0
        run.mode = 3 if h == h_up else 1
        run.acc.n_breakaways += run.acc.active
    run.event()


def _stuck_propagate(run: _Run, h: float) -> None:
    """Mode 2 over h: Φ_2 of (3-22) and its (x1, x4) noise (4-11), both in closed form.

    With y = β4·h and E = 1 − e^(−y): COV = σ4²·[[(y − E − E²/2)/β4³, −E²/(2β4²)],
    [·, E(2 − E)/(2β4)]], the exact integral of (4-8) for the OU command velocity.
    Drawn as a 2 × 2 Cholesky factor with two unit normals, as the general factor does.
    """
    X = run.X
    b3, b4, s4 = run.cache.b3_b4_s4
    y = b4 * h
    E = -math.expm1(-y)
    x4 = X[X4]
    X[X1] -= x4 * E / b4                                  # q14
    X[X4] = x4 * (1.0 - E)                                # q44
    X[X3] = X[U] + (X[X3] - X[U]) * math.exp(-b3 * h)
    if run.noisy and s4 > 0:
        c11 = s4 * _e4(y) / b4**3
        c14 = -s4 * E * E / (2.0 * b4 * b4)
        c44 = s4 * E * (2.0 - E) / (2.0 * b4)
        l11 = math.sqrt(max(c11, 0.0))
        l21 = c14 / l11 if l11 > 0.0 else 0.0      # zero-length step (breakaway at once)
        l22 = math.sqrt(max(c44 - l21 * l21, 0.0))
        z1, z2 = run.rng.standard_normal(2)
        X[X1] += l11 * z1
        X[X4] += l21 * z1 + l22 * z2


def _e4(y: float) -> float:
    """∫₀^y (1 − e^(−s))² ds = y − E − E²/2 with E = 1 − e^(−y), without cancellation."""
    if y >= 0.5:
        E = e1(y)
        return y - E - 0.5 * E * E
    # Σ_{k≥2} (−1)^k (2^k − 2) y^(k+1)/(k+1)!
    total, fact, k = 0.0, 6.0, 2
    power = y**3
    while k < 40:
        term = (2.0**k - 2.0) * power / fact
        total += term if k % 2 == 0 else -term
        if term <= 1e-17 * total:
            break
        k += 1
        power *= y
        fact *= k + 1
    return total


def _draw(run: _Run, mode: int, h: float) -> np.ndarray:
    f = run.cache.factor(mode, h)
    return f.sample(run.rng.standard_normal(f.m))


# --- modes 1 and 3: moving ------------------------------------------------------------------

def _moving(run: _Run, t_end: float) -> None:
    p = run.p
    s = 1.0 if run.mode == 3 else -1.0
    x3, u = run.X[X3], run.X[U]
    ks = run.ks()
    restore_kc = None
    if p.coulomb + run.X[X5] < 0.0:
        restore_kc, run.X[X6] = run.X[X6], -run.X[X5]   # clamp kc at 0 for this segment
    h_end = t_end - run.t
    h_fb = _flyback_time(run)
    # At breakaway x3 = ±ks exactly and still rising: that is inside the reflection regime.
    reflecting = s * x3 > ks or (s * x3 == ks and s * u > ks)
    h_reg = math.inf
    if reflecting and s * u < ks:
        h_reg = torque_crossing_time(x3, u, s * ks, p.motor_time_constant)
        if h_reg == math.inf:          # within rounding of ks and heading below it
            reflecting = False
    h = min(h_end, h_fb, h_reg)
    try:
        if run.noisy and run.sigma_v2 > 0.0 and (reflecting or run.opts.zero_velocity == "bridge"):
            stopped = _kernel_segment(run, h, reflecting)
        elif reflecting:
            _advance_moving(run, h)
            stopped = False
        elif run.noisy and run.sigma_v2 > 0.0:
            stopped = _newton_zero(run, h)
        else:
            stopped = _advance_to_zero_or(run, h)
    finally:
        if restore_kc is not None:
            run.X[X6] = restore_kc
    if stopped:
        _velocity_zero(run)
        run.event()
        return
    if h == h_end:
        run.t = t_end
        return
    if h == h_fb:
        _end_flyback(run)
    else:
        run.X[X3] = s * ks              # end of the reflection regime: exactly at stiction
    run.event()


def _kernel_segment(run: _Run, h: float, reflecting: bool) -> bool:
    """Noisy moving segment in the compiled kernel (same mathematics as the Python path)."""
    x3, u = run.X[X3], run.X[U]
    X = run.X.copy()
    sub = run.opts.reflect_substep if reflecting else run.opts.substep
    budget = max(run.opts.max_events - run.count, 1)
    peak0 = run.acc.peak_abs_error if run.acc.active else 0.0
    advanced, stopped, peak, n, chattered = moving_noisy(
        X, run.mode, h, reflecting, sub, run.opts.bisection_tol, run.cache.pv, run.rng, peak0, budget)
    run.X = X
    run.torque_metrics(x3, u, advanced)
    run.acc.merge_peak(peak)
    run.acc.n_substeps += n if run.acc.active else 0
    run.count += n
    run.t += advanced
    if chattered:
        raise _Stop(Status.CHATTER, f"more than {run.opts.max_events} events in one interval at t={run.t:.6f} s")
    return stopped


def _velocity_zero(run: _Run) -> None:
    """x2 has reached 0 in mode 1 or 3: reflect, reverse or stick (SPEC §2 switching table)."""
    s = 1.0 if run.mode == 3 else -1.0
    x3, ks = run.X[X3], run.ks()
    run.X[X2] = 0.0
    if s * x3 > ks:
        return                                   # torque still breaks stiction forward
    if -s * x3 > ks:
        run.mode = 1 if run.mode == 3 else 3     # breaks stiction the other way
        run.acc.n_breakaways += run.acc.active
        return
    run.mode = 2
    run.acc.n_sticks += run.acc.active


def _mean_velocity(run: _Run, tau: float) -> float:
    P = run.cache.phi(run.mode, tau) if tau > 0 else None
    return run.X[X2] if P is None else float(P[X2] @ run.X)


def _first_zero_deterministic(run: _Run, h: float) -> float:
    """First τ in (0, h] where the mean velocity reaches 0, or inf (exact to ~1e-15 s)."""
    s = 1.0 if run.mode == 3 else -1.0
    f = lambda tau: _mean_velocity(run, tau)
    # ẋ2 ∝ x3(τ) − s·kc changes sign once at most: x2's only extremum.
    t_ext = torque_crossing_time(run.X[X3], run.X[U], s * run.kc(), run.p.motor_time_constant)
    if s * run.X[X2] <= 0.0:
        return 0.0          # at zero velocity below stiction: sticks at once
    lo = 0.0
    for hi in ((t_ext, h) if 0.0 < t_ext < h else (h,)):
        if s * f(hi) <= 0.0:
            return brentq(f, lo, hi, xtol=1e-16, rtol=8.9e-16, maxiter=200)
        lo = hi
    return math.inf


def _advance_to_zero_or(run: _Run, h: float) -> bool:
    """Advance a non-reflecting moving segment without white velocity noise by h, or to the
    first zero of its mean velocity. True when it ended at a velocity zero (x2 = 0)."""
    tau = _first_zero_deterministic(run, h)
    if tau <= h:
        _advance_moving(run, tau)
        run.X[X2] = 0.0
        return True
    _advance_moving(run, h)
    return False


def _advance_moving(run: _Run, h: float) -> None:
    """Exact propagation over h of a moving segment without white velocity noise, with metrics.

    (Segments with σ2 > 0 go through the compiled kernel, plant._kernels.moving_noisy.)
    """
    if h <= 0:
        return
    x3, u = run.X[X3], run.X[U]
    run.torque_metrics(x3, u, h)
    _deterministic_move(run, h)
    if run.noisy:
        # σ2 = 0: the path is the mean path plus the slow x4/x5 diffusions, so one exact
        # Gaussian jump suffices; the peak comes from the mean path's exact interior extrema
        # (the noise there is ~1e-15 rad over a segment).
        run.X = run.X + _draw(run, run.mode, h)
        run.acc.merge_peak(abs(run.X[X1]))


def _deterministic_move(run: _Run, h: float) -> None:
    x1_start = abs(run.X[X1])
    run.acc.merge_peak(x1_start)
    if run.acc.active:
        for tau in _x1_extrema(run, h):
            run.acc.merge_peak(abs(run.cache.phi(run.mode, tau)[X1] @ run.X))
    run.X = run.cache.phi(run.mode, h) @ run.X
    run.t += h
    run.acc.merge_peak(abs(run.X[X1]))


def _x1_extrema(run: _Run, h: float) -> list[float]:
    """Interior roots of ẋ1 = x2 − x4 on (0, h) for the noise-free path (exact)."""
    s = 1.0 if run.mode == 3 else -1.0
    g = lambda tau: float((run.cache.phi(run.mode, tau)[X2] - run.cache.phi(run.mode, tau)[X4]) @ run.X) \
        if tau > 0 else run.X[X2] - run.X[X4]
    t_ext = torque_crossing_time(run.X[X3], run.X[U], s * run.kc(), run.p.motor_time_constant)
    knots = [0.0] + ([t_ext] if 0.0 < t_ext < h else []) + [h]
    roots = []
    for lo, hi in zip(knots, knots[1:]):
        glo, ghi = g(lo), g(hi)
        if glo * ghi < 0:
            roots.append(brentq(g, lo, hi, xtol=1e-16, rtol=8.9e-16, maxiter=200))
    return roots


def _substep_peak(run: _Run, Xa: np.ndarray, Xb: np.ndarray, h: float) -> None:
    if not run.acc.active:
        return
    peak = max(abs(Xa[X1]), abs(Xb[X1]))
    if (Xa[X2] - Xa[X4]) * (Xb[X2] - Xb[X4]) < 0:
        peak = max(peak, hermite_peak(h, Xa[X1], Xa[X2] - Xa[X4], Xb[X1], Xb[X2] - Xb[X4]))
    run.acc.merge_peak(peak)


def _newton_zero(run: _Run, h: float) -> bool:
    """Section 4.5: hold Z fixed and iterate g ← g − v(g)/a(g) from the segment end (4-38)."""
    mode = run.mode
    x3, u = run.X[X3], run.X[U]
    f_full = run.cache.factor(mode, h)
    z = run.rng.standard_normal(f_full.m)

    def velocity(tau: float) -> float:
        f = run.cache.factor(mode, tau)
        return float(run.cache.phi(mode, tau)[X2] @ run.X + f.sample(z)[X2])

    s = 1.0 if mode == 3 else -1.0
    g = h
    found = False
    if s * run.X[X2] <= 0.0:
        g, found = 0.0, True
    for _ in range(0 if found else 20):
        v = velocity(g)
        P = run.cache.phi(mode, g)
        Xg = P @ run.X
        accel = run.p.alpha * (Xg[X3] - s * (run.p.coulomb + Xg[X5]))
        if accel == 0.0:
            break
        step = v / accel
        if g == h and step <= 0:       # first correction positive in time: no zero before h
            break
        g_new = g - step
        if not (0.0 < g_new <= h):
            break
        if abs(g_new - g) < 1e-13:
            g, found = g_new, True
            break
        g = g_new
    if not found and s * velocity(h) <= 0.0:
        # Newton left (0, h] although the fixed-Z path ends on the far side: bracket instead.
        g, found = brentq(velocity, min(1e-12, h / 2), h, xtol=1e-15, rtol=8.9e-16), True
    run.torque_metrics(x3, u, g if found else h)
    tau = g if found else h
    f = run.cache.factor(mode, tau)
    Xa = run.X
    Xb = run.cache.phi(mode, tau) @ Xa + f.sample(z)
    _substep_peak(run, Xa, Xb, tau)
    run.X = Xb
    run.t += tau
    run.acc.n_substeps += run.acc.active
    if found:
        run.X[X2] = 0.0
    return found
