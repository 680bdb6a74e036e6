"""One move of the identification's noise-free model in one compiled call (issue 25, fifth session).

:class:`plant.identification.fit._Model` plays each move of a log from rest, sample by sample,
through the family's step. For lugre that step is :func:`plant.lugre.interval.advance`: the
compiled interval kernel plus ≈ 16 µs of Python per sample (argument checks, the state object).
:func:`play_move` calls the very same kernel, with the same arguments in the same order, in one
compiled loop over the move's samples, with the fit's settle test (a settled shaft is frozen).
Noise-free only (no noise stream, no event record). Predictions are bit-identical to the Python
loop over ``advance`` (tests/test_identify_speed.py). Additive: nothing else calls it.

:func:`play_all` (issue 25, lugrefast) plays every simulated move of a prediction in one compiled
call on a trimmed copy of the kernel's noise-free arithmetic (below): ≈ 1.6× faster per prediction,
the same angles and the same work counts, bit for bit. When the tolerance vector carries a fifth
entry > 0 (the fit's, ``fit._LUGRE_STIFF``), a step where the shaft slides and λh exceeds it is an
extrapolated linearly implicit Euler step instead (issue 25, eleventh session, below): then the
angles are the Dormand–Prince ones within ≈ 5e-11 rad, not bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.dopri import A as _A, B as _B, C as _C, E as _E
from plant.lugre.integrate import _H0, A1, A2, A3, A4, A5, AKC, ATH, AU, AZ
from plant.lugre.interval import (_CHATTER, _DIVERGED, _MAX_STEPS, N_STATE, NO_EVENTS, SHEET_EVENTS, SHEET_FLYBACK,
                                  SHEET_MODE, SHEET_SIZE, SHEET_STATUS, SHEET_SUBSTEPS, SHEET_T, STATUS_OK,
                                  VELOCITY_THRESHOLD, interval_kernel)
from plant.lugre.law import (L_ALPHA, L_BETA3, L_BETA4, L_BETA5, L_KC, L_KS, L_PHASE, L_PULL, L_RIPPLE, L_S0, L_S1,
                             L_S2, L_SPRING, L_VS, L_WAVENUMBER)

__all__ = ["play_move", "prepare", "WholePlan", "play_all"]

_BAD_LEVEL = 3    # plant.lugre.interval's status code of a bad bridge level

_NO_NOISE = np.empty(0)


@njit(cache=True)
def _play(x, tau, offs, levs, starts, bridge, prm, L, o, tol, z, ev, last, sigma0, ring, settled, x1):
    """x1[k] = the angle after sample k of the move from state ``x`` (mode 2, no flyback, t = 0);
    returns (kernel status code, samples done, the kernel's events and integrator steps summed).
    After sample ``last`` (u = 0 from there) the shaft is frozen once |z| + |x3|/σ0 + |x2|·ring ≤
    ``settled`` (plant.identification.fit)."""
    out = np.empty(N_STATE + SHEET_SIZE)
    mode, flyback, t = np.int64(2), bool(False), 0.0    # typed, not literal: one kernel signature
    n = x1.shape[0]
    k = 0
    n_ev, n_sub = 0.0, 0.0
    while k < n:
        interval_kernel(x, mode, flyback, t, tau, offs[starts[k]:starts[k + 1]].copy(),
                        levs[starts[k]:starts[k + 1]].copy(), bridge, prm, L, o, z, np.int64(0), ev, out, tol)
        n_ev += out[N_STATE + SHEET_EVENTS]
        n_sub += out[N_STATE + SHEET_SUBSTEPS]
        code = int(out[N_STATE + SHEET_STATUS])
        if code != STATUS_OK:
            return code, k, n_ev, n_sub
        x = out[:N_STATE].copy()
        t = out[N_STATE + SHEET_T]
        mode = int(out[N_STATE + SHEET_MODE])
        flyback = out[N_STATE + SHEET_FLYBACK] != 0.0
        x1[k] = x[0]
        k += 1
        if k <= last:
            continue
        if abs(x[7]) + abs(x[2]) / sigma0 + abs(x[1]) * ring <= settled:
            x1[k:] = x[0]
            break
    return STATUS_OK, k, n_ev, n_sub


def prepare(commands) -> tuple:
    """A move's commands as the kernel reads them: (offsets, levels, first segment per sample, bridge)."""
    offs = np.concatenate([c.arrays()[0] for c in commands])
    levs = np.concatenate([c.arrays()[1] for c in commands])
    starts = np.cumsum([0] + [len(c.segments) for c in commands]).astype(np.int64)
    return offs, levs, starts, commands[0].drive.value == "bridge"


def play_move(x0, prepared, params, options, tolerances, last: int, ring: float,
              settled: float) -> tuple[np.ndarray | None, tuple[int, int, int]]:
    """(x1, work): the move's angles x1 after each of its commands (``prepared`` = :func:`prepare`)
    from the state ``x0`` (t = 0, mode 2), or None when the plant leaves ``ok`` (the kernel's
    status, or g(v) = 0: ZeroDivisionError, where ``advance`` returns ``Status.ERROR``); ``work``
    = (samples stepped, events, integrator steps), the counts ``advance`` reports per interval,
    summed (zeros after a ZeroDivisionError, whose counts are lost with the kernel's frame).

    ``options``: the noise is off whatever they say (as ``advance`` without a noise stream).

    Raises
    ------
    ValueError
        A bridge level other than 0 and ±u_max (as ``advance``).
    """
    offs, levs, starts, bridge = prepared
    o = options.kernel_vector().copy()
    o[0] = 0.0
    x1 = np.empty(starts.shape[0] - 1)
    try:
        code, k, n_ev, n_sub = _play(np.asarray(x0, dtype=np.float64).copy(), params.sample_period, offs, levs, starts, bridge,
                        params.kernel_record(), params.law_vector(), o, tolerances, _NO_NOISE, NO_EVENTS, last,
                        params.bristle_stiffness, ring, settled, x1)
    except ZeroDivisionError:
        return None, (0, 0, 0)
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max})")
    return (x1 if code == STATUS_OK else None), (k + (code != STATUS_OK), int(n_ev), int(n_sub))


# --- a whole noise-free prediction in one compiled call (issue 25, lugrefast) ----------------------
# The arithmetic of plant.lugre.interval.interval_kernel on its noise-free path (integrate.segment with
# eps = inf, integrate._step, law.rhs), the operations that feed the state kept in the same order, so
# the angles are bit-identical (tests/test_identify_speed.py). Left out, as the fit reads none of them:
# the peak of |x1| (hermite_peak: 2 exp, 2 expm1 per Dormand–Prince step), the torque integrals and the
# event record; x5(t) = x5₀·e^(−β5·t) is x5₀ itself where x5₀ = 0 (the fit's plant: 0·e^(…) = x5₀
# exactly, sign of zero included), which saves one exp of three per right-hand side.

@njit(cache=True)
def _rhs_s(t, v, z, D, u, x30, x50, th0, L):
    """law.rhs's (v̇, ż, Ḋ), the same operations, the segment constants (C_U, C_X30, C_X50, C_TH0) as
    scalars and C_P0 = 0 (F not returned); x5 = x5₀ where x5₀ = 0 (see above)."""
    alpha, s0, s1, s2 = L[L_ALPHA], L[L_S0], L[L_S1], L[L_S2]
    x3 = u + (x30 - u) * math.exp(-L[L_BETA3] * t)
    x5 = x50 if x50 == 0.0 else x50 * math.exp(-L[L_BETA5] * t)
    a = L[L_RIPPLE]
    m = 1.0 + a * math.sin(L[L_WAVENUMBER] * (th0 + D) + L[L_PHASE]) if a != 0.0 else 1.0
    kc = max(L[L_KC] * m + x5, 0.0)
    ks = max(L[L_KS] * m + x5, 0.0)
    r = v / L[L_VS]
    g = kc + (ks - kc) * math.exp(-r * r)
    zdot = v - s0 * abs(v) * z / g
    F = s0 * z + s1 * zdot + s2 * v
    vdot = alpha * (x3 + 0.0 + L[L_SPRING] * (L[L_PULL] * t - D) - F)
    return vdot, zdot, v


# the Dormand–Prince tableau (plant.dopri) as compile-time constants of the scalar step
_A10 = float(_A[1, 0])
_A20 = float(_A[2, 0])
_A21 = float(_A[2, 1])
_A30 = float(_A[3, 0])
_A31 = float(_A[3, 1])
_A32 = float(_A[3, 2])
_A40 = float(_A[4, 0])
_A41 = float(_A[4, 1])
_A42 = float(_A[4, 2])
_A43 = float(_A[4, 3])
_A50 = float(_A[5, 0])
_A51 = float(_A[5, 1])
_A52 = float(_A[5, 2])
_A53 = float(_A[5, 3])
_A54 = float(_A[5, 4])
_C1 = float(_C[1])
_C2 = float(_C[2])
_C3 = float(_C[3])
_C4 = float(_C[4])
_C5 = float(_C[5])
_B0 = float(_B[0])
_B1 = float(_B[1])
_B2 = float(_B[2])
_B3 = float(_B[3])
_B4 = float(_B[4])
_B5 = float(_B[5])
_E0 = float(_E[0])
_E1 = float(_E[1])
_E2 = float(_E[2])
_E3 = float(_E[3])
_E4 = float(_E[4])
_E5 = float(_E[5])
_E6 = float(_E[6])


@njit(cache=True)
def _dp_step_s(t, y0, y1, y2, f0, f1, f2, h, u, x30, x50, th0, L):
    """integrate._step on scalars (stage slopes in locals, the same sums in the same order):
    (yn0, yn1, yn2, K6 = the slopes at yn (3), the error vector (3))."""
    s0 = y0 + h * (0.0 + _A10 * f0)
    s1 = y1 + h * (0.0 + _A10 * f1)
    s2 = y2 + h * (0.0 + _A10 * f2)
    k10, k11, k12 = _rhs_s(t + _C1 * h, s0, s1, s2, u, x30, x50, th0, L)
    s0 = y0 + h * (0.0 + _A20 * f0 + _A21 * k10)
    s1 = y1 + h * (0.0 + _A20 * f1 + _A21 * k11)
    s2 = y2 + h * (0.0 + _A20 * f2 + _A21 * k12)
    k20, k21, k22 = _rhs_s(t + _C2 * h, s0, s1, s2, u, x30, x50, th0, L)
    s0 = y0 + h * (0.0 + _A30 * f0 + _A31 * k10 + _A32 * k20)
    s1 = y1 + h * (0.0 + _A30 * f1 + _A31 * k11 + _A32 * k21)
    s2 = y2 + h * (0.0 + _A30 * f2 + _A31 * k12 + _A32 * k22)
    k30, k31, k32 = _rhs_s(t + _C3 * h, s0, s1, s2, u, x30, x50, th0, L)
    s0 = y0 + h * (0.0 + _A40 * f0 + _A41 * k10 + _A42 * k20 + _A43 * k30)
    s1 = y1 + h * (0.0 + _A40 * f1 + _A41 * k11 + _A42 * k21 + _A43 * k31)
    s2 = y2 + h * (0.0 + _A40 * f2 + _A41 * k12 + _A42 * k22 + _A43 * k32)
    k40, k41, k42 = _rhs_s(t + _C4 * h, s0, s1, s2, u, x30, x50, th0, L)
    s0 = y0 + h * (0.0 + _A50 * f0 + _A51 * k10 + _A52 * k20 + _A53 * k30 + _A54 * k40)
    s1 = y1 + h * (0.0 + _A50 * f1 + _A51 * k11 + _A52 * k21 + _A53 * k31 + _A54 * k41)
    s2 = y2 + h * (0.0 + _A50 * f2 + _A51 * k12 + _A52 * k22 + _A53 * k32 + _A54 * k42)
    k50, k51, k52 = _rhs_s(t + _C5 * h, s0, s1, s2, u, x30, x50, th0, L)
    yn0 = y0 + h * (0.0 + _B0 * f0 + _B1 * k10 + _B2 * k20 + _B3 * k30 + _B4 * k40 + _B5 * k50)
    yn1 = y1 + h * (0.0 + _B0 * f1 + _B1 * k11 + _B2 * k21 + _B3 * k31 + _B4 * k41 + _B5 * k51)
    yn2 = y2 + h * (0.0 + _B0 * f2 + _B1 * k12 + _B2 * k22 + _B3 * k32 + _B4 * k42 + _B5 * k52)
    k60, k61, k62 = _rhs_s(t + h, yn0, yn1, yn2, u, x30, x50, th0, L)
    e0 = h * (0.0 + _E0 * f0 + _E1 * k10 + _E2 * k20 + _E3 * k30 + _E4 * k40 + _E5 * k50 + _E6 * k60)
    e1 = h * (0.0 + _E0 * f1 + _E1 * k11 + _E2 * k21 + _E3 * k31 + _E4 * k41 + _E5 * k51 + _E6 * k61)
    e2 = h * (0.0 + _E0 * f2 + _E1 * k12 + _E2 * k22 + _E3 * k32 + _E4 * k42 + _E5 * k52 + _E6 * k62)
    return yn0, yn1, yn2, k60, k61, k62, e0, e1, e2


# --- the fit's stiff-sliding step (issue 25, eleventh session) ----------------------------------------
# While the shaft slides fast, the bristle state relaxes at λ = σ0·|v|/g(v) (ż = v − σ0·|v|·z/g); the
# explicit Dormand–Prince step is then bound by stability (|hλ| ≲ 3.3), not by the tolerance, and a
# prediction's cost grows ∝ σ0 (dev log 4646 case 12 at σ0 = 3e6: 97 % of 536 000 accepted steps had
# λh > 1, mean h 5.8 µs). There, when the fit asks for it (``tol[4]`` > 0, the threshold on λh) and
# the law is the fit's (no ripple, x5 = 0), a step is the linearly implicit Euler method extrapolated
# (Deuflhard's; Hairer & Wanner, Solving ODEs II, §IV.9, extrapolation methods): substeps
# (I − hJ)·Δ = h·f(t_i, y_i) + h²·∂f/∂t with J = ∂f/∂y and ∂f/∂t at the step's start, n = 1 … 6 substeps
# over the step, the results extrapolated in h (Aitken–Neville, the error's expansion in powers of h):
# order 6, its error the difference of the tableau's last two columns, under the same norm and
# tolerance as the Dormand–Prince step. Linearly implicit Euler damps |hλ| → ∞ (R(∞) = 0, and so does each
# extrapolated value, a linear combination of such results), so the step follows the accuracy the slow motion needs. Independent truth: tests/test_identify_stiff.py
# (solve_ivp Radau at rtol 1e-12, every sample of the default plan's moves at σ0 up to 3e6).
_LIE_COLUMNS = 6      # substep counts 1 … 6: 21 right-hand sides per step
_LIE_STEP_COST = 3    # a step counted as this many Dormand–Prince steps (work clock; its CPU measured 2.9–3.7×)


@njit(cache=True)
def _lie_solve(m00, m01, m02, m10, m11, h, b0, b1, b2):
    """Solve (I − hJ)·x = b for J = [[·, ·, ·], [·, ·, 0], [1, 0, 0]] given m00 = 1 − h·J00, m01 = −h·J01,
    m02 = −h·J02, m10 = −h·J10, m11 = 1 − h·J11 (row 3 is Ḋ = v): x2 = b2 + h·x0, x1 = (b1 − m10·x0)/m11."""
    x0 = (b0 - m01 * b1 / m11 - m02 * b2) / (m00 - m01 * m10 / m11 + m02 * h)
    x1 = (b1 - m10 * x0) / m11
    return x0, x1, b2 + h * x0


@njit(cache=True)
def _lie_step_s(t, y0, y1, y2, H, u, x30, x50, th0, L):
    """One extrapolated linearly implicit Euler step of (v, z, D) from segment time t over H (the fit's
    law: no ripple, x5 = 0): (yn0, yn1, yn2, error vector (3))."""
    alpha, s0, s1, s2 = L[L_ALPHA], L[L_S0], L[L_S1], L[L_S2]
    kc = max(L[L_KC], 0.0)
    ks = max(L[L_KS], 0.0)
    vs = L[L_VS]
    r = y0 / vs
    ex = math.exp(-r * r)
    g = kc + (ks - kc) * ex
    gp = (ks - kc) * ex * (-2.0 * r / vs)          # g'(v)
    av = abs(y0)
    sg = 1.0 if y0 > 0.0 else -1.0
    jzz = -s0 * av / g                              # ∂ż/∂z
    jzv = 1.0 - s0 * y1 * sg / g + s0 * y1 * av * gp / (g * g)   # ∂ż/∂v
    jvv = -alpha * (s1 * jzv + s2)                  # ∂v̇/∂v
    jvz = -alpha * (s0 + s1 * jzz)                  # ∂v̇/∂z
    jvd = -alpha * L[L_SPRING]                      # ∂v̇/∂D
    b3 = L[L_BETA3]
    ft0 = alpha * (-b3 * (x30 - u) * math.exp(-b3 * t) + L[L_SPRING] * L[L_PULL])   # ∂v̇/∂t
    T0 = np.empty((_LIE_COLUMNS, _LIE_COLUMNS))
    T1 = np.empty((_LIE_COLUMNS, _LIE_COLUMNS))
    T2 = np.empty((_LIE_COLUMNS, _LIE_COLUMNS))
    for j in range(_LIE_COLUMNS):
        n = j + 1
        h = H / n
        m00, m01, m02, m10, m11 = 1.0 - h * jvv, -h * jvz, -h * jvd, -h * jzv, 1.0 - h * jzz
        w0, w1, w2 = y0, y1, y2
        for i in range(n):
            f0, f1, f2 = _rhs_s(t + i * h, w0, w1, w2, u, x30, x50, th0, L)
            d0, d1, d2 = _lie_solve(m00, m01, m02, m10, m11, h, h * (f0 + h * ft0), h * f1, h * f2)
            w0 += d0
            w1 += d1
            w2 += d2
        T0[j, 0], T1[j, 0], T2[j, 0] = w0, w1, w2
        for k in range(1, j + 1):
            c = 1.0 / ((j + 1.0) / (j + 1.0 - k) - 1.0)
            T0[j, k] = T0[j, k - 1] + (T0[j, k - 1] - T0[j - 1, k - 1]) * c
            T1[j, k] = T1[j, k - 1] + (T1[j, k - 1] - T1[j - 1, k - 1]) * c
            T2[j, k] = T2[j, k - 1] + (T2[j, k - 1] - T2[j - 1, k - 1]) * c
    K = _LIE_COLUMNS - 1
    return (T0[K, K], T1[K, K], T2[K, K], T0[K, K] - T0[K, K - 1], T1[K, K] - T1[K, K - 1],
            T2[K, K] - T2[K, K - 1])


@njit(cache=True, inline="always")
def _error_norm(e0, e1, e2, y0, yn0, y1, yn1, hh, atol0, atol1, atol2, rtol):
    """The RMS of a step's error estimate (e0, e1, e2) over the mixed tolerances of (v, z, D), the
    scale of D being the displacement hh·max|v| (the same norm for the explicit and the stiff step)."""
    sc0 = atol0 + rtol * max(abs(y0), abs(yn0))
    sc1 = atol1 + rtol * max(abs(y1), abs(yn1))
    sc2 = atol2 + rtol * hh * max(abs(y0), abs(yn0))
    acc = 0.0 + (e0 / sc0) ** 2
    acc += (e1 / sc1) ** 2
    acc += (e2 / sc2) ** 2
    return math.sqrt(acc / 3.0)


@njit(cache=True)
def _segment_s(X, H, L, hbox, vth, mode, tol):
    """integrate.segment, noise-free (eps = inf), without the peak, on scalars (:func:`_dp_step_s`):
    the same arithmetic, bit for bit; (advanced, new mode, steps)."""
    u, x30, x40, x50, th0, x10 = X[AU], X[A3], X[A4], X[A5], X[ATH], X[A1]
    y0, y1, y2 = X[A2], X[AZ], 0.0
    f0, f1, f2 = _rhs_s(0.0, y0, y1, y2, u, x30, x50, th0, L)
    b4 = L[L_BETA4]
    rtol, atol0, atol1, atol2 = tol[0], tol[1], tol[2], tol[3]
    t = 0.0
    h = hbox[0] if hbox[0] > 0.0 else _H0
    steps = 0
    new_mode = mode
    # the fit's stiff-sliding step (above): tol[4] = the threshold on λh, when given and > 0
    stiff = tol[4] if tol.shape[0] > 4 else 0.0
    if stiff > 0.0 and (L[L_RIPPLE] != 0.0 or x50 != 0.0):
        stiff = 0.0
    while t < H:
        last = h >= H - t
        hh = H - t if last else h
        if stiff > 0.0 and mode != 2:
            kcs = max(L[L_KC], 0.0)
            rr = y0 / L[L_VS]
            lam = L[L_S0] * abs(y0) / (kcs + (max(L[L_KS], 0.0) - kcs) * math.exp(-rr * rr))
            if lam * hh > stiff:
                yn0, yn1, yn2, e0, e1, e2 = _lie_step_s(t, y0, y1, y2, hh, u, x30, x50, th0, L)
                steps += _LIE_STEP_COST
                err = _error_norm(e0, e1, e2, y0, yn0, y1, yn1, hh, atol0, atol1, atol2, rtol)
                if not err <= 1.0:
                    h = hh * max(0.2, 0.9 * err ** (-1.0 / _LIE_COLUMNS)) if math.isfinite(err) else 0.2 * hh
                    if steps > 5_000_000:
                        break
                    continue
                t = H if last else t + hh
                y0, y1, y2 = yn0, yn1, yn2
                f0, f1, f2 = _rhs_s(t, y0, y1, y2, u, x30, x50, th0, L)
                if not last:
                    h = hh * (5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** (-1.0 / _LIE_COLUMNS))))
                new_mode = 3 if y0 > vth else (1 if y0 < -vth else 2)
                if new_mode != mode:
                    break
                continue
        yn0, yn1, yn2, k0, k1, k2, e0, e1, e2 = _dp_step_s(t, y0, y1, y2, f0, f1, f2, hh, u, x30, x50, th0, L)
        steps += 1
        err = _error_norm(e0, e1, e2, y0, yn0, y1, yn1, hh, atol0, atol1, atol2, rtol)
        if not err <= 1.0:
            h = hh * max(0.2, 0.9 * err ** -0.2) if math.isfinite(err) else 0.2 * hh
            if steps > 5_000_000:
                break
            continue
        t = H if last else t + hh
        y0, y1, y2 = yn0, yn1, yn2
        f0, f1, f2 = k0, k1, k2
        if not last:
            h = hh * (5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2)))
        new_mode = 3 if y0 > vth else (1 if y0 < -vth else 2)
        if new_mode != mode:
            break
    hbox[0] = h
    X[A1] = x10 + y2 - x40 * (-math.expm1(-b4 * t)) / b4
    X[A2] = y0
    X[AZ] = y1
    X[A3] = u + (x30 - u) * math.exp(-L[L_BETA3] * t)
    X[A4] = x40 * math.exp(-b4 * t)
    X[A5] = x50 * math.exp(-L[L_BETA5] * t)
    X[ATH] = th0 + y2
    return t, new_mode, steps


@njit(cache=True)
def _interval(X, S, t0, duration, offsets, levels, lo, hi, bridge, umax, tau3, L, maxev, diverge, tol, hbox):
    """interval_kernel's noise-free path on the 9-slot state X over segments lo ≤ seg < hi of
    (offsets, levels); S = [t, mode, flyback, events, substeps, status, event count] updated as its
    sheet (events and sub-steps summed over the interval, the event count reset per interval)."""
    hbox[0] = 0.0
    S[3] = 0.0
    S[4] = 0.0
    S[6] = 0.0
    k = hi - lo
    stop = False
    for seg in range(k):
        t_seg_end = t0 + (offsets[lo + seg + 1] if seg + 1 < k else duration)
        level = levels[lo + seg]
        if not bridge:                                   # interval._apply_level
            X[AU] = min(max(level, -umax), umax)
            S[2] = 0.0
        elif level != 0.0 and abs(abs(level) - umax) > 1e-9 * umax:
            S[5] = _BAD_LEVEL
            break
        elif level > 0:
            X[AU], S[2] = umax, 0.0
        elif level < 0:
            X[AU], S[2] = -umax, 0.0
        elif X[A3] != 0.0:
            X[AU], S[2] = -math.copysign(umax, X[A3]), 1.0
        else:
            X[AU], S[2] = 0.0, 0.0
        if seg > 0:                                      # a level event (interval._event)
            S[3] += 1.0
            S[6] += 1.0
            if S[6] > maxev:
                S[5] = _CHATTER
                break
        while S[0] < t_seg_end:
            h_end = t_seg_end - S[0]
            h_fb = tau3 * math.log1p(abs(X[A3]) / umax) if S[2] != 0.0 else math.inf
            h = min(h_end, h_fb)
            old = int(S[1])
            advanced, new, steps = _segment_s(X, h, L, hbox, VELOCITY_THRESHOLD, old, tol)
            S[4] += steps
            if S[4] > _MAX_STEPS:
                S[5] = _CHATTER
                stop = True
                break
            full = advanced >= h
            if full and h == h_end:
                S[0] = t_seg_end
            else:
                S[0] += advanced
            if full and h == h_fb and h != h_end:
                X[A3] = 0.0
                X[AU] = 0.0
                S[2] = 0.0
                S[3] += 1.0
                S[6] += 1.0
                if S[6] > maxev:
                    S[5] = _CHATTER
                    stop = True
                    break
            if new != old:
                S[1] = float(new)
                S[3] += 1.0
                S[6] += 1.0
                if S[6] > maxev:
                    S[5] = _CHATTER
                    stop = True
                    break
            if not (abs(X[A1]) <= diverge):
                S[5] = _DIVERGED
                stop = True
                break
        if stop:
            break
    if S[5] == STATUS_OK:
        S[0] = t0 + duration


@njit(cache=True)
def _move(x0, tau, offs, levs, starts, s0, n, bridge, umax, tau3, L, maxev, diverge, tol, last, sigma0, ring, settled,
          x1, hbox, X, S):
    """:func:`_play` on the trimmed interval for samples starts[s0 : s0 + n]: x1[0:n] the angles;
    returns (status code, samples done, events, integrator steps)."""
    X[A1], X[A2], X[A3], X[A4], X[A5], X[AKC], X[AU], X[ATH], X[AZ] = \
        x0[0], x0[1], x0[2], x0[3], x0[4], 0.0, x0[5], x0[6], x0[7]
    S[0], S[1], S[2], S[5] = 0.0, 2.0, 0.0, 0.0
    n_ev, n_sub = 0.0, 0.0
    k = 0
    while k < n:
        t = S[0]
        _interval(X, S, t, tau, offs, levs, starts[s0 + k], starts[s0 + k + 1], bridge, umax, tau3, L, maxev,
                  diverge, tol, hbox)
        n_ev += S[3]
        n_sub += S[4]
        code = int(S[5])
        if code != STATUS_OK:
            return code, k, n_ev, n_sub
        x1[k] = X[A1]
        k += 1
        if k <= last:
            continue
        if abs(X[AZ]) + abs(X[A3]) / sigma0 + abs(X[A2]) * ring <= settled:
            x1[k:n] = X[A1]
            break
    return STATUS_OK, k, n_ev, n_sub


@njit(cache=True)
def _play_all(x0, tau, offs, levs, starts, first, count, lasts, bridge, umax, tau3, L, maxev, diverge, tol, sigma0,
              ring, settled, prices, spent, deadline, x1, work):
    """Moves j = 0, 1, … (samples starts[first[j]] … of the concatenated commands, ``count[j]`` of them,
    their angles into x1[first[j] : first[j] + count[j]]), each as :func:`_play` plays it, stopping before
    move j once ``spent`` (the work clock) is past ``deadline`` — the check ``_Model.predict`` makes — with
    each move's work priced as ``_WorkClock.add`` does; work[j] = (samples, events, steps). Returns
    (moves played, status code of the last, 1 if it raised ZeroDivisionError: g(v) = 0)."""
    hbox, X, S = np.zeros(1), np.empty(9), np.zeros(7)
    a, b, c = prices[0], prices[1], prices[2]
    for j in range(first.shape[0]):
        if spent > deadline:
            return j, STATUS_OK, 0
        try:
            code, k, n_ev, n_sub = _move(x0, tau, offs, levs, starts, first[j], count[j], bridge, umax, tau3, L,
                                         maxev, diverge, tol, lasts[j], sigma0, ring, settled,
                                         x1[first[j]:first[j] + count[j]], hbox, X, S)
        except Exception:      # only ZeroDivisionError can arise here (numba catches Exception alone)
            work[j, 0], work[j, 1], work[j, 2] = 0.0, 0.0, 0.0
            return j + 1, STATUS_OK, 1
        samples = k + 1 if code != STATUS_OK else k
        work[j, 0], work[j, 1], work[j, 2] = samples, n_ev, n_sub
        spent += a * samples + b * int(n_ev) + c * int(n_sub)
        if code != STATUS_OK:
            return j + 1, code, 0
    return first.shape[0], STATUS_OK, 0


class WholePlan:
    """A log's noise-free lugre prediction as one compiled call (:func:`_play_all`): which moves are
    simulated, in ``_Model.predict``'s order, and where each move's predicted rows come from.

    ``sims``: the simulated moves (g), in order; ``rows``: per predicted row, its source in the angle
    buffer (indexed by the log's sample: a simulated move's angles sit at its own samples), its sign
    (a mirror kind's response is the negated one) and its move's offset."""

    def __init__(self, commands, segs, lasts, sims, src, offsets, n_out) -> None:
        self.offs = np.concatenate([c.arrays()[0] for c in commands])
        self.levs = np.concatenate([c.arrays()[1] for c in commands])
        self.starts = np.cumsum([0] + [len(c.segments) for c in commands]).astype(np.int64)
        self.bridge = commands[0].drive.value == "bridge"
        self.first = np.array([segs[g][0] for g in sims], dtype=np.int64)
        self.count = np.array([segs[g][1] - segs[g][0] for g in sims], dtype=np.int64)
        self.lasts = np.array([lasts[g] for g in sims], dtype=np.int64)
        self.sims = list(sims)
        idx, sign, off = [], [], []
        for g, (j, s) in enumerate(src):
            idx.append(self.first[j] + np.arange(n_out[g]))
            sign.append(np.full(n_out[g], s))
            off.append(np.full(n_out[g], offsets[g]))
        self.src = np.concatenate(idx).astype(np.int64)
        self.sign = np.concatenate(sign)
        self.off = np.concatenate(off)
        self.n = len(commands)


def play_all(plan: WholePlan, x1: np.ndarray, x0, params, options, tolerances, ring: float, settled: float, prices,
             spent: float, deadline: float, j0: int = 0):
    """The moves ``plan.sims[j0:]`` played by :func:`_play_all` from the state ``x0``, their angles
    into ``x1`` (a buffer over the log's samples): (work per move played (samples, events, steps),
    status code of the last move played, whether it raised ZeroDivisionError: g(v) = 0). Stops before a move once
    ``spent`` plus the priced work is past ``deadline``, as ``_Model.predict``'s check does.

    Raises
    ------
    ValueError
        A bridge level other than 0 and ±u_max (as ``advance``).
    """
    o = options.kernel_vector()
    work = np.zeros((plan.first.shape[0] - j0, 3))
    played, code, zero_div = _play_all(np.asarray(x0, dtype=np.float64), params.sample_period, plan.offs, plan.levs,
                                       plan.starts, plan.first[j0:], plan.count[j0:], plan.lasts[j0:], plan.bridge,
                                       params.u_max, params.motor_time_constant, params.law_vector(), o[5], o[6],
                                       tolerances, params.bristle_stiffness, ring, settled,
                                       np.asarray(prices, dtype=np.float64), spent, deadline, x1, work)
    if code == _BAD_LEVEL:
        raise ValueError(f"bridge drive levels must be 0 or ±u_max ({params.u_max})")
    return work[:played].astype(np.int64), code, bool(zero_div)
