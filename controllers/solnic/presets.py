"""Named option sets of the solnic controller, and the validation of its options.

``thesis`` (the default) reproduces section 7.3: a_c calibrated so that, with the true
parameters and no noise, the optimal medium correction has a peak error of 1.4 µrad (the
medium figure of section 7.3); initial k̂s, k̂c at half their true values, Δt_u,inc four times
its properly adjusted value, Δt_u,opt = 0, x̂1 = x̂4 = 0.

``high-error-cost`` charges more for error and less for control effort (section 7.3, last
paragraph): a_c calibrated for a peak error of one tenth of the classical limit (2-6),
0.1 × 7.09 µrad = 0.709 µrad.

The a_c numbers come from :func:`controllers.solnic.cost.calibrate_error_cost` on Table 2-1
(``PlantParams()``), x4 = 30 µrad/s; ``tests/test_solnic_cost.py`` recomputes them.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["PRESETS", "DEFAULTS", "resolve_options"]

# calibrate_error_cost(PlantParams(), target_peak=1.4e-6).a_c: Δt_u,opt = 1.35859 ms,
# Δc = 2.800 µrad, properly adjusted Δt_u,inc = 80.71 µs (Δc 1.94/2.80/3.88 µrad).
A_C_THESIS = 1.8012e-4            # rad per ozf·in
# calibrate_error_cost(PlantParams(), target_peak=0.1 * PlantParams().classical_bound()).a_c:
# Δt_u,opt = 1.21645 ms, Δc = 1.418 µrad, Δt_u,inc = 63.85 µs.
A_C_HIGH_ERROR_COST = 5.4243e-5   # rad per ozf·in

DEFAULTS: dict[str, Any] = {
    "a_c": A_C_THESIS,                 # error/effort cost ratio of (6-4) [rad per ozf·in]
    "a_cov": 0.5,                      # covariance-reduction weight a of (5-18)
    "a_gain": 0.3,                     # (6-9)
    "a_ratio": 2.0,                    # (6-9)
    "min_inc_factor": 0.5,             # lower clip of the (6-9) factor
    "initial_friction_factor": 0.5,    # k̂s, k̂c start at this × k̄s, k̄c (section 7.3)
    "friction_prior_std_fraction": 1.0,  # std of the initial k̂ errors, × the initial k̂
    "initial_increment_factor": 4.0,   # Δt_u,inc starts at this × the adjusted increment
    "dtu_inc_initial": None,           # or an explicit initial Δt_u,inc [s]
    "dtu_opt_initial": 0.0,            # [s] (section 7.3)
    "x1_prior_std": 1e-4,              # [rad], diffuse
    "x4_prior_std": 72.7e-6,           # [rad/s], 15 deg/h, the largest rate of section 2.1
    "stuck_confidence_sigmas": 3.0,    # t_max = t_nominal + 3σ (5-11): confidence 0.9987
    "motion_confidence": 0.98,         # update k̂ only if confidence Δc ≠ 0 ≥ 0.98
    "overshoot_factor": 1.5,           # overshoot errors corrected only beyond 1.5·Δc_p
    "max_correction_fraction": 0.25,   # limit on one k̂ correction, × k̂s (fictitious variance)
    "fd_step": 1e-4,                   # quasipartial step [ozf·in]
    "dce_variance": "exact",           # (5-14): "exact" or "independent" (see controller)
    # improvements over the text, off by default:
    "dc_measurement": "faithful",      # or "data-only": k̂ updated from the samples' evidence only
    "friction_noise_in_filter": False,  # add the w2 spread of Δc to VAR[Δc_e] in (5-16)
    "cost_variances": False,           # keep VAR(Δc_p) + VAR[x̂1] in C1 (6-1)
}

PRESETS: dict[str, dict[str, Any]] = {
    "thesis": {},
    "high-error-cost": {"a_c": A_C_HIGH_ERROR_COST},
}

_POSITIVE = {"a_c", "a_ratio", "initial_friction_factor", "friction_prior_std_fraction",
             "initial_increment_factor", "x1_prior_std", "x4_prior_std",
             "stuck_confidence_sigmas", "max_correction_fraction", "fd_step", "overshoot_factor"}
_UNIT = {"a_cov", "a_gain", "min_inc_factor"}   # in (0, 1]
_BOOL = {"friction_noise_in_filter", "cost_variances"}


def resolve_options(preset: str = "thesis", **options: Any) -> dict[str, Any]:
    """Defaults ← preset ← explicit options, validated; ``ValueError`` names the option."""
    if preset not in PRESETS:
        raise ValueError(f"preset must be one of {sorted(PRESETS)}, got {preset!r}")
    unknown = sorted(set(options) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"unknown solnic option {unknown[0]!r}; options are {sorted(DEFAULTS)}")
    out = dict(DEFAULTS)
    out.update(PRESETS[preset])
    out.update(options)
    if out["dce_variance"] not in ("exact", "independent"):
        raise ValueError(f"option dce_variance must be 'exact' or 'independent', got {out['dce_variance']!r}")
    if out["dc_measurement"] not in ("faithful", "data-only"):
        raise ValueError(f"option dc_measurement must be 'faithful' or 'data-only', got {out['dc_measurement']!r}")
    for name, value in out.items():
        if name in ("dce_variance", "dc_measurement"):
            continue
        if name in _BOOL:
            if not isinstance(value, bool):
                raise ValueError(f"option {name} must be a bool, got {value!r}")
            continue
        if value is None and name == "dtu_inc_initial":
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"option {name} must be a finite number, got {value!r}")
        out[name] = float(value)
        if name in _POSITIVE and not value > 0:
            raise ValueError(f"option {name} must be > 0, got {value!r}")
        if name in _UNIT and not 0 < value <= 1:
            raise ValueError(f"option {name} must be in (0, 1], got {value!r}")
    if not 0.5 < out["motion_confidence"] < 1:
        raise ValueError(f"option motion_confidence must be in (0.5, 1), got {out['motion_confidence']!r}")
    if out["dtu_opt_initial"] < 0:
        raise ValueError(f"option dtu_opt_initial must be >= 0, got {out['dtu_opt_initial']!r}")
    if out["dtu_inc_initial"] is not None and not out["dtu_inc_initial"] > 0:
        raise ValueError(f"option dtu_inc_initial must be > 0, got {out['dtu_inc_initial']!r}")
    out["preset"] = preset
    return out
