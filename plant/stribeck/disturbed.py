"""The ``stribeck`` family with an Ornstein–Uhlenbeck disturbance torque d on the load (SPEC §11).

ḋ = −d/τd + √(2/τd)·σd·w_d adds to the load's torque balance in every mode,
v̇ = α·(x3 + d − s·F(|v|)) while sliding, and the stuck shaft breaks away when |x3 + d| > ks.
The state carries d as an eighth entry, x = [x1, x2, x3, x4, x5, u, θ, d].

Scheme (plant.stribeck.moving's noisy grid, d added to it):

* d moves by its exact OU transition over each sub-step of ``substep`` (or to an event): d⁺ =
  ρ·d + σd·√(1 − ρ²)·ζ, ρ = e^(−h/τd).
* sliding: within a sub-step the drift holds d at its start value — the sub-step is
  plant.stribeck.moving.noisy_segment with x3 and u shifted by d (the two enter v̇ only as
  x3 + d) — the left-point rule for ∫d, whose local error has mean O(h²) and variance O(h³):
  weak order 1, the order of the family's noisy scheme (bridge-located zeros) itself.
  A zero is switched by SPEC §2's table with x3 + d; the first sub-step after a breakaway or
  reversal is reflected (the load leaves v = 0 pushed by |x3 + d| ≥ ks).
* stuck: x3 is deterministic (closed form), so g = x3 + d crosses ±ks with the Brownian-bridge
  probability exp(−2·c_a·c_b/(σ²·h)) of its barrier distance c (σ² = 2σd²/τd), located by bridge
  bisection to ``bisection_tol``: d's midpoint is Gaussian given both ends (the OU bridge: mean
  ρ_½·(d_a + d_b)/(1 + ρ_½²), variance σd²·(1 − ρ_½²)/(1 + ρ_½²)), c drawn from it conditioned on
  a crossing (plant.multimode.zero_velocity.hitting_midpoint), the first crossing's half chosen
  in proportion to its probability. x1, x4 by their exact stuck transition.
* noise off: d(t) = d(0)·e^(−t/τd); with d(0) = 0 the interval is the compiled step itself
  (d stays 0); otherwise sliding holds d at each sub-step's midpoint value in the family's
  Dormand–Prince segment (second order in ``substep``), stuck crossings are sign changes at
  sub-step ends bisected to ``bisection_tol``, and the first ``reflect_substep`` after a
  breakaway, reversal or reflection is pushed as with noise (else a load at v = 0 whose held
  x3 + d sits a rounding below ks would stop at once, again and again).

With ``disturbance_torque_std`` = 0 the family never enters this module (bit for bit).
"""

from __future__ import annotations

import math

import numpy as np

from plant.drive import DriveCommand, DriveType
from plant.multimode.disturbed import _apply_level as _level
from plant.multimode.segments import torque_integrals
from plant.multimode.stuck import stuck_propagate
from plant.multimode.zero_velocity import hitting_midpoint
from plant.randomness import NoiseStream
from plant.state import EVENT_FIELDS, EventKind, IntervalResult, PlantState, SimOptions, Status
from plant.stribeck import interval as compiled
from plant.stribeck.law import effective_levels
from plant.stribeck.moving import noisy_segment, rk_segment

__all__ = ["N_X", "D", "advance", "initial_state"]

N_X = 8          # x1, x2, x3, x4, x5, u, θ, d
D = 7
A1, A2, A3, A4, A5, AKC, AU, ATH = range(8)
_MARGIN = 4096   # unread normals guaranteed before a compiled call (one sub-step uses < 100)


def initial_state(params, x5: float) -> PlantState:
    x = np.zeros(N_X)
    x[3] = params.command_velocity_initial
    x[4] = x5
    x.flags.writeable = False
    return PlantState(0.0, x, 2, False)


class _Noise:
    """The plant's normals as (z, cursor) for the compiled kernels, with room guaranteed."""

    def __init__(self, noise: NoiseStream):
        self.noise = noise
        self.z, pos = noise.window()
        self.cursor = np.array([pos], dtype=np.int64)

    def ready(self):
        pos = int(self.cursor[0])
        if pos + _MARGIN > self.z.shape[0]:
            while pos + _MARGIN > self.z.shape[0]:
                self.z, pos = self.noise.grow(pos)
            self.cursor[0] = pos
        return self.z, self.cursor

    def normal(self) -> float:
        z, c = self.ready()
        x = float(z[c[0]])
        c[0] += 1
        return x

    def uniform(self) -> float:
        return 0.5 * math.erfc(-self.normal() / math.sqrt(2.0))

    def done(self):
        self.noise.consumed(int(self.cursor[0]))


def _cross(ca, cb, w, sig2):
    """P(a Brownian bridge from ca to cb over w touches 0); 1 unless both are > 0."""
    if ca <= 0.0 or cb <= 0.0:
        return 1.0
    if sig2 <= 0.0:
        return 0.0
    return math.exp(-2.0 * ca * cb / (sig2 * w))


class _Run:
    def __init__(self, p, o, t, mode, fb, record):
        self.p, self.o = p, o
        self.prm = p.kernel_record()[0]
        self.L = p.law_vector()
        self.t, self.mode, self.fb = t, mode, fb
        self.peak = self.iabs = self.isq = self.chg = self.dur = 0.0
        self.nev = self.nbrk = self.nstk = self.nsub = 0
        self.status = Status.OK
        self.events = [] if record else None
        self.just_broke = False
        self.hbox = np.zeros(1)

    def tick(self):
        if self.nev + self.nsub > self.o.max_events:
            self.status = Status.CHATTER
            return True
        return False

    def event(self, X, kind):
        self.nev += 1
        if self.events is not None:
            self.events.append((self.t, X[A1], X[A2], X[A3], float(self.mode), X[AU], int(kind)))
        return self.tick()

    def torque(self, x3, u, h, bridge):
        if h <= 0.0:
            return
        integral, absolute, square = torque_integrals(x3, u, h, self.p.motor_time_constant)
        self.iabs += absolute
        self.isq += square
        self.chg += (u / self.p.u_max) * integral if bridge else absolute
        self.dur += h


def _apply_level(X, run, level, bridge):
    """plant.multimode.disturbed._apply_level on this path's layout."""
    return _level(X, run, level, bridge, AU, A3)
    if level != 0.0 and abs(abs(level) - umax) > 1e-9 * umax:
        return False
    if level > 0:
        X[AU], run.fb = umax, False
    elif level < 0:
        X[AU], run.fb = -umax, False
    elif X[A3] != 0.0:
        X[AU], run.fb = -math.copysign(umax, X[A3]), True
    else:
        X[AU], run.fb = 0.0, False
    return True


def _ou(d, h, p, noise):
    """d after h [s]: exact OU step (its mean noise-free)."""
    rho = math.exp(-h / p.disturbance_torque_tau)
    if noise is None:
        return d * rho
    return d * rho + p.disturbance_torque_std * math.sqrt(-math.expm1(-2.0 * h / p.disturbance_torque_tau)) * \
        noise.normal()


def _stuck(X, dbox, run, t_end, bridge, noise):
    """One stuck sub-step (or to a breakaway / flyback end); True when the interval must stop."""
    p, o = run.p, run.o
    kc, ks = effective_levels(X[ATH], X[A5], run.L)
    x3, u, d = X[A3], X[AU], dbox[0]
    g = x3 + d
    if abs(g) > ks:
        return _breakaway(X, run, g)
    room = t_end - run.t
    h_fb = math.inf if not run.fb else p.motor_time_constant * math.log1p(abs(x3) / p.u_max)
    w = min(o.substep, room, h_fb)
    tau3, taud = p.motor_time_constant, p.disturbance_torque_tau
    x3b = u + (x3 - u) * math.exp(-w / tau3)
    db = _ou(d, w, p, noise)
    sig2 = 2.0 * p.disturbance_torque_std ** 2 / taud if noise is not None else 0.0
    gb = x3b + db
    up = _cross(ks - g, ks - gb, w, sig2)
    dn = _cross(ks + g, ks + gb, w, sig2)
    prob = 1.0 - (1.0 - up) * (1.0 - dn)
    crossed = prob >= 1.0 or (prob > 0.0 and noise.uniform() < prob)
    run.nsub += 1
    if crossed:
        sgn = 1.0 if up >= dn else -1.0        # c = ks − sgn·(x3 + d) > 0 inside
        ta, tb, da, dbb = 0.0, w, d, db
        while tb - ta > o.bisection_tol:
            half = 0.5 * (tb - ta)
            tm = ta + half
            x3a = u + (x3 - u) * math.exp(-ta / tau3)
            x3bb = u + (x3 - u) * math.exp(-tb / tau3)
            x3m = u + (x3 - u) * math.exp(-tm / tau3)
            ca, cb = ks - sgn * (x3a + da), ks - sgn * (x3bb + dbb)
            rh = math.exp(-half / taud)
            mu_d = rh * (da + dbb) / (1.0 + rh * rh)
            if noise is None:
                dm = d * math.exp(-tm / taud)
            else:
                sd = p.disturbance_torque_std * math.sqrt(-math.expm1(-2.0 * half / taud) / (1.0 + rh * rh))
                mu_c = ks - sgn * (x3m + mu_d)
                if ca > 0.0 and cb > 0.0 and sig2 > 0.0:
                    z, cur = noise.ready()
                    cm = hitting_midpoint(ca, cb, mu_c, sd, sig2 * half, z, cur)
                else:
                    cm = mu_c + sd * noise.normal()
                dm = sgn * (ks - cm) - x3m
            cm = ks - sgn * (x3m + dm)
            pl = _cross(ca, cm, half, sig2)
            pr = _cross(cm, cb, half, sig2)
            pc = 1.0 - (1.0 - pl) * (1.0 - pr)
            run.nsub += 1
            if pl >= 1.0 or (pl > 0.0 and noise is not None and noise.uniform() * pc < pl):
                tb, dbb = tm, dm
            else:
                ta, da = tm, dm
        w, db = tb, dbb
    run.torque(x3, u, w, bridge)
    x1a = abs(X[A1])
    if noise is None:
        stuck_propagate(X, w, run.prm, False, np.empty(0), np.zeros(1, dtype=np.int64))
    else:
        z, cur = noise.ready()
        stuck_propagate(X, w, run.prm, True, z, cur)
    run.peak = max(run.peak, x1a, abs(X[A1]))
    dbox[0] = db
    run.t += w
    if crossed:
        return _breakaway(X, run, X[A3] + db)
    if w == h_fb and h_fb <= room:
        X[A3] = X[AU] = 0.0
        run.fb = False
        return run.event(X, EventKind.FLYBACK_END)
    if w == room:
        run.t = t_end
    return False


def _breakaway(X, run, g):
    X[A2] = 0.0
    run.mode = 3 if g > 0 else 1
    run.nbrk += 1
    run.just_broke = True
    return run.event(X, EventKind.BREAKAWAY)


def _moving(X, dbox, run, t_end, bridge, noise):
    """One sliding sub-step (or to a velocity zero / flyback end); True when the interval must stop."""
    p, o, L = run.p, run.o, run.L
    s = 1.0 if run.mode == 3 else -1.0
    x3, u, d = X[A3], X[AU], dbox[0]
    room = t_end - run.t
    h_fb = math.inf if not run.fb else p.motor_time_constant * math.log1p(abs(x3) / p.u_max)
    H = min(o.substep, room, h_fb)
    shift = d
    if run.just_broke:
        kc, ks = effective_levels(X[ATH], X[A5], L)
        H = min(o.reflect_substep, H)
        # the push that starts the motion: reflected in this first sub-step (s·(x3 + d) ≥ ks)
        shift = d + s * max(0.0, ks * (1.0 + 1e-12) + 1e-300 - s * (x3 + d))
    elif noise is None:
        shift = d * math.exp(-0.5 * H / p.disturbance_torque_tau)          # the midpoint's d
    run.just_broke = False
    X[A3] = x3 + shift
    X[AU] = u + shift
    if noise is None:
        adv, stopped, peak, n = rk_segment(X, s, H, L, run.peak, run.hbox)
    else:
        z, cur = noise.ready()
        budget = max(o.max_events - run.nev - run.nsub, 1)
        adv, stopped, peak, n = noisy_segment(X, s, H, run.prm, L, o.substep, o.reflect_substep, o.bisection_tol,
                                              z, cur, run.peak, budget)
    X[AU] = u
    X[A3] = u + (x3 - u) * math.exp(-adv / p.motor_time_constant)
    dbox[0] = _ou(d, adv, p, noise)
    run.peak = peak
    run.nsub += n
    run.torque(x3, u, adv, bridge)
    run.t += adv
    if run.tick():
        return True
    if stopped:
        return _velocity_zero(X, dbox[0], run, s)
    if adv < H:
        run.status = Status.CHATTER
        return True
    if H == h_fb and h_fb <= room:
        X[A3] = X[AU] = 0.0
        run.fb = False
        return run.event(X, EventKind.FLYBACK_END)
    if H == room:
        run.t = t_end
    return False


def _velocity_zero(X, d, run, s):
    """x2 = 0 while sliding: reflect, reverse or stick by x3 + d against ks (SPEC §2)."""
    X[A2] = 0.0
    kc, ks = effective_levels(X[ATH], X[A5], run.L)
    g = X[A3] + d
    if s * g > ks:
        kind = EventKind.REFLECTION
        run.just_broke = True
    elif -s * g > ks:
        run.mode = 1 if run.mode == 3 else 3
        run.nbrk += 1
        run.just_broke = True
        kind = EventKind.REVERSAL
    else:
        run.mode = 2
        run.nstk += 1
        kind = EventKind.STICK
    return run.event(X, kind)


def advance(state: PlantState, command: DriveCommand, params, noise: NoiseStream | None,
            options: SimOptions = SimOptions(), *, duration: float | None = None,
            record: bool = False) -> IntervalResult:
    """One interval of the disturbed stribeck plant; the contract of plant.stribeck.interval.advance."""
    h = params.sample_period if duration is None else float(duration)
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"duration must be a finite positive number of seconds, got {duration!r}")
    x = np.asarray(state.x, dtype=float)
    if x.shape != (N_X,):
        raise ValueError(f"a disturbed stribeck state has {N_X} entries (x1..x5, u, θ, d), got shape {x.shape}")
    noisy = bool(options.noise and noise is not None)
    if not noisy and x[D] == 0.0:                 # d stays 0: the compiled step
        r = compiled.advance(state._replace(x=x[:D]), command, params, None, options, duration=duration,
                             record=record)
        xo = np.append(r.state.x, 0.0)
        xo.flags.writeable = False
        return r._replace(state=r.state._replace(x=xo))
    offsets, levels = command.arrays()
    if offsets[-1] >= h:
        raise ValueError(f"DriveCommand segment at offset {offsets[-1]!r} s lies beyond the interval of {h!r} s")
    bridge = command.drive is DriveType.BRIDGE
    nz = _Noise(noise) if noisy else None
    X = np.array([x[0], x[1], x[2], x[3], x[4], params.coulomb, x[5], x[6]])
    dbox = [float(x[D])]
    run = _Run(params, options, state.t, state.mode, state.flyback, record)
    run.peak = abs(X[A1])
    t0 = state.t
    for seg in range(len(offsets)):
        t_seg_end = t0 + (offsets[seg + 1] if seg + 1 < len(offsets) else h)
        if not _apply_level(X, run, float(levels[seg]), bridge):
            raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max}), got {command.segments!r}")
        stop = seg > 0 and run.event(X, EventKind.LEVEL)
        while not stop and run.t < t_seg_end:
            if run.mode == 2:
                stop = _stuck(X, dbox, run, t_seg_end, bridge, nz)
            else:
                stop = _moving(X, dbox, run, t_seg_end, bridge, nz)
            stop = stop or run.status is not Status.OK
            if not stop and not (abs(X[A1]) <= options.diverge_error):
                run.status = Status.DIVERGED
                stop = True
        if stop:
            break
    if nz is not None:
        nz.done()
    if run.status is Status.OK:
        run.t = t0 + h
    xo = np.array([X[A1], X[A2], X[A3], X[A4], X[A5], X[AU], X[ATH], dbox[0]])
    xo.flags.writeable = False
    new = PlantState(run.t, xo, int(run.mode), bool(run.fb))
    message = ""
    if run.status is Status.CHATTER:
        message = f"more than {options.max_events} events in one interval at t={run.t:.6f} s"
    elif run.status is Status.DIVERGED:
        message = f"|x1| = {abs(X[A1]):.3g} rad at t={run.t:.6f} s"
    events = None
    if record:
        arr = np.array(run.events, dtype=float).reshape(-1, len(EVENT_FIELDS))
        events = {name: arr[:, i].copy() for i, name in enumerate(EVENT_FIELDS)}
        events["mode"] = events["mode"].astype(np.int8)
        events["kind"] = events["kind"].astype(np.int8)
    return IntervalResult(new, run.status, message, run.peak, run.iabs, run.isq, run.chg, run.dur, run.nev,
                          run.nbrk, run.nstk, run.nsub, events)
