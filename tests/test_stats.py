"""reports.stats against independent truth: bootstrap coverage by Monte-Carlo, Pareto by brute force."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from reports.stats import median_ci, paired_ratio, pareto_front


def test_median_ci_covers_the_true_median_in_at_least_93_percent_of_400_draws():
    # Exponential(1): true median ln 2. n = 20 (the frontier's seeds). Binomial sd of the coverage
    # estimate at 95 % is 1.1 %, so >= 93 % fails a correct 95 % interval with probability < 4 %.
    rng = np.random.default_rng(12345)
    truth = math.log(2.0)
    hits = 0
    widths = []
    for k in range(400):
        ci = median_ci(rng.exponential(1.0, 20), n_resamples=999, random_state=k)
        hits += ci.low <= truth <= ci.high
        widths.append(ci.high - ci.low)
        assert ci.low <= ci.median <= ci.high
    assert hits / 400 >= 0.93
    assert np.median(widths) < 1.0            # not a trivially wide interval


def test_median_ci_is_reproducible_and_handles_degenerate_samples():
    x = np.arange(25.0)
    assert median_ci(x) == median_ci(x)
    one = median_ci([3.0, math.nan])
    assert (one.median, one.low, one.high, one.n) == (3.0, 3.0, 3.0, 1)
    assert math.isnan(median_ci([]).median)


def test_paired_ratio_recovers_a_known_ratio_and_probability():
    rng = np.random.default_rng(7)
    b = rng.lognormal(0.0, 1.0, 30)
    exact = paired_ratio(0.5 * b, b)                  # every seed exactly halved
    assert exact.ratio == pytest.approx(0.5) and exact.low == pytest.approx(0.5)
    assert exact.p_improvement == 1.0
    # a/b lognormal(log 0.8, 0.1): coverage of the true ratio 0.8 over 200 draws
    hits = 0
    for k in range(200):
        bb = rng.lognormal(0.0, 1.0, 20)
        aa = bb * 0.8 * rng.lognormal(0.0, 0.1, 20)
        r = paired_ratio(aa, bb, n_resamples=999, random_state=k)
        hits += r.low <= 0.8 <= r.high
    assert hits / 200 >= 0.90
    tie = paired_ratio([1.0, 2.0], [1.0, 3.0])
    assert tie.p_improvement == pytest.approx(0.75)
    with pytest.raises(ValueError, match="equal lengths"):
        paired_ratio([1.0], [1.0, 2.0])


def _brute_front(x, y):
    out = []
    for i in range(len(x)):
        if not (np.isfinite(x[i]) and np.isfinite(y[i])):
            continue
        dominated = any(x[j] <= x[i] and y[j] <= y[i] and (x[j] < x[i] or y[j] < y[i])
                        for j in range(len(x)) if np.isfinite(x[j]) and np.isfinite(y[j]))
        if not dominated:
            out.append(i)
    return sorted(out)


def test_pareto_front_hand_built_with_ties():
    #        0    1    2    3    4    5    6    7
    x = [1.0, 2.0, 2.0, 3.0, 1.0, 4.0, 3.0, math.nan]
    y = [5.0, 3.0, 3.0, 3.0, 6.0, 1.0, 2.0, 0.0]
    # 0 (1,5) front; 4 (1,6) dominated by 0; 1 and 2 exact ties (2,3) both front;
    # 3 (3,3) dominated by 1; 6 (3,2) front; 5 (4,1) front; 7 NaN never.
    assert sorted(pareto_front(x, y).tolist()) == [0, 1, 2, 5, 6]


def test_pareto_front_matches_brute_force_on_random_sets_with_ties():
    rng = np.random.default_rng(3)
    for _ in range(200):
        n = int(rng.integers(1, 15))
        x = rng.integers(0, 5, n).astype(float)
        y = rng.integers(0, 5, n).astype(float)
        assert sorted(pareto_front(x, y).tolist()) == _brute_front(x, y)
