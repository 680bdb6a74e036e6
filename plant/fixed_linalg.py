"""Small dense linear algebra in a fixed order of operations: the same bits on every x86-64 CPU.

Why: numpy's ``@``/``np.dot`` and ``np.linalg`` (and scipy's BLAS/LAPACK that numba calls) go
through OpenBLAS, which picks its kernel by CPU (or ``OPENBLAS_CORETYPE``); each kernel sums in
its own order, so the plants' noise factors and bridge laws differed in their last bits between
machines, and stick-slip amplified that into different rows (docs/results.md, "Reproducibility
across machines"). Every routine here is a plain loop compiled by numba (no fast-math: LLVM
neither reassociates nor contracts to FMA), on IEEE doubles with ``+ − × ÷``, ``math.sqrt`` and
(:func:`gemv_lanes` only) an explicit fused multiply–add (LLVM's ``llvm.fma.f64``: one rounding,
in hardware or libm) — all correctly rounded, so a result depends on the inputs alone. The matrices are small
(≤ 10 × 10: the plants' noise covariances and bridge laws); the loops are cheaper than a BLAS
call from numba at these sizes.

Orders of operations (all sums run over the index ascending, starting from 0.0 or the first
named term):

* :func:`gemv_lanes` ``y = A·x`` in the order of OpenBLAS's Haswell ``dgemv_t`` (the plants'
  sub-step products, kept in the order their rows were first computed in): four FMA lanes
  l_j = fma(A[i,k], x[k], l_j) over k = j, j + 4, … < m − m mod 4, y = (l0 + l2) + (l1 + l3),
  then the 1–3 remaining terms: y = fma(a, x, y); y + fma(a0, x0, a1·x1);
  y + fma(a2, x2, fma(a0, x0, a1·x1)).
* :func:`mat_vec` ``y_i = Σ_k A[i,k]·x[k]``; :func:`mat_mat` ``C_ij = Σ_k A[i,k]·B[k,j]``;
  :func:`mat_mat_t` ``C_ij = Σ_k A[i,k]·B[j,k]`` (A·Bᵀ); :func:`gram` ``C = B·Bᵀ`` as
  :func:`mat_mat_t` on i ≤ j, mirrored (exactly symmetric).
* :func:`cholesky` (Cholesky–Crout, column by column, Golub & Van Loan, *Matrix Computations*,
  4th ed., Alg. 4.2.1): ``d = D[j,j] − Σ_{k<j} L[j,k]²``, ``L[j,j] = √d``,
  ``L[i,j] = (D[i,j] − Σ_{k<j} L[i,k]·L[j,k]) / L[j,j]`` for i > j, the sums subtracted term by
  term in k order; fails (returns False) at the first pivot d that is not > 0 (as LAPACK dpotrf:
  D not positive definite to working precision).
* :func:`eigh_jacobi`: the symmetric eigenproblem by the cyclic Jacobi method (Golub & Van Loan
  Alg. 8.5.3) with Rutishauser's rotation formulas (Wilkinson & Reinsch, *Handbook*, II/1):
  sweeps over (p, q), p = 0…n−2, q = p+1…n−1 in that order; the pair is annihilated unless
  |a_pq| ≤ ε·√(|a_pp|·|a_qq|) (ε = 2⁻⁵³; it is then set to 0: the relative-accuracy stopping rule
  of Demmel & Veselić, SIAM J. Matrix Anal. Appl. 13(4), 1992) or a_pq = 0; the iteration stops
  after the first sweep that rotates nothing (at most :data:`MAX_SWEEPS`). Eigenvalues ascending
  (a stable insertion sort: equal values keep their diagonal order), eigenvectors the columns of
  V, as numpy.linalg.eigh; V·diag(λ)·Vᵀ = S and VᵀV = I to a few ulps·n.
* :func:`pinv_hermitian`: numpy.linalg.pinv(A, rcond, hermitian=True)'s recipe on
  :func:`eigh_jacobi`: 1/λ where |λ| > rcond·max|λ|, else 0, summed as
  ``P_ij = Σ_k (V[i,k]·w_k)·V[j,k]`` over k ascending.

Units: whatever the caller's matrix carries (covariances in the plant state's units squared).
"""

from __future__ import annotations

import math

import llvmlite.ir as ir
import numpy as np
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["fma", "gemv_lanes", "mat_vec", "mat_mat", "mat_mat_t", "gram", "cholesky", "eigh_jacobi", "pinv_hermitian", "MAX_SWEEPS"]

MAX_SWEEPS = 60         # cyclic Jacobi converges quadratically: ≤ 10 sweeps for n ≤ 10 in practice
_EPS = 2.0 ** -53


@intrinsic
def fma(typingctx, a, b, c):
    """a·b + c with one rounding (LLVM's llvm.fma.f64); controllers._fma calls this one."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True)
def gemv_lanes(A, x, out):
    """out = A·x (A n × m) in OpenBLAS's Haswell dgemv_t order (module docstring): numpy's product
    on such a machine, bit for bit (tests/test_disturbed_jit.py), with no BLAS call; ~20× cheaper
    than one from numba at these sizes."""
    n, m = A.shape
    m1 = m - (m & 3)
    r = m - m1
    for i in range(n):
        y = 0.0
        if m1 > 0:
            a0 = a1 = a2 = a3 = 0.0
            for k in range(0, m1, 4):
                a0 = fma(A[i, k], x[k], a0)
                a1 = fma(A[i, k + 1], x[k + 1], a1)
                a2 = fma(A[i, k + 2], x[k + 2], a2)
                a3 = fma(A[i, k + 3], x[k + 3], a3)
            y = (a0 + a2) + (a1 + a3)
        if r == 1:
            y = fma(A[i, m1], x[m1], y)
        elif r == 2:
            y = y + fma(A[i, m1], x[m1], A[i, m1 + 1] * x[m1 + 1])
        elif r == 3:
            y = y + fma(A[i, m1 + 2], x[m1 + 2], fma(A[i, m1], x[m1], A[i, m1 + 1] * x[m1 + 1]))
        out[i] = y


@njit(cache=True)
def mat_vec(A, x, out):
    """out[i] = Σ_k A[i, k]·x[k] (k ascending) for i < A.shape[0]."""
    n, m = A.shape
    for i in range(n):
        acc = 0.0
        for k in range(m):
            acc += A[i, k] * x[k]
        out[i] = acc


@njit(cache=True)
def mat_mat(A, B):
    """A·B: C[i, j] = Σ_k A[i, k]·B[k, j] (k ascending)."""
    n, m = A.shape
    p = B.shape[1]
    C = np.empty((n, p))
    for i in range(n):
        for j in range(p):
            acc = 0.0
            for k in range(m):
                acc += A[i, k] * B[k, j]
            C[i, j] = acc
    return C


@njit(cache=True)
def mat_mat_t(A, B):
    """A·Bᵀ: C[i, j] = Σ_k A[i, k]·B[j, k] (k ascending)."""
    n, m = A.shape
    p = B.shape[0]
    C = np.empty((n, p))
    for i in range(n):
        for j in range(p):
            acc = 0.0
            for k in range(m):
                acc += A[i, k] * B[j, k]
            C[i, j] = acc
    return C


@njit(cache=True)
def gram(B):
    """B·Bᵀ, exactly symmetric: the upper triangle as :func:`mat_mat_t`, mirrored."""
    n, m = B.shape
    C = np.empty((n, n))
    for i in range(n):
        for j in range(i, n):
            acc = 0.0
            for k in range(m):
                acc += B[i, k] * B[j, k]
            C[i, j] = acc
            C[j, i] = acc
    return C


@njit(cache=True)
def cholesky(D, L):
    """Lower-triangular L with L·Lᵀ = D into ``L`` (module docstring's order); False, L partly
    written, when D is not positive definite to working precision (a pivot not > 0, or NaN)."""
    n = D.shape[0]
    for i in range(n):
        for j in range(n):
            L[i, j] = 0.0
    for j in range(n):
        d = D[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return False
        piv = math.sqrt(d)
        L[j, j] = piv
        for i in range(j + 1, n):
            acc = D[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = acc / piv
    return True


@njit(cache=True)
def eigh_jacobi(S):
    """(λ ascending, V): S = V·diag(λ)·Vᵀ for a symmetric S (only its upper triangle and diagonal
    are read), by cyclic Jacobi (module docstring: sweep order, rotation, stopping rule)."""
    n = S.shape[0]
    a = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            a[i, j] = S[i, j] if i <= j else S[j, i]
    V = np.zeros((n, n))
    for i in range(n):
        V[i, i] = 1.0
    for sweep in range(MAX_SWEEPS):
        rotated = False
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                if abs(apq) <= _EPS * math.sqrt(abs(a[p, p]) * abs(a[q, q])):
                    a[p, q] = 0.0
                    a[q, p] = 0.0
                    continue
                rotated = True
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                if abs(theta) > 1e150:                 # θ² would overflow: t = 1/(2θ) to working precision
                    t = 0.5 / theta
                else:
                    t = 1.0 / (abs(theta) + math.sqrt(theta * theta + 1.0))
                    if theta < 0.0:
                        t = -t
                c = 1.0 / math.sqrt(t * t + 1.0)
                s = t * c
                tau = s / (1.0 + c)
                a[p, p] = a[p, p] - t * apq
                a[q, q] = a[q, q] + t * apq
                a[p, q] = 0.0
                a[q, p] = 0.0
                for r in range(n):
                    if r != p and r != q:
                        arp = a[r, p]
                        arq = a[r, q]
                        a[r, p] = arp - s * (arq + tau * arp)
                        a[r, q] = arq + s * (arp - tau * arq)
                        a[p, r] = a[r, p]
                        a[q, r] = a[r, q]
                for r in range(n):
                    vrp = V[r, p]
                    vrq = V[r, q]
                    V[r, p] = vrp - s * (vrq + tau * vrp)
                    V[r, q] = vrq + s * (vrp - tau * vrq)
        if not rotated:
            break
    lam = np.empty(n)
    for i in range(n):
        lam[i] = a[i, i]
    order = np.arange(n)
    for i in range(1, n):                              # stable insertion sort, ascending
        j = i
        while j > 0 and lam[order[j - 1]] > lam[order[j]]:
            order[j - 1], order[j] = order[j], order[j - 1]
            j -= 1
    lo = np.empty(n)
    Vo = np.empty((n, n))
    for j in range(n):
        lo[j] = lam[order[j]]
        for i in range(n):
            Vo[i, j] = V[i, order[j]]
    return lo, Vo


@njit(cache=True)
def pinv_hermitian(A, rcond):
    """The pseudo-inverse of a symmetric A: 1/λ above rcond·max|λ| on :func:`eigh_jacobi`'s
    spectrum, 0 below (numpy.linalg.pinv(A, rcond, hermitian=True)'s rule)."""
    n = A.shape[0]
    lam, V = eigh_jacobi(A)
    top = 0.0
    for j in range(n):
        top = max(top, abs(lam[j]))
    cutoff = rcond * top
    w = np.empty(n)
    for j in range(n):
        w[j] = 1.0 / lam[j] if abs(lam[j]) > cutoff else 0.0
    P = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            acc = 0.0
            for k in range(n):
                acc += (V[i, k] * w[k]) * V[j, k]
            P[i, j] = acc
    return P
