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
    from plant.two_mass.interval import MOVE_SCRATCH, _SHEET, _event_scratch, interval_k, interval_kernel, plan
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
        out1, out2 = np.empty(8 + _SHEET), np.empty(8 + _SHEET)     # 15 slots before the root-step count
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


# --- the second speed pass (issue 22: pulse-width on compliant) -------------------------------

def test_div_k_and_interleaved_series_give_numbas_plain_bits():
    """``modes._div_k`` against numba's complex ÷ int (random values, signed zeros, inf, nan), and
    ``motion._modal_factors`` (the φ1, φ2 series of all modes summed side by side) against the
    plain per-mode series written here as the kernel had it (``term * x / k``), e^x by cmath,
    the closed forms beyond |x| = ½: bit for bit (float.hex of both parts, so signed zeros count)
    over widths from 1e-9 s to 2 ms, including |λt| within ulps of ½."""
    from numba import njit

    from plant.two_mass.interval import plan
    from plant.two_mass.modes import _div_k
    from plant.two_mass.motion import _modal_factors, mode_row

    @njit
    def both(a, k):
        return a / k, _div_k(a, k)

    @njit
    def plain_phi(x):            # the series and closed forms before the fast path
        if abs(x) < 0.5:
            term = 1.0 + 0j
            t1 = 1.0 + 0j
            for k in range(2, 30):
                term = term * x / k
                t1 += term
                if abs(term) < 1e-18 * abs(t1):
                    break
            term = 0.5 + 0j
            t2 = 0.5 + 0j
            for k in range(3, 32):
                term = term * x / k
                t2 += term
                if abs(term) < 1e-18 * abs(t2):
                    break
            return cmath.exp(x), t1, t2
        return cmath.exp(x), (cmath.exp(x) - 1.0) / x, (cmath.exp(x) - 1.0 - x) / (x * x)

    def hx(c):
        return (float(c.real).hex(), float(c.imag).hex())

    rng = np.random.default_rng(22)
    vals = list(rng.normal(size=3000) * 10.0 ** rng.uniform(-300, 300, 3000)
                + 1j * rng.normal(size=3000) * 10.0 ** rng.uniform(-300, 300, 3000))
    vals += [complex(a, b) for a in (0.0, -0.0, 1.5, -2.0, np.inf, -np.inf, np.nan, 5e-324)
             for b in (0.0, -0.0, 3.0, -1e-310, np.inf, np.nan)]
    for a in vals:
        for k in (2, 3, 17, 31):
            x, y = both(complex(a), k)
            assert hx(x) == hx(y), (a, k)

    p = _compliant()
    q, V, Vi, lam, *_ = plan(p, SimOptions())
    G = np.empty((5, 1, 5), dtype=np.complex128)
    checked = 0
    for mode in (1, 2, 3):
        r = mode_row(mode)
        n = 3 if mode == 2 else 5
        big = max(abs(lam[r, i]) for i in range(n))
        ts = list(10.0 ** rng.uniform(-9, -2.7, 300)) + [0.5 / big * (1 + e * 2.2e-16) for e in range(-6, 7)]
        for t in ts:
            _modal_factors(mode, t, lam, G, 0)
            for i in range(n):
                ref = plain_phi(lam[r, i] * t)
                got = (G[0, 0, i], G[1, 0, i], G[2, 0, i])
                assert [hx(c) for c in got] == [hx(c) for c in ref], (mode, t, i)
                checked += 1
    assert checked > 3000


def test_row_w_is_the_real_part_of_the_complex_sum():
    """``motion._row_w`` (real parts only) against the complex sum it replaced, bit for bit."""
    from numba import njit

    from plant.two_mass.motion import _row_w

    @njit
    def plain(V, r, k, C, c, n):
        acc = 0j
        for i in range(n):
            acc += V[r, k, i] * C[c, i]
        return acc.real

    rng = np.random.default_rng(5)
    for _ in range(2000):
        V = (rng.normal(size=(3, 5, 5)) + 1j * rng.normal(size=(3, 5, 5))) * 10.0 ** rng.uniform(-8, 8)
        C = (rng.normal(size=(4, 5)) + 1j * rng.normal(size=(4, 5))) * 10.0 ** rng.uniform(-8, 8)
        C[rng.random((4, 5)) < 0.2] = complex(-0.0, 0.0)
        r, k, c, n = int(rng.integers(3)), int(rng.integers(5)), int(rng.integers(4)), int(rng.integers(1, 6))
        assert float(_row_w(V, r, k, C, c, n)).hex() == float(plain(V, r, k, C, c, n)).hex()


def test_gauss_step_t_is_the_plain_gaussian_step():
    """``interval._gauss_step_t`` (Φ's structural zero products skipped, six normals in one bounds
    check) against ``interval._gauss_step`` (the full P·X and one ``normal`` per draw) on the
    plan's tables: the same state bits (signed zeros in X included) and the same cursor, also
    when the buffer ends inside the six draws (both raise NoiseExhausted)."""
    from plant.randomness import NoiseExhausted
    from plant.two_mass.interval import _gauss_step, _gauss_step_t, plan
    from plant.two_mass.motion import NNB, NX

    p = _compliant()
    q, V, Vi, lam, o, TP, TL, BT = plan(p, SimOptions())
    rng = np.random.default_rng(11)
    z = rng.standard_normal(5000)
    for case in range(400):
        X = rng.normal(size=NX) * 10.0 ** rng.uniform(-6, 2, NX)
        X[rng.random(NX) < 0.25] = -0.0
        m, j = int(rng.integers(2)), int(rng.integers(2))
        pos = int(rng.integers(0, 4990))
        c1, c2 = np.array([pos]), np.array([pos])
        o1, o2 = np.empty(NX), np.empty(NX)
        _gauss_step(X, TP[m, j], TL[m, j], z, c1, o1)
        _gauss_step_t(X, TP, TL, m, j, z, c2, o2, np.empty(NNB))
        assert o1.tobytes() == o2.tobytes() and c1[0] == c2[0], case
    for pos in (4995, 4999, 5000):
        for f in (lambda c: _gauss_step(X, TP[0, 0], TL[0, 0], z, c, np.empty(NX)),
                  lambda c: _gauss_step_t(X, TP, TL, 0, 0, z, c, np.empty(NX), np.empty(NNB))):
            with pytest.raises(NoiseExhausted):
                f(np.array([pos]))


def test_bisections_in_scratch_and_of_a_fresh_width_give_the_plain_bisections_bits():
    """``bridge.bisect_w`` (scratch, no reference counting; the plan's table, then a table too
    short so it builds laws itself) and ``bridge.bisect_fresh`` (Φ, Q of a level carried to the
    next) against ``bridge.bisect``: the same crossing time, levels, end state and draws."""
    from plant.two_mass.bridge import BISECT_SCRATCH, bisect, bisect_fresh, bisect_w
    from plant.two_mass.interval import plan
    from plant.two_mass.motion import A2, NNB, NX, process_noise, transition

    p = _compliant()
    opts = SimOptions()
    q, V, Vi, lam, o, TP, TL, BT = plan(p, opts)
    prm = p.kernel_record()[0]
    sig_v2 = prm["alpha"] ** 2 * prm["sigma2_sq"]
    rng = np.random.default_rng(4)
    z = rng.standard_normal(200_000)
    for case in range(60):
        mode = 1 if case % 2 else 3
        m = 0 if mode == 1 else 1
        Xa = rng.normal(size=NX) * 1e-3
        Xb = Xa + rng.normal(size=NX) * 1e-4
        Xa[A2], Xb[A2] = 1e-4 * rng.uniform(0.1, 1), -1e-4 * rng.uniform(0.1, 1)     # a sign change: a crossing
        pos = int(rng.integers(0, 150_000))
        c0 = np.array([pos])
        X0 = np.empty(NX)
        r0 = bisect(mode, Xa, Xb, opts.substep, opts.bisection_tol, prm, q, V, Vi, lam, sig_v2, z, c0, X0, BT[m])
        for table in (BT[m], BT[m, :3]):
            ref_c, ref_X = np.array([pos]), np.empty(NX)
            ref = bisect(mode, Xa, Xb, opts.substep, opts.bisection_tol, prm, q, V, Vi, lam, sig_v2, z, ref_c, ref_X,
                         table)
            c1, X1 = np.array([pos]), np.empty(NX)
            got = bisect_w(mode, Xa, Xb, opts.substep, opts.bisection_tol, prm, q, V, Vi, lam, sig_v2, z, c1, X1, table,
                           np.full(BISECT_SCRATCH, np.nan))
            assert got == ref and c1[0] == ref_c[0] and X1.tobytes() == ref_X.tobytes(), case
        assert r0 == ref                      # the short table builds the very laws of the long one
        w = float(rng.uniform(2e-6, 1.5e-4))
        P, Q = np.empty((NX, NX)), np.empty((NNB, NNB))
        transition(mode, w, prm, q, V, Vi, lam, P)
        process_noise(mode, w, prm, q, V, Vi, lam, Q)
        c2, X2 = np.array([pos]), np.empty(NX)
        ref2 = bisect(mode, Xa, Xb, w, opts.bisection_tol, prm, q, V, Vi, lam, sig_v2, z, c2, X2, BT[m, :0])
        c3, X3 = np.array([pos]), np.empty(NX)
        got2 = bisect_fresh(mode, Xa, Xb, w, opts.bisection_tol, prm, V, Vi, lam, sig_v2, z, c3, X3, P, Q)
        assert got2 == ref2 and c3[0] == c2[0] and X3.tobytes() == X2.tobytes(), case


def test_stays_inside_only_where_the_search_finds_no_exit():
    """``interval._stays_inside`` (the bound that skips the stuck search) is a proof, not a guess:
    on random stuck states — ringing shafts, currents and drives of either sign, torques from far
    inside ±ks to just below it — wherever it says True, the plain search (``_torque_exit``, the
    safe steps) returns (inf, 0), and ``_torque_exit_w`` equals ``_torque_exit`` everywhere. The
    bound must also decide a good share of the quiet cases (else it saves nothing)."""
    from plant.two_mass.interval import _stays_inside, _torque_exit, _torque_exit_w, plan
    from plant.two_mass.modes import NCORE
    from plant.two_mass.motion import A3, AKC, AU, PHI, WM

    p = _compliant()
    q, V, Vi, lam, *_ = plan(p, SimOptions())
    prm = p.kernel_record()[0]
    k, c = p.shaft_stiffness, p.shaft_damping
    rng = np.random.default_rng(2211)
    C = np.empty((5, NCORE), dtype=complex)
    F = np.empty((3, NCORE))
    proved = quiet = 0
    for case in range(3000):
        X = np.zeros(9)
        X[AKC] = p.coulomb
        scale = 10.0 ** rng.uniform(-3, 0.3)
        X[PHI] = rng.uniform(-1, 1) * scale * p.stiction / k
        X[WM] = rng.uniform(-1, 1) * scale * 40.0 * p.stiction / k
        X[A3] = rng.uniform(-1, 1) * scale * p.stiction
        X[AU] = rng.choice([0.0, 0.0, p.u_max, -p.u_max, 0.3 * p.stiction])
        ks = p.stiction * rng.uniform(0.5, 1.5)
        if abs(k * X[PHI] + c * X[WM]) >= ks:
            continue
        horizon = float(rng.choice([1e-4, 1e-3, 0.01]) * rng.uniform(0.1, 1.0))
        plain = _torque_exit(X, ks, horizon, prm, q, V, Vi, lam)
        assert _torque_exit_w(X, ks, horizon, prm, q, V, Vi, lam, C, F) == plain, case
        if _stays_inside(C, 3, ks, horizon):
            proved += 1
            assert plain == (np.inf, 0), case
        quiet += plain == (np.inf, 0)
    assert proved > 0.3 * quiet and quiet > 500
