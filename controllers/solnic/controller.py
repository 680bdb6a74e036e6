"""The solnic controller: semi-open-loop, nonlinear, identification and control (ch. 5–7).

Every sample the controller

1. propagates the mode-2 filter on (x̂1, x̂4) and uses y(n) only if the shaft is stuck with
   confidence 0.9987, i.e. past t_max = t_nominal + 3√(H_tb P_b H_tb') of the last pulse (5-11);
2. plans the next correction: Δt_u from the size schedule, Δc_p,cond and the quasipartials from
   the internal plant model, and the unsymmetrical trigger (section 7.2). When a correction is
   due it first evaluates the previous cycle — Δc_e (5-13), VAR[Δc_e] (5-14), the 0.98
   significance test, the friction-filter update (5-15)–(5-18), the start-up sizes and, after
   twelve cycles, the costs (6-1)–(6-5) and the updates (6-9), (6-10) — and re-plans;
3. launches the pulse, possibly inside the interval at the predicted trigger time, and resets
   x̂1 and its variance from the prediction, (5-6) and (5-9).

Set-boundary fix (a bug, not a reading of the text): the next pulse's size depends on the
outcome of the last cycle of a set of twelve ((6-9), (6-10) re-optimise) and of every start-up
cycle (section 7.2). Such a cycle is evaluated as soon as ``evaluation_samples`` samples past
t_max are in, and the trigger is planned with the new size. Before the fix the first trigger
after a set was planned with the finished set's *large* Δc_p, so the controller waited for
x̂1 = −Δc_large/2 and then fired a small pulse (thesis seed 3: a 12.6 µrad pulse from
x̂1 = −40.2 µrad). ``legacy_set_boundary=True`` reproduces it for the regression test.

Errata handled here and in the modules: (6-10) as printed steps uphill, we use the vertex of
the parabola (:mod:`controllers.solnic.strategy`); the text's k̂s ≥ k̂c is a clip of the mean
that leaves P_b untouched (:mod:`controllers.solnic.friction_filter`; the options
``friction_constraints="distribution"`` and the joint EKF condition the distribution instead).

Interpretation of (5-14): the printed formula, VAR[x̂1(t_b)] + VAR[x̂1(t_a)] +
2·COV[x̂1(t_b), x̂1(t_a)]·(t_b − t_a) + VAR[x̂4(t_b)](t_b − t_a)², is garbled (the third term
has the wrong units and the sign of the x̂1(t_b)–x̂1(t_a) covariance is wrong for a
difference). The default, ``dce_variance="exact"``, evaluates the variance of
Δc_e = x̂1(t_b) − x̂1(t_a) + x̂4(t_b)(t_b − t_a) exactly, with the covariances of the
current errors with the frozen x̂1(t_a) carried by the mode-2 filter; it keeps every term
the text names. ``dce_variance="independent"`` treats x̂1(t_a) as independent, i.e.
P11(t_b) + P11(t_a) + 2·P14(t_b)(t_b − t_a) + P44(t_b)(t_b − t_a)².

The significance test is one-sided: the motion must be in the pulse's direction with
Φ(z) ≥ 0.98, z = sign·Δc_e/σ (z ≥ 2.05, the text's "twice its standard deviation").

Option ``dc_measurement="data-only"`` (off by default) removes the double use of the
prediction: x̂1 is reset from Δc_p, so Δc_e already leans on Δc_p and the residual
Δc_e − Δc_p,cond understates the evidence as P_b shrinks. With it the friction filter gets
the samples' own evidence about Δc (prior divided out of the augmented state d of the
mode-2 filter); the significance test uses the posterior of d.

The mode-2 filter's prior is x̂1 = x̂4 = 0 with standard deviations ``x1_prior_std`` (diffuse)
and ``x4_prior_std`` = 15 deg/h, the largest tracking rate of section 2.1; the text gives no
prior variances. The prior on (k̂c, k̂s) is diagonal with a standard deviation equal to the
initial estimate (a factor-of-two error is one sigma).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import lru_cache
from statistics import NormalDist
from typing import Any

import numpy as np

from controllers.base import Controller, register
from controllers.law import CompiledLaw, register_owner
from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams
from controllers.models.acker import max_on_time

from controllers.solnic.cost import cycle_cost, optimal_dtu, optimal_increment
from controllers.solnic.friction_filter import FrictionFilter
from controllers.solnic.grid_posterior import FrictionGrid, Predictive
from controllers.solnic import cycle_step as _cyc, idle_step as _idle, noise_model as _noise
from controllers.solnic.filter_kernels import (joint_add_motion, joint_condition, joint_launch, joint_moved,
                                                joint_predict, joint_update, joint_valid, quadratic_form2)
from controllers.solnic.joint_filter import KS as _KS, JointFilter
from controllers.solnic.mode2_filter import Mode2Filter
from controllers.solnic.noise_model import braked_pulse_noise, pulse_bias, pulse_noise
from controllers.solnic.predictor import LAZY, Predictor, PulsePrediction, peak_torque
from controllers.solnic.options import KNOBS, PRESETS, SolnicOptions
from controllers.solnic.series import cycle_event_times, log_series
from controllers.solnic.strategy import (LARGE, MEDIUM, SMALL, STARTUP_RAISE, STARTUP_SETTLE,
                                         SizeSchedule, plan_trigger)

__all__ = ["SolnicController", "adjusted_increment"]

_NAN = float("nan")
_OFF = DriveCommand.hold(0.0, DriveType.BRIDGE)   # immutable: one shared "off" command (2 µs a sample)
_STD_NORMAL = NormalDist()                       # N(0, 1): one instance, not one per evaluation


@lru_cache(maxsize=1)
def _load_joint_kernels() -> None:
    """Call the joint EKF's launch and constraint kernels once per process on dummy arrays, with
    the argument types of a run: loading them from numba's cache costs ~10–140 ms the first time
    (LLVM's set-up, their libraries), paid at the first reset in the process (the forkserver's
    warm-up, bench/warm.py, resets every controller: its cell processes inherit them), not at
    the first launch after the grid's hand-over. No result depends on it."""
    z, P, h, out = np.array([0.0, 0.0, 1.0, 2.0, 0.0]), np.eye(5), np.ones(2), np.empty(4)
    joint_launch(z, P, h, h.copy(), 1.5, 1, 1e-5, 1e-10, 0.0, math.inf, 1e-3, 1e-4, out)
    joint_moved(z, P, 1.5, 4.0)
    joint_valid(z, P, 4.0)
    joint_condition(z, P, np.ones(5), 1.0, True)


_WARMED_STEPS: set[str] = set()     # the idle step kinds whose in-loop Python sample is compiled here


def _warm_in_loop(controller: "SolnicController") -> None:
    """Once per process and idle-step kind: compile the step's ``objmode`` block and load the
    Python sample's kernels, so that the first cell of a process does neither (issue 27: a worker
    process's first solnic-modern cell cost 0.33 s against 0.19 s, solnic's 0.21 s against 0.04 s).

    numba compiles a step's ``objmode`` block (:func:`~controllers.solnic.idle_step._python_sample`)
    at its first execution in each process and does not cache it (~0.07 s): the step is called
    once on a state whose filter time lies ahead of the sample (the step gives it to Python at
    once) with an owner key no controller holds (the Python sample returns 0). The kernels of
    the Python sample (predictor, noise model, filters, grid) are loaded from numba's cache at
    their first call (~0.04 s): they are called on fresh objects of the controller's options
    or on dummy arrays of the run's types. Nothing of ``controller`` is read but its options and
    plant, nothing it holds is touched, and none of its methods runs; anything raised is dropped.
    Paid at the first reset in the process (the forkserver's warm-up, bench/warm.py, resets every
    controller: its cell processes inherit it)."""
    kind = controller._compiled_kind()
    if kind is None or kind in _WARMED_STEPS:
        return
    _WARMED_STEPS.add(kind)
    try:
        joint = kind == "joint"
        if joint:
            step, n_s, n_p, key = (_cyc.joint_cycle_step_address(), _cyc.N_CYCLE_STATE, _cyc.N_CYCLE_PARAMS,
                                   _idle.J_OWNER)
        else:
            step, n_s, n_p, key = _idle.idle_step_address(), 2 * _idle.N_STATE, _idle.N_PARAMS, _idle.OWNER
        state, p = np.zeros(n_s), np.zeros(n_p)
        state[_idle.FT] = 1.0                   # the filter ahead of sample 0: given to Python at once
        p[key] = -1.0                           # no controller holds this key: the sample returns 0
        step(state, p, 0.0, np.empty(4), np.empty(4))
        _load_sample_kernels(controller.options, controller.params, joint)
    except Exception:  # noqa: BLE001 — a warm-up never changes an outcome
        pass


def _load_sample_kernels(o: SolnicOptions, params: PlantParams, joint: bool) -> None:
    """The kernels a Python sample calls, on fresh objects (see :func:`_warm_in_loop`)."""
    f = o.initial_friction_factor
    kc, ks = f * params.coulomb, min(f * params.stiction, 0.999 * params.u_max)
    kc = min(kc, ks)
    dtu = min(adjusted_increment(params, o.a_c, o.a_ratio)[1], max_on_time(params))
    brake = o.brake_margin_sigmas if o.braking_pulse else None
    for margin in ((None, brake) if joint else (None,)):
        pr = Predictor(params, fd_step=o.fd_step, brake_margin=margin, brake_min_ratio=o.brake_min_ratio)
        pr.predict(ks, kc, dtu)
        pred = pr.conditional(ks, kc, dtu)
    P2 = np.diag([(0.5 * kc) ** 2, (0.5 * ks) ** 2])
    if not joint:
        ff = FrictionFilter(kc, ks, P2, params.u_max, a=o.a_cov, max_correction_fraction=o.max_correction_fraction,
                            constraints=o.friction_constraints)
        ff.motion_variance(np.asarray(pred.H_b, dtype=float))
        ff.update(np.asarray(pred.H_b, dtype=float), 1e-7, 1e-12, pred.peak_torque)
        return
    if pred.t_breakaway is not None:                # by the module's names (tests replace this one's)
        _noise.pulse_noise(params, ks, kc, dtu, pred.t_breakaway, pred.t_current_zero, pred.t_nominal)
        _noise.pulse_bias(params, ks, kc, dtu, pred.t_breakaway, pred.t_current_zero, pred.t_nominal)
    _noise.braked_pulse_noise(params, 2.0, 1.0, 1.2e-3, 2e-4, 3e-3, 4e-3)
    z, P = np.array([0.0, 0.0, kc, ks, 0.0]), np.eye(5) * 1e-12
    joint_predict(z, P, -1e-3, 0.99, 1e-14, 1e-14, 1e-14)
    joint_update(z, P, 1e-12, 0.0)
    joint_add_motion(z, P, np.zeros(5), 1e-6, 1e-14, math.inf, 1e-6)
    quadratic_form2(np.ones(2), P[2:4, 2:4])
    if o.friction_grid:
        g = FrictionGrid(params, [kc, ks], P2, n=o.grid_points, memory=o.grid_memory)
        gp = g.predictive(dtu, 2.5, 0.8)
        if gp.p_motion > 0:
            g.update(dtu, 1, gp.dc_mean, (0.1 * gp.dc_mean) ** 2, 2.5, 0.8)


@lru_cache(maxsize=32)
def adjusted_increment(params: PlantParams, a_c: float, a_ratio: float = 2.0) -> tuple[float, float]:
    """(Δt_u,opt, Δt_u,inc) properly adjusted for the true plant: the optimum of the noise-free
    cost curve at x4 = ``command_velocity_initial`` and the increment with Δc ratio ``a_ratio``.

    Section 7.3's "Δt_u,inc four times too large" is relative to this increment.
    """
    opt = optimal_dtu(params, a_c)
    return opt, optimal_increment(params, opt, a_ratio)



@dataclass
class _Cycle:
    """What the controller remembers about the pulse whose outcome is still to be measured."""

    t_a: float
    x1_a: float
    var_x1_a: float
    sign: int
    dt_u: float
    size: int
    delta_c: float            # |Δc_p,cond| [rad]
    H_b: np.ndarray           # quasipartials of |Δc| (positive-direction convention)
    peak_torque: float
    moving_time: float
    overshoot: bool
    noise_var: float = 0.0    # VAR[Δc] from w2 (noise-aware model) [rad²]
    spread_var: float = 0.0   # VAR[Δc_p] from the friction uncertainty [rad²]


@register("solnic")
class SolnicController(Controller):
    """Solnic controller on the switched bridge (levels +u_max, 0, −u_max).

    Parameters
    ----------
    options : SolnicOptions, optional
        A complete option set (positional); or
    preset : str
        ``"thesis"`` (the default when no options object is given) or ``"high-error-cost"``;
        see :mod:`controllers.solnic.options`.
    **fields
        Overrides of any :class:`~controllers.solnic.options.SolnicOptions` field, e.g. ``a_c``.

    Raises
    ------
    ValueError
        Naming the offending preset or option.
    """

    drive = DriveType.BRIDGE
    family = "solnic"
    counter = "pulses"
    description = "solnic: semi-open-loop nonlinear identification and control (Acker 1967)"
    Options = SolnicOptions
    presets = PRESETS
    knobs = KNOBS

    python_in_loop = True     # the compiled idle step's Python samples inside its loop (False: hand-backs)
    cycle_in_loop = True      # solnic-modern's common post-hand-over cycles compiled (controllers.solnic.cycle_step)

    def __init__(self, options: SolnicOptions | None = None, /, *, preset: str | None = None,
                 **fields: Any) -> None:
        if options is None and preset is None:
            preset = "thesis"
        Controller.__init__(self, options, preset=preset, **fields)
        self.preset = preset if preset is not None else "custom"
        self._ready = False

    # ------------------------------------------------------------------ run set-up
    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        o = self.options
        self.params = params
        self.rng = rng
        # braking pulses (option): not while the grid posterior, whose likelihood is the single
        # pulse's, is in charge; switched on at its hand-over
        self._brake_margin = o.brake_margin_sigmas if o.braking_pulse else None
        self.predictor = Predictor(params, fd_step=o.fd_step,
                                   brake_margin=None if o.friction_grid else self._brake_margin,
                                   brake_min_ratio=o.brake_min_ratio)
        f = o.initial_friction_factor
        kc0, ks0 = f * params.coulomb, f * params.stiction
        ks0 = min(ks0, 0.999 * params.u_max)
        kc0 = min(kc0, ks0)
        s = o.friction_prior_std_fraction
        self.friction = FrictionFilter(kc0, ks0, np.diag([(s * kc0) ** 2, (s * ks0) ** 2]),
                                       params.u_max, a=o.a_cov,
                                       max_correction_fraction=o.max_correction_fraction,
                                       constraints=o.friction_constraints)
        sigma1 = params.measurement_noise_std if params.measurement_noise_std > 0 else 1e-9
        prior = np.diag([o.x1_prior_std ** 2, o.x4_prior_std ** 2])
        self.joint: JointFilter | None = None
        if o.friction_estimator == "joint-ekf":
            self.joint = JointFilter(params.command_velocity_tau, params.sigma4_sq, sigma1, [0.0, 0.0],
                                     prior, [kc0, ks0], self.friction.P, params.u_max)
            self.mode2 = self.joint
            self.friction = self.joint.friction
            _load_joint_kernels()
        else:
            self.mode2 = Mode2Filter(params.command_velocity_tau, params.sigma4_sq, sigma1,
                                     [0.0, 0.0], prior)
        self.grid: FrictionGrid | None = None
        if o.friction_grid:
            self.grid = FrictionGrid(params, [kc0, ks0], self.friction.P, n=o.grid_points,
                                     memory=o.grid_memory)
            self._grid_memo: dict[float, Predictive] = {}
            self._grid_key = -1
        if o.dtu_inc_initial is not None:
            inc0 = o.dtu_inc_initial
            self.adjusted = (_NAN, _NAN)
        else:
            self.adjusted = adjusted_increment(params, o.a_c, o.a_ratio)
            inc0 = o.initial_increment_factor * self.adjusted[1]
        self.schedule = SizeSchedule(dtu_opt=o.dtu_opt_initial, dtu_inc=inc0)
        self.dtu_max = max_on_time(params)
        self.z_motion = NormalDist().inv_cdf(o.motion_confidence)
        self._n = 0
        self._t_max = -math.inf
        self._samples_since_launch = 0
        self._undecided = 0
        self._posterior = (0.0, 0.0, o.x1_prior_std**2, 0.0, o.x4_prior_std**2)
        self._nis: list[float] = []
        self._noise_memo: dict[tuple[float, float, float], tuple[float, float]] = {}
        self._pending: _Cycle | None = None
        self._costs = (_NAN, _NAN, _NAN)
        self._dc_ratio = _NAN
        self.log: list[dict[str, float]] = []
        self.counts = dict(pulses=0, overshoot_corrections=0, samples_used=0, samples_rejected=0,
                           cycles_evaluated=0, significant_cycles=0, friction_updates=0,
                           cost_evaluations=0, startup_cycles=0, shrinks=0, clipped_updates=0,
                           undecided_cycles=0, grid_handover_cycle=0, braked_pulses=0)
        self._idle: CompiledLaw | None = None
        self._ready = True
        _warm_in_loop(self)

    # ------------------------------------------------------------------ the compiled idle sample
    def compiled_law(self) -> CompiledLaw | None:
        """The idle sample compiled (:mod:`controllers.solnic.idle_step`): the faithful
        estimators' (two filters, no grid, no noise-aware model) or the joint EKF's with the
        noise-aware model (``solnic-modern``, grid or not); None for other option sets.

        While it is in use the state lives in its array between Python samples: ``step``
        imports it first and exports it after (a hand-back is the Python path's sample).
        """
        o = self.options
        kind = self._compiled_kind()
        if kind is None:
            return None
        joint = kind == "joint"
        if joint:
            f, n_p, n_s, step = self.joint, _cyc.N_CYCLE_PARAMS, _cyc.N_CYCLE_STATE, _cyc.joint_cycle_step_address()
        else:
            f, n_p, n_s, step = self.mode2, _idle.N_PARAMS, 2 * _idle.N_STATE, _idle.idle_step_address()
        p = np.empty(n_p)
        p[_idle.TS], p[_idle.R] = self.params.sample_period, f.R
        p[_idle.TAU4:_idle.Q44C + 1] = _idle.mode2_coefficients(f.tau4, f.sigma4_sq)
        p[_idle.EVAL_SAMPLES], p[_idle.OVERSHOOT] = o.evaluation_samples, o.overshoot_factor
        owner = register_owner(self) if self.python_in_loop else 0.0
        if not joint:
            p[_idle.OWNER] = owner
        if joint:
            U, t3, a, fd = self.predictor._constants
            s2, cap, min_ratio = self.predictor._brake_constants
            p[_idle.J_U:_idle.J_UMAX + 1] = U, t3, a, fd, s2, cap, min_ratio, f.u_max
            p[_idle.J_OWNER] = owner
            p[_cyc.P_ZMOT], p[_cyc.P_POWER], p[_cyc.P_MAXUND] = self.z_motion, o.no_motion_power, o.max_undecided_cycles
            p[_cyc.P_STUCK], p[_cyc.P_S5], p[_cyc.P_DTUMAX] = (o.stuck_confidence_sigmas, float(self.params.sigma5_sq),
                                                               self.dtu_max)
            p[_cyc.P_TWO], p[_cyc.P_ULEVEL] = 2.0, self.params.u_max
            p[_cyc.P_ON] = (self.cycle_in_loop and o.motion_decision == "three-way" and not o.joint_correction_limit
                            and not o.legacy_set_boundary)
        self._in_loop: tuple | None = None
        self._replay: BaseException | None = None
        self._idle = CompiledLaw(step, np.zeros(n_s), p, DriveType.BRIDGE, 4)
        self._plan_key: tuple[float, float, float] | None = None
        self._memo_seen = (0, 0)
        self._export_idle()
        return self._idle

    def _compiled_kind(self) -> str | None:
        """Which idle step :meth:`compiled_law` would give now: ``"joint"`` (the joint EKF with
        the noise-aware model), ``"mode2"`` (the faithful estimators) or None."""
        o = self.options
        if not self._ready or self._n != 0:
            return None
        if self.joint is not None:
            ok = type(self.joint) is JointFilter and o.noise_aware_model and self.predictor._compiled
            return "joint" if ok else None
        ok = self.grid is None and not o.noise_aware_model and type(self.mode2) is Mode2Filter
        return "mode2" if ok else None

    def _export_idle(self) -> None:
        """The state into the idle step's array, with the plan of the next sample cached."""
        if self.joint is not None:
            self._export_joint()
            return
        s, m = self._idle.state, self.mode2
        anchor, motion = m._anchor, m._motion
        s[_idle.N:_idle.DUE + 1] = (                # the layout's order, N … DUE
            self._n, m.x1, m.x4, m.p11, m.p14, m.p44, m.t,
            anchor is not None, *(anchor if anchor is not None else (0.0, 0.0)),
            motion is not None, *(motion if motion is not None else (0.0, 0.0)), m.motion_mean, m.motion_var,
            self._t_max, self._samples_since_launch, self.counts["samples_used"], self.counts["samples_rejected"],
            *self._posterior, self._pending is not None and self._outcome_sets_next_size())
        s[_idle.PLAN_USED] = 0.0
        self._exported_n = self._n
        # the plan of the next sample: Δt_u of the schedule as it stands, Δc_p,cond and the
        # current-zero time of that pulse with the current k̂ (without the predictor's side
        # effects: they are replayed by _import_idle if an idle sample used the plan)
        s[_idle.PLAN_OK], self._plan_key = 0.0, None
        dtu = self.schedule.next_dtu()
        if dtu > 0:
            dtu = min(dtu, self.dtu_max)
            pred = self.predictor.conditional_peek(self.friction.ks, self.friction.kc, dtu)
            if pred is not None:
                s[_idle.DC_PLAN], s[_idle.DURATION] = abs(pred.delta_c), pred.t_current_zero
                s[_idle.PLAN_OK], self._plan_key = 1.0, (self.friction.ks, self.friction.kc, dtu)

    def _export_joint(self) -> None:
        """:meth:`_export_idle` for :func:`~controllers.solnic.idle_step.joint_idle_step`: the
        joint Gaussian, the keys of the predictor's memo, the Δt_u (and the grid's cached
        predictive) of the next sample."""
        s, j, pr = self._idle.state, self.joint, self.predictor
        s[_idle.N], s[_idle.FT] = self._n, j.t
        s[_idle.J_Z:_idle.J_Z + 5] = j.z
        s[_idle.J_P:_idle.J_P + 25] = j.P.ravel()
        s[_idle.J_SNAP], s[_idle.J_NS] = j._snapshot is not None, 0.0
        s[_idle.T_MAX:_idle.DUE + 1] = (self._t_max, self._samples_since_launch, self.counts["samples_used"],
                                        self.counts["samples_rejected"], *self._posterior,
                                        self._pending is not None and self._outcome_sets_next_size())
        self._exported_n = self._n
        # the memo's keys with this brake margin (the others cannot be hit, but count in its size)
        memo = pr.__dict__.setdefault("_conditional_memo", {})
        clears, n_seen = self._memo_seen
        if clears != pr.memo_clears or len(memo) < n_seen:
            n_seen, s[_idle.J_MK] = 0, 0.0
        mk = int(s[_idle.J_MK])
        if len(memo) > n_seen:
            margin = pr.brake_margin
            new = [k for k in itertools.islice(reversed(memo), len(memo) - n_seen)][::-1]
            for key in new:
                if key[3] == 1 and key[4] == 1e-6 and key[5] == margin:
                    s[_idle.J_MTAB + 3 * mk:_idle.J_MTAB + 3 * mk + 3] = key[:3]
                    mk += 1
        if margin_changed := (s[_idle.J_MARGIN] != (-1.0 if pr.brake_margin is None else pr.brake_margin)):
            mk = 0                                          # the hand-over: rebuild for the new margin
            for key in memo:
                if key[3] == 1 and key[4] == 1e-6 and key[5] == pr.brake_margin:
                    s[_idle.J_MTAB + 3 * mk:_idle.J_MTAB + 3 * mk + 3] = key[:3]
                    mk += 1
        del margin_changed
        self._memo_seen = (pr.memo_clears, len(memo))
        self._export_cycles(s)
        s[_idle.J_MK] = s[_idle.J_MK0] = mk
        s[_idle.J_MCOUNT], s[_idle.J_CLEARED], s[_idle.J_RUNS] = len(memo), 0.0, 0.0
        brake, margin = pr._brake_args()[:2]
        s[_idle.J_BRAKE], s[_idle.J_MARGIN] = brake, (margin if brake else -1.0)
        s[_idle.PLAN_OK] = s[_idle.J_GRID] = s[_idle.J_GP_OK] = 0.0
        dtu = self.schedule.next_dtu()
        if not dtu > 0:
            return
        dtu = min(dtu, self.dtu_max)
        s[_idle.J_DTU], s[_idle.J_PEAK] = dtu, peak_torque(self.params, dtu)
        if self.grid is not None:
            s[_idle.J_GRID] = 1.0
            gp = (self._grid_memo.get(dtu) if (self.grid.version, len(self.grid.obs)) == self._grid_key
                  else None)
            if gp is None:
                return                                      # computed from this sample's prediction: in Python
            if gp.p_motion > 0:
                s[_idle.J_GP_OK], s[_idle.J_GP_DC] = 1.0, gp.dc_mean
        s[_idle.PLAN_OK] = 1.0

    def _export_cycles(self, s: np.ndarray) -> None:
        """What :func:`~controllers.solnic.cycle_step._cycle` reads and writes besides the idle
        step's state: the pending cycle, the undecided run, the counters, the schedule, the
        joint filter's motion-update count and prior of d; no cycle done yet."""
        c, C, sch, cnt = self._pending, _cyc, self.schedule, self.counts
        s[C.F_OK] = self.grid is None
        if c is not None:
            s[C.PC_HAS:C.PC_SPREAD + 1] = (1.0, c.t_a, c.x1_a, c.var_x1_a, c.sign, c.dt_u, c.size, c.delta_c,
                                          c.H_b[0], c.H_b[1], c.peak_torque, c.moving_time, c.overshoot,
                                          c.noise_var, c.spread_var)
        else:
            s[C.PC_HAS] = 0.0
        s[C.UNDEC] = self._undecided
        s[C.CN_EVAL:C.CN_BRAKED + 1] = (cnt["cycles_evaluated"], cnt["undecided_cycles"], cnt["significant_cycles"],
                                        cnt["friction_updates"], cnt["startup_cycles"], cnt["pulses"],
                                        cnt["overshoot_corrections"], cnt["braked_pulses"])
        s[C.SC_OPT:C.SC_N + 1] = (sch.dtu_opt, sch.dtu_inc, sch.size, sch.dtu_startup, sch.cycles_done, 0.0, 0.0)
        j = self.joint
        s[C.J_NMU], (s[C.J_MP0], s[C.J_MP1]) = j.n_motion_updates, j.motion_prior
        s[C.SN_NEW] = s[C.F_DONE] = s[C.LOG_N] = 0.0

    def _import_cycles(self, s: np.ndarray) -> None:
        """The objects as the compiled cycles since the export left them (:meth:`_export_cycles`);
        the log entries and the filter's snapshot are consumed from the array."""
        C, j, sch, cnt = _cyc, self.joint, self.schedule, self.counts
        head = s[C.F_OK:C.LOG_N + 1].tolist()
        v = lambda i: head[i - C.F_OK]                                      # noqa: E731
        if v(C.SN_NEW):
            j._snapshot = (s[C.SN_Z:C.SN_Z + 5].copy(), s[C.SN_P:C.SN_P + 25].reshape(5, 5).copy(), v(C.SN_T))
            j._since = []
        for i in range(int(v(C.LOG_N))):
            e = s[C.LOG_TAB + C.N_LOG_FIELDS * i:C.LOG_TAB + C.N_LOG_FIELDS * (i + 1)].tolist()
            entry = dict(t_a=e[C.L_TA], t_b=e[C.L_TB], x1_a=e[C.L_X1A], size=e[C.L_SIZE], dt_u=e[C.L_DTU],
                         sign=e[C.L_SIGN], dc_p=e[C.L_DCP], dc_e=e[C.L_DCE], sd_e=e[C.L_SDE],
                         significant=e[C.L_SIG], ks_before=e[C.L_KSB], kc_before=e[C.L_KCB])
            if e[C.L_HASNIS]:
                self._nis.append(e[C.L_NIS])
                entry["nis"] = e[C.L_NIS]
            entry.update(ks=e[C.L_KS], kc=e[C.L_KC], decision=C.DECISIONS[int(e[C.L_DEC])])
            self.log.append(entry)
        self._pending = (_Cycle(v(C.PC_TA), v(C.PC_X1A), v(C.PC_VX1A), int(v(C.PC_SIGN)), v(C.PC_DTU),
                                int(v(C.PC_SIZE)), v(C.PC_DC), np.array([v(C.PC_HB0), v(C.PC_HB1)]),
                                v(C.PC_PEAK), v(C.PC_MOVING), bool(v(C.PC_OVER)), v(C.PC_NOISE), v(C.PC_SPREAD))
                         if v(C.PC_HAS) else None)
        self._undecided = int(v(C.UNDEC))
        for name, i in (("cycles_evaluated", C.CN_EVAL), ("undecided_cycles", C.CN_UNDEC),
                        ("significant_cycles", C.CN_SIG), ("friction_updates", C.CN_FU),
                        ("startup_cycles", C.CN_STARTUP), ("pulses", C.CN_PULSES),
                        ("overshoot_corrections", C.CN_OVER), ("braked_pulses", C.CN_BRAKED)):
            cnt[name] = int(v(i))
        sch.dtu_opt, sch.dtu_inc, sch.size = v(C.SC_OPT), v(C.SC_INC), int(v(C.SC_SIZE))
        sch.dtu_startup, sch.cycles_done = v(C.SC_STARTUP), int(v(C.SC_DONE))
        if v(C.SC_RESET):
            sch.set_sizes = []
        sch.set_sizes.extend(int(x) for x in s[C.SC_TAB:C.SC_TAB + int(v(C.SC_N))].tolist())
        j.n_motion_updates = int(v(C.J_NMU))
        j.motion_prior = (v(C.J_MP0), v(C.J_MP1))
        self._t_max = s.item(_idle.T_MAX)
        s[C.SN_NEW] = s[C.F_DONE] = s[C.LOG_N] = s[C.SC_RESET] = s[C.SC_N] = 0.0

    def _import_joint(self) -> None:
        s, j, pr = self._idle.state, self.joint, self.predictor
        head = s[:_idle.J_Z].tolist()                   # the scalars N … J_CLEARED as Python floats
        self._n = self._exported_n = int(head[_idle.N])
        j.t = head[_idle.FT]
        j.z[:] = s[_idle.J_Z:_idle.J_Z + 5]
        j.P[:] = s[_idle.J_P:_idle.J_P + 25].reshape(5, 5)
        if s[_cyc.F_DONE] != 0.0:
            self._import_cycles(s)                      # before the since-buffer: a launch resets it
        ns = int(head[_idle.J_NS])
        if ns:
            buf = iter(s[_idle.J_SBUF:_idle.J_SBUF + 2 * ns].tolist())
            j._since.extend(zip(buf, buf))              # the (t, y) pairs in order
            s[_idle.J_NS] = 0.0
        self._samples_since_launch = int(head[_idle.SINCE])
        self.counts["samples_used"], self.counts["samples_rejected"] = int(head[_idle.USED]), int(head[_idle.REJECTED])
        self._posterior = tuple(head[_idle.POST:_idle.POST + 5])
        # the predictor's memo and model runs as the idle samples' conditional() calls left them
        pr.n_model_runs += int(head[_idle.J_RUNS])
        memo = pr.__dict__.setdefault("_conditional_memo", {})
        mk0, mk = int(head[_idle.J_MK0]), int(head[_idle.J_MK])
        if head[_idle.J_CLEARED] != 0.0:
            memo.clear()
            pr.memo_clears += 1
            mk0 = 0
        if mk > mk0:
            # the keys (k̂s, k̂c, Δt_u, 1, 1e-6, margin) in the order the samples added them
            tab = iter(s[_idle.J_MTAB + 3 * mk0:_idle.J_MTAB + 3 * mk].tolist())
            rep = itertools.repeat
            memo.update(zip(zip(tab, tab, tab, rep(1), rep(1e-6), rep(pr.brake_margin)), rep(LAZY)))
        s[_idle.J_MK0], s[_idle.J_CLEARED], s[_idle.J_RUNS] = mk, 0.0, 0.0
        self._memo_seen = (pr.memo_clears, len(memo))

    def _import_idle(self) -> None:
        """The objects from the idle step's array, if compiled samples ran since the export."""
        s = self._idle.state
        if s[_idle.N] == self._exported_n:
            return
        if self.joint is not None:
            self._import_joint()
            return
        m = self.mode2
        (n, m.x1, m.x4, m.p11, m.p14, m.p44, m.t, _, c0, c1, _, m0, m1, mean, var, _, since, used, rejected,
         *post) = s[_idle.N:_idle.POST + 5].tolist()
        self._n = self._exported_n = int(n)
        if m._anchor is not None:
            m._anchor = (c0, c1)
        if m._motion is not None:
            m._motion = (m0, m1)
            m.motion_mean, m.motion_var = mean, var
        self._samples_since_launch = int(since)
        self.counts["samples_used"], self.counts["samples_rejected"] = int(used), int(rejected)
        self._posterior = tuple(post)
        if s[_idle.PLAN_USED] != 0.0:
            self.predictor.conditional(*self._plan_key)     # what the first idle sample's _plan did
        s[_idle.PLAN_USED] = 0.0

    def _loop_sample(self) -> tuple[bool, float]:
        """(staged, n) of the sample the compiled step gives to Python: whether the joint step
        has done its filter updates (``J_STAGE``), and the sample's number n (its entry state's
        ``s[N]``; the staged array has n + 1)."""
        s = self._idle.state
        staged = self.joint is not None and s[_idle.J_STAGE] != 0.0
        return staged, (s[_idle.N] - 1.0 if staged else s[_idle.N])

    def _sample_in_loop(self, y: float, offs: np.ndarray, levs: np.ndarray) -> int:
        """A sample the joint idle step cannot do, done from inside the compiled loop
        (:func:`~controllers.solnic.idle_step._python_sample`): :meth:`step` on the state array
        as the step found it, the command into (offs, levs); returns its segment count.

        The sample's outcome is kept for the runner's :meth:`step` call where the loop hands the
        sample back after all: an exception (``_replay``, raised again there), or a command the
        loop cannot take (more segments than it holds, or one its test,
        :func:`plant.law_step.check_command` with the plant's τs and u_max, rejects: returned
        there with the state after it, ``_in_loop``). A sample the loop redoes (its interval
        needed more noise or log room, :func:`plant.law_driver.run_law_chunks`) gets the same
        command and state again, not a second Python sample.
        """
        s = self._idle.state
        staged, n = self._loop_sample()
        done = self._in_loop
        if done is not None and done[0] == n:             # the loop redoes sample n
            _, k, o, v, after, _ = done
            s[:] = after
            offs[:k], levs[:k] = o, v
            return k
        try:
            command = self._staged_step() if staged else self.step(y)
        except BaseException as exc:
            self._replay = exc
            # the loop restores the sample's entry state (s[N] = n); the objects stay as the
            # exception left them, as on the Python path (no import of the entry state)
            self._exported_n = int(n)
            return 0
        o, v = command.arrays()
        k = o.shape[0]
        self._in_loop = (n, k, o.copy(), v.copy(), s.copy(), command)
        if k > offs.shape[0] or command.drive is not DriveType.BRIDGE:
            return 0                                      # handed back: step returns it
        offs[:k], levs[:k] = o, v
        return k

    # ------------------------------------------------------------------ per sample
    def step(self, y: float) -> DriveCommand:
        if not self._ready:
            raise RuntimeError("SolnicController.step called before reset")
        if self._idle is None:
            return self._step(y)
        if self._replay is not None:                  # a sample done in the loop raised: raise it here
            exc, self._replay = self._replay, None
            raise exc
        done = self._in_loop
        if done is not None and done[0] == self._idle.state[_idle.N]:
            # done in the loop, its command handed back (the loop could not take it): the same
            # command and state, not a second Python sample
            self._in_loop = None
            self._idle.state[:] = done[4]
            return done[5]
        self._import_idle()
        command = self._step(y)
        self._export_idle()
        return command

    def _staged_step(self) -> DriveCommand:
        """:meth:`step` of a sample whose filter updates the joint idle step has done
        (``J_STAGE`` 1: the array holds them, the counters and the posterior): the rest of it."""
        fired = self._idle.state[_idle.J_STAGE] == 2.0
        self._import_idle()
        command = self._step_tail((self._n - 1) * self.params.sample_period, fired)
        self._export_idle()
        return command

    def _step(self, y: float) -> DriveCommand:
        t = self._n * self.params.sample_period
        self._n += 1
        self.mode2.predict(t)
        if t >= self._t_max and math.isfinite(y):
            self.mode2.update(y)
            self.counts["samples_used"] += 1
            self._samples_since_launch += 1
        else:
            self.counts["samples_rejected"] += 1
        self._posterior = self.mode2.moments()
        return self._step_tail(t)

    def _step_tail(self, t: float, fired: bool = False) -> DriveCommand:
        """The sample at t = n·τs after the filters' updates: the set-boundary evaluation, the
        plan (``fired``: the compiled step's first trigger test of :meth:`_plan` fired)."""
        if (self._pending is not None and self._outcome_sets_next_size()
                and self._samples_since_launch >= self.options.evaluation_samples):
            # Set-boundary fix: the next Δt_u depends on this cycle's outcome (a finished set
            # is re-optimised by (6-9), (6-10); start-up sizes react to significance), so the
            # cycle is evaluated as soon as its samples are in and the trigger is planned with
            # the new size, not with the stale one.
            self._evaluate(t)
        return self._plan(t, fired)

    def _outcome_sets_next_size(self) -> bool:
        """Whether the pending cycle's evaluation changes the size of the next pulse."""
        if self.options.legacy_set_boundary:
            return False
        sch = self.schedule
        return sch.set_complete or sch.size in (STARTUP_RAISE, STARTUP_SETTLE)

    def _next_dtu(self) -> float:
        sch = self.schedule
        for _ in range(4):
            dtu = sch.next_dtu()
            if dtu > 0:
                return min(dtu, self.dtu_max)
            if sch.size >= SMALL:
                sch.skip_size()
                if sch.set_complete:
                    self._reoptimise()
            else:
                sch.dtu_startup = sch.dtu_inc / 4.0
        return min(max(sch.next_dtu(), sch.dtu_inc), self.dtu_max)

    def _plan(self, t: float, fired: bool = False) -> DriveCommand:
        """The trigger test of the next pulse; with a pending cycle, a trigger evaluates it and
        plans again. ``fired``: the compiled step has made the first test with the same Δt_u,
        prediction and bias (its cached plan, key-matched: :func:`~controllers.solnic.idle_step._joint_idle`)
        and it fired; the steps below have no side effect on the outcome there (the Δt_u is the
        schedule's without a skip, the memo holds the prediction, the grid's predictive is cached),
        so with a pending cycle they are not repeated."""
        ts = self.params.sample_period
        earliest = max(0.0, self._t_max - t)
        for attempt in range(2):
            if attempt == 0 and fired and self._pending is not None:
                self._evaluate(t)
                continue
            dtu = self._next_dtu()
            pred = self.predictor.conditional(self.friction.ks, self.friction.kc, dtu)
            x1, x4 = self.mode2.x1, self.mode2.x4
            dc_plan = abs(pred.delta_c)
            gp = self._grid_predictive(dtu, pred)
            if gp is not None:
                dc_plan = gp.dc_mean                        # w2 bias included
            elif self.options.noise_aware_model:
                # a trigger here only evaluates the pending cycle and re-plans: the bias alone
                dc_plan += (self._pulse_bias(pred, dtu) if self._pending is not None and attempt == 0
                            else self._pulse_noise(pred, dtu)[0])
            trig = plan_trigger(x1, x4, self.mode2.drift_std(), dc_plan, horizon=ts,
                                earliest=earliest, duration=pred.t_current_zero,
                                overshoot_factor=self.options.overshoot_factor)
            if trig is None:
                return _OFF
            if self._pending is not None and attempt == 0:
                self._evaluate(t)
                continue
            return self._launch(t, trig.offset, trig.sign, trig.overshoot, dtu, pred)
        return _OFF

    def _launch(self, t: float, offset: float, sign: int, overshoot: bool, dtu: float,
                pred: PulsePrediction) -> DriveCommand:
        t_a = t + offset
        self.mode2.predict(t_a)
        x1_a, var_x1_a = self.mode2.x1, self.mode2.p11
        if self.joint is None:
            self.mode2.set_anchor()
        dc = abs(pred.delta_c)
        noise_var = 0.0
        fused = False
        gp = self._grid_predictive(dtu, pred)
        if gp is not None:
            # the posterior predictive of the grid: d ~ (mean, spread + w2 + no-motion mass),
            # uncorrelated with the joint filter's k block (the grid, not the samples, updates k)
            dc = gp.dc_mean
            p_zero = 1.0 - gp.p_motion
            spread = gp.dc_var + (self.options.grid_model_error * dc) ** 2
            t_nominal, sd_t = gp.t_stop_mean, math.sqrt(gp.t_stop_var)
            moving = 0.0                                    # the grid has no x5 drift
        elif self.joint is not None and type(self.joint) is JointFilter:
            # the joint EKF's launch in one compiled call (filter_kernels.joint_launch): the
            # spreads and Prob(no motion) on the k block, add_motion, propagate, as below
            if self.options.noise_aware_model:
                bias, noise_var = self._pulse_noise(pred, dtu)
                dc += bias                                  # E[Δc] with the w2 push and tail
            j = self.joint
            limit = (self.options.max_correction_fraction * j.z.item(_KS)
                     if self.options.joint_correction_limit else math.inf)
            j._snapshot = (j.z.copy(), j.P.copy(), j.t)     # JointFilter.add_motion's first steps
            j._since = []
            out = np.empty(4)
            joint_launch(j.z, j.P, pred.H_b, pred.H_tb, float(pred.peak_torque), sign, dc, dc**2,
                         float(noise_var), float(limit), (pred.t_nominal - pred.t_breakaway
                                                          if pred.t_breakaway is not None else 0.0),
                         float(self.params.sigma5_sq), out)
            j.motion_prior = (j.z.item(4), out.item(3))
            spread, t_nominal = out.item(0), pred.t_nominal
            sd_t = math.sqrt(max(out.item(1), 0.0))
            moving = pred.t_nominal - pred.t_breakaway if pred.t_breakaway is not None else 0.0
            fused = True
        else:
            if self.options.noise_aware_model:
                bias, noise_var = self._pulse_noise(pred, dtu)
                dc += bias                                  # E[Δc] with the w2 push and tail
            spread = self.friction.motion_variance(pred.H_b)
            t_nominal = pred.t_nominal
            sd_t = math.sqrt(max(self.friction.time_variance(pred.H_tb), 0.0))
            moving = pred.t_nominal - pred.t_breakaway if pred.t_breakaway is not None else 0.0
            p_zero = self.friction.prob_no_motion(pred.peak_torque)
        if not fused:
            var_dc = spread + dc**2 * p_zero + noise_var    # (5-9), noise-aware: w2 over T_m
            if gp is not None:
                self.joint.add_motion(sign, dc, np.zeros(2), var_dc)
            elif self.joint is not None:    # d = sign(Δc + H_b(k − k̂)) + n; k̂ spread is in the state
                limit = (self.options.max_correction_fraction * self.friction.ks
                         if self.options.joint_correction_limit else math.inf)
                self.joint.add_motion(sign, dc, pred.H_b, noise_var + dc**2 * p_zero, limit)
            else:
                self.mode2.add_motion(sign * dc, var_dc)                            # (5-6)
        k = self.options.stuck_confidence_sigmas
        self._t_max = t_a + t_nominal + k * sd_t                                    # (5-11)
        self._samples_since_launch = 0
        if not fused:
            self.friction.propagate(moving, self.params.sigma5_sq)                  # (5-15)
        self._pending = _Cycle(t_a, x1_a, var_x1_a, sign, dtu, self.schedule.size, dc,
                               np.array(pred.H_b, dtype=float), pred.peak_torque, moving, overshoot,
                               noise_var, spread)
        if self.schedule.size in (STARTUP_RAISE, STARTUP_SETTLE):
            self.counts["startup_cycles"] += 1
        self.schedule.launched(dtu)
        self.counts["pulses"] += 1
        self.counts["overshoot_corrections"] += int(overshoot)
        if pred.t_off is not None:                     # braking pair: +u for Δt_u, −u to t_off, off
            self.counts["braked_pulses"] += 1
            level = sign * self.params.u_max
            segs = [(offset, level), (offset + dtu, -level), (offset + pred.t_off, 0.0)]
            if offset > 0:
                segs.insert(0, (0.0, 0.0))
            return DriveCommand(segs, DriveType.BRIDGE)
        return DriveCommand.pulse(offset, dtu, sign * self.params.u_max)

    def _pulse_noise(self, pred: PulsePrediction, dtu: float) -> tuple[float, float]:
        """(bias, variance) of |Δc| from w2 for the pulse ``pred`` [rad, rad²], memoised."""
        key = (self.friction.ks, self.friction.kc, dtu, pred.t_off)
        hit = self._noise_memo.get(key)
        if hit is None:
            ks = min(self.friction.ks, pred.peak_torque * (1.0 - 1e-6))
            noise = pulse_noise if pred.t_off is None else braked_pulse_noise
            n = noise(self.params, ks, min(self.friction.kc, ks), dtu, pred.t_breakaway,
                      pred.t_current_zero, pred.t_nominal)
            hit = (n.bias, n.variance)
            if len(self._noise_memo) > 512:
                self._noise_memo.clear()
            self._noise_memo[key] = hit
        return hit

    def _pulse_bias(self, pred: PulsePrediction, dtu: float) -> float:
        """``self._pulse_noise(pred, dtu)[0]``, from the memo or by the mean-only solve."""
        hit = self._noise_memo.get((self.friction.ks, self.friction.kc, dtu, pred.t_off))
        if hit is not None:
            return hit[0]
        if self.joint is not None and self._idle is not None:
            s, c = self._idle.state, _idle.J_LAST       # the compiled step's plan of this sample
            if s[c + _idle.C_VALID] != 0.0 and s[c + _idle.C_BIAS_OK] != 0.0 and s[c + _idle.C_R0] == 0.0:
                brake, margin = self.predictor._brake_args()[:2]
                if s[c + _idle.C_KS:c + _idle.C_PEAK + 1].tolist() == [
                        self.friction.ks, self.friction.kc, dtu, brake, margin if brake else -1.0, pred.peak_torque]:
                    return float(s[c + _idle.C_BIAS])     # the same key: the same solve's result
        ks = min(self.friction.ks, pred.peak_torque * (1.0 - 1e-6))
        return pulse_bias(self.params, ks, min(self.friction.kc, ks), dtu, pred.t_breakaway,
                          pred.t_current_zero, pred.t_nominal, braked=pred.t_off is not None)

    def _noise_ratios(self, dtu: float, pred: PulsePrediction | None = None) -> tuple[float, float]:
        """(VAR/f, bias/√f) of the w2 moments at the point estimate, f = α²σ2²T_m³/3; the grid
        scales them to every lattice point. Defaults 2.5 and 0.8 (the middle of the ranges
        measured in issue 13) when the point estimate predicts no motion."""
        if not self.options.noise_aware_model:
            return 0.0, 0.0
        if pred is None:
            pred = self.predictor.conditional(self.friction.ks, self.friction.kc, dtu)
        p = self.params
        T = pred.t_nominal - pred.t_breakaway if pred.t_breakaway is not None else 0.0
        f = p.alpha**2 * p.sigma2_sq * T**3 / 3.0
        if not f > 0:
            return 2.5, 0.8
        bias, var = self._pulse_noise(pred, dtu)
        # clipped to the ranges the derivation gives away from degenerate pulses (issue 13:
        # 1.3–3.7 and 0.6–1.0); a pulse that barely breaks away has T_m → 0 and 0/0 ratios
        return min(max(var / f, 0.0), 4.0), min(max(bias / math.sqrt(f), 0.0), 1.2)

    def _grid_predictive(self, dtu: float, pred: PulsePrediction | None = None) -> Predictive | None:
        """The grid posterior's predictive of a pulse of ``dtu`` (None without the grid or
        without motion mass), memoised until the next grid update."""
        if self.grid is None:
            return None
        key = (self.grid.version, len(self.grid.obs))
        if key != self._grid_key:
            self._grid_memo.clear()
            self._grid_key = key
        gp = self._grid_memo.get(dtu)
        if gp is None:
            gp = self._grid_memo[dtu] = self.grid.predictive(dtu, *self._noise_ratios(dtu, pred))
        return gp if gp.p_motion > 0 else None

    def _evaluate(self, t_b: float) -> None:
        c, self._pending = self._pending, None
        x1_b, x4_b = self.mode2.x1, self.mode2.x4
        dt = t_b - c.t_a
        dc_e = x1_b - c.x1_a + x4_b * dt                                            # (5-13)
        if self.joint is not None:
            # confidence that the pulse moved the shaft: the posterior of d (prior × samples)
            dc_e, var_e = self.joint.motion_mean, self.joint.motion_var
        elif self.options.dce_variance == "exact":
            var_e = self.mode2.motion_variance(t_b)                                 # (5-14)
        else:
            P = self.mode2.P
            var_e = P[0, 0] + c.var_x1_a + 2.0 * P[0, 1] * dt + P[1, 1] * dt**2    # (5-14)
        var_meas = var_e
        dc_meas = dc_e
        if self.options.dc_measurement == "data-only" and self.joint is None:
            # significance from the posterior of d; the k̂ update from the samples alone
            dc_e, var_e = self.mode2.motion_mean, self.mode2.motion_var
            dc_meas, var_meas = self.mode2.motion_likelihood()
        if self.options.noise_aware_model:
            var_meas += c.noise_var                         # the friction filter's R
        elif self.options.friction_noise_in_filter:
            p = self.params
            var_meas += p.alpha**2 * p.sigma2_sq * c.moving_time**3 / 3.0
        sd = math.sqrt(max(var_e, 1e-300))
        z = c.sign * dc_e / sd if math.isfinite(sd) else 0.0
        significant = z >= self.z_motion
        decision = "moved" if significant else "none"
        if not significant and self.options.motion_decision == "three-way":
            # "no motion" only if the test could have seen the predicted motion: power of the
            # one-sided test against Δc_p; otherwise undecided (keep the schedule, no k̂ update)
            # Δc itself is uncertain (k̂ spread H P_b H', w2 scatter): marginal power
            var_k = c.spread_var if self.grid is not None else self.friction.motion_variance(c.H_b)
            spread = math.sqrt(sd * sd + var_k + c.noise_var)
            power = _STD_NORMAL.cdf((c.delta_c - self.z_motion * sd) / spread)
            if power < self.options.no_motion_power:
                self._undecided += 1
                # past the bound: fall back to the start-up sizes, but this is no evidence
                decision = ("undecided" if self._undecided <= self.options.max_undecided_cycles
                            else "fallback")
        if decision != "undecided":
            self._undecided = 0
        self.counts["cycles_evaluated"] += 1
        self.counts["undecided_cycles"] += int(decision == "undecided")
        entry = dict(t_a=c.t_a, t_b=t_b, x1_a=c.x1_a, size=float(c.size), dt_u=c.dt_u, sign=float(c.sign),
                     dc_p=c.delta_c, dc_e=c.sign * dc_e, sd_e=sd, significant=float(significant),
                     ks_before=self.friction.ks, kc_before=self.friction.kc)
        if significant:
            self.counts["significant_cycles"] += 1
        if self.joint is not None:
            # normalised innovation of Δc: the samples' evidence against the prediction
            prior_mean, prior_var = self.joint.motion_prior
            m, R = self.joint.motion_likelihood()
            if math.isfinite(R):
                nis = (m - prior_mean) ** 2 / (R + prior_var)
                self._nis.append(nis)
                entry["nis"] = nis
            if self.grid is not None:
                # every cycle, whatever the decision: the exact likelihood of its evidence
                self.grid.update(c.dt_u, c.sign, m, R, *self._noise_ratios(c.dt_u))
                self.counts["friction_updates"] += int(math.isfinite(R))
                if decision == "none":
                    self.joint.no_motion(c.peak_torque, censor=False)
                self.joint.set_friction(self.grid.mean, self.grid.cov)
                n_sets = self.options.grid_handover_sets
                if n_sets and self.counts["cost_evaluations"] >= n_sets:
                    # hand over: the joint EKF goes on from the grid's moments, k correlated
                    # again with (x1, x4, d) through the quasipartials of each pulse
                    self.joint.set_friction(self.grid.mean, self.grid.cov * self.options.grid_handover_inflation)
                    self.grid = None
                    self.predictor.brake_margin = self._brake_margin
                    self.counts["grid_handover_cycle"] = self.counts["cycles_evaluated"]
            elif decision == "moved":
                self.joint.moved(c.peak_torque)
                self.counts["friction_updates"] += 1
            elif decision == "none":
                # d = 0, then (censored_no_motion) k_s ≥ peak torque
                self.joint.no_motion(c.peak_torque, censor=self.options.censored_no_motion)
        elif significant and math.isfinite(var_meas):
            residual = c.sign * dc_meas - c.delta_c
            upd = self.friction.update(c.H_b, residual, var_meas, c.peak_torque)
            self._nis.append(residual**2 / upd.innovation_var)
            entry["nis"] = residual**2 / upd.innovation_var
            self.counts["friction_updates"] += 1
            self.counts["shrinks"] += upd.shrinks
            self.counts["clipped_updates"] += int(upd.clipped)
        elif decision == "none" and self.options.censored_no_motion:
            # (a powerful test saw nothing; the fallback after undecided cycles is not evidence)
            # no breakaway: censored evidence k_s ≥ peak torque, on the distribution
            self.friction.condition(np.array([0.0, -1.0]), -c.peak_torque)
        entry.update(ks=self.friction.ks, kc=self.friction.kc, decision=decision)
        self.log.append(entry)
        if decision == "undecided":
            self.schedule.undecided(c.size, c.dt_u)
        else:
            self.schedule.evaluated(significant, c.size, c.dt_u)
        if self.schedule.set_complete:
            self._reoptimise()

    def _reoptimise(self) -> None:
        """Costs of the three sizes with the current estimates (6-1)–(6-5); (6-10), (6-9)."""
        sch, o, p = self.schedule, self.options, self.params
        x4 = self.mode2.x4
        costs, motions = [], []
        for size in (SMALL, MEDIUM, LARGE):
            dtu = sch.normal_dtu(size)
            if dtu <= 0:
                costs.append(math.inf)
                motions.append(0.0)
                continue
            dtu = min(dtu, self.dtu_max)
            pred = self.predictor.predict(self.friction.ks, self.friction.kc, dtu)
            dc, noise_var = abs(pred.delta_c), 0.0
            gp = self._grid_predictive(dtu, pred)
            if gp is not None:
                # the size does not move the shaft unless the posterior says it probably does
                dc = gp.dc_mean if gp.p_motion >= 0.5 else 0.0
                if dc == 0.0:
                    costs.append(math.inf)
                    motions.append(0.0)
                    continue
                noise_var = gp.dc_var                       # w2 and the posterior spread
            elif o.noise_aware_model and dc > 0:
                bias, noise_var = self._pulse_noise(pred, dtu)
                dc += bias                                  # E[Δc] in (6-1), (6-3)
            var_dc = var_x1 = 0.0
            if o.cost_variances:
                var_dc = noise_var + (self.friction.motion_variance(pred.H_b) if gp is None else 0.0)
                var_x1 = self.mode2.p11
            costs.append(cycle_cost(dtu, dc, x4, o.a_c, p, var_dc, var_x1).total)
            motions.append(dc)
        ratio = motions[2] / motions[0] if motions[0] > 0 else math.inf
        self._costs = tuple(costs)
        self._dc_ratio = ratio
        sch.reoptimise(*costs, ratio, o.a_gain, o.a_ratio, o.min_inc_factor)
        self.counts["cost_evaluations"] += 1

    # ------------------------------------------------------------------ reporting
    def internals(self) -> dict[str, float]:
        if not self._ready:
            return {}
        if self._idle is not None:
            self._import_idle()
        P = self.friction.P
        sch = self.schedule
        return {
            "ks_hat": self.friction.ks, "kc_hat": self.friction.kc,
            "P_kc_kc": float(P[0, 0]), "P_ks_ks": float(P[1, 1]), "P_kc_ks": float(P[0, 1]),
            "dtu_opt": sch.dtu_opt,
            "dtu_inc": sch.dtu_inc,
            "cost_small": self._costs[0], "cost_medium": self._costs[1], "cost_large": self._costs[2],
            "dc_ratio": self._dc_ratio, "cycle_size": float(sch.size),
            "x1_hat": float(self.mode2.x[0]), "x4_hat": float(self.mode2.x[1]),
            # for the report's figures (protocol v2 series)
            "ks_kc_corr": float(P[0, 1] / math.sqrt(P[0, 0] * P[1, 1])) if P[0, 0] * P[1, 1] > 0 else _NAN,
            "dt_opt_rel_error": (abs(sch.dtu_opt - self.adjusted[0]) / self.adjusted[0]
                                 if self.adjusted[0] > 0 else _NAN),
            "n_cost_updates": float(self.counts["cost_evaluations"]),
            # the mode-2 filter at the sample instant (before any pulse of this step), for NEES
            "m2_x1": self._posterior[0], "m2_x4": self._posterior[1], "m2_P11": self._posterior[2],
            "m2_P14": self._posterior[3], "m2_P44": self._posterior[4],
        }

    def event_times(self) -> dict[str, np.ndarray]:
        """``pulse`` and ``phase:<size>`` launch instants [s] (:mod:`controllers.solnic.series`)."""
        if not self._ready:
            return {}
        if self._idle is not None:
            self._import_idle()
        cycles = [(e["t_a"], int(e["size"])) for e in self.log]
        if self._pending is not None:
            cycles.append((self._pending.t_a, int(self._pending.size)))
        return cycle_event_times(cycles)

    def report_series(self, t: np.ndarray, warmup_s: float) -> dict[str, np.ndarray]:
        """Δc of the last large cycle and the last Δc_e/Δc_p mismatch, held on ``t``."""
        if self._ready and self._idle is not None:
            self._import_idle()                         # the compiled cycles' log entries
        return log_series(self.log if self._ready else [], t)

    def summary(self) -> dict[str, Any]:
        if not self._ready:
            return {"preset": self.preset, "a_c": self.options.a_c}
        if self._idle is not None:
            self._import_idle()
        out: dict[str, Any] = {
            "preset": self.preset, "a_c": self.options.a_c,
            "ks_hat": self.friction.ks, "kc_hat": self.friction.kc,
            "P_kc_kc": float(self.friction.P[0, 0]), "P_ks_ks": float(self.friction.P[1, 1]),
            "P_kc_ks": float(self.friction.P[0, 1]),
            "dtu_opt": self.schedule.dtu_opt, "dtu_inc": self.schedule.dtu_inc,
            "dtu_opt_adjusted": self.adjusted[0], "dtu_inc_adjusted": self.adjusted[1],
            "x4_hat": float(self.mode2.x[1]), "model_runs": self.predictor.n_model_runs,
        }
        out.update(self.counts)
        out["dc_nis_mean"] = float(np.mean(self._nis)) if self._nis else _NAN
        return out
