"""The linear designs' discrete transfer functions in plain float arithmetic (controllers/discrete_tf.py)
and observer-pid's closed-form observer design, against python-control, scipy's expm and mpmath at
40 digits. Why they exist: docs/results.md, "Reproducibility across machines"."""

from __future__ import annotations

import cmath
import math

import control as ct
import mpmath
import numpy as np
import pytest
import scipy.linalg

from controllers.discrete_tf import margins, poly_add, poly_eval, poly_mul, tustin_first_order, zoh_gimbal
from controllers.linear import design_linear
from controllers.observer_pid import _ackermann, _observer_design, _zoh
from plant.params import PlantParams

mpmath.mp.dps = 40


def _mp_polyval(coeffs, z):
    """c(z) at 40 digits, coefficients highest power first, by Horner's rule."""
    acc = mpmath.mpc(0)
    for c in coeffs:
        acc = acc * z + mpmath.mpf(float(c))
    return acc


def _mp_zoh_response(J: float, tau3: float, ts: float, z: complex) -> complex:
    """Pd(z) = C·(zI − Φ)⁻¹·Γ with [Φ Γ; 0 1] = expm([F G; 0 0]·τs) at 40 digits, states (c, ċ, x3)."""
    F = mpmath.matrix([[0, 1, 0, 0], [0, 0, mpmath.mpf(1) / J, 0], [0, 0, -mpmath.mpf(1) / tau3, mpmath.mpf(1) / tau3],
                       [0, 0, 0, 0]])
    E = mpmath.expm(F * ts)
    Phi = E[0:3, 0:3]
    Gam = E[0:3, 3]
    M = mpmath.mpc(z) * mpmath.eye(3) - Phi
    x = mpmath.lu_solve(M, Gam)
    return complex(x[0])


@pytest.mark.parametrize("J, tau3, ts", [(0.5, 0.008, 0.01), (0.5, 0.008, 0.001), (2.0, 0.05, 0.01), (0.1, 1.0, 0.001)])
def test_zoh_gimbal_is_the_exact_zoh_of_the_gimbal_loop(J, tau3, ts):
    """The float coefficients, evaluated at 40 digits (so that only their rounding is tested, not
    the cancellation of evaluating (z − 1)² near z = 1), give the exact response to 1e-13, also
    where τs ≪ τ3 (the cancellation-free remainders)."""
    num, den = zoh_gimbal(J, tau3, ts)
    for theta in (0.05, 0.1, 1.0, 2.5):
        z = cmath.exp(1j * theta)
        ref = _mp_zoh_response(J, tau3, ts, z)
        zm = mpmath.mpc(z)
        got = complex(_mp_polyval(num, zm) / _mp_polyval(den, zm))
        # each coefficient's rounding (half an ulp) moves the value by at most its condition number:
        # Σ|cₖ|/|c(z)|, large near z = 1, where |den| ≈ θ²·|z − p|
        cond = (sum(abs(c) for c in num) / abs(poly_eval(num, z)) + sum(abs(c) for c in den) / abs(poly_eval(den, z)))
        assert abs(got - ref) <= (1e-13 + 2.0 ** -52 * cond) * abs(ref), (theta, ref, cond)
    # python-control's route (expm, then ss2tf) agrees to the 6–9 digits its numerator keeps
    # (ss2tf's cancellation; worst where τs ≪ τ3); the 40-digit check above is the truth
    ref = ct.sample_system(ct.tf([1.0], [tau3 * J, J, 0.0, 0.0]), ts, method="zoh")
    np.testing.assert_allclose(den, ref.den[0][0], rtol=1e-12)
    np.testing.assert_allclose(num, ref.num[0][0][-3:], rtol=1e-5)


def test_tustin_first_order_matches_python_control_and_is_exact_at_the_prewarp_frequency():
    ts, w = 0.01, 48.7
    for num, den in (((1.0, 4.87), (1.0, 0.81)), ((1.0, 4.87), (1.0, 0.0)), ((0.05, 1.0), (0.008, 1.0))):
        n, d = tustin_first_order(num, den, ts, w)
        ref = ct.sample_system(ct.tf(list(num), list(den)), ts, method="tustin", prewarp_frequency=w)
        np.testing.assert_allclose(n, ref.num[0][0], rtol=1e-12)
        np.testing.assert_allclose(d, ref.den[0][0], rtol=1e-12, atol=1e-15)
        z = cmath.exp(1j * w * ts)
        s = 1j * w
        h_c = (num[0] * s + num[1]) / (den[0] * s + den[1])
        assert abs(poly_eval(n, z) / poly_eval(d, z) - h_c) <= 1e-13 * abs(h_c)


def test_poly_ops_are_numpys():
    rng = np.random.default_rng(5)
    for _ in range(20):
        a, b = rng.normal(size=rng.integers(1, 6)), rng.normal(size=rng.integers(1, 6))
        np.testing.assert_allclose(poly_mul(a, b), np.polymul(a, b), rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(poly_add(a, b), np.polyadd(a, b), rtol=0, atol=0)
        z = complex(*rng.normal(size=2))
        assert abs(poly_eval(a, z) - np.polyval(a, z)) <= 1e-13 * max(1.0, abs(np.polyval(a, z)))


def _mp_loop(num, den, w, ts):
    z = mpmath.exp(1j * mpmath.mpf(w) * ts)
    return _mp_polyval(num, z) / _mp_polyval(den, z)


@pytest.mark.parametrize("kw", [dict(), dict(integral=True), dict(lag_ratio=1.0), dict(crossover=20.0),
                                dict(crossover=30.0, integral=True)])
def test_margins_are_the_crossings_of_the_loop(kw):
    """Each gain crossover has |L| = 1 and each phase crossover Im L = 0, Re L < 0 (40-digit
    evaluation, to 1e-10: float evaluation of L near its crossings); the crossings are python-control's (``poly`` method) to its accuracy, but for its
    ω → 0 artefact (a 'phase crossover' with |L| > 1e6 where the double integrator's phase tends to
    −180°)."""
    d = design_linear(PlantParams(), **kw)
    num, den, ts = d.open_loop.num[0][0], d.open_loop.den[0][0], d.open_loop.dt
    gm, pm, w_pc, w_gc = margins(num, den, ts)
    assert w_gc and all(abs(abs(_mp_loop(num, den, w, ts)) - 1) < 1e-12 for w in w_gc)
    for w, g in zip(w_pc, gm):
        v = _mp_loop(num, den, w, ts)
        assert abs(v.imag) < 1e-10 * abs(v) and v.real < 0 and abs(g * abs(v) - 1) < 1e-10
    for w, p in zip(w_gc, pm):
        assert abs(p - (math.degrees(float(mpmath.arg(_mp_loop(num, den, w, ts)))) % 360.0 - 180.0)) < 1e-9
    rgm, rpm, _, rw_pc, rw_gc, _ = ct.stability_margins(d.open_loop, method="poly", returnall=True)
    keep = np.asarray(rgm) > 1e-6
    np.testing.assert_allclose(w_pc, np.asarray(rw_pc)[keep], rtol=1e-6)
    np.testing.assert_allclose(gm, np.asarray(rgm)[keep], rtol=1e-5)
    np.testing.assert_allclose(w_gc, rw_gc, rtol=1e-6)
    np.testing.assert_allclose(pm, rpm, rtol=1e-6, atol=1e-6)


def test_a_design_reaches_no_python_control_computation(monkeypatch):
    """The numbers of a design come from discrete_tf alone: with python-control's sampling,
    products, feedback and margins made to fail, a fresh design (a plant no cache has seen) is
    computed and equals the same design computed with them in place."""
    p = PlantParams(inertia=0.4321)
    before = design_linear(p, 25.0).summary()
    from controllers import linear
    linear._design.cache_clear()
    linear._discrete_plant.cache_clear()

    def boom(*a, **k):
        raise AssertionError("python-control computed part of a design")

    for name in ("sample_system", "stability_margins", "feedback", "series", "c2d"):
        monkeypatch.setattr(ct, name, boom)
    monkeypatch.setattr(ct.TransferFunction, "__mul__", boom)
    monkeypatch.setattr(ct.TransferFunction, "__add__", boom)
    again = design_linear(p, 25.0).summary()
    assert again == before


def test_observer_zoh_is_scipys_expm_and_ackermann_places_the_poles():
    J, tau3, ts = 0.5, 0.008, 0.01
    Phi, Gamma = _zoh(J, tau3, ts)
    F = np.array([[0, 1, 0, 0], [0, 0, 1 / J, -1 / J], [0, 0, -1 / tau3, 0], [0, 0, 0, 0]], dtype=float)
    M = np.zeros((5, 5))
    M[:4, :4], M[:4, 4] = F * ts, np.array([0, 0, 1 / tau3, 0]) * ts
    E = scipy.linalg.expm(M)
    np.testing.assert_allclose(Phi, E[:4, :4], rtol=1e-14, atol=1e-17)
    np.testing.assert_allclose(Gamma, E[:4, 4], rtol=1e-14, atol=1e-17)
    _, _, L, poles, err, _ = _observer_design(J, tau3, ts, 20.0, (3.0, 4.0))
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(err).real), np.sort(poles), rtol=1e-9)
    A = Phi[np.ix_([0, 1, 3], [0, 1, 3])]
    with pytest.raises(ValueError, match="not observable"):
        _ackermann(A, np.array([0.0, 0.0, 0.0]), poles)
