"""The axis loop (issue 25): the identification plan, the log format and its errors, and the fit.

Truth is independent of the fitting code: logs are simulated from chosen parameters (the
family's exact simulator, with Table 2-1 noise), and the fit must recover them — exactly for a
noise-free log, within its stated 95 % intervals in ≥ 90 % of held-out cases with noise.
"""

from __future__ import annotations

import math
import os
import re
import time
import tomllib

import numpy as np
import pytest

from plant.identification import (ExperimentOptions, LogError, design_experiment, fit_log, read_log,
                                  simulate_log, write_log)
from plant.protocol import get_family
from reports.cli import app
from tests.cli_helpers import cli
from typer.testing import CliRunner


class _Out:
    def __init__(self, r):
        self.returncode, self.stdout, self.stderr = r.exit_code, r.stdout, r.stderr


def _inproc(*args):
    """The CLI in this process (no second load of the compiled plant); ``cli`` runs a real process."""
    return _Out(CliRunner().invoke(app, [str(a) for a in args]))

CORE = ("coulomb", "stiction", "inertia", "motor_time_constant")
FAMILIES = ("multimode", "stribeck", "lugre", "two-mass")


@pytest.fixture(scope="module")
def plan():
    return design_experiment()


def _truth(p, truth):
    return {"coulomb": truth["coulomb"], "stiction": truth["stiction"], "inertia": p.inertia,
            "motor_time_constant": p.motor_time_constant}


# ---------------------------------------------------------------- the plan

def test_plan_respects_limits_and_has_every_part(plan):
    levels = np.array([v for c in plan.commands for _, v in c.segments])
    assert np.abs(levels).max() <= 20.0
    ramp = [c.segments[0][1] for c in plan.commands if len(c.segments) == 1]
    # ramps both ways up to 0.15·max_torque = 3 ozf·in in steps of 3/15
    assert max(ramp) == pytest.approx(3.0) and min(ramp) == pytest.approx(-3.0)
    widths = {(round(c.segments[1][0], 6), math.copysign(1, c.segments[0][1]), abs(c.segments[0][1]))
              for c in plan.commands if len(c.segments) == 2}
    assert len(widths) == 2 * 7          # 4 widths at 20 and 3 at 10 ozf·in, both directions
    assert plan.commands[0].segments == ((0.0, 0.0),) and all(c.segments == ((0.0, 0.0),) for c in plan.commands[:200])
    assert "breaks away" in plan.description and "pulse law" in plan.description


def test_plan_csv_round_trip_and_cli(tmp_path, plan):
    out = _inproc("experiment", "--out", tmp_path / "plan.csv", "--drive", "bridge")
    assert out.returncode == 0, out.stderr
    back = read_log(tmp_path / "plan.csv", want_y=False)
    assert back.drive == "bridge" and back.y is None
    assert back.commands == design_experiment(ExperimentOptions(drive="bridge")).commands
    write_log(plan, tmp_path / "p.parquet")
    assert read_log(tmp_path / "p.parquet", want_y=False).commands == plan.commands
    bad = _inproc("experiment", "--out", tmp_path / "x.csv", "--ramp-fraction", "2")
    assert bad.returncode == 2 and "ramp-fraction" in bad.stderr and "Traceback" not in bad.stderr


# ---------------------------------------------------------------- bad logs

_GOOD = "# drive = linear\n# sample_period = 0.01\nt [s],u [ozf*in],y [rad]\n0.0,0,1e-6\n0.01,1.5,2e-6\n0.02,0,3e-6\n"


@pytest.mark.parametrize("text, needle", [
    (_GOOD.replace("0.01,1.5,2e-6", "0.01,1.5,nan"), "log.csv:5: column 'y'"),
    (_GOOD.replace("0.02,0,3e-6", "0.005,0,3e-6"), "log.csv:6: column 't'"),
    (_GOOD.replace("0.02,0,3e-6", "0.03,0,3e-6"), "log.csv:6: column 't': missing sample"),
    (_GOOD.replace("y [rad]", "y [urad]"), "log.csv:3: column 'y': unit 'urad'"),
    (_GOOD.replace("y [rad]", "y [rad],w [s]").replace("e-6\n", "e-6,0\n"), "log.csv:3: column 'w [s]': unknown column"),
    (_GOOD.replace("# drive = linear\n", ""), "header 'drive' missing"),
    (_GOOD.replace("0.01,1.5,", "0.01,abc,"), "log.csv:5: column 'u'"),
])
def test_bad_log_is_one_line_exit_2(tmp_path, text, needle):
    (tmp_path / "log.csv").write_text(text)
    with pytest.raises(LogError, match=re.escape(needle.split(": ", 1)[-1])):
        read_log(tmp_path / "log.csv")
    run = cli if "unit" in needle else _inproc   # one real process, the rest in this one
    out = run("identify", tmp_path / "log.csv", "--out", tmp_path / "a.toml")
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and needle in out.stderr.replace("\n", ""), out.stderr
    assert not (tmp_path / "a.toml").exists()


# ---------------------------------------------------------------- the fit

def test_noise_free_log_is_recovered_exactly(plan):
    """Noise-free truth: the least-squares fit must return the parameters that made the log."""
    p = get_family("multimode").Params().replace(coulomb=1.1, stiction=1.75, inertia=0.62, motor_time_constant=0.0095)
    log, truth = simulate_log(design_experiment(ExperimentOptions(repeats=1)), "multimode", p, None)
    fit = fit_log(log, "multimode", bootstrap=0)
    for k, v in _truth(p, truth).items():
        assert fit.estimates[k] == pytest.approx(v, rel=1e-5), k


def test_noise_free_stribeck_log_is_recovered_exactly():
    """The stribeck fit (six parameters: the core, v_s and b) on a noise-free log of a strong curve
    returns the parameters that made it (the fitter is right; with noise, v_s and b are weakly
    identified by this plan — docs/axis.md)."""
    truth = dict(coulomb=1.1, stiction=1.75, inertia=0.62, motor_time_constant=0.0095, stribeck_velocity=0.012,
                 viscous=1.0)
    p = get_family("stribeck").Params().replace(**truth)
    log, _ = simulate_log(design_experiment(ExperimentOptions(repeats=1)), "stribeck", p, None)
    fit = fit_log(log, "stribeck", bootstrap=0)
    for k, v in truth.items():
        assert fit.estimates[k] == pytest.approx(v, rel=1e-4), k


def test_sigma1_and_one_noisy_fit():
    """σ1 from the rests within its interval; the core parameters within 25 % of the truth. On the
    plan without holds, where this seed was checked (on the plan with holds σ̂1 of this seed lies
    2.5 sd low, a 1-in-80 draw; tests/test_identify_plan.py checks σ1's coverage over 20 seeds)."""
    p = get_family("multimode").Params()
    log, truth = simulate_log(design_experiment(ExperimentOptions(holds=0)), "multimode", p, 4242)
    fit = fit_log(log, "multimode", bootstrap=0)
    lo, hi = fit.interval["measurement_noise_std"]
    assert lo <= p.measurement_noise_std <= hi
    for k, v in _truth(p, truth).items():
        assert abs(fit.estimates[k] / v - 1) < 0.25, (k, fit.estimates[k], v)


def _random_params(rng):
    fam = get_family("multimode")
    kc = rng.uniform(0.9, 1.6)
    return fam.Params().replace(coulomb=kc, stiction=kc * rng.uniform(1.2, 1.6), inertia=rng.uniform(0.3, 0.9),
                                motor_time_constant=rng.uniform(0.006, 0.011))


@pytest.mark.slow
def test_multimode_coverage_on_held_out_truth(plan):
    """10 random parameter sets (seed 9001, not used while writing the fit): every core parameter
    inside its stated 95 % interval in ≥ 90 % of the 40 cases; relative errors printed."""
    rng = np.random.default_rng(9001)
    inside, errors, seconds = [], [], []
    for case in range(10):
        p = _random_params(rng)
        log, truth = simulate_log(plan, "multimode", p, 9001_000 + case)
        t0 = time.perf_counter()
        fit = fit_log(log, "multimode", bootstrap=20, seed=case)
        seconds.append(time.perf_counter() - t0)
        for k, v in _truth(p, truth).items():
            lo, hi = fit.interval[k]
            inside.append(lo <= v <= hi)
            errors.append((k, fit.estimates[k] / v - 1))
    by = {k: np.array([e for n, e in errors if n == k]) for k in CORE}
    print("coverage", np.mean(inside), "median |rel err|", {k: float(np.median(np.abs(v))) for k, v in by.items()},
          "fit s", np.round(seconds, 1))
    assert np.mean(inside) >= 0.90


# ---------------------------------------------------------------- the loop through the CLI

def test_axis_loop_cli(tmp_path):
    """experiment → a log simulated from hidden parameters → identify → a matrix `list` accepts."""
    assert _inproc("experiment", "--out", tmp_path / "plan.csv", "--repeats", "2").returncode == 0
    plan = read_log(tmp_path / "plan.csv", want_y=False)
    hidden = get_family("multimode").Params().replace(coulomb=1.25, stiction=1.9, inertia=0.4)
    log, truth = simulate_log(plan, "multimode", hidden, 77)
    write_log(log, tmp_path / "log.csv")
    out = _inproc("identify", tmp_path / "log.csv", "--out", tmp_path / "axis.toml", "--bootstrap", "0")
    assert out.returncode == 0, out.stderr
    doc = tomllib.loads((tmp_path / "axis.toml").read_text())
    sc = doc["scenarios"]["axis"]
    assert sc["plant"] == "multimode" and abs(sc["stiction"] / truth["stiction"] - 1) < 0.3
    assert "plotly" in (tmp_path / "axis.html").read_text()[:2_000_000].lower()
    listed = _inproc("list", "--matrix", tmp_path / "axis.toml")
    assert listed.returncode == 0 and "axis" in listed.stdout, listed.stderr


@pytest.mark.slow
def test_axis_loop_runs_the_fitted_matrix_as_is(tmp_path):
    """The whole loop in real processes: experiment → log from hidden parameters → identify →
    `run --matrix axis.toml` on the file exactly as written; every cell ends ok."""
    import pandas as pd

    assert cli("experiment", "--out", tmp_path / "plan.csv").returncode == 0
    plan = read_log(tmp_path / "plan.csv", want_y=False)
    hidden = get_family("multimode").Params().replace(coulomb=1.3, stiction=1.85, inertia=0.55,
                                                      motor_time_constant=0.009)
    log, _ = simulate_log(plan, "multimode", hidden, 5150)
    write_log(log, tmp_path / "log.csv")
    assert cli("identify", tmp_path / "log.csv", "--out", tmp_path / "axis.toml", "--bootstrap", "0").returncode == 0
    out = cli("run", "--matrix", tmp_path / "axis.toml", "--out", tmp_path / "run", "--traces", "none", timeout=900)
    assert out.returncode == 0, out.stderr
    rows = pd.read_parquet(tmp_path / "run" / "results.parquet")
    written = tomllib.loads((tmp_path / "axis.toml").read_text())["matrix"]
    assert len(written["controllers"]) >= 7 and written["seeds"] == [0, 1]      # the quick matrix's controllers
    assert set(rows["scenario"]) == {"axis"} and (rows["status"] == "ok").all()
    assert len(rows) == len(written["controllers"]) * len(written["seeds"])


# ---------------------------------------------------------------- frontier --matrix on identify's file

def _identified_axis(tmp_path):
    """axis.toml as `identify` writes it, from a short log of a hidden multimode axis."""
    plan = design_experiment(ExperimentOptions(repeats=1))
    hidden = get_family("multimode").Params().replace(coulomb=1.2, stiction=1.7, inertia=0.45)
    log, _ = simulate_log(plan, "multimode", hidden, 31)
    write_log(log, tmp_path / "log.csv")
    out = _inproc("identify", tmp_path / "log.csv", "--out", tmp_path / "axis.toml", "--bootstrap", "0")
    assert out.returncode == 0, out.stderr
    return tmp_path / "axis.toml"


def test_frontier_takes_the_identified_matrix(tmp_path, monkeypatch):
    """`frontier --matrix axis.toml`: the file as identify wrote it is completed from the registry
    (its scenario, seeds and run length kept); a tiny copy of it (2 s, one seed, two controllers)
    runs through the real command; a bad file is one line naming it, exit 2."""
    import pandas as pd

    import controllers.base as cb
    from bench.frontier import frontier_matrix_data
    from bench.matrix import parse_matrix

    axis = _identified_axis(tmp_path)
    written = tomllib.loads(axis.read_text())
    data = frontier_matrix_data(True, axis)
    assert data["scenarios"] == written["scenarios"] and data["matrix"]["scenarios"] == ["axis"]
    assert data["matrix"]["seeds"] == written["matrix"]["seeds"] and data["matrix"]["duration_s"] == 100
    assert set(written["matrix"]["controllers"]) | set(cb.available_controllers()) == set(data["matrix"]["controllers"])
    assert any(data.get("sweep", {}).values())          # knobs swept, as the built-in frontier
    parse_matrix(data, str(axis), check_resets=False)

    text = axis.read_text()
    for old, new in (("duration_s = 100", "duration_s = 2"), ("warmup_s = 20", "warmup_s = 1"),
                     ("seeds = [0, 1]", "seeds = [0]")):
        assert old in text
        text = text.replace(old, new)
    text = re.sub(r"controllers = \[.*\]", 'controllers = ["linear", "oracle-pulse"]', text)
    (tmp_path / "tiny.toml").write_text(text)
    full = cb.available_controllers()
    monkeypatch.setattr(cb, "available_controllers", lambda: {k: full[k] for k in ("linear", "oracle-pulse")})
    res = _inproc("frontier", "--matrix", tmp_path / "tiny.toml", "--quick", "--out", tmp_path / "fr")
    assert res.returncode == 0, res.stderr
    df = pd.read_parquet(tmp_path / "fr" / "results.parquet")
    assert set(df["scenario"]) == {"axis"} and (df["status"] == "ok").all()
    assert {"linear", "oracle-pulse"} <= {c.split("[")[0] for c in df["controller"]} and df["controller"].nunique() > 2
    assert (tmp_path / "fr" / "report.html").is_file()

    (tmp_path / "bad.toml").write_text(axis.read_text().replace("seeds = [0, 1]", 'seeds = "zero"'))
    for bad, needle in ((tmp_path / "bad.toml", "bad.toml"), (tmp_path / "none.toml", "none.toml")):
        res = _inproc("frontier", "--matrix", bad, "--out", tmp_path / "fr2")
        assert res.returncode == 2 and "Traceback" not in res.stderr
        assert len(res.stderr.strip().splitlines()) == 1 and needle in res.stderr, res.stderr
        assert not (tmp_path / "fr2").exists()


# ---------------------------------------------------------------- --family auto

@pytest.mark.slow      # two whole choices, ~25 CPU s: make test-slow (choose_family end to end stays in make test: tests/test_identify_parallel.py)
def test_auto_prefers_the_simpler_family_unless_the_richer_predicts_held_out_moves_better():
    """The held-out rule on logs with sensor noise only (σ1 = 5 µrad, no friction noise), so the
    generating law is the only structure: a stribeck log with a strong curve (v_s = 20 mrad/s,
    b = 2) is stribeck; a multimode log is multimode (stribeck nests it: not separable → simpler)."""
    from plant.identification.fit import _rule_pairwise, choose_family

    plan = design_experiment(ExperimentOptions(repeats=1))
    quiet = dict(friction_noise_psd=0.0, correlated_friction_std=0.0)
    for family, extra in (("stribeck", dict(stribeck_velocity=0.02, viscous=2.0)), ("multimode", {})):
        p = get_family(family).Params().replace(coulomb=1.2, stiction=1.8, inertia=0.6, **quiet, **extra)
        log, _ = simulate_log(plan, family, p, 2024)
        fit, choice = choose_family(log, ("multimode", "stribeck"), bootstrap=0)
        assert choice.family == fit.family == family, (family, choice)
        assert set(choice.score) == {"multimode", "stribeck"} and choice.excess[choice.best] == 0.0
        # the tenth session's "pairwise" rule on the same held-out scores picks the same family
        assert _rule_pairwise(list(choice.score), choice.score, choice.pairs) == family, (family, choice.pairs)
        other = ({"multimode", "stribeck"} - {family}).pop()
        if family == "stribeck":
            # the richer family wins: multimode is separably worse by the rule's own test (Wilcoxon's
            # signed rank over moves, W > 2 null sd) and worse on the mean score. (Until the fifth
            # session this asserted mean excess > 2 SE — the output-error rule's test; with the new
            # fits multimode's excess here is carried by a few moves it predicts 10³ σ off, and its
            # SE with it, so the mean ± SE no longer measures what the rule decides on.)
            w, sd = choice.ranks[other]
            assert w > 2 * sd > 0 and choice.excess[other] > 0, (choice.ranks, choice.excess, choice.excess_se)


def test_auto_folds_hold_every_kind_of_move_in_both_directions(plan):
    """Each fold of the held-out split holds every ramp, hold level and pulse width of the default
    plan in both directions (alternate pairs, the split before, put a hold level in one fold only)."""
    from plant.identification.fit import _folds, moves

    fold = _folds(plan)
    kinds = {}
    for m, (s, e) in enumerate(moves(plan)):
        segs = plan.commands[s].segments
        level = next(v for _, v in segs if v != 0.0)
        width = segs[1][0] if len(segs) > 1 else None
        kind = (len(segs), abs(level), width, plan.commands[s + 3].segments == segs)
        kinds.setdefault(kind, set()).add((int(fold[m]), level > 0))
    assert len(kinds) >= 10
    for kind, seen in kinds.items():
        assert seen == {(0, True), (0, False), (1, True), (1, False)}, (kind, seen)
    assert abs(int(fold.sum()) - fold.size / 2) <= 1


def test_auto_rule_threshold_against_scipy_wilcoxon():
    """The signed-rank rule's threshold (``choose_family(separable=…)``, :data:`_SEPARABLE_Z`): a
    richer family best by the mean, multimode worse with a signed-rank z that scipy's Wilcoxon test
    (normal approximation, no continuity correction, zeros dropped) puts between 1 and 2 — kept
    (multimode chosen) at a threshold above that z, dropped (the richer family chosen) below it; a
    threshold outside [0, 10] is one clear error before any fit."""
    from scipy import stats

    from plant.identification.fit import RULE, _SEPARABLE_Z, _rule, _rule_text, _signed_rank, choose_family

    rng = np.random.default_rng(7)
    richer = rng.normal(0.0, 1.0, 60)
    multimode = richer + rng.normal(0.25, 1.0, 60)
    multimode[:3] = richer[:3]                                   # moves neither family moves: ties, dropped
    z_scipy = abs(stats.wilcoxon(multimode - richer, zero_method="wilcox", correction=False, method="approx").zstatistic)
    assert 1.0 < z_scipy < 2.0, z_scipy
    w, sd = _signed_rank(multimode, richer)
    assert w / sd == pytest.approx(z_scipy, rel=1e-12)
    fams = ("multimode", "two-mass")
    score = {"multimode": float(np.mean(multimode)), "two-mass": float(np.mean(richer))}
    assert score["two-mass"] < score["multimode"]
    excess, se = {"multimode": w, "two-mass": 0.0}, {"multimode": sd, "two-mass": 0.0}
    assert _rule(fams, score, excess, se, z_scipy + 0.01) == "multimode"
    assert _rule(fams, score, excess, se, z_scipy - 0.01) == "two-mass"
    assert _rule(fams, score, excess, se) == ("multimode" if z_scipy <= 2.0 else "two-mass")    # _SEPARABLE_SE = 2
    assert _rule(fams, score, excess, se, _SEPARABLE_Z) == ("multimode" if z_scipy <= _SEPARABLE_Z else "two-mass")
    assert "exceeds 2 null standard deviations" in RULE and RULE == _rule_text(_SEPARABLE_Z) == _rule_text(2.0)
    assert "exceeds 0.5 null standard deviations" in _rule_text(0.5)     # FamilyChoice.rule states the threshold used
    log = simulate_log(design_experiment(ExperimentOptions(repeats=1, holds=0)), "multimode",
                       get_family("multimode").Params(), 5)[0]
    for bad in (-0.5, 11.0, math.nan, "2"):
        with pytest.raises(ValueError, match="separable"):
            choose_family(log, separable=bad)


def test_auto_pairwise_rule_against_scipy_wilcoxon():
    """The "pairwise" rule (``choose_family(rule="pairwise")``, issue 25's tenth session) on given
    per-move scores shaped like fresh log 7531 lugre k=0: stribeck best by the mean (four moves it
    predicts far better), lugre better than every other family on most moves. scipy's Wilcoxon
    test (normal approximation, no continuity correction, zeros dropped) says which pairs are
    separable; the "mean" rule keeps multimode (not separably worse than stribeck), the pairwise rule
    picks lugre (no family separably better than it; each other family separably worse than it).
    A cycle of separable pairs falls back to the mean rule; an infinite score is never chosen."""
    from scipy import stats

    from plant.identification.fit import _rule, _rule_pairwise, _signed_rank, choose_family

    rng = np.random.default_rng(11)
    n = 90
    lugre = rng.normal(-60.0, 1.0, n)
    stribeck = lugre + np.abs(rng.normal(0.4, 0.3, n))
    stribeck[:4] -= 40.0                                         # four moves stribeck predicts far better
    multimode = stribeck + rng.normal(0.05, 1.0, n)
    multimode[:4] = lugre[:4] + 1.0
    two_mass = lugre + np.abs(rng.normal(0.6, 0.3, n))
    pm = {"multimode": multimode, "two-mass": two_mass, "stribeck": stribeck, "lugre": lugre}
    fams = list(pm)
    score = {f: float(np.mean(v)) for f, v in pm.items()}
    assert min(score, key=score.get) == "stribeck"

    def z_scipy(a, b):
        r = stats.wilcoxon(pm[a] - pm[b], zero_method="wilcox", correction=False, method="approx")
        return math.copysign(abs(r.zstatistic), float(np.sum(np.sign(pm[a] - pm[b]) * stats.rankdata(np.abs(pm[a] - pm[b])))))

    pairs = {(a, b): _signed_rank(pm[a], pm[b]) for a in fams for b in fams if a != b}
    for (a, b), (w, sd) in pairs.items():
        assert w / sd == pytest.approx(z_scipy(a, b), rel=1e-9)
    assert z_scipy("multimode", "stribeck") < 2.0                 # the mean rule keeps multimode
    assert all(z_scipy(f, "lugre") > 2.0 for f in fams if f != "lugre")
    assert all(z_scipy("lugre", f) < -2.0 for f in fams if f != "lugre")
    best = "stribeck"
    assert _rule(fams, score, {f: pairs[f, best][0] if f != best else 0.0 for f in fams},
                 {f: pairs[f, best][1] if f != best else 0.0 for f in fams}, 2.0) == "multimode"
    assert _rule_pairwise(fams, score, pairs, 2.0) == "lugre"
    # a cycle: multimode separably worse than two-mass, two-mass than stribeck, stribeck than multimode —
    # no family is kept, and the mean rule decides: two-mass best by the mean, multimode 3 sd worse
    # (dropped), stribeck 3 sd better (W < 0: kept), two-mass has fewer parameters
    m, t, s_ = "multimode", "two-mass", "stribeck"
    cyc = {(m, t): (30.0, 10.0), (t, m): (-30.0, 10.0), (t, s_): (30.0, 10.0), (s_, t): (-30.0, 10.0),
           (s_, m): (30.0, 10.0), (m, s_): (-30.0, 10.0)}
    sc = {m: 1.0, t: 0.0, s_: 2.0}
    assert _rule_pairwise((m, t, s_), sc, cyc, 2.0) == "two-mass" == \
        _rule((m, t, s_), sc, {m: 30.0, t: 0.0, s_: -30.0}, {m: 10.0, t: 0.0, s_: 10.0}, 2.0)
    assert _rule_pairwise((m, t, s_), sc, cyc, 3.5) == "multimode"       # no pair separable at 3.5: the simplest
    # a failed fold fit (infinite score) is never kept, even when no family is separably better
    inf_score = dict(score, lugre=math.inf)
    assert _rule_pairwise(fams, inf_score, pairs, 2.0) != "lugre"
    log = simulate_log(design_experiment(ExperimentOptions(repeats=1, holds=0)), "multimode",
                       get_family("multimode").Params(), 5)[0]
    for bad in ("ranks", "", None):
        with pytest.raises(ValueError, match="rule"):
            choose_family(log, rule=bad)
    with pytest.raises(ValueError, match="pairwise"):
        choose_family(log, rule="pairwise", criterion="output-error")


def test_shifted_core_survives_a_stiction_gap_below_rounding():
    """A multimode fold fit may end with k̄s − k̄c below k̄c's rounding (dev log 8484 lugre k=0 raised
    a math domain error in choose_family): the shifted start keeps k̄c·factor and k̄s − k̄c·factor > 0."""
    from plant.identification.fit import _shifted

    core = np.array([math.log(1.5), math.log(1.5) - 60.0, math.log(0.5), math.log(0.01)])
    for factor in (1.0, 0.92, 0.78):
        c = _shifted(core, factor)
        assert np.all(np.isfinite(c))
        assert math.exp(c[0]) == pytest.approx(1.5 * factor, rel=1e-12)
        assert math.exp(c[0]) + math.exp(c[1]) == pytest.approx(1.5, rel=1e-12)   # k̄s held
    ordinary = np.array([math.log(1.2), math.log(0.4), math.log(0.5), math.log(0.01)])
    c = _shifted(ordinary, 0.85)
    assert math.exp(c[0]) + math.exp(c[1]) == pytest.approx(1.6, rel=1e-12)


def test_auto_rule_fewest_parameters_then_lower_score():
    """The stated rule on given scores: the fewest fitted parameters among the families within
    2 SE of the best; stribeck and lugre (six each) are told apart by their scores, not by order."""
    from plant.identification.fit import RULE, _rule

    fams = ("multimode", "two-mass", "stribeck", "lugre")
    score = {"multimode": -18.0, "two-mass": -18.1, "stribeck": -18.6, "lugre": -18.75}

    def pick(se_of):
        best = min(score, key=score.get)
        excess = {f: score[f] - score[best] for f in fams}
        return _rule(fams, score, excess, {f: se_of.get(f, 0.1) for f in fams})

    assert pick({}) == "lugre"                                 # stribeck +0.15 ± 0.10: not separable, same count
    assert pick({"two-mass": 0.4}) == "two-mass"               # +0.65 within 2 × 0.4: fewer parameters win
    assert pick({"multimode": 0.4, "two-mass": 0.4}) == "multimode"
    score["stribeck"] = -18.8                                  # stribeck best now: lugre not chosen
    assert pick({}) == "stribeck"
    assert "fewest" in RULE and "lower score" in RULE
    score["two-mass"] = math.inf                               # a failed fold fit: score and SE infinite
    assert pick({"two-mass": math.inf, "multimode": 0.1}) == "stribeck"
    score["multimode"] = -18.7                                 # multimode within 2 SE: it wins, two-mass never
    assert pick({"two-mass": math.inf}) == "multimode"


def test_auto_folds_never_leave_a_fold_empty(plan):
    """A plan whose every move is of its own kind (each level made unique) still splits into two
    folds of equal size (within one move); the default plan's split is unchanged by that rule."""
    import dataclasses

    from plant.drive import DriveCommand
    from plant.identification.fit import _folds, moves

    before = _folds(plan)
    cmds = list(plan.commands)
    for i, (s, e) in enumerate(moves(plan)):
        for j in range(s, e):
            c = cmds[j]
            cmds[j] = DriveCommand(tuple((t, v * (1 + 1e-6 * (i + 1))) for t, v in c.segments), c.drive)
    unique = dataclasses.replace(plan, commands=tuple(cmds))
    fold = _folds(unique)
    assert fold.size == before.size and abs(int(fold.sum()) - fold.size / 2) <= 1
    assert np.array_equal(_folds(plan), before)


@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("SOLNIC_AXIS_STUDY"), reason="the auto study (about 40 min CPU for 40 logs "
                    "on the plan with holds): set SOLNIC_AXIS_STUDY=1 to run it; its last, partial results are in "
                    "docs/axis.md")
@pytest.mark.parametrize("family", ["multimode", "stribeck", "lugre", "two-mass"])
def test_auto_on_held_out_truth(family):
    """10 random axes of ``family`` in the stated region (tests/identify_draws.py; seed 4711, not
    used while writing the rule), default plan, Table 2-1 noise. Asserted: the generating family
    is among the families the rule could not separate from the best (its paired excess within
    2 standard errors) in ≥ 90 % of the logs — the rule never confidently rejects the truth.
    Printed (docs/axis.md): how often auto picks the generating family, and the CPU time per log."""
    from plant.identification.fit import choose_family
    from tests.identify_draws import draw

    plan = design_experiment()
    rng = np.random.default_rng([4711, list(FAMILIES).index(family)])
    kept, picked, cpu = [], [], []
    for case in range(10):
        log, _ = simulate_log(plan, family, draw(family, rng), 4711_000 + 100 * list(FAMILIES).index(family) + case)
        t0 = time.process_time()
        fit, choice = choose_family(log, bootstrap=0)
        cpu.append(time.process_time() - t0)
        kept.append(choice.excess[family] <= 2 * choice.excess_se[family])
        picked.append(choice.family)
    print(family, "picked", picked, "truth not rejected", sum(kept), "/ 10; CPU s per log", np.round(cpu, 1))
    assert np.mean(kept) >= 0.9


def test_bootstrap_refit_reaches_the_parameters_of_a_noise_free_log():
    """The bootstrap's refit (fit._refit: the final least-squares pass started at the point
    estimate) started at one axis's parameters, on the noise-free log of another axis 3–6 % away,
    returns that axis's parameters (the model is exact there, so its least-squares point is the
    truth that made the log)."""
    from plant.identification.fit import _refit, _Model

    plan = design_experiment(ExperimentOptions(repeats=1, holds=1))
    fam = get_family("multimode")
    a = dict(coulomb=1.1, stiction=1.75, inertia=0.62, motor_time_constant=0.0095)
    b = dict(coulomb=1.1 * 1.04, stiction=1.75 * 1.03, inertia=0.62 * 0.95, motor_time_constant=0.0095 * 1.06)
    log_b, _ = simulate_log(plan, "multimode", fam.Params().replace(**b), None)
    base = fam.Params().replace(u_max=max(float(log_b.u_max), fam.Params().u_max), sample_period=log_b.sample_period)
    model = _Model(log_b, "multimode", base)

    def z_of(d):
        return np.log([d["coulomb"], d["stiction"] - d["coulomb"], d["inertia"], d["motor_time_constant"]])
    z = _refit(model, z_of(a), np.full(model.rows.size, 1e-6), (-np.inf, np.inf))
    np.testing.assert_allclose(np.exp(z), np.exp(z_of(b)), rtol=1e-5)


def test_bootstrap_leaves_out_a_replicate_log_that_diverged(monkeypatch):
    """A replicate log whose simulation leaves ``ok`` (a lugre replicate of seed 7207 wandered past
    1 rad) is left out and counted in ``fit.method``; the fit does not crash."""
    import plant.identification.simulate as sim

    plan = design_experiment(ExperimentOptions(repeats=1, holds=1))
    log, _ = simulate_log(plan, "multimode", get_family("multimode").Params(), 4242)
    calls = []

    def flaky(*args, **kwargs):
        calls.append(1)
        if len(calls) % 2 == 0:
            raise RuntimeError("simulated log: sample 1: plant status diverged")
        return simulate_log(*args, **kwargs)
    monkeypatch.setattr(sim, "simulate_log", flaky)
    fit = fit_log(log, "multimode", bootstrap=10)
    assert len(calls) == 10
    assert "5 of 10 simulated replicate logs left ok" in fit.method
    assert "parametric bootstrap (5 logs" in fit.method
    assert all(np.isfinite(fit.interval[k]).all() for k in CORE)


def test_a_parameter_no_refit_moves_gets_no_zero_width_interval(monkeypatch):
    """Replicate refits that leave one parameter exactly at the estimate (a zero derivative along
    it) must not give it a zero-width interval, nor make every replicate that moved it "wild"
    (robust sd 0): its sd falls back to the cluster-robust one, said in ``fit.method``; the other
    parameters keep their bootstrap intervals."""
    import plant.identification.fit as fitmod

    plan = design_experiment(ExperimentOptions(repeats=1, holds=1))
    log, _ = simulate_log(plan, "multimode", get_family("multimode").Params(), 4242)
    refit, calls = fitmod._refit, []

    def frozen(model, z, scale, box):
        calls.append(1)
        zb = refit(model, z, scale, box)
        zb[3] = z[3] if len(calls) % 4 else z[3] + 1e-3    # τ3 left where it was by 3 of 4 refits
        return zb
    monkeypatch.setattr(fitmod, "_refit", frozen)
    fit = fit_log(log, "multimode", bootstrap=8)
    lo, hi = fit.interval["motor_time_constant"]
    assert hi > lo and "parametric bootstrap (8 logs" in fit.method
    assert "(0 replicate(s) beyond 10 sd left out)" in fit.method
    lo, hi = fit.interval["inertia"]
    assert hi - lo > 0
    calls.clear()
    monkeypatch.setattr(fitmod, "_refit", lambda model, z, scale, box: np.append(refit(model, z, scale, box)[:3], z[3:]))
    fit = fit_log(log, "multimode", bootstrap=8)      # no refit moves τ3: the cluster-robust sd for it
    lo, hi = fit.interval["motor_time_constant"]
    assert hi > lo and "motor_time_constant: no replicate refit moved it" in fit.method


def test_calibration_interval_is_the_closed_form_inverse_regression_and_covers():
    """fit._calibration_interval against Eisenhart's closed form: the x with
    (y0 − a − b·x)² ≤ q²s²(1 + 1/n + (x − x̄)²/Sxx), the roots of a quadratic (to the grid's step);
    on a Monte-Carlo of 2000 straight-line data sets (b = 0.8, s = 0.3, n = 10) it holds the true
    x0 in 95 % ± 1.5 % of them (3 binomial sd); with no slope (b = 0, an estimator that does not
    follow the truth) it reaches the span's ends and goes on to the bound."""
    from plant.identification.fit import _calibration_interval

    rng = np.random.default_rng(20261127)
    lo, hi, bound = 0.0, 4.0, (-3.0, 7.0)
    x = lo + (np.arange(10) + 0.5) / 10 * (hi - lo)
    n = x.size
    q = __import__("scipy.stats").stats.t.ppf(0.975, n - 2)
    hits, checked = 0, 0
    for trial in range(2000):
        y = 1.0 + 0.8 * x + 0.3 * rng.standard_normal(n)
        x0 = rng.uniform(0.5, 3.5)
        y0 = 1.0 + 0.8 * x0 + 0.3 * rng.standard_normal()
        a_, b_ = _calibration_interval(x, y, y0, lo, hi, bound)[:2]
        hits += a_ <= x0 <= b_
        if trial < 50:        # closed form: A x² + B x + C ≤ 0
            b, a = np.polyfit(x, y, 1)
            s2 = np.sum((y - a - b * x) ** 2) / (n - 2)
            xm, sxx = x.mean(), np.sum((x - x.mean()) ** 2)
            k = q * q * s2
            A = b * b - k / sxx
            B = -2 * b * (y0 - a) + 2 * k * xm / sxx
            C = (y0 - a) ** 2 - k * (1 + 1 / n) - k * xm * xm / sxx
            if A > 0 and B * B - 4 * A * C > 0:
                r1, r2 = sorted(np.roots([A, B, C]).real)
                if lo < r1 and r2 < hi:
                    checked += 1
                    assert a_ == pytest.approx(r1, abs=(hi - lo) / 800) and b_ == pytest.approx(r2, abs=(hi - lo) / 800)
    assert checked >= 20
    assert abs(hits / 2000 - 0.95) <= 3 * math.sqrt(0.95 * 0.05 / 2000)
    y = 2.0 + 0.3 * rng.standard_normal(n)          # flat: the estimate does not follow the truth
    assert _calibration_interval(x, y, float(np.mean(y)), lo, hi, bound)[:2] == bound


@pytest.mark.slow
def test_two_mass_bootstrap_spreads_the_shaft_truths_and_states_the_calibration(monkeypatch):
    """The two-mass bootstrap simulates replicate i at k_sh = the i-th log-even midpoint of
    2.5e3–2e5 ozf·in/rad (the other fields at the estimate), in golden-ratio order, states the calibration interval for
    k_sh in ``fit.method``, and that interval holds the estimate's own calibration: it is within
    the fit's bound (a factor 30 of 4e4) and nonempty; the core keeps its bootstrap interval."""
    import plant.identification.simulate as sim

    plan = design_experiment(ExperimentOptions(repeats=1, holds=1))
    p = get_family("two-mass").Params().replace(coulomb=1.2, stiction=1.7, inertia=0.55,
                                                motor_time_constant=0.0085, shaft_stiffness=1.5e4)
    log, _ = simulate_log(plan, "two-mass", p, 5150)
    seen = []

    def spy(plan_, family, params, seed):
        seen.append(params.shaft_stiffness)
        return simulate_log(plan_, family, params, seed)
    monkeypatch.setattr(sim, "simulate_log", spy)
    fit = fit_log(log, "two-mass", bootstrap=5)
    expect = np.exp(np.log(2.5e3) + (np.arange(5) + 0.5) / 5 * np.log(2e5 / 2.5e3))
    # run in golden-ratio order: frac(k·0.618…) = 0, .618, .236, .854, .472 for k = 0..4, ranks 0 3 1 4 2
    np.testing.assert_allclose(seen, expect[[0, 3, 1, 4, 2]], rtol=1e-12)
    assert "shaft_stiffness: calibration interval" in fit.method
    lo, hi = fit.interval["shaft_stiffness"]
    assert 4e4 / 30 * (1 - 1e-9) <= lo < hi <= 4e4 * 30 * (1 + 1e-9)
    assert all(fit.interval[k][0] < fit.interval[k][1] for k in CORE)


def test_lugre_bootstrap_spreads_the_stribeck_velocity_truths_and_calibrates(monkeypatch):
    """Lugre's v_s gets the calibration interval (issue 25, eighth session): replicate i is simulated at
    v_s = the i-th log-even midpoint of 0.5–24 mrad/s (golden-ratio order; the draws' region 4–10 mrad/s
    inside), its other fields at the estimate. The point fit and the replicates' fits are stand-ins (a
    known estimator, so the test takes seconds): one whose ln v̂_s follows ln v_s (slope 1, sd 0.05)
    gives an interval that holds the real log's truth and is much narrower than the span; one that
    ignores v_s (an estimate that does not follow the truth) gives the fit's bounded range, marked not
    identified. The core keeps its bias-corrected bootstrap interval; σ0 is not calibrated."""
    import plant.identification.fit as fitmod
    import plant.identification.simulate as sim

    plan = design_experiment(ExperimentOptions(repeats=1, holds=1))
    p = get_family("lugre").Params().replace(coulomb=1.2, stiction=1.6, inertia=0.5, motor_time_constant=0.008,
                                              bristle_stiffness=2e5, stribeck_velocity=6e-3)
    log, _ = simulate_log(plan, "lugre", p, 1729)
    z_hat = np.log([1.2, 0.4, 0.5, 0.008, 6e-3, 2e5])
    seen, rng = [], np.random.default_rng(1729)

    def spy(plan_, family, params, seed):     # the truth is what matters here, not the replicate's noise
        seen.append(params.stribeck_velocity)
        return log, {"coulomb": params.coulomb, "stiction": params.stiction, "x5": 0.0}

    def stand_in(log_, family, base, z0=None, deadline=math.inf, points=None, clock=None, final_nfev=60):
        model = fitmod._Model(log_, family, base)
        n = 4 + 2
        lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
        lo[4:], hi[4:] = np.log([4e-3, 1e6]) - math.log(30.0), np.log([4e-3, 1e6]) + math.log(30.0)
        model.box, model.start_point, model.start_note = (lo, hi), z_hat[4:].copy(), ""
        model.scale = np.full(model.rows.size, 5e-6)
        if points is None:        # the real log's point fit
            return z_hat, model, 5e-6, 100, np.zeros(model.rows.size), np.zeros((model.rows.size, n)), False
        zb = z_hat + 0.02 * rng.standard_normal(n)
        zb[4] = (math.log(seen[-1]) if follows else z_hat[4]) + 0.05 * rng.standard_normal()
        return zb, model, 5e-6, 100, None, None, False

    monkeypatch.setattr(sim, "simulate_log", spy)
    monkeypatch.setattr(fitmod, "_point_fit", stand_in)
    expect = np.exp(np.log(5e-4) + (np.arange(8) + 0.5) / 8 * np.log(2.4e-2 / 5e-4))
    # golden-ratio order: frac(k·0.618…) = 0, .618, .236, .854, .472, .090, .708, .326 for k = 0..7
    order = [0, 5, 2, 7, 4, 1, 6, 3]
    for follows in (True, False):
        seen.clear()
        fit = fit_log(log, "lugre", bootstrap=8)
        np.testing.assert_allclose(seen, expect[order], rtol=1e-12)
        assert "stribeck_velocity: calibration interval" in fit.method
        assert "bristle_stiffness: calibration" not in fit.method
        lo, hi = fit.interval["stribeck_velocity"]
        if follows:
            assert lo <= 6e-3 <= hi and hi / lo < 1.6
            assert "stribeck_velocity" not in fit.not_identified
        else:
            assert (lo, hi) == pytest.approx((4e-3 / 30, 4e-3 * 30), rel=1e-9)
            assert "stribeck_velocity" in fit.not_identified
        for k in CORE:
            assert fit.interval[k][0] < fit.estimates[k] < fit.interval[k][1]


def test_a_calibration_point_the_family_rejects_gets_no_replicate():
    """Held-out seed 6571, lugre case 9: with its fitted k̄c = 0.626, k̄s = 1.255 ozf·in,
    σ0 = 3.83e5 ozf·in/rad (σ1 = 707, σ2 = 0.2 as given), the lowest v_s points of the calibration
    span break LuGre's dissipativity condition
    σ1²·|v| ≤ 4·(σ1 + σ2)·g(v), so building their truth raised out of fit_log. They are left out
    (and named); every other point keeps its replicate index and its log-even v_s."""
    from plant.identification.fit import _CALIBRATED, _replicate_truths
    from plant.lugre.params import LuGreParams

    fitted = LuGreParams(coulomb=0.6256531847821101, stiction=1.254659659212424, inertia=0.34528064361533545,
                         motor_time_constant=0.004174423627541125, stribeck_velocity=1.4897748e-02,
                         bristle_stiffness=3.8277147e+05)
    lo, hi = (math.log(v) for v in _CALIBRATED["lugre"]["stribeck_velocity"])
    truths, invalid = _replicate_truths(fitted, {"stribeck_velocity": (lo, hi)}, 10, range(10))
    points = [math.exp(lo + (i + 0.5) / 10 * (hi - lo)) for i in range(10)]
    rejected = []
    for v in points:            # the truth: which points the family itself refuses
        try:
            fitted.replace(stribeck_velocity=v)
        except ValueError:
            rejected.append(v)
    assert rejected and len(rejected) < 10                      # the case this test is about
    assert [at["stribeck_velocity"] for at in invalid] == rejected
    assert [i for i, _, _ in truths] == [i for i, v in enumerate(points) if v not in rejected]
    assert all(p.stribeck_velocity == points[i] == at["stribeck_velocity"] and p.bristle_stiffness == 3.8277147e+05
               for i, at, p in truths)
    assert _replicate_truths(fitted, {}, 3, range(3)) == ([(0, {}, fitted), (1, {}, fitted), (2, {}, fitted)], [])


def test_identify_rule_bad_value_is_one_line(tmp_path):
    """``identify --rule`` other than mean or pairwise: one line naming the option, exit 2."""
    for bad in ("ranks", "MEAN", ""):
        r = _inproc("identify", tmp_path / "axis.csv", "--family", "auto", "--rule", bad)
        assert r.returncode == 2, (bad, r.stdout, r.stderr)
        assert "--rule" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_identify_separable_bad_value_is_one_line(tmp_path):
    """``identify --separable`` outside [0, 10] (or not finite): one line naming the option, exit 2."""
    for bad in ("-1", "11", "nan"):
        r = _inproc("identify", tmp_path / "axis.csv", "--family", "auto", "--separable", bad)
        assert r.returncode == 2, (bad, r.stdout, r.stderr)
        assert "--separable" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
