"""plant.fixed_linalg (the plants' BLAS/LAPACK-free linear algebra) against LAPACK and exact properties.

* each routine is its documented order of operations: bit for bit a plain-Python loop of that
  order (CPython floats are the same IEEE doubles, an independent implementation);
* Cholesky: L·Lᵀ = D within Higham's componentwise backward bound (Thm 10.3, slack 4), L
  equal to LAPACK's within a condition-scaled tolerance, failure on singular and indefinite
  matrices (the plants' zero-row and rank-deficient covariances);
* Jacobi: eigenvalues equal to LAPACK's within c·n·ε·‖S‖ (both backward stable: Weyl),
  V·diag(λ)·Vᵀ = S and VᵀV = I to c·n·ε, repeated and zero eigenvalues, eigenvectors against
  LAPACK's where the gap allows (sin θ ≤ c·ε·‖S‖/gap);
* the hermitian pseudo-inverse against numpy's, and its Penrose identities on a singular matrix;
* the disturbed plant's real covariances (Q(h) of each mode over the sub-step ladder).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from plant import fixed_linalg as fl

EPS = np.finfo(float).eps
SIZES = (1, 2, 3, 5, 6, 8, 10)


def _spd(rng, n, decades=3.0):
    A = rng.standard_normal((n, n)) * np.exp(decades * rng.standard_normal((n, n)))
    return A @ A.T + 1e-3 * np.eye(n)


def _py_cholesky(D):
    n = len(D)
    L = [[0.0] * n for _ in range(n)]
    for j in range(n):
        d = float(D[j][j])
        for k in range(j):
            d -= L[j][k] * L[j][k]
        if not d > 0.0:
            return None
        L[j][j] = math.sqrt(d)
        for i in range(j + 1, n):
            acc = float(D[i][j])
            for k in range(j):
                acc -= L[i][k] * L[j][k]
            L[i][j] = acc / L[j][j]
    return np.array(L)


def test_products_are_their_documented_order_bit_for_bit():
    rng = np.random.default_rng(1)
    for n in SIZES:
        A = rng.standard_normal((n, n + 1)) * np.exp(3 * rng.standard_normal((n, n + 1)))
        B = rng.standard_normal((n + 1, 3))
        C = rng.standard_normal((4, n + 1))
        x = rng.standard_normal(n + 1)
        y = np.empty(n)
        fl.mat_vec(A, x, y)
        ref = [sum_in_order(A[i, k] * x[k] for k in range(n + 1)) for i in range(n)]
        assert y.tolist() == ref
        assert fl.mat_mat(A, B).tolist() == [[sum_in_order(A[i, k] * B[k, j] for k in range(n + 1)) for j in range(3)]
                                             for i in range(n)]
        assert fl.mat_mat_t(A, C).tolist() == [[sum_in_order(A[i, k] * C[j, k] for k in range(n + 1)) for j in range(4)]
                                               for i in range(n)]
        G = fl.gram(A)
        assert np.array_equal(G, G.T)
        assert np.array_equal(G, fl.mat_mat_t(A, A))      # products commute exactly: the same sums
        assert np.allclose(G, A @ A.T, rtol=0, atol=4 * (n + 1) * EPS * (np.abs(A) @ np.abs(A).T).max())


def sum_in_order(terms):
    acc = 0.0
    for t in terms:
        acc += float(t)
    return acc


def test_cholesky_is_the_textbook_loop_and_lapacks_factor_to_rounding():
    rng = np.random.default_rng(2)
    for n in SIZES:
        for _ in range(100):
            D = _spd(rng, n)
            L = np.empty((n, n))
            assert fl.cholesky(D, L)
            assert np.array_equal(L, _py_cholesky(D))
            assert np.array_equal(L, np.tril(L))
            assert np.all(np.abs(L @ L.T - D) <= 4 * (n + 1) * EPS * (np.abs(L) @ np.abs(L).T))
            # forward error: |ΔL| ≲ κ(D)·ε·|L| (Higham §10.1); 1e2 of slack on the constant
            Ln = np.linalg.cholesky(D)
            kappa = np.linalg.cond(D)
            assert np.abs(L - Ln).max() <= 1e2 * n * kappa * EPS * np.abs(Ln).max()


def test_cholesky_fails_where_lapack_does():
    L = np.empty((2, 2))
    assert not fl.cholesky(np.array([[1.0, 1.0], [1.0, 1.0]]), L)        # singular: pivot exactly 0
    assert not fl.cholesky(np.array([[1.0, 2.0], [2.0, 1.0]]), L)        # indefinite
    assert not fl.cholesky(np.array([[0.0, 0.0], [0.0, 1.0]]), L)        # a zero row
    assert not fl.cholesky(np.array([[np.nan, 0.0], [0.0, 1.0]]), L)
    for D in (np.array([[1.0, 1.0], [1.0, 1.0]]), np.array([[1.0, 2.0], [2.0, 1.0]])):
        with pytest.raises(np.linalg.LinAlgError):
            np.linalg.cholesky(D)


def _check_eigh(S, lam, V, c=8.0):
    n = S.shape[0]
    norm = max(np.abs(np.linalg.eigvalsh(S)).max(), 1e-300)
    assert np.all(np.diff(lam) >= 0.0)
    assert np.abs(lam - np.linalg.eigvalsh(S)).max() <= c * n * EPS * norm
    assert np.abs(V @ np.diag(lam) @ V.T - S).max() <= c * n * EPS * norm
    assert np.abs(V.T @ V - np.eye(n)).max() <= c * n * EPS


def test_jacobi_against_lapack_on_random_symmetric_matrices():
    rng = np.random.default_rng(3)
    for n in SIZES:
        for _ in range(100):
            S = _spd(rng, n) if _ % 2 else (lambda M: M + M.T)(rng.standard_normal((n, n)))
            lam, V = fl.eigh_jacobi(S)
            _check_eigh(S, lam, V)
            ln, Vn = np.linalg.eigh(S)
            norm = np.abs(ln).max()
            for j in range(n):       # eigenvectors where the gap to the others is > 1e-6·‖S‖
                gap = np.min(np.abs(np.delete(ln, j) - ln[j])) if n > 1 else np.inf
                if gap > 1e-6 * norm:
                    c = float(V[:, j] @ Vn[:, j])
                    sin = float(np.linalg.norm(V[:, j] - c * Vn[:, j]))     # |sin θ|, no cancellation
                    assert sin <= 64 * n * EPS * norm / gap + 1e-15


def test_jacobi_on_repeated_zero_and_diagonal_spectra():
    rng = np.random.default_rng(4)
    Q, _ = np.linalg.qr(rng.standard_normal((6, 6)))
    S = Q @ np.diag([1.0, 1.0, 2.0, 2.0, 2.0, 5.0]) @ Q.T
    S = 0.5 * (S + S.T)
    lam, V = fl.eigh_jacobi(S)
    _check_eigh(S, lam, V)
    B = rng.standard_normal((8, 2))
    P = B @ B.T                                       # rank 2: six zero eigenvalues
    lam, V = fl.eigh_jacobi(P)
    _check_eigh(P, lam, V)
    assert np.sum(lam > 1e-13 * lam.max()) == 2
    lam, V = fl.eigh_jacobi(np.diag([3.0, -1.0, 2.0]))
    assert lam.tolist() == [-1.0, 2.0, 3.0] and np.array_equal(np.abs(V), np.eye(3)[:, [1, 2, 0]])
    lam, V = fl.eigh_jacobi(np.zeros((4, 4)))
    assert lam.tolist() == [0.0] * 4 and np.array_equal(V, np.eye(4))
    lam, V = fl.eigh_jacobi(np.array([[1.0, 1e-300], [1e-300, 1.0]]))     # below the stopping rule
    assert lam.tolist() == [1.0, 1.0]
    lam, V = fl.eigh_jacobi(np.array([[1e-200, 1.0], [1.0, -1e-200]]))   # θ near 0
    assert abs(lam[0] + 1.0) <= 2 * EPS and abs(lam[1] - 1.0) <= 2 * EPS
    lam, V = fl.eigh_jacobi(np.array([[1e200, 1e-160], [1e-160, -1e200]]))  # |θ| > 1e150
    assert lam.tolist() == [-1e200, 1e200]


def test_jacobi_stops_within_its_sweep_limit_on_graded_matrices():
    """Entries spanning 20 decades (as the plants' covariances: x1 ~ 1e-10 rad, d ~ 1 ozf·in)."""
    rng = np.random.default_rng(5)
    for _ in range(200):
        n = 8
        d = np.exp(rng.uniform(-23, 0, n))
        C = _spd(rng, n, 0.5)
        C = C / np.sqrt(np.outer(np.diag(C), np.diag(C)))
        S = C * np.outer(d, d)
        lam, V = fl.eigh_jacobi(S)
        _check_eigh(S, lam, V)


def test_hermitian_pinv_against_numpy_and_penrose():
    rng = np.random.default_rng(6)
    for n in SIZES:
        for _ in range(50):
            S = _spd(rng, n, 1.0)
            H = 0.5 * (S + S.T) - 0.1 * np.trace(S) * np.eye(n)
            P = fl.pinv_hermitian(H, 1e-13)
            Pn = np.linalg.pinv(H, 1e-13, hermitian=True)
            kappa = np.linalg.cond(H)
            assert np.abs(P - Pn).max() <= 64 * n * kappa * EPS * np.abs(Pn).max()
    B = rng.standard_normal((5, 3))
    A = B @ B.T                                       # singular, rank 3
    P = fl.pinv_hermitian(A, 1e-13)
    scale = np.abs(A).max()
    assert np.abs(A @ P @ A - A).max() <= 1e-12 * scale
    assert np.abs(P @ A @ P - P).max() <= 1e-12 * np.abs(P).max()
    assert np.abs(P - np.linalg.pinv(A, 1e-13, hermitian=True)).max() <= 1e-10 * np.abs(P).max()


def test_the_disturbed_plants_covariances_factor_to_rounding():
    """Q(h) of every mode over the ladder's widths (semi-definite: zero rows and, at short
    widths, near-singular blocks): the compiled noise factor B·Bᵀ reproduces Q's non-zero block."""
    from bench.scenarios import builtin_scenarios
    from plant.multimode import disturbed, disturbed_jit

    p = builtin_scenarios()["disturbed"].params
    for mode in (1, 2, 3):
        for h in (1e-3 * 2.0 ** -k for k in range(0, 30, 3)):
            _, Q = disturbed._closed_form(p, mode, h)
            rows = np.empty(8, np.int64)
            Bflat = np.empty(64)
            m = disturbed_jit._noise_factor(Q, rows, Bflat)
            mm = abs(m)
            r = rows[:mm]
            B = Bflat[:mm * mm].reshape((mm, mm))
            D = Q[np.ix_(r, r)]
            d = np.sqrt(np.diag(D))
            err = np.abs(B @ B.T - D) / np.outer(d, d)
            assert err.max() <= 1e-13, (mode, h, m, err.max())
            f = disturbed.noise_factor(Q)
            assert np.array_equal(f.rows, r) and np.array_equal(f.B, B)
