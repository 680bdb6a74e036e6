"""Reference simulators of the ``stribeck`` family, independent of its compiled step.

* :func:`event_driven` — noise-free, ``scipy.integrate.solve_ivp`` (Radau by default) on the
  full state (x1, x2, x3, x4, x5, θ) with terminal events for breakaway (x3 = ±ks while
  stuck), velocity zero (sliding) and the flyback end, and SPEC §2's switching table at each
  velocity zero: what a user would write today.
* :func:`euler_maruyama` — fixed-step Euler–Maruyama for many paths at once (numpy), with the
  mode logic checked once per step (SPEC §2's fixed-step reference): a stick when the velocity
  changes sign with |x3| ≤ ks, a reversal when |x3| > ks the other way, reflection while the
  torque still breaks stiction forward.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from plant.drive import DriveType

__all__ = ["event_driven", "euler_maruyama"]


def _levels(p, theta, x5):
    m = 1.0 + p.friction_ripple * math.sin(2.0 * math.pi * theta / p.ripple_period + p.ripple_phase)
    return max(p.coulomb * m + x5, 0.0), max(p.stiction * m + x5, 0.0)


def _friction(p, v, theta, x5):
    kc, ks = _levels(p, theta, x5)
    return kc + (ks - kc) * math.exp(-(abs(v) / p.stribeck_velocity) ** p.stribeck_exponent) + p.viscous * abs(v)


def event_driven(params, x0, mode0, commands, *, method="Radau", rtol=1e-11, duration=None):
    """x1 at the end of each interval, and the final (x, mode), under ``commands`` (one per interval).

    ``x0`` = (x1, x2, x3, x4, x5, u, θ); ``mode0`` in {1, 2, 3}; flyback off at the start.
    """
    p = params
    J, tau3, tau4, tau5 = p.inertia, p.motor_time_constant, p.command_velocity_tau, p.correlated_friction_tau
    span = p.sample_period if duration is None else duration
    y = np.array([x0[0], x0[1], x0[2], x0[3], x0[4], x0[6]], dtype=float)
    u, mode, flyback, t = float(x0[5]), int(mode0), False, 0.0
    atol = np.array([1e-20, 1e-16, 1e-13, 1e-20, 1e-13, 1e-20])
    out = []

    def rhs(_, z):
        x1, x2, x3, x4, x5, th = z
        dx3 = (u - x3) / tau3
        if mode == 2:
            return [-x4, 0.0, dx3, -x4 / tau4, 0.0, 0.0]
        s = 1.0 if mode == 3 else -1.0
        return [x2 - x4, (x3 - s * _friction(p, x2, th, x5)) / J, dx3, -x4 / tau4, -x5 / tau5, x2]

    for cmd in commands:
        offsets = [o for o, _ in cmd.segments] + [span]
        bridge = cmd.drive is DriveType.BRIDGE
        t_int = t
        for k, (_, level) in enumerate(cmd.segments):
            t_end = t_int + offsets[k + 1]
            if not bridge:
                u, flyback = min(max(level, -p.u_max), p.u_max), False
            elif level != 0.0:
                u, flyback = math.copysign(p.u_max, level), False
            elif y[2] != 0.0:
                u, flyback = -math.copysign(p.u_max, y[2]), True
            else:
                u, flyback = 0.0, False
            while t_end - t > 1e-15:
                events = []
                if flyback:
                    ev_fb = lambda _, z: z[2]
                    ev_fb.terminal = True
                    events.append(("flyback", ev_fb))
                if mode == 2:
                    ks = _levels(p, y[5], y[4])[1]
                    up = lambda _, z, ks=ks: z[2] - ks
                    up.terminal, up.direction = True, 1
                    dn = lambda _, z, ks=ks: z[2] + ks
                    dn.terminal, dn.direction = True, -1
                    events += [("up", up), ("down", dn)]
                else:
                    zero = lambda _, z: z[1]
                    zero.terminal, zero.direction = True, (-1 if mode == 3 else 1)
                    events.append(("zero", zero))
                sol = solve_ivp(rhs, (t, t_end), y, method=method, rtol=rtol, atol=atol,
                                events=[e for _, e in events])
                hit = None
                for (name, _), te, ye in zip(events, sol.t_events, sol.y_events):
                    if len(te) and (hit is None or te[0] < hit[1]):
                        hit = (name, te[0], ye[0])
                if hit is None:
                    y, t = sol.y[:, -1].copy(), t_end
                    break
                name, t, y = hit[0], hit[1], hit[2].copy()
                if name == "flyback":
                    y[2], u, flyback = 0.0, 0.0, False
                elif name in ("up", "down"):
                    mode = 3 if name == "up" else 1
                    y[2] = _levels(p, y[5], y[4])[1] * (1 if mode == 3 else -1)
                else:
                    y[1] = 0.0
                    s = 1.0 if mode == 3 else -1.0
                    ks = _levels(p, y[5], y[4])[1]
                    if s * y[2] > ks:
                        pass
                    elif -s * y[2] > ks:
                        mode = 1 if mode == 3 else 3
                    else:
                        mode = 2
        t = t_int + span
        out.append(y[0])
    x = np.array([y[0], y[1], y[2], y[3], y[4], u, y[5]])
    return np.array(out), x, mode


def euler_maruyama(params, x0, mode0, commands, n_paths, h, rng):
    """Fixed-step Euler–Maruyama of ``n_paths`` paths: x1 at the end of each interval (n_int × n_paths).

    Bridge drive with flyback diodes; every noise of SPEC §2 (w2 while sliding, w4, w5 while
    sliding). Mode logic once per step, as SPEC §2's fixed-step reference.
    """
    p = params
    J, tau3 = p.inertia, p.motor_time_constant
    n = n_paths
    x1 = np.full(n, float(x0[0]))
    x2 = np.full(n, float(x0[1]))
    x3 = np.full(n, float(x0[2]))
    x4 = np.full(n, float(x0[3]))
    x5 = np.full(n, float(x0[4]))
    th = np.full(n, float(x0[6]))
    mode = np.full(n, int(mode0))
    sw2 = math.sqrt(p.sigma2_sq * h) / J
    sw4 = math.sqrt(p.sigma4_sq * h)
    sw5 = math.sqrt(p.sigma5_sq * h)
    steps = int(round(p.sample_period / h))
    out = np.empty((len(commands), n))
    u = np.zeros(n)
    for i, cmd in enumerate(commands):
        offsets = np.array([o for o, _ in cmd.segments])
        lv = np.array([lev for _, lev in cmd.segments])
        for k in range(steps):
            tk = k * h
            level = lv[np.searchsorted(offsets, tk + 1e-15, side="right") - 1]
            if level != 0.0:
                u[:] = math.copysign(p.u_max, level)
            else:
                u = np.where(x3 > 0, -p.u_max, np.where(x3 < 0, p.u_max, 0.0)) * (np.abs(x3) > 0)
            m = 1.0 + p.friction_ripple * np.sin(2.0 * np.pi * th / p.ripple_period + p.ripple_phase)
            kc = np.maximum(p.coulomb * m + x5, 0.0)
            ks = np.maximum(p.stiction * m + x5, 0.0)
            moving = mode != 2
            s = np.where(mode == 3, 1.0, -1.0)
            F = kc + (ks - kc) * np.exp(-(np.abs(x2) / p.stribeck_velocity) ** p.stribeck_exponent) \
                + p.viscous * np.abs(x2)
            dW2 = rng.standard_normal(n)
            dW4 = rng.standard_normal(n)
            dW5 = rng.standard_normal(n)
            x2n = np.where(moving, x2 + h * (x3 - s * F) / J + sw2 * dW2, 0.0)
            x1 = x1 + h * (x2 - x4)
            th = th + h * x2
            x3_old = x3
            x3 = u + (x3 - u) * math.exp(-h / tau3)       # exact for the lag (u constant on the step)
            # flyback ends when the current crosses zero
            fly = (level == 0.0)
            x3 = np.where(fly & (np.sign(x3) != np.sign(x3_old)), 0.0, x3)
            x4 = x4 - h * x4 / p.command_velocity_tau + sw4 * dW4
            x5 = np.where(moving, x5 - h * x5 / p.correlated_friction_tau + sw5 * dW5, x5)
            # mode logic once per step
            crossed = moving & (s * x2n <= 0.0)
            fwd_break = s * x3 > ks
            back_break = -s * x3 > ks
            x2n = np.where(crossed & fwd_break, -x2n, x2n)                       # reflection
            rev = crossed & ~fwd_break & back_break
            stick = crossed & ~fwd_break & ~back_break
            mode = np.where(rev, np.where(mode == 3, 1, 3), mode)
            x2n = np.where(rev, 0.0, x2n)
            mode = np.where(stick, 2, mode)
            x2n = np.where(stick, 0.0, x2n)
            brk_up = (mode == 2) & (x3 > ks)
            brk_dn = (mode == 2) & (x3 < -ks)
            mode = np.where(brk_up, 3, np.where(brk_dn, 1, mode))
            x2 = x2n
        out[i] = x1
    return out
