"""The multimode plant with an Ornstein–Uhlenbeck disturbance torque d on the load (SPEC §11).

d acts in every mode: ḋ = −d/τd + √(2/τd)·σd·w_d (σd = ``disturbance_torque_std``, τd =
``disturbance_torque_tau``, w_d unit white noise), added to the load's torque balance,

    ẋ2 = α(x3 + d − s·kc − s·x5) + α·w2   (moving, s = +1 forward),

and a stuck shaft breaks away when |x3 + d| > ks. The state carries d as a seventh entry,
x = [x1, x2, x3, x4, x5, u, d]. With d the plant is still linear per mode, so it stays exact:
on the augmented vector Y = [x1, x2, x3, x4, x5, d, kc, u] each mode is Ẏ = A·Y + noise, and
a step of width h is Y⁺ = Φ(h)·Y + N. Φ(h) and COV[N] are closed forms (d's column is x5's
with s = +1 and β5 → 1/τd, its noise independent of the others; :func:`_closed_form`), checked
against expm and Van Loan (IEEE TAC 23(3), 1978: expm of [[−A, Qc], [0, Aᵀ]]·h) in
tests/test_disturbance_torque.py; the noise is drawn through the minimal factor (4-20) of
:mod:`plant.multimode.noise`; all cached per (plant, mode, h).

Events are located as the noisy velocity zero of :mod:`plant.multimode.zero_velocity` is:
exact Gaussian sub-steps (long rungs h·2^k only while the barrier is 8.5σ away), a crossing
inside a sub-step with both ends on one side happens with the Brownian-bridge probability
exp(−2·g_a·g_b/(σ²·h)), and it is located by bridge bisection (each midpoint drawn from its
Gaussian law given both ends, accepted in proportion to the probability that a half holds a
crossing, the first half chosen in proportion to its own) down to ``bisection_tol``:

* stuck: the first passage of g = x3 + d through ±ks (σ² = σd²·2/τd, the intensity of d);
* moving: the first zero of x2 (σ² = α²σ2²; with σ2 = 0, x2 is C¹ and a zero is a sign change
  at a sub-step end or a bisection point). At a zero the switching table of SPEC §2 applies
  with x3 + d in place of x3; while s·(x3 + d) ≥ ks at a sub-step's start the crossing is
  reflected (Skorokhod push, as in zero_velocity), so the end of that regime is resolved to
  ``reflect_substep`` rather than in closed form (d is random).

With ``disturbance_torque_std`` = 0 the family runs :func:`plant.multimode.interval.advance`
itself, bit for bit. This module is the Python reference (``advance_python``), kept as it was:
it caches what depends only on (mode, h) or (mode, h, e) — Φ, Q and their factors, the bridge
law, and the bisection's conditional law given c — and does the sub-step's tests in scalar
arithmetic on Python floats (the same doubles). The same law runs compiled in
:mod:`plant.multimode.disturbed_jit` (and its closed loops, :mod:`~plant.multimode.disturbed_loop`),
bit for bit where OpenBLAS sums in the same order (tests/test_disturbed_jit.py).
"""

from __future__ import annotations

import math
import threading
from functools import lru_cache

import numpy as np

from plant.drive import DriveCommand, DriveType
from plant.expfun import e1, e2, e4
from plant.multimode import disturbed_jit
from plant.multimode.moving import phi_moving, q_moving, substep_peak
from plant.fixed_linalg import eigh_jacobi, gram, mat_mat, mat_mat_t, mat_vec, pinv_hermitian
from plant.multimode.noise import noise_factor
from plant.multimode.segments import torque_integrals
from plant.multimode.zero_velocity import FAR_SIGMAS, LADDER, hitting_midpoint
from plant.params import PlantParams
from plant.randomness import NoiseExhausted, NoiseStream
from plant.state import EVENT_FIELDS, EventKind, IntervalResult, PlantState, SimOptions, Status

__all__ = ["N_X", "D", "advance", "advance_python", "transition", "initial_state"]

N_X = 7     # x1, x2, x3, x4, x5, u, d
D = 6       # index of d in the state vector
Y1, Y2, Y3, Y4, Y5, YD, YKC, YU = range(8)
_N = 8


def initial_state(params: PlantParams, x5: float) -> PlantState:
    """Shaft stuck at zero error, no current, x4 = ``command_velocity_initial``, x5 given, d = 0."""
    x = np.zeros(N_X)
    x[3] = params.command_velocity_initial
    x[4] = x5
    x.flags.writeable = False
    return PlantState(0.0, x, 2, False)


class _Step:
    """Φ(h), Q(h), its minimal factor, and the bridge law of the midpoint of a width-h step."""

    __slots__ = ("phi", "Q", "factor", "rows", "B", "m", "_bridge", "_given")

    def __init__(self, phi, Q):
        self.phi, self.Q = phi, Q
        self.factor = f = noise_factor(Q)
        self.rows, self.B, self.m = f.rows, f.B, f.m
        self._bridge = None
        self._given = {}     # barrier functional e -> the bisection's conditional law (see _bisect)


@lru_cache(maxsize=16)
def _cache(params: PlantParams) -> dict:
    return {}


def _records(params: PlantParams) -> tuple[np.ndarray, np.ndarray]:
    """The plant's kernel record, and one that makes q_moving's x5 slot the disturbance d
    (β5 → 1/τd, σ5² → 2σd²/τd, no w2, no w4), cached with the transitions."""
    memo = _cache(params)
    recs = memo.get("records")
    if recs is None:
        rec = params.kernel_record()
        rd = rec.copy()
        rd[0]["beta5"] = 1.0 / params.disturbance_torque_tau
        rd[0]["sigma5_sq"] = 2.0 * params.disturbance_torque_std ** 2 / params.disturbance_torque_tau
        rd[0]["sigma2_sq"] = 0.0
        rd[0]["sigma4_sq"] = 0.0
        recs = memo["records"] = (rec, rd)
    return recs


# Y-index of each slot of plant.multimode.moving's augmented vector [x1, x2, x3, x4, x5, kc, u].
_FROM7 = np.array([Y1, Y2, Y3, Y4, Y5, YKC, YU])
_BLOCK = np.array([Y1, Y2, Y4, Y5])
_IX7, _IXB = np.ix_(_FROM7, _FROM7), np.ix_(_BLOCK, _BLOCK)
_IXD, _IXD4 = np.ix_([Y1, Y2, YD], [Y1, Y2, YD]), np.ix_([0, 1, 3], [0, 1, 3])


def _closed_form(params: PlantParams, mode: int, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ(h), Q(h)) in closed form. Moving: Φ of (3-20)/(3-21) (phi_moving) plus d's column,
    which is x5's with s = +1 and β5 → βd (ẋ2 gets α·d, x5 enters as s·α·x5); Q = q_moving's
    block plus d's share, q_moving's x5 share with the d record (the noises are independent).
    Stuck: (3-22) and (4-11) as plant.multimode.stuck, d an Ornstein–Uhlenbeck step."""
    rec, rd = _records(params)
    p = params
    bd = 1.0 / p.disturbance_torque_tau
    sd2 = 2.0 * p.disturbance_torque_std ** 2 / p.disturbance_torque_tau
    phi = np.zeros((_N, _N))
    Q = np.zeros((_N, _N))
    if mode == 2:
        b3, b4, s4 = p.beta3, p.beta4, p.sigma4_sq
        y = b4 * h
        E = e1(y)
        for i in range(_N):
            phi[i, i] = 1.0
        phi[Y1, Y4] = -E / b4
        phi[Y4, Y4] = 1.0 - E
        phi[Y3, Y3] = math.exp(-b3 * h)
        phi[Y3, YU] = e1(b3 * h)
        phi[YD, YD] = math.exp(-bd * h)
        Q[Y1, Y1] = s4 * e4(y) / b4 ** 3
        Q[Y1, Y4] = Q[Y4, Y1] = -s4 * E * E / (2.0 * b4 * b4)
        Q[Y4, Y4] = s4 * E * (2.0 - E) / (2.0 * b4)
        Q[YD, YD] = sd2 * e1(2.0 * bd * h) / (2.0 * bd)
        return phi, Q
    P7 = np.empty((7, 7))
    phi_moving(mode, h, rec[0], P7)
    phi[_IX7] = P7
    a = p.alpha
    phi[Y1, YD] = a * e2(bd * h) / (bd * bd)
    phi[Y2, YD] = a * e1(bd * h) / bd
    phi[YD, YD] = math.exp(-bd * h)
    Q4 = np.empty((4, 4))
    q_moving(mode, h, rec[0], Q4)
    Q[_IXB] = Q4
    q_moving(1, h, rd[0], Q4)                      # d's share on (x1, x2, ·, d)
    Q[_IXD] += Q4[_IXD4]
    return phi, Q


def transition(params: PlantParams, mode: int, h: float) -> _Step:
    """The cached :class:`_Step` of ``mode`` over ``h`` [s] (closed form; Van Loan is the tests' oracle)."""
    return _transition(_cache(params), params, mode, h)


def _transition(memo: dict, params: PlantParams, mode: int, h: float) -> _Step:
    key = (mode, h)
    step = memo.get(key)
    if step is None:
        if len(memo) > 4096:
            memo.clear()
        step = memo[key] = _Step(*_closed_form(params, mode, h))
    return step


def _bridge_law(memo, params, mode, w):
    """(Φ(w/2), G, factor of Σ): X_m = Φ(w/2)X_a + G·(X_b − Φ(w)X_a) + N(0, Σ), Matheron's rule."""
    full = _transition(memo, params, mode, w)
    if full._bridge is None:
        half = _transition(memo, params, mode, w / 2)
        Qh, Qw, Ph = half.Q, full.Q, half.phi
        rows = np.flatnonzero(np.diag(Qw) > 0.0)
        M = mat_mat_t(Qh, Ph)                          # COV[X_m, X_b | X_a] = Qh·Phᵀ
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


class _Draws:
    """Unit normals (and uniforms U = Φ(Z)) read in order from the plant's :class:`NoiseStream`."""

    def __init__(self, noise: NoiseStream):
        self.noise = noise
        self.z, self.pos = noise.window()

    def normals(self, n: int) -> np.ndarray:
        if self.pos + n > self.z.shape[0]:
            self.z, self.pos = self.noise.grow(self.pos)
        out = self.z[self.pos:self.pos + n]
        self.pos += n
        return out

    def uniform(self) -> float:
        return 0.5 * math.erfc(-float(self.normals(1)[0]) / math.sqrt(2.0))

    def done(self) -> None:
        self.noise.consumed(self.pos)


def _mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A·x in the compiled path's fixed order (disturbed_jit._gemv: no BLAS, the same bits on every CPU)."""
    out = np.empty(A.shape[0])
    disturbed_jit._gemv(np.ascontiguousarray(A), np.ascontiguousarray(x, dtype=float), out)
    return out


def _dot(e: np.ndarray, x: np.ndarray) -> float:
    """e·x summed in index order (disturbed_jit._edot)."""
    return float(disturbed_jit._edot(np.ascontiguousarray(e, dtype=float), np.ascontiguousarray(x, dtype=float)))


def _gauss(step: _Step, Y: np.ndarray, draws: _Draws | None) -> np.ndarray:
    out = _mv(step.phi, Y)
    if draws is not None and step.m:
        out[step.rows] += _mv(step.B, draws.normals(step.m))
    return out


class _Run:
    """One interval's mutable bookkeeping (the counterpart of interval.py's work sheet)."""

    def __init__(self, p, o, t, mode, flyback, record):
        self.p, self.o = p, o
        self.memo = _cache(p)
        self.sig2_moving = p.alpha ** 2 * p.sigma2_sq     # α²σ2², x2's noise intensity
        self.t, self.mode, self.fb = t, mode, flyback
        self.peak = self.iabs = self.isq = self.chg = self.dur = 0.0
        self.nev = self.nbrk = self.nstk = self.nsub = self.count = 0
        self.status = Status.OK
        self.events = [] if record else None
        self.just_broke = False

    def tick(self, n=1):
        self.count += n
        if self.count > self.o.max_events:
            self.status = Status.CHATTER
            return True
        return False

    def event(self, Y, kind):
        self.nev += 1
        if self.events is not None:
            self.events.append((self.t, Y[Y1], Y[Y2], Y[Y3], float(self.mode), Y[YU], int(kind)))
        return self.tick()

    def torque(self, x3, u, h, bridge):
        if h <= 0.0:
            return
        integral, absolute, square = torque_integrals(x3, u, h, self.p.motor_time_constant)
        self.iabs += absolute
        self.isq += square
        self.chg += (u / self.p.u_max) * integral if bridge else absolute
        self.dur += h


def _apply_level(Y, run, level, bridge, iu=YU, i3=Y3):
    """The level in force from now (SPEC §2's drives): clipped on the amplifier; on the bridge
    ±u_max or 0, a 0 with torque left starting the flyback. ``iu``, ``i3``: where u and x3 sit in
    ``Y`` (this plant's layout by default; the stribeck and lugre paths pass theirs). False for
    a bridge level that is neither."""
    umax = run.p.u_max
    if not bridge:
        Y[iu] = min(max(level, -umax), umax)
        run.fb = False
        return True
    if level != 0.0 and abs(abs(level) - umax) > 1e-9 * umax:
        return False
    if level > 0:
        Y[iu], run.fb = umax, False
    elif level < 0:
        Y[iu], run.fb = -umax, False
    elif Y[i3] != 0.0:
        Y[iu], run.fb = -math.copysign(umax, Y[i3]), True
    else:
        Y[iu], run.fb = 0.0, False
    return True
    if level != 0.0 and abs(abs(level) - umax) > 1e-9 * umax:
        return False
    if level > 0:
        Y[YU], run.fb = umax, False
    elif level < 0:
        Y[YU], run.fb = -umax, False
    elif Y[Y3] != 0.0:
        Y[YU], run.fb = -math.copysign(umax, Y[Y3]), True
    else:
        Y[YU], run.fb = 0.0, False
    return True


def _ks(p, Y):
    return max(p.stiction + Y[Y5], 0.0)


_TOP = 2.0 ** (LADDER - 1)


def _ladder_width(room, sub, far):
    """``room`` itself or the longest rung sub·2^k ≤ room for which ``far(w)`` holds, else
    min(sub, room)."""
    w = sub * _TOP
    if sub < room <= w and far(room):
        return room, True
    while w > sub:
        if w <= room and far(w):
            return w, True
        w /= 2.0
    return min(sub, room), False


def _x3_at(p, x3, u, w):
    return u + (x3 - u) * math.exp(-w / p.motor_time_constant)


def _stuck_far(p, sig2, ks, x3, u, d):
    """far(w): no passage of x3 + d through ±ks within w beyond 8.5σ of d's increment (x3 is
    monotone). The w-free parts are evaluated once per sub-step (Python floats: the same IEEE
    doubles as numpy's scalars, cheaper arithmetic)."""
    ad = abs(d)
    ax3, g, tau3 = abs(x3), x3 - u, p.motor_time_constant

    def far(w):
        x3max = max(ax3, abs(u + g * math.exp(-w / tau3)))      # |_x3_at(w)|
        return ks - x3max - ad > FAR_SIGMAS * math.sqrt(sig2 * w)
    return far


def _moving_far(p, dirn, x2, x3, x5, kc, u, d):
    """far(w): s·x2 stays 8.5σ of the step's x2 noise above 0 over w. The mean velocity's slope
    is α·(x3 + d − s·(kc + x5)) at the start and changes at most at M = α·(β3|u − x3| + βd|d| +
    β5|x5|) (x3, the means of d and x5 are exponentials), so s·x̄2(τ) ≥ s·x2 + ṡ0·τ − M·τ²/2,
    a concave bound whose minimum on [0, w] is at an end. The w-free parts are evaluated once
    per sub-step."""
    a = p.alpha
    v0 = dirn * x2
    slope = dirn * a * (x3 + d) - a * (kc + x5)
    curv = a * (abs(u - x3) / p.motor_time_constant + abs(d) / p.disturbance_torque_tau
                + abs(x5) / p.correlated_friction_tau)
    # x2's noise: α·∫w2 plus α·∫ of the zero-mean parts of d and x5, whose variances over w are
    # at most those of the integrated Brownian motions of their intensities (w³/3 each)
    s2, sd2, s5 = p.sigma2_sq, 2.0 * p.disturbance_torque_std ** 2 / p.disturbance_torque_tau, p.sigma5_sq

    def far(w):
        low = min(v0, v0 + slope * w - 0.5 * curv * w * w)
        w3 = w ** 3
        sd = a * (math.sqrt(s2 * w) + math.sqrt(sd2 * w3 / 3.0) + math.sqrt(s5 * w3 / 3.0))
        return low > FAR_SIGMAS * sd
    return far


def _cross_prob(va, vb, w, sig2):
    """P(a Brownian bridge from va > 0 to vb over w touches 0); 1 when vb ≤ 0, 0 for w = 0 (what
    exp(−∞) gave, without numpy's divide-by-zero warning)."""
    if vb <= 0.0 or va <= 0.0:
        return 1.0
    if sig2 <= 0.0 or not w > 0.0:
        return 0.0
    return math.exp(-2.0 * va * vb / (sig2 * w))


def _barrier(p, mode, dirn, Ya, Yb, w, sig2):
    """(crossing probability over a sub-step from Ya to Yb, barrier functional (e, c0)): the
    barrier distance is c = e·Y + c0 > 0 inside. Stuck: the nearer of ks ∓ (x3 + d) (the other
    one's probability is counted too; it is below e^-35 unless ks < 6σ of d's step)."""
    e = np.zeros(_N)
    if mode == 2:
        ks = _ks(p, Ya)
        ga, gb = Ya[Y3] + Ya[YD], Yb[Y3] + Yb[YD]
        up = _cross_prob(ks - ga, ks - gb, w, sig2)
        dn = _cross_prob(ks + ga, ks + gb, w, sig2)
        sgn = -1.0 if up >= dn else 1.0
        e[Y3] = e[YD] = sgn
        return 1.0 - (1.0 - up) * (1.0 - dn), e, ks
    e[Y2] = dirn
    return _cross_prob(dirn * Ya[Y2], dirn * Yb[Y2], w, sig2), e, 0.0


def _bisect(p, mode, e, c0, Ya, Yb, w, tol, sig2, draws, run):
    """:func:`bridge_bisect` on this plant's steps."""
    memo = run.memo
    return bridge_bisect(lambda h: _bridge_law(memo, p, mode, h), e, c0, Ya, Yb, w, tol, sig2, draws, run)


def bridge_bisect(law, e, c0, Ya, Yb, w, tol, sig2, draws, run):
    """Locate the first crossing of c = e·Y + c0 through 0 inside (0, w], given that there is one:
    (offset, state there). Each midpoint is drawn from its Gaussian law given both ends
    (Matheron's rule), c first and conditioned on a crossing (the exact sampler
    :func:`plant.multimode.zero_velocity.hitting_midpoint`), then the rest given c.

    ``law(h)`` is the step of width h carrying ``_bridge`` = (Φ(h/2), G, factor of Σ) and the
    ``_given`` cache (:func:`_bridge_law`; the two-mass family passes its own); ``run.nsub``
    counts the levels; ``draws`` None is the noise-free path (its mean)."""
    t0 = 0.0
    cursor = np.zeros(1, dtype=np.int64)
    ekey = e.tobytes()
    while w > tol:
        full = law(w)
        Ph, G, B = full._bridge
        mean = _mv(Ph, Ya) + _mv(G, Yb - _mv(full.phi, Ya))
        given = full._given.get(ekey)
        if given is None:                           # depends on (mode, w, e) only: computed once
            given = full._given[ekey] = _conditional(B, e)
        var, k, F = given
        mu = _dot(e, mean) + c0
        a, b = _dot(e, Ya) + c0, _dot(e, Yb) + c0
        half = w / 2
        if draws is None:                           # noise-free: the path is its mean, Φ(w/2)·Ya
            Ym = mean
            cm = _dot(e, Ym) + c0
        elif var > 0.0:
            sd = math.sqrt(var)
            if a > 0.0 and b > 0.0 and sig2 > 0.0:
                while True:
                    cursor[0] = draws.pos
                    try:
                        cm = hitting_midpoint(a, b, mu, sd, sig2 * half, draws.z, cursor)
                        break
                    except NoiseExhausted:
                        draws.z, draws.pos = draws.noise.grow(draws.pos)
                draws.pos = int(cursor[0])
            else:
                cm = mu + sd * float(draws.normals(1)[0])
            Ym = mean + k * (cm - mu)
            if F is not None:
                Ym += _fixed_mv(F, draws.normals(F.shape[1]))
        else:
            Ym = mean + (_fixed_mv(B, draws.normals(B.shape[1])) if B.shape[1] else 0.0)
            cm = _dot(e, Ym) + c0
        pl = _cross_prob(a, cm, half, sig2)
        pr = _cross_prob(cm, b, half, sig2)
        pc = 1.0 - (1.0 - pl) * (1.0 - pr)
        run.nsub += 1
        if pl >= 1.0 or (pl > 0.0 and draws is not None and draws.uniform() * pc < pl):
            Yb = Ym
        else:
            Ya, t0 = Ym, t0 + half
        w = half
    return t0 + w, Yb


def _fixed_mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A·x summed over k ascending (:func:`plant.fixed_linalg.mat_vec`, the compiled bisection's
    factor products)."""
    out = np.empty(A.shape[0])
    mat_vec(np.ascontiguousarray(A), np.ascontiguousarray(x, dtype=float), out)
    return out


def _conditional(B, e):
    """(var, k, F) of the midpoint's law N(·, S = B·Bᵀ) given c = e·Y: var = eᵀSe, the gain
    k = Se/var and a factor F of the conditional covariance S − Se·(Se)ᵀ/var (None when it is 0)."""
    S = gram(np.ascontiguousarray(B))
    Se = _fixed_mv(S, e)
    var = _dot(e, Se)
    if not var > 0.0:
        return var, None, None
    k = Se / var
    R = S - np.outer(Se, Se) / var
    lam, V = eigh_jacobi(0.5 * (R + R.T))
    keep = lam > 1e-14 * max(lam.max(initial=0.0), 1e-300)
    F = (V[:, keep] * np.sqrt(lam[keep])) if keep.any() else None
    return var, k, F


def _segment(Y, run, t_end, bridge, draws, sig_d2):
    """Advance by one sub-step (or to the next event); True when the interval must stop."""
    p, o = run.p, run.o
    mode = run.mode
    room = t_end - run.t
    _, x2, x3, _, x5, d, _, u = Y.tolist()          # Python floats, the same doubles
    h_fb = math.inf if not run.fb else p.motor_time_constant * math.log1p(abs(x3) / p.u_max)  # flyback end
    room_fb = min(room, h_fb)
    ks = max(p.stiction + x5, 0.0)                  # _ks
    if mode == 2:
        dirn = 0.0
        g = x3 + d
        if abs(g) > ks:                             # at (or past) stiction: breaks away now
            return _breakaway(Y, run, g)
        sig2 = sig_d2
        if ks - abs(x3) - abs(d) > 0.0:
            w, far = _ladder_width(room_fb, o.substep, _stuck_far(p, sig2, ks, x3, u, d))
        else:        # no rung is far: ks − x3max − |d| ≤ ks − |x3| − |d| ≤ 0 (rounding is monotone)
            w, far = min(o.substep, room_fb), False
        rungs = False
    else:
        dirn = 1.0 if mode == 3 else -1.0
        kc = p.coulomb if p.coulomb + x5 >= 0.0 else -x5
        Y[YKC] = kc
        reflecting = dirn * (x3 + d) >= ks
        sig2 = run.sig2_moving if draws is not None else 0.0
        if run.just_broke:
            reflecting, run.just_broke = True, False      # at ±ks exactly: the push starts the motion
        if dirn * x2 > 0.0:
            w, far = _ladder_width(room_fb, o.substep, _moving_far(p, dirn, x2, x3, x5, kc, u, d))
        else:        # no rung is far: low ≤ s·x2 ≤ 0 ≤ 8.5σ (also for a NaN)
            w, far = min(o.substep, room_fb), False
        if reflecting and not far:
            w = min(o.reflect_substep, room_fb)
        rungs = reflecting and not far
    step = _transition(run.memo, p, mode, w)
    Yb = _gauss(step, Y, draws)
    run.nsub += 1
    if run.tick():
        return True
    crossed = False
    if mode != 2 and rungs:                         # reflected: the Skorokhod push of zero_velocity
        va, vb = dirn * Y[Y2], dirn * Yb[Y2]
        if sig2 > 0.0:
            m = 0.5 * (va + vb - math.sqrt((vb - va) ** 2 - 2.0 * sig2 * w * math.log(draws.uniform())))
        else:
            m = min(va, vb)
        if m < 0.0:
            Yb[Y2] -= dirn * m
            Yb[Y1] -= dirn * m * w / 2.0
    else:
        prob, e, c0 = _barrier(p, mode, dirn, Y, Yb, w, sig2)
        if prob >= 1.0 or (prob > 0.0 and not far and draws.uniform() < prob):
            crossed = True
    if crossed:
        tc, Yb = _bisect(p, mode, e, c0, Y.copy(), Yb, w, o.bisection_tol, sig2, draws, run)
        if run.status is not Status.OK:
            return True
        w = tc
    run.torque(x3, u, w, bridge)
    run.peak = substep_peak(Y, Yb, w, run.peak) if mode != 2 else max(run.peak, abs(Y[Y1]), abs(Yb[Y1]))
    Y[:] = Yb
    Y[Y3] = _x3_at(p, x3, u, w)                     # x3 is deterministic: the closed form
    run.t += w
    if crossed:
        if mode == 2:
            return _breakaway(Y, run, Y[Y3] + Y[YD])
        return _velocity_zero(Y, run, dirn)
    if w == h_fb and h_fb <= room:
        Y[Y3] = Y[YU] = 0.0
        run.fb = False
        return run.event(Y, EventKind.FLYBACK_END)
    if w == room:
        run.t = t_end
    return False


def _breakaway(Y, run, g):
    Y[Y2] = 0.0
    run.mode = 3 if g > 0 else 1
    run.nbrk += 1
    run.just_broke = True
    return run.event(Y, EventKind.BREAKAWAY)


def _velocity_zero(Y, run, dirn):
    """x2 = 0 in a moving mode: reflect, reverse or stick (SPEC §2 with x3 + d)."""
    g = Y[Y3] + Y[YD]
    ks = _ks(run.p, Y)
    Y[Y2] = 0.0
    if dirn * g > ks:
        kind = EventKind.REFLECTION
    elif -dirn * g > ks:
        run.mode = 1 if run.mode == 3 else 3
        run.nbrk += 1
        kind = EventKind.REVERSAL
    else:
        run.mode = 2
        run.nstk += 1
        kind = EventKind.STICK
    return run.event(Y, kind)


def advance_python(state: PlantState, command: DriveCommand, params: PlantParams, noise: NoiseStream | None,
                   options: SimOptions = SimOptions(), *, duration: float | None = None,
                   record: bool = False) -> IntervalResult:
    """One interval of the disturbed plant in plain Python: the reference of the compiled
    :func:`advance` (bit-identical, tests/test_disturbed_jit.py)."""
    h = params.sample_period if duration is None else duration
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"duration must be a finite positive number of seconds, got {duration!r}")
    offsets, levels = command.arrays()
    if offsets[-1] >= h:
        raise ValueError(f"DriveCommand segment at offset {offsets[-1]!r} s lies beyond the interval of {h!r} s")
    bridge = command.drive is DriveType.BRIDGE
    noisy = options.noise and noise is not None
    draws = _Draws(noise) if noisy else None
    p = params
    x = state.x
    d0 = float(x[D]) if x.shape[0] > D else 0.0
    Y = np.array([x[0], x[1], x[2], x[3], x[4], d0, params.coulomb, x[5]], dtype=float)
    run = _Run(p, options, state.t, state.mode, state.flyback, record)
    sig_d2 = 2.0 * p.disturbance_torque_std ** 2 / p.disturbance_torque_tau if noisy else 0.0
    t0 = state.t
    stop = False
    for seg in range(len(offsets)):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < len(offsets) else h)
        if not _apply_level(Y, run, float(levels[seg]), bridge):
            raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max}), got {command.segments!r}")
        if seg > 0 and run.event(Y, EventKind.LEVEL):
            break
        while run.t < t_seg_end:
            stop = _segment(Y, run, t_seg_end, bridge, draws, sig_d2)
            if stop or run.status is not Status.OK:
                stop = True
                break
            if not (abs(Y[Y1]) <= options.diverge_error):
                run.status = Status.DIVERGED
                stop = True
                break
        if stop:
            break
    if draws is not None:
        draws.done()
    if run.status is Status.OK:
        run.t = t0 + h
    xo = np.array([Y[Y1], Y[Y2], Y[Y3], Y[Y4], Y[Y5], Y[YU], Y[YD]])
    xo.flags.writeable = False
    new = PlantState(run.t, xo, int(run.mode), bool(run.fb))
    message = ""
    if run.status is Status.CHATTER:
        message = f"more than {options.max_events} events in one interval at t={run.t:.6f} s"
    elif run.status is Status.DIVERGED:
        message = f"|x1| = {abs(Y[Y1]):.3g} rad at t={run.t:.6f} s"
    events = None
    if record:
        arr = np.array(run.events, dtype=float).reshape(-1, len(EVENT_FIELDS))
        events = {name: arr[:, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, run.status, message, run.peak, run.iabs, run.isq, run.chg, run.dur, run.nev,
                          run.nbrk, run.nstk, run.nsub, events)


_NO_EVENTS = np.empty((0, len(EVENT_FIELDS)))
_NO_NOISE = np.empty(0)
_SCRATCH = threading.local()
_STATUS_OF = {1: Status.CHATTER, 2: Status.DIVERGED}


def advance(state: PlantState, command: DriveCommand, params: PlantParams, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """One interval of the disturbed plant, compiled (:mod:`plant.multimode.disturbed_jit`); the
    contract of :func:`plant.multimode.interval.advance`, the results of :func:`advance_python`."""
    h = params.sample_period if duration is None else duration
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"duration must be a finite positive number of seconds, got {duration!r}")
    offsets, levels = command.arrays()
    if offsets[-1] >= h:
        raise ValueError(f"DriveCommand segment at offset {offsets[-1]!r} s lies beyond the interval of {h!r} s")
    bridge = command.drive is DriveType.BRIDGE
    noisy = options.noise and noise is not None
    ov, *K = disturbed_jit.kernel_inputs(params, options)
    if not noisy and ov[0] != 0.0:
        ov = ov.copy()
        ov[0] = 0.0
    x = np.array(state.x, dtype=np.float64)   # a writable copy: the kernels' one signature (docs/plant.md)
    out = np.empty(N_X + disturbed_jit.SHEET_SIZE)
    ev = getattr(_SCRATCH, "events", None) if record else _NO_EVENTS
    if ev is None:
        ev = _SCRATCH.events = np.empty((4096, len(EVENT_FIELDS)))
    z, pos = noise.window() if noisy else (_NO_NOISE, 0)
    while True:
        try:
            pos_after = disturbed_jit.interval_kernel(x, state.mode, state.flyback, state.t, h, offsets, levels, bridge,
                                                      ov, *K, z, pos, ev, out)
            break
        except NoiseExhausted:
            z, pos = noise.grow(pos)
        except disturbed_jit.RecordFull:
            ev = _SCRATCH.events = np.empty((4 * ev.shape[0], len(EVENT_FIELDS)))
    if noisy:
        noise.consumed(pos_after)
    (t, mode, flyback, _, peak, iabs, isq, chg, dur, nev, nbrk, nstk, nsub, code, nrec, _) = out[N_X:].tolist()
    if code == 3:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max}), got {command.segments!r}")
    xo = out[:N_X].copy()
    xo.flags.writeable = False
    new = PlantState(t, xo, int(mode), flyback != 0.0)
    status, message = Status.OK, ""
    if code == 1:
        status, message = Status.CHATTER, f"more than {options.max_events} events in one interval at t={t:.6f} s"
    elif code == 2:
        status, message = Status.DIVERGED, f"|x1| = {abs(xo[0]):.3g} rad at t={t:.6f} s"
    events = None
    if record:
        n = int(nrec)
        events = {name: ev[:n, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, status, message, peak, iabs, isq, chg, dur, int(nev), int(nbrk), int(nstk), int(nsub),
                          events)
