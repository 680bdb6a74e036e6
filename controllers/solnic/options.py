"""Options of the solnic controller: one frozen dataclass, its presets and its tuning knob.

``SolnicOptions()`` is faithful to the text (chapters 5–7, section 7.3). Every improvement on
the text is a flag that is off by default; the registered variant ``solnic-modern`` turns on
the combination that measured best (see :mod:`controllers.solnic.modern`).

Presets (built with :func:`dataclasses.replace` of the defaults):

``thesis`` (the default)
    Section 7.3: a_c calibrated so that, with the true parameters and no noise, the optimal
    medium correction has a peak error of 1.4 µrad (the medium figure of section 7.3); k̂s, k̂c
    start at half their true values, Δt_u,inc at four times its properly adjusted value,
    Δt_u,opt = 0, x̂1 = x̂4 = 0.
``high-error-cost``
    Section 7.3, last paragraph: a_c calibrated for a peak error of one tenth of the classical
    limit (2-6), 0.1 × 7.09 µrad = 0.709 µrad.

The a_c numbers come from :func:`controllers.solnic.cost.calibrate_error_cost` on Table 2-1
(``PlantParams()``), x4 = 30 µrad/s; ``tests/test_solnic_cost.py`` recomputes them.
"""

from __future__ import annotations

import dataclasses
import math
import types
from dataclasses import dataclass
from typing import Literal

__all__ = ["SolnicOptions", "PRESETS", "KNOBS", "A_C_THESIS", "A_C_HIGH_ERROR_COST"]

# calibrate_error_cost(PlantParams(), target_peak=1.4e-6).a_c: Δt_u,opt = 1.35859 ms,
# Δc = 2.800 µrad, properly adjusted Δt_u,inc = 80.71 µs (Δc 1.94/2.80/3.88 µrad).
A_C_THESIS = 1.8012e-4            # rad per ozf·in
# calibrate_error_cost(PlantParams(), target_peak=0.1 * PlantParams().classical_bound()).a_c:
# Δt_u,opt = 1.21645 ms, Δc = 1.418 µrad, Δt_u,inc = 63.85 µs.
A_C_HIGH_ERROR_COST = 5.4243e-5   # rad per ozf·in


def _bad(field: str, rule: str, value: object) -> ValueError:
    return ValueError(f"option {field!r} of 'solnic' must be {rule}, got {value!r}")


@dataclass(frozen=True)
class SolnicOptions:
    """Options of :class:`~controllers.solnic.controller.SolnicController`.

    Faithful to the text
    --------------------
    a_c : float
        Error/effort cost ratio of (6-4) [rad per ozf·in]; > 0.
    a_cov : float
        Covariance-reduction weight a of (5-18); in (0, 1], 0.5 in the text.
    a_gain, a_ratio : float
        Gain and target Δc ratio of the increment update (6-9); 0.3 and 2.
    min_inc_factor : float
        Lower clip of the (6-9) factor; in (0, 1] (the text: "converged as long as Δt_u,inc > 0").
    initial_friction_factor : float
        k̂s, k̂c start at this × k̄s, k̄c (section 7.3: 0.5).
    friction_prior_std_fraction : float
        Std of the initial k̂ errors, × the initial k̂ (the text gives no P_b(0)).
    initial_increment_factor : float
        Δt_u,inc starts at this × the properly adjusted increment (section 7.3: 4).
    dtu_inc_initial : float or None
        An explicit initial Δt_u,inc [s] instead of the factor.
    dtu_opt_initial : float
        Initial Δt_u,opt [s] (section 7.3: 0); ≥ 0.
    x1_prior_std, x4_prior_std : float
        Prior stds of x̂1 [rad] (diffuse) and x̂4 [rad/s] (15 deg/h, section 2.1).
    stuck_confidence_sigmas : float
        t_max = t_nominal + this·σ_t (5-11): 3 gives confidence 0.9987.
    motion_confidence : float
        Update k̂ only if confidence that Δc ≠ 0 is at least this; in (0.5, 1), 0.98.
    overshoot_factor : float
        Overshoot errors are corrected only beyond this × Δc_p (section 7.2: 1.5).
    max_correction_fraction : float
        Limit on one k̂ correction, × k̂s, via a fictitious variance (section 5.3).
    fd_step : float
        Step of the quasipartials (5-2), (5-12) [ozf·in].
    dce_variance : {"exact", "independent"}
        Reading of the garbled (5-14); see :mod:`controllers.solnic.controller`.

    Improvements, off by default
    ----------------------------
    evaluation_samples : int
        A cycle whose outcome decides the next size (the last of a set of twelve, a start-up
        cycle) is evaluated once this many samples past t_max are in, so the next trigger is
        planned with the new size (the set-boundary fix; the text does not say when); ≥ 1.
    legacy_set_boundary : bool
        Reproduce the set-boundary bug that was fixed (the first trigger after a finished set
        computed with the stale large size). For regression tests only.
    dc_measurement : {"faithful", "data-only"}
        "data-only": the friction filter gets the samples' own evidence about Δc, the prior
        Δc_p divided out (no double use of the prediction).
    friction_noise_in_filter : bool
        Add the w2 spread of Δc, α²σ2²T_m³/3, to VAR[Δc_e] in (5-16).
    noise_aware_model : bool
        Δc_p carries the bias and variance of the friction noise over the moving time
        (:mod:`controllers.solnic.noise_model`), in (5-6), (5-9) and the friction filter's R.
    motion_decision : {"two-way", "three-way"}
        "three-way": moved / no motion (only when the data could have seen the predicted motion)
        / undecided (keep the schedule, skip the k̂ update).
    max_undecided_cycles : int
        With "three-way", this many undecided cycles in a row count as "no motion"; ≥ 1.
    no_motion_power : float
        With "three-way", "no motion" needs the 0.98 test to have had at least this power
        against the predicted motion Δc_p; in (0.5, 1).
    cost_variances : bool
        Keep VAR(Δc_p) + VAR[x̂1] in C1 (6-1).
    friction_constraints : {"clip", "distribution"}
        "clip" (the text, section 5.3): k̂s ≤ applied torque by shrinking its quasipartial, then
        k̂s ≥ k̂c by raising k̂s, P untouched. "distribution": each constraint conditions the
        Gaussian N(k̂, P_b) on the half-plane (moment-matched truncation), mean and P.
    friction_estimator : {"modified-kalman", "joint-ekf"}
        "modified-kalman": the text's two filters, (5-1)–(5-18). "joint-ekf": one Gaussian on
        (x1, x4, k_c, k_s, d) (:mod:`controllers.solnic.joint_filter`), the prediction used once,
        constraints and "no motion" on the distribution; ``dc_measurement``,
        ``friction_constraints``, ``a_cov`` and ``max_correction_fraction`` do not apply.
    joint_correction_limit : bool
        With "joint-ekf": limit large k̂ corrections by a fictitious variance of the motion d
        (``max_correction_fraction`` × k̂s for a residual of the whole Δc), section 5.3.
    friction_grid : bool
        With "joint-ekf": the friction posterior is a grid over (k_c, k_s) updated with each
        pulse's exact pulse-response likelihood (:mod:`controllers.solnic.grid_posterior`);
        "no motion" is its censored evidence, the constraints its support; the pulse's
        predicted Δc, its spread and t_max come from the posterior predictive, and the joint
        filter keeps (x1, x4, d) with the grid's moments as its k block. Tuning (seeds 0–4)
        in :mod:`controllers.solnic.modern`.
    grid_points : int
        Lattice points per axis of ``friction_grid``; ≥ 2 (64): the cell spread is a difference of neighbours.
    braking_pulse : bool
        Follow each forward pulse with a reverse drive (bridge, −sign·u_max) timed from the
        model to end the motion early (:mod:`controllers.solnic.braking`); the predictor's Δc,
        t_stop, quasipartials and current zero (hence t_max and the trigger) are the pair's.
        Not while ``friction_grid`` is still in charge (its likelihood is the single pulse's).
    brake_margin_sigmas : float
        With ``braking_pulse``: the noise-free velocity left at the end of the reverse current,
        in standard deviations of the w2 velocity spread; ≥ 0.75 (where the noise model's
        coasting formulas hold).
    brake_min_ratio : float
        With ``braking_pulse``: brake only pulses whose single version ends the flyback with a
        noise-free velocity of at least this many w2 velocity SDs (long coasts); ≥ 0.
    grid_memory : float
        With ``friction_grid``: the evidence of the pulse j cycles back counts e^(−j/memory)
        [pulses]; > 0, inf keeps all of it.
    grid_handover_sets : int
        With ``friction_grid``: after this many sets of twelve cycles (cost evaluations) the
        grid hands over to the joint EKF, which goes on from the grid's mean and covariance;
        0 keeps the grid for the whole run; ≥ 0.
    grid_handover_inflation : float
        The covariance handed over is the grid's × this; ≥ 1.
    grid_model_error : float
        With ``friction_grid``: a relative error of the predicted Δc added to the prior
        variance of the pulse's motion in the mode-2/joint filter, (this × Δc)²; ≥ 0.
    censored_no_motion : bool
        A "no motion" decision is censored evidence k_s ≥ the applied peak torque, applied as a
        half-plane condition on N(k̂, P_b).
    """

    a_c: float = A_C_THESIS
    a_cov: float = 0.5
    a_gain: float = 0.3
    a_ratio: float = 2.0
    min_inc_factor: float = 0.5
    initial_friction_factor: float = 0.5
    friction_prior_std_fraction: float = 1.0
    initial_increment_factor: float = 4.0
    dtu_inc_initial: float | None = None
    dtu_opt_initial: float = 0.0
    x1_prior_std: float = 1e-4
    x4_prior_std: float = 72.7e-6
    stuck_confidence_sigmas: float = 3.0
    motion_confidence: float = 0.98
    overshoot_factor: float = 1.5
    max_correction_fraction: float = 0.25
    fd_step: float = 1e-4
    dce_variance: Literal["exact", "independent"] = "exact"
    evaluation_samples: int = 3
    legacy_set_boundary: bool = False
    dc_measurement: Literal["faithful", "data-only"] = "faithful"
    friction_noise_in_filter: bool = False
    noise_aware_model: bool = False
    motion_decision: Literal["two-way", "three-way"] = "two-way"
    max_undecided_cycles: int = 3
    no_motion_power: float = 0.9
    cost_variances: bool = False
    friction_constraints: Literal["clip", "distribution"] = "clip"
    censored_no_motion: bool = False
    joint_correction_limit: bool = False
    friction_estimator: Literal["modified-kalman", "joint-ekf"] = "modified-kalman"
    friction_grid: bool = False
    grid_points: int = 64
    grid_memory: float = math.inf
    grid_model_error: float = 0.0
    grid_handover_sets: int = 0
    grid_handover_inflation: float = 1.0
    braking_pulse: bool = False
    brake_margin_sigmas: float = 0.75
    brake_min_ratio: float = 0.0

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.type in ("float", "float | None") and v is not None:
                if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or (
                        math.isinf(v) and not (f.name == "grid_memory" and v > 0)):
                    raise _bad(f.name, "a finite number" + (" or inf" if f.name == "grid_memory" else ""), v)
            if f.type == "bool" and not isinstance(v, bool):
                raise _bad(f.name, "true or false", v)
        for name in ("a_c", "a_ratio", "initial_friction_factor", "friction_prior_std_fraction",
                     "initial_increment_factor", "x1_prior_std", "x4_prior_std",
                     "stuck_confidence_sigmas", "max_correction_fraction", "fd_step",
                     "overshoot_factor", "grid_memory"):
            if not getattr(self, name) > 0:
                raise _bad(name, "> 0", getattr(self, name))
        for name in ("a_cov", "a_gain", "min_inc_factor"):
            if not 0 < getattr(self, name) <= 1:
                raise _bad(name, "in (0, 1]", getattr(self, name))
        for name in ("motion_confidence", "no_motion_power"):
            if not 0.5 < getattr(self, name) < 1:
                raise _bad(name, "in (0.5, 1)", getattr(self, name))
        if isinstance(self.grid_handover_sets, bool) or not isinstance(self.grid_handover_sets, int) \
                or self.grid_handover_sets < 0:
            raise _bad("grid_handover_sets", "an integer >= 0", self.grid_handover_sets)
        if not self.grid_handover_inflation >= 1:
            raise _bad("grid_handover_inflation", ">= 1", self.grid_handover_inflation)
        if not self.brake_margin_sigmas >= 0.75:
            raise _bad("brake_margin_sigmas", ">= 0.75", self.brake_margin_sigmas)
        if not self.brake_min_ratio >= 0:
            raise _bad("brake_min_ratio", ">= 0", self.brake_min_ratio)
        if not self.grid_model_error >= 0:
            raise _bad("grid_model_error", ">= 0", self.grid_model_error)
        if not self.dtu_opt_initial >= 0:
            raise _bad("dtu_opt_initial", ">= 0 [s]", self.dtu_opt_initial)
        if self.dtu_inc_initial is not None and not self.dtu_inc_initial > 0:
            raise _bad("dtu_inc_initial", "> 0 [s] or None", self.dtu_inc_initial)
        if self.dce_variance not in ("exact", "independent"):
            raise _bad("dce_variance", "'exact' or 'independent'", self.dce_variance)
        if self.dc_measurement not in ("faithful", "data-only"):
            raise _bad("dc_measurement", "'faithful' or 'data-only'", self.dc_measurement)
        if self.motion_decision not in ("two-way", "three-way"):
            raise _bad("motion_decision", "'two-way' or 'three-way'", self.motion_decision)
        if self.friction_constraints not in ("clip", "distribution"):
            raise _bad("friction_constraints", "'clip' or 'distribution'", self.friction_constraints)
        if self.friction_estimator not in ("modified-kalman", "joint-ekf"):
            raise _bad("friction_estimator", "'modified-kalman' or 'joint-ekf'", self.friction_estimator)
        if self.friction_grid and self.friction_estimator != "joint-ekf":
            raise _bad("friction_grid", "false unless friction_estimator is 'joint-ekf'", self.friction_grid)
        for name, least in (("evaluation_samples", 1), ("max_undecided_cycles", 1), ("grid_points", 2)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < least:
                raise _bad(name, f"an integer >= {least}", v)


_DEFAULT = SolnicOptions()
PRESETS = types.MappingProxyType({
    "thesis": _DEFAULT,
    "high-error-cost": dataclasses.replace(_DEFAULT, a_c=A_C_HIGH_ERROR_COST),
})

# a_c sweep [rad per ozf·in]: from the high-error-cost value toward a_c → 0 (error dominates,
# pulses shrink toward breakaway) up to twice the thesis value (effort dominates).
KNOBS = types.MappingProxyType({
    "a_c": (2e-6, 5e-6, 1e-5, 2e-5, A_C_HIGH_ERROR_COST, 1e-4, A_C_THESIS, 3.6e-4),
})
