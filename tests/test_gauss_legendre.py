"""plant.gauss_legendre's literal rules against mpmath at 40 digits and the exactness property.

The constants are numpy's leggauss output (kept so that no row moves): its nodes are within 4 ulps
of the zeros of P_n, its weights within 1e-14 relative (up to 58 ulps: leggauss rescales them to
sum to 2), so a rule integrates x^k, k ≤ 2n − 1, to 4e-15.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest

from plant.gauss_legendre import nodes_weights


@pytest.mark.parametrize("n", [4, 8, 12])
def test_nodes_and_weights_are_gauss_legendre_to_a_few_ulps(n):
    x, w = nodes_weights(n)
    with mpmath.workdps(40):
        for i in range(n):
            # Newton on P_n from the tabulated node converges to the true zero at 40 digits
            t = mpmath.mpf(float(x[i]))
            for _ in range(8):
                t -= mpmath.legendre(n, t) / mpmath.diff(lambda s: mpmath.legendre(n, s), t)
            assert abs(mpmath.mpf(float(x[i])) - t) <= 4 * np.spacing(abs(x[i])), (n, i)
            wt = 2 / ((1 - t ** 2) * mpmath.diff(lambda s: mpmath.legendre(n, s), t) ** 2)
            assert abs(mpmath.mpf(float(w[i])) - wt) <= 1e-14 * wt, (n, i)      # numpy's weights: ≤ 58 ulps
    assert np.all(np.diff(x) > 0) and np.array_equal(x, -x[::-1]) and np.array_equal(w, w[::-1])


@pytest.mark.parametrize("n", [4, 8, 12])
def test_the_rule_integrates_polynomials_of_degree_2n_minus_1(n):
    x, w = nodes_weights(n)
    for k in range(2 * n):
        exact = 0.0 if k % 2 else 2.0 / (k + 1)
        assert abs(math.fsum(w * x ** k) - exact) <= 4e-15, (n, k)
    assert abs(math.fsum(w * x ** (2 * n)) - 2.0 / (2 * n + 1)) > 1e-8      # and not of degree 2n (1.8e-7 at n = 12)


def test_an_untabulated_rule_is_refused():
    with pytest.raises(ValueError, match="not tabulated"):
        nodes_weights(5)
