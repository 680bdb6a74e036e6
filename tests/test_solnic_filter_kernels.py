"""The compiled filter steps against the textbook matrix formulas written out here with numpy.

Tolerance rtol 1e-12: the kernels and numpy differ only in the rounding of 2-term sums (one
fused multiply-add against two roundings), ≈ 1e-16 relative per operation.
"""

import numpy as np
import pytest

from controllers.solnic.filter_kernels import (friction_covariance, friction_gain,
                                               friction_update_clip, joint_predict, joint_update,
                                               quadratic_form2)
from controllers.solnic.mode2_filter import mode2_transition


def _spd(rng, n, scale):
    A = rng.standard_normal((n, n))
    return (A @ A.T + n * np.eye(n)) * scale


@pytest.mark.parametrize("seed", range(5))
def test_joint_predict_and_update_match_the_matrix_formulas(seed):
    rng = np.random.default_rng(seed)
    scale = np.array([1e-5, 1e-4, 0.5, 0.7, 1e-5])          # x1, x4 [rad, rad/s], k [ozf·in], d
    P = _spd(rng, 5, 1.0) * np.outer(scale, scale)
    z = rng.standard_normal(5) * scale
    h = rng.uniform(1e-3, 0.05)
    Phi2, Q2 = mode2_transition(h, 1000.0, 2 * (30e-6) ** 2 / 1000.0)
    F = np.eye(5)
    F[:2, :2] = Phi2
    Q = np.zeros((5, 5))
    Q[:2, :2] = Q2
    z_ref, P_ref = F @ z, F @ P @ F.T + Q
    z_k, P_k = z.copy(), P.copy()
    joint_predict(z_k, P_k, Phi2[0, 1], Phi2[1, 1], Q2[0, 0], Q2[0, 1], Q2[1, 1])
    np.testing.assert_allclose(z_k, z_ref, rtol=1e-12, atol=1e-12 * np.abs(z_ref).max())
    np.testing.assert_allclose(P_k, P_ref, rtol=1e-12, atol=1e-12 * np.abs(P_ref).max())

    R, y = (5e-6) ** 2, z_ref[0] + rng.normal(0.0, 5e-6)
    H = np.zeros(5)
    H[0] = 1.0
    S = H @ P_ref @ H + R
    K = P_ref @ H / S
    z_up = z_ref + K * (y - H @ z_ref)
    P_up = (np.eye(5) - np.outer(K, H)) @ P_ref
    innovation = joint_update(z_k, P_k, R, y)
    assert innovation == pytest.approx(y - z_ref[0], rel=1e-12)
    np.testing.assert_allclose(z_k, z_up, rtol=1e-12, atol=1e-12 * np.abs(z_up).max())
    np.testing.assert_allclose(P_k, P_up, rtol=1e-12, atol=1e-12 * np.abs(P_ref).max())
    np.testing.assert_array_equal(P_k, P_k.T)                # symmetrised exactly
    assert np.all(np.linalg.eigvalsh(P_k) > 0)


@pytest.mark.parametrize("seed", range(5))
def test_friction_kernels_match_the_matrix_formulas(seed):
    rng = np.random.default_rng(100 + seed)
    P = _spd(rng, 2, 0.02)
    H = rng.standard_normal(2) * 3e-6
    assert quadratic_form2(H, P) == pytest.approx(H @ P @ H, rel=1e-12)
    r, R, a = rng.normal(0.0, 2e-6), (1.5e-6) ** 2, 0.5
    K0, K1, S, R_used = friction_gain(P, H[0], H[1], r, R, np.inf)
    assert R_used == R and S == pytest.approx(H @ P @ H + R, rel=1e-12)
    np.testing.assert_allclose([K0, K1], P @ H / (H @ P @ H + R), rtol=1e-12)
    P_new = friction_covariance(P, K0, K1, H[0], H[1], a)
    ref = (np.eye(2) - a * np.outer([K0, K1], H)) @ P
    np.testing.assert_allclose(P_new, 0.5 * (ref + ref.T), rtol=1e-12)
    # a cap on the correction: R raised so that max |K_i r| equals the limit
    limit = 0.5 * max(abs(K0 * r), abs(K1 * r))
    K0c, K1c, Sc, R_c = friction_gain(P, H[0], H[1], r, R, limit)
    assert R_c > R and max(abs(K0c * r), abs(K1c * r)) == pytest.approx(limit, rel=1e-9)
    # the full clip-mode update without an active constraint is the plain update
    k = np.array([1.0, 2.0])
    k_new, P_u, S_u, R_u, shrinks, clipped = friction_update_clip(k, P, H, r, R, a, np.inf, 19.0, 10)
    np.testing.assert_allclose(k_new, k + np.array([K0, K1]) * r, rtol=1e-12)
    np.testing.assert_allclose(P_u, P_new, rtol=1e-12)
    assert shrinks == 0 and not clipped


def test_friction_update_clip_shrinks_a_fallacious_raise_of_ks():
    """A raise of k̂s past the cap halves ∂Δc/∂k̂s until the corrected k̂s is below it."""
    P = np.array([[0.04, 0.0], [0.0, 0.09]])
    H = np.array([0.0, -4e-6])
    r, R = -2e-6, (1e-6) ** 2                # K1·r > 0: a raise of k̂s
    k = np.array([1.0, 2.0])
    cap = 2.01
    k_new, _, _, _, shrinks, clipped = friction_update_clip(k, P, H, r, R, 0.5, np.inf, cap, 10)
    h1 = H[1] * 0.5 ** shrinks
    K1 = P[1, 1] * h1 / (P[1, 1] * h1 * h1 + R)
    assert shrinks > 0 and not clipped and k_new[1] <= cap
    assert k_new[1] == pytest.approx(2.0 + K1 * r, rel=1e-12)
    h1_prev = 2.0 * h1                       # one shrink fewer would still have passed the cap
    assert 2.0 + P[1, 1] * h1_prev / (P[1, 1] * h1_prev ** 2 + R) * r > cap


@pytest.mark.parametrize("seed", range(3))
def test_half_plane_kernels_match_the_regression_formulas(seed):
    """General c (not only the ±1 constraints): moments c·μ, c'Pc and the regression of x on s."""
    from controllers.solnic.filter_kernels import half_plane_apply, half_plane_moments

    rng = np.random.default_rng(200 + seed)
    P = _spd(rng, 5, 0.3)
    mean, c = rng.standard_normal(5), rng.standard_normal(5)
    m, v = half_plane_moments(mean, P, c)
    assert m == pytest.approx(c @ mean, rel=1e-12, abs=1e-14)
    assert v == pytest.approx(c @ P @ c, rel=1e-12)
    mean_s, var_s = m - 0.3 * np.sqrt(v), 0.6 * v
    new_mean, new_P = half_plane_apply(mean, P, c, m, v, mean_s, var_s)
    Pc = P @ c
    np.testing.assert_allclose(new_mean, mean + Pc * (mean_s - m) / v, rtol=1e-12, atol=1e-14)
    ref = P - np.outer(Pc, Pc) * (v - var_s) / v**2
    np.testing.assert_allclose(new_P, ref, rtol=1e-12, atol=1e-14)
    # the conditioned s has the requested moments
    assert c @ new_mean == pytest.approx(mean_s, rel=1e-10, abs=1e-12)
    assert c @ new_P @ c == pytest.approx(var_s, rel=1e-10)


@pytest.mark.parametrize("limit", [np.inf, 1e-3])
def test_joint_add_motion_matches_the_augmented_matrix_formulas(limit):
    """d = h·(z − ẑ) + d̂ + n replaces z[4] (P[4,:] = P h, VAR[d] = h'Ph + VAR[n], raised to
    max|P_kd|·|Δc|/limit), then x1 ← x1 + d: J P J' with J = I + e_0 e_4'."""
    from controllers.solnic.filter_kernels import joint_add_motion

    rng = np.random.default_rng(7)
    scale = np.array([1e-5, 1e-4, 0.5, 0.7, 1e-5])
    P = _spd(rng, 5, 1.0) * np.outer(scale, scale)
    z = rng.standard_normal(5) * scale
    h = np.zeros(5)
    h[2:4] = [3e-6, -2e-6]
    d_mean, vn, dc = -4e-6, 1e-13, 4e-6
    Ph = P @ h
    var_d = h @ Ph + vn
    if np.isfinite(limit):
        var_d = max(var_d, np.abs(Ph[2:4]).max() * dc / limit)
        assert var_d > 10 * (h @ Ph + vn)          # the limit is what sets VAR[d] here
    P2 = P.copy()
    P2[4, :] = P2[:, 4] = Ph
    P2[4, 4] = var_d
    J = np.eye(5)
    J[0, 4] = 1.0
    z_ref = z.copy()
    z_ref[4] = d_mean
    z_ref = J @ z_ref
    P_ref = J @ P2 @ J.T
    got = joint_add_motion(z, P, h, d_mean, vn, limit, dc)
    assert got == pytest.approx(var_d, rel=1e-12)
    np.testing.assert_allclose(z, z_ref, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(P, P_ref, rtol=1e-12, atol=1e-12 * np.abs(P_ref).max())


def _old_condition(z, P, c, bound):
    """JointFilter.condition as it was (numpy and :func:`condition_half_plane`, new arrays)."""
    from controllers.solnic.truncation import condition_half_plane
    out = condition_half_plane(z, P, c, bound, True)
    return (z, P) if out is None else out


def _old_valid(z, P, u_max):
    """JointFilter._valid as it was, step by step in Python."""
    for idx, val, bound in (((3,), (1.0,), u_max * (1.0 - 1e-6)), ((2, 3), (1.0, -1.0), 0.0), ((2,), (-1.0,), 0.0)):
        c = np.zeros(5)
        c[list(idx)] = val
        z, P = _old_condition(z, P, c, bound)
    z = z.copy()
    kc = min(max(z[2], 0.0), u_max * (1 - 1e-6))
    z[2] = kc
    z[3] = min(max(z[3], kc), u_max * (1 - 1e-6))
    return z, P


@pytest.mark.parametrize("seed", range(4))
def test_joint_condition_is_the_truncated_gaussian_and_the_python_path_bit_for_bit(seed):
    """c·z ≤ b: the conditioned mean and variance of s = c·z are scipy's truncated normal's
    (independent truth, rtol 1e-9); z and P equal condition_half_plane's (the Python path) bit
    for bit; a bound more than 8 σ above the mean changes nothing."""
    from scipy.stats import truncnorm

    from controllers.solnic.filter_kernels import joint_condition
    rng = np.random.default_rng(100 + seed)
    for _ in range(50):
        P = _spd(rng, 5, 0.1)
        z = rng.standard_normal(5)
        c = np.zeros(5)
        c[rng.choice(5, 2, replace=False)] = (1.0, -1.0)
        m, v = c @ z, c @ P @ c
        b = m + rng.uniform(-3.0, 3.0) * np.sqrt(v)
        z_k, P_k = z.copy(), P.copy()
        assert joint_condition(z_k, P_k, c, b, True)
        z_p, P_p = _old_condition(z, P, c, b)
        assert z_k.tobytes() == z_p.tobytes() and P_k.tobytes() == P_p.tobytes()
        tn = truncnorm(-np.inf, (b - m) / np.sqrt(v), loc=m, scale=np.sqrt(v))
        np.testing.assert_allclose(c @ z_k, tn.mean(), rtol=1e-9, atol=1e-9 * np.sqrt(v))
        np.testing.assert_allclose(c @ P_k @ c, tn.var(), rtol=1e-7)
        z_f, P_f = z.copy(), P.copy()
        assert not joint_condition(z_f, P_f, c, m + 8.5 * np.sqrt(v), True)
        assert (z_f == z).all() and (P_f == P).all()


@pytest.mark.parametrize("seed", range(4))
def test_joint_valid_and_moved_equal_the_python_steps_bit_for_bit(seed):
    """The compiled constraints of JointFilter._valid and .moved against the Python steps they
    replace (condition_half_plane three or four times, Python's min/max guard), on means inside
    and outside the valid set 0 ≤ k_c ≤ k_s < u_max; after them the means lie inside it."""
    from controllers.solnic.filter_kernels import joint_moved, joint_valid
    rng = np.random.default_rng(200 + seed)
    u_max = 4.0
    for _ in range(100):
        P = _spd(rng, 5, rng.uniform(1e-3, 1.0))
        z = rng.standard_normal(5)
        z[2:4] = rng.uniform(-1.0, 5.0, 2)
        z_k, P_k = z.copy(), P.copy()
        joint_valid(z_k, P_k, u_max)
        z_p, P_p = _old_valid(z, P, u_max)
        assert z_k.tobytes() == z_p.tobytes() and P_k.tobytes() == P_p.tobytes()
        assert 0.0 <= z_k[2] <= z_k[3] < u_max
        peak = rng.uniform(0.5, 5.0)
        z_k, P_k = z.copy(), P.copy()
        joint_moved(z_k, P_k, peak, u_max)
        c = np.zeros(5)
        c[3] = 1.0
        z_p, P_p = _old_valid(*_old_condition(z, P, c, min(peak, u_max) * (1.0 - 1e-6)), u_max)
        assert z_k.tobytes() == z_p.tobytes() and P_k.tobytes() == P_p.tobytes()


@pytest.mark.parametrize("limit", [np.inf, 0.05])
def test_joint_launch_equals_the_python_launch_steps_bit_for_bit(limit):
    """joint_launch against the JointFilter/FrictionView steps it replaces in a launch
    (motion_variance, time_variance, prob_no_motion, add_motion, propagate), bit for bit, with
    and without the correction limit and with a k_s variance of zero (Prob(no motion) 0 or 1)."""
    from controllers.solnic.filter_kernels import joint_launch
    from controllers.solnic.joint_filter import JointFilter
    rng = np.random.default_rng(7)
    for i in range(60):
        scale = np.array([1e-5, 1e-4, 0.5, 0.7, 1e-5])
        jf = JointFilter(1000.0, 1e-12, 5e-6, [0.0, 0.0], np.eye(2) * 1e-10, [0.8, 1.9], np.eye(2) * 0.1, 4.0)
        jf.P[:] = _spd(rng, 5, 1.0) * np.outer(scale, scale)
        if i % 10 == 0:
            jf.P[3, :] = jf.P[:, 3] = 0.0
        jf.z[:] = rng.standard_normal(5) * scale + np.array([0, 0, 0.8, 1.9, 0])
        H_b, H_tb = rng.standard_normal(2) * 1e-5, rng.standard_normal(2) * 1e-3
        peak, sign = rng.uniform(1.0, 3.0), int(rng.choice([-1, 1]))
        dc, nv, moving, s5 = rng.uniform(1e-6, 5e-5), rng.uniform(0, 1e-12), rng.uniform(0, 3e-3), 1e-4
        z, P = jf.z.copy(), jf.P.copy()
        f = jf.friction
        want = (f.motion_variance(H_b), f.time_variance(H_tb), f.prob_no_motion(peak))
        jf.add_motion(sign, dc, H_b, nv + dc**2 * want[2], limit)
        f.propagate(moving, s5)
        out = np.empty(4)
        joint_launch(z, P, H_b, H_tb, peak, sign, dc, dc**2, nv, limit, moving, s5, out)
        assert out[:3].tobytes() == np.array(want).tobytes() and out[3] == jf.motion_prior[1]
        assert z.tobytes() == jf.z.tobytes() and P.tobytes() == jf.P.tobytes()
