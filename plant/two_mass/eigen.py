"""The two-mass cores' eigen-decompositions in closed form: A = V·diag(λ)·V⁻¹ without LAPACK.

Why: ``np.linalg.eig`` and ``inv`` go through OpenBLAS/LAPACK, whose kernel (chosen by CPU)
rounds in its own order; the modal forms, and through stick-slip the rows of ``compliant``,
then differed between machines (docs/results.md, "Reproducibility across machines"). The
cores are block upper triangular, so their eigenvectors follow on paper; here they are
evaluated with Python floats and complexes (``+ − × ÷``, ``math.sqrt``: correctly rounded, the
same on every CPU).

**The shaft block.** Moving (plant.two_mass.modes), on t = [x2, φ, ω_m] with a = 1/J,
μ = a + 1/J_m [1/(oz·in·s²)], k [ozf·in/rad], c [ozf·in·s/rad]::

    T = [[−a·c, a·k, a·c], [−1, 0, 1], [c/J_m, −k/J_m, −c/J_m]]

has λ = 0 (rigid body) with right vector [1, 0, 1] and left vector [J, 0, J_m]/(J + J_m)
(momentum), and the shaft pair λ² + μ·c·λ + μ·k = 0 (q = ω_m − x2, φ̇ = q,
q̇ = −μ·(k·φ + c·q)) with right vector [−a·λ, μ, λ/J_m] and left vector [−1, λ + μ·c, 1]
divided by their product μ·(2λ + μ·c). Stuck, on [φ, ω_m] (x2 ≡ 0)::

    T = [[0, 1], [−k/J_m, −c/J_m]]

has λ² + (c/J_m)·λ + k/J_m = 0, right vector [1, λ], left vector [λ + c/J_m, 1]/(2λ + c/J_m).
The pair: complex −p/2 ± i·√(q − p²/4) (p the λ coefficient, q the constant); real, the root
−(p + √(p² − 4q))/2 and q over it (no cancellation); the second member of a complex pair is the
exact conjugate of the first. TwoMassParams rejects a critically damped shaft (a double root).

**The decoupled states.** Each further state s_j of the core (x3, x5, the disturbance d) obeys
ṡ_j = −β_j·s_j + input and enters the shaft block through a column r_j. Its eigenvalue is
λ = −β_j, right vector [t_j, e_j] with (T − λI)·t_j = −r_j solved in closed form (moving: with
R = −r_j, φ = −(R2 − R0 + (μc + λ)·R1)/(λ² + μcλ + μk), q = R1 + λφ, x2 = (a·(kφ + cq) − R0)/λ,
ω_m = x2 + q; stuck: φ = −(R1 + (c/J_m + λ)·R0)/(λ² + (c/J_m)λ + k/J_m), ω_m = R0 + λφ), left
vector e_j.
A shaft mode's left vector gains u·r_j/(λ + β_j) in slot j. Right vectors are scaled to unit
Euclidean norm (as LAPACK's), each left vector by the inverse factor, so V⁻¹·V = I.

Orders: modes [0, λ₊, λ₋, then the decoupled states in core order] moving, [λ₊, λ₋, x3] stuck.
A decoupled λ = −β_j within ``DEFECTIVE``·(λ² + |p·λ| + q) of a shaft root makes V singular to
working precision (the shaft's characteristic polynomial vanishes there): :func:`core_modes`
then returns None.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["core_modes", "DEFECTIVE"]

DEFECTIVE = 1e-8


def _pair(p: float, q: float) -> tuple[complex, complex]:
    """The roots of λ² + p·λ + q = 0 (p, q ≥ 0, not a double root), complex ones conjugate."""
    disc = p * p - 4.0 * q
    if disc < 0.0:
        re = -0.5 * p
        im = 0.5 * math.sqrt(-disc)
        return complex(re, im), complex(re, -im)
    big = -0.5 * (p + math.sqrt(disc))
    return complex(big), complex(q / big)


def _unit(v: list) -> tuple[list, float]:
    """v / ‖v‖₂ and ‖v‖₂ (the sum of |v_i|² in index order)."""
    s = 0.0
    for x in v:
        s += x.real * x.real + x.imag * x.imag
    n = math.sqrt(s)
    return [x / n for x in v], n


def core_modes(kind: str, alpha: float, motor_inertia: float, k: float, c: float,
               decoupled: list[tuple[float, tuple[float, ...]]]):
    """(V, V⁻¹, λ) of a two-mass core, or None when V would be singular (module docstring).

    ``kind``: "moving" (shaft block [x2, φ, ω_m]) or "stuck" ([φ, ω_m]); ``decoupled``: one
    (β_j [1/s], r_j) per further core state in order, r_j its column in the shaft block's rows.
    Complex arrays, V's columns the right eigenvectors, V⁻¹'s rows the left ones.
    """
    a, Jm = alpha, motor_inertia
    if kind == "moving":
        mu = a + 1.0 / Jm
        p, q = mu * c, mu * k
        nt = 3
        lp, lm = _pair(p, q)
        lams = [0j, lp]
        right = [[1 + 0j, 0j, 1 + 0j], [-a * lp, complex(mu), lp / Jm]]
        inv_m = 1.0 / a + Jm
        left = [[(1.0 / a) / inv_m + 0j, 0j, Jm / inv_m + 0j],
                [x / (mu * (2.0 * lp + p)) for x in (-1 + 0j, lp + p, 1 + 0j)]]
    else:
        p, q = c / Jm, k / Jm
        nt = 2
        lp, lm = _pair(p, q)
        lams = [lp]
        right = [[1 + 0j, lp]]
        left = [[x / (2.0 * lp + p) for x in (lp + p, 1 + 0j)]]
    # the pair's second member: the exact conjugate (real pair: computed)
    if lp.imag != 0.0:
        lams.append(lp.conjugate())
        right.append([x.conjugate() for x in right[-1]])
        left.append([x.conjugate() for x in left[-1]])
    else:
        lams.append(lm)
        if kind == "moving":
            right.append([-a * lm, complex(mu), lm / Jm])
            left.append([x / (mu * (2.0 * lm + p)) for x in (-1 + 0j, lm + p, 1 + 0j)])
        else:
            right.append([1 + 0j, lm])
            left.append([x / (2.0 * lm + p) for x in (lm + p, 1 + 0j)])
    for beta, _ in decoupled:                 # −β at a shaft root: V singular (module docstring)
        ell = -beta
        if abs(ell * ell + p * ell + q) <= DEFECTIVE * (ell * ell + abs(p * ell) + q):
            return None
    nshaft = len(lams)
    n = nt + len(decoupled)
    V = np.zeros((n, n), dtype=np.complex128)
    Vi = np.zeros((n, n), dtype=np.complex128)
    lam = np.zeros(n, dtype=np.complex128)
    for i in range(nshaft):
        v, norm = _unit(right[i])
        for r in range(nt):
            V[r, i] = v[r]
            Vi[i, r] = left[i][r] * norm
        lam[i] = lams[i]
        for j, (beta, col) in enumerate(decoupled):
            acc = 0j
            for r in range(nt):
                acc += left[i][r] * col[r]
            Vi[i, nt + j] = (acc / (lams[i] + beta)) * norm
    for j, (beta, col) in enumerate(decoupled):
        ell = -beta
        den = ell * ell + p * ell + q
        R = [-x for x in col]
        if kind == "moving":
            phi = -(R[2] - R[0] + (p + ell) * R[1]) / den
            qv = R[1] + ell * phi
            x2 = (a * (k * phi + c * qv) - R[0]) / ell
            t = [x2, phi, x2 + qv]
        else:
            phi = -(R[1] + (p + ell) * R[0]) / den
            t = [phi, R[0] + ell * phi]
        v, norm = _unit([complex(x) for x in t] + [complex(1.0 if jj == j else 0.0) for jj in range(len(decoupled))])
        for r in range(n):
            V[r, nt + j] = v[r]
        Vi[nt + j, nt + j] = norm
        lam[nt + j] = ell
    return V, Vi, lam
