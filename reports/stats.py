"""Statistics over seeds: medians with bootstrap confidence intervals, paired ratios, Pareto fronts.

Method (stated in the report and the README):

* **Median and its 95 % CI** — ``scipy.stats.bootstrap`` with the *percentile* method,
  :data:`N_RESAMPLES` resamples and a fixed ``random_state`` (:data:`SEED`), so a report is
  reproducible bit for bit. The percentile interval is used rather than BCa because BCa's
  acceleration is undefined for the median of small samples with ties (it returns NaN and warns);
  its coverage for the median at n ≥ 20 is checked in the tests by Monte-Carlo.
* **Paired ratio** of controller A to B on the same seeds — the geometric mean of the per-seed
  ratios a_i/b_i, exp(mean(log(a_i/b_i))), with a *BCa* bootstrap CI over seeds (resampling
  pairs, so the seed-to-seed correlation of A and B stays in), and the **probability of
  improvement** P(a < b), estimated as the share of seeds on which A is lower (ties count ½).
* **Pareto front** — the non-dominated points when both coordinates are to be minimised; a point
  is dominated when another is ≤ in both and < in at least one, so exact ties stay on the front.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

__all__ = ["N_RESAMPLES", "SEED", "CONFIDENCE", "MedianCI", "PairedRatio", "median_ci", "paired_ratio",
           "crossing_level", "crossing_ci",
           "pareto_front", "METHOD_TEXT"]

N_RESAMPLES = 2000
SEED = 20260514
CONFIDENCE = 0.95
METHOD_TEXT = (f"median with a {CONFIDENCE:.0%} bootstrap CI (scipy.stats.bootstrap, percentile method, "
               f"{N_RESAMPLES} resamples, random_state {SEED}); paired ratios: geometric mean of the "
               f"per-seed ratios with a BCa bootstrap CI over seed pairs; P(improvement) = share of "
               f"seeds on which the first is lower (ties ½)")


@dataclass(frozen=True)
class MedianCI:
    """A sample median with its bootstrap confidence interval [same unit as the data]."""

    median: float
    low: float
    high: float
    n: int


@dataclass(frozen=True)
class PairedRatio:
    """Geometric-mean ratio a/b over paired seeds, its CI, and P(a < b)."""

    ratio: float
    low: float
    high: float
    p_improvement: float
    n: int


def _finite(values) -> np.ndarray:
    a = np.asarray(values, dtype=float).ravel()
    return a[np.isfinite(a)]


def median_ci(values, *, confidence: float = CONFIDENCE, n_resamples: int = N_RESAMPLES,
              random_state: int = SEED) -> MedianCI:
    """Median of the finite ``values`` and its percentile-bootstrap CI.

    One value gives a degenerate interval; none gives NaNs.
    """
    from scipy.stats import bootstrap

    a = _finite(values)
    n = a.size
    if n == 0:
        return MedianCI(math.nan, math.nan, math.nan, 0)
    med = float(np.median(a))
    if n == 1 or np.all(a == a[0]):
        return MedianCI(med, med, med, n)
    res = bootstrap((a,), np.median, confidence_level=confidence, n_resamples=n_resamples,
                    method="percentile", random_state=np.random.default_rng(random_state), vectorized=True)
    ci = res.confidence_interval
    return MedianCI(med, float(ci.low), float(ci.high), n)


def paired_ratio(a, b, *, confidence: float = CONFIDENCE, n_resamples: int = N_RESAMPLES,
                 random_state: int = SEED) -> PairedRatio:
    """Ratio of ``a`` to ``b`` paired by position (same seeds), on pairs where both are > 0.

    Returns the geometric mean of a_i/b_i with a BCa bootstrap CI (percentile if BCa is
    undefined), and P(a < b) with ties counting ½.
    """
    from scipy.stats import bootstrap

    a = np.asarray(a, dtype=float).ravel()
    b = np.asarray(b, dtype=float).ravel()
    if a.shape != b.shape:
        raise ValueError(f"paired_ratio needs equal lengths, got {a.size} and {b.size}")
    keep = np.isfinite(a) & np.isfinite(b) & (a > 0) & (b > 0)
    a, b = a[keep], b[keep]
    n = a.size
    if n == 0:
        return PairedRatio(math.nan, math.nan, math.nan, math.nan, 0)
    logs = np.log(a / b)
    ratio = float(np.exp(logs.mean()))
    p = float(np.mean(a < b) + 0.5 * np.mean(a == b))
    if n == 1 or np.all(logs == logs[0]):
        return PairedRatio(ratio, ratio, ratio, p, n)
    lo = hi = math.nan
    for method in ("BCa", "percentile"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = bootstrap((logs,), np.mean, confidence_level=confidence, n_resamples=n_resamples,
                            method=method, random_state=np.random.default_rng(random_state), vectorized=True)
        lo, hi = res.confidence_interval
        if np.isfinite(lo) and np.isfinite(hi):
            break
    return PairedRatio(ratio, float(np.exp(lo)), float(np.exp(hi)), p, n)


def pareto_front(x, y) -> np.ndarray:
    """Indices of the non-dominated points of (x, y), both minimised, sorted by x then y.

    NaN points are never on the front. O(n log n): sort by (x, y) and keep a point when its y is
    below every y before it, or it ties exactly with the last kept point.
    """
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    if x.shape != y.shape:
        raise ValueError(f"pareto_front needs equal lengths, got {x.size} and {y.size}")
    idx = [i for i in np.lexsort((y, x)) if np.isfinite(x[i]) and np.isfinite(y[i])]
    front: list[int] = []
    best_y = math.inf
    for i in idx:
        if y[i] < best_y:
            front.append(int(i))
            best_y = y[i]
        elif front and x[i] == x[front[-1]] and y[i] == y[front[-1]]:
            front.append(int(i))          # an exact duplicate of a front point: neither dominates
    return np.asarray(front, dtype=int)


def crossing_level(levels, medians, threshold: float) -> float:
    """The level at which ``medians`` (one per increasing level) first reach ``threshold``.

    Linear interpolation between the last level below the threshold and the first at or above
    it. ``-inf`` when the first level is already at or above it (it never beats the threshold
    in the swept range), ``+inf`` when no level reaches it (it beats it everywhere swept).
    """
    x = np.asarray(levels, dtype=float)
    m = np.asarray(medians, dtype=float)
    above = np.flatnonzero(m >= threshold)
    if above.size == 0:
        return math.inf
    k = int(above[0])
    if k == 0:
        return -math.inf
    x0, x1, m0, m1 = x[k - 1], x[k], m[k - 1], m[k]
    return float(x0 + (threshold - m0) * (x1 - x0) / (m1 - m0)) if m1 != m0 else float(x1)


def crossing_ci(levels, values, threshold: float, *, confidence: float = CONFIDENCE,
                n_resamples: int = N_RESAMPLES, random_state: int = SEED) -> tuple[float, float, float]:
    """:func:`crossing_level` of the per-level medians of ``values`` [seed, level] and a
    percentile-bootstrap CI that resamples whole seeds (rows), keeping the pairing across levels.

    ``values`` [seed, level, point] crosses the *best* median over the points at each level
    (the best a controller reaches over its knob); the bootstrap takes that minimum in every
    resample. Rows with a NaN anywhere are dropped. Infinite crossings enter the percentiles
    as ±inf.
    """
    v = np.asarray(values, dtype=float)
    v = v[np.all(np.isfinite(v.reshape(v.shape[0], -1)), axis=1)]
    if v.shape[0] == 0:
        return math.nan, math.nan, math.nan

    def best(med: np.ndarray) -> np.ndarray:
        return med.min(axis=-1) if v.ndim == 3 else med

    point = crossing_level(levels, best(np.median(v, axis=0)), threshold)
    rng = np.random.default_rng(random_state)
    idx = rng.integers(0, v.shape[0], size=(n_resamples, v.shape[0]))
    meds = best(np.median(v[idx], axis=1))                    # [resample, level]
    boot = np.array([crossing_level(levels, row, threshold) for row in meds])
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(boot, [alpha, 1.0 - alpha], method="inverted_cdf")
    return point, float(lo), float(hi)
