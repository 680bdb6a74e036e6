"""Noisy work-precision: the weak error of Euler–Maruyama against the exact simulator (issue #10).

The dissertation's speed claim is about simulating the *noisy* plant. With noise, two methods
cannot be compared path by path (each draws its own noise); they are compared by the
statistics of what a controller cares about: the motion Δc of one switched-bridge pulse
(Δt_u = 1.2 ms, Table 2-1 noise, from rest with x4 = 0).

* **Exact**: ``n_paths`` noisy :func:`plant.pulse_response` draws (seeds 0 … n−1).
* **Euler–Maruyama** (the default family's ``fixed_step_pulses``, compiled, same mode logic) at
  several step sizes h, ``n_paths`` paths each.

For each statistic — the mean of Δc and its 95th percentile — the weak error of EM at h is
(EM statistic − exact statistic), reported with a 95 % Monte-Carlo confidence interval: the
standard errors of two independent samples combined (for the mean, s/√n; for the percentile,
the asymptotic √(q(1−q)/n)/f̂(x_q), f̂ a Gaussian-kernel density at the quantile). An error is
*resolved* at h when its CI excludes 0.

The cost of equal error: the target is the half-width of the exact estimate's CI (what n
exact paths can tell apart). The EM step that reaches it is the coarsest h whose CI contains 0
and whose error lies within the target, and ``cost_ratio`` is EM's wall time per path at that
h over the exact simulator's. If no measured h gets there, the ratio is a lower bound from the
finest step (flagged).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from plant import PlantParams, pulse_response
from bench.exact import EXACT_METHOD, fixed_step_pulses

__all__ = ["WeakErrorConfig", "weak_error_comparison", "QUICK_WEAK", "FULL_WEAK"]

_Z95 = 1.959963984540054


@dataclass(frozen=True)
class WeakErrorConfig:
    """``dt_u`` pulse width [s]; ``n_paths`` per method; EM ``steps`` [s], coarse to fine."""

    dt_u: float = 1.2e-3
    n_paths: int = 4000
    steps: tuple[float, ...] = (1e-5, 3e-6, 1e-6, 3e-7, 1e-7)


QUICK_WEAK = WeakErrorConfig(n_paths=1500, steps=(1e-5, 1e-6))
FULL_WEAK = WeakErrorConfig()


def _stat(x: np.ndarray, which: str) -> tuple[float, float]:
    """(statistic, standard error) of a sample: ``mean`` or ``p95``."""
    n = x.size
    if which == "mean":
        return float(x.mean()), float(x.std(ddof=1) / math.sqrt(n))
    q = 0.95
    value = float(np.quantile(x, q))
    density = float(stats.gaussian_kde(x)(value)[0])
    return value, math.sqrt(q * (1 - q) / n) / density


def weak_error_comparison(params: PlantParams | None = None, config: WeakErrorConfig = FULL_WEAK,
                          seed: int = 0) -> dict[str, Any]:
    """Run the comparison (module docstring); JSON-ready."""
    p = params or PlantParams()
    cfg = config
    pulse_response(p, cfg.dt_u, seed=10**9)                    # compile outside the timing
    fixed_step_pulses(p, cfg.dt_u, 1e-5, 4, seed=10**9)
    t0 = time.perf_counter()
    exact = np.array([pulse_response(p, cfg.dt_u, seed=seed + k).delta_c for k in range(cfg.n_paths)])
    exact_wall = (time.perf_counter() - t0) / cfg.n_paths
    ref = {w: _stat(exact, w) for w in ("mean", "p95")}
    rows = [{"method": EXACT_METHOD, "step_s": None, "wall_per_path_s": exact_wall,
             **{f"{w}_rad": ref[w][0] for w in ref}, **{f"{w}_se_rad": ref[w][1] for w in ref}}]
    for h in cfg.steps:
        t0 = time.perf_counter()
        em = fixed_step_pulses(p, cfg.dt_u, h, cfg.n_paths, seed=seed + 7919)
        wall = (time.perf_counter() - t0) / cfg.n_paths
        row: dict[str, Any] = {"method": "euler_maruyama", "step_s": h, "wall_per_path_s": wall}
        for w in ("mean", "p95"):
            value, se = _stat(em, w)
            err = value - ref[w][0]
            half = _Z95 * math.hypot(se, ref[w][1])
            row.update({f"{w}_rad": value, f"{w}_se_rad": se, f"{w}_error_rad": err,
                        f"{w}_error_ci_rad": [err - half, err + half], f"{w}_error_resolved": abs(err) > half})
        rows.append(row)
    equal = {}
    for w in ("mean", "p95"):
        target = _Z95 * ref[w][1]
        ok = [r for r in rows[1:] if not r[f"{w}_error_resolved"] and abs(r[f"{w}_error_rad"]) <= target]
        if ok:
            r = ok[0]
            equal[w] = {"target_rad": target, "step_s": r["step_s"], "cost_ratio": r["wall_per_path_s"] / exact_wall,
                        "lower_bound": False}
        else:
            r = rows[-1]
            equal[w] = {"target_rad": target, "step_s": None, "cost_ratio": r["wall_per_path_s"] / exact_wall,
                        "lower_bound": True}
    return {"dt_u_s": cfg.dt_u, "n_paths": cfg.n_paths, "rows": rows, "equal_error": equal,
            "method": ("weak error of the mean and the 95th percentile of Δc with 95 % Monte-Carlo CIs "
                       "(independent samples; percentile SE from the asymptotic order-statistic variance)")}
