"""Reference simulator of the ``lugre`` family, independent of its compiled step.

:func:`event_driven` — noise-free ``scipy.integrate.solve_ivp`` (Radau by default) on the full
state (x1, x2, x3, x4, x5, θ, z), piecewise in the command's segments, with the flyback end
(x3 = 0) as a terminal event: what a user would write today. :func:`spring_block` — the
stick-slip example of Canudas de Wit et al. (1995): a mass m on the LuGre law, pulled through a
spring k whose end moves at v_p.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

from plant.drive import DriveType

__all__ = ["event_driven", "spring_block", "euler_maruyama"]


def _friction(p, v, z, theta, x5):
    m = 1.0 + p.friction_ripple * math.sin(2.0 * math.pi * theta / p.ripple_period + p.ripple_phase)
    kc, ks = max(p.coulomb * m + x5, 0.0), max(p.stiction * m + x5, 0.0)
    g = kc + (ks - kc) * math.exp(-(v / p.stribeck_velocity) ** 2)
    zdot = v - p.bristle_stiffness * abs(v) * z / g
    return p.bristle_stiffness * z + p.bristle_damping * zdot + p.viscous * v, zdot


def event_driven(params, x0, commands, *, method="Radau", rtol=1e-11, duration=None):
    """x1 at the end of each interval and the final state, under ``commands`` (one per interval).

    ``x0`` = (x1, x2, x3, x4, x5, u, θ, z); flyback off at the start.
    """
    p = params
    J, tau3, tau4, tau5 = p.inertia, p.motor_time_constant, p.command_velocity_tau, p.correlated_friction_tau
    span = p.sample_period if duration is None else duration
    y = np.array([x0[0], x0[1], x0[2], x0[3], x0[4], x0[6], x0[7]], dtype=float)
    u, t = float(x0[5]), 0.0
    atol = np.array([1e-20, 1e-15, 1e-13, 1e-20, 1e-13, 1e-20, 1e-20])
    out = []

    def rhs(_, s):
        x1, x2, x3, x4, x5, th, z = s
        F, zdot = _friction(p, x2, z, th, x5)
        return [x2 - x4, (x3 - F) / J, (u - x3) / tau3, -x4 / tau4, -x5 / tau5, x2, zdot]

    for cmd in commands:
        offsets = [o for o, _ in cmd.segments] + [span]
        bridge = cmd.drive is DriveType.BRIDGE
        t_int = t
        for k, (_, level) in enumerate(cmd.segments):
            t_end = t_int + offsets[k + 1]
            flyback = False
            if not bridge:
                u = min(max(level, -p.u_max), p.u_max)
            elif level != 0.0:
                u = math.copysign(p.u_max, level)
            elif y[2] != 0.0:
                u, flyback = -math.copysign(p.u_max, y[2]), True
            else:
                u = 0.0
            while t_end - t > 1e-15:
                events = []
                if flyback:
                    ev = lambda _, s: s[2]
                    ev.terminal = True
                    events.append(ev)
                sol = solve_ivp(rhs, (t, t_end), y, method=method, rtol=rtol, atol=atol, events=events or None)
                if flyback and len(sol.t_events[0]):
                    t, y = sol.t_events[0][0], sol.y_events[0][0].copy()
                    y[2], u, flyback = 0.0, 0.0, False
                    continue
                y, t = sol.y[:, -1].copy(), t_end
        t = t_int + span
        out.append(y[0])
    return np.array(out), np.array([y[0], y[1], y[2], y[3], y[4], u, y[5], y[6]])


def spring_block(sigma0, sigma1, sigma2, fc, fs, vs, mass, k, pull, t_end, *, method="Radau", rtol=1e-11,
                 n_out=200_001):
    """The 1995 paper's stick-slip example: m·ẍ = k·(v_p·t − x) − F (LuGre), from rest.

    Returns (t, x, v, F) on a uniform grid of ``n_out`` points."""
    def rhs(t, s):
        x, v, z = s
        g = fc + (fs - fc) * math.exp(-(v / vs) ** 2)
        zdot = v - sigma0 * abs(v) * z / g
        F = sigma0 * z + sigma1 * zdot + sigma2 * v
        return [v, (k * (pull * t - x) - F) / mass, zdot]

    t = np.linspace(0.0, t_end, n_out)
    sol = solve_ivp(rhs, (0.0, t_end), [0.0, 0.0, 0.0], method=method, rtol=rtol, atol=[1e-14, 1e-14, 1e-16],
                    t_eval=t)
    x, v, z = sol.y
    g = fc + (fs - fc) * np.exp(-(v / vs) ** 2)
    zdot = v - sigma0 * np.abs(v) * z / g
    return t, x, v, sigma0 * z + sigma1 * zdot + sigma2 * v


def euler_maruyama(params, x0, commands, n_paths, h, rng):
    """Fixed-step Euler–Maruyama of ``n_paths`` paths: x1 at the end of each interval (n_int × n_paths).

    Bridge drive with flyback diodes; w2 on x2 with intensity σ2²·(1 − exp(−(x2/v_s)²)) (as the
    family), w4, and w5 on x5 (not frozen); x3 exact per step for constant u.
    """
    p = params
    J, tau3, s0, s1, s2 = p.inertia, p.motor_time_constant, p.bristle_stiffness, p.bristle_damping, p.viscous
    n = n_paths
    x1, x2, x3, x4, x5, th, z = (np.full(n, float(x0[i])) for i in (0, 1, 2, 3, 4, 6, 7))
    sw2 = math.sqrt(p.sigma2_sq * h) / J
    sw4 = math.sqrt(p.sigma4_sq * h)
    sw5 = math.sqrt(p.sigma5_sq * h)
    steps = int(round(p.sample_period / h))
    out = np.empty((len(commands), n))
    decay = math.exp(-h / tau3)
    for i, cmd in enumerate(commands):
        offsets = np.array([o for o, _ in cmd.segments])
        lv = np.array([lev for _, lev in cmd.segments])
        for k in range(steps):
            level = lv[np.searchsorted(offsets, k * h + 1e-15, side="right") - 1]
            if level != 0.0:
                u = np.full(n, math.copysign(p.u_max, level))
            else:
                u = -np.sign(x3) * p.u_max
            m = 1.0 + p.friction_ripple * np.sin(2.0 * np.pi * th / p.ripple_period + p.ripple_phase)
            kc = np.maximum(p.coulomb * m + x5, 0.0)
            ks = np.maximum(p.stiction * m + x5, 0.0)
            g = kc + (ks - kc) * np.exp(-(x2 / p.stribeck_velocity) ** 2)
            zdot = x2 - s0 * np.abs(x2) * z / g
            F = s0 * z + s1 * zdot + s2 * x2
            slide = np.sqrt(-np.expm1(-(x2 / p.stribeck_velocity) ** 2))   # w2 through the sliding part
            x2n = x2 + h * (x3 - F) / J + sw2 * slide * rng.standard_normal(n)
            x1 = x1 + h * (x2 - x4)
            th = th + h * x2
            z = z + h * zdot
            x3_old = x3
            x3 = u + (x3 - u) * decay
            if level == 0.0:
                x3 = np.where(np.sign(x3) != np.sign(x3_old), 0.0, x3)
            x4 = x4 - h * x4 / p.command_velocity_tau + sw4 * rng.standard_normal(n)
            x5 = x5 - h * x5 / p.correlated_friction_tau + sw5 * rng.standard_normal(n)
            x2 = x2n
        out[i] = x1
    return out
