"""The joint EKF against independent oracles: an explicit augmented Kalman filter, and the
half-plane conditioning against rejection sampling."""

import numpy as np
import pytest

from controllers.solnic.joint_filter import JointFilter
from controllers.solnic.mode2_filter import mode2_transition

TAU4, S4, SIG1 = 1000.0, 2 * (30e-6) ** 2 / 1000.0, 5e-6


def _joint():
    return JointFilter(TAU4, S4, SIG1, [0.0, 3e-5], np.diag([1e-10, 1e-10]), [0.7, 1.05],
                       np.diag([0.49, 1.1]), 20.0)


def test_pulse_and_samples_match_an_explicit_linear_filter():
    """After a pulse with a linear motion model d = s(Δc + H(k − k̂)) + n, the filter equals the
    textbook Kalman filter of the 5-state linear system written out with full matrices."""
    f = _joint()
    z = f.z.copy()
    P = f.P.copy()
    rng = np.random.default_rng(3)
    H_b, dc, vn, sign = np.array([2e-6, -3e-6]), 2.5e-6, 1e-12, -1
    t = 0.0
    for n in range(40):
        t += 0.01
        f.predict(t)
        Phi2, Q2 = mode2_transition(0.01, TAU4, S4)
        F = np.eye(5)
        F[:2, :2] = Phi2
        Q = np.zeros((5, 5))
        Q[:2, :2] = Q2
        z, P = F @ z, F @ P @ F.T + Q
        if n == 10:
            f.add_motion(sign, dc, H_b, vn)
            # augment: new d with cross-covariances, then x1 += d, written with matrices
            G = np.zeros(5)
            G[2:4] = sign * H_b
            z = z.copy()
            z[4] = sign * dc
            P2 = P.copy()
            P2[4, :] = P2[:, 4] = 0.0
            T = np.eye(5)
            T[4, :] = G                    # d = G·z_old + sign·dc − G·k̂ + n (affine)
            T[4, 4] = 0.0
            P2 = T @ P2 @ T.T
            P2[4, 4] += vn
            J = np.eye(5)
            J[0, 4] = 1.0
            z[0] += z[4]
            P = J @ P2 @ J.T
        y = rng.normal(0, SIG1)
        Hm = np.zeros(5)
        Hm[0] = 1.0
        S = Hm @ P @ Hm + SIG1**2
        K = P @ Hm / S
        z = z + K * (y - z[0])
        P = P - np.outer(K, Hm @ P)
        f.update(y)
    np.testing.assert_allclose(f.z, z, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(f.P, P, rtol=1e-7, atol=1e-22)


def test_condition_matches_rejection_sampling():
    """Tolerance: 200 000 draws; mean and covariance within 0.01 (MC errors ≈ 0.002)."""
    f = _joint()
    f.P[2, 3] = f.P[3, 2] = 0.2
    z0, P0 = f.z.copy(), f.P.copy()
    c = np.zeros(5)
    c[2], c[3] = 1.0, -1.0
    f.condition(c, -0.5)
    draws = np.random.default_rng(1).multivariate_normal(z0[2:4], P0[2:4, 2:4], 200_000)
    kept = draws[draws @ c[2:4] <= -0.5]
    np.testing.assert_allclose(f.z[2:4], kept.mean(axis=0), atol=0.01)
    np.testing.assert_allclose(f.P[2:4, 2:4], np.cov(kept.T), atol=0.01)


def test_predict_backwards_is_an_error():
    f = _joint()
    f.predict(1.0)
    with pytest.raises(ValueError, match="backwards"):
        f.predict(0.5)


def test_no_motion_equals_a_filter_that_never_had_the_pulse():
    """Undo + replay: after ``no_motion`` (uncensored) the state equals a filter fed the same
    samples without any pulse (x1, x4 and k alike)."""
    f, g = _joint(), _joint()
    rng = np.random.default_rng(5)
    t = 0.0
    for n in range(30):
        t += 0.01
        for h in (f, g):
            h.predict(t)
        if n == 8:
            f.add_motion(1, 3e-6, np.array([2e-6, -3e-6]), 1e-12)
        y = rng.normal(0, SIG1)
        f.update(y)
        g.update(y)
    f.no_motion(5.0, censor=False)
    g._valid()                    # no_motion ends with the constraints on the distribution
    np.testing.assert_allclose(f.z[:4], g.z[:4], rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(f.P[:4, :4], g.P[:4, :4], rtol=1e-10, atol=1e-24)
