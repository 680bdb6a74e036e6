"""An independent reference for the two-mass plant: ``solve_ivp`` (DOP853) with events.

Written from the equations of SPEC §11 (not from plant.two_mass): the ODE per mode, the
switching table of SPEC §2 with the shaft torque T = k·φ + c·(ω_m − x2) on the load, the
bridge's flyback. Noise-free only (x4 decays, x5 constant). ``max_step`` bounds the step so
that solve_ivp's sign-change event test cannot step over a short excursion.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp


def _rhs(mode, p, u, x5):
    J, Jm, k, c = p.inertia, p.motor_inertia, p.shaft_stiffness, p.shaft_damping
    tau3, tau4 = p.motor_time_constant, p.command_velocity_tau
    kc = max(p.coulomb + x5, 0.0)
    s = 0.0 if mode == 2 else (1.0 if mode == 3 else -1.0)

    def f(t, y):
        x1, x2, x3, x4, phi, wm = y
        T = k * phi + c * (wm - x2)
        dx2 = 0.0 if mode == 2 else (T - s * kc) / J
        return [x2 - x4, dx2, (u - x3) / tau3, -x4 / tau4, wm - x2, (x3 - T) / Jm]
    return f


def reference_interval(p, y, mode, flyback, segments, bridge, duration, t0=0.0, x5=0.0, max_step=2e-5,
                       rtol=1e-13):
    """Advance y = [x1, x2, x3, x4, φ, ω_m] over one interval; (y, mode, flyback, events).

    ``segments``: [(offset, level)]. Events: (t, kind) with kind in {"breakaway", "stick",
    "reversal", "flyback_end"}.
    """
    y = np.array(y, dtype=float)
    k, c = p.shaft_stiffness, p.shaft_damping
    ks = max(p.stiction + x5, 0.0)
    events = []
    atol = np.array([1e-18, 1e-16, 1e-14, 1e-18, 1e-18, 1e-16])
    u = 0.0
    for i, (off, level) in enumerate(segments):
        t_end = t0 + (segments[i + 1][0] if i + 1 < len(segments) else duration)
        t = t0 + off
        if bridge:
            if level != 0:
                u, flyback = math.copysign(p.u_max, level), False
            elif y[2] != 0.0:
                u, flyback = -math.copysign(p.u_max, y[2]), True
            else:
                u, flyback = 0.0, False
        else:
            u, flyback = min(max(level, -p.u_max), p.u_max), False
        while t < t_end:
            evs = []
            if mode == 2:
                up = lambda t, y: k * y[4] + c * (y[5] - y[1]) - ks
                up.terminal, up.direction = True, 1
                dn = lambda t, y: k * y[4] + c * (y[5] - y[1]) + ks
                dn.terminal, dn.direction = True, -1
                evs += [up, dn]
            else:
                s = 1.0 if mode == 3 else -1.0
                vz = lambda t, y: y[1]
                vz.terminal, vz.direction = True, -s
                evs.append(vz)
            if flyback:
                fb = lambda t, y: y[2]
                fb.terminal, fb.direction = True, -math.copysign(1.0, y[2])
                evs.append(fb)
            sol = solve_ivp(_rhs(mode, p, u, x5), (t, t_end), y, method="DOP853", rtol=rtol, atol=atol,
                            events=evs, max_step=max_step)
            hits = [(te[0], j) for j, te in enumerate(sol.t_events) if len(te)]
            if not hits:
                y = sol.y[:, -1].copy()
                t = t_end
                continue
            te, j = min(hits)
            y = sol.y_events[j][0].copy()
            t = te
            which = evs[j]
            if flyback and which is evs[-1]:
                y[2] = 0.0
                u, flyback = 0.0, False
                events.append((t, "flyback_end"))
            elif mode == 2:
                mode = 3 if which is evs[0] else 1
                events.append((t, "breakaway"))
            else:
                y[1] = 0.0
                s = 1.0 if mode == 3 else -1.0
                T = k * y[4] + c * (y[5] - y[1])
                if s * T > ks:
                    events.append((t, "reflection"))
                elif -s * T > ks:
                    mode = 1 if mode == 3 else 3
                    events.append((t, "reversal"))
                else:
                    mode = 2
                    events.append((t, "stick"))
    return y, mode, flyback, events
