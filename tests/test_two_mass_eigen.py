"""plant.two_mass.eigen (the cores' closed-form eigen-decompositions) against LAPACK's eig.

For the moving (5 × 5, and 6 × 6 with the disturbance d) and stuck (3 × 3) cores of the
built-in compliant shaft and of light, heavy (overdamped: a real pair), undamped and stiff
variants: the eigenvalues equal np.linalg.eig's to 1e-12 relative to ‖A‖ (matched pairwise),
A·V = V·diag(λ) and V⁻¹·V = I to 1e-13 (the closed form is exact up to a few roundings per
entry), columns of unit norm, the rigid-body eigenvalue exactly 0 and no positive real part
(modes.first_root's bound needs it), complex pairs exact conjugates; and the singular case
(1/τ3 at a real shaft root) is refused.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.scenarios import builtin_scenarios
from plant.two_mass import disturbed
from plant.two_mass.eigen import core_modes
from plant.two_mass.modes import NCORE, core_matrix, decompose

BASE = builtin_scenarios()["compliant"].params
VARIANTS = {
    "compliant": BASE,
    "light-damping": dataclasses.replace(BASE, shaft_damping=0.05),
    "undamped": dataclasses.replace(BASE, shaft_damping=0.0),
    "overdamped": dataclasses.replace(BASE, shaft_damping=400.0),
    "stiff": dataclasses.replace(BASE, shaft_stiffness=4e6, motor_inertia=0.01),
}


def _check(A, V, Vi, lam):
    n = A.shape[0]
    scale = np.abs(A).max()
    ref = np.linalg.eigvals(A)
    got = list(lam)
    for r in ref:                       # match each LAPACK eigenvalue to the nearest closed-form one
        j = int(np.argmin([abs(g - r) for g in got]))
        assert abs(got[j] - r) <= 1e-12 * scale, (r, got[j])
        got.pop(j)
    assert np.abs(A @ V - V @ np.diag(lam)).max() <= 1e-13 * scale
    assert np.abs(Vi @ V - np.eye(n)).max() <= 1e-13
    assert np.allclose(np.linalg.norm(V, axis=0), 1.0, rtol=0, atol=4e-16 * n)
    assert np.all(lam.real <= 0.0)
    for i in range(n):
        if lam[i].imag != 0.0:
            j = [k for k in range(n) if lam[k] == lam[i].conjugate()]
            assert j and np.array_equal(V[:, j[0]], V[:, i].conj())


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_decompose_is_the_cores_eigen_decomposition(name):
    p = VARIANTS[name]
    V, Vi, lam = decompose(p)
    for row, mode in ((0, 1), (1, 3), (2, 2)):
        A, n = core_matrix(mode, p)
        _check(A, V[row, :n, :n], Vi[row, :n, :n], lam[row, :n])
        if mode != 2:
            assert 0.0 in lam[row, :n].tolist()      # the rigid body, exactly
        assert np.all(V[row, n:, :] == 0) and np.all(lam[row, n:] == 0) and n <= NCORE


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_the_disturbed_moving_core_with_d_is_its_eigen_decomposition(name):
    p = dataclasses.replace(VARIANTS[name], disturbance_torque_std=0.28, disturbance_torque_tau=0.02)
    for mode in (1, 3):
        A = disturbed.drift(p, mode)[0][np.ix_(disturbed._CORE, disturbed._CORE)]
        V, Vi, lam = disturbed._moving_modal.__wrapped__(p, mode)
        _check(A, V, Vi, lam)


def test_a_decay_rate_at_a_shaft_root_is_refused():
    """Overdamped shaft with 1/τ3 exactly at one real root: V would be singular."""
    a, Jm, k, c = BASE.alpha, BASE.motor_inertia, BASE.shaft_stiffness, 400.0
    mu = a + 1.0 / Jm
    p_, q_ = mu * c, mu * k
    root = -0.5 * (p_ + np.sqrt(p_ * p_ - 4 * q_))
    assert core_modes("moving", a, Jm, k, c, [(-root, (0.0, 0.0, 1.0 / Jm))]) is None
    assert core_modes("moving", a, Jm, k, c, [(-1.5 * root, (0.0, 0.0, 1.0 / Jm))]) is not None
