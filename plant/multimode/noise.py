"""Minimal factorization of a covariance for sampling, (4-20)–(4-34).

A Gaussian vector N with covariance C is drawn as N = A·z with z ~ N(0, I_m) and A·Aᵀ = C.
The seed's construction (4-20) is A = R·B: R (n × m, zeros and ones, RᵀR = I) keeps the m
non-zero rows of C (4-28), and B is the lower-triangular Cholesky factor of D = RᵀCR with a
positive diagonal (4-22)–(4-34). One unit normal is drawn per non-zero row.

When D is singular although no row is zero (for instance perfectly correlated entries), the
Cholesky factor does not exist; B then comes from the eigen-decomposition of the diagonally
scaled D (B = S⁻¹·V·√Λ), which still satisfies B·Bᵀ = D.

Both factorizations and the product B·z are :mod:`plant.fixed_linalg`'s fixed-order loops (the
Cholesky–Crout column loop, cyclic Jacobi, k-ascending sums), not LAPACK/BLAS: the same bits on
every CPU (docs/results.md, "Reproducibility across machines").
"""

from __future__ import annotations

import numpy as np

from plant.fixed_linalg import cholesky, eigh_jacobi, mat_vec

__all__ = ["noise_factor", "NoiseFactor"]


class NoiseFactor:
    """A = R·B for one covariance; ``sample(z)`` maps m unit normals to the n-vector N."""

    __slots__ = ("rows", "B", "n")

    def __init__(self, rows: np.ndarray, B: np.ndarray, n: int) -> None:
        self.rows = rows
        self.B = B
        self.n = n

    @property
    def m(self) -> int:
        """Number of unit normals one sample consumes (non-zero rows of C)."""
        return len(self.rows)

    @property
    def A(self) -> np.ndarray:
        """The n × m factor A = R·B  (4-20)."""
        A = np.zeros((self.n, self.m))
        A[self.rows, :] = self.B
        return A

    def sample(self, z: np.ndarray) -> np.ndarray:
        out = np.zeros(self.n)
        if self.m:
            y = np.empty(self.m)
            mat_vec(self.B, np.ascontiguousarray(z, dtype=float), y)
            out[self.rows] = y
        return out


def noise_factor(C: np.ndarray) -> NoiseFactor:
    """Factor a symmetric positive-semi-definite C as R·B, (4-20)–(4-34).

    Raises
    ------
    ValueError
        If C is not square, not finite, not symmetric, or has a negative eigenvalue beyond
        round-off.
    """
    C = np.asarray(C, dtype=float)
    if C.ndim != 2 or C.shape[0] != C.shape[1]:
        raise ValueError(f"covariance must be a square matrix, got shape {C.shape}")
    if not np.all(np.isfinite(C)):
        raise ValueError("covariance must be finite")
    scale = np.max(np.abs(C)) if C.size else 0.0
    if not (C == C.T).all() and not np.allclose(C, C.T, rtol=1e-10, atol=1e-14 * scale):
        raise ValueError("covariance must be symmetric")
    rows = np.flatnonzero(np.any(C != 0.0, axis=1))   # k(i) of (4-28)
    D = C[np.ix_(rows, rows)]                          # D = RᵀCR  (4-26)
    if len(rows) == 0:
        return NoiseFactor(rows, np.zeros((0, 0)), C.shape[0])
    B = np.empty(D.shape)
    if not cholesky(np.ascontiguousarray(D), B):     # (4-29)–(4-34)
        B = _eigen_factor(D)
    return NoiseFactor(rows, B, C.shape[0])


def _eigen_factor(D: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.abs(np.diag(D)))
    d[d == 0] = 1.0
    Ds = D / np.outer(d, d)
    lam, V = eigh_jacobi(0.5 * (Ds + Ds.T))
    tol = 1e-10 * max(lam.max(initial=0.0), 1e-300)
    if lam.min(initial=0.0) < -tol:
        raise ValueError(f"covariance is not positive semi-definite (eigenvalue {lam.min():.3g})")
    return (V * np.sqrt(np.clip(lam, 0.0, None))) * d[:, None]
