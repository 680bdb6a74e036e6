"""The two-mass kernel's cheaper forms give the very bits of the plain ones (issue 22, speed).

* ``modes._small`` / ``modes._tiny`` (the φ1/φ2 branch and series stop decided by squared
  moduli away from the threshold) against ``abs`` comparisons, on random values and on values
  within a few ulps of each threshold;
* ``motion.transition`` / ``motion.process_noise`` (e^(λt), φ1, φ2 shared across columns and
  noise sources) against the same matrix and Gauss–Legendre sum built here from
  ``motion.propagate`` column by column;
* ``modes._g_fast`` against the plain modal sum (and numpy's closed form) on random modal sums;
* ``interval._torque_exit_w`` (allocation-free, no reference counting) against
  ``interval._torque_exit``, and its root against brentq on the closed form.
Bit-for-bit equality of whole compliant cells with main 77118a2 was checked once (docs/plant.md).
"""

from __future__ import annotations

import cmath

import numpy as np
import pytest
from scipy.optimize import brentq

from bench.scenarios import builtin_scenarios
from plant.state import SimOptions


def _compliant():
    return builtin_scenarios()["compliant"].params


def _edge_values(rng, radius, n):
    """Complex numbers with modulus within a few ulps of ``radius`` and random ones around it."""
    ang = rng.uniform(0, 2 * np.pi, n)
    r = radius * (1.0 + rng.integers(-8, 9, n) * np.finfo(float).eps)
    near = r * np.exp(1j * ang)
    wide = rng.uniform(0.0, 2.0 * radius, n) * np.exp(1j * rng.uniform(0, 2 * np.pi, n))
    axes = np.concatenate([r, -r, 1j * r]).astype(complex)
    return np.concatenate([near, wide, axes])


def test_small_and_tiny_decide_as_abs():
    from plant.two_mass.modes import _small, _tiny

    rng = np.random.default_rng(7)
    for x in _edge_values(rng, 0.5, 400):
        assert _small.py_func(complex(x)) == (abs(complex(x)) < 0.5)
    totals = np.concatenate([_edge_values(rng, 1.0, 60), _edge_values(rng, 0.4, 60)])
    for total in totals:
        if abs(total) == 0.0:
            continue
        for term in _edge_values(rng, 1e-18 * abs(total), 5):
            t, s = complex(term), complex(total)
            assert _tiny.py_func(t, s) == (abs(t) < 1e-18 * abs(s))
    assert _tiny.py_func(1e-170 + 0j, 0.5 + 0j)      # a square that underflows: still tiny


@pytest.mark.parametrize("mode", [1, 2, 3])
@pytest.mark.parametrize("h", [1e-5, 1.37e-4, 2.3e-3])
def test_transition_and_noise_equal_the_column_by_column_build(mode, h):
    from plant.two_mass.interval import plan
    from plant.two_mass.motion import _GL_W, _GL_X, A2, A4, A5, NB, NNB, NX, process_noise, propagate, transition

    p = _compliant()
    q, V, Vi, lam, *_ = plan(p, SimOptions())
    prm = p.kernel_record()[0]
    P = np.empty((NX, NX))
    transition(mode, h, prm, q, V, Vi, lam, P)
    ref = np.empty((NX, NX))
    col = np.empty(NX)
    for j in range(NX):
        e = np.zeros(NX)
        e[j] = 1.0
        propagate(e, mode, h, prm, q, V, Vi, lam, col)
        ref[:, j] = col
    assert np.array_equal(P, ref)

    Q = np.empty((NNB, NNB))
    process_noise(mode, h, prm, q, V, Vi, lam, Q)
    r = 0 if mode == 1 else (1 if mode == 3 else 2)
    rho = max([prm["beta4"]] + [abs(lam[r, i]) for i in range(5)])
    panels = max(1, int(np.ceil(rho * h / 0.125)))
    width = h / panels
    Qr = np.zeros((NNB, NNB))
    for j, qj in ((A2, prm["alpha"] * prm["alpha"] * prm["sigma2_sq"]), (A4, prm["sigma4_sq"]), (A5, prm["sigma5_sq"])):
        if (mode == 2 and j != A4) or qj == 0.0:
            continue
        for pn in range(panels):
            lo = pn * width
            for k in range(8):
                v = lo + 0.5 * width * (_GL_X[k] + 1.0)
                e = np.zeros(NX)
                e[j] = 1.0
                propagate(e, mode, v, prm, q, V, Vi, lam, col)
                wk = 0.5 * width * _GL_W[k] * qj
                for a in range(NNB):
                    for b in range(NNB):
                        Qr[a, b] += wk * col[NB[a]] * col[NB[b]]
    for a in range(NNB):
        for b in range(a + 1, NNB):
            Qr[a, b] = Qr[b, a] = 0.5 * (Qr[a, b] + Qr[b, a])
    assert np.array_equal(Q, Qr)


def test_torque_exit_scratch_form_equals_the_plain_one_and_brentq():
    from plant.two_mass.interval import _torque_exit, _torque_exit_w, plan
    from plant.two_mass.modes import NCORE
    from plant.two_mass.motion import A3, AKC, AU, PHI, WM

    p = _compliant()
    q, V, Vi, lam, *_ = plan(p, SimOptions())
    prm = p.kernel_record()[0]
    k, c = p.shaft_stiffness, p.shaft_damping
    rng = np.random.default_rng(3)
    C = np.empty((5, NCORE), dtype=complex)
    F = np.empty((3, NCORE))
    hits = 0
    for _ in range(40):
        X = np.zeros(9)
        X[AKC] = p.coulomb
        X[PHI] = rng.uniform(-1.5, 1.5) * p.stiction / k        # torque inside ±ks
        X[WM] = rng.uniform(-1.0, 1.0) * 40.0 * p.stiction / k     # ringing
        X[A3], X[AU] = rng.uniform(-3, 3), rng.choice([0.0, p.u_max, -p.u_max])
        if abs(k * X[PHI] + c * X[WM]) >= p.stiction:
            continue
        plain = _torque_exit(X, p.stiction, 0.01, prm, q, V, Vi, lam)
        fast = _torque_exit_w(X, p.stiction, 0.01, prm, q, V, Vi, lam, C, F)
        assert plain == fast
        t, side = plain
        if side != 0:
            hits += 1
            # the closed form: T(s) = k·φ(s) + c·ω_m(s) from the rotor ODE, sampled by propagate
            from plant.two_mass.motion import propagate
            Xn = np.empty(9)

            def torque(s):
                propagate(X, 2, s, prm, q, V, Vi, lam, Xn)
                return k * Xn[PHI] + c * Xn[WM] - side * p.stiction
            grid = np.linspace(0.0, t, 200)
            vals = [torque(s) for s in grid[1:-1]]
            assert all(side * v < 0 for v in vals)                 # no earlier crossing
            lo = grid[-2]
            assert abs(brentq(torque, lo, t + 1e-9, xtol=1e-15) - t) < 1e-12
    assert hits >= 5


def test_g_fast_gives_the_bits_of_the_plain_sum():
    """``modes._g_fast`` (|λ| given, Σ|terms| only on request, the b-term skipped where b = 0)
    against the plain modal sum on random modal sums: g, g', M2 and Σ|terms| bit for bit
    (float.hex, so signed zeros count), over λ with light and heavy damping, t = 0 included,
    b = ±0 included; the plain g and g' against numpy's closed form to 1e-9 of Σ|terms|."""
    from numba import njit

    from plant.two_mass.modes import _g_fast, phi1

    @njit
    def g_values(ca, cb, lam, n, t):   # the plain sum (the kernel's form before the fast path)
        g = g1 = m2 = size = 0.0
        for i in range(n):
            l = lam[i]
            e = cmath.exp(l * t)
            term = ca[i] * e + cb[i] * (t * phi1(l * t))
            g += term.real
            size += abs(term)
            d = e * (l * ca[i] + cb[i])
            g1 += d.real
            m2 += abs(l) * abs(d)
        return g, g1, m2, size

    @njit
    def moduli(lam):            # |λ_i| as the kernel takes them (numba's abs, not numpy's hypot)
        out = np.empty(lam.shape[0])
        for i in range(lam.shape[0]):
            out[i] = abs(lam[i])
        return out

    rng = np.random.default_rng(2207)
    checked_zero_b = 0
    for case in range(3000):
        n = int(rng.integers(1, 5))
        lam = (-rng.uniform(0.0, 3e3, n) + 1j * rng.uniform(-2e3, 2e3, n)).astype(np.complex128)
        ca = (rng.normal(size=n) + 1j * rng.normal(size=n)) * 10.0 ** rng.uniform(-3, 3, n)
        cb = (rng.normal(size=n) + 1j * rng.normal(size=n)) * 10.0 ** rng.uniform(-3, 3, n)
        zero = rng.random(n) < 0.4
        cb[zero] = complex(-0.0, 0.0) if case % 2 else 0.0
        checked_zero_b += int(zero.sum())
        t = 0.0 if case % 7 == 0 else float(rng.uniform(0.0, 5e-3))
        plain = g_values(ca, cb, lam, n, t)
        lt = lam * t       # the definition in numpy: t·φ1(λt) = (e^(λt) − 1)/λ, g' = Σ (λa + b)·e^(λt)
        tphi = np.where(lt == 0, t, np.expm1(lt) / np.where(lam == 0, 1, lam))
        ref_g = float(np.sum(ca * np.exp(lt) + cb * tphi).real)
        ref_g1 = float(np.sum((lam * ca + cb) * np.exp(lt)).real)
        scale = plain[3] + float(np.sum(np.abs((lam * ca + cb) * np.exp(lt))))
        assert abs(plain[0] - ref_g) <= 1e-9 * scale and abs(plain[1] - ref_g1) <= 1e-9 * scale, case
        fast = _g_fast(ca, cb, lam, moduli(lam), n, t, True)
        assert [float(v).hex() for v in fast] == [float(v).hex() for v in plain], (case, fast, plain)
        no_size = _g_fast(ca, cb, lam, moduli(lam), n, t, False)
        assert [float(v).hex() for v in no_size[:3]] == [float(v).hex() for v in plain[:3]] and no_size[3] == 0.0
    assert checked_zero_b > 1000


def test_interval_k_reads_the_first_k_segments_and_is_interval_kernel_bit_for_bit():
    """``interval.interval_k`` (no reference counting, the caller's dirty scratch, the drive's first
    k segments of longer arrays whose tail is NaN) against ``interval_kernel`` on exact slices:
    the same state, work sheet, events and noise position on a noisy train of bridge pulses and
    linear levels that sticks, breaks loose and reverses."""
    from plant.two_mass.interval import MOVE_SCRATCH, _event_scratch, interval_k, interval_kernel, plan
    from plant.two_mass.modes import NCORE
    from plant.two_mass.motion import NX
    p = _compliant()
    q, V, Vi, lam, o, TP, TL, BT = plan(p, SimOptions())
    prm = p.kernel_record()
    z = np.random.default_rng(np.random.SeedSequence(7)).standard_normal(1_000_000)
    rng = np.random.default_rng(3)
    tau = p.sample_period
    x = np.zeros(8)
    t, mode, fb, pos = 0.0, 2, False, 0
    scratch = (np.full(1, -5, np.int64), np.full(NX, np.nan), np.full(NX, np.nan),
               np.full((5, NCORE), np.nan + 0j), np.full((3, NCORE), np.nan), np.full(MOVE_SCRATCH, np.nan))
    events = 0
    for n in range(120):
        bridge = n % 2 == 0
        if bridge:
            lv = p.u_max * rng.choice([-1.0, 1.0])
            w = rng.uniform(0.1, 0.6) * tau
            offs, levs = np.array([0.0, w]), np.array([lv, 0.0])
        else:
            offs, levs = np.array([0.0]), np.array([p.u_max * rng.uniform(-0.6, 0.6)])
        k = offs.shape[0]
        pad_o = np.concatenate([offs, np.full(3, np.nan)])
        pad_l = np.concatenate([levs, np.full(3, np.nan)])
        ev1, ev2 = _event_scratch().copy(), _event_scratch().copy()
        out1, out2 = np.empty(8 + 15), np.empty(8 + 15)
        p1 = interval_kernel(x, mode, fb, t, tau, offs, levs, bridge, prm, q, V, Vi, lam, o, TP, TL, BT, z, pos, ev1,
                             out1)
        p2 = interval_k(x, mode, fb, t, tau, pad_o, pad_l, k, bridge, prm, q, V, Vi, lam, o, TP, TL, BT, z, pos, ev2,
                        out2, *scratch)
        nrec = int(out1[8 + 14])
        assert p1 == p2 and out1.tobytes() == out2.tobytes() and ev1[:nrec].tobytes() == ev2[:nrec].tobytes(), n
        assert out1[8 + 13] == 0.0, n                  # status ok
        events += int(out1[8 + 9])
        x = out1[:8].copy()
        t, mode, fb, pos = out1[8], int(out1[9]), out1[10] != 0.0, p1
    assert events > 20 and pos > 1000                   # pulses break loose and stick; noise was drawn
