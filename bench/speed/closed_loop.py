"""The closed-loop statistic with noise (issue 27 item 2): solnic's peak error over seeds with the
plant simulated exactly and by Euler–Maruyama at fixed steps.

A benchmark user depends on the distribution of a controller's score over seeds, not on one
pulse's Δc. Here the identification controller (:data:`controllers.roles.IDENTIFICATION`, its
registry defaults) runs closed loop on ``thesis`` (Table 2-1, with noise), once per seed with
the default family's exact step and once per seed and step h with the same plant stepped by
Euler–Maruyama (``fixed_step_family(h)`` of :mod:`bench.exact`: the same seam, the same
:class:`bench.runner.PlantLoop`, the same seeds).

**What is compared.** For each method, the peak error over the scoring window (``peak_error_rad``)
of ``n_seeds`` runs. A seed fixes the sensor noise, the controller's stream and x5(0) for every
method; the plant noise is read from the same stream but consumed differently (EM takes 3
normals per step), so the plant noise paths are *not* coupled and the samples are treated as
independent. Reported per method: median and 95th percentile with bootstrap 95 % CIs
(``scipy.stats.bootstrap``, percentile method); per EM step: the difference EM − exact of both
statistics with an unpaired two-sample bootstrap CI (the verdict's basis), and the seed-paired
CI of the median difference (valid too, as seeds are independent; tighter only if the shared
streams correlate the scores).

**Resolution.** With independent samples, a difference is resolved only when it exceeds the CI
half-width of the difference, roughly 2·1.25·σ/√n for a median (σ the spread of the peak
error over seeds): ``resolution_pct`` states it per step, in % of the exact statistic.
**Verdict** per h: "distinguishable" when either CI of the difference (median or p95) excludes 0,
else "not distinguishable at ±resolution".

**Cost.** CPU seconds (``time.process_time``) per cell, methods interleaved seed by seed in one
process, compilation excluded (every family runs once before the timing); ``cost_ratio`` is
EM's median CPU per cell over the exact one's.

**Noise-free check.** One noise-free cell per method: |peak_EM − peak_exact| / peak_exact, which
falls like O(h) (Euler's order) — the deterministic part of the difference.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

__all__ = ["ClosedLoopEMConfig", "closed_loop_em", "QUICK_CLOSED_LOOP", "FULL_CLOSED_LOOP"]

_SCENARIO = "thesis"


@dataclass(frozen=True)
class ClosedLoopEMConfig:
    """``steps`` EM steps [s], coarse to fine; ``n_seeds`` seeds 0…n−1 per method;
    ``duration_s`` and ``warmup_s`` of every cell [s]; ``n_resamples`` bootstrap resamples."""

    steps: tuple[float, ...] = (1e-4, 3e-5, 1e-5, 3e-6)
    n_seeds: int = 100
    duration_s: float = 100.0
    warmup_s: float = 20.0
    n_resamples: int = 2000

    def __post_init__(self) -> None:
        if not self.steps or any(not (0 < h <= 1e-3) for h in self.steps):
            raise ValueError(f"ClosedLoopEMConfig.steps must be steps in (0, 1e-3] s, got {self.steps!r}")
        if self.n_seeds < 5:
            raise ValueError(f"ClosedLoopEMConfig.n_seeds must be >= 5, got {self.n_seeds!r}")
        if not (0 <= self.warmup_s < self.duration_s and math.isfinite(self.duration_s)):
            raise ValueError(f"ClosedLoopEMConfig.warmup_s must be in [0, duration_s), got "
                             f"{self.warmup_s!r}, {self.duration_s!r}")
        if self.n_resamples < 100:
            raise ValueError(f"ClosedLoopEMConfig.n_resamples must be >= 100, got {self.n_resamples!r}")


QUICK_CLOSED_LOOP = ClosedLoopEMConfig(steps=(1e-4, 1e-5), n_seeds=20, duration_s=20.0, warmup_s=5.0,
                                       n_resamples=1000)
FULL_CLOSED_LOOP = ClosedLoopEMConfig()


def _median(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.median(x, axis=axis)


def _p95(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.quantile(x, 0.95, axis=axis)


def _ci(data: tuple[np.ndarray, ...], stat: Callable, rng: np.random.Generator, n: int,
        paired: bool = False) -> list[float]:
    """Bootstrap 95 % percentile interval of ``stat`` over ``data`` (one or two samples)."""
    from scipy.stats import bootstrap

    res = bootstrap(data, stat, n_resamples=n, confidence_level=0.95, method="percentile",
                    paired=paired, vectorized=True, random_state=rng)
    return [float(res.confidence_interval.low), float(res.confidence_interval.high)]


def _summary(x: np.ndarray, rng: np.random.Generator, n: int) -> dict[str, Any]:
    return {"median_rad": float(np.median(x)), "median_ci_rad": _ci((x,), _median, rng, n),
            "p95_rad": float(_p95(x)), "p95_ci_rad": _ci((x,), _p95, rng, n)}


def _cell(params: Any, controller_name: str, cfg: ClosedLoopEMConfig, seed: int, family: Any,
          noise: bool = True) -> tuple[float, float, str]:
    """(peak error [rad], CPU seconds, status) of one closed-loop cell."""
    from bench.runner import run_closed_loop
    from controllers import make_controller

    controller = make_controller(controller_name)
    t0 = time.process_time()
    res = run_closed_loop(params, controller, duration_s=cfg.duration_s, warmup_s=cfg.warmup_s, seed=seed,
                          noise=noise, family=family)
    return float(res.metrics["peak_error_rad"]), time.process_time() - t0, str(res.status)


def closed_loop_em(config: ClosedLoopEMConfig = FULL_CLOSED_LOOP, *,
                   progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Run the study (module docstring); JSON-ready (NaN where a statistic has no ok cells)."""
    from bench.exact import EXACT_METHOD, fixed_step_family
    from bench.scenarios import builtin_scenarios
    from controllers import roles
    from plant.protocol import get_family

    cfg = config
    say = progress or (lambda _msg: None)
    scenario = builtin_scenarios()[_SCENARIO]
    params, name = scenario.params, roles.IDENTIFICATION
    if scenario.family != EXACT_METHOD or scenario.model is not None or scenario.mismatch:
        raise RuntimeError(f"scenario {_SCENARIO!r} is no longer the default family's plant told the truth")
    exact_family = get_family(scenario.family)
    methods: list[tuple[str, float | None, Any]] = [(EXACT_METHOD, None, exact_family)]
    methods += [("euler_maruyama", h, fixed_step_family(h)) for h in cfg.steps]
    short = ClosedLoopEMConfig(cfg.steps, cfg.n_seeds, 10 * params.sample_period, 0.0, cfg.n_resamples)
    for _, _, fam in methods:                                   # compile outside the timing
        _cell(params, name, short, 10**6, fam)
    noise_free = [_cell(params, name, cfg, 0, fam, noise=False)[0] for _, _, fam in methods]

    peaks = np.full((len(methods), cfg.n_seeds), np.nan)
    cpu = np.full((len(methods), cfg.n_seeds), np.nan)
    statuses: list[list[str]] = [[] for _ in methods]
    for seed in range(cfg.n_seeds):
        if seed % 10 == 0:
            say(f"closed-loop EM: seed {seed}/{cfg.n_seeds}")
        for i, (_, _, fam) in enumerate(methods):
            peaks[i, seed], cpu[i, seed], status = _cell(params, name, cfg, seed, fam)
            statuses[i].append(status)

    rng = np.random.default_rng(np.random.SeedSequence(20271))
    exact = peaks[0][np.isfinite(peaks[0])]
    ref = _summary(exact, rng, cfg.n_resamples)
    exact_cpu = float(np.median(cpu[0]))
    rows: list[dict[str, Any]] = [{
        "method": EXACT_METHOD, "step_s": None, **ref, "cpu_per_cell_s": exact_cpu,
        "n_ok": int(exact.size), "noise_free_peak_rad": noise_free[0]}]
    for i, (label, h, fam) in enumerate(methods[1:], start=1):
        em = peaks[i][np.isfinite(peaks[i])]
        row: dict[str, Any] = {"method": label, "step_s": h,
                               "effective_step_s": fam.effective_step(params.sample_period),
                               **_summary(em, rng, cfg.n_resamples), "cpu_per_cell_s": float(np.median(cpu[i])),
                               "n_ok": int(em.size), "noise_free_peak_rad": noise_free[i],
                               "noise_free_rel_diff": abs(noise_free[i] - noise_free[0]) / noise_free[0]}
        row["cost_ratio"] = row["cpu_per_cell_s"] / exact_cpu
        distinct = False
        for w, stat in (("median", _median), ("p95", _p95)):
            diff = float(stat(em) - stat(exact))
            ci = _ci((em, exact), lambda a, b, axis=-1, s=stat: s(a, axis=axis) - s(b, axis=axis),
                     rng, cfg.n_resamples)
            half = (ci[1] - ci[0]) / 2
            ref_value = ref[f"{w}_rad"]
            resolved = not (ci[0] <= 0.0 <= ci[1])
            distinct = distinct or resolved
            row.update({f"{w}_diff_rad": diff, f"{w}_diff_ci_rad": ci, f"{w}_diff_pct": 100 * diff / ref_value,
                        f"{w}_resolution_pct": 100 * half / ref_value, f"{w}_resolved": resolved})
        both = np.isfinite(peaks[0]) & np.isfinite(peaks[i])
        row["median_diff_paired_ci_rad"] = _ci(
            (peaks[i][both], peaks[0][both]),
            lambda a, b, axis=-1: np.median(a, axis=axis) - np.median(b, axis=axis), rng, cfg.n_resamples,
            paired=True)
        row["seed_correlation"] = float(np.corrcoef(peaks[i][both], peaks[0][both])[0, 1])
        res = row["median_resolution_pct"]
        row["verdict"] = (f"distinguishable from exact (median {row['median_diff_pct']:+.3g} %, "
                          f"p95 {row['p95_diff_pct']:+.3g} %)" if distinct else
                          f"not distinguishable from exact at ±{res:.2g} % of the median "
                          f"(±{row['p95_resolution_pct']:.2g} % of the p95)")
        rows.append(row)
    return {
        "controller": name, "scenario": _SCENARIO, "n_seeds": cfg.n_seeds, "seeds": [0, cfg.n_seeds - 1],
        "duration_s": cfg.duration_s, "warmup_s": cfg.warmup_s, "rows": rows,
        "statuses": {(m if h is None else f"{m}(h={h:g})"): sorted(set(s)) for (m, h, _), s in zip(methods, statuses)},
        "peaks_rad": {(m if h is None else f"{m}(h={h:g})"): p.tolist() for (m, h, _), p in zip(methods, peaks)},
        "method": ("peak error over the scoring window, one cell per seed and method, same seeds; plant noise "
                   "paths not coupled, so the samples are compared as independent (two-sample percentile "
                   f"bootstrap, {cfg.n_resamples} resamples, 95 %); CPU per cell by time.process_time, methods "
                   "interleaved seed by seed, compilation excluded"),
    }
