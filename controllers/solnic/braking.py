"""A braking pulse: a forward pulse followed by a timed reverse drive that ends the motion early.

Option ``braking_pulse`` of :class:`~controllers.solnic.options.SolnicOptions` (issue 13). The
friction noise w2 scatters a pulse's motion with variance ≈ α²σ2²·T_m³/3 and more (T_m the
moving time, :mod:`controllers.solnic.noise_model`), and after the flyback the shaft coasts on
Coulomb friction alone, decelerating at only α·k_c (2.8 rad/s² for Table 2-1). A pulse pair
shortens that tail: the bridge drives +u_max for Δt_u, then −u_max until t_off, then is
switched off (the diodes drive +u_max until the now negative current is back to zero at
t_cz2), then 0. On the bridge −u_max after Δt_u is what the flyback applies anyway, so the pair
is the single pulse whose flyback voltage is held past the current zero: x3 goes negative and
the shaft decelerates at α(k_c − x3) > α·k_c.

Noise-free response (sign +1; the plant's closed forms (3-20)/(3-21) through
:func:`controllers.models.acker.move_closed_form`): stuck until x3 = k_s at t_b = −τ3·ln(1 − k_s/u_max); driven to
Δt_u; u = −u_max to t_off; u = +u_max to t_cz2 = t_off + τ3·ln((u_max − x3(t_off))/u_max);
coasting at −α·k_c to the stop t_stop = t_cz2 + v(t_cz2)/(α·k_c), Δc = x1(t_cz2) +
v(t_cz2)²/(2α·k_c). If the velocity reaches zero earlier, the stop is that zero (a safeguarded
root of the closed-form velocity); the shaft sticks there if |x3| ≤ k_s.

Timing (from the model, not from the text): t_off is chosen so that the noise-free velocity at
the end of the reverse current is a margin of r_b standard deviations of the w2 velocity
spread, v(t_cz2) = r_b·s·√(t_cz2 − t_b) (s² = α²σ2²). Then (i) the noisy shaft stops, with
high probability, after x3 is back above −k_s — a stop while x3 < −k_s would reverse the shaft
(mode 1) — and (ii) the noise model's coasting formulas (1)–(3) hold with t_cz2 in place of
t_cz (v0(t_cz2)/√V = r_b ≥ 0.75, where they agree with the exact backward equations). v(t_cz2)
decreases strictly with t_off (a longer reverse drive removes more velocity), so t_off is a
bisection root. For the largest pairs the reverse current goes below −k_s before t_off
(x3(t_off) = −3.2 ozf·in at Δt_u = 3 ms): a noisy path that sticks early would then break away
backward; such paths are in the Monte-Carlo of ``tests/test_solnic_braking.py`` (the pair's
mean and variance stay within its tolerances), not in the noise model. No brake when the single pulse already ends with v(t_cz) ≤ r_b·√V, and
t_cz2 is capped at ``max_duration`` (the pair must end inside one sample interval; a capped
pair brakes less than the target, never more).
"""

from __future__ import annotations

import math

from numba import njit

from controllers.models.acker import closed_form_kernel, move_closed_form, velocity_root

__all__ = ["brake_timing", "braked_response"]


@njit(cache=True)
def _pair(dt_u, t_off, U, t3, a, ks, kc):
    """(Δc, t_b or −1, t_cz2, t_stop, v(t_cz2), x3 at the stop) of the pair, noise-free, sign +1.

    ``t_off`` ≤ the single pulse's current zero gives the single pulse. A stop before t_cz2
    returns v(t_cz2) = −1 (the velocity's first zero ends the motion there).
    """
    x3_on = -U * math.expm1(-dt_u / t3)
    t_cz = dt_u + t3 * math.log1p(x3_on / U)
    if not t_off > t_cz:
        dc, tb, tcz, ts = closed_form_kernel(dt_u, U, t3, a, ks, kc)
        return dc, tb, tcz, ts, math.nan, 0.0
    t_b = -t3 * math.log1p(-ks / U)
    if not dt_u > t_b:
        return 0.0, -1.0, t_cz, 0.0, 0.0, 0.0
    x1, x2, x3 = move_closed_form(0.0, 0.0, ks, U, kc, dt_u - t_b, t3, a)           # driven
    h = t_off - dt_u
    e1_, v_end, x3e = move_closed_form(x1, x2, x3, -U, kc, h, t3, a)                 # flyback, then reverse drive
    if v_end <= 0.0:
        tau = velocity_root(x1, x2, x3, -U, kc, h, t3, a)
        x1s, _, x3s = move_closed_form(x1, x2, x3, -U, kc, tau, t3, a)
        return x1s, t_b, t_off + t3 * math.log((U - x3e) / U), dt_u + tau, -1.0, x3s
    x1, x2, x3 = e1_, v_end, x3e
    t_f = t3 * math.log((U - x3) / U)                                     # diodes +U to x3 = 0
    t_cz2 = t_off + t_f
    v_cz2 = move_closed_form(x1, x2, x3, U, kc, t_f, t3, a)[1]
    if v_cz2 <= 0.0:
        tau = velocity_root(x1, x2, x3, U, kc, t_f, t3, a)
        x1s, _, x3s = move_closed_form(x1, x2, x3, U, kc, tau, t3, a)
        return x1s, t_b, t_cz2, t_off + tau, -1.0, x3s
    x1 = move_closed_form(x1, x2, x3, U, kc, t_f, t3, a)[0]
    return x1 + v_cz2 * v_cz2 / (2.0 * a * kc), t_b, t_cz2, t_cz2 + v_cz2 / (a * kc), v_cz2, 0.0


@njit(cache=True)
def _timing(dt_u, U, t3, a, ks, kc, s2, margin, max_duration, min_ratio):
    """t_off of the pair (module docstring), or −1 when no brake applies."""
    x3_on = -U * math.expm1(-dt_u / t3)
    t_cz = dt_u + t3 * math.log1p(x3_on / U)
    t_b = -t3 * math.log1p(-ks / U)
    if not (dt_u > t_b and kc > 0.0 and s2 > 0.0) or t_cz >= max_duration:
        return -1.0
    r = _pair(dt_u, t_cz, U, t3, a, ks, kc)
    if r[3] <= t_cz:                                                      # stops during the flyback
        return -1.0
    v_cz = a * kc * (r[3] - t_cz)
    if v_cz <= max(margin, min_ratio) * math.sqrt(s2 * (t_cz - t_b)):
        return -1.0
    # the longest reverse drive whose current is back to zero by max_duration T: with
    # y = e^(−(t_off − Δt_u)/τ3), x3(t_off) = −U + (x3_on + U)·y and t_cz2 = t_off +
    # τ3·ln((U − x3(t_off))/U) = T give 2/y − (1 + x3_on/U) = e^((T − Δt_u)/τ3), so
    t_cap = dt_u + t3 * math.log(0.5 * (1.0 + x3_on / U + math.exp((max_duration - dt_u) / t3)))
    g_hi = _brake_excess(dt_u, t_cap, U, t3, a, ks, kc, s2, margin, t_b)
    if g_hi >= 0.0:
        return t_cap                                                      # capped: brake as much as fits
    # the root of g(t_off) = v(t_cz2) − r_b·√(s²(t_cz2 − t_b)), decreasing: g(lo) > 0 ≥ g(hi).
    # Illinois regula falsi (the retained end's g halved), a bisection step whenever the bracket
    # has not halved in two steps (g jumps to −1 where the pair stops early), and every trial
    # point at least tol/2 inside the bracket, so a root at an end closes it at once: ~10
    # evaluations of the pair instead of bisection's ~40. Returns lo, g(lo) > 0, within tol.
    tol = 1e-14
    lo, hi = t_cz, t_cap
    g_lo = v_cz - margin * math.sqrt(s2 * (t_cz - t_b))                  # the single pulse: > 0
    side, width, stale = 0, hi - lo, 0
    for _ in range(200):
        if hi - lo <= tol:
            break
        if stale >= 2:
            mid, stale, width = 0.5 * (lo + hi), 0, 0.5 * (hi - lo)
        else:
            mid = lo + (hi - lo) * (g_lo / (g_lo - g_hi))
            mid = min(max(mid, lo + 0.5 * tol), hi - 0.5 * tol)
        g = _brake_excess(dt_u, mid, U, t3, a, ks, kc, s2, margin, t_b)
        if g > 0.0:
            lo, g_lo = mid, g
            if side == 1:
                g_hi *= 0.5
            side = 1
        else:
            hi, g_hi = mid, g
            if side == -1:
                g_lo *= 0.5
            side = -1
        if hi - lo <= 0.5 * width:
            width, stale = hi - lo, 0
        else:
            stale += 1
    return lo


@njit(cache=True)
def _brake_excess(dt_u, t_off, U, t3, a, ks, kc, s2, margin, t_b):
    """g(t_off) = v(t_cz2) − r_b·√(s²(t_cz2 − t_b)) [rad/s] of the pair (the timing's root)."""
    g = _pair(dt_u, t_off, U, t3, a, ks, kc)
    return g[4] - margin * math.sqrt(s2 * (g[2] - t_b))


def brake_timing(params, dt_u: float, margin: float, max_duration: float | None = None,
                 min_ratio: float = 0.0) -> float | None:
    """t_off [s] from the pulse start for a pulse of ``dt_u`` with ``params``' friction, or None.

    ``margin`` is r_b (standard deviations of the w2 velocity spread left at t_cz2);
    ``max_duration`` caps t_cz2 (default 0.8 × the sample period); ``min_ratio``: brake only
    pulses whose single version ends the flyback with v0(t_cz) ≥ that many standard deviations
    (a long coast: the pulses whose scatter the brake reduces most). Without friction noise
    (σ2 = 0) there is no scatter to reduce and no brake.
    """
    p = params
    cap = 0.8 * p.sample_period if max_duration is None else float(max_duration)
    t = _timing(float(dt_u), p.u_max, p.motor_time_constant, p.alpha, p.stiction, p.coulomb,
                p.alpha**2 * p.sigma2_sq, float(margin), cap, float(min_ratio))
    return None if t < 0.0 else float(t)


def braked_response(params, dt_u: float, t_off: float | None):
    """(Δc [rad], t_breakaway [s] or None, t_current_zero [s], t_stop [s]) of the pair, sign +1,
    noise-free; ``t_off=None`` is the single pulse (:func:`plant.pulse_response`)."""
    p = params
    dc, tb, tcz, ts, _, _ = _pair(float(dt_u), -1.0 if t_off is None else float(t_off), p.u_max,
                                  p.motor_time_constant, p.alpha, p.stiction, p.coulomb)
    return dc, (None if tb < 0.0 else tb), tcz, (ts if tb >= 0.0 else 0.0)
