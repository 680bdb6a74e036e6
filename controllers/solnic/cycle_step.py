"""solnic-modern's pulse cycle after the grid's hand-over as one compiled step (issue 27).

The joint idle step (:func:`~controllers.solnic.idle_step.joint_idle_step`) gives Python every
sample whose first trigger test fires with a cycle pending (``J_STAGE`` 2): there
:meth:`SolnicController._plan <controllers.solnic.controller.SolnicController._plan>` evaluates
the cycle (:meth:`~controllers.solnic.controller.SolnicController._evaluate`: (5-13), the 0.98
test, the three-way decision, the NIS, :meth:`JointFilter.moved
<controllers.solnic.joint_filter.JointFilter.moved>`, the size schedule), plans again
(:meth:`Predictor.conditional <controllers.solnic.predictor.Predictor.conditional>`, the w2
moments of :func:`~controllers.solnic.noise_model.pulse_noise` or
:func:`~controllers.solnic.noise_model.braked_pulse_noise`, :func:`~controllers.solnic.strategy.plan_trigger`)
and launches (:meth:`~controllers.solnic.controller.SolnicController._launch`: (5-6), (5-9), (5-11),
(5-15) through :func:`~controllers.solnic.filter_kernels.joint_launch`). After the hand-over
(no grid) that is ~1000 samples a 100 s thesis cell at ~44 µs of interpretation each.

:func:`joint_cycle_step` is the joint idle step plus :func:`_cycle`, which does that sample in the
loop where it is one of the common cases — the decision "moved", "undecided" or "fallback", no set
completed (the optimiser (6-1)–(6-10) stays Python), a Δt_u the schedule gives without a skip, a
prediction without an error, a command ``DriveCommand`` accepts — and otherwise changes nothing
and lets the sample go to Python as before. Every number is the Python step's operation on the
same operands in the same order: Python's ``max``/``min`` as their comparisons, ``x**2`` as
libm's ``pow`` (CPython's float power, which need not round as x·x does; the exponent is read
from ``p`` so that LLVM cannot turn it into a product), ``NormalDist().cdf`` as
0.5·(1 + erf(x/√2)) with libm's ``erf`` (what CPython's ``math.erf`` calls), the kernels the
Python objects call (``joint_moved``, ``joint_predict`` with the mode-2 transition of
:func:`~controllers.solnic.idle_step._transition`, ``joint_launch``, ``quadratic_form2``,
``_conditional_kernel``, ``_pulse_noise``, ``_coasting_moments``). The memos the Python path
keeps (the noise model's, the filter's transitions) are pure functions of their keys, so they
are not kept here; the predictor's memo keys and model-run count are emulated as the idle step
does. The cycle's effects on the Python objects — the pending cycle, the log entry and NIS,
the schedule, the counters, the filter's snapshot and prior of d, t_max — are kept in the
state array (layout below) and read back at the next Python sample
(:meth:`SolnicController._import_cycles <controllers.solnic.controller.SolnicController._import_cycles>`).
Bit-identity: tests/test_solnic_cycle_step.py (rows with the step on and off, libm's pow and erf).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, objmode

from controllers.solnic import idle_step as _i
from controllers.solnic.filter_kernels import joint_launch, joint_moved, joint_predict, quadratic_form2
from controllers.solnic.noise_model import _GL_W, _GL_X, _coasting_moments, _pulse_noise
from controllers.solnic.predictor import _conditional_kernel
from controllers.law import StepAddress, step_address

__all__ = ["joint_cycle_step", "joint_cycle_step_address", "N_CYCLE_STATE", "N_CYCLE_PARAMS"]

# the size schedule's codes and set length (controllers.solnic.strategy)
_RAISE, _SETTLE, _SMALL, _MEDIUM, _LARGE, _PER_SIZE = -1.0, 0.0, 1.0, 2.0, 3.0, 4.0

# state behind the joint idle step's layout: whether the cycle may run (the controller's options
# and objects allow it: no grid, a pending cycle), the pending cycle (_Cycle's fields), the
# undecided run, the counters, the schedule (SizeSchedule's fields; the sizes appended to its
# set_sizes and whether it was reset), the joint filter's motion-update count, prior of d and
# snapshot (z, P, t; whether a launch replaced it), the cycles done since the last export
B = _i.N_JOINT_STATE
F_OK = B
(PC_HAS, PC_TA, PC_X1A, PC_VX1A, PC_SIGN, PC_DTU, PC_SIZE, PC_DC, PC_HB0, PC_HB1, PC_PEAK, PC_MOVING,
 PC_OVER, PC_NOISE, PC_SPREAD) = range(B + 1, B + 16)
UNDEC = B + 16
(CN_EVAL, CN_UNDEC, CN_SIG, CN_FU, CN_STARTUP, CN_PULSES, CN_OVER, CN_BRAKED) = range(B + 17, B + 25)
(SC_OPT, SC_INC, SC_SIZE, SC_STARTUP, SC_DONE, SC_RESET, SC_N) = range(B + 25, B + 32)
N_SETS = 48                       # set sizes appended between Python samples; more: to Python
SC_TAB = B + 32
J_NMU = SC_TAB + N_SETS
J_MP0, J_MP1 = J_NMU + 1, J_NMU + 2
SN_NEW = J_NMU + 3
SN_Z = SN_NEW + 1
SN_P = SN_Z + 5
SN_T = SN_P + 25
F_DONE = SN_T + 1
# the log entries of the cycles done (SolnicController.log, in its keys' order) and their NIS
(L_TA, L_TB, L_X1A, L_SIZE, L_DTU, L_SIGN, L_DCP, L_DCE, L_SDE, L_SIG, L_KSB, L_KCB, L_HASNIS, L_NIS, L_KS, L_KC,
 L_DEC) = range(17)
N_LOG_FIELDS = 17
N_LOG = 48                        # entries between Python samples; more: to Python
LOG_N = F_DONE + 1
LOG_TAB = LOG_N + 1
N_CYCLE_STATE = LOG_TAB + N_LOG * N_LOG_FIELDS
DECISIONS = ("moved", "undecided", "fallback")

# params behind the joint idle step's: z of the 0.98 test, the no-motion power, the undecided
# bound, the t_max sigmas, σ5², Δt_u's cap, 2.0 (pow's exponent, read at run time), u_max of the
# plant (the pulse level), whether the cycle runs at all
(P_ZMOT, P_POWER, P_MAXUND, P_STUCK, P_S5, P_DTUMAX, P_TWO, P_ULEVEL, P_ON) = range(
    _i.N_JOINT_PARAMS, _i.N_JOINT_PARAMS + 9)
N_CYCLE_PARAMS = _i.N_JOINT_PARAMS + 9


@njit(cache=True)
def _pmax(a, b):
    """Python's ``max(a, b)`` for floats: b only if b > a."""
    return b if b > a else a


@njit(cache=True)
def _pmin(a, b):
    """Python's ``min(a, b)`` for floats: b only if b < a."""
    return b if b < a else a


@njit(cache=True)
def _sq(x, two):
    """CPython's ``x**2`` for a float: pow(|x|, 2.0) from libm (0 and NaN as CPython's
    special cases give them, which libm's pow gives too)."""
    return math.pow(abs(x), two)


@njit(cache=True)
def _next_dtu(size, dtu_opt, dtu_inc, dtu_startup):
    """SizeSchedule.next_dtu."""
    if size == _RAISE:
        return dtu_startup + dtu_inc
    if size == _SETTLE:
        return dtu_startup
    return dtu_opt + (size - _MEDIUM) * dtu_inc


@njit(cache=True)
def _trigger(x1, x4, x4_std, delta_c, horizon, earliest, duration, overshoot_factor):
    """:func:`~controllers.solnic.strategy.plan_trigger` (x4_significance 2):
    (fires, sign, offset, overshoot)."""
    half = abs(delta_c) / 2.0
    o0 = earliest if earliest > 0.0 else 0.0
    if not (abs(x4) >= 2.0 * x4_std and x4 != 0.0):
        if abs(x1) >= half and x1 != 0.0:
            ok = o0 >= earliest and o0 + duration <= horizon
            return ok, (-1.0 if x1 > 0 else 1.0), o0, False
        return False, 0.0, 0.0, False
    d = 1.0 if x4 > 0 else -1.0
    if d * x1 >= overshoot_factor * abs(delta_c) and abs(delta_c) > 0:
        return o0 >= earliest and o0 + duration <= horizon, -d, o0, True
    wait = (d * x1 + half) / abs(x4)
    o = 0.0
    if wait > o:
        o = wait
    if earliest > o:
        o = earliest
    return o >= earliest and o + duration <= horizon, d, o, False


@njit(cache=True)
def _noise(p, ks, kc, dtu, tb, tcz, t_stop, t_off, peak):
    """SolnicController._pulse_noise: (bias, variance) of pulse_noise / braked_pulse_noise."""
    ksn = _pmin(ks, peak * (1.0 - 1e-6))
    kcn = _pmin(kc, ksn)
    s2 = p[_i.J_S2]
    if tb < 0.0 or s2 <= 0 or not t_stop > tb:
        return 0.0, 0.0
    al, U, tau = p[_i.J_ALPHA], p[_i.J_U], p[_i.J_T3]
    if t_off >= 0.0 and t_stop > tcz and kcn > 0:
        return _coasting_moments(al, U, tau, s2, ksn, kcn, dtu, tb, tcz, t_stop, U * -math.expm1(-dtu / tau),
                                 _GL_X, _GL_W, al * kcn * (t_stop - tcz))
    return _pulse_noise(al, U, tau, s2, ksn, kcn, dtu, tb, tcz, t_stop, _GL_X, _GL_W)


@njit(cache=True)
def _segment_ok(o, prev):
    return o > prev and o - o == 0.0


@njit(cache=True)
def _cycle(s, p, t, offs, levs, evaluate):
    """The sample (module docstring) — with ``evaluate``, the pending cycle's evaluation first —
    or 0 with ``s`` untouched."""
    two = p[P_TWO]
    z0 = s[_i.J_Z:_i.J_Z + 5]
    P0 = s[_i.J_P:_i.J_P + 25].reshape((5, 5))
    z = z0.copy()
    P = P0.copy()
    earliest = s[_i.T_MAX] - t
    if not earliest > 0.0:
        earliest = 0.0
    # -- _evaluate(t): the joint EKF without the grid
    c_sign = c_size = c_dtu = dc_e = sd = 0.0
    significant = False
    undecided = s[UNDEC]
    decision = 0
    ks_before = kc_before = 0.0
    has_nis, nis = False, 0.0
    n_mu, fu = s[J_NMU], 0.0
    opt, inc, size, startup, done = s[SC_OPT], s[SC_INC], s[SC_SIZE], s[SC_STARTUP], s[SC_DONE]
    reset = False
    if evaluate:
        c_sign, c_size, c_dtu = s[PC_SIGN], s[PC_SIZE], s[PC_DTU]
        dc_e, var_e = z[4], P[4, 4]
        sd = math.sqrt(_pmax(var_e, 1e-300))
        zz = c_sign * dc_e / sd if math.isfinite(sd) else 0.0
        significant = zz >= p[P_ZMOT]
        undecided = s[UNDEC]
        decision = 0                                   # moved
        if not significant:
            hb = np.empty(2)
            hb[0], hb[1] = s[PC_HB0], s[PC_HB1]
            var_k = quadratic_form2(hb, P[2:4, 2:4])
            spread = math.sqrt(sd * sd + var_k + s[PC_NOISE])
            x = (s[PC_DC] - p[P_ZMOT] * sd) / spread
            power = 0.5 * (1.0 + math.erf((x - 0.0) / (1.0 * math.sqrt(2.0))))
            if not power < p[P_POWER]:
                return 0                               # "none": JointFilter.no_motion in Python
            undecided += 1.0
            decision = 1 if undecided <= p[P_MAXUND] else 2
        if decision != 1:
            undecided = 0.0
        ks_before, kc_before = z[3], z[2]
        prior_mean, prior_var = s[J_MP0], s[J_MP1]
        post_var = P[4, 4]
        has_nis, nis = False, 0.0
        if post_var > 0 and prior_var > 0:             # JointFilter.motion_likelihood
            info = 1.0 / post_var - 1.0 / prior_var
            if info > 1e-12 / post_var:
                R = 1.0 / info
                m = R * (z[4] / post_var - prior_mean / prior_var)
                if math.isfinite(R):
                    has_nis, nis = True, _sq(m - prior_mean, two) / (R + prior_var)
        n_mu, fu = s[J_NMU], 0.0
        if decision == 0:
            n_mu += 1.0
            joint_moved(z, P, s[PC_PEAK], p[_i.J_UMAX])
            fu = 1.0
        # the schedule: undecided() or evaluated(significant, size, dt_u)
        opt, inc, size, startup, done = s[SC_OPT], s[SC_INC], s[SC_SIZE], s[SC_STARTUP], s[SC_DONE]
        reset = False
        if decision == 1:
            if c_size == _RAISE:
                startup = _pmax(c_dtu - inc, 0.0)
            elif c_size == _SETTLE:
                startup = c_dtu
        elif c_size == _RAISE:
            if significant:
                size = _SETTLE
                startup = _pmax(c_dtu - inc / 2.0, 0.0)
        elif c_size == _SETTLE:
            if significant:
                opt = c_dtu
                size, done, reset = _SMALL, 0.0, True
            else:
                startup = c_dtu + inc / 4.0
        elif not significant and size >= _SMALL:
            size = _RAISE
            startup = _pmax(c_dtu, opt)
            done = 0.0
        if size >= _SMALL and done >= 3 * _PER_SIZE:
            return 0                                   # a set is complete: the optimiser in Python
    # -- _plan's attempt after the evaluation (or its first, without a pending cycle): Δt_u, the
    # prediction, the bias (the full moments: no cycle is pending), the trigger
    dtu = _next_dtu(size, opt, inc, startup)
    if not dtu > 0:
        return 0                                   # a size skipped: in Python
    dtu = _pmin(dtu, p[P_DTUMAX])
    ks, kc = z[3], z[2]
    brake, margin = s[_i.J_BRAKE], s[_i.J_MARGIN]
    r, ks_u, kc_u, runs0 = _conditional_kernel(ks, kc, dtu, p[_i.J_U], p[_i.J_T3], p[_i.J_ALPHA], p[_i.J_FD],
                                               brake != 0.0, margin, p[_i.J_S2], p[_i.J_CAP],
                                               p[_i.J_MINRATIO], 1e-6)
    if r[0] != 0:
        return 0                                   # Predictor._prediction raises: in Python
    dc_p, tb, tcz, t_stop, t_off = r[2], r[3], r[4], r[5], r[10]
    peak = -p[_i.J_U] * math.expm1(-dtu / p[_i.J_T3]) if dtu > 0 else 0.0
    bias, noise_var = _noise(p, ks, kc, dtu, tb, tcz, t_stop, t_off, peak)
    dc_plan = abs(dc_p) + bias
    x4_std = math.sqrt(_pmax(P[1, 1], 0.0))
    fires, sign, offset, overshoot = _trigger(z[0], z[1], x4_std, dc_plan, p[_i.TS], earliest, tcz,
                                              p[_i.OVERSHOOT])
    k = 1
    t_a = t
    ft = s[_i.FT]
    level = 0.0
    if fires:
        # -- _launch
        t_a = t + offset
        h = t_a - ft
        if h > 0:
            f12, f22, q11, q14, q44 = _i._transition(p, h)
            joint_predict(z, P, f12, f22, q11, q14, q44)
            ft = t_a
        elif h < -1e-12:
            return 0
        level = sign * p[P_ULEVEL]
        if t_off >= 0.0:
            o1, o2, o3 = offset, offset + dtu, offset + t_off
            if offset > 0:
                k = 4
                if not (_segment_ok(o1, 0.0) and _segment_ok(o2, o1) and _segment_ok(o3, o2)):
                    return 0
            else:
                k = 3
                if not (o1 == 0.0 and _segment_ok(o2, o1) and _segment_ok(o3, o2)):
                    return 0
            if k > offs.shape[0]:
                return 0
        else:
            if offset < 0 or dtu < 0:
                return 0
            if dtu == 0:
                k = 1
            elif offset == 0:
                k = 2
                if not _segment_ok(dtu, 0.0):
                    return 0
            else:
                k = 3
                if not (_segment_ok(offset, 0.0) and _segment_ok(offset + dtu, offset)):
                    return 0
        if not (level - level == 0.0):
            return 0
    # room for the log entry and the schedule's appended size
    n_log = int(s[LOG_N])
    n_set = int(s[SC_N])
    if (evaluate and n_log >= N_LOG) or (fires and size >= _SMALL and n_set >= N_SETS):
        return 0
    mk = int(s[_i.J_MK])
    hit = _i._memo_hit(s, ks, kc, dtu)
    cleared = (not hit) and s[_i.J_MCOUNT] > 256
    if cleared and s[_i.J_CLEARED] != 0.0:
        return 0                                   # a second clear before the import: in Python
    # ---- commit: nothing above has written to s
    if evaluate:
        e = LOG_TAB + N_LOG_FIELDS * n_log
        s[e + L_TA], s[e + L_TB], s[e + L_X1A], s[e + L_SIZE] = s[PC_TA], t, s[PC_X1A], c_size
        s[e + L_DTU], s[e + L_SIGN], s[e + L_DCP], s[e + L_DCE] = c_dtu, c_sign, s[PC_DC], c_sign * dc_e
        s[e + L_SDE], s[e + L_SIG], s[e + L_KSB], s[e + L_KCB] = sd, 1.0 if significant else 0.0, ks_before, kc_before
        s[e + L_HASNIS], s[e + L_NIS], s[e + L_KS], s[e + L_KC] = 1.0 if has_nis else 0.0, nis, ks, kc
        s[e + L_DEC] = decision
        s[LOG_N] = n_log + 1.0
        s[CN_EVAL] += 1.0
        s[CN_UNDEC] += 1.0 if decision == 1 else 0.0
        s[CN_SIG] += 1.0 if significant else 0.0
        s[CN_FU] += fu
        s[J_NMU] = n_mu
        s[UNDEC] = undecided
    if reset:
        s[SC_RESET], s[SC_N] = 1.0, 0.0
    if not hit:                                    # Predictor.conditional's memo and model runs
        if cleared:
            s[_i.J_MCOUNT] = 0.0
            s[_i.J_MK] = 0.0
            s[_i.J_CLEARED] = 1.0
            mk = 0
        j = _i.J_MTAB + 3 * mk
        s[j], s[j + 1], s[j + 2] = ks, kc, dtu
        s[_i.J_MK] = mk + 1.0
        s[_i.J_MCOUNT] += 1.0
        s[_i.J_RUNS] += runs0 + r[1]
    s[PC_HAS] = 0.0
    if fires:
        x1_a, var_x1_a = z[0], P[0, 0]
        dc = abs(dc_p) + bias
        for i in range(5):
            s[SN_Z + i] = z[i]
        for i in range(25):
            s[SN_P + i] = P[i // 5, i % 5]
        s[SN_T], s[SN_NEW] = ft, 1.0
        hb = np.empty(2)
        hb[0], hb[1] = r[6], r[7]
        htb = np.empty(2)
        htb[0], htb[1] = r[8], r[9]
        moving = t_stop - tb if tb >= 0.0 else 0.0
        out = np.empty(4)
        joint_launch(z, P, hb, htb, peak, sign, dc, _sq(dc, two), noise_var, math.inf, moving, p[P_S5], out)
        s[J_MP0], s[J_MP1] = z[4], out[3]
        sd_t = math.sqrt(_pmax(out[1], 0.0))
        s[_i.T_MAX] = t_a + t_stop + p[P_STUCK] * sd_t
        s[_i.SINCE] = 0.0
        s[_i.J_SNAP], s[_i.J_NS] = 1.0, 0.0
        s[PC_HAS], s[PC_TA], s[PC_X1A], s[PC_VX1A], s[PC_SIGN] = 1.0, t_a, x1_a, var_x1_a, sign
        s[PC_DTU], s[PC_SIZE], s[PC_DC], s[PC_HB0], s[PC_HB1] = dtu, size, dc, r[6], r[7]
        s[PC_PEAK], s[PC_MOVING], s[PC_OVER], s[PC_NOISE], s[PC_SPREAD] = peak, moving, 1.0 if overshoot else 0.0, \
            noise_var, out[0]
        if size == _RAISE or size == _SETTLE:
            s[CN_STARTUP] += 1.0
        # SizeSchedule.launched(dtu)
        if size == _RAISE:
            startup = dtu
        elif size >= _SMALL:
            s[SC_TAB + int(s[SC_N])] = size
            s[SC_N] += 1.0
            done += 1.0
            if done % _PER_SIZE == 0 and size < _LARGE:
                size += 1.0
        s[CN_PULSES] += 1.0
        s[CN_OVER] += 1.0 if overshoot else 0.0
        if t_off >= 0.0:
            s[CN_BRAKED] += 1.0
            if k == 4:
                offs[0], levs[0] = 0.0, 0.0
                offs[1], levs[1] = offset, level
                offs[2], levs[2] = offset + dtu, -level
                offs[3], levs[3] = offset + t_off, 0.0
            else:
                offs[0], levs[0] = offset, level
                offs[1], levs[1] = offset + dtu, -level
                offs[2], levs[2] = offset + t_off, 0.0
        elif k == 1:
            offs[0], levs[0] = 0.0, 0.0
        elif k == 2:
            offs[0], levs[0] = 0.0, level
            offs[1], levs[1] = dtu, 0.0
        else:
            offs[0], levs[0] = 0.0, 0.0
            offs[1], levs[1] = offset, level
            offs[2], levs[2] = offset + dtu, 0.0
    else:
        offs[0], levs[0] = 0.0, 0.0
    for i in range(5):
        s[_i.J_Z + i] = z[i]
    for i in range(25):
        s[_i.J_P + i] = P[i // 5, i % 5]
    s[_i.FT] = ft
    s[SC_OPT], s[SC_INC], s[SC_SIZE], s[SC_STARTUP], s[SC_DONE] = opt, inc, size, startup, done
    # _export_joint's plan of the next sample (no grid after the hand-over)
    pending = s[PC_HAS] != 0.0
    s[_i.DUE] = 1.0 if pending and (size >= _SMALL and done >= 3 * _PER_SIZE or size == _RAISE
                                    or size == _SETTLE) else 0.0
    s[_i.PLAN_OK] = s[_i.J_GRID] = s[_i.J_GP_OK] = 0.0
    nd = _next_dtu(size, opt, inc, startup)
    if nd > 0:
        nd = _pmin(nd, p[P_DTUMAX])
        s[_i.J_DTU] = nd
        s[_i.J_PEAK] = -p[_i.J_U] * math.expm1(-nd / p[_i.J_T3]) if nd > 0 else 0.0
        s[_i.PLAN_OK] = 1.0
    s[F_DONE] += 1.0
    return k


@njit(cache=True)
def joint_cycle_step(s, p, y, offs, levs):
    """:func:`~controllers.solnic.idle_step.joint_idle_step` with :func:`_cycle` at a sample
    whose first trigger test fires (a pending cycle evaluated first) or whose set-boundary
    evaluation is due."""
    owned = p[_i.J_OWNER] != 0.0
    if owned:
        _i._save_entry(s)
    s[_i.J_STAGE] = 0.0
    k = _i._joint_idle(s, p, y, offs, levs)
    if k == 0 and p[P_ON] != 0.0 and s[F_OK] != 0.0:
        t = (s[_i.N] - 1.0) * p[_i.TS]
        if s[_i.J_STAGE] == 2.0:                # the first trigger test fired: evaluate a pending cycle
            k = _cycle(s, p, t, offs, levs, s[PC_HAS] != 0.0)
        elif (s[_i.J_STAGE] == 1.0 and s[PC_HAS] != 0.0 and s[_i.DUE] != 0.0
              and s[_i.SINCE] >= p[_i.EVAL_SAMPLES]):   # the set-boundary evaluation (SolnicController._step_tail)
            k = _cycle(s, p, t, offs, levs, True)
    if k != 0 or not owned:
        return k
    for i in range(17):
        s[_i.J_LAST + i] = s[_i.J_CACHE + i]
    if s[_i.J_STAGE] == 0.0:
        _i._restore_entry(s)
    with objmode(k="intp"):
        k = _i._python_sample(p[_i.J_OWNER], y, offs, levs)
    return k


_ADDRESS: list[StepAddress] = []


def joint_cycle_step_address() -> StepAddress:
    """:func:`joint_cycle_step` as a :class:`StepAddress` (made once per process)."""
    if not _ADDRESS:
        _ADDRESS.append(step_address(joint_cycle_step))
    return _ADDRESS[0]
