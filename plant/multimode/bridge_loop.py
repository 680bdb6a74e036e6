"""The noisy moving segment's sub-step loop: the bridge locator or the reflection, on the step ladder.

:func:`bridge_run` replaced ``zero_velocity.bridge_segment`` (kept as the bit-for-bit reference in
tests/reference_kernels.py) with the same operations in the same order, so the same numbers and
the same normals read, made cheaper where that changes no bit:

* the crossing test is :func:`plant.multimode.crossing.crossed` (a table of log Φ decides
  most sub-steps without exp and erfc);
* the 7 × 7 and 4 × 4 scratch matrices of the fresh end-of-segment step and the ladder's
  thresholds come in as views made once per interval (three reshapes per segment were numba
  runtime calls);
* it is compiled without numba's reference counting (it allocates nothing);
* the reflecting push (:func:`_reflect_low`) skips erfc and log where the table of log Φ shows
  that the bridge minimum stays above 0 (:func:`plant.multimode.crossing.minimum_above_zero`);
* the fresh end-of-segment step takes Φ and Q from one call
  (:func:`plant.multimode.moving.phi_q_moving`), which evaluates the decays both use once.

tests/test_bridge_loop.py runs both on the same states and normals.
"""
from __future__ import annotations

from numba import njit

from plant.multimode.crossing import crossed, minimum_above_zero
from plant.multimode.moving import chol_psd, phi_q_moving, substep_peak, velocity_extremum_time
from plant.multimode.zero_velocity import _bisect, _bridge_low, _copy, _mean_min, _step
from plant.randomness import ZPOS

__all__ = ["bridge_run"]

A1, A2, A5 = 0, 1, 4


@njit(cache=True, _nrt=False, inline="always")
def _reflect_low(va, vb, h, sig_v2, z, cursor):
    """:func:`plant.multimode.zero_velocity._bridge_low` where it is below 0 (the push), and
    min(va, vb) ≥ 0 where it is not: the same normal read, erfc and log skipped when the table
    of log Φ decides that the minimum stays above 0 (both ends above 0, x < 0)."""
    if va > 0.0 and vb > 0.0:
        i = cursor[ZPOS]
        if i < z.shape[0]:
            x = z[i]
            if x < 0.0 and minimum_above_zero(va, vb, 2.0 * sig_v2 * h, x):
                cursor[ZPOS] = i + 1
                return min(va, vb)
    return _bridge_low(va, vb, h, sig_v2, z, cursor)


@njit(cache=True, _nrt=False)
def bridge_run(X, mode, h, reflect, o_sub, o_rsub, tol, p, TP, TL, TH, BPh, BPw, BG, BC, z, cursor, peak,
               max_steps, W, P, L, Qtmp):
    """Advance a noisy moving segment of length h in place (bridge locator, or reflection).

    Steps come from a ladder of widths h_j·2^k (``TP[m, j, k], TL[m, j, k]``: Φ and noise
    factor, :func:`substep_tables`; j = 0 regular with h_0 = ``o_sub``, j = 1 reflecting with
    h_1 = ``o_rsub``; m = 0 for mode 1, 1 for mode 3). Each step takes the longest rung k whose
    threshold ``TH[j, k]`` (:func:`ladder_thresholds`) the mean velocity clears over the whole
    step; near zero that is rung 0, the fixed sub-step. When that rung reaches the segment's end
    the rest of the segment is one step, factored afresh (a shorter width is admissible too,
    since both bounds grow with h); otherwise the step is the longest admissible rung leaving
    more than half of it, and the last ≤ 1.5·h_j is again one fresh step. The choice depends on
    the state at the step's start only, so the chain of exact transitions X⁺ = Φ(h)X + N stays
    exact; what a long step neglects is bounded in ``ladder_thresholds`` (crossing probability
    ≤ 5.7e-17 per step; reflection: x1 push error rate no larger than the reflect sub-step's at
    zero velocity). Every step keeps the Brownian-bridge crossing test (regular) or the Skorokhod push
    (reflecting) below.

    ``W`` is scratch space (≥ 370 floats, of which W[0:14] and W[96:] are used here) owned by the
    caller; ``P`` (7 × 7), ``L`` and ``Qtmp`` (4 × 4) scratch views, ``TH`` the (2, LADDER) thresholds.

    Returns (advanced [s], stopped, peak |x1|, sub-steps used, chattered). ``stopped``: the
    velocity reached zero at X (x2 set to 0) after ``advanced`` seconds.
    """
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
            phi_q_moving(mode, step, p, P, Qtmp)
            chol_psd(Qtmp, L)
            _step(X, P, L, z, cursor, Xb)
        n += 1
        if n > max_steps:
            return t, False, peak, n, True
        if reflect:
            va, vb = s * X[A2], s * Xb[A2]
            low = _reflect_low(va, vb, step, sig_v2, z, cursor) if sig_v2 > 0 else min(va, vb)
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
