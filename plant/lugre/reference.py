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

__all__ = ["event_driven", "spring_block"]


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
