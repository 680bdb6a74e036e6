"""The two-mass plant with an Ornstein–Uhlenbeck disturbance torque d on the load (SPEC §11).

d acts in every mode: ḋ = −d/τd + √(2/τd)·σd·w_d (σd = ``disturbance_torque_std``, τd =
``disturbance_torque_tau``), added to the load's torque balance (plant.two_mass.modes),

    J·ẋ2 = k·φ + c·(ω_m − x2) + d − s·(kc + x5) + w2     (moving, s = +1 forward),

and the stuck load breaks away when |T + d| > ks, T = k·φ + c·(ω_m − x2) the shaft torque. The
state carries d as a ninth entry, x = [x1, x2, x3, x4, x5, u, φ, ω_m, d]. The plant stays
linear per mode: on Y = [x1, x2, x3, x4, x5, d, kc, u, φ, ω_m] each mode is Ẏ = A·Y + noise,
a step of width h is Y⁺ = Φ(h)·Y + N with Φ(h) = expm(A·h) and COV[N] = Q(h) by Van Loan
(IEEE TAC 23(3), 1978) on a short base width h/2^j (‖·‖·h/2^j ≤ ½, where its Taylor series
converges fast and nothing cancels) doubled up, Φ(2w) = Φ(w)², Q(2w) = Q(w) + Φ(w)·Q(w)·Φ(w)ᵀ
(checked against scipy.linalg.expm and Van Loan in tests/test_two_mass_disturbed.py); drawn
through the minimal factor
(4-20) of plant.multimode.noise; all cached per (plant, mode, h). While stuck, x2 ≡ 0 and x5 is
frozen (SPEC §2): d does not reach the rotor, T is deterministic.

Events (the scheme of plant.multimode.disturbed, whose helpers this module reuses):

* noisy: exact Gaussian sub-steps of ``substep`` (``reflect_substep`` while the load is pushed
  at zero velocity: s·(T + d) ≥ ks with s·x2 within 8.5σ of 0, the Skorokhod push of
  plant.multimode.zero_velocity; a zero reached from farther is a reflection event); a
  crossing inside a sub-step with both ends on one side happens with the Brownian-bridge
  probability exp(−2·c_a·c_b/(σ²·w)) of the barrier distance c, and is located
  by bridge bisection to ``bisection_tol`` (midpoints from their Gaussian law given both ends,
  Matheron's rule; the barrier coordinate first, conditioned on a crossing). Stuck: c = ks ∓
  (T + d), σ² = 2σd²/τd (d's intensity; T is C¹). Moving: c = s·x2, σ² = α²σ2² (with σ2 = 0,
  x2 is C¹ and a zero is a sign change at a sub-step end). The bridge test treats the smooth
  part of c as linear within a sub-step: its curvature (the shaft's ringing) is neglected
  there, an error that vanishes with ``substep`` (1e-4 s ≪ the 6.7 ms period of ``compliant``).
  Stuck, longer rungs sub·2^j are taken while the mean of T + d stays 8.5σ of the rung's noise
  inside ±ks (one exact first-exit call, modes.first_exit): a passage there has probability
  below 1e-16 and is not tested (the ladder of plant.multimode.zero_velocity).
* noise-free: the interval is the compiled exact step of plant.two_mass.interval when d = 0
  (d then stays 0); with d ≠ 0, the stuck breakaway is the first exit of T(t) + d(0)·e^(−t/τd)
  from (−ks, ks) by plant.two_mass.modes.first_exit (exact), and the moving velocity zero the
  first root of x2 (plant.two_mass.modes.first_root on the modal form of the core
  [x2, φ, ω_m, x3, x5, d], d one more exponential), the peak |x1| at the roots of ẋ1 likewise.

At a velocity zero the switching table of SPEC §2 applies with T + d in place of x3.

With ``disturbance_torque_std`` = 0 the family never enters this module (bit for bit the
compiled plant).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from plant.drive import DriveCommand, DriveType
from plant.fixed_linalg import eigh_jacobi, mat_mat, mat_mat_t, pinv_hermitian
from plant.multimode.disturbed import _apply_level, _breakaway, _cross_prob, _Draws, _mv, _Run, _Step, bridge_bisect
from plant.multimode.moving import substep_peak
from plant.multimode.zero_velocity import FAR_SIGMAS, LADDER
from plant.randomness import NoiseStream
from plant.state import EVENT_FIELDS, EventKind, IntervalResult, PlantState, SimOptions, Status
from plant.two_mass import interval as compiled
from plant.two_mass.eigen import core_modes
from plant.two_mass.modes import M_STUCK, NCORE, decompose, first_exit, first_root
from plant.two_mass.params import TwoMassParams

__all__ = ["N_X", "D", "advance", "transition", "drift", "initial_state"]

N_X = 9      # x1, x2, x3, x4, x5, u, φ, ω_m, d
D = 8        # index of d in the state vector
# Y: the multimode disturbed layout (its helpers index Y1..YU) plus the shaft.
Y1, Y2, Y3, Y4, Y5, YD, YKC, YU, YPHI, YWM = range(10)
_N = 10


def initial_state(params: TwoMassParams, x5: float) -> PlantState:
    """Load stuck at zero error, shaft relaxed and at rest, no current, d = 0; x4, x5 as multimode."""
    x = np.zeros(N_X)
    x[3] = params.command_velocity_initial
    x[4] = x5
    x.flags.writeable = False
    return PlantState(0.0, x, 2, False)


def drift(p: TwoMassParams, mode: int) -> tuple[np.ndarray, np.ndarray]:
    """(A, Qc) of Ẏ = A·Y + noise in ``mode`` (module docstring; Qc the white-noise intensities)."""
    a, Jm, k, c = p.alpha, p.motor_inertia, p.shaft_stiffness, p.shaft_damping
    bd = 1.0 / p.disturbance_torque_tau
    A = np.zeros((_N, _N))
    Qc = np.zeros((_N, _N))
    A[Y1, Y4] = -1.0
    A[Y3, Y3], A[Y3, YU] = -p.beta3, p.beta3
    A[Y4, Y4] = -p.beta4
    A[YD, YD] = -bd
    A[YPHI, YWM] = 1.0
    A[YWM, Y3], A[YWM, YPHI], A[YWM, YWM] = 1.0 / Jm, -k / Jm, -c / Jm
    Qc[Y4, Y4] = p.sigma4_sq
    Qc[YD, YD] = 2.0 * p.disturbance_torque_std ** 2 * bd
    if mode != 2:
        s = 1.0 if mode == 3 else -1.0
        A[Y1, Y2] = 1.0
        A[Y2, Y2], A[Y2, YPHI], A[Y2, YWM], A[Y2, YD] = -a * c, a * k, a * c, a
        A[Y2, Y5] = A[Y2, YKC] = -s * a
        A[Y5, Y5] = -p.beta5
        A[YPHI, Y2] = -1.0
        A[YWM, Y2] = c / Jm
        Qc[Y2, Y2] = a * a * p.sigma2_sq
        Qc[Y5, Y5] = p.sigma5_sq
    return A, Qc


def _phi_q(p: TwoMassParams, mode: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Φ(h) and Q(h): Van Loan's expm of [[A, Qc], [0, −Aᵀ]]·w = [[Φ(w), Q(w)·Φ(w)^-ᵀ], [0, Φ(w)^-ᵀ]]
    by its Taylor series on w = h/2^j (‖·‖₁·w ≤ ½: 24 terms leave < 1e-25), then j doublings
    Φ(2w) = Φ(w)², Q(2w) = Q(w) + Φ(w)·Q(w)·Φ(w)ᵀ (module docstring)."""
    A, Qc = drift(p, mode)
    M = np.zeros((2 * _N, 2 * _N))
    M[:_N, :_N], M[:_N, _N:], M[_N:, _N:] = A, Qc, -A.T
    norm = np.abs(M).sum(axis=0).max()
    j = max(0, math.ceil(math.log2(max(norm * h / 0.5, 1.0))))
    Mw = M * (h / 2.0 ** j)
    F = np.eye(2 * _N)
    term = np.eye(2 * _N)
    for i in range(1, 25):
        term = mat_mat(term, Mw) / i
        F = F + term
    P = np.ascontiguousarray(F[:_N, :_N])
    Q = mat_mat_t(np.ascontiguousarray(F[:_N, _N:]), P)
    for _ in range(j):
        Q = Q + mat_mat_t(mat_mat(P, Q), P)
        P = mat_mat(P, P)
    Q = 0.5 * (Q + Q.T)
    return P, Q


@lru_cache(maxsize=16)
def _cache(params: TwoMassParams) -> dict:
    return {}


def transition(params: TwoMassParams, mode: int, h: float) -> _Step:
    """The cached Φ(h), Q(h) and noise factor of ``mode`` over ``h`` [s]."""
    memo = _cache(params)
    key = (mode, h)
    step = memo.get(key)
    if step is None:
        if len(memo) > 4096:
            memo.clear()
        step = memo[key] = _Step(*_phi_q(params, mode, h))
    return step


def _bridge_law(params, mode, w):
    """(Φ(w/2), G, factor of Σ) of the midpoint given both ends (Matheron's rule), on the step."""
    full = transition(params, mode, w)
    if full._bridge is None:
        half = transition(params, mode, w / 2)
        Qh, Qw, Ph = half.Q, full.Q, half.phi
        rows = np.flatnonzero(np.diag(Qw) > 0.0)
        M = mat_mat_t(Qh, Ph)
        G = np.zeros((_N, _N))
        if rows.size:
            sc = np.sqrt(np.diag(Qw)[rows])
            inv = pinv_hermitian(Qw[np.ix_(rows, rows)] / np.outer(sc, sc), 1e-13)
            G[:, rows] = mat_mat(np.ascontiguousarray(M[:, rows] / sc), inv) / sc
        S = Qh - mat_mat_t(G, M)
        S = 0.5 * (S + S.T)
        lam, V = eigh_jacobi(S)
        B = V * np.sqrt(np.clip(lam, 0.0, None))
        keep = np.flatnonzero(lam > 1e-14 * max(lam.max(initial=0.0), 1e-300))
        full._bridge = (Ph, G, B[:, keep])
    return full


def _gauss(step, Y, draws):
    out = _mv(step.phi, Y)
    if draws is not None and step.m:
        out[step.rows] += _mv(step.B, draws.normals(step.m))
    return out


def _cmv(A, x):
    """A·x for a complex A (rows summed in index order, Python complexes: no BLAS)."""
    out = np.empty(A.shape[0], dtype=np.complex128)
    for i in range(A.shape[0]):
        acc = 0j
        for j in range(A.shape[1]):
            acc += complex(A[i, j]) * complex(x[j])
        out[i] = acc
    return out


def _shaft(p, Y):
    """T = k·φ + c·(ω_m − x2) [ozf·in]."""
    return p.shaft_stiffness * Y[YPHI] + p.shaft_damping * (Y[YWM] - Y[Y2])


def _barrier_vector(p, sgn):
    """e with e·Y = sgn·(T + d)."""
    e = np.zeros(_N)
    e[YPHI], e[YWM], e[Y2], e[YD] = sgn * p.shaft_stiffness, sgn * p.shaft_damping, -sgn * p.shaft_damping, sgn
    return e


def _bisect(p, mode, e, c0, Ya, Yb, w, tol, sig2, draws, run):
    """First crossing of c = e·Y + c0 through 0 in (0, w], given one: (offset, state there)
    (plant.multimode.disturbed.bridge_bisect on this plant's steps)."""
    return bridge_bisect(lambda h: _bridge_law(p, mode, h), e, c0, Ya, Yb, w, tol, sig2, draws, run)


@lru_cache(maxsize=16)
def _modal(params: TwoMassParams):
    return decompose(params)


def _stuck_exit(p, Y, ks, horizon):
    """Noise-free stuck: first t ≤ horizon with |T(t) + d(0)·e^(−t/τd)| = ks, and its side."""
    V, Vi, lam = _modal(p)
    z = np.array([Y[YPHI], Y[YWM], Y[Y3]])
    b = np.array([0.0, 0.0, p.beta3 * Y[YU]])
    n = 3
    w0 = _cmv(Vi[M_STUCK, :n, :n], z)
    b0 = _cmv(Vi[M_STUCK, :n, :n], b)
    cv = p.shaft_stiffness * V[M_STUCK, 0, :n] + p.shaft_damping * V[M_STUCK, 1, :n]
    ca = np.zeros(NCORE + 1, dtype=np.complex128)
    cb = np.zeros(NCORE + 1, dtype=np.complex128)
    lm = np.zeros(NCORE + 1, dtype=np.complex128)
    ca[:n], cb[:n], lm[:n] = cv * w0, cv * b0, lam[M_STUCK, :n]
    ca[n], lm[n] = Y[YD], -1.0 / p.disturbance_torque_tau
    return first_exit(ca, cb, lm, n + 1, -ks, ks, horizon)


@lru_cache(maxsize=16)
def _moving_modal(params: TwoMassParams, mode: int):
    """(V, V⁻¹, λ) of the moving core with d, z = [x2, φ, ω_m, x3, x5, d] (ż = A·z + b), in closed
    form (plant.two_mass.eigen.core_modes: no LAPACK), or None when V is singular to working
    precision (1/τ3, 1/τ5 or 1/τd at a shaft eigenvalue): then sub-steps decide."""
    a, Jm = params.alpha, params.motor_inertia
    s = 1.0 if mode == 3 else -1.0
    return core_modes("moving", a, Jm, params.shaft_stiffness, params.shaft_damping,
                      [(params.beta3, (0.0, 0.0, 1.0 / Jm)), (params.beta5, (-s * a, 0.0, 0.0)),
                       (1.0 / params.disturbance_torque_tau, (a, 0.0, 0.0))])


_CORE = [Y2, YPHI, YWM, Y3, Y5, YD]


def _moving_root(p, Y, mode, sigma, horizon, which=0):
    """Noise-free: the first zero in (0, horizon] of x2 (which = 0) or of ẋ1 = x2 − x4 (which = 1)
    (modes.first_root: exact; inf if none, −1 if it did not converge); None when the modal form
    is unavailable."""
    modal = _moving_modal(p, mode)
    if modal is None:
        return None
    V, Vi, lam = modal
    A, _ = drift(p, mode)
    z = Y[_CORE]
    Ab = A[np.ix_(_CORE, [YKC, YU])]
    b = np.array([Ab[i, 0] * Y[YKC] + Ab[i, 1] * Y[YU] for i in range(len(_CORE))])
    ca = np.zeros(7, dtype=np.complex128)
    cb = np.zeros(7, dtype=np.complex128)
    lm = np.zeros(7, dtype=np.complex128)
    ca[:6], cb[:6], lm[:6] = V[0] * _cmv(Vi, z), V[0] * _cmv(Vi, b), lam
    n = 6
    if which == 1:
        ca[6], lm[6] = -Y[Y4], -p.beta4
        n = 7
    return first_root(ca, cb, lm, n, sigma, horizon)


def _x1_peak(p, Y, mode, w, peak):
    """max(peak, |x1| at the roots of ẋ1 = x2 − x4 in (0, w)) on the noise-free path from Y."""
    t, Ya = 0.0, Y.copy()
    for _ in range(1000):
        slope = Ya[Y2] - Ya[Y4]
        sigma = 1.0 if slope > 0.0 else -1.0
        r = _moving_root(p, Ya, mode, sigma, w - t, 1)
        if r is None or not (0.0 < r < w - t):
            break
        Ya = _gauss(transition(p, mode, r), Ya, None)
        peak = max(peak, abs(Ya[Y1]))
        t += r
    return peak


def _stuck_width(p, Y, ks, g, room, sub, sig2):
    """(width, far) of a noisy stuck sub-step: the longest rung sub·2^j (≤ sub·2^(LADDER−1), or
    ``room`` itself) over which the mean of g = T + d, T(t) + d·e^(−t/τd), stays 8.5σ√W inside
    ±ks (W the longest candidate; plant.two_mass.modes.first_exit, one call), so that a passage
    within it has probability below 1e-16 and is not tested; else (sub, False)."""
    top = sub * 2.0 ** (LADDER - 1)
    W = min(room, top)
    if W <= sub:
        return W, False
    band = ks - FAR_SIGMAS * math.sqrt(sig2 * W)
    if band <= abs(g):
        return sub, False
    t, side = _stuck_exit(p, Y, band, W)
    if side == 0 and t == math.inf:
        return W, True
    if not t >= sub:
        return sub, False
    w = sub
    while 2.0 * w <= t:
        w *= 2.0
    return w, True


def _velocity_zero(Y, run, dirn):
    """x2 = 0 while moving: reflect, reverse or stick by T + d against ks (SPEC §2)."""
    Y[Y2] = 0.0
    g = _shaft(run.p, Y) + Y[YD]
    ks = max(run.p.stiction + Y[Y5], 0.0)
    if dirn * g > ks:
        kind = EventKind.REFLECTION
    elif -dirn * g > ks:
        run.mode = 1 if run.mode == 3 else 3
        run.nbrk += 1
        run.just_broke = True
        kind = EventKind.REVERSAL
    else:
        run.mode = 2
        run.nstk += 1
        kind = EventKind.STICK
    return run.event(Y, kind)


def _segment(Y, run, t_end, bridge, draws, sig_d2):
    """Advance by one sub-step (or to the next event); True when the interval must stop."""
    p, o = run.p, run.o
    mode = run.mode
    room = t_end - run.t
    x3, u = float(Y[Y3]), float(Y[YU])
    h_fb = math.inf if not run.fb else p.motor_time_constant * math.log1p(abs(x3) / p.u_max)
    room_fb = min(room, h_fb)
    ks = max(p.stiction + Y[Y5], 0.0)
    rungs = False
    if mode == 2:
        dirn = 0.0
        g = _shaft(p, Y) + Y[YD]
        if abs(g) > ks:
            return _breakaway(Y, run, g)
        sig2 = sig_d2
        w, far = min(o.substep, room_fb), False
        if draws is not None and sig2 > 0.0:
            w, far = _stuck_width(p, Y, ks, g, room_fb, o.substep, sig2)
        if draws is None:
            w, side = _stuck_exit(p, Y, ks, room_fb)
            if w < 0.0:
                run.status = Status.ERROR
                return True
            crossed = side != 0
            w = w if crossed else room_fb
    else:
        dirn = 1.0 if mode == 3 else -1.0
        Y[YKC] = p.coulomb if p.coulomb + Y[Y5] >= 0.0 else -Y[Y5]
        sig2 = run.sig2_moving if draws is not None else 0.0
        near = dirn * Y[Y2] <= FAR_SIGMAS * math.sqrt(sig2 * o.substep)
        rungs = (near and dirn * (_shaft(p, Y) + Y[YD]) >= ks) or run.just_broke
        run.just_broke = False
        w = min(o.reflect_substep if rungs else o.substep, room_fb)
        if draws is None and not rungs:
            tau = _moving_root(p, Y, mode, dirn, room_fb)
            if tau is not None and tau >= 0.0:
                crossed = tau <= room_fb
                w = tau if crossed else room_fb
                Yb = _gauss(transition(p, mode, w), Y, None)
                run.peak = _x1_peak(p, Y, mode, w, run.peak)
                run.nsub += 1
                if run.tick():
                    return True
                return _finish(Y, Yb, run, w, x3, u, h_fb, room, t_end, bridge, crossed, mode, dirn)
    step = transition(p, mode, w)
    Yb = _gauss(step, Y, draws)
    run.nsub += 1
    if run.tick():
        return True
    if mode == 2 and draws is None:
        pass
    elif mode != 2 and rungs:                     # reflected at zero velocity: the Skorokhod push
        crossed = False
        va, vb = dirn * Y[Y2], dirn * Yb[Y2]
        if sig2 > 0.0:
            m = 0.5 * (va + vb - math.sqrt((vb - va) ** 2 - 2.0 * sig2 * w * math.log(draws.uniform())))
        else:
            m = min(va, vb)
        if m < 0.0:
            Yb[Y2] -= dirn * m
            Yb[Y1] -= dirn * m * w / 2.0
            Yb[YPHI] += dirn * m * w / 2.0
    else:
        if mode == 2:
            gb = _shaft(p, Yb) + Yb[YD]
            up = _cross_prob(ks - g, ks - gb, w, sig2)
            dn = _cross_prob(ks + g, ks + gb, w, sig2)
            sgn = -1.0 if up >= dn else 1.0
            e, c0 = _barrier_vector(p, sgn), ks
            prob = 1.0 - (1.0 - up) * (1.0 - dn)
        else:
            e = np.zeros(_N)
            e[Y2] = dirn
            c0 = 0.0
            prob = _cross_prob(dirn * Y[Y2], dirn * Yb[Y2], w, sig2)
        crossed = prob >= 1.0 or (prob > 0.0 and draws is not None and not (mode == 2 and far)
                                  and draws.uniform() < prob)
        if crossed:
            tc, Yb = _bisect(p, mode, e, c0, Y.copy(), Yb, w, o.bisection_tol, sig2, draws, run)
            if run.status is not Status.OK:
                return True
            w = tc
    return _finish(Y, Yb, run, w, x3, u, h_fb, room, t_end, bridge, crossed, mode, dirn)


def _finish(Y, Yb, run, w, x3, u, h_fb, room, t_end, bridge, crossed, mode, dirn):
    """Book the sub-step from Y to Yb of width w and handle its event; True to stop."""
    p = run.p
    run.torque(x3, u, w, bridge)
    run.peak = substep_peak(Y, Yb, w, run.peak) if mode != 2 else max(run.peak, abs(Y[Y1]), abs(Yb[Y1]))
    Y[:] = Yb
    Y[Y3] = u + (x3 - u) * math.exp(-w / p.motor_time_constant)
    run.t += w
    if crossed:
        if mode == 2:
            return _breakaway(Y, run, _shaft(p, Y) + Y[YD])
        return _velocity_zero(Y, run, dirn)
    if w == h_fb and h_fb <= room:
        Y[Y3] = Y[YU] = 0.0
        run.fb = False
        return run.event(Y, EventKind.FLYBACK_END)
    if w == room:
        run.t = t_end
    return False


def advance(state: PlantState, command: DriveCommand, params: TwoMassParams, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """One interval of the disturbed two-mass plant; the contract of plant.two_mass.interval.advance."""
    h = params.sample_period if duration is None else float(duration)
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"interval duration must be a finite positive number of seconds, got {duration!r}")
    x = np.asarray(state.x, dtype=float)
    if x.shape != (N_X,):
        raise ValueError(f"disturbed two-mass state must have {N_X} entries, got shape {x.shape}")
    noisy = bool(options.noise and noise is not None)
    if not noisy and x[D] == 0.0:                 # d stays 0: the compiled exact step
        r = compiled.advance(state._replace(x=x[:D]), command, params, None, options, duration=duration,
                             record=record)
        xo = np.append(r.state.x, 0.0)
        xo.flags.writeable = False
        return r._replace(state=r.state._replace(x=xo))
    offsets, levels = command.arrays()
    if offsets[-1] >= h:
        raise ValueError(f"command segment at offset {offsets[-1]} s lies beyond the interval ({h} s)")
    bridge = command.drive is DriveType.BRIDGE
    draws = _Draws(noise) if noisy else None
    p = params
    Y = np.array([x[0], x[1], x[2], x[3], x[4], x[8], p.coulomb, x[5], x[6], x[7]], dtype=float)
    run = _Run(p, options, state.t, state.mode, state.flyback, record)
    sig_d2 = 2.0 * p.disturbance_torque_std ** 2 / p.disturbance_torque_tau if noisy else 0.0
    t0 = state.t
    for seg in range(len(offsets)):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < len(offsets) else h)
        if not _apply_level(Y, run, float(levels[seg]), bridge):
            raise ValueError(f"bridge drive levels must be 0 or ±u_max ({p.u_max}), got {command.segments!r}")
        stop = seg > 0 and run.event(Y, EventKind.LEVEL)
        while not stop and run.t < t_seg_end:
            stop = _segment(Y, run, t_seg_end, bridge, draws, sig_d2) or run.status is not Status.OK
            if not stop and not (abs(Y[Y1]) <= options.diverge_error):
                run.status = Status.DIVERGED
                stop = True
        if stop:
            break
    if draws is not None:
        draws.done()
    if run.status is Status.OK:
        run.t = t0 + h
    xo = np.array([Y[Y1], Y[Y2], Y[Y3], Y[Y4], Y[Y5], Y[YU], Y[YPHI], Y[YWM], Y[YD]])
    xo.flags.writeable = False
    new = PlantState(run.t, xo, int(run.mode), bool(run.fb))
    message = ""
    if run.status is Status.CHATTER:
        message = f"more than {options.max_events} events and sub-steps in one interval at t = {run.t:.6g} s"
    elif run.status is Status.DIVERGED:
        message = f"|x1| exceeded {options.diverge_error} rad at t = {run.t:.6g} s"
    elif run.status is Status.ERROR:
        message = f"the first-root locator did not converge at t = {run.t:.6g} s"
    events = None
    if record:
        arr = np.array(run.events, dtype=float).reshape(-1, len(EVENT_FIELDS))
        events = {name: arr[:, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, run.status, message, run.peak, run.iabs, run.isq, run.chg, run.dur, run.nev,
                          run.nbrk, run.nstk, run.nsub, events)
