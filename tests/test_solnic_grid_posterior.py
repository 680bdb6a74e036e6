"""The grid posterior over (k_c, k_s) (controllers/solnic/grid_posterior.py) against
independent truth: the event-driven pulse simulator for its motion table, and rejection
sampling from the prior for the posterior (the lattice, its zooms and the cell spread are what
is under test; the likelihood's model D(k) is the table checked in the first test)."""

import math

import numpy as np
import pytest

from controllers.solnic.grid_posterior import FrictionGrid, pulse_table
from plant import PlantParams, pulse_response
from plant.state import SimOptions

QUIET = PlantParams().replace(friction_noise_psd=0.0)


def test_table_matches_the_event_driven_simulator():
    """The compiled table against the general simulator (pulse_response with options)."""
    rng = np.random.default_rng(1)
    ks = rng.uniform(0.5, 3.5, 6)
    kc = ks * rng.uniform(0.2, 1.0, 6)
    for dtu in (0.9e-3, 1.4e-3, 2.0e-3):
        dc, ts, tb = pulse_table(QUIET, dtu, kc, ks)
        for i in range(ks.size):
            r = pulse_response(QUIET.with_friction(ks[i], kc[i]), dtu, options=SimOptions(noise=False))
            if r.t_breakaway is None:
                assert tb[i] < 0 and dc[i] == 0.0
            else:
                assert dc[i] == pytest.approx(r.delta_c, rel=1e-6, abs=1e-12)
                assert ts[i] == pytest.approx(r.t_stop, rel=1e-6)


def _rejection(prior_mean, prior_cov, obs, n=400_000, seed=0):
    """Samples of the exact posterior: prior on the valid set, accept with L/L_max."""
    rng = np.random.default_rng(seed)
    k = rng.multivariate_normal(prior_mean, prior_cov, size=n)
    kc, ks = k[:, 0], k[:, 1]
    ok = (kc > 0) & (kc <= ks) & (ks < QUIET.u_max)
    kc, ks = kc[ok], ks[ok]
    logL = np.zeros(kc.size)
    for dtu, m, R in obs:
        dc, _, tb = pulse_table(QUIET, dtu, kc, ks)
        d = np.where(tb >= 0, dc, 0.0)
        logL += -0.5 * (m - d) ** 2 / R
    acc = rng.uniform(size=kc.size) < np.exp(logL - logL.max())
    return kc[acc], ks[acc]


def _grid(prior_mean, prior_cov, obs, n=64):
    g = FrictionGrid(QUIET, prior_mean, prior_cov, n=n)
    for dtu, m, R in obs:
        g.update(dtu, 1, m, R)
    return g


def _compare(g, kc, ks, tol_sd=0.15):
    """Posterior mean within 0.15 posterior sd (+ MC error), sd within 15 %."""
    assert kc.size > 3000
    mc_mean = np.array([kc.mean(), ks.mean()])
    mc_sd = np.array([kc.std(), ks.std()])
    sd = np.sqrt(np.diag(g.cov))
    err = np.abs(g.mean - mc_mean)
    assert np.all(err < tol_sd * mc_sd + 4 * mc_sd / math.sqrt(kc.size)), (g.mean, mc_mean, mc_sd)
    assert np.all(np.abs(sd / mc_sd - 1) < 0.15), (sd, mc_sd)


PRIOR = (np.array([0.7, 1.05]), np.diag([0.7**2, 1.05**2]))     # section 7.3 start


def test_constraints_act_on_the_distribution():
    """No data: the prior restricted to 0 < k_c ≤ k_s < u_max, also for a prior mean outside."""
    for mean in (PRIOR[0], np.array([1.5, 1.2])):
        cov = PRIOR[1] if mean is PRIOR[0] else np.diag([0.3**2, 0.3**2])
        g = _grid(mean, cov, [])
        kc, ks, w = g.points()
        assert np.all(kc > 0) and np.all(kc <= ks) and np.all(ks < QUIET.u_max)
        assert w.sum() == pytest.approx(1.0)
        rkc, rks = _rejection(mean, cov, [])
        _compare(g, rkc, rks)
    assert g.mean[0] < g.mean[1]            # the mean is pulled inside kc ≤ ks, not clipped


def test_posterior_matches_rejection_sampling_after_pulses():
    """Three pulses of different sizes at a true (1.5, 2.2): the ridges of one size intersect.
    Enough evidence to zoom the lattice; the posterior stays exact up to it."""
    true = (1.5, 2.2)
    obs = []
    for dtu, noise in ((1.3e-3, 0.3e-6), (1.6e-3, -0.2e-6), (1.9e-3, 0.4e-6)):
        dc = pulse_table(QUIET, dtu, np.array([true[0]]), np.array([true[1]]))[0][0]
        obs.append((dtu, dc + noise, (1.0e-6) ** 2))
    g = _grid(*PRIOR, obs)
    assert g.n_regrids >= 1
    kc, ks = _rejection(*PRIOR, obs, n=2_000_000)
    _compare(g, kc, ks)


def test_no_motion_is_censored_evidence():
    """A pulse that did not move the shaft (d ≈ 0, sd 0.3 µrad): the posterior is the prior
    restricted to the frictions under which that pulse moves by less than ~1 µrad — k_s above
    its peak torque, or just below it (a late breakaway moves little) — by rejection
    sampling; the grid puts the same mass above the peak torque."""
    dtu = 1.0e-3
    peak = QUIET.u_max * -math.expm1(-dtu / QUIET.motor_time_constant)
    obs = [(dtu, 0.0, (0.3e-6) ** 2)]
    g = _grid(*PRIOR, obs)
    kc, ks = _rejection(*PRIOR, obs)
    _compare(g, kc, ks, tol_sd=0.2)
    gkc, gks, w = g.points()
    mc_above = float(np.mean(ks >= peak))
    assert mc_above > 0.6                   # measured 0.78; the prior has 0.10 above
    assert float(np.mean(_rejection(*PRIOR, [])[1] >= peak)) < 0.2
    assert float(np.sum(w[gks >= peak])) == pytest.approx(mc_above, abs=0.03)
    # against the prior alone, the evidence raised k_s
    assert g.mean[1] > PRIOR[0][1] + 0.5


def test_wide_evidence_changes_nothing_and_bad_evidence_is_ignored():
    g = _grid(*PRIOR, [])
    before, sd = g.mean, np.sqrt(np.diag(g.cov))
    g.update(1.5e-3, 1, 3e-6, 1.0)                 # R = 1 rad²: no information
    # up to the lattice (the first update may re-fit it to the prior's mass)
    assert np.all(np.abs(g.mean - before) < 0.1 * sd)
    g.update(1.5e-3, 1, math.nan, 1e-12)           # nothing measured
    g.update(1.5e-3, 1, 3e-6, math.inf)
    assert len(g.obs) == 1


def test_predictive_brackets_the_truth():
    """After the three pulses the predictive of a fourth size contains its true motion."""
    true = (1.5, 2.2)
    obs = []
    for dtu in (1.3e-3, 1.6e-3, 1.9e-3):
        dc = pulse_table(QUIET, dtu, np.array([true[0]]), np.array([true[1]]))[0][0]
        obs.append((dtu, dc, (0.5e-6) ** 2))
    g = _grid(*PRIOR, obs)
    dtu = 1.45e-3
    dc = pulse_table(QUIET, dtu, np.array([true[0]]), np.array([true[1]]))[0][0]
    p = g.predictive(dtu)
    assert p.p_motion > 0.99
    assert abs(p.dc_mean - dc) < 3 * math.sqrt(p.dc_var) + 0.2e-6


def test_table_of_the_needed_points_is_the_full_tables():
    """The lattice table evaluates only the valid points and their neighbours (issue 27); at
    the valid points Δc, t_stop, t_breakaway and the cell spread equal the table of every
    point, on the first lattice (about half of it invalid) and on re-fitted ones."""
    p = PlantParams()
    g = FrictionGrid(p, [p.coulomb, p.stiction], np.diag([p.coulomb**2, p.stiction**2]), n=32)
    rng = np.random.default_rng(5)
    skipped = 0
    for round_ in range(4):
        for dtu in (0.8e-3, 1.3e-3, 2.1e-3):
            g._tables.clear()
            part = g.table(dtu)
            need = g._need
            g._need, g._tables = np.ones_like(need), {}
            full = g.table(dtu)
            g._need = need
            assert all(np.array_equal(a, b) for a, b in zip(part, full))
            skipped += int(np.sum(~need))
        # re-fit the lattice on evidence from a pulse of the true friction
        dtu = 1.3e-3
        dc = pulse_table(p, dtu, np.array([p.coulomb]), np.array([p.stiction]))[0][0]
        g.update(dtu, 1, dc * (1 + 0.05 * rng.standard_normal()), (0.05 * dc) ** 2)
    assert skipped > 0 and g.n_regrids > 0


def test_noise_moments_kept_with_the_table_follow_the_lattice():
    """The moving-time terms f = α²σ2²T_m³/3 and √f are kept with each pulse table (issue 27):
    the moments equal the formula of the module docstring on the current table, bit for bit,
    for several Δt_u and ratios, before and after re-fitted lattices (which must drop them)."""
    p = PlantParams()
    g = FrictionGrid(p, [p.coulomb, p.stiction], np.diag([p.coulomb**2, p.stiction**2]), n=32)
    s2 = p.alpha**2 * p.sigma2_sq
    assert s2 > 0
    rng = np.random.default_rng(6)
    versions = set()
    for round_ in range(4):
        for dtu, vr, br in ((0.8e-3, 2.5, 0.8), (1.3e-3, 1.3, 0.6), (1.3e-3, 3.7, 1.0), (2.1e-3, 0.0, 0.0)):
            mean, var, moves, ts = g.noise_moments(dtu, vr, br)
            dc, ts0, tb, spread = g.table(dtu)
            tm = np.maximum(ts0 - tb, 0.0)
            f = np.where(tb >= 0.0, s2 * (tm * tm * tm) / 3.0, 0.0)      # T_m³ as T_m·T_m·T_m
            want_mean, want_var = (dc + br * np.sqrt(f), spread + vr * f) if (vr > 0 or br > 0) else (dc, spread)
            assert mean.tobytes() == want_mean.tobytes() and var.tobytes() == want_var.tobytes()
            assert np.array_equal(moves, tb >= 0.0) and ts is ts0
            with pytest.raises(ValueError):
                moves[0] = not moves[0]                  # shared with later calls: read-only
        versions.add(g.version)
        dtu = 1.3e-3
        dc = pulse_table(p, dtu, np.array([p.coulomb]), np.array([p.stiction]))[0][0]
        g.update(dtu, 1, dc * (1 + 0.05 * rng.standard_normal()), (0.05 * dc) ** 2, 2.5, 0.8)
    assert len(versions) > 1 and g.n_regrids > 0


def test_compiled_table_is_the_numpy_table_bit_for_bit(monkeypatch):
    """The lattice table is one compiled call (issue 27): Δc, t_stop, t_breakaway and the cell
    spread at the valid points equal the numpy formulation (tests/reference_kernels.py:
    np.clip, the closed form, np.gradient per axis) bit for bit — lattices of 2, 3, 5 and
    64 points a side (edges everywhere, and the default), five Δt_u each, the first lattice and
    re-fitted ones — and the table no longer calls np.gradient."""
    from tests.reference_kernels import grid_table

    p = PlantParams()
    rng = np.random.default_rng(11)
    grids = []
    for n in (2, 3, 5, 64):
        for _ in range(3):
            k0 = [rng.uniform(0.3, 1.5) * p.coulomb, rng.uniform(0.5, 1.5) * p.stiction]
            grids.append(FrictionGrid(p, k0, np.diag(rng.uniform(0.05, 1.0, 2) * np.square(k0)), n=n))
    g = FrictionGrid(p, [p.coulomb, p.stiction], np.diag([p.coulomb**2, p.stiction**2]), n=32)
    dc = pulse_table(p, 1.3e-3, np.array([p.coulomb]), np.array([p.stiction]))[0][0]
    while g.n_regrids < 2:
        g.update(1.3e-3, 1, dc * (1 + 0.05 * rng.standard_normal()), (0.05 * dc) ** 2)
    grids.append(g)
    want = {}
    for i, grid in enumerate(grids):
        for dtu in (0.5e-3, 0.95e-3, 1.2e-3, 1.7e-3, 2.5e-3):
            want[i, dtu] = grid_table(grid, dtu)

    def no_gradient(*a, **k):
        raise AssertionError("np.gradient called")

    monkeypatch.setattr(np, "gradient", no_gradient)
    moved = 0
    for i, grid in enumerate(grids):
        for dtu in (0.5e-3, 0.95e-3, 1.2e-3, 1.7e-3, 2.5e-3):
            grid._tables.clear()
            got = grid.table(dtu)
            assert all(a.shape == b.shape and a.tobytes() == b.tobytes() for a, b in zip(got, want[i, dtu]))
            moved += int(np.sum(got[2] >= 0))
    assert moved > 0


def test_compiled_predictive_is_the_numpy_predictive_bit_for_bit(monkeypatch):
    """The predictive's quantiles are one compiled call (issue 27): equal by ``float.hex`` to the
    numpy formulation (the points of weight > 1e-9·p, weights / p, ``_weighted_quantiles`` of
    Δc and t_stop) on re-fitted lattices with five Δt_u and three noise ratios, on random
    heavy-tailed weights, and on values with many ties (a stable sort keeps their order); and
    ``predictive`` no longer calls numpy's argsort."""
    from controllers.solnic.grid_posterior import _quantiles3, _weighted_quantiles

    def numpy_predictive(g, dt_u, vr, br):
        mean, var, moves, ts = g.noise_moments(dt_u, vr, br)
        w = g.w * moves
        p = float(np.sum(w))
        keep = np.flatnonzero(w > 1e-9 * p)
        w, mean, var, ts = w[keep] / p, mean[keep], var[keep], ts[keep]
        (q16, q50, q84), i50 = _weighted_quantiles(mean, w, (0.16, 0.5, 0.84))
        (t16, t50, t84), _ = _weighted_quantiles(ts, w, (0.16, 0.5, 0.84))
        return [p, q50, (0.5 * (q84 - q16)) ** 2 + float(var[i50]), t50, (0.5 * (t84 - t16)) ** 2]

    p = PlantParams()
    rng = np.random.default_rng(12)
    g = FrictionGrid(p, [p.coulomb, p.stiction], np.diag([p.coulomb**2, p.stiction**2]), n=32)
    dc = pulse_table(p, 1.3e-3, np.array([p.coulomb]), np.array([p.stiction]))[0][0]
    cases = []
    for round_ in range(3):
        for dtu in (0.6e-3, 0.95e-3, 1.2e-3, 1.7e-3, 2.5e-3):
            for vr, br in ((0.0, 0.0), (2.5, 0.8), (1.3, 0.6)):
                cases.append((dtu, vr, br, None))
        cases.append((1.2e-3, 2.5, 0.8, "heavy-tailed"))
        for _ in range(3):
            g.update(1.3e-3, 1, dc * (1 + 0.05 * rng.standard_normal()), (0.05 * dc) ** 2, 2.5, 0.8)
        want = []
        for dtu, vr, br, w in cases[-16:]:
            w0 = g.w
            if w is not None:                            # random weights on this lattice
                w = rng.random(g.w.size) ** 8
                g.w = w / w.sum()
            want.append(numpy_predictive(g, dtu, vr, br))
            got = g.predictive(dtu, vr, br)
            g.w = w0
            assert [float.hex(v) for v in (got.p_motion, got.dc_mean, got.dc_var, got.t_stop_mean, got.t_stop_var)] \
                == [float.hex(v) for v in want[-1]]
    assert g.n_regrids > 0
    for _ in range(20):                                  # ties: the stable order decides the median's point
        x = rng.integers(0, 5, 40).astype(float)
        w = rng.random(40)
        w /= w.sum()
        (q, i) = _quantiles3(x, w)
        qs, i50 = _weighted_quantiles(x, w, (0.16, 0.5, 0.84))
        assert list(q) == qs and i == i50
    monkeypatch.setattr(np, "argsort", lambda *a, **k: (_ for _ in ()).throw(AssertionError("np.argsort")))
    assert g.predictive(1.2e-3, 2.5, 0.8).p_motion > 0


def test_compiled_loglik_is_the_numpy_loglik_bit_for_bit(monkeypatch):
    """A pulse's log-likelihood on the lattice (1) is one compiled call plus libm's log per point
    (issue 27; libm's, not numpy's SIMD ufunc, since 2026-11-28): equal byte for byte to the
    expression −(m − d)²/(2(R + v)) − ½·log(R + v), log by ``math.log`` entry by entry, with
    d = sign·mean where the shaft moves, for both signs, with and without the noise ratios, on the
    first lattice and re-fitted ones; and it no longer calls np.where."""
    p = PlantParams()
    rng = np.random.default_rng(13)
    g = FrictionGrid(p, [p.coulomb, p.stiction], np.diag([p.coulomb**2, p.stiction**2]), n=32)
    dc = pulse_table(p, 1.3e-3, np.array([p.coulomb]), np.array([p.stiction]))[0][0]
    cases, want = [], []
    for round_ in range(3):
        for dtu in (0.6e-3, 1.2e-3, 2.5e-3):
            for sign in (1, -1):
                for vr, br in ((0.0, 0.0), (2.5, 0.8), (0.0, 0.7), (1.9, 0.0)):
                    ob = (dtu, sign, sign * dc * rng.uniform(0.2, 2.0), (dc * rng.uniform(0.01, 0.5)) ** 2, vr, br)
                    mean, var, moves, _ = g.noise_moments(dtu, vr, br)
                    d = np.where(moves, sign * mean, 0.0)
                    var = ob[3] + var
                    cases.append((g.version, ob))
                    want.append(-0.5 * (ob[2] - d) ** 2 / var - 0.5 * np.array([math.log(v) for v in var]))
        with monkeypatch.context() as mp:
            mp.setattr(np, "where", lambda *a, **k: (_ for _ in ()).throw(AssertionError("np.where")))
            for (version, ob), w in zip(cases[-24:], want[-24:]):
                assert g.version == version and g._loglik(*ob).tobytes() == w.tobytes()
        for _ in range(3):
            g.update(1.3e-3, 1, dc * (1 + 0.05 * rng.standard_normal()), (0.05 * dc) ** 2, 2.5, 0.8)
    assert g.n_regrids > 0


def test_two_by_two_algebra_is_numpys_without_lapack():
    """The lattice's eigen-decomposition, inverse and determinant (plain float arithmetic, so the
    same bits under every BLAS kernel) against numpy's LAPACK: A·v = λ·v, orthonormal v, λ
    ascending, to 4 ulp of the largest |λ|; diagonal matrices included."""
    from controllers.solnic.grid_posterior import _det2, _eigh2, _inv2
    rng = np.random.default_rng(11)
    for k in range(500):
        a = rng.normal(size=(2, 2))
        m = a @ a.T * 10.0 ** rng.uniform(-6, 3)
        if k % 5 == 0:
            m[0, 1] = m[1, 0] = 0.0
        lam, vec = _eigh2(m)
        ref = np.linalg.eigh(m)[0]
        scale = np.max(np.abs(ref))
        assert lam[0] <= lam[1]
        np.testing.assert_allclose(lam, ref, rtol=0, atol=8e-16 * scale)
        np.testing.assert_allclose(m @ vec, vec * lam, rtol=0, atol=8e-16 * scale)
        np.testing.assert_allclose(vec.T @ vec, np.eye(2), rtol=0, atol=8e-16)
        assert abs(_det2(m) - np.linalg.det(m)) <= 4e-15 * scale * scale   # LAPACK: LU, a few roundings
        np.testing.assert_allclose(_inv2(m) @ m, np.eye(2), rtol=0, atol=8e-16 * np.linalg.cond(m))
    with pytest.raises(ValueError, match="invertible"):
        _inv2(np.zeros((2, 2)))


def test_a_solnic_modern_cell_calls_no_blas_or_lapack_through_numpy(monkeypatch):
    """The grid posterior's algebra stays off BLAS/LAPACK (whose kernels round per CPU): a 5-s
    thesis cell runs with numpy's linear-algebra entry points made to fail. (The ``@`` operator
    cannot be intercepted; the module has none.)"""
    from bench.runner import run_closed_loop
    from bench.scenarios import builtin_scenarios
    from controllers import make_controller

    def boom(*a, **k):
        raise AssertionError("BLAS/LAPACK on solnic-modern's path")

    for name in ("eigh", "det", "inv", "solve", "eig", "pinv", "norm"):
        monkeypatch.setattr(np.linalg, name, boom)
    for name in ("dot", "einsum", "matmul", "inner", "vdot", "tensordot"):
        monkeypatch.setattr(np, name, boom)
    s = builtin_scenarios()["thesis"]
    r = run_closed_loop(s.params, make_controller("solnic-modern"), duration_s=5.0, seed=0)
    assert r.status == "ok", r.message
    assert r.summary["pulses"] > 0
