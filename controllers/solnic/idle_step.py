"""solnic's idle sample as one compiled step: the ``compiled_law`` hook with a hand-back per pulse cycle.

Between pulses a faithful solnic sample (:meth:`SolnicController.step
<controllers.solnic.controller.SolnicController.step>`) is: the time update of the mode-2
filter (3-22), (4-11) to t = n·τs, the measurement update past t_max (5-11), the posterior
moments, and the trigger test of section 7.2 (:func:`~controllers.solnic.strategy.plan_trigger`)
against the Δc_p,cond of the next pulse — which answers "off" on all samples but the one that
launches. :func:`idle_step` does exactly that arithmetic on a float64 state array (layout
below) in the same order of floating-point operations, and *hands the sample back* (returns 0,
:mod:`plant.law_step`) wherever the Python logic must run: a trigger that fires (pulse launch,
the cycle's evaluation (5-13)–(5-18), the optimiser (6-1)–(6-10)), a due set-boundary
evaluation, a Δt_u or a prediction the cached plan cannot give. That is one or two hand-backs
per pulse cycle (~12 samples on thesis).

The plan's Δc_p,cond and current-zero time are constant between hand-backs (k̂ and the size
schedule change only in the Python logic): the controller caches them in the array after each
Python sample (:meth:`~controllers.solnic.controller.SolnicController._export_idle`), and the
Python path reads the state back before it runs (``_import_idle``). The predictor's memo and
model-run count, which the Python sample would touch at the first idle sample, are replayed at
that import (the prediction is the same pure function of (k̂s, k̂c, Δt_u)), so the summary is
the Python path's too.

The step reaches the compiled loop as a bare function address (:class:`~controllers.law.StepAddress`): a
numba dispatcher passed as a first-class function is typed and its address looked up again
at every entry into the loop (~50 µs on the loaded 2-core machine, i.e. per hand-back), the
address object costs ~5 µs. Called through that address (numba's C wrapper), an exception
inside the step cannot propagate: the call returns 0, the hand-back, and the Python sample
meets the same case (the filters' divisions are the only places; they raise
ZeroDivisionError in Python too).

:func:`idle_step` serves the faithful estimators (two filters, no grid, no noise-aware model,
i.e. ``solnic``); :func:`joint_idle_step` the joint EKF with the noise-aware model
(``solnic-modern``), whose k̂ moves at every sample: it predicts the next pulse afresh (keeping
the last sample's plan by its key) and solves only the mean's backward equation for the w2 bias
(:func:`~controllers.solnic.noise_model._pulse_bias`). Bit-identity is tested against the
recorded (Python) path, tests/test_solnic_idle_step.py.

A sample handed back need not leave the loop: when the controller registers itself
(:func:`controllers.law.register_owner`, its key in ``p``), the step restores the sample's entry state (saved
behind the layout at each entry) and calls the controller's Python sample from inside the loop
through numba's ``objmode`` (:func:`_python_sample`, ~1–2 µs), which returns the command's segments
— the hand-back's own Python sample without the loop's exit and re-entry and the runner's Python
interval (:meth:`SolnicController._sample_in_loop
<controllers.solnic.controller.SolnicController._sample_in_loop>`; tests/test_solnic_in_loop.py).
The joint step restores the entry state only where it stopped before its filter updates
(``J_STAGE`` 0); past them (1), or past a trigger test that fired (2), the Python sample goes on
from the step's work (:meth:`SolnicController._staged_step
<controllers.solnic.controller.SolnicController._staged_step>`).
"""

from __future__ import annotations

import math

from numba import njit, objmode

from controllers.solnic.filter_kernels import joint_predict, joint_update
from controllers.solnic.noise_model import _GL_X, _GL_W, _coasting_moments, _pulse_bias
from controllers.solnic.predictor import _conditional_kernel
from controllers.law import StepAddress, owner_of, step_address

__all__ = ["idle_step", "idle_step_address", "mode2_coefficients", "N_STATE", "N_PARAMS"]

# state s: the sample count, the mode-2 filter, the controller's counters, the cached plan
(N, X1, X4, P11, P14, P44, FT, HAS_ANCHOR, C0, C1, HAS_MOTION, M0, M1, MMEAN, MVAR, T_MAX, SINCE, USED,
 REJECTED, POST, _P1, _P2, _P3, _P4, DUE, PLAN_OK, DC_PLAN, DURATION, PLAN_USED) = range(29)
N_STATE = 29
# params p: τs, R = σ1², τ4, 1/τ4, σ4²τ4³, −σ4²τ4², σ4²τ4, evaluation_samples, overshoot_factor,
# the key of the controller that does a Python sample inside the loop (0: hand it back instead;
# then s[N_STATE:2·N_STATE] holds the sample's entry state)
TS, R, TAU4, B4, Q11C, Q14C, Q44C, EVAL_SAMPLES, OVERSHOOT, OWNER = range(10)
N_PARAMS = 10


def _python_sample(key, y, offs, levs):
    """Called from a compiled step (numba ``objmode``): the Python sample of the controller
    registered under ``key``, its command in (offs, levs); returns the segment count, or 0 to
    hand the sample back after all."""
    owner = owner_of(key)
    return 0 if owner is None else owner._sample_in_loop(y, offs, levs)


def mode2_coefficients(tau4: float, sigma4_sq: float) -> tuple[float, float, float, float, float]:
    """(τ4, 1/τ4, σ4²τ4³, −σ4²τ4², σ4²τ4): the constant factors of
    :func:`~controllers.solnic.mode2_filter.mode2_transition`, formed as it forms them."""
    return tau4, 1.0 / tau4, sigma4_sq * tau4**3, -sigma4_sq * tau4**2, sigma4_sq * tau4


@njit(cache=True)
def _e1(x):
    return -math.expm1(-x)


@njit(cache=True)
def _f3(x):
    """:func:`controllers.solnic.mode2_filter._f3` (the same series and the same sums)."""
    if x < 0.1:
        total = 0.0
        term = x * x / 2.0
        for n in range(3, 30):
            term *= x / n
            sgn = 1.0 if (n + 1) % 2 == 0 else -1.0
            total += sgn * (2.0 ** (n - 1) - 2.0) * term
            if abs(term) * 2.0 ** n < 1e-18 * abs(total):
                break
        return total
    return x - 2.0 * _e1(x) + _e1(2.0 * x) / 2.0


@njit(cache=True)
def _fires(x1, x4, x4_std, delta_c, horizon, earliest, duration, overshoot_factor):
    """Whether :func:`~controllers.solnic.strategy.plan_trigger` returns a trigger (x4_significance 2)."""
    half = abs(delta_c) / 2.0
    o0 = earliest if earliest > 0.0 else 0.0
    if not (abs(x4) >= 2.0 * x4_std and x4 != 0.0):
        if abs(x1) >= half and x1 != 0.0:
            return o0 >= earliest and o0 + duration <= horizon
        return False
    d = 1.0 if x4 > 0 else -1.0
    if d * x1 >= overshoot_factor * abs(delta_c) and abs(delta_c) > 0:
        return o0 >= earliest and o0 + duration <= horizon
    wait = (d * x1 + half) / abs(x4)
    o = 0.0
    if wait > o:
        o = wait
    if earliest > o:
        o = earliest
    return o >= earliest and o + duration <= horizon


@njit(cache=True)
def idle_step(s, p, y, offs, levs):
    """:func:`_idle` (solnic's idle sample); where that hands the sample back and the controller
    is registered (``p[OWNER]``; ``s`` then has room for the entry state after the layout), the
    sample from its entry state in Python inside the loop (:func:`_python_sample`)."""
    owned = p[OWNER] != 0.0
    if owned:
        for i in range(N_STATE):
            s[N_STATE + i] = s[i]
    k = _idle(s, p, y, offs, levs)
    if k != 0 or not owned:
        return k
    for i in range(N_STATE):
        s[i] = s[N_STATE + i]
    with objmode(k="intp"):
        k = _python_sample(p[OWNER], y, offs, levs)
    return k


@njit(cache=True)
def _idle(s, p, y, offs, levs):
    """One solnic sample if it is idle (the bridge off: k = 1, level 0), else 0 (hand back).

    The mode-2 filter's predict/update (:class:`~controllers.solnic.mode2_filter.Mode2Filter`,
    anchor and motion covariances included) and the controller's bookkeeping, in its order.
    """
    n = s[N]
    t = n * p[TS]
    # Mode2Filter.predict(t)
    h = t - s[FT]
    if h < -1e-12:
        return 0
    if h > 0:
        x = p[B4] * h
        e = _e1(x)
        f12 = -p[TAU4] * e
        f22 = 1.0 - e
        q11 = p[Q11C] * _f3(x)
        q14 = p[Q14C] * e * e / 2.0
        q44 = p[Q44C] * _e1(2.0 * x) / 2.0
        if s[HAS_ANCHOR] != 0.0:
            c1 = s[C1]
            s[C0] = s[C0] + f12 * c1
            s[C1] = f22 * c1
        if s[HAS_MOTION] != 0.0:
            m1 = s[M1]
            s[M0] = s[M0] + f12 * m1
            s[M1] = f22 * m1
        x4, p14, p44 = s[X4], s[P14], s[P44]
        s[X1] += f12 * x4
        s[X4] = f22 * x4
        a11 = s[P11] + f12 * p14
        a12 = p14 + f12 * p44
        s[P11] = a11 + f12 * a12 + q11
        s[P14] = f22 * a12 + q14
        s[P44] = f22 * f22 * p44 + q44
        s[FT] = t
    s[N] = n + 1.0
    if t >= s[T_MAX] and math.isfinite(y):
        # Mode2Filter.update(y)
        innovation = y - s[X1]
        p11, p14, p44 = s[P11], s[P14], s[P44]
        S = p11 + p[R]
        k1 = p11 / S
        k4 = p14 / S
        if s[HAS_ANCHOR] != 0.0:
            c0, c1 = s[C0], s[C1]
            s[C0] = c0 - k1 * c0
            s[C1] = c1 - k4 * c0
        if s[HAS_MOTION] != 0.0:
            m0, m1 = s[M0], s[M1]
            k_d = m0 / S
            s[MMEAN] += k_d * innovation
            s[MVAR] -= k_d * m0
            s[M0] = m0 - k1 * m0
            s[M1] = m1 - k4 * m0
        s[X1] += k1 * innovation
        s[X4] += k4 * innovation
        s[P11] = p11 - k1 * p11
        s[P14] = p14 - k1 * p14
        s[P44] = p44 - k4 * p14
        s[USED] += 1.0
        s[SINCE] += 1.0
    else:
        s[REJECTED] += 1.0
    s[POST], s[POST + 1], s[POST + 2], s[POST + 3], s[POST + 4] = s[X1], s[X4], s[P11], s[P14], s[P44]
    if s[DUE] != 0.0 and s[SINCE] >= p[EVAL_SAMPLES]:
        return 0                                  # the set-boundary evaluation
    if s[PLAN_OK] == 0.0:
        return 0                                  # no cached plan: Python plans
    earliest = s[T_MAX] - t
    if not earliest > 0.0:
        earliest = 0.0
    p44 = s[P44]
    x4_std = math.sqrt(0.0 if 0.0 > p44 else p44)   # max(p44, 0.0), NaN kept
    if _fires(s[X1], s[X4], x4_std, s[DC_PLAN], p[TS], earliest, s[DURATION], p[OVERSHOOT]):
        return 0                                  # a pulse (and the pending cycle's evaluation)
    s[PLAN_USED] = 1.0
    offs[0] = 0.0
    levs[0] = 0.0
    return 1


_ADDRESS: list[StepAddress] = []


def idle_step_address() -> StepAddress:
    """:func:`idle_step` as a :class:`StepAddress` (made once per process)."""
    if not _ADDRESS:
        _ADDRESS.append(step_address(idle_step))
    return _ADDRESS[0]


# -- solnic-modern: the joint EKF's idle sample -------------------------------------------------
# state: the sample count, filter time, counters and posterior as above (same indices up to
# PLAN_USED), then the plan's inputs, the joint Gaussian z (5) and P (5×5), the samples since
# the last pulse (for JointFilter.no_motion), and the keys of the predictor's memo.
(J_DTU, J_PEAK, J_BRAKE, J_MARGIN, J_GRID, J_GP_OK, J_GP_DC, J_RUNS, J_SNAP, J_NS, J_MCOUNT, J_MK, J_MK0,
 J_CLEARED) = range(29, 43)
J_Z = 43
J_P = J_Z + 5
J_SBUF = J_P + 25
N_SINCE = 128                     # (t, y) pairs kept in the array; more: the sample is handed back
J_MTAB = J_SBUF + 2 * N_SINCE
N_MEMO = 258                      # Predictor.conditional's memo holds ≤ 257 keys (cleared past 256)
J_CACHE = J_MTAB + 3 * N_MEMO
# the last sample's plan (a pure function of its key): valid, key (k̂s, k̂c, Δt_u, brake, margin,
# peak torque), Predictor.conditional's status, runs and (Δc, t_breakaway, t_cz, t_stop, t_off),
# the w2 bias (valid flag, value). The shaft moves and the measurement update is skipped until
# t_max, so k̂ and the plan repeat on those samples.
(C_VALID, C_KS, C_KC, C_DTU, C_BRAKE, C_MARGIN, C_PEAK, C_R0, C_R1, C_RUNS0, C_DC, C_TB, C_TCZ, C_TSTOP, C_TOFF,
 C_BIAS_OK, C_BIAS) = range(17)
# the sample's entry state where the step writes before it may hand the sample to Python
# (:func:`_python_sample`): s[:J_SBUF], the plan cache and the memo table's first key (the
# only live entries a step overwrites; it appends to the since-buffer and the table otherwise)
J_ENTRY = J_CACHE + 17
N_ENTRY = J_SBUF + 17 + 3
# the plan cache as the step left it at a sample it gave to Python (not restored): the Python
# planner reads its w2 bias where the key matches (SolnicController._pulse_bias)
J_LAST = J_ENTRY + N_ENTRY
# how far the step got before it gave the sample to Python: 1 = the filters' time and
# measurement updates, the counters and the posterior are done (the Python sample goes on from
# there, :meth:`SolnicController._step_tail`), 2 = also the plan of the sample's first trigger
# test (the cached plan, this k̂'s prediction, its w2 bias) fires, 0 = the sample's entry state
# is restored
J_STAGE = J_LAST + 17
N_JOINT_STATE = J_STAGE + 1
# params: TS..OVERSHOOT as above, then the predictor's and the noise model's constants, and the
# key of the controller that does a Python sample inside the loop (0: hand it back instead)
(J_U, J_T3, J_ALPHA, J_FD, J_S2, J_CAP, J_MINRATIO, J_UMAX, J_OWNER) = range(9, 18)
N_JOINT_PARAMS = 18


@njit(cache=True)
def _transition(p, h):
    """(Φ12, Φ22, q11, q14, q44) of :func:`~controllers.solnic.mode2_filter.mode2_transition`."""
    x = p[B4] * h
    e = _e1(x)
    return -p[TAU4] * e, 1.0 - e, p[Q11C] * _f3(x), p[Q14C] * e * e / 2.0, p[Q44C] * _e1(2.0 * x) / 2.0


@njit(cache=True)
def _memo_hit(s, ks, kc, dtu):
    for i in range(int(s[J_MK])):
        j = J_MTAB + 3 * i
        if s[j] == ks and s[j + 1] == kc and s[j + 2] == dtu:
            return True
    return False


@njit(cache=True)
def _save_entry(s):
    e = J_ENTRY
    for i in range(J_SBUF):
        s[e + i] = s[i]
    for i in range(17):
        s[e + J_SBUF + i] = s[J_CACHE + i]
    for i in range(3):
        s[e + J_SBUF + 17 + i] = s[J_MTAB + i]


@njit(cache=True)
def _restore_entry(s):
    e = J_ENTRY
    for i in range(J_SBUF):
        s[i] = s[e + i]
    for i in range(17):
        s[J_CACHE + i] = s[e + J_SBUF + i]
    for i in range(3):
        s[J_MTAB + i] = s[e + J_SBUF + 17 + i]


@njit(cache=True)
def joint_idle_step(s, p, y, offs, levs):
    """:func:`_joint_idle` (solnic-modern's idle sample); where that hands the sample back and
    the controller is registered (``p[J_OWNER]``), the sample from its entry state in Python
    inside the loop (:func:`_python_sample`, what the runner would do after the hand-back, without
    leaving the compiled loop)."""
    owned = p[J_OWNER] != 0.0
    if owned:
        _save_entry(s)
    s[J_STAGE] = 0.0
    k = _joint_idle(s, p, y, offs, levs)
    if k != 0 or not owned:
        return k
    for i in range(17):
        s[J_LAST + i] = s[J_CACHE + i]
    if s[J_STAGE] == 0.0:
        _restore_entry(s)
    with objmode(k="intp"):
        k = _python_sample(p[J_OWNER], y, offs, levs)
    return k


@njit(cache=True)
def _joint_idle(s, p, y, offs, levs):
    """solnic-modern's sample if it is idle, else 0 (hand back): the joint EKF's predict and
    update (:class:`~controllers.solnic.joint_filter.JointFilter`, its compiled kernels), the
    prediction of the next pulse at this sample's k̂ (:meth:`Predictor.conditional
    <controllers.solnic.predictor.Predictor.conditional>`, its memo and model-run count
    emulated), its w2 bias (:func:`~controllers.solnic.noise_model.pulse_noise` or
    :func:`~controllers.solnic.noise_model.braked_pulse_noise`) or the grid's cached
    predictive, and the trigger test."""
    z = s[J_Z:J_Z + 5]
    P = s[J_P:J_P + 25].reshape((5, 5))
    n = s[N]
    t = n * p[TS]
    h = t - s[FT]
    if h < -1e-12:
        return 0
    if h > 0:
        f12, f22, q11, q14, q44 = _transition(p, h)
        joint_predict(z, P, f12, f22, q11, q14, q44)
        s[FT] = t
    s[N] = n + 1.0
    if t >= s[T_MAX] and math.isfinite(y):
        if s[J_SNAP] != 0.0:
            k = int(s[J_NS])
            if k >= N_SINCE:
                return 0
            s[J_SBUF + 2 * k] = s[FT]
            s[J_SBUF + 2 * k + 1] = y
            s[J_NS] = k + 1.0
        joint_update(z, P, p[R], y)
        kc = z[2]
        if not (0.0 <= kc and kc <= z[3] and z[3] < p[J_UMAX]):
            return 0                              # JointFilter._valid: conditioning in Python
        s[USED] += 1.0
        s[SINCE] += 1.0
    else:
        s[REJECTED] += 1.0
    s[POST], s[POST + 1], s[POST + 2], s[POST + 3], s[POST + 4] = z[0], z[1], P[0, 0], P[0, 1], P[1, 1]
    s[J_STAGE] = 1.0                              # from here a hand-back keeps the filters' work
    if s[DUE] != 0.0 and s[SINCE] >= p[EVAL_SAMPLES]:
        return 0
    if s[PLAN_OK] == 0.0:
        return 0
    earliest = s[T_MAX] - t
    if not earliest > 0.0:
        earliest = 0.0
    ks, kc, dtu = z[3], z[2], s[J_DTU]
    hit = _memo_hit(s, ks, kc, dtu)
    c = J_CACHE
    brake, margin, peak = s[J_BRAKE], s[J_MARGIN], s[J_PEAK]
    if not (s[c + C_VALID] != 0.0 and s[c + C_KS] == ks and s[c + C_KC] == kc and s[c + C_DTU] == dtu
            and s[c + C_BRAKE] == brake and s[c + C_MARGIN] == margin and s[c + C_PEAK] == peak):
        r, ks_u, kc_u, runs0 = _conditional_kernel(ks, kc, dtu, p[J_U], p[J_T3], p[J_ALPHA], p[J_FD],
                                                   brake != 0.0, margin, p[J_S2], p[J_CAP],
                                                   p[J_MINRATIO], 1e-6)
        s[c + C_VALID], s[c + C_KS], s[c + C_KC], s[c + C_DTU] = 1.0, ks, kc, dtu
        s[c + C_BRAKE], s[c + C_MARGIN], s[c + C_PEAK] = brake, margin, peak
        s[c + C_R0], s[c + C_R1], s[c + C_RUNS0] = r[0], r[1], runs0
        s[c + C_DC], s[c + C_TB], s[c + C_TCZ], s[c + C_TSTOP], s[c + C_TOFF] = r[2], r[3], r[4], r[5], r[10]
        s[c + C_BIAS_OK] = 0.0
    if s[c + C_R0] != 0:
        return 0                                  # Predictor._prediction raises: in Python
    if not hit:
        if s[J_MCOUNT] > 256:                     # memo.clear()
            s[J_MCOUNT] = 0.0
            s[J_MK] = 0.0
            s[J_CLEARED] = 1.0
        j = J_MTAB + 3 * int(s[J_MK])
        s[j], s[j + 1], s[j + 2] = ks, kc, dtu
        s[J_MK] += 1.0
        s[J_MCOUNT] += 1.0
        s[J_RUNS] += s[c + C_RUNS0] + s[c + C_R1]
    dc, tb, tcz, t_stop, t_off = s[c + C_DC], s[c + C_TB], s[c + C_TCZ], s[c + C_TSTOP], s[c + C_TOFF]
    dc_plan = abs(dc)
    if s[J_GRID] != 0.0 and s[J_GP_OK] != 0.0:
        dc_plan = s[J_GP_DC]                      # the grid's predictive (w2 bias included)
    elif s[c + C_BIAS_OK] != 0.0:
        dc_plan += s[c + C_BIAS]                  # the same plan's bias, computed at an earlier sample
    else:                                         # SolnicController._pulse_noise(pred, dtu)[0]
        cap = peak * (1.0 - 1e-6)
        ksn = cap if cap < ks else ks
        kcn = ksn if ksn < kc else kc
        s2 = p[J_S2]
        bias = 0.0
        if tb >= 0.0 and s2 > 0 and t_stop > tb:
            al, U, tau = p[J_ALPHA], p[J_U], p[J_T3]
            if t_off >= 0.0 and t_stop > tcz and kcn > 0:
                bias = _coasting_moments(al, U, tau, s2, ksn, kcn, dtu, tb, tcz, t_stop,
                                         U * -math.expm1(-dtu / tau), _GL_X, _GL_W, al * kcn * (t_stop - tcz))[0]
            else:
                bias = _pulse_bias(al, U, tau, s2, ksn, kcn, dtu, tb, tcz, t_stop, _GL_X, _GL_W)
        s[c + C_BIAS_OK], s[c + C_BIAS] = 1.0, bias
        dc_plan += bias
    x4_std = math.sqrt(0.0 if 0.0 > P[1, 1] else P[1, 1])
    if _fires(z[0], z[1], x4_std, dc_plan, p[TS], earliest, tcz, p[OVERSHOOT]):
        s[J_STAGE] = 2.0                          # the planner's first trigger test fires, too
        return 0
    offs[0] = 0.0
    levs[0] = 0.0
    return 1


_JOINT_ADDRESS: list[StepAddress] = []


def joint_idle_step_address() -> StepAddress:
    """:func:`joint_idle_step` as a :class:`StepAddress` (made once per process)."""
    if not _JOINT_ADDRESS:
        _JOINT_ADDRESS.append(step_address(joint_idle_step))
    return _JOINT_ADDRESS[0]
