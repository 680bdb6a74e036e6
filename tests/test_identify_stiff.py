"""The fit's stiff-sliding step (issue 25, eleventh session) against independent truth.

While the shaft slides fast the bristle state relaxes at λ = σ0·|v|/g(v); the fit's explicit
Dormand–Prince step was then stability-bound and a lugre prediction cost ∝ σ0 (a low-friction dev
log at σ0 = 3e6: 97 % of its steps). Where λh would exceed ``fit._LUGRE_STIFF`` the fit's whole-
prediction path (plant.lugre.move_loop.play_all) takes an extrapolated linearly implicit Euler step
instead. The bound it must keep is the fit tolerance's (tests/test_identify_tolerance.py): every
sample within 0.01·σ1/√N = 6e-10 rad of the true response, so that a converged estimate moves by
< 0.01 of its standard error. Checked here:

* moves of the default plan on a low-friction axis (long slides, k̄c = 0.65) at σ0 = 3e6 (the fit's
  cap) and 1e6, and at a draws'-region point, against ``solve_ivp`` (Radau, rtol 1e-12) from rest;
* one extrapolated step on its own against Radau on the segment's ODE (plant.lugre.law.rhs), stiff
  (hλ ≈ 100): within its own error estimate's order of magnitude, and order ≥ 4 as H halves;
* that the stiff step runs where it should and cuts the counted work (else it buys nothing), and
  that with it off (``_Model.lugre_stiff = 0``) a prediction is the Dormand–Prince one, bit for bit.
"""

from __future__ import annotations


import numpy as np
import pytest
from scipy.integrate import solve_ivp

from plant.identification.fit import _LUGRE_STIFF, _Model, _WorkClock
from plant.lugre.law import rhs
from plant.lugre.move_loop import _lie_step_s
from plant.protocol import get_family
from tests.test_identify_tolerance import BOUND, _model, worst_against_radau


# (k̄c, k̄s − k̄c, J, τ3, v_s, σ0): a low-friction axis (dev log 4646 case 12's truth, rounded) at the
# fit's σ0 cap and at 1e6, and the draws' region's middle
LOW_FRICTION = [0.665, 0.55, 0.8, 0.008, 0.0052, 3e6]
POINTS = (LOW_FRICTION, LOW_FRICTION[:5] + [1e6], [1.2, 0.5, 0.5, 0.008, 0.006, 2e5])


def test_the_stiff_step_is_on_in_the_fit():
    assert _Model.lugre_stiff == _LUGRE_STIFF > 0.0


@pytest.mark.parametrize("point", [POINTS[0]] + [pytest.param(q, marks=pytest.mark.slow) for q in POINTS[1:]],
                         ids=["low-friction-3e6", "low-friction-1e6", "mid"])
def test_prediction_against_radau_within_the_bound(point):
    worst, checked = worst_against_radau(_model(), point)
    assert checked >= 8
    print(f"worst |prediction − Radau| {worst:.3g} rad over {checked} kinds of move")
    assert worst <= BOUND, f"{worst:.3g} rad > {BOUND:.3g} rad"


def _segment_truth(L, y, u, x30, H):
    """Radau (rtol 1e-13) on the segment ODE (v, z, D) of plant.lugre.law.rhs from y over H."""
    C = np.array([u, x30, 0.0, 0.0, 0.0])
    sol = solve_ivp(lambda t, w: rhs(t, w[0], w[1], w[2], C, L)[:3], (0.0, H), y, method="Radau",
                    rtol=1e-13, atol=[1e-16, 1e-20, 1e-20])
    return sol.y[:, -1]


def test_one_extrapolated_step_against_radau_stiff():
    """From fast sliding (v = 0.08 rad/s, z on its steady state g/σ0) under a decaying drive torque,
    steps of H = 6.4, 3.2, 1.6 ms (hλ ≈ 580–2300, far past the explicit step's stability bound ≈ 3.3):
    the result is within 10× its error estimate of Radau's (measured 0.4×), and the error falls at
    least 2⁵× per halving of H (measured 78–117×: order 6 in the stiff regime)."""
    p = get_family("lugre").Params().replace(coulomb=0.665, stiction=1.215, inertia=0.8, motor_time_constant=0.008,
                                             stribeck_velocity=0.0052, bristle_stiffness=3e6)
    L = p.law_vector()
    v = 0.08
    z = p.coulomb / p.bristle_stiffness         # g(v) ≈ k̄c at v ≫ v_s
    y = np.array([v, z, 0.0])
    u, x30 = -2.0, 3.0
    lam = p.bristle_stiffness * v / p.coulomb
    errs = []
    for H in (6.4e-3, 3.2e-3, 1.6e-3):
        assert H * lam > 500.0
        *yn, e0, e1, e2 = _lie_step_s(0.0, y[0], y[1], y[2], H, u, x30, 0.0, 0.0, L)
        ref = _segment_truth(L, y, u, x30, H)
        err = np.abs(np.array(yn) - ref)
        est = np.abs([e0, e1, e2])
        assert err[0] <= 10.0 * est[0] + 1e-15 and err[2] <= 10.0 * est[2] + 1e-18
        errs.append(err)
    print("errors (v, z, D)", errs)
    for i in (0, 2):                 # v, and the displacement the fit reads (z's error is at rounding)
        assert errs[0][i] / errs[1][i] >= 32.0 and errs[1][i] / errs[2][i] >= 32.0


def test_the_stiff_step_runs_and_cuts_the_work_within_the_bound_of_dormand_prince():
    stiff, dp = _model(), _model()
    dp.lugre_stiff = 0.0
    for point in POINTS:
        z = np.log(point)
        stiff.clock, dp.clock = _WorkClock(), _WorkClock()
        a, b = stiff.predict(z), dp.predict(z)
        assert a is not None and b is not None
        assert np.max(np.abs(a - b)) <= BOUND
        assert stiff.clock.spent < dp.clock.spent
    # at the cap on the low-friction axis the explicit step was stability-bound: ≥ 5× less counted work
    z = np.log(LOW_FRICTION)
    stiff.clock, dp.clock = _WorkClock(), _WorkClock()
    stiff.predict(z)
    dp.predict(z)
    assert stiff.clock.spent < 0.2 * dp.clock.spent


def test_with_the_stiff_step_off_a_prediction_is_dormand_prince_bit_for_bit():
    """lugre_stiff = 0 is the path before (the per-move compiled path has the plant's step alone)."""
    off, per_move = _model(), _model()
    off.lugre_stiff = 0.0
    per_move.whole_moves = False
    z = np.log(LOW_FRICTION[:5] + [1e6])
    assert np.array_equal(off.predict(z), per_move.predict(z))
