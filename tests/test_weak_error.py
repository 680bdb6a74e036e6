"""The noisy weak-error comparison's statistics against Monte-Carlo truth (bench.weak_error)."""

import numpy as np
import pytest

from bench.weak_error import _stat


@pytest.mark.parametrize("which", ["mean", "p95"])
def test_standard_errors_match_the_spread_over_replications(which):
    # 400 replications of n = 1500 exponential draws (skewed like Δc): the reported SE of one
    # replication must match the SD of the statistic across replications within 10 % (the SD of
    # a sample SD from 400 replications is ~3.5 %, and the percentile SE is asymptotic).
    rng = np.random.default_rng(5)
    reps = [_stat(rng.exponential(2.0, 1500), which) for _ in range(400)]
    values = np.array([v for v, _ in reps])
    ses = np.array([s for _, s in reps])
    assert np.median(ses) == pytest.approx(values.std(ddof=1), rel=0.10)
    truth = 2.0 if which == "mean" else -2.0 * np.log(0.05)
    assert values.mean() == pytest.approx(truth, rel=0.01)
