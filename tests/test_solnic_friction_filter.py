"""The modified Kalman filter on (k̂c, k̂s), (5-15)–(5-18), and its constraints."""

import math

import numpy as np
import pytest
from scipy.stats import norm

from controllers.solnic.friction_filter import FrictionFilter

P0 = np.array([[0.04, -0.01], [-0.01, 0.09]])


def _filter(**kw):
    kw.setdefault("max_correction_fraction", math.inf)
    return FrictionFilter(1.0, 2.0, P0, 20.0, **kw)


def test_unconstrained_update_is_kalman_with_scaled_covariance_reduction():
    H = np.array([-4.6e-6, -1.3e-6])
    r, R = 0.2e-6, (1.5e-6) ** 2
    for a in (1.0, 0.5):
        f = _filter(a=a)
        f.update(H, r, R, peak_torque=19.0)
        S = H @ P0 @ H + R
        K = P0 @ H / S
        np.testing.assert_allclose(f.k, np.array([1.0, 2.0]) + K * r, rtol=1e-12)   # (5-16), (5-17)
        np.testing.assert_allclose(f.P, P0 - a * np.outer(K, H @ P0), rtol=1e-12)  # (5-18)


def test_large_corrections_limited_by_fictitious_variance():
    H = np.array([-4.6e-6, -1.3e-6])
    f = FrictionFilter(1.0, 2.0, P0, 20.0, max_correction_fraction=0.05)
    upd = f.update(H, -5e-6, (0.5e-6) ** 2, peak_torque=19.0)
    assert max(abs(d) for d in upd.delta) == pytest.approx(0.05 * 2.0, rel=1e-9)
    assert upd.fictitious_var > (0.5e-6) ** 2
    # P is reduced consistently with the gain actually used
    K = P0 @ H / (H @ P0 @ H + upd.fictitious_var)
    np.testing.assert_allclose(f.P, P0 - 0.5 * np.outer(K, H @ P0), rtol=1e-10)


def test_ks_never_above_the_torque_that_moved_the_shaft():
    H = np.array([-1e-6, 4e-6])          # a residual that would raise k̂s a lot
    f = _filter()
    upd = f.update(H, 1e-6, (0.2e-6) ** 2, peak_torque=2.1)
    assert f.ks <= 2.1
    assert upd.shrinks > 0               # the k̂s quasipartial was reduced, not just clipped
    assert f.kc <= f.ks


def test_ks_not_below_kc_and_kc_not_negative():
    f = FrictionFilter(1.0, 1.05, np.diag([0.01, 0.5]), 20.0, max_correction_fraction=math.inf)
    f.update(np.array([0.0, -2e-6]), 3e-6, (0.1e-6) ** 2, peak_torque=19.0)
    assert f.ks >= f.kc >= 0.0


def test_propagation_adds_common_x5_drift():
    f = _filter()
    f.propagate(2e-3, 1.8e-4)                                               # (5-15)
    np.testing.assert_allclose(f.P, P0 + 1.8e-4 * 2e-3 * np.ones((2, 2)), rtol=1e-14)


def test_probability_of_no_motion():
    f = _filter()
    for torque in (1.5, 2.0, 2.7):
        assert f.prob_no_motion(torque) == pytest.approx(norm.sf(torque, loc=2.0, scale=0.3), rel=1e-12)


def test_errors():
    with pytest.raises(ValueError, match="a must be"):
        FrictionFilter(1.0, 2.0, P0, 20.0, a=0.0)
    with pytest.raises(ValueError, match="kc0 <= ks0"):
        FrictionFilter(2.0, 1.0, P0, 20.0)
    with pytest.raises(ValueError, match="max_correction_fraction"):
        FrictionFilter(1.0, 2.0, P0, 20.0, max_correction_fraction=0.0)
    with pytest.raises(ValueError, match="finite"):
        _filter().update([math.nan, 0.0], 0.0, 1.0, 5.0)


def test_condition_matches_monte_carlo_truncation():
    """Half-plane conditioning (constraints on the distribution) against rejection sampling.

    Tolerance: 200 000 draws, kept fraction ≈ 0.3; mean within 0.01 and covariance within
    0.01 (absolute, ozf·in and ozf²·in²; MC standard errors ≈ 0.002).
    """
    from controllers.solnic.friction_filter import FrictionFilter
    k0 = np.array([0.7, 1.05])
    P0 = np.array([[0.49, 0.2], [0.2, 1.1]])
    f = FrictionFilter(k0[0], k0[1], P0, 20.0)
    c, b = np.array([1.0, -1.0]), -0.5             # k_s ≥ k_c + 0.5
    f.condition(c, b)
    draws = np.random.default_rng(1).multivariate_normal(k0, P0, 200_000)
    kept = draws[draws @ c <= b]
    assert 0.2 < len(kept) / len(draws) < 0.5
    np.testing.assert_allclose(f.k, kept.mean(axis=0), atol=0.01)
    np.testing.assert_allclose(f.P, np.cov(kept.T), atol=0.01)
