"""One sample interval of the two-mass plant, compiled whole: the pure step (SPEC §11).

Events, as the multimode plant (plant.multimode.interval) with the shaft torque
T = k·φ + c·(ω_m − x2) on the load in place of x3:

* command level changes (the command's segments) and the flyback end x3 = 0 (closed form);
* breakaway while stuck, |T| = ks: the first root of T ∓ ks (plant.two_mass.modes.first_root:
  T is deterministic while stuck — x2 ≡ 0, x5 frozen, the rotor carries no noise);
* velocity zero while moving: noise-free (or σ2 = 0) the first root of the mean load velocity;
  noisy, exact Gaussian sub-steps X⁺ = Φ(h)X + L·ζ with the Brownian-bridge crossing test and
  bridge bisection of plant.multimode.zero_velocity, on the 6-dim noisy block
  (plant.two_mass.bridge). At a zero: reflect if s·T > ks, reverse if −s·T > ks, else stick.
  A noisy sub-step that starts with s·T > ks reflects x2 at 0 (the Skorokhod push of the bridge
  minimum, as plant.multimode.zero_velocity), in sub-steps of ``reflect_substep``.

Peak |x1|: noise-free, x1 at every root of ẋ1 = x2 − x4 (first_root, repeatedly); noisy, the
cubic Hermite of each sub-step (plant.multimode.moving.substep_peak); stuck, x1 is monotone.
∫|x3|, ∫x3² and the supply charge are the multimode closed forms (x3 does not see the shaft).
"""

from __future__ import annotations

import math
import threading
from functools import lru_cache

import numpy as np
from numba import njit

from plant.drive import DriveCommand, DriveType
from plant.multimode.interval import _apply_level, _end_flyback, _flyback_time, _torque_metrics
from plant.multimode.moving import substep_peak
from plant.multimode.stuck import stuck_propagate
from plant.multimode.zero_velocity import _crossed
from plant.randomness import NoiseExhausted, NoiseStream, normal
from plant.state import EVENT_FIELDS, EventKind, IntervalResult, PlantState, SimOptions, Status
from plant.two_mass.bridge import BISECT_SCRATCH, bisect_fresh, bisect_w, bridge_tables
from plant.two_mass.modes import M_STUCK, NCORE, decompose, first_exit, first_exit_n, first_root, first_root_n
from plant.two_mass.motion import (A1, A2, A3, A4, A5, AKC, AU, NB, NNB, NX, PHI, WM, mode_row, process_noise,
                                   rotor_after, _start_coords_w, propagate, psd_factor, start_coords,
                                   transition, transition_u, process_noise_u, unit_coords)
from plant.two_mass.params import TwoMassParams

__all__ = ["advance", "N_X", "root_steps"]

N_X = 8   # x = [x1, x2, x3, x4, x5, u, φ, ω_m]

_T, _MODE, _FB, _COUNT, _PEAK, _IABS, _ISQ, _CHG, _DUR, _NEV, _NBRK, _NSTK, _NSUB, _STATUS, _NREC, _NROOT = range(16)
_SHEET = 16   # _NROOT: the root searches' safe steps (modes.first_root_n, first_exit_n), for the fit's work clock
_O_NOISE, _O_NEWTON, _O_SUB, _O_RSUB, _O_TOL, _O_MAXEV, _O_DIVERGE = range(7)
_OK, _CHATTER, _DIVERGED, _BAD_LEVEL, _NO_ROOT = 0, 1, 2, 3, 4
_LEVEL, _FLYBACK_END, _BREAKAWAY, _REGIME_END, _STICK, _REVERSAL, _REFLECTION = (int(k) for k in EventKind)


class _RecordFull(Exception):
    """The event buffer is full (the caller enlarges it and runs the interval again)."""


@njit(cache=True)
def _tick(S, n, o):
    S[_COUNT] += n
    if S[_COUNT] > o[_O_MAXEV]:
        S[_STATUS] = _CHATTER
        return True
    return False


@njit(cache=True)
def _event(S, X, kind, o, ev):
    S[_NEV] += 1.0
    n = int(S[_NREC])
    if ev.shape[0] > 0:
        if n >= ev.shape[0]:
            raise _RecordFull()
        ev[n, 0] = S[_T]
        ev[n, 1] = X[A1]
        ev[n, 2] = X[A2]
        ev[n, 3] = X[A3]
        ev[n, 4] = S[_MODE]
        ev[n, 5] = X[AU]
        ev[n, 6] = kind
        S[_NREC] = n + 1
    return _tick(S, 1.0, o)


@njit(cache=True)
def shaft_torque(X, q):
    """T = k·φ + c·(ω_m − x2) [ozf·in], the shaft's torque on the load."""
    return q[0] * X[PHI] + q[1] * (X[WM] - X[A2])


@njit(cache=True)
def _torque_exit(X, ks, horizon, p, q, V, Vi, lam):
    """Stuck: the first time |T| reaches ks, and the side (+1, −1; 0 if not within ``horizon``)."""
    W0 = np.empty(NCORE, dtype=np.complex128)
    B0 = np.empty(NCORE, dtype=np.complex128)
    n = start_coords(X, 2, p, q, Vi, W0, B0)
    ca = np.zeros(NCORE, dtype=np.complex128)
    cb = np.zeros(NCORE, dtype=np.complex128)
    lm = np.zeros(NCORE, dtype=np.complex128)
    for i in range(n):
        cv = q[0] * V[M_STUCK, 0, i] + q[1] * V[M_STUCK, 1, i]
        ca[i] = cv * W0[i]
        cb[i] = cv * B0[i]
        lm[i] = lam[M_STUCK, i]
    return first_exit(ca, cb, lm, n, -ks, ks, horizon)


@njit(cache=True, _nrt=False)
def _torque_exit_w(X, ks, horizon, p, q, V, Vi, lam, C, F):
    """:func:`_torque_exit` in the scratch C (5 × NCORE complex: w, b̃, then the coefficients
    and exponents in rows 2-4) and F (3 × NCORE: z, b, |λ|): the same operations,
    allocation-free and without reference counting."""
    h, side, _ = _torque_exit_n(X, ks, horizon, p, q, V, Vi, lam, C, F)
    return h, side


@njit(cache=True, _nrt=False)
def _torque_exit_n(X, ks, horizon, p, q, V, Vi, lam, C, F):
    """:func:`_torque_exit_w` and the safe steps its search took (0 when the bound decided)."""
    n = _start_coords_w(X, 2, p, Vi, C, F)
    for i in range(NCORE):
        C[2, i] = 0j
        C[3, i] = 0j
        C[4, i] = 0j
    for i in range(n):
        cv = q[0] * V[M_STUCK, 0, i] + q[1] * V[M_STUCK, 1, i]
        C[2, i] = cv * C[0, i]
        C[3, i] = cv * C[1, i]
        C[4, i] = lam[M_STUCK, i]
    if _stays_inside(C, n, ks, horizon):
        return math.inf, 0, 0
    for i in range(n):
        F[2, i] = abs(C[4, i])
    return first_exit_n(C[2], C[3], C[4], F[2], n, -ks, ks, horizon)


@njit(cache=True, _nrt=False)
def _stays_inside(C, n, ks, horizon):
    """True when a bound proves that :func:`first_exit_al` on (C[2], C[3], C[4], F[2]) returns
    (inf, 0): |T| stays below ks on [0, horizon] with a margin far above the search's rounding,
    so no safe step can see the level, and the steps are long enough that their number stays far
    below its limit. The search's own answer, without its steps (each an exp, a sincos and a
    hypot per modal term); where the bound does not decide, the search runs as before.

    With Re λ ≤ 0: |a·e^(λt)| ≤ |a|, |b·t·φ1(λt)| = |b·(e^(λt) − 1)/λ| ≤ |b|·min(t, 2/|λ|), so
    |g(t)| ≤ G = Σ |a_i| + |b_i|·min(horizon, 2/|λ_i|) (|λ_i| bounded below by max(|Re|, |Im|)),
    and, writing b·t·φ1(λt) = (b/λ)(e^(λt) − 1) when no λ_i is 0, also
    |g(t)| ≤ |Re Σ b_i/λ_i| + Σ |a_i + b_i/λ_i| (the steady part, the ringing part), whichever is
    smaller (a rounding of the quotients is ~1e-16 of G, inside the 1e-9 margin below);
    |g'| ≤ D1 = Σ |λ_i·a_i + b_i| and the search's curvature bound M2(t) ≤ M2 = Σ |λ_i|·|λ_i·a_i + b_i|
    (each |z| bounded above by |Re z| + |Im z|). If G·(1 + 1e-9) < ks, the distance y to either
    level is ≥ δ = ks − G·(1 + 1e-9) (the computed sum of the terms is within ~1e-14·G of the exact
    one) and ≤ 2·ks, so every safe step s ≥ min(√(2δ/M2), 2δ/(2·D1 + √(4·M2·ks)))
    (:func:`plant.two_mass.modes.first_exit_al`'s two step formulas); with s ≥ 2·s_min,
    s_min > 1e-12 s and horizon ≤ 1000·s_min the search takes fewer than 1002 steps (its limit is
    100000), none below 1e-15 s, and never finds g ≥ ks or g ≤ −ks."""
    if not (ks > 0.0):
        return False
    G = 0.0
    D1 = 0.0
    M2 = 0.0
    Gs = 0.0                    # the second form: Σ|a_i + b_i/λ_i| ...
    cs = 0j                     # ... and the steady part Σ −b_i/λ_i (all λ_i ≠ 0)
    split = True
    for i in range(n):
        a, b, lam = C[2, i], C[3, i], C[4, i]
        al = max(abs(lam.real), abs(lam.imag))      # ≤ |λ|: 2/al ≥ 2/|λ|, the bound stays one
        reach = horizon if al * horizon <= 2.0 else 2.0 / al
        G += abs(a.real) + abs(a.imag) + (abs(b.real) + abs(b.imag)) * reach
        d = lam * a + b
        dm = abs(d.real) + abs(d.imag)
        D1 += dm
        M2 += (abs(lam.real) + abs(lam.imag)) * dm
        if al > 0.0:
            c = b / lam
            Gs += abs(a.real + c.real) + abs(a.imag + c.imag)
            cs -= c
        else:
            split = False
    if split:
        G = min(G, Gs + abs(cs.real))
    bound = G * (1.0 + 1e-9)
    if not (bound < ks):
        return False
    delta = ks - bound
    s1 = math.sqrt(2.0 * delta / M2) if M2 > 0.0 else math.inf
    den = 2.0 * D1 + math.sqrt(4.0 * M2 * ks)
    s2 = 2.0 * delta / den if den > 0.0 else math.inf
    s_min = 0.5 * min(s1, s2)
    return s_min > 1e-12 and horizon <= 1000.0 * s_min


@njit(cache=True)
def _velocity_root(X, mode, which, sigma, horizon, p, q, V, Vi, lam):
    """First root of the mean x2 (which = 0) or of ẋ1 = x2 − x4 (which = 1) while moving, and
    the safe steps its search took (modes.first_root_n)."""
    r = mode_row(mode)
    W0 = np.empty(NCORE, dtype=np.complex128)
    B0 = np.empty(NCORE, dtype=np.complex128)
    n = start_coords(X, mode, p, q, Vi, W0, B0)
    ca = np.zeros(NCORE + 1, dtype=np.complex128)
    cb = np.zeros(NCORE + 1, dtype=np.complex128)
    lm = np.zeros(NCORE + 1, dtype=np.complex128)
    for i in range(n):
        ca[i] = V[r, 0, i] * W0[i]
        cb[i] = V[r, 0, i] * B0[i]
        lm[i] = lam[r, i]
    m = n
    if which == 1:
        ca[n] = -X[A4]
        lm[n] = -p.beta4
        m = n + 1
    al = np.empty(max(m, 1))
    for i in range(m):
        al[i] = abs(lm[i])
    return first_root_n(ca, cb, lm, al, m, sigma, horizon)


# --- mode 2 -----------------------------------------------------------------------------------

@njit(cache=True, _nrt=False)
def _stuck(X, S, t_end, bridge, p, q, V, Vi, lam, o, z, cursor, ev, Xn, C, F):
    """A stuck load to the breakaway, the flyback end or t_end; True when the interval must stop.
    Allocation-free, compiled without reference counting (each of its thirteen array arguments
    cost an atomic incref/decref pair per call)."""
    ks = max(p.stiction + X[A5], 0.0)
    h_end = t_end - S[_T]
    h_fb = _flyback_time(X, S, p)
    horizon = min(h_end, h_fb)
    h_brk, side, steps = _torque_exit_n(X, ks, horizon, p, q, V, Vi, lam, C, F)
    S[_NROOT] += steps
    if h_brk < 0.0:
        S[_STATUS] = _NO_ROOT
        return True
    h = min(h_end, h_fb, h_brk)
    x1_before = abs(X[A1])
    _torque_metrics(S, X[A3], X[AU], h, bridge, p)
    # C[0], C[1]: X's stuck start coordinates, from _torque_exit_w (X unchanged since)
    rotor_after(X, h, V, lam, C, Xn)
    X[PHI], X[WM] = Xn[PHI], Xn[WM]
    stuck_propagate(X, h, p, o[_O_NOISE] != 0.0, z, cursor)    # x1, x4 (with w4) and x3
    S[_PEAK] = max(S[_PEAK], x1_before, abs(X[A1]))
    if h == h_end:
        S[_T] = t_end
        return False
    S[_T] += h
    if h == h_fb:
        _end_flyback(X, S)
        return _event(S, X, _FLYBACK_END, o, ev)
    X[A2] = 0.0
    S[_MODE] = 3.0 if side > 0 else 1.0
    S[_NBRK] += 1.0
    return _event(S, X, _BREAKAWAY, o, ev)


# --- modes 1 and 3 ----------------------------------------------------------------------------

@njit(cache=True)
def _velocity_zero(X, S, p, q):
    """x2 has reached 0: reflect, reverse or stick by the shaft torque (SPEC §2); the event kind."""
    mode = int(S[_MODE])
    s = 1.0 if mode == 3 else -1.0
    X[A2] = 0.0
    T = shaft_torque(X, q)
    ks = max(p.stiction + X[A5], 0.0)
    if s * T > ks:
        return _REFLECTION
    if -s * T > ks:
        S[_MODE] = 1.0 if mode == 3 else 3.0
        S[_NBRK] += 1.0
        return _REVERSAL
    S[_MODE] = 2.0
    S[_NSTK] += 1.0
    return _STICK


@njit(cache=True)
def _x1_peak(X, mode, tau, p, q, V, Vi, lam, peak, Xn):
    """(max(peak, |x1| at the roots of ẋ1 = x2 − x4 in (0, τ)), work) for the noise-free segment
    from X; work: the searches' safe steps, and one per root for its propagation.

    Nothing is left of the segment once t = τ (e.g. τ = 0: a velocity zero at the segment's
    start, as at a Zeno point where the load reflects again and again at one instant): the
    loop returns there. It used to search on with a zero horizon, and a root at 0 sent it
    round all 10000 times on zero-length steps (2·10⁴ counted steps per such segment, issue 25's
    tenth session). Those rounds cannot change the peak: a zero horizon gives a root of 0, ∞,
    −1 or beyond the horizon, only 0 goes on, with the zero-length step r = min(1e-12, 0) = 0,
    and propagating by 0 leaves x1 exact (x1 + 0·(…) − x4·expm1(0)/β4); so the same peak."""
    t = 0.0
    work = 0
    Xa = X.copy()
    for _ in range(10000):
        if tau - t == 0.0:
            return peak, work
        d = Xa[A2] - Xa[A4]
        sigma = 1.0 if d > 0.0 else -1.0
        if d == 0.0:
            Xd = np.empty(NX)
            propagate(Xa, mode, 1e-9, p, q, V, Vi, lam, Xd)
            sigma = 1.0 if Xd[A2] - Xd[A4] > 0.0 else -1.0
        r, steps = _velocity_root(Xa, mode, 1, sigma, tau - t, p, q, V, Vi, lam)
        work += steps + 1
        if not (r > 0.0 and r < tau - t):
            if r == 0.0:
                r = min(1e-12, tau - t)   # a double zero at the start: step past it
            else:
                return peak, work
        propagate(Xa, mode, r, p, q, V, Vi, lam, Xn)
        Xa[:] = Xn
        t += r
        peak = max(peak, abs(Xa[A1]))
    return peak, work


@njit(cache=True, _nrt=True)
def _quiet_segment(X, S, mode, s, h, bridge, p, q, V, Vi, lam, noise_on, z, cursor, Xn, x3, u):
    """:func:`_moving`'s segment when x2 carries no white noise: the first root of the mean
    velocity, the peak, the closed form (and the segment's exact noise). Returns −1 when no root
    was found, 1 at a velocity zero, else 0. It allocates: reference counting on, explicitly."""
    tau, steps = _velocity_root(X, mode, 0, s, h, p, q, V, Vi, lam)
    S[_NROOT] += steps
    if tau < 0.0:
        return -1
    stopped = tau <= h
    advanced = tau if stopped else h
    _torque_metrics(S, x3, u, advanced, bridge, p)
    S[_PEAK], work = _x1_peak(X, mode, advanced, p, q, V, Vi, lam, max(S[_PEAK], abs(X[A1])), Xn)
    S[_NROOT] += work
    propagate(X, mode, advanced, p, q, V, Vi, lam, Xn)
    X[:] = Xn
    if noise_on:
        _add_noise(X, mode, advanced, p, q, V, Vi, lam, z, cursor)
    S[_PEAK] = max(S[_PEAK], abs(X[A1]))
    S[_T] += advanced
    if stopped:
        X[A2] = 0.0
    return 1 if stopped else 0


MOVE_SCRATCH = 2 * NX + NX * NX + 2 * NNB * NNB + NNB + BISECT_SCRATCH  # _moving's W: Xb, Xc, P, Q, L, ζ, bisection


@njit(cache=True, _nrt=False)
def _moving(X, S, t_end, bridge, p, q, V, Vi, lam, o, TP, TL, BT, z, cursor, ev, Xn, W):
    """A moving load to the velocity zero, the flyback end or t_end. Compiled without reference
    counting, the noisy sub-steps' scratch in W (MOVE_SCRATCH floats); the noise-free segment
    (:func:`_quiet_segment`) and what allocates in the noisy one keep reference counting."""
    mode = int(S[_MODE])
    s = 1.0 if mode == 3 else -1.0
    X[AKC] = p.coulomb if p.coulomb + X[A5] >= 0.0 else -X[A5]
    h_end = t_end - S[_T]
    h_fb = _flyback_time(X, S, p)
    h = min(h_end, h_fb)
    noise_on = o[_O_NOISE] != 0.0
    x3, u = X[A3], X[AU]
    if noise_on and p.sigma2_sq > 0.0:
        budget = max(o[_O_MAXEV] - S[_COUNT], 1.0)
        o1, o2, o3, o4 = NX, 2 * NX, 2 * NX + NX * NX, 2 * NX + NX * NX + NNB * NNB
        o5 = o4 + NNB * NNB
        advanced, stopped, peak, n, chattered = _noisy_segment(
            X, mode, h, p, q, V, Vi, lam, o, TP, TL, BT, z, cursor, S[_PEAK], budget, W[:o1], W[o1:o2],
            W[o2:o3].reshape((NX, NX)), W[o3:o4].reshape((NNB, NNB)), W[o4:o5].reshape((NNB, NNB)), W[o5:o5 + NNB],
            W[o5 + NNB:o5 + NNB + BISECT_SCRATCH])
        _torque_metrics(S, x3, u, advanced, bridge, p)
        S[_PEAK] = peak
        S[_NSUB] += n
        S[_T] += advanced
        if chattered or _tick(S, n, o):
            S[_STATUS] = _CHATTER
            return True
    else:
        r = _quiet_segment(X, S, mode, s, h, bridge, p, q, V, Vi, lam, noise_on, z, cursor, Xn, x3, u)
        if r < 0:
            S[_STATUS] = _NO_ROOT
            return True
        stopped = r == 1
    if stopped:
        kind = _velocity_zero(X, S, p, q)
        return _event(S, X, kind, o, ev)
    if h == h_end:
        S[_T] = t_end
        return False
    _end_flyback(X, S)
    return _event(S, X, _FLYBACK_END, o, ev)


@njit(cache=True)
def _add_noise(X, mode, h, p, q, V, Vi, lam, z, cursor):
    """X += L(h)·ζ: the segment's exact noise when x2 carries no white noise (σ2 = 0)."""
    Q = np.empty((NNB, NNB))
    L = np.empty((NNB, NNB))
    process_noise(mode, h, p, q, V, Vi, lam, Q)
    psd_factor(Q, L)
    _apply_factor(X, L, z, cursor)


@njit(cache=True)
def _apply_factor(X, L, z, cursor):
    zeta = np.empty(NNB)
    for i in range(NNB):
        zeta[i] = normal(z, cursor)
    for i in range(NNB):
        acc = 0.0
        for j in range(i + 1):
            acc += L[i, j] * zeta[j]
        X[NB[i]] += acc


@njit(cache=True)
def _gauss_step(X, P, L, z, cursor, out):
    """out = P·X + L·ζ (ζ: six unit normals, on the noisy block)."""
    for i in range(NX):
        acc = 0.0
        for j in range(NX):
            acc += P[i, j] * X[j]
        out[i] = acc
    _apply_factor(out, L, z, cursor)


@njit(cache=True, _nrt=False)
def _gauss_step_t(X, TP, TL, m, j, z, cursor, out, zeta):
    """:func:`_gauss_step` with P = TP[m, j], L = TL[m, j] read in place (no views) and ζ in the
    scratch ``zeta``: the same operations and draws, allocation-free, without reference counting."""
    for i in (A1, A2, A5, PHI, WM):
        acc = 0.0
        for k in range(NX):
            acc += TP[m, j, i, k] * X[k]
        out[i] = acc
    # Φ's rows of x3, x4, kc and u are zero off (x3, u), x4, kc, u by construction (motion.
    # _state_from_coords_e: 0 + (0 − 0)·e3, 0·(1 − E4), copies), and a product 0·X[k] added to
    # a sum that starts at +0 never changes it (finite X): the same sums without those products
    acc = 0.0
    acc += TP[m, j, A3, A3] * X[A3]
    acc += TP[m, j, A3, AU] * X[AU]
    out[A3] = acc
    acc = 0.0
    acc += TP[m, j, A4, A4] * X[A4]
    out[A4] = acc
    acc = 0.0
    acc += TP[m, j, AKC, AKC] * X[AKC]
    out[AKC] = acc
    acc = 0.0
    acc += TP[m, j, AU, AU] * X[AU]
    out[AU] = acc
    i0 = cursor[0]
    if 0 <= i0 and i0 + NNB <= z.shape[0]:     # the next six normals in one bounds check
        for i in range(NNB):
            zeta[i] = z[i0 + i]
        cursor[0] = i0 + NNB
    else:
        for i in range(NNB):
            zeta[i] = normal(z, cursor)
    for i in range(NNB):
        acc = 0.0
        for k in range(i + 1):
            acc += TL[m, j, i, k] * zeta[k]
        out[NB[i]] += acc


@njit(cache=True, _nrt=True)
def _fresh_step(X, mode, step, p, q, V, Vi, lam, P, Q, L, z, cursor, Xb):
    """A sub-step of its own width: Φ(h), Q(h) and the factor built afresh, then the Gaussian step
    (they allocate: reference counting on, explicitly)."""
    U = np.empty((NX, 2, NCORE), dtype=np.complex128)
    unit_coords(mode, p, Vi, U)                 # the unit start coordinates, once for Φ and Q
    transition_u(mode, step, p, V, lam, U, P)
    process_noise_u(mode, step, p, V, lam, U, Q)
    psd_factor(Q, L)
    _gauss_step(X, P, L, z, cursor, Xb)


@njit(cache=True, _nrt=True)
def _bisect_fresh_rc(mode, Xa, Xb, h, tol, p, V, Vi, lam, sig_v2, z, cursor, Xout, P, Q):
    """:func:`plant.two_mass.bridge.bisect_fresh` (a sub-step of its own width, whose Φ(h) and
    Q(h) are P and Q) with reference counting on (it allocates)."""
    return bisect_fresh(mode, Xa, Xb, h, tol, p, V, Vi, lam, sig_v2, z, cursor, Xout, P, Q)


@njit(cache=True, _nrt=False)
def _noisy_segment(X, mode, h, p, q, V, Vi, lam, o, TP, TL, BT, z, cursor, peak, max_steps, Xb, Xc, P, Q, L, zeta,
                   Wb):
    """Advance a noisy moving segment of length h in place: exact Gaussian sub-steps of
    ``substep`` (``reflect_substep`` while s·T > ks), the bridge crossing test and bisection.
    Xb, Xc (NX), P (NX × NX), Q, L (NNB × NNB), ζ (NNB) and Wb (the bisection's,
    BISECT_SCRATCH): the caller's scratch; compiled without reference counting
    (:func:`_fresh_step` and :func:`_bisect_fresh_rc` keep it).

    Returns (advanced, stopped, peak, sub-steps, chattered).
    """
    s = 1.0 if mode == 3 else -1.0
    m = 0 if mode == 1 else 1
    sig_v2 = p.alpha * p.alpha * p.sigma2_sq
    t = 0.0
    n = 0
    while h - t > 0.0:
        rem = h - t
        ks = max(p.stiction + X[A5], 0.0)
        reflect = s * shaft_torque(X, q) > ks
        j = 1 if reflect else 0
        sub = o[_O_RSUB] if reflect else o[_O_SUB]
        fresh = rem <= 1.5 * sub and rem != sub
        if fresh:
            step = rem
            _fresh_step(X, mode, step, p, q, V, Vi, lam, P, Q, L, z, cursor, Xb)
        else:
            step = sub
            _gauss_step_t(X, TP, TL, m, j, z, cursor, Xb, zeta)
        n += 1
        if n > max_steps:
            return t, False, peak, n, True
        if reflect:
            va, vb = s * X[A2], s * Xb[A2]
            both = va > 0.0 and vb > 0.0
            e = -2.0 * va * vb / (sig_v2 * step) if both else 0.0
            x = normal(z, cursor)
            # p_push = e^e (1 unless both > 0) is only compared with ½: exp only near ln ½
            if x >= 0.0 and both and (e < -0.7 or math.exp(e) <= 0.5):
                low = min(va, vb)
            elif both and e < -70.0 and x > -11.0 and min(va, vb) >= 1e-6 * max(va, vb):
                # U = Φ(x) > 1.9e-28 > e^e: the bridge minimum below is ≥ 0 with a relative
                # margin ≥ 1e-7 (far above rounding), so no push — decided without erfc and log
                low = 0.0
            else:
                uu = 0.5 * math.erfc(-x / math.sqrt(2.0))
                low = 0.5 * (va + vb - math.sqrt((vb - va) ** 2 - 2.0 * sig_v2 * step * math.log(uu)))
            if low < 0.0:
                Xb[A2] += s * (-low)
                Xb[A1] += s * (-low) * step / 2.0
                Xb[PHI] -= s * (-low) * step / 2.0
        else:
            if _crossed(X[A2], Xb[A2], step, sig_v2, z, cursor):
                if fresh:    # P, Q: this sub-step's Φ(step), Q(step) (_fresh_step)
                    tc, lv = _bisect_fresh_rc(mode, X, Xb, step, o[_O_TOL], p, V, Vi, lam, sig_v2, z, cursor, Xc,
                                              P, Q)
                else:
                    tc, lv = bisect_w(mode, X, Xb, step, o[_O_TOL], p, q, V, Vi, lam, sig_v2, z, cursor, Xc, BT[m],
                                      Wb)
                n += lv
                peak = substep_peak(X, Xc, tc, peak)
                for i in range(NX):
                    X[i] = Xc[i]
                X[A2] = 0.0
                return t + tc, True, peak, n, False
        peak = substep_peak(X, Xb, step, peak)
        for i in range(NX):
            X[i] = Xb[i]
        t += step
    return h, False, peak, n, False


# --- the interval -----------------------------------------------------------------------------

@njit(cache=True)
def interval_kernel(x, mode, flyback, t0, duration, offsets, levels, bridge, prm, q, V, Vi, lam, o, TP, TL, BT,
                    z, zpos, ev, out):
    """Advance over [t0, t0 + duration) under the command (offsets, levels); see advance()."""
    return interval_k(x, mode, flyback, t0, duration, offsets, levels, offsets.shape[0], bridge, prm, q, V, Vi, lam, o,
                      TP, TL, BT, z, zpos, ev, out, np.empty(1, dtype=np.int64), np.empty(NX), np.empty(NX),
                      np.empty((5, NCORE), dtype=np.complex128), np.empty((3, NCORE)), np.empty(MOVE_SCRATCH))


@njit(cache=True, _nrt=False)
def interval_k(x, mode, flyback, t0, duration, offsets, levels, k, bridge, prm, q, V, Vi, lam, o, TP, TL, BT, z, zpos,
               ev, out, cursor, X, Xn, C, F, W):
    """:func:`interval_kernel` on the drive's first ``k`` segments, with a compiled caller's
    scratch (``cursor`` one int64, X and Xn NX floats, C 5 × NCORE complex and F 3 × NCORE, as
    :func:`~plant.two_mass.motion.rotor_after` and :func:`_torque_exit_w` use them, W MOVE_SCRATCH floats for
    :func:`_moving`): the same operations, compiled without reference counting (its fifteen array
    arguments and five allocations cost ~40 atomic operations per sample)."""
    p = prm[0]
    S = out[N_X:]
    cursor[0] = zpos
    X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU], X[PHI], X[WM] = (x[0], x[1], x[2], x[3], x[4], p.coulomb,
                                                                         x[5], x[6], x[7])
    for i in range(_SHEET):
        S[i] = 0.0
    S[_T], S[_MODE], S[_FB] = t0, mode, 1.0 if flyback else 0.0
    for seg in range(k):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < k else duration)
        if not _apply_level(X, S, levels[seg], bridge, p):
            S[_STATUS] = _BAD_LEVEL
            break
        if seg > 0 and _event(S, X, _LEVEL, o, ev):
            break
        stop = False
        while S[_T] < t_seg_end:
            if S[_MODE] == 2.0:
                stop = _stuck(X, S, t_seg_end, bridge, p, q, V, Vi, lam, o, z, cursor, ev, Xn, C, F)
            else:
                stop = _moving(X, S, t_seg_end, bridge, p, q, V, Vi, lam, o, TP, TL, BT, z, cursor, ev, Xn, W)
            if stop:
                break
            if not (abs(X[A1]) <= o[_O_DIVERGE]):
                S[_STATUS] = _DIVERGED
                stop = True
                break
        if stop:
            break
    if S[_STATUS] == _OK:
        S[_T] = t0 + duration
    out[0], out[1], out[2], out[3], out[4], out[5], out[6], out[7] = (X[A1], X[A2], X[A3], X[A4], X[A5], X[AU],
                                                                      X[PHI], X[WM])
    return cursor[0]


_SCRATCH = threading.local()
_NO_EVENTS = np.empty((0, len(EVENT_FIELDS)))
_NO_NOISE = np.empty(0)
_STATUS_OF = {_OK: Status.OK, _CHATTER: Status.CHATTER, _DIVERGED: Status.DIVERGED, _NO_ROOT: Status.ERROR}


def root_steps() -> int:
    """The root searches' safe steps (and x1-peak roots) of every :func:`advance` on this thread
    so far: work that samples, events and sub-steps do not show (a stiff, lightly damped shaft
    rings at a high frequency, and each interval's searches step through its ringing). Read it
    before and after a simulation for that simulation's count (the fit's work clock)."""
    return getattr(_SCRATCH, "root_steps", 0)


def _event_scratch() -> np.ndarray:
    ev = getattr(_SCRATCH, "events", None)
    if ev is None:
        ev = _SCRATCH.events = np.empty((4096, len(EVENT_FIELDS)))
    return ev


@lru_cache(maxsize=64)
def plan(params: TwoMassParams, options: SimOptions) -> tuple:
    """(q, V, V⁻¹, λ, options vector, TP, TL, BT): the per-(params, options) tables.

    TP, TL: Φ and the noise factor of the sub-step (j = 0) and the reflecting sub-step (j = 1)
    for both moving modes; BT: the bridge laws of the bisection levels (plant.two_mass.bridge).
    """
    q = np.array([params.shaft_stiffness, params.shaft_damping, params.motor_inertia])
    V, Vi, lam = decompose(params)
    for a in (q, V, Vi, lam):       # frozen before the table builders use them, as the kernels get them:
        a.flags.writeable = False   # one compiled signature of process_noise, bridge_law (docs/plant.md)
    prm = params.kernel_record()
    TP = np.empty((2, 2, NX, NX))
    TL = np.empty((2, 2, NNB, NNB))
    Q = np.empty((NNB, NNB))
    for m, mode in enumerate((1, 3)):
        for j, h in enumerate((options.substep, options.reflect_substep)):
            transition(mode, h, prm[0], q, V, Vi, lam, TP[m, j])
            process_noise(mode, h, prm[0], q, V, Vi, lam, Q)
            psd_factor(Q, TL[m, j])
    levels = max(0, math.ceil(math.log2(options.substep / options.bisection_tol)))
    BT = bridge_tables(prm[0], q, V, Vi, lam, options.substep, levels)
    out = (q, V, Vi, lam, options.kernel_vector(), TP, TL, BT)
    for a in out:
        a.flags.writeable = False
    return out


def _message(code: int, state: PlantState, options: SimOptions) -> str:
    if code == _CHATTER:
        return f"more than {options.max_events} events and sub-steps in one interval at t = {state.t:.6g} s"
    if code == _DIVERGED:
        return f"|x1| exceeded {options.diverge_error} rad at t = {state.t:.6g} s"
    return f"the first-root locator did not converge at t = {state.t:.6g} s"


def advance(state: PlantState, command: DriveCommand, params: TwoMassParams, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """Advance the two-mass plant over one interval under ``command``: the pure step
    (as :func:`plant.multimode.interval.advance`; x carries φ and ω_m after u)."""
    h = params.sample_period if duration is None else float(duration)
    if not h > 0:
        raise ValueError(f"interval duration must be > 0, got {h!r}")
    offsets, levels = command.arrays()
    if offsets[-1] >= h:
        raise ValueError(f"command segment at offset {offsets[-1]} s lies beyond the interval ({h} s)")
    x = np.array(state.x, dtype=float)   # a writable copy: the kernels' one signature (docs/plant.md)
    if x.shape != (N_X,):
        raise ValueError(f"two-mass state must have {N_X} entries, got shape {x.shape}")
    bridge = command.drive is DriveType.BRIDGE
    noisy = bool(options.noise and noise is not None)
    q, V, Vi, lam, o, TP, TL, BT = plan(params, options)
    if not noisy:
        o = o.copy()
        o[_O_NOISE] = 0.0
        o.flags.writeable = False   # read-only like plan()'s: the kernels' one signature (docs/plant.md)
    out = np.empty(N_X + _SHEET)
    ev = _event_scratch() if record else _NO_EVENTS
    z, pos = noise.window() if noisy else (_NO_NOISE, 0)
    while True:
        try:
            pos_after = interval_kernel(x, state.mode, state.flyback, state.t, h, offsets, levels, bridge,
                                        params.kernel_record(), q, V, Vi, lam, o, TP, TL, BT, z, pos, ev, out)
            break
        except NoiseExhausted:
            z, pos = noise.grow(pos)
        except _RecordFull:
            ev = _SCRATCH.events = np.empty((4 * ev.shape[0], len(EVENT_FIELDS)))
    if noisy:
        noise.consumed(pos_after)
    x_out = out[:N_X].copy()
    (t, mode, flyback, _, peak, iabs, isq, chg, dur, nev, nbrk, nstk, nsub, code, nrec, nroot) = out[N_X:].tolist()
    _SCRATCH.root_steps = getattr(_SCRATCH, "root_steps", 0) + int(nroot)
    code = int(code)
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max}), got {command.segments!r}")
    x_out.flags.writeable = False
    new = PlantState(t, x_out, int(mode), flyback != 0.0)
    status = _STATUS_OF[code]
    message = "" if code == _OK else _message(code, new, options)
    events = None
    if record:
        n = int(nrec)
        events = {name: ev[:n, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, status, message, peak, iabs, isq, chg, dur, int(nev), int(nbrk), int(nstk),
                          int(nsub), events)
