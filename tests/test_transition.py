"""Closed-form Φ(h) against scipy's expm; Q(h) against Van Loan; the noise factor (4-20)."""

import mpmath
import numpy as np
import pytest
from scipy.linalg import expm

from plant import PlantParams
from plant.multimode.noise import noise_factor
from plant.multimode.transition import X1, X2, X4, X5, drift_matrix, noise_intensity, phi, process_noise

PARAMS = [PlantParams(), PlantParams(inertia=2.0, motor_time_constant=3e-3, correlated_friction_tau=5.0,
                                     command_velocity_tau=20.0, stiction=3.0, coulomb=1.0)]


_SCALES = np.diag([1e-6, 1e-3, 1.0, 1e-5, 0.1, 1.0, 10.0])   # rad, rad/s, ozf·in, rad/s, ...


def _mp_expm(F, h):
    mpmath.mp.dps = 40
    return np.array(mpmath.expm(mpmath.matrix(F.tolist()) * mpmath.mpf(h)).tolist(), dtype=float)


def _compare(P, E, rtol, entrywise=True):
    S, Si = _SCALES, np.linalg.inv(_SCALES)
    Ps, Es = Si @ P @ S, Si @ E @ S
    scale = np.abs(Es).max()
    assert np.abs(Ps - Es).max() <= rtol * scale
    if not entrywise:
        return
    significant = np.abs(Es) > 1e-6 * scale
    rel = np.abs(Ps - Es)[significant] / np.abs(Es)[significant]
    assert rel.max() <= rtol, rel.max()


@pytest.mark.parametrize("params", PARAMS)
@pytest.mark.parametrize("mode", [1, 2, 3])
def test_phi_matches_expm(params, mode):
    """Φ(h) = expm(F·h) to 1e-12 relative, h log-uniform in [1e-6, 10] s.

    Compared in physically scaled coordinates (x1 in µrad, u in 10 ozf·in, ...) where the
    entries of Φ are O(1). Oracles: a 40-digit mpmath expm over the whole range, entry by
    entry; scipy's expm norm-wise where ‖F·h‖ ≤ 50 (beyond that, and on entries far below the
    norm, its own round-off exceeds 1e-12: 4e-12 measured at h = 3 s).
    """
    rng = np.random.default_rng(11)
    F = drift_matrix(mode, params)
    if mode == 2:
        # (3-8) has −∞ at (2,2): x2 is clamped to 0. Its exponential has a zero row and column 2.
        F[X2, :] = 0.0
    norm = np.abs(F).sum(axis=0).max()
    clamp = np.eye(7)
    if mode == 2:
        clamp[X2, X2] = 0.0
    for h in 10 ** rng.uniform(-6, 1, size=30):
        P = phi(mode, h, params)
        _compare(P, clamp @ _mp_expm(F, h) @ clamp, 1e-13)
        if norm * h <= 50:
            _compare(P, clamp @ expm(F * h) @ clamp, 1e-12, entrywise=False)


_NOISY = [X1, X2, X4, X5]


def _van_loan(F, Qc, h):
    """Van Loan (1978): the covariance from expm of [[−F, Q], [0, Fᵀ]]·h.

    Applied to the noise-reachable block {x1, x2, x4, x5}; x3 and u receive no noise and
    feed the others only deterministically, and keeping β3 out avoids e^(β3·h) overflow.
    """
    F = F[np.ix_(_NOISY, _NOISY)]
    Qc = Qc[np.ix_(_NOISY, _NOISY)]
    n = F.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n], M[:n, n:], M[n:, n:] = -F, Qc, F.T
    E = expm(M * h)
    out = np.zeros((7, 7))
    out[np.ix_(_NOISY, _NOISY)] = E[n:, n:].T @ E[:n, n:]
    return out


@pytest.mark.parametrize("params", PARAMS)
@pytest.mark.parametrize("mode", [1, 2, 3])
@pytest.mark.parametrize("h", [1e-6, 1e-4, 3e-3, 1e-2, 0.5, 10.0])
def test_process_noise_matches_van_loan(params, mode, h):
    C = process_noise(mode, h, params)
    V = _van_loan(drift_matrix(mode, params), noise_intensity(mode, params), h)
    # Compare in correlation units: entries span ~25 decades.
    d = np.sqrt(np.maximum(np.diag(V), 1e-300))
    nz = np.diag(V) > 0
    Cn, Vn = (C / np.outer(d, d))[np.ix_(nz, nz)], (V / np.outer(d, d))[np.ix_(nz, nz)]
    assert np.allclose(Cn, Vn, atol=1e-7, rtol=0), np.abs(Cn - Vn).max()
    assert np.allclose(np.diag(C)[nz], np.diag(V)[nz], rtol=1e-7)
    assert np.all(C[~nz] == 0)


def test_corrected_closed_forms_4_10_and_4_11_at_small_h():
    """Leading terms of (4-10)/(4-11) with the SPEC §9 errata: h³/3 and α²h⁴/8."""
    p = PlantParams()
    a, s2, s4, s5 = p.alpha, p.sigma2_sq, p.sigma4_sq, p.sigma5_sq
    h = 1e-3
    C1 = process_noise(1, h, p)
    assert C1[X1, X1] == pytest.approx(a**2 * s2 * h**3 / 3 + s4 * h**3 / 3 + s5 * a**2 * h**5 / 20, rel=1e-6)
    assert C1[X1, X2] == pytest.approx(a**2 * s2 * h**2 / 2 + s5 * a**2 * h**4 / 8, rel=1e-6)
    assert C1[X2, X2] == pytest.approx(a**2 * s2 * h + s5 * a**2 * h**3 / 3, rel=1e-6)
    assert C1[X1, X4] == pytest.approx(-s4 * h**2 / 2, rel=1e-5)
    assert C1[X1, X5] == pytest.approx(s5 * a * h**3 / 6, rel=1e-5)
    assert C1[X2, X5] == pytest.approx(s5 * a * h**2 / 2, rel=1e-5)
    assert C1[X5, X5] == pytest.approx(s5 * h, rel=1e-5)
    C3 = process_noise(3, h, p)
    assert C3[X1, X5] == pytest.approx(-C1[X1, X5]) and C3[X2, X5] == pytest.approx(-C1[X2, X5])
    C2 = process_noise(2, h, p)
    assert C2[X1, X1] == pytest.approx(s4 * h**3 / 3, rel=1e-5)   # erratum: h³/3, not h/3
    assert C2[X2, X2] == 0 and C2[X5, X5] == 0


def _check_factor(C):
    f = noise_factor(C)
    A = f.A
    assert np.allclose(A @ A.T, C, atol=1e-12 * np.abs(C).max())
    assert f.m == int(np.count_nonzero(np.any(C != 0, axis=1)))
    return f


def test_factor_drops_zero_rows_and_uses_one_normal_per_row():
    C = process_noise(1, 1e-3, PlantParams())
    f = _check_factor(C)
    assert f.m == 4 and list(f.rows) == [X1, X2, X4, X5]
    B = f.B
    assert np.allclose(B, np.tril(B)) and np.all(np.diag(B) > 0)     # (4-22), (4-23)


def test_factor_handles_singular_covariance_without_zero_rows():
    v = np.array([1.0, 2.0, -3.0])
    C = np.outer(v, v) + np.diag([0.0, 0.0, 0.0])
    _check_factor(C)
    C2 = np.zeros((5, 5))
    C2[np.ix_([0, 2, 4], [0, 2, 4])] = np.outer(v, v) * 1e-12 + np.outer([1, 0, 1], [1, 0, 1]) * 1e-13
    _check_factor(C2)


def test_factor_sample_statistics():
    C = process_noise(3, 2e-3, PlantParams())
    f = noise_factor(C)
    rng = np.random.default_rng(5)
    N = np.array([f.sample(rng.standard_normal(f.m)) for _ in range(20000)])
    d = np.sqrt(np.diag(C))
    nz = d > 0
    emp = np.cov(N[:, nz].T) / np.outer(d[nz], d[nz])
    # Correlation estimates have standard error ≤ 1/√N ≈ 0.007; allow 5 SE.
    assert np.allclose(emp, C[np.ix_(nz, nz)] / np.outer(d[nz], d[nz]), atol=0.035)


@pytest.mark.parametrize("bad, match", [(np.ones((2, 3)), "square"), (np.array([[1.0, np.nan], [np.nan, 1]]), "finite"),
                                        (np.array([[1.0, 0.5], [0.0, 1.0]]), "symmetric"),
                                        (np.array([[1.0, 2.0], [2.0, 1.0]]), "positive semi-definite")])
def test_factor_rejects_bad_matrices(bad, match):
    with pytest.raises(ValueError, match=match):
        noise_factor(bad)


def test_stuck_closed_form_matches_general_factor_statistics():
    """Mode 2's scalar fast path (exact 2 × 2 covariance) against process_noise (quadrature)."""
    from plant.expfun import e1, e4 as _e4

    p = PlantParams(command_velocity_tau=3.0)
    for h in (1e-5, 1e-2, 0.7, 4.0):
        y, E, b4, s4 = p.beta4 * h, e1(p.beta4 * h), p.beta4, p.sigma4_sq
        C = process_noise(2, h, p)
        assert s4 * _e4(y) / b4**3 == pytest.approx(C[X1, X1], rel=1e-12)
        assert -s4 * E * E / (2 * b4 * b4) == pytest.approx(C[X1, X4], rel=1e-12)
        assert s4 * E * (2 - E) / (2 * b4) == pytest.approx(C[X4, X4], rel=1e-12)


@pytest.mark.parametrize("params", PARAMS)
@pytest.mark.parametrize("mode", [1, 3])
def test_compiled_closed_forms_equal_the_python_ones(params, mode):
    """plant.multimode.moving restates Φ and Q in scalar form for numba; both must agree, and the
    scalar mean path must equal Φ(h)·X."""
    from plant.multimode.moving import chol_psd, mean_path, phi_moving, q_moving

    pv = params.kernel_record()[0]
    idx = np.array(_NOISY)
    X = np.array([3e-6, -2e-4, 1.7, 2.9e-5, 0.21, params.coulomb, -20.0])
    for h in (1e-7, 3e-5, 1e-3, 0.4, 7.0):
        P = np.empty((7, 7))
        phi_moving(mode, h, pv, P)
        assert np.allclose(P, phi(mode, h, params), rtol=1e-14, atol=0)
        assert np.allclose(mean_path(mode, h, X, pv), (expm(drift_matrix(mode, params) * h) @ X)[:4],
                           rtol=1e-10, atol=1e-18)
        Q, L = np.empty((4, 4)), np.empty((4, 4))
        q_moving(mode, h, pv, Q)
        Qref = process_noise(mode, h, params)[np.ix_(idx, idx)]
        d = np.sqrt(np.diag(Qref))
        assert np.allclose(Q / np.outer(d, d), Qref / np.outer(d, d), rtol=0, atol=1e-12)
        chol_psd(Q, L)
        assert np.allclose((L @ L.T) / np.outer(d, d), Q / np.outer(d, d), atol=1e-12)
