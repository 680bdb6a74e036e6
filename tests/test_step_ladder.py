"""The noisy moving mode's step ladder (plant.multimode.zero_velocity) against independent truth.

The ladder lengthens a Gaussian sub-step when the state is far from a velocity zero (crossing
probability ≤ 6Φ(−8.5) per step) and, while reflecting, up to the regular sub-step when the
expected x1 error rate of the Skorokhod push stays within that of the fixed reflect sub-step at
zero velocity. Where that matters most — dither around the breakaway level, and a long
reflection regime from breakaway — the exact simulator's distributions must match
Euler–Maruyama with the same mode logic (plant.multimode.reference.fixed_step) at a step 50–500× finer
than the ladder's shortest rung.

Tolerances: two-sample KS p > 0.01 per statistic; means within 4 standard errors of the
difference (SE from both samples). EM's own bias (discrete monitoring of velocity zeros, O(√dt))
is below the Monte-Carlo noise here: with 8000 exact and 4000 EM paths at 0.1 µs the dither's
mean x1(9 ms) was 3.325 vs 3.310 µrad (SE of the difference 0.043), and the fixed sub-steps
before the ladder gave 3.339.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from plant import PlantParams
from plant.drive import DriveCommand, DriveType
from plant.multimode.interval import advance
from plant.randomness import NoiseStream
from plant.multimode.reference import Schedule, fixed_step
from plant.state import PlantState, SimOptions
from plant.multimode.zero_velocity import FAR_SIGMAS, LADDER, _push_bound, ladder_thresholds

P0 = PlantParams()
N_EXACT = 2000
N_EM = 1000


def _exact(x0: np.ndarray, mode: int, command: DriveCommand, duration: float, seed: int,
           split: float) -> tuple[np.ndarray, np.ndarray, float]:
    """N_EXACT paths from one stream: columns x1(split), x2(split), moving(split), x1(end); the
    mean sub-steps per path; the mean per-path sticks."""
    x = np.array(x0, dtype=float)
    x.flags.writeable = False
    first = DriveCommand(tuple(s for s in command.segments if s[0] < split), command.drive)
    rest = [(max(off - split, 0.0), lvl) for off, lvl in command.segments]
    rest = [(off, lvl) for i, (off, lvl) in enumerate(rest) if i + 1 == len(rest) or rest[i + 1][0] > 0.0]
    second = DriveCommand(tuple(rest), command.drive)
    noise = NoiseStream.from_seed(seed)
    out = np.empty((N_EXACT, 4))
    substeps = sticks = 0
    for i in range(N_EXACT):
        a = advance(PlantState(0.0, x, mode, False), first, P0, noise, duration=split)
        b = advance(a.state, second, P0, noise, duration=duration - split)
        assert a.status == "ok" and b.status == "ok"
        out[i] = a.state.x[0], a.state.x[1], float(a.state.mode != 2), b.state.x[0]
        substeps += a.n_substeps + b.n_substeps
        sticks += a.n_sticks + b.n_sticks
    return out, substeps / N_EXACT, sticks / N_EXACT


def _em(x0: np.ndarray, mode: int, command: DriveCommand, duration: float, dt: float, seed: int,
        split: float) -> np.ndarray:
    """N_EM Euler–Maruyama paths: the same columns as :func:`_exact`."""
    sched = Schedule(np.array([s[0] for s in command.segments]), np.array([s[1] for s in command.segments]),
                     command.drive, duration)
    start = np.tile(np.r_[x0[:5], float(mode)], (N_EM, 1))
    rng = np.random.default_rng(seed)
    head = Schedule(sched.times, sched.levels, sched.drive, split)
    a = fixed_step(P0, head, dt, x0=start, n_paths=N_EM, rng=rng)
    mid = a.final[:, [0, 1, 2, 3, 4, 6]]
    k = np.searchsorted(sched.times, split, side="right") - 1
    tail = Schedule(np.r_[split, sched.times[k + 1:]], np.r_[sched.levels[k], sched.levels[k + 1:]], sched.drive,
                    duration)
    b = fixed_step(P0, tail, dt, x0=mid, n_paths=N_EM, rng=rng)
    return np.column_stack([a.final[:, 0], a.final[:, 1], (a.final[:, 6] != 2.0).astype(float), b.final[:, 0]])


def _compare(exact: np.ndarray, em: np.ndarray, label: str, capsys) -> None:
    names = ("x1(split)", "x2(split)", "x1(end)")
    with capsys.disabled():
        print(f"\n  {label}:")
        for col, name in zip((0, 1, 3), names):
            e, f = exact[:, col], em[:, col]
            se = math.sqrt(e.var(ddof=1) / len(e) + f.var(ddof=1) / len(f))
            ks = stats.ks_2samp(e, f)
            print(f"    {name}: exact mean {e.mean():.4e} sd {e.std():.3e}; EM mean {f.mean():.4e} sd {f.std():.3e}; "
                  f"diff {(e.mean() - f.mean()) / se:+.2f} SE; KS p = {ks.pvalue:.3f}")
            assert ks.pvalue > 0.01, name
            assert abs(e.mean() - f.mean()) < 4 * se, name
        pe, pf = exact[:, 2].mean(), em[:, 2].mean()
        se = math.sqrt(pe * (1 - pe) / len(exact) + pf * (1 - pf) / len(em))
        print(f"    moving at split: exact {pe:.3f}, EM {pf:.3f}")
        assert abs(pe - pf) < 4 * max(se, 1e-3)


def test_dither_around_breakaway_matches_euler_maruyama(capsys):
    """250 Hz square wave of ±22 ozf·in (x3 swings about ±2.7, just beyond ks = 2.1) from a stuck
    shaft at x3 = −2.0: from the first crest on, every half-period breaks away, reflects, moves
    and sticks (≈ 3.7 sticks per path). Split at 4.5 ms, where about a third of the paths move;
    end at 9 ms. (The start is inside the stiction band: a stuck start beyond it breaks away at
    once with x3 set to ±ks, which EM does not do.)"""
    half = 2e-3
    cmd = DriveCommand(tuple((k * half, 22.0 * (1 if k % 2 == 0 else -1)) for k in range(5)), DriveType.LINEAR)
    x0 = np.array([0.0, 0.0, -2.0, 0.0, 0.0, 0.0])
    exact, substeps, sticks = _exact(x0, 2, cmd, 9e-3, seed=11, split=4.5e-3)
    em = _em(x0, 2, cmd, 9e-3, 2e-7, seed=12, split=4.5e-3)
    _compare(exact, em, f"dither, {substeps:.0f} sub-steps and {sticks:.2f} sticks per path", capsys)
    assert sticks > 3.0                              # the drive sticks the shaft every half-period
    assert 0.2 < exact[:, 2].mean() < 0.8            # a mixed population at the split


def test_long_reflection_from_breakaway_matches_euler_maruyama(capsys):
    """Breakaway at x3 = ks under u = 2.4 > ks: the torque stays beyond stiction, so x2 is a
    reflected diffusion from 0 with a small drift for the whole 3 ms (every push enters x1)."""
    ks = P0.stiction
    cmd = DriveCommand.hold(2.4, DriveType.LINEAR)
    x0 = np.array([0.0, 0.0, ks, 0.0, 0.0, 0.0])
    exact, substeps, _ = _exact(x0, 3, cmd, 3e-3, seed=21, split=1e-3)
    em = _em(x0, 3, cmd, 3e-3, 1e-7, seed=22, split=1e-3)
    assert np.all(exact[:, 2] == 1.0)
    # the ladder is in use: fewer steps than the fixed reflect sub-step would take
    assert substeps < 0.75 * 3e-3 / SimOptions().reflect_substep
    _compare(exact, em, f"reflection, {substeps:.0f} sub-steps per path", capsys)


def test_push_bound_is_the_mean_overshoot_of_a_half_normal():
    """G(κ) = E[(|Z| − κ)⁺] (the driftless E[L_h]/(σ√h) from x2 = κσ√h), by Monte Carlo."""
    z = np.abs(np.random.default_rng(3).standard_normal(2_000_000))
    for kappa in (0.0, 0.3, 0.8, 1.5, 2.5):
        mc = np.maximum(z - kappa, 0.0)
        assert _push_bound(kappa) == pytest.approx(mc.mean(), abs=4 * mc.std() / math.sqrt(len(z)))


def test_ladder_thresholds_follow_their_rules():
    """The far rule's 6Φ(−K) bound, and the reflect budget √(2^k)·G(κ_k) = G(0), recomputed."""
    p = P0
    sub, rsub = 1e-4, 1e-5
    TH = ladder_thresholds(p.alpha, p.sigma2_sq, p.sigma5_sq, p.beta5, sub, rsub)
    assert TH.shape == (2, LADDER) and np.all(TH[:, 0] == -np.inf)
    assert np.all(np.diff(TH[:, 1:], axis=1) > 0)
    assert 6 * stats.norm.sf(FAR_SIGMAS) < 1e-16
    sig_v = p.alpha * math.sqrt(p.sigma2_sq)
    for k in range(1, LADDER):
        h = sub * 2**k
        far = FAR_SIGMAS * (sig_v * math.sqrt(h) + p.alpha * math.sqrt(p.sigma5_sq) * h**1.5 * math.exp(p.beta5 * h))
        assert TH[0, k] == pytest.approx(far, rel=1e-12)
        h = rsub * 2**k
        if h <= sub:
            kappa = TH[1, k] / (sig_v * math.sqrt(h))
            # independent G: E[(|Z| − κ)⁺] by quadrature of the half-normal tail
            g = 2 * (stats.norm.pdf(kappa) - kappa * stats.norm.sf(kappa))
            assert math.sqrt(2**k) * g == pytest.approx(math.sqrt(2 / math.pi), rel=1e-9)
        else:
            assert TH[1, k] > 8 * sig_v * math.sqrt(h)


@pytest.mark.parametrize("params", [P0, P0.replace(command_velocity_std=0.0)])
def test_bridge_law_matches_gaussian_conditioning(params):
    """The bisection's midpoint law (Matheron gain G, conditional factor C) against numpy:
    G = Q(w/2)·Φ_hᵀ·pinv(Q(w)) on the noisy block, Σ = Q(w/2) − G·Φ_h·Q(w/2); with σ4 = 0 (the
    pulse plant) x4 has no noise, and scratch memory full of NaN must not leak into the law."""
    from plant.multimode.moving import NOISY_BLOCK, phi_moving, q_moving
    from plant.multimode.zero_velocity import _bridge_law

    prm = params.kernel_record()[0]
    for mode in (1, 3):
        for w in (1e-4, 3.3e-5, 1e-6):
            Ph, Pw, G, C = np.empty((7, 7)), np.empty((7, 7)), np.empty((4, 4)), np.empty((4, 4))
            _bridge_law(mode, w, prm, Ph, Pw, G, C, np.full(116, np.nan))
            Q1, Qw, P = np.empty((4, 4)), np.empty((4, 4)), np.empty((7, 7))
            q_moving(mode, w / 2, prm, Q1)
            q_moving(mode, w, prm, Qw)
            phi_moving(mode, w / 2, prm, P)
            P2 = P[np.ix_(NOISY_BLOCK, NOISY_BLOCK)]
            d = np.sqrt(np.diag(Qw))
            d[d == 0] = 1.0
            Gref = (Q1 @ P2.T / d) @ np.linalg.pinv(Qw / np.outer(d, d), rcond=1e-13) / d
            S = Q1 - Gref @ P2 @ Q1
            s1 = np.sqrt(np.diag(Q1))
            s1[s1 == 0] = 1.0
            assert np.all(np.isfinite(G)) and np.all(np.isfinite(C))
            assert np.allclose(G * d[None, :] / s1[:, None], Gref * d[None, :] / s1[:, None], rtol=0, atol=1e-9)
            assert C[0, 0] == pytest.approx(math.sqrt(S[1, 1]), rel=1e-9)
            # the conditional covariance of (x1, x4, x5) given x2, rebuilt from C
            o = [0, 2, 3]
            R = S[np.ix_(o, o)] - np.outer(S[o, 1], S[1, o]) / S[1, 1]
            Lc = C[1:, 1:]
            so = s1[o]
            assert np.allclose((Lc @ Lc.T) / np.outer(so, so), R / np.outer(so, so), rtol=0, atol=1e-9)
            # regression of (x1, x4, x5) on x2, compared as correlations (x1's is round-off here)
            sc = math.sqrt(S[1, 1]) / np.where(np.diag(S)[o] > 0, np.sqrt(np.abs(np.diag(S)[o])), 1.0)
            assert np.allclose(C[1:, 0] * sc, S[o, 1] / S[1, 1] * sc, rtol=0, atol=1e-7)
