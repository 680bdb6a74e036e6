"""Slow studies of issue 25 on the plan with torque holds (docs/axis.md has the measured numbers).

* coverage of the stribeck fit: random axes of tests/identify_draws.py (seed 2611, not used while
  writing the fit or the plan), Table 2-1 noise, default plan, 10-replicate bootstrap;
* coverage of the lugre fit (same seed and draws, family index 2);
* the auto pick: seed 7531, 2 logs per family (test_ninth_auto_picks_the_generating_family, the
  ninth session's dev-chosen threshold); seed 5757 (test_eighth_auto_picks_the_generating_family, the
  eighth session's features); seed 9393 (test_auto_picks_the_generating_family; 6262 was the
  fourth session's, 6161 the third session's, on the output-error rule) and
  tests/test_identify.py::test_auto_on_held_out_truth (seed 4711, 10 per family; SOLNIC_AXIS_STUDY=1).
"""

from __future__ import annotations

import math
import os
import time

import numpy as np
import pytest

from plant.identification import design_experiment, fit_log, simulate_log
from plant.identification.families import FAMILY_FREE

CORE = ("coulomb", "stiction", "inertia", "motor_time_constant")
AUTO_SEED = 6262   # the auto study of issue 25's fourth session (a dev seed since the fifth)
# the auto study of issue 25's fifth session: named before it ran, never used while writing the
# t predictive, the robust fold fits or the signed-rank rule (dev seed 6262)
FRESH_AUTO_SEED = 9393


def coverage_case(family: str, case: int, seed: int = 2611, bootstrap: int = 10, options=None):
    """One log of ``family`` at the ``case``-th random axis: per fitted field (truth, estimate,
    interval, identified?) and the fit's CPU seconds. The truth of k̄c, k̄s is the effective
    level k̄ + x5(0) (SPEC §2), the others the drawn values. ``options``: the plan's
    ``ExperimentOptions`` (default: the default plan)."""
    from tests.identify_draws import draw

    rng = np.random.default_rng([seed, list(FAMILY_FREE).index(family)])
    for _ in range(case + 1):
        p = draw(family, rng)
    plan = design_experiment() if options is None else design_experiment(options)
    log, truth = simulate_log(plan, family, p, seed * 1000 + case)
    t0 = time.process_time()
    fit = fit_log(log, family, bootstrap=bootstrap, seed=case)
    cpu = time.process_time() - t0
    out = {}
    for k in CORE + FAMILY_FREE[family]:
        v = truth[k] if k in ("coulomb", "stiction") else getattr(p, k)
        out[k] = (v, fit.estimates[k], fit.interval[k], k not in fit.not_identified)
    return out, cpu


def auto_case(family: str, case: int, seed: int = AUTO_SEED, options=None, separable=None, **choose):
    """``choose_family`` (bootstrap 0; the rule's threshold ``separable``, default the default; its
    other keyword options ``choose``, e.g. ``restart=True``) on one log of ``family`` at the
    ``case``-th random axis of tests/identify_draws.py (draws from ``default_rng([seed, f])``, log
    seed seed·1000 + 100·f + case, f the family's index in FAMILY_FREE; the plan of ``options``,
    default the default plan): (choice, CPU seconds)."""
    from plant.identification import ExperimentOptions
    from plant.identification.fit import choose_family
    from tests.identify_draws import draw

    f = list(FAMILY_FREE).index(family)
    rng = np.random.default_rng([seed, f])
    for _ in range(case + 1):
        p = draw(family, rng)
    log, _ = simulate_log(design_experiment(options or ExperimentOptions()), family, p, seed * 1000 + 100 * f + case)
    t0 = time.process_time()
    _, choice = choose_family(log, bootstrap=0, separable=separable, **choose)
    return choice, time.process_time() - t0


def separation_case(family: str, case: int, seed: int = 4242, replicates: int = 40) -> dict[str, float]:
    """How far the generating law is from the best multimode fit, against the friction noise
    (docs/axis.md, "what the log can tell"): the noise-free log of the ``case``-th axis of
    ``default_rng([seed, f])``, multimode fitted to it (``bootstrap=0``), and per kind of move
    (ramp, hold, pulse) the sum over moves of the Mahalanobis distance² between the two noise-free
    y, the covariance that of ``replicates`` noisy logs of the generating family (x5 off; low
    rank, plus σ1²·I). Seed 4242 was the dev seed of the fourth session."""
    from plant.identification.fit import moves
    from tests.identify_draws import draw

    plan = design_experiment()
    segs = moves(plan.with_y(np.zeros(plan.n)))
    rng = np.random.default_rng([seed, list(FAMILY_FREE).index(family)])
    for _ in range(case + 1):
        p = draw(family, rng)
    log0, _ = simulate_log(plan, family, p, None)
    fit = fit_log(log0, "multimode", bootstrap=0)
    quiet = p.replace(correlated_friction_std=0.0)
    Y = np.array([simulate_log(plan, family, quiet, 1000 + k)[0].y for k in range(replicates)])
    s1 = p.measurement_noise_std
    out = {"ramp": 0.0, "hold": 0.0, "pulse": 0.0}
    for s, e in segs:
        cmds = plan.commands[s:e]
        on = sum(1 for c in cmds if any(v != 0.0 for _, v in c.segments))
        kind = "pulse" if on <= 5 else ("ramp" if cmds[1].segments != cmds[0].segments else "hold")
        idx = np.arange(s + 1, e)
        d = log0.y[idx] - fit.y_model[idx]
        A = (Y[:, idx] - Y[:, idx].mean(axis=0)) / math.sqrt(replicates - 1)
        Ad = A @ d       # (s1² I + Aᵀ A)⁻¹ by Woodbury
        out[kind] += float(d @ d - Ad @ np.linalg.solve(np.eye(replicates) * s1 ** 2 + A @ A.T, Ad)) / s1 ** 2
    return out


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 10 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_stribeck_coverage_on_held_out_truth():
    """10 random stribeck axes: every identified core field (k̄c, k̄s, J, τ3) inside its stated 95 %
    interval in ≥ 90 % of the cases; v_s and b printed with their coverage and how often they
    are marked not identified (docs/axis.md)."""
    inside, rows = [], []
    for case in range(10):
        res, cpu = coverage_case("stribeck", case)
        rows.append((res, cpu))
        inside += [lo <= v <= hi for k, (v, _, (lo, hi), _) in res.items() if k in CORE]
    for res, cpu in rows:
        print({k: (round(v, 5), round(e, 5), (round(lo, 5), round(hi, 5)), ok) for k, (v, e, (lo, hi), ok) in res.items()},
              f"cpu {cpu:.1f}")
    assert np.mean(inside) >= 0.90


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 50 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_lugre_coverage_on_held_out_truth():
    """10 random lugre axes (seed 2611, draws from ``default_rng([2611, 2])``, not used while writing
    the fit): every fitted field (k̄c, k̄s, J, τ3, v_s, σ0) inside its stated 95 % interval in ≥ 90 %
    of the cases (the must-show of issue 25). Each log costs about 300 CPU s (the point fit ~30 s
    and the 10-replicate bootstrap; the default 300-s budget may cut the bootstrap, stated in
    ``fit.method``). Measured so far (docs/axis.md, "Coverage of the lugre fit"): cases 0 and 1
    only, 6 of 12 inside (50 %), 301 CPU s each — not run to the end; it is expected to fail.
    (Measured with the bootstrap before issue 25's fourth session; the fresh-seed study is
    :func:`test_fresh_lugre_coverage_all_fields`.)"""
    inside = []
    for case in range(10):
        res, cpu = coverage_case("lugre", case)
        print({k: (round(v, 6), round(e, 6), (round(lo, 6), round(hi, 6)), ok) for k, (v, e, (lo, hi), ok) in res.items()},
              f"cpu {cpu:.1f}")
        inside += [lo <= v <= hi for v, _, (lo, hi), _ in res.values()]
    assert np.mean(inside) >= 0.90


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 10 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured (2026-11-27, fifth session: t predictive, robust multi-start fold "
                   "fits, signed-rank rule) on the 8 logs of the fresh seed 9393: 5 of 8 — multimode 2/2, lugre 2/2, "
                   "two-mass 1/2 (other: multimode), stribeck 0/2 (multimode, multimode: signed-rank z = 1.35 and "
                   "1.92, not > 2); below the must-show of ≥ 90 % (docs/axis.md)")
def test_auto_picks_the_generating_family():
    """``--family auto`` on 2 fresh logs per family (seed 9393, cases 0–1, :func:`auto_case`; the
    criterion, the fits and the rule were fixed before these logs ran): the generating family picked
    in ≥ 90 % of the 8 logs (the must-show of issue 25 asks ≥ 10 logs per family; docs/axis.md has
    the confusion matrix and the CPU per log). Measured: 5 of 8, CPU 47–151 s per log (median 68 s;
    one process per log, loaded machine). The fourth session's rule: 3 of 7 on seed 6262; the
    third session's output-error rule: 3 of 8 on seed 6161. Measured with the fold fits stopping at
    CPU-clock budgets (a rerun under another load could differ by a fit); since the seventh session
    the budgets count work (docs/axis.md, "Budgets"), so a rerun gives the same picks anywhere.
    Measured with the fifth session's score features; since the eighth session the held-out score
    reads each sample after the command (not re-run on this seed: see
    :func:`test_eighth_auto_picks_the_generating_family`)."""
    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            choice, cpu = auto_case(family, case, seed=FRESH_AUTO_SEED)
            picked[family, case] = choice.family
            print(family, case, choice.family, f"cpu {cpu:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked


# the auto study of issue 25's eighth session (features: each sample after the command, dev seed
# 8484): named before it ran, never used while choosing the features
EIGHTH_AUTO_SEED = 5757


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 11 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured (2026-11-27, eighth session) on the 8 logs of the fresh seed 5757 "
                   "with the default features (the fifth session's): 7 of 8 — two-mass k=0 picked multimode (the "
                   "shaft not seen); below the must-show of ≥ 90 % (docs/axis.md)")
def test_eighth_auto_picks_the_generating_family():
    """``--family auto`` (default features, :data:`plant.identification.fit._WINDOW_SPEC`) on 2
    fresh logs per family (seed 5757, cases 0–1, :func:`auto_case`, default plan): the generating
    family picked in ≥ 90 % of the 8 logs (docs/axis.md, "Eighth session: auto"). Measured: the
    study ran with the finer set (each of the 5 samples after the command a feature of the held-out
    score, :data:`~plant.identification.fit._FINER_WINDOW_SPEC`) and picked 6 of 8 (stribeck k=1:
    multimode, z = 1.44; two-mass k=0: multimode); its fold fits — the same under both sets —
    scored with the default set picked 7 of 8. The default was kept at the merge (the finer set
    had no held-out evidence for it); 7 of 8 is that choice's number, made after seeing this seed.
    CPU 36–158 s per log (median 67 s; one process per log, two at a time, loaded machine)."""
    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            choice, cpu = auto_case(family, case, seed=EIGHTH_AUTO_SEED)
            picked[family, case] = choice.family
            print(family, case, choice.family, f"cpu {cpu:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked


# the auto study of issue 25's ninth session: named before any run of this session, never used
# while tuning the rule (dev seed 8484, tests/identify_dev.py); the candidate was fixed before it ran
NINTH_AUTO_SEED = 7531


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 6 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured (2026-11-28, ninth session) on the 8 logs of the fresh "
                   "seed 7531 with the candidate threshold 0.5: 6 of 8 — stribeck k=1 picked multimode (multimode best by "
                   "the mean), lugre k=0 picked stribeck (stribeck best by the mean, lugre better by ranks, z = -3.18); "
                   "the default threshold 2 also 6 of 8 (lugre k=0: multimode); below the must-show of >= 90 % "
                   "(docs/axis.md)")
def test_ninth_auto_picks_the_generating_family():
    """``--family auto`` with the ninth session's candidate threshold (``separable=0.5``,
    :data:`plant.identification.fit._NINTH_SEPARABLE_Z`, chosen on dev seed 8484 before this seed
    ran) on 2 fresh logs per family (seed 7531, cases 0–1, :func:`auto_case`, default plan): the
    generating family picked in ≥ 90 % of the 8 logs (docs/axis.md, "Ninth session: auto"). The
    default rule's pick (threshold 2) on the same fold fits is printed beside it. Measured with
    tests/identify_dev.py (the same fold fits, no final point fit): 6 of 8 at 0.5 and 6 of 8 at 2;
    CPU of the choice 27–212 s per log (median 48 s; one process per log, two at a time, load 10–15)."""
    from plant.identification.fit import _NINTH_SEPARABLE_Z, _rule

    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            choice, cpu = auto_case(family, case, seed=NINTH_AUTO_SEED, separable=_NINTH_SEPARABLE_Z)
            picked[family, case] = choice.family
            fams = list(choice.score)
            default = _rule(fams, choice.score, {f: w for f, (w, _) in choice.ranks.items()},
                            {f: sd for f, (_, sd) in choice.ranks.items()}, 2.0)
            print(family, case, choice.family, "(threshold 2:", default + ")", f"cpu {cpu:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked


FRESH_SEED = 7207   # the coverage study of issue 25's fourth session (dev seed 5150; never used while writing)


def _fresh_coverage(family: str, cases, seed: int = FRESH_SEED) -> dict[str, list[bool]]:
    """Per fitted field, inside its stated 95 % interval on each of ``cases`` (:func:`coverage_case`
    at ``seed``, 10-replicate bootstrap); relative errors and CPU printed."""
    inside: dict[str, list[bool]] = {}
    for case in cases:
        res, cpu = coverage_case(family, case, seed=seed, bootstrap=10)
        print(family, case, f"cpu {cpu:.1f}", {k: (round(e / v - 1, 3), lo <= v <= hi) for k, (v, e, (lo, hi), _) in res.items()})
        for k, (v, _, (lo, hi), _) in res.items():
            inside.setdefault(k, []).append(lo <= v <= hi)
    print({k: f"{sum(v)}/{len(v)}" for k, v in inside.items()})
    return inside


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 4 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_fresh_stribeck_coverage_all_fields():
    """10 random stribeck axes at the fresh seed 7207 (draws from ``default_rng([7207, 1])``): every
    fitted field (k̄c, k̄s, J, τ3, v_s, b) inside its stated 95 % interval in ≥ 90 % of the 60 cases.
    Measured (2026-11-27, loaded machine): 54 of 60 (90.0 %) — k̄c 9/10, k̄s 10/10, J 10/10,
    τ3 8/10, v_s 8/10, b 9/10; but v_s reached its fit bound in 6 logs and then has the bounded
    range as its interval (marked not identified in 9 of 10; median |error| 92 %); the core alone
    37 of 40. CPU per log 19–92 s (median 26 s). docs/axis.md, "Fourth session"."""
    inside = _fresh_coverage("stribeck", range(10))
    assert np.mean([x for v in inside.values() for x in v]) >= 0.90


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 5 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_fresh_two_mass_coverage_all_fields():
    """10 random two-mass axes at the fresh seed 7207 (draws from ``default_rng([7207, 3])``): every
    fitted field (k̄c, k̄s, J, τ3, k_sh) inside its stated 95 % interval in ≥ 90 % of the 50 cases.
    Measured (2026-11-27, loaded machine): 43 of 50 (86 %), a miss — k̄c 10/10, k̄s 7/10 (misses
    −8 %, +14 %, −33 %), J 10/10, τ3 7/10, k_sh 9/10 (marked not identified in 6 of 10; median
    |error| 87 %). CPU per log 7–274 s (median 10 s). docs/axis.md, "Fourth session"."""
    inside = _fresh_coverage("two-mass", range(10))
    assert np.mean([x for v in inside.values() for x in v]) >= 0.90


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 15 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_fresh_lugre_coverage_all_fields():
    """10 random lugre axes at the fresh seed 7207 (draws from ``default_rng([7207, 2])``): every
    fitted field (k̄c, k̄s, J, τ3, v_s, σ0) inside its stated 95 % interval in ≥ 90 % of the 60 cases.
    Measured (2026-11-27, loaded machine): only cases 0, 3, 4, 5 ran to the end, 24 of 24 inside,
    with wide intervals (σ0, v_s marked not identified on all four); 149–166 CPU s per log. Case 1 was
    stopped after > 300 CPU s; case 2 crashed on a diverged replicate log and, re-run after the fix,
    had 2 of 6 inside (k̄s +46 %; J, τ3, v_s zero-width intervals from refits that never moved, now
    left out): 26 of 30 on five logs, a miss.
    Coverage over 10 logs is not shown. docs/axis.md, "Fourth session"."""
    inside = _fresh_coverage("lugre", range(10))
    assert np.mean([x for v in inside.values() for x in v]) >= 0.90


FIFTH_SEED = 3907   # issue 25's fifth session: named before any run (designed starts, bootstrap on the point fit's path)
LUGRE_CASES = 10      # the must-show asks >= 10 logs (cases 5-9 run in the seventh session)
TWO_MASS_CASES = 5


def _fifth_coverage(family: str, cases) -> float:
    """Share of the fitted fields inside their stated 95 % intervals over ``cases`` at
    :data:`FIFTH_SEED` (:func:`coverage_case`, 10-replicate bootstrap; per case printed)."""
    inside = _fresh_coverage(family, cases, FIFTH_SEED)
    return float(np.mean([x for v in inside.values() for x in v]))


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 30 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_fifth_lugre_coverage_all_fields():
    """Random lugre axes at the fresh seed 3907 (draws from ``default_rng([3907, 2])``; named before
    any run): every fitted field inside its stated 95 % interval in ≥ 90 % of the cases, with the
    designed starts and the bootstrap on the point fit's path (issue 25's fifth session).
    Measured on cases 0–4: 24 of 30 inside (80 %), a miss: case 3 ran past the 300-s CPU budget
    (302 s) with intervals 0–7 % wide, 2 of 6 inside; the other four 22 of 24 (v_s −76 %, −69 % out).
    CPU per log 77, 327, 137, 302, 129 s: the 60-s goal missed (docs/axis.md, "Fifth session").
    Cases 5–9 (seventh session, on the work-clock budgets; estimator otherwise unchanged): 26 of 30
    — v_s out on cases 5 and 9 (+60 %, −83 %), k̄c and k̄s out on case 8 (+7 %, −19 %); CPU 316,
    76, 185, 358, 177 s. All ten: 50 of 60 (83 %), a miss. Re-run with v_s's calibration interval
    (eighth session, the same point estimates): 50 of 60 again (v_s 8/10, τ3 8/10, σ0 9/10); cases 3
    and 8 (CPU 320, 338 s) had the bootstrap cut below 5 replicates by the work budget and the
    cluster-robust covariance stood in (8 of the 10 misses). CPU per log 70–338 s (median 112 s).
    With 3 replicates enough for the bootstrap's t interval (``fit._MIN_REPLICATES``, eighth session,
    chosen after seeing these misses, so not a held-out test of it): cases 3 and 8 re-run, the same
    estimates, 12 of 12 inside but wide (k̄s not identified on both) — **58 of 60 (96.7 %)**; the other
    eight cases are unchanged by it (5 or more replicates each). The strict xfail is removed."""
    assert _fifth_coverage("lugre", range(LUGRE_CASES)) >= 0.90


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 4 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_fifth_two_mass_coverage_all_fields():
    """Random two-mass axes at the fresh seed 3907 (draws from ``default_rng([3907, 3])``; named
    before any run): every fitted field inside its stated 95 % interval in ≥ 90 % of the cases,
    with the designed starts and the bootstrap on the point fit's path (issue 25's fifth session).
    Measured on cases 0–4: 18 of 25 inside (72 %), a miss: the shaft stiffness is fitted 1.5–11 times
    too stiff and its bootstrap, simulated at that stiff estimate, does not see softer shafts; case 1
    ran 334 CPU s, past the 300-s budget, with intervals 1–7 % wide: 1 of 5 inside (which fallback
    the budget rule took was not recorded).
    CPU per log 19, 334, 19, 50, 248 s (docs/axis.md, "Fifth session"). Re-run with k_sh's calibration
    interval (seventh session; the point estimates unchanged): 25 of 25 inside, k_sh the bounded
    range (not identified) on all five; CPU per log 20, 21, 24, 25, 146 s. The strict xfail is removed."""
    assert _fifth_coverage("two-mass", range(TWO_MASS_CASES)) >= 0.90


SEVENTH_SEED = 2718   # issue 25's seventh session: named before any run (the calibration interval for k_sh;
                      # dev seed 5150)
SEVENTH_TWO_MASS_CASES = 10


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 15 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_seventh_two_mass_coverage_all_fields():
    """Random two-mass axes at the fresh seed 2718 (draws from ``default_rng([2718, 3])``, log seed
    2718·1000 + k; named before any run): every fitted field inside its stated 95 % interval in
    ≥ 90 % of the cases, with k_sh's calibration interval (replicate truths spread over
    2.5e3–2e5 ozf·in/rad, issue 25's seventh session; docs/axis.md, "Seventh session").
    Measured (2026-11-27, loaded machine, cases 0–9): 47 of 50 (94 %) — k̄c, k̄s, J 9/10 (all three
    misses on case 2, where the 300-s budget cut the bootstrap below 5 replicates and the optimistic
    cluster-robust covariance stood in), τ3 10/10, k_sh 10/10 (the bounded range, not identified,
    on 8). CPU per log 16–377 s (median 22 s)."""
    inside = _fresh_coverage("two-mass", range(SEVENTH_TWO_MASS_CASES), SEVENTH_SEED)
    assert np.mean([x for v in inside.values() for x in v]) >= 0.90


EIGHTH_SEED = 8191    # issue 25's eighth session: named before any run (the calibration interval for lugre's v_s;
                      # dev seed 1729)
EIGHTH_LUGRE_CASES = 10


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 30 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_eighth_lugre_coverage_all_fields():
    """Random lugre axes at the fresh seed 8191 (draws from ``default_rng([8191, 2])``, log seed
    8191·1000 + k; named before any run): every fitted field (k̄c, k̄s, J, τ3, v_s, σ0) inside its stated
    95 % interval in ≥ 90 % of the cases, with v_s's calibration interval (replicate truths spread over
    0.5–24 mrad/s, issue 25's eighth session; docs/axis.md, "Eighth session").
    Measured (cases 0–9, `fit_log(…, bootstrap=10)`, one log per process, two at a time, `nice 10`):
    52 of 60 (86.7 %), a miss. Case 4 (σ0 fitted +455 %, 332 CPU s): the budget cut its bootstrap
    after 4 replicates, the optimistic cluster-robust covariance stood in, 1 of 6 inside; the other
    nine logs 51 of 54. Also out: v_s on case 3 (+34 %; calibration slope −0.36), k̄c and τ3 on case 8
    (−15 %, −50 %). v_s marked not identified on 9 of 10 (calibration slopes −0.36 to 0.55).
    CPU per log 58–332 s (median 128 s): the 60-s goal is missed. With 3 replicates enough for the
    bootstrap's t interval (``fit._MIN_REPLICATES``, chosen after seeing this study, so not a held-out
    test of it): case 4 re-run, the same estimates, 6 of 6 inside (k̄c 1.03–1.23, k̄s 0.44–2.03,
    τ3 5.4–21 ms; v_s and σ0 not identified) — **57 of 60 (95 %)**; the other nine cases are unchanged
    by it (5 or more replicates each). The strict xfail is removed."""
    inside = _fresh_coverage("lugre", range(EIGHTH_LUGRE_CASES), EIGHTH_SEED)
    assert np.mean([x for v in inside.values() for x in v]) >= 0.90


NINTH_SEED = 6571     # issue 25's ninth session (helper lugre9): named and committed before any run, to confirm
                      # lugre (and two-mass) coverage on held-out logs with fit._MIN_REPLICATES = 3 (chosen in
                      # the eighth session after seeing seeds 8191 and 3907); never used while writing the fit
NINTH_CASES = 10


def _ninth_coverage(family: str, cases=range(NINTH_CASES)) -> float:
    """Share of the fitted fields inside their stated 95 % intervals over ``cases`` at
    :data:`NINTH_SEED` (:func:`coverage_case`, 10-replicate bootstrap, as :func:`_fresh_coverage`).
    A log whose fit raises states no interval: its fields count as outside (the error printed)."""
    inside, n_fields = [], 4 + len(FAMILY_FREE[family])
    for case in cases:
        try:
            res, cpu = coverage_case(family, case, seed=NINTH_SEED, bootstrap=10)
        except (ValueError, RuntimeError) as exc:
            print(family, case, "the fit raised:", exc)
            inside += [False] * n_fields
            continue
        print(family, case, f"cpu {cpu:.1f}", {k: (round(e / v - 1, 3), lo <= v <= hi) for k, (v, e, (lo, hi), _) in res.items()})
        inside += [lo <= v <= hi for v, _, (lo, hi), _ in res.values()]
    return float(np.mean(inside))


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 30 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_ninth_lugre_coverage_all_fields():
    """Random lugre axes at the held-out seed 6571 (:data:`NINTH_SEED`, draws from ``default_rng([6571, 2])``,
    log seed 6571·1000 + k; named and committed before any run): every fitted field (k̄c, k̄s, J, τ3, v_s, σ0)
    inside its stated 95 % interval in ≥ 90 % of the 60 cases, on the code with v_s's calibration
    interval and ``fit._MIN_REPLICATES`` = 3 (both chosen in the eighth session; nothing tuned on this
    seed). Measured (one log per process, `nice 10`, load 7–14): **56 of 60 (93.3 %)** — case 9 first
    raised (a bootstrap truth failing LuGre's dissipativity check; fixed in the same session by leaving
    such calibration points out, no other log changed; re-run 5 of 6); the other nine 51 of 54 — k̄c
    9/9, k̄s 8/9, J 7/9, τ3 9/9, v_s 9/9 (not identified on 8), σ0 9/9 (not identified on 6). Misses:
    J on case 1 (+92 %), J on case 4 (−8.7 %: the budget cut the bootstrap after 1 replicate, the
    cluster-robust covariance stood in), k̄s on case 5 (+14 %), k̄c on case 9 (−3.7 %, 4 replicates).
    CPU per log 40–329 s (median 147 s), ≤ 60 s on 2 of 10. docs/axis.md, "Ninth session"."""
    assert _ninth_coverage("lugre") >= 0.90


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"),
                    reason="about 5 min of CPU on the final code (tenth session): SOLNIC_AXIS_STUDY=1")
def test_ninth_two_mass_coverage_all_fields():
    """Random two-mass axes at the held-out seed 6571 (:data:`NINTH_SEED`, draws from ``default_rng([6571, 3])``,
    log seed 6571·1000 + k; named before any run): every fitted field (k̄c, k̄s, J, τ3, k_sh) inside its
    stated 95 % interval in ≥ 90 % of the 50 cases, with k_sh's calibration interval (seventh session;
    confirmed before on seed 2718 only). Measured: case 1 raised (no fit: see
    :func:`test_identify_start_below_u_max`); case 8 ran past 481 CPU s (the 300-s work budget had not
    stopped it) and was stopped; the other eight 37 of 40 — k̄c 6/8 (case 3 −19 %, case 4 −5.1 %),
    k̄s 8/8, J 7/8 (case 3 +113 %), τ3 8/8, k_sh 8/8 (not identified on all 8; median |error| 269 %).
    CPU per log 17–155 s (median 24 s), ≤ 60 s on 6 of 8. docs/axis.md, "Ninth session".
    Re-run on the final code (tenth session, after the _start fix, the clock and the k̄s = k̄c kernel
    fix; not held out any more): **46 of 50 (92 %)**, the strict xfail removed — the same four misses,
    case 8 5 of 5 (101.7 CPU s); CPU per log 11–102 s (median 20 s), ≤ 60 s on 9 of 10.
    docs/axis.md, "Tenth session"."""
    assert _ninth_coverage("two-mass") >= 0.90


def _no_breakaway_log():
    """NINTH_SEED's two-mass case 1: effective k̄s 3.010 ozf·in, above the default plan's ramp peak
    0.15·20 = 3.0, so no ramp breaks the shaft away; a full-torque pulse does."""
    from tests.identify_draws import draw

    rng = np.random.default_rng([NINTH_SEED, list(FAMILY_FREE).index("two-mass")])
    for _ in range(2):
        p = draw("two-mass", rng)
    log, truth = simulate_log(design_experiment(), "two-mass", p, NINTH_SEED * 1000 + 1)
    assert truth["stiction"] > 0.15 * log.u_max       # the case these tests are about
    return log


def test_start_lies_below_u_max_when_no_ramp_breaks_the_shaft_away():
    """fit._start on that log: k̄s between the largest level that moved nothing (3.0) and u_max, and
    a start whose residuals are not all the invalid-parameter penalty (they were: k̄s = u_max)."""
    from plant.identification.fit import _Model, _sigma1, _start
    from plant.protocol import get_family

    log = _no_breakaway_log()
    base = get_family("multimode").Params().replace(u_max=log.u_max, sample_period=log.sample_period)
    model = _Model(log, "multimode", base)
    sigma1 = max(_sigma1(log, model.segs)[0], 1e-12)
    z = _start(model, sigma1)
    ks = math.exp(z[0]) + math.exp(z[1])
    assert 0.15 * log.u_max < ks < 0.5 * log.u_max, ks
    r = model.residual(z, np.full(model.rows.size, sigma1))
    assert np.all(np.isfinite(r)) and np.ptp(r) > 0


@pytest.mark.slow
def test_identify_start_below_u_max():
    """A log whose ramps never break the shaft away (NINTH_SEED's two-mass case 1: effective k̄s 3.010 ozf·in
    against the default plan's ramp peak 0.15·20 = 3.0) still gets a fit whose k̄s lies below u_max.
    Found in the ninth session: fit._start took k̄s from the first move that moved the shaft, a
    full-torque pulse, k̄s = u_max, an invalid start whose residuals are all the constant penalty, so
    the fit never moved and fit_log raised 'u_max must be > stiction' (every family alike). Now the
    start is just above the largest level that moved nothing. The fit need not be accurate: the plan
    is outside its design (docs/axis.md: set the peak to 1.2–1.5× the stiction you expect)."""
    log = _no_breakaway_log()
    fit = fit_log(log, "multimode", bootstrap=0)
    assert math.isfinite(fit.estimates["stiction"]) and fit.estimates["stiction"] < log.u_max


TENTH_SEED = 3181     # issue 25's tenth session (helper twomass10): named and committed before any run, to measure
                      # two-mass coverage on held-out logs on the code with fit._start's no-breakaway fix and the
                      # work clock's root-step price (both made after NINTH_SEED's study began); never used before
TENTH_CASES = 10


def _tenth_coverage(cases=range(TENTH_CASES)) -> float:
    """Share of the two-mass fields inside their stated 95 % intervals over ``cases`` at
    :data:`TENTH_SEED` (:func:`coverage_case`, 10-replicate bootstrap, as :func:`_fresh_coverage`).
    A log whose fit raises states no interval: its fields count as outside (the error printed)."""
    inside = []
    for case in cases:
        try:
            res, cpu = coverage_case("two-mass", case, seed=TENTH_SEED, bootstrap=10)
        except (ValueError, RuntimeError) as exc:
            print("two-mass", case, "the fit raised:", exc)
            inside += [False] * (4 + len(FAMILY_FREE["two-mass"]))
            continue
        print("two-mass", case, f"cpu {cpu:.1f}", {k: (round(e / v - 1, 3), lo <= v <= hi) for k, (v, e, (lo, hi), _) in res.items()})
        inside += [lo <= v <= hi for v, _, (lo, hi), _ in res.values()]
    return float(np.mean(inside))


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 5 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_tenth_two_mass_coverage_all_fields():
    """Random two-mass axes at the held-out seed 3181 (:data:`TENTH_SEED`, draws from ``default_rng([3181, 3])``,
    log seed 3181·1000 + k; named and committed before any run): every fitted field (k̄c, k̄s, J, τ3, k_sh)
    inside its stated 95 % interval in ≥ 90 % of the 50 cases, on the code with the two-mass kernel's
    k̄s = k̄c fix (tenth session; committed before this seed's logs ran on it). Measured (one log per process,
    `nice 10`, two at once, loaded machine, load 7–12): **47 of 50 (94 %)** — k̄c 10/10, k̄s 9/10 (case 5
    −3.4 %), J 9/10 (case 8 −7.7 %), τ3 10/10, k_sh 9/10 (case 1: −46 %, calibration interval 1.3e3–6.5e3
    against 2.06e4; not identified, the bounded range, on the other 9). CPU per log 12–80 s (median 18.6 s),
    ≤ 60 s on 9 of 10. Case 0 had run past 335 CPU s unfinished on the code before the fix (stopped).
    docs/axis.md, "Tenth session"."""
    assert _tenth_coverage() >= 0.90


# the auto study of issue 25's tenth session: named and committed before any run of it, never used
# while choosing the rule (dev seed 8484, tests/identify_dev.py); the "pairwise" rule was fixed before it ran
TENTH_AUTO_SEED = 2953


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 8 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured (2026-11-28, tenth session) on the 8 logs of the fresh seed 2953 "
                   "with the pairwise rule: 5 of 8 — stribeck k=1 picked multimode (multimode z -0.04 against "
                   "stribeck), two-mass k=0 and k=1 picked multimode (shafts fitted 3-4x too stiff); the default "
                   "(mean) rule also 5 of 8 on the same fold fits; below the must-show of >= 90 % (docs/axis.md)")
def test_tenth_auto_pairwise_picks_the_generating_family():
    """``--family auto --rule pairwise`` (:func:`plant.identification.fit._rule_pairwise`: the
    simplest family that no other family predicts separably better, every pair tested by the
    signed-rank test at the threshold 2; chosen on dev seed 8484 before this seed ran) on 2 fresh
    logs per family (seed 2953, cases 0–1, :func:`auto_case`'s draws and log seeds, default plan):
    the generating family picked in ≥ 90 % of the 8 logs (docs/axis.md, "Tenth session: auto").
    Measured with tests/identify_dev.py (the same fold fits): 5 of 8 with the pairwise rule and 5
    of 8 with the default rule; CPU of the choice 26–118 s per log (median 43 s; one process per
    log, two at a time, load 8–10)."""
    from plant.identification import ExperimentOptions
    from plant.identification.fit import _rule, choose_family
    from tests.identify_draws import draw

    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            f = list(FAMILY_FREE).index(family)
            rng = np.random.default_rng([TENTH_AUTO_SEED, f])
            for _ in range(case + 1):
                p = draw(family, rng)
            log, _ = simulate_log(design_experiment(ExperimentOptions()), family, p,
                                  TENTH_AUTO_SEED * 1000 + 100 * f + case)
            t0 = time.process_time()
            _, choice = choose_family(log, bootstrap=0, final_fit=False, rule="pairwise")
            picked[family, case] = choice.family
            default = _rule(list(choice.score), choice.score, {f: w for f, (w, _) in choice.ranks.items()},
                            {f: sd for f, (_, sd) in choice.ranks.items()}, 2.0)
            print(family, case, choice.family, "(mean rule:", default + ")", f"cpu {time.process_time() - t0:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked


# issue 25's tenth session, second fresh seed: named and committed before any run of it, never used while
# choosing; choose_family(restart=True) (a stuck first multimode fold fit re-started from the refit's core)
# was chosen on dev seed 8484 (8 of 10 against 7 of 10) before it ran
TENTH_RESTART_SEED = 3671


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 8 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured (2026-11-28, tenth session) on the 8 logs of the fresh seed 3671 "
                   "with restart=True: 5 of 8 — multimode k=0 picked two-mass (multimode z 3.09), stribeck k=0 and "
                   "two-mass k=0 picked multimode; the restart fired on no fold, so the default is 5 of 8 too; below "
                   "the must-show of >= 90 % (docs/axis.md)")
def test_tenth_auto_restart_picks_the_generating_family():
    """``choose_family(…, restart=True)`` (the default rule; a fold whose first multimode fit costs
    more than :data:`plant.identification.fit._RESTART_FACTOR` times multimode's refit in its own
    noise frame is fitted again from the refit's core) on 2 fresh logs per family (seed 3671, cases
    0–1, :func:`auto_case`'s draws and log seeds, default plan): the generating family picked in
    ≥ 90 % of the 8 logs (docs/axis.md, "Tenth session: auto"). Measured (this function's call, in
    one process per log, two at a time, load 2.4–5.3): 5 of 8; the restart fired on none of the 16
    folds; CPU 28–139 s per log (median 50 s)."""
    from plant.identification import ExperimentOptions
    from plant.identification.fit import choose_family
    from tests.identify_draws import draw

    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            f = list(FAMILY_FREE).index(family)
            rng = np.random.default_rng([TENTH_RESTART_SEED, f])
            for _ in range(case + 1):
                p = draw(family, rng)
            log, _ = simulate_log(design_experiment(ExperimentOptions()), family, p,
                                  TENTH_RESTART_SEED * 1000 + 100 * f + case)
            t0 = time.process_time()
            _, choice = choose_family(log, bootstrap=0, final_fit=False, restart=True)
            picked[family, case] = choice.family
            print(family, case, choice.family, f"cpu {time.process_time() - t0:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked


# issue 25's eleventh session: named and committed before any run of it, never used while choosing;
# the plan with torque doublets (ExperimentOptions(doublets=6), `experiment --doublets 6`) was chosen on
# dev seed 8484 (docs/axis.md "Eleventh session: auto — the shaft") before it ran
ELEVENTH_AUTO_SEED = 6827
ELEVENTH_DOUBLETS = 6


def _assert_doublet_auto_picks(seed: int):
    """``--family auto`` on 2 logs per family at ``seed`` (:func:`auto_case`) on the plan with
    doublets=6: the generating family picked in ≥ 90 % of the 8."""
    from plant.identification import ExperimentOptions

    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            choice, cpu = auto_case(family, case, seed=seed, options=ExperimentOptions(doublets=ELEVENTH_DOUBLETS))
            picked[family, case] = choice.family
            print(family, case, choice.family, f"cpu {cpu:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked


def _assert_doublet_coverage(family: str, seed: int):
    """Every fitted field of 5 random ``family`` axes at ``seed`` (:func:`coverage_case`, bootstrap 20)
    on the plan with doublets=6 inside its stated 95 % interval in ≥ 90 % of the fields."""
    from plant.identification import ExperimentOptions

    inside = []
    for case in range(5):
        res, cpu = coverage_case(family, case, seed=seed, bootstrap=20,
                                 options=ExperimentOptions(doublets=ELEVENTH_DOUBLETS))
        print(family, case, f"cpu {cpu:.1f}", {k: (round(e / v - 1, 3), lo <= v <= hi) for k, (v, e, (lo, hi), _) in res.items()})
        inside += [lo <= v <= hi for v, _, (lo, hi), _ in res.values()]
    assert np.mean(inside) >= 0.90


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 8 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_eleventh_auto_with_doublets_picks_the_generating_family():
    """``--family auto`` (the default rule and fits) on logs of the plan with torque doublets
    (``ExperimentOptions(doublets=6)``: 2 and 2.5-ms doublets +u/−u, 6 per width and direction, 24
    moves, +9.8 s of hardware time; chosen on dev seed 8484) on 2 fresh logs per family (seed 6827,
    cases 0–1, :func:`auto_case`'s draws and log seeds): the generating family picked in ≥ 90 % of
    the 8 logs (docs/axis.md, "Eleventh session: auto — the shaft"). Measured (2026-11-28, the same
    draws, plan and choice without the final point fit, one process per log, two at a time, load
    5–7): **8 of 8**, every family picked right by both rules; CPU of the choice 21–81 s per log."""
    _assert_doublet_auto_picks(ELEVENTH_AUTO_SEED)


ELEVENTH_SEED = 5381   # issue 25's eleventh session (helper fit11): named and committed before any run, to measure
                       # lugre's fit time and coverage with the fit's stiff-sliding step (plant.lugre.move_loop,
                       # fit._LUGRE_STIFF) on logs never used while writing it (dev seed 4646, cases 2 and 12)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 15 min of CPU: SOLNIC_AXIS_STUDY=1")
def test_eleventh_lugre_coverage_all_fields():
    """Random lugre axes at the fresh seed 5381 (:data:`ELEVENTH_SEED`, draws from ``default_rng([5381, 2])``,
    log seed 5381·1000 + k, cases 0–9; named and committed before any run): every fitted field inside its
    stated 95 % interval in ≥ 90 % of the 60 cases with the default 20-replicate bootstrap
    (:func:`coverage_case`). Measured (one log per process, `nice 10`, load 5–8, after the stiff-sliding step):
    **59 of 60 (98.3 %)** — k̄c 10/10, k̄s 10/10, J 9/10 (case 5 −29.6 %), τ3 10/10, v_s 10/10 (not identified
    on 10), σ0 10/10 (not identified on 9); the work budget hit on none; CPU per log 49.6–88.3 s (median
    56.2 s). docs/axis.md, "Eleventh session"."""
    inside = []
    for case in range(10):
        res, cpu = coverage_case("lugre", case, seed=ELEVENTH_SEED, bootstrap=20)
        print("lugre", case, f"cpu {cpu:.1f}", {k: (round(e / v - 1, 3), lo <= v <= hi) for k, (v, e, (lo, hi), _) in res.items()})
        inside += [lo <= v <= hi for v, _, (lo, hi), _ in res.values()]
    assert np.mean(inside) >= 0.90


# issue 25's eleventh session (the lead, after helper auto8's seed 6827): two more fresh seeds for the
# plan with torque doublets, named and committed before any of their logs ran, never used while choosing
DOUBLET_AUTO_SEED = 4409      # `auto` on the doublet plan, a second fresh seed after 6827
DOUBLET_COVERAGE_SEED = 6203  # coverage of every family's fit on the doublet plan


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 6 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured 6 of 8 (both stribeck logs picked as multimode; the pairwise "
                   "rule 7 of 8): docs/axis.md, 'Eleventh session: the doublet plan on held-out logs'")
def test_eleventh_auto_with_doublets_second_fresh_seed():
    """As :func:`test_eleventh_auto_with_doublets_picks_the_generating_family` on the fresh seed 4409:
    the generating family picked in ≥ 90 % of 2 logs per family on the doublet plan (docs/axis.md,
    "Eleventh session: the doublet plan on held-out logs"). Measured (2026-11-28, `choose_family` without
    the final point fit, one process per log, load ≈ 2): **6 of 8** — two-mass 2/2 (multimode's z 4.86,
    5.43), lugre 2/2, multimode 2/2, stribeck 0/2 (→ multimode: z 1.39; −0.41 against lugre's best by the
    mean, where the pairwise rule picks stribeck); CPU of the choice 18–44 s per log."""
    _assert_doublet_auto_picks(DOUBLET_AUTO_SEED)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 20 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.parametrize("family", ["two-mass", pytest.param("multimode", marks=pytest.mark.xfail(
    strict=True, reason="measured 17 of 20: case 2 misses k̄c, J, τ3 (k̄c by 5e-4 below its interval)")),
    "stribeck", "lugre"])
def test_eleventh_coverage_on_the_doublet_plan(family):
    """Every fitted field inside its stated 95 % interval in ≥ 90 % of 5 random axes per family (fresh
    seed 6203, cases 0–4, default 20-replicate bootstrap) on the plan with doublets=6 (docs/axis.md,
    "Eleventh session: the doublet plan on held-out logs"). Measured (2026-11-28, one process per log,
    two at a time, load ≈ 2): two-mass 25 of 25 (k_sh not identified on 5 of 5), multimode **17 of 20**,
    stribeck 29 of 30, lugre 30 of 30; CPU per log 30–102 s two-mass, 3–5 s multimode, 31–60 s
    stribeck, 50–73 s lugre."""
    _assert_doublet_coverage(family, DOUBLET_COVERAGE_SEED)


# issue 25's eleventh session (helper plan11, b9961ba): two more fresh seeds for the doublet plan, named and
# committed before any run of them (run on 3ddf87d, before the lugre fit's stiff-sliding step was merged)
PLAN11_AUTO_SEED = 7193
PLAN11_COVERAGE_SEED = 5419


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 8 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured 5 of 8 (both stribeck logs and two-mass k=1 picked as "
                   "multimode): docs/axis.md, 'Eleventh session: the doublet plan on held-out logs'")
def test_eleventh_auto_with_doublets_third_fresh_seed():
    """As :func:`test_eleventh_auto_with_doublets_picks_the_generating_family` on the fresh seed 7193.
    Measured (helper plan11, on 3ddf87d, one process per log, two at a time): **5 of 8** — lugre 2/2,
    multimode 2/2, two-mass 1/2 (k=1: multimode's z 1.98), stribeck 0/2 (multimode's z 0.06, 0.91);
    the pairwise rule also 5 of 8; CPU of the choice 29–87 s per log."""
    _assert_doublet_auto_picks(PLAN11_AUTO_SEED)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="several min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.parametrize("family", ["two-mass", "multimode", "stribeck", "lugre"])
def test_eleventh_doublet_plan_coverage_second_seed(family):
    """As :func:`test_eleventh_coverage_on_the_doublet_plan` at the fresh seed 5419. Measured (helper
    plan11, on 3ddf87d; the cases that ran before its deadline): two-mass 25 of 25 (cases 0–4),
    multimode 15 of 16 (cases 0–3), stribeck 11 of 12 (cases 0–1), lugre 12 of 12 (cases 0–1)."""
    _assert_doublet_coverage(family, PLAN11_COVERAGE_SEED)


# issue 25's twelfth session (helper strib12): the plan with slow reversals (ExperimentOptions(reversals=3),
# `experiment --reversals 3`, with doublets=6) was chosen on dev seed 8484's stribeck axes (docs/axis.md,
# "Twelfth session"); this fresh seed was named and committed before any of its logs ran
TWELFTH_AUTO_SEED = 3517
TWELFTH_REVERSALS = 3


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 7 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.xfail(strict=True, reason="measured 7 of 8 (stribeck k=0 picked as multimode, stribeck's z 5.81 "
                   "against it): docs/axis.md, 'Twelfth session: auto — the Stribeck law'")
def test_twelfth_auto_with_doublets_and_reversals():
    """``--family auto`` (the default rule and fits) on 2 fresh logs per family (seed 3517, cases 0–1,
    :func:`auto_case`'s draws and log seeds) of the plan with torque doublets and slow reversals
    (``ExperimentOptions(doublets=6, reversals=3)``: +19.8 s over the doublet plan): the generating family
    picked in ≥ 90 % of the 8 logs. Measured (2026-11-28, `choose_family` without the final point fit, one
    process per log, two at a time, load 2–5): **7 of 8** — lugre 2/2, multimode 2/2, two-mass 2/2,
    stribeck 1/2 (k=0 → multimode); the pairwise rule also 7 of 8; CPU of the choice 37–82 s per log. The same
    logs on the doublet plan alone (run after, for comparison): 6 of 8 (stribeck k=0 → lugre, k=1 → multimode)."""
    from plant.identification import ExperimentOptions

    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            choice, cpu = auto_case(family, case, seed=TWELFTH_AUTO_SEED,
                                    options=ExperimentOptions(doublets=ELEVENTH_DOUBLETS, reversals=TWELFTH_REVERSALS))
            picked[family, case] = choice.family
            print(family, case, choice.family, f"cpu {cpu:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked


# issue 25's thirteenth session (helper vsprof13): choose_family(stribeck_profile=True, restart=True) on
# the doublet plan, checked on dev seed 8484 only (docs/axis.md "Thirteenth session"); this fresh seed
# was named and committed before any of its logs ran
THIRTEENTH_AUTO_SEED = 4637
# the session's second fresh seed, named and committed (after 4637's logs ran) before any of its logs ran
THIRTEENTH_SECOND_SEED = 8219
# the profile's points then joined the unshifted core's group of starts (chosen on dev seed 8484's reversal-plan
# logs); the session's third fresh seed, named and committed with that change before any of its logs ran
THIRTEENTH_THIRD_SEED = 6143


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="about 8 min of CPU: SOLNIC_AXIS_STUDY=1")
@pytest.mark.parametrize("seed", [
    pytest.param(THIRTEENTH_AUTO_SEED, marks=pytest.mark.xfail(strict=True, reason=(
        "measured 6 of 8 on 4637 (both stribeck logs picked as multimode, its z 1.57 and 1.53 against stribeck), "
        "with either design of the profile: docs/axis.md, 'Thirteenth session: auto — a profile in the Stribeck "
        "fold fit'"))),
    pytest.param(THIRTEENTH_SECOND_SEED, marks=pytest.mark.xfail(strict=True, reason=(
        "measured 5 of 8 on 8219 (both stribeck logs → multimode, lugre k=0 → two-mass), with either design of "
        "the profile: docs/axis.md, 'Thirteenth session'"))),
    THIRTEENTH_THIRD_SEED])
def test_thirteenth_auto_with_the_stribeck_profile_and_restart(seed):
    """``--family auto`` with the stribeck fold fit's profile over v_s and the restart
    (``choose_family(stribeck_profile=True, restart=True)``) on 2 fresh logs per family (seed 4637, 8219 or 6143,
    cases 0–1, :func:`auto_case`'s draws and log seeds) of the doublet plan (``ExperimentOptions(doublets=6)``):
    the generating family picked in ≥ 90 % of the 8 logs. Measured (2026-11-28, ``choose_family`` without the
    final point fit, one process per log, two at a time, load ≤ 2 beside them): **seed 4637: 6 of 8** —
    multimode 2/2, lugre 2/2, two-mass 2/2, stribeck 0/2 (→ multimode: its z 1.57, 1.53 against stribeck);
    the same logs without the options also 6 of 8 (the same picks); CPU of the choice 25–62 s per log
    (without: 20–54). **Seed 8219: 5 of 8** — multimode 2/2, two-mass 2/2, lugre 1/2 (k=0 → two-mass),
    stribeck 0/2 (→ multimode: z 0.62, 0.99); without the options 6 of 8 (stribeck k=1 picked: the
    profile's group led one of its folds to the multimode corner); CPU 25–47 s (without: 20–40). These two
    seeds ran with the first design (the profile a group of starts of its own) and again with the second
    (its points in the unshifted core's group, the code now): the same picks. **Seed 6143** (second design,
    named with it): **8 of 8**; without the options 7 of 8 (stribeck k=1 → multimode, a fold at the stuck
    core, which the restart re-fitted); CPU 30–102 s per log (without: 27–75)."""
    from plant.identification import ExperimentOptions

    picked = {}
    for family in FAMILY_FREE:
        for case in (0, 1):
            choice, cpu = auto_case(family, case, seed=seed, options=ExperimentOptions(doublets=ELEVENTH_DOUBLETS),
                                    stribeck_profile=True, restart=True)
            picked[family, case] = choice.family
            print(family, case, choice.family, f"cpu {cpu:.1f}")
    assert np.mean([f == p for (f, _), p in picked.items()]) >= 0.9, picked
