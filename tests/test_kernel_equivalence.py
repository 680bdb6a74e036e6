"""Issue 27's cheaper kernels give the numbers of the code they replaced, bit for bit.

* :func:`plant.multimode.zero_velocity._step` (four normals behind one bounds check) against
  the four-call reference (tests/reference_kernels.py), on the ladder's own Φ and noise factors;
* :func:`plant.multimode.zero_velocity._crossed` (:func:`plant.multimode.crossing.crossed`) against ``pc >= 1.0 or uniform_below(pc)``
  with pc = :func:`_cross_prob`: the same decision from the same number of normals, also where
  its shortcut applies (exponent < −70) and around its bounds;
* :func:`plant.multimode.zero_velocity._bridge_low` (the reflecting sub-step's push, exp skipped
  where it cannot decide) and :func:`plant.multimode.segments.hermite_peak` (roots in scalars,
  for the interval's reference-count-free fast path) against the forms they replaced;
* the multimode family's compiled ``pulse_motion`` against the generic
  :meth:`plant.protocol.PlantFamily.pulse_motion` (Python intervals through ``advance``), from
  stuck states with friction offsets, including no-pulse and failing cases.
"""

import math

import numpy as np
import pytest

from plant.multimode.interval import _tables
from plant.multimode.segments import hermite_peak
from plant.multimode.zero_velocity import _bridge_low, _cross_prob, _crossed, _step
from plant.params import PlantParams
from plant.protocol import PlantFamily, get_family
from plant.randomness import NoiseExhausted, uniform_below
from plant.state import PlantState, SimOptions
from tests.reference_kernels import bridge_low as reference_bridge_low
from tests.reference_kernels import hermite_peak as reference_hermite_peak
from tests.reference_kernels import step as reference_step


def test_step_reads_the_same_normals_and_gives_the_same_state():
    _, TP, TL, *_ = _tables(PlantParams(), SimOptions())
    rng = np.random.default_rng(0)
    z = rng.standard_normal(64)
    for trial in range(200):
        X = rng.normal(0.0, 1.0, 7) * np.array([1e-5, 1e-3, 1.0, 1e-4, 0.3, 1.0, 3.0])
        P, L = TP[trial % 2, trial % 3 % 2, trial % TP.shape[2]], TL[trial % 2, trial % 3 % 2, trial % TP.shape[2]]
        c1, c2 = np.array([trial % 50], dtype=np.int64), np.array([trial % 50], dtype=np.int64)
        o1, o2 = np.empty(7), np.empty(7)
        _step(X, P, L, z, c1, o1)
        reference_step(X, P, L, z, c2, o2)
        assert c1[0] == c2[0] == trial % 50 + 4
        assert np.array_equal(o1, o2)
    with pytest.raises(NoiseExhausted):           # fewer than four normals left
        _step(X, P, L, z, np.array([61], dtype=np.int64), o1)


def _reference_crossed(va, vb, h, s2, z, cursor):
    pc = _cross_prob(va, vb, h, s2)
    return pc >= 1.0 or uniform_below(z, cursor, pc)


@pytest.mark.parametrize("seed", range(3))
def test_crossing_decision_and_draws_match_the_probability_form(seed):
    rng = np.random.default_rng(seed)
    # normals including the far tail below −11 where the shortcut must defer to erfc
    z = np.concatenate((rng.standard_normal(4000), [-11.5, -11.0, -10.999, -12.0, -40.0, 0.0, -0.0]))
    rng.shuffle(z)
    n_short = 0
    for i in range(4000):
        s2 = 10.0 ** rng.uniform(-10, -4)
        h = 10.0 ** rng.uniform(-6, -3)
        scale = math.sqrt(s2 * h) * 10.0 ** rng.uniform(-1, 1.5)
        va, vb = rng.normal(0, scale), rng.normal(0, scale)
        if i % 7 == 0:
            vb = -va if i % 14 == 0 else 0.0
        if i % 11 == 0:                   # exponent right at the shortcut's edge
            vb = 70.0 * s2 * h / (2.0 * va) * (1.0 + rng.uniform(-1e-12, 1e-12)) if va != 0 else vb
        pos = i % (z.shape[0] - 1)
        c1, c2 = np.array([pos], dtype=np.int64), np.array([pos], dtype=np.int64)
        assert _crossed(va, vb, h, s2, z, c1) == _reference_crossed(va, vb, h, s2, z, c2), (va, vb, h, s2, z[pos])
        assert c1[0] == c2[0]
        n_short += va * vb > 0 and -2.0 * va * vb / (s2 * h) < -70.0
    assert n_short > 300
    # deep in the shortcut with a normal below −11: erfc decides (no crossing: Φ(−40) ≈ 0 < pc is false)
    c1, c2 = np.array([0], dtype=np.int64), np.array([0], dtype=np.int64)
    zz = np.array([-40.0])
    assert _crossed(1.0, 1.0, 1.0, 0.02, zz, c1) == _reference_crossed(1.0, 1.0, 1.0, 0.02, zz, c2)


def test_compiled_pulse_motion_is_the_generic_one():
    fam = get_family("multimode")
    rng = np.random.default_rng(27)
    n_moved = n_fail = 0
    for params in (PlantParams(), PlantParams().replace(friction_noise_psd=0.0), PlantParams().replace(stiction=2.9)):
        for _ in range(40):
            x = np.array([rng.normal(0, 2e-5), 0.0, 0.0, rng.normal(0, 1e-4), rng.normal(0, 0.3), 0.0])
            x.flags.writeable = False
            state = PlantState(rng.uniform(0, 10), x, 2, False)
            dtu = float(rng.choice([0.0, rng.uniform(0, 3e-3), rng.uniform(0.8e-3, 1.6e-3)]))
            sign = int(rng.choice([-1, 1]))
            try:
                want = PlantFamily.pulse_motion(fam, params, state, dtu, sign)
            except RuntimeError as e:
                with pytest.raises(RuntimeError, match=str(e)[:20]):
                    fam.pulse_motion(params, state, dtu, sign)
                n_fail += 1
                continue
            got = fam.pulse_motion(params, state, dtu, sign)
            assert got == want
            n_moved += want[0] != 0.0
    assert n_moved > 40


def test_compiled_log1p_is_pythons():
    # the compiled pulse_motion sizes its flyback chunks with numba's log1p where the generic
    # path uses math.log1p: the same function of the C library, checked value for value
    from numba import njit

    f = njit(lambda v: math.log1p(v))
    rng = np.random.default_rng(1)
    for v in np.concatenate((rng.uniform(0.0, 1.0, 5000), 10.0 ** rng.uniform(-18, 0, 5000))):
        assert f(v) == math.log1p(v)


def test_reflection_push_skips_exp_only_where_it_cannot_decide():
    """The same minimum (bit for bit) and the same normal read as the form that always computes
    p = exp(e): across e from −200 to +1 (both velocities positive, one or both ≤ 0), dense
    around the shortcut's bound e = −0.7 and the test's own p = ½ (e = −ln 2), x of both signs."""
    rng = np.random.default_rng(7)
    sig_v2, h = 0.37, 1e-5
    es = np.concatenate((-np.geomspace(1e-6, 200.0, 400), np.linspace(-0.75, -0.65, 400),
                         -math.log(2.0) + np.linspace(-1e-12, 1e-12, 41), [0.0, 1.0]))
    z = rng.standard_normal(4096)
    pushed = 0
    for i, e in enumerate(es):
        va = rng.uniform(0.1, 10.0) * math.sqrt(sig_v2 * h)
        vb = -e * sig_v2 * h / (2.0 * va) if e < 0 else (-va if e > 0 else 0.0)
        for k in range(3):
            start = (7 * i + k) % 4000
            c1, c2 = np.array([start], dtype=np.int64), np.array([start], dtype=np.int64)
            a, b = ((va, vb), (vb, va), (va, -vb))[k]
            m1 = _bridge_low(a, b, h, sig_v2, z, c1)
            m2 = reference_bridge_low(a, b, h, sig_v2, z, c2)
            assert c1[0] == c2[0] == start + 1
            assert m1 == m2 or (math.isnan(m1) and math.isnan(m2))
            pushed += m2 < 0.0
    assert pushed > 100                  # the push itself is exercised, not only the shortcut


def test_hermite_peak_with_scalar_roots_is_the_array_form():
    rng = np.random.default_rng(3)
    for _ in range(3000):
        h = 10.0 ** rng.uniform(-7, -3)
        ya, yb = rng.normal(0.0, 1e-5, 2)
        da, db = rng.normal(0.0, 1e-2, 2)
        if rng.uniform() < 0.1:
            da = -db                        # A = 0 cases: 3·c3 vanishes with ya = yb
            yb = ya
        assert hermite_peak(h, ya, da, yb, db) == reference_hermite_peak(h, ya, da, yb, db)
    assert hermite_peak(0.0, 1.0, 1.0, 2.0, -1.0) == 0.0


def _kernel_records():
    """Table 2-1 (β4 = β5, the decays shared) and variants with β4 ≠ β5, fast decays (the
    Gauss–Legendre branch of q_moving) and no x4 noise, as kernel records."""
    base = PlantParams()
    variants = [base, base.replace(command_velocity_tau=333.0),
                base.replace(correlated_friction_tau=0.025, command_velocity_tau=0.14),
                base.replace(correlated_friction_tau=5e-4, command_velocity_tau=5e-4),
                base.replace(command_velocity_std=0.0)]
    return [v.kernel_record() for v in variants]


@pytest.mark.slow      # 4050 cases, ~15 CPU s (q_moving's quadrature on the fast-decay record at widths to 1 s): make test-slow
def test_phi_and_q_with_shared_evaluations_are_the_separate_forms():
    """phi_moving, q_moving and the fused phi_q_moving (the fresh end-of-segment step) give the
    entries of the forms that evaluate every e-function per entry (tests/reference_kernels.py),
    bit for bit, for widths from 1e-12 s to 1 s (both branches of q_moving) and both modes."""
    from plant.multimode.moving import phi_moving, phi_q_moving, q_moving
    from tests.reference_kernels import phi_moving_ref, q_moving_ref
    rng = np.random.default_rng(11)
    widths = np.concatenate((10.0 ** rng.uniform(-12, 0, 400), [1e-5, 2e-5, 1.5e-4, 0.004, 0.01]))
    n_fused_shared = 0
    for rec in _kernel_records():
        p = rec[0]
        for h in widths:
            for mode in (1, 3):
                P1, P2, P3 = np.empty((7, 7)), np.empty((7, 7)), np.empty((7, 7))
                Q1, Q2, Q3 = np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
                phi_moving_ref(mode, h, p, P1)
                q_moving_ref(mode, h, p, Q1)
                phi_moving(mode, h, p, P2)
                q_moving(mode, h, p, Q2)
                phi_q_moving(mode, h, p, P3, Q3)
                for A, B in ((P1, P2), (P1, P3), (Q1, Q2), (Q1, Q3)):
                    assert np.array_equal(A.view(np.uint64), B.view(np.uint64)), (mode, h, p["beta4"], p["beta5"])
                n_fused_shared += p["beta4"] * h == p["beta5"] * h
    assert n_fused_shared > 500            # the shared-decay branch is exercised


def test_hitting_midpoint_without_exp_of_zero_is_the_full_form():
    """_hitting_midpoint (exp skipped for the largest weight, exp(0) = 1, and the acceptance
    test by uniform_below) returns the midpoint of the form that evaluates all three exps and
    ``uniform() < accept`` (tests/reference_kernels.py), bit for bit, and reads the same normals:
    ends from 0.01 to 30 σ, means on both sides of 0, ties between weights, sd = 0."""
    from plant.multimode.zero_velocity import _hitting_midpoint
    from tests.reference_kernels import hitting_midpoint_ref
    rng = np.random.default_rng(5)
    z = rng.standard_normal(200_000)
    pos = 0
    for trial in range(6000):
        sd = 10.0 ** rng.uniform(-9, -5) if trial % 50 else 0.0
        s2h = sd * sd * rng.uniform(2.0, 6.0) if sd > 0 else 1e-12
        a, b = 10.0 ** rng.uniform(-2, 1.5, 2) * math.sqrt(s2h)
        if trial % 7 == 0:
            b = a                                   # w1 = w2: a tie for the largest weight
        mu = rng.normal(0.0, 3.0) * sd
        c1, c2 = np.array([pos], dtype=np.int64), np.array([pos], dtype=np.int64)
        m1 = _hitting_midpoint(a, b, mu, sd, s2h, z, c1)
        m2 = hitting_midpoint_ref(a, b, mu, sd, s2h, z, c2)
        assert c1[0] == c2[0]
        assert m1 == m2, (trial, a, b, mu, sd, s2h)
        pos = int(c1[0]) if c1[0] < 190_000 else 0


def test_bisection_level_skipping_the_right_half_probability_is_the_full_form():
    """_bisect_level (the right half's crossing probability evaluated only when the left half's
    is below 1) draws the same midpoint, reads the same normals and picks the same half as the
    form that always evaluates both (tests/reference_kernels.py), on the bisection tables of
    Table 2-1: ends of one sign (the hitting sampler) and of opposite signs, both modes."""
    from plant.multimode.zero_velocity import _bisect_level
    from tests.reference_kernels import bisect_level_ref
    _, _, _, BPh, BPw, BG, BC = _tables(PlantParams(), SimOptions())
    p = PlantParams()
    sig_v2 = p.alpha ** 2 * p.sigma2_sq
    rng = np.random.default_rng(9)
    z = rng.standard_normal(400_000)
    pos, lefts, levels_seen = 0, 0, set()
    for trial in range(8000):
        m, k = trial % 2, trial % BPh.shape[1]
        half = SimOptions().substep / 2 ** (k + 1)
        scale = math.sqrt(sig_v2 * 2 * half)
        Xa = rng.normal(0.0, 1.0, 7) * np.array([1e-5, 1.0, 1.0, 1e-4, 0.3, 1.0, 3.0])
        Xa[1] = abs(rng.normal(0.0, 2.0)) * scale * (1 if m == 1 else -1)
        Xb = Xa.copy()
        Xb[1] = Xa[1] * rng.uniform(-1.5, 3.0)
        Xm1, Xm2, F1, F2 = np.empty(7), np.empty(7), np.empty(7), np.empty(7)
        c1, c2 = np.array([pos], dtype=np.int64), np.array([pos], dtype=np.int64)
        r1 = _bisect_level(BPh[m, k], BPw[m, k], BG[m, k], BC[m, k], Xa, Xb, Xm1, F1, half, sig_v2, z, c1)
        r2 = bisect_level_ref(BPh[m, k], BPw[m, k], BG[m, k], BC[m, k], Xa, Xb, Xm2, F2, half, sig_v2, z, c2)
        assert r1 == r2 and c1[0] == c2[0]
        assert np.array_equal(Xm1.view(np.uint64), Xm2.view(np.uint64))
        lefts += r1
        levels_seen.add(k)
        pos = int(c1[0]) if c1[0] < 390_000 else 0
    assert 1000 < lefts < 7000 and len(levels_seen) == BPh.shape[1]
