"""Issue 27: the interval's cheaper noisy sub-step loop gives the numbers of the code it replaced.

* :func:`plant.multimode.crossing.crossed` (the crossing decision from a table of log Φ, exp and
  erfc only inside a cell) against ``pc >= 1.0 or uniform_below(pc)`` with
  pc = :func:`plant.multimode.zero_velocity._cross_prob` and against the code it replaced
  (``tests.reference_kernels.crossed_exact``): the same decision from the same normals,
  on random exponents and normals, at the grid's points and with the exponent placed at log Φ(x)
  itself (where only exp and erfc can decide);
* the table's cells bracket log Φ (computed independently with scipy's ``log_ndtr``);
* :func:`plant.multimode.bridge_loop.bridge_run` against
  ``tests.reference_kernels.bridge_segment`` (the code it replaced) on random segments: the same state, peak,
  sub-step count and read position, bit for bit.
"""

import math

import numpy as np
import pytest
from scipy.special import log_ndtr

from plant.multimode.bridge_loop import bridge_run
from plant.multimode.crossing import GRID_MIN, GRID_STEP, LOG_PHI_HI, LOG_PHI_LO, crossed, exp_below
from plant.multimode.interval import _tables
from plant.multimode.zero_velocity import _cross_prob
from plant.params import PlantParams
from tests.reference_kernels import bridge_segment, crossed_exact
from plant.randomness import uniform_below
from plant.state import SimOptions


def _reference(va, vb, h, s2, z, cursor):
    pc = _cross_prob(va, vb, h, s2)
    return pc >= 1.0 or uniform_below(z, cursor, pc)


def _check(e, x, h=1e-4, s2=0.3, sign=1.0):
    """Both decisions for exponent e and next normal x (va = vb·… chosen to give e)."""
    va = sign * math.sqrt(max(-e, 0.0) * s2 * h / 2.0) if e <= 0 else sign * 1.0
    vb = va if e <= 0 else -va
    z = np.array([x, 0.25])
    c1, c2 = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)
    c3 = np.zeros(1, dtype=np.int64)
    got = crossed(va, vb, h, s2, z, c1)
    want = _reference(va, vb, h, s2, z, c2)
    assert got == want == crossed_exact(va, vb, h, s2, z, c3), (e, x, va, vb)   # and the code it replaced
    assert c1[0] == c2[0] == c3[0]
    return want


def test_table_brackets_log_phi():
    a = GRID_MIN + GRID_STEP * np.arange(LOG_PHI_LO.shape[0] + 1)
    exact = log_ndtr(a)
    assert np.all(LOG_PHI_LO < exact[:-1]) and np.all(LOG_PHI_HI > exact[1:])
    # the margin is small: the cells stay as narrow as the grid makes them
    scale = np.maximum(1.0, np.abs(exact))
    assert np.all(exact[:-1] - LOG_PHI_LO < 2e-9 * scale[:-1]) and np.all(LOG_PHI_HI - exact[1:] < 2e-9 * scale[1:])
    # inside a cell, log Φ lies between its bounds (Φ increasing)
    mid = a[:-1] + GRID_STEP * np.random.default_rng(0).uniform(0, 1, a.shape[0] - 1)
    assert np.all((LOG_PHI_LO < log_ndtr(mid)) & (log_ndtr(mid) < LOG_PHI_HI))


@pytest.mark.parametrize("seed", range(2))
def test_crossing_decision_matches_on_random_draws(seed):
    rng = np.random.default_rng(seed)
    n_true = 0
    for _ in range(20000):
        e = -(10.0 ** rng.uniform(-8, 2.2)) if rng.uniform() < 0.9 else rng.uniform(-1e-5, 1.0)
        x = rng.standard_normal() * (1.0 if rng.uniform() < 0.8 else 6.0)
        n_true += _check(e, x, sign=rng.choice([-1.0, 1.0]))
    assert 500 < n_true < 19000          # both decisions exercised


def test_crossing_decision_matches_where_only_exp_and_erfc_decide():
    rng = np.random.default_rng(5)
    # x on and next to the grid's points, e within rounding of log Φ(x) and of the cells' bounds
    a = GRID_MIN + GRID_STEP * rng.integers(0, LOG_PHI_LO.shape[0] + 1, 3000)
    xs = np.concatenate((a, np.nextafter(a, -np.inf), np.nextafter(a, np.inf), rng.uniform(-17, 1, 3000)))
    for x in xs:
        lp = math.log(0.5 * math.erfc(-x / math.sqrt(2.0)))
        i = int((x - GRID_MIN) / GRID_STEP)
        edges = [lp, np.nextafter(lp, -np.inf), np.nextafter(lp, np.inf), lp * (1 + 1e-12), lp * (1 - 1e-12)]
        if 0 <= i < LOG_PHI_LO.shape[0]:
            edges += [LOG_PHI_LO[i], LOG_PHI_HI[i], np.nextafter(LOG_PHI_LO[i], 0), np.nextafter(LOG_PHI_HI[i], 0)]
        for e in edges:
            if e < 0:
                _check(float(e), float(x))
    for e in (-70.0, np.nextafter(-70.0, 0), -1e-6, np.nextafter(-1e-6, 0), -0.7, np.nextafter(-0.7, 0),
              -math.log(2.0), -1e-17, 0.0):
        for x in (-40.0, -16.0, -11.0, -10.99, -1e-300, -0.0, 0.0, 1e-300, 0.5, 8.0):
            _check(float(e), float(x))


def test_exp_below_is_uniform_below_of_exp_down_to_underflow():
    # the disturbed kernel's moving crossing (plant.multimode.disturbed_jit._decide) decides
    # exponents from −745 to −1e-6 with it
    rng = np.random.default_rng(11)
    es = np.concatenate((-np.geomspace(1e-6, 745.0, 4000)[1:-1], -rng.uniform(0, 745, 4000)))
    n_true = 0
    for e in es:
        for x in (rng.standard_normal(), -abs(rng.standard_normal()) * 6.0,
                  math.sqrt(2.0) * -math.sqrt(-e) * rng.uniform(0.9, 1.1)):
            z = np.array([x])
            c1, c2 = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)
            got = exp_below(float(e), z, c1)
            want = uniform_below(z, c2, math.exp(e))
            assert got == want and c1[0] == c2[0] == 1, (e, x)
            n_true += want
    assert n_true > 1000


def test_bridge_run_is_bridge_segment():
    params, options = PlantParams(), SimOptions()
    TH, TP, TL, BPh, BPw, BG, BC = _tables(params, options)
    p = params.kernel_record()[0]
    sig = math.sqrt(params.alpha ** 2 * params.sigma2_sq)
    rng = np.random.default_rng(27)
    z = rng.standard_normal(400_000)
    pos = 0
    stopped_n = reflected_n = long_n = 0
    for trial in range(400):
        mode = 3 if trial % 2 else 1
        s = 1.0 if mode == 3 else -1.0
        reflect = trial % 5 == 0
        v = s * abs(rng.normal(0, 1.0)) * sig * math.sqrt(1e-4) * 10.0 ** rng.uniform(-1, 2.5)
        X = np.array([rng.normal(0, 3e-5), v, s * rng.uniform(1.0, 9.0) * (1.5 if reflect else 0.8),
                      rng.normal(0, 1e-4), rng.normal(0, 0.3), params.coulomb, s * rng.choice([0.0, 18.0, 36.0])])
        h = 10.0 ** rng.uniform(-5, -2.3)
        X1, X2 = X.copy(), X.copy()
        W1, W2 = np.zeros(400), np.zeros(400)
        c1, c2 = np.array([pos], dtype=np.int64), np.array([pos], dtype=np.int64)
        args = (mode, h, reflect, options.substep, options.reflect_substep, options.bisection_tol, p, TP, TL, TH,
                BPh, BPw, BG, BC, z)
        r1 = bridge_run(X1, *args, c1, 1e-6 * trial, 10_000.0, W1, W1[14:63].reshape((7, 7)),
                        W1[63:79].reshape((4, 4)), W1[79:95].reshape((4, 4)))
        r2 = bridge_segment(X2, *args, c2, 1e-6 * trial, 10_000.0, W2)
        assert r1 == r2
        assert np.array_equal(X1, X2) and c1[0] == c2[0]
        stopped_n += r1[1]
        reflected_n += reflect
        long_n += r1[3] > 5
        pos = int(c1[0])
    assert stopped_n > 30 and reflected_n > 50 and long_n > 50


def test_reflect_low_decides_no_push_as_the_computed_minimum_does():
    """bridge_loop._reflect_low (erfc and log skipped where the table of log Φ shows the bridge
    minimum stays ≥ 0) against zero_velocity._bridge_low, which evaluates it: the same normal
    read, a push exactly where _bridge_low's minimum is below 0 and then the same minimum, bit
    for bit. Cases straddle the decision ln Φ(x) = e = −2·va·vb/(σ_v²h) at relative distances
    down to 1e-15, with va ≈ vb and va ≫ vb, x across the grid and off it."""
    from plant.multimode.bridge_loop import _reflect_low
    from plant.multimode.zero_velocity import _bridge_low
    rng = np.random.default_rng(21)
    sig_v2, h = 0.37, 1e-5
    xs = np.concatenate((rng.uniform(-16.5, 0.5, 3000), -np.geomspace(1e-9, 15.99, 300), [-16.0, -1e-300, 0.0]))
    rel = np.concatenate(([0.0], np.geomspace(1e-15, 0.9, 40)))
    decided = pushed = 0
    for x in xs:
        z = np.array([x])
        lphi = math.log(0.5 * math.erfc(-x / math.sqrt(2.0)))
        for r in rel:
            for sign in (-1.0, 1.0):
                e = lphi * (1.0 + sign * r)
                ratio = 10.0 ** rng.uniform(0, 4) if rng.uniform() < 0.5 else 1.0
                prod = -e * sig_v2 * h / 2.0                  # va·vb
                va = math.sqrt(prod * ratio)
                vb = prod / va
                for a, b in ((va, vb), (vb, va)):
                    c1, c2 = np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64)
                    got = _reflect_low(a, b, h, sig_v2, z, c1)
                    ref = _bridge_low(a, b, h, sig_v2, z, c2)
                    assert c1[0] == c2[0] == 1
                    assert (got < 0.0) == (ref < 0.0), (x, e, a, b)
                    if ref < 0.0:
                        assert got == ref
                        pushed += 1
                    else:
                        assert got == ref or got == min(a, b)
                        decided += got != ref
    assert decided > 10_000 and pushed > 10_000
