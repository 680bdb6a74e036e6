"""The noisy moving segment's sub-step loop, as the interval's fast path runs it.

:func:`bridge_run` is :func:`plant.multimode.zero_velocity.bridge_segment` (the bridge locator or
the reflection, on the step ladder: see there) with the same operations in the same order, so
the same numbers and the same normals read, made cheaper where that changes no bit:

* the crossing test is :func:`plant.multimode.crossing.crossed` (a table of log Φ decides
  most sub-steps without exp and erfc);
* the 7 × 7 and 4 × 4 scratch matrices of the fresh end-of-segment step and the ladder's
  thresholds come in as views made once per interval (three reshapes per segment were numba
  runtime calls);
* it is compiled without numba's reference counting (it allocates nothing).

tests/test_kernel_equivalence.py runs both on the same states and normals.
"""

from __future__ import annotations

from numba import njit

from plant.multimode.crossing import crossed
from plant.multimode.moving import chol_psd, phi_moving, q_moving, substep_peak, velocity_extremum_time
from plant.multimode.zero_velocity import _bisect, _bridge_low, _copy, _mean_min, _step

__all__ = ["bridge_run"]

A1, A2, A5 = 0, 1, 4


@njit(cache=True, _nrt=False)
def bridge_run(X, mode, h, reflect, o_sub, o_rsub, tol, p, TP, TL, TH, BPh, BPw, BG, BC, z, cursor, peak,
               max_steps, W, P, L, Qtmp):
    """:func:`plant.multimode.zero_velocity.bridge_segment` with ``P`` (7 × 7), ``L`` and ``Qtmp``
    (4 × 4) given as scratch instead of cut from ``W`` (≥ 370 floats, of which W[0:14] and
    W[96:] are used here), and ``TH`` the (2, LADDER) thresholds. Returns (advanced [s],
    stopped, peak |x1|, sub-steps used, chattered)."""
    s = 1.0 if mode == 3 else -1.0
    m = 0 if mode == 1 else 1
    j = 1 if reflect else 0
    base = o_rsub if reflect else o_sub
    sig_v2 = p.alpha * p.alpha * p.sigma2_sq
    nrung = TP.shape[2]
    Xb = W[0:7]
    Xc = W[7:14]
    t = 0.0
    n = 0
    while h - t > 0.0:
        rem = h - t
        k = 0
        if nrung > 1 and s * X[A2] >= TH[j, 1] and base < rem:
            k = 1
            while k + 1 < nrung and s * X[A2] >= TH[j, k + 1] and base * 2.0**k < rem:
                k += 1
            if reflect:
                while k > 0:
                    w = min(base * 2.0**k, rem)
                    if s * X[A2] - 0.5 * p.alpha * abs(X[A5]) * p.beta5 * w * w >= TH[j, k]:
                        break
                    k -= 1
            else:
                t_ext = velocity_extremum_time(mode, X, p)
                while k > 0 and _mean_min(mode, X, p, min(base * 2.0**k, rem), t_ext) < TH[j, k]:
                    k -= 1
        sub = base * 2.0**k
        regular = not (rem <= sub or (k == 0 and rem <= 1.5 * sub))
        if regular:
            while k > 0 and 1.5 * sub >= rem:
                k -= 1
                sub = sub / 2.0
            step = sub
            _step(X, TP[m, j, k], TL[m, j, k], z, cursor, Xb)
        else:
            step = rem
            phi_moving(mode, step, p, P)
            q_moving(mode, step, p, Qtmp)
            chol_psd(Qtmp, L)
            _step(X, P, L, z, cursor, Xb)
        n += 1
        if n > max_steps:
            return t, False, peak, n, True
        if reflect:
            va, vb = s * X[A2], s * Xb[A2]
            low = _bridge_low(va, vb, step, sig_v2, z, cursor) if sig_v2 > 0 else min(va, vb)
            if low < 0.0:
                Xb[A2] += s * (-low)
                Xb[A1] += s * (-low) * step / 2.0
        else:
            if crossed(X[A2], Xb[A2], step, sig_v2, z, cursor):
                if regular and k == 0:
                    tc, lv = _bisect(mode, X, Xb, step, tol, p, sig_v2, z, cursor, Xc, BPh, BPw, BG, BC, W[96:])
                else:
                    tc, lv = _bisect(mode, X, Xb, step, tol, p, sig_v2, z, cursor, Xc, BPh[:, :0], BPw[:, :0],
                                     BG[:, :0], BG[:, :0], W[96:])
                n += lv
                peak = substep_peak(X, Xc, tc, peak)
                _copy(X, Xc)
                X[A2] = 0.0
                return t + tc, True, peak, n, False
        peak = substep_peak(X, Xb, step, peak)
        _copy(X, Xb)
        t += step
    return h, False, peak, n, False
