"""The mode-2 filter against a textbook Kalman filter written here from scratch."""

import numpy as np
import pytest
from scipy.linalg import expm

from controllers.solnic.mode2_filter import Mode2Filter, mode2_transition

TAU4, S4, SIG1 = 1000.0, 1.8e-14, 5e-6


def _van_loan(h, tau4=TAU4, s4=S4):
    """Φ and ∫Φ Qc Φ' by Van Loan's method for ẋ1 = −x4, ẋ4 = −x4/τ4 + w4."""
    F = np.array([[0.0, -1.0], [0.0, -1.0 / tau4]])
    Qc = np.diag([0.0, s4])
    M = np.zeros((4, 4))
    M[:2, :2] = -F
    M[:2, 2:] = Qc
    M[2:, 2:] = F.T
    E = expm(M * h)
    Phi = E[2:, 2:].T
    return Phi, Phi @ E[:2, 2:]


@pytest.mark.parametrize("h", [1e-4, 3.7e-3, 0.01, 1.0, 250.0])
def test_transition_matches_van_loan(h):
    Phi, Q = mode2_transition(h, TAU4, S4)
    Phi_ref, Q_ref = _van_loan(h)
    np.testing.assert_allclose(Phi, Phi_ref, rtol=1e-12, atol=0)
    np.testing.assert_allclose(Q, Q_ref, rtol=1e-9, atol=0)
    # the text's (4-11) with the erratum h³/3 is the leading term
    if h <= 0.01:
        assert Q[0, 0] == pytest.approx(S4 * h**3 / 3, rel=1e-4)


def _synthetic(rng, n, h=0.01):
    """Data from the linear model itself, with irregular steps."""
    x = np.array([2e-6, 30e-6])
    times, ys = [], []
    t = 0.0
    for k in range(n):
        dt = h if k % 7 else h * 0.37
        Phi, Q = _van_loan(dt)
        x = Phi @ x + rng.multivariate_normal(np.zeros(2), Q)
        t += dt
        times.append(t)
        ys.append(x[0] + SIG1 * rng.standard_normal())
    return times, ys


def test_equals_textbook_kalman_filter():
    rng = np.random.default_rng(7)
    times, ys = _synthetic(rng, 300)
    x0, P0 = np.array([0.0, 0.0]), np.diag([1e-8, 5e-9])
    f = Mode2Filter(TAU4, S4, SIG1, x0, P0)
    x, P, t = x0.copy(), P0.copy(), 0.0
    H = np.array([[1.0, 0.0]])
    for k, (tk, y) in enumerate(zip(times, ys)):
        Phi, Q = _van_loan(tk - t)
        x, P = Phi @ x, Phi @ P @ Phi.T + Q                    # textbook predict
        if k % 5 != 3:                                         # some samples rejected
            S = H @ P @ H.T + SIG1**2
            K = P @ H.T @ np.linalg.inv(S)
            x = x + (K @ (np.array([y]) - H @ x)).ravel()
            P = (np.eye(2) - K @ H) @ P                        # textbook update
        t = tk
        f.predict(tk)
        if k % 5 != 3:
            f.update(y)
        np.testing.assert_allclose(f.x, x, rtol=1e-12, atol=1e-12 * np.abs(x).max())
        np.testing.assert_allclose(f.P, P, rtol=1e-12, atol=1e-12 * np.abs(P).max())


def test_anchor_and_motion_match_augmented_filter():
    """Delayed state x1(t_a) and the motion d against a 4-state textbook filter."""
    rng = np.random.default_rng(3)
    f = Mode2Filter(TAU4, S4, SIG1, [0.0, 0.0], np.diag([1e-8, 5e-9]))
    # state (x1, x4, frozen x̂1(t_a) error reference a, d); a is a constant with no updates
    X = np.zeros(4)
    P = np.zeros((4, 4))
    P[:2, :2] = f.P
    t = 0.0

    def step(X, P, t, tn, y):
        Phi, Q = _van_loan(tn - t)
        F = np.eye(4)
        F[:2, :2] = Phi
        Qa = np.zeros((4, 4))
        Qa[:2, :2] = Q
        X, P = F @ X, F @ P @ F.T + Qa
        H = np.array([1.0, 0, 0, 0])
        S = H @ P @ H + SIG1**2
        K = P @ H / S
        K[2] = 0.0                     # the frozen estimate x̂1(t_a) is never corrected
        X = X + K * (y - H @ X)
        P = P - np.outer(K, H @ P) - np.outer(H @ P, K) + np.outer(K, K) * S
        return X, P

    for k in range(20):
        t_new = t + 0.01
        y = rng.normal(0, SIG1)
        X, P = step(X, P, t, t_new, y)
        f.predict(t_new)
        f.update(y)
        t = t_new
    t_a = t + 0.004                      # the pulse starts inside the interval
    f.predict(t_a)
    Phi, Q = _van_loan(0.004)
    F = np.eye(4); F[:2, :2] = Phi
    Qa = np.zeros((4, 4)); Qa[:2, :2] = Q
    X, P = F @ X, F @ P @ F.T + Qa
    t = t_a
    # anchor: a := x1(t_a) error, identical to e1 at t_a
    f.set_anchor()
    X[2] = X[0]
    P[2, :] = P[0, :]
    P[:, 2] = P[:, 0]
    # correction: d ~ N(dc, V); x1 += d
    dc, V = 3e-6, 4e-12
    f.add_motion(dc, V)
    X[0] += dc
    X[3] = dc
    P[3, :] = 0.0; P[:, 3] = 0.0
    P[3, 3] = V
    T = np.eye(4); T[0, 3] = 1.0          # x1 ← x1 + e_d
    P = T @ P @ T.T
    for k in range(9):
        t_new = (int(round(t_a / 0.01)) + 1 + k) * 0.01
        y = 3e-6 - 0.3e-6 * k + rng.normal(0, SIG1)
        X, P = step(X, P, t, t_new, y)
        f.predict(t_new)
        f.update(y)
        t = t_new
    np.testing.assert_allclose(f.x, X[:2], rtol=1e-12)
    np.testing.assert_allclose(f.P, P[:2, :2], rtol=1e-10)
    a = np.array([1.0, t - t_a, -1.0, 0.0])      # error of x̂1(t_b) − x̂1(t_a) + x̂4(t_b)(t_b − t_a)
    assert f.motion_variance(t) == pytest.approx(a @ P @ a, rel=1e-9)
    assert f.motion_mean == pytest.approx(X[3], rel=1e-10)
    assert f.motion_var == pytest.approx(P[3, 3], rel=1e-9)
    m, R = f.motion_likelihood()
    # product of prior and likelihood gives the posterior
    assert 1 / R + 1 / V == pytest.approx(1 / P[3, 3], rel=1e-9)
    assert m / R + dc / V == pytest.approx(X[3] / P[3, 3], rel=1e-9)


def test_errors():
    with pytest.raises(ValueError, match="tau4"):
        Mode2Filter(0.0, S4, SIG1, [0, 0], np.eye(2))
    with pytest.raises(ValueError, match="sigma1"):
        Mode2Filter(TAU4, S4, 0.0, [0, 0], np.eye(2))
    f = Mode2Filter(TAU4, S4, SIG1, [0, 0], np.eye(2), t0=1.0)
    with pytest.raises(ValueError, match="backwards"):
        f.predict(0.5)
    with pytest.raises(ValueError, match="anchor"):
        f.motion_variance()
    with pytest.raises(ValueError, match="variance"):
        f.add_motion(1e-6, -1.0)
    with pytest.raises(ValueError, match="h must be"):
        mode2_transition(-1.0, TAU4, S4)
