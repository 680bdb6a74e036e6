"""Issue 25: ``identify`` on several processes gives the same fit, bit for bit.

The bootstrap's replicates (``fit_log(mapper=…)``) and ``choose_family``'s two folds may run in a
process pool; the reference is the sequential code path (``mapper=map``, the default, itself
equal to the code before the mapper existed). In-process mappers that run the work out of order
stand in for a pool here (the replay does not know who ran a replicate); one CLI test runs a real
forkserver pool in a fresh process."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from plant.identification import ExperimentOptions, design_experiment, fit_log, simulate_log, write_log
from plant.identification import fit as fit_module
from plant.identification.fit import choose_family
from plant.protocol import get_family
from reports.axis import fit_workers
from reports.cli import app


def _short_log(family: str, **fields):
    p = get_family(family).Params().replace(coulomb=1.1, stiction=1.75, inertia=0.62, **fields)
    return simulate_log(design_experiment(ExperimentOptions(repeats=1, holds=0)), family, p, 5)[0]


@pytest.fixture(scope="module")
def mm_log():
    return _short_log("multimode")


@pytest.fixture(scope="module")
def tm_log():
    return _short_log("two-mass", shaft_stiffness=1.5e4)


def _reversed_eager(fn, items):
    """A stand-in for a pool's map: every item computed, the last first, results in item order."""
    items = list(items)
    return iter([fn(x) for x in reversed(items)][::-1])


def _lazy(fn, items):
    """A stand-in for a pool's map that computes an item only when its result is asked for."""
    return (fn(x) for x in items)


def _fields(fit):
    return (fit.family, fit.params, fit.estimates, fit.std, fit.interval, fit.bic, fit.method, fit.budget_note,
            fit.n_moves, fit.n_samples, fit.y_model.tobytes())


def _bootstrap_checks(log, family, bootstrap, monkeypatch):
    """The deadline checks of the bootstrap of an uncut fit (budget 1e9, not hit): (clock, asking
    family) of each, in order."""
    past, sequential = fit_module._WorkClock.past, fit_module._sequential
    seen, start = [], []

    def recording(self, deadline, family):
        if deadline == 1e9:
            seen.append((self.spent, family))
        return past(self, deadline, family)

    def marking(*args):
        start.append(len(seen))       # the bootstrap starts here
        return sequential(*args)
    monkeypatch.setattr(fit_module._WorkClock, "past", recording)
    monkeypatch.setattr(fit_module, "_sequential", marking)
    full = fit_log(log, family, bootstrap=bootstrap, budget_s=1e9)
    monkeypatch.setattr(fit_module._WorkClock, "past", past)
    monkeypatch.setattr(fit_module, "_sequential", sequential)
    assert not full.budget_note and start
    return seen[start[0]:]


def _reruns(monkeypatch) -> list:
    """Counts the replicates the replay re-runs on the shared clock (not on a worker's trace clock)."""
    replicate, out = fit_module._replicate, []

    def counting(*args):
        if not isinstance(args[-1], fit_module._TraceClock):
            out.append(1)
        return replicate(*args)
    monkeypatch.setattr(fit_module, "_replicate", counting)
    return out


def _cut_before(checks, k):
    """A budget whose first check past it is ``checks[k]`` (the clock strictly grew there)."""
    assert checks[k][0] > checks[k - 1][0]
    return 0.5 * (checks[k - 1][0] + checks[k][0])


def test_parallel_bootstrap_equals_the_sequential_loop(mm_log, monkeypatch):
    """Multimode (each replicate a refit from the estimate): the same AxisFit, bit for bit, with
    the replicates computed out of order or lazily, with no budget cut and with budgets that cut
    the bootstrap after ≥ 3 of its 10 replicates (the sd from those done) or after < 3 (the
    cluster-robust covariance instead; ``fit._MIN_REPLICATES``)."""
    ref = fit_log(mm_log, "multimode", bootstrap=10)
    assert not ref.budget_note and "10 logs simulated" in ref.method
    assert _fields(fit_log(mm_log, "multimode", bootstrap=10, mapper=_reversed_eager)) == _fields(ref)
    checks = _bootstrap_checks(mm_log, "multimode", 10, monkeypatch)
    done = []
    for frac, mapper in ((0.2, _lazy), (0.75, _reversed_eager)):
        budget = _cut_before(checks, int(frac * len(checks)))
        seq = fit_log(mm_log, "multimode", bootstrap=10, budget_s=budget)
        assert "hit in the bootstrap after" in seq.budget_note
        done.append(int(seq.budget_note.split("after ")[1].split(" of")[0]))
        assert _fields(fit_log(mm_log, "multimode", bootstrap=10, budget_s=budget, mapper=mapper)) == _fields(seq)
    assert done[0] < fit_module._MIN_REPLICATES <= done[1] < 10
    # a worker budget *below* the sequential one (a wrong rounding margin; here half a replicate's
    # mean work): the replay meets a worker's cut before its own and re-runs that replicate on
    # the shared clock — still exact
    s0, per_replicate = checks[0][0], (checks[-1][0] - checks[0][0]) / 10
    monkeypatch.setattr(fit_module, "_REPLAY_MARGIN", (0.5 * per_replicate - (budget - s0)) / budget)
    reruns = _reruns(monkeypatch)
    assert _fields(fit_log(mm_log, "multimode", bootstrap=10, budget_s=budget, mapper=_lazy)) == _fields(seq)
    assert len(reruns) >= 1


def _multi_start_cut(tm_log, monkeypatch, asker):
    """Two-mass (each replicate the point fit's path, multimode's fit nested in its start), 5
    replicates, cut at the first check past a third of the bootstrap's checks asked by ``asker``."""
    checks = _bootstrap_checks(tm_log, "two-mass", 5, monkeypatch)
    k = next(k for k in range(len(checks) // 3, len(checks)) if checks[k][1] == asker and checks[k][0] > checks[k - 1][0])
    budget = _cut_before(checks, k)
    seq = fit_log(tm_log, "two-mass", bootstrap=5, budget_s=budget)
    assert "hit in the bootstrap" in seq.budget_note
    reruns = _reruns(monkeypatch)
    assert _fields(fit_log(tm_log, "two-mass", bootstrap=5, budget_s=budget, mapper=_lazy)) == _fields(seq)
    assert len(reruns) == (asker == "multimode")     # the nested cut's replicate re-run here, the outer's dropped


def test_parallel_bootstrap_cut_in_the_nested_multimode_fit(tm_log, monkeypatch):
    """A budget cut at a check of the multimode fit nested in a replicate's start (which stops at
    its best point while the outer fit goes on: the replay re-runs that replicate on the shared
    clock) gives the sequential fit, bit for bit."""
    _multi_start_cut(tm_log, monkeypatch, "multimode")


@pytest.mark.slow
def test_parallel_bootstrap_cut_in_a_multi_start_refit(tm_log, monkeypatch):
    """A budget cut at a check of a two-mass replicate's own model (the fit stops: the replicate is
    dropped and the loop ends) gives the sequential fit, bit for bit."""
    _multi_start_cut(tm_log, monkeypatch, "two-mass")


def test_choose_family_folds_in_any_order_give_the_same_choice(tm_log):
    """The two folds are independent: run the second first, the choice, scores, per-move scores,
    signed ranks (against the best and pairwise) and fold fits are those of the sequential loop,
    bit for bit (CPU and wall time excepted)."""
    fams = ["multimode", "two-mass"]
    _, ref = choose_family(tm_log, fams, final_fit=False)
    _, other = choose_family(tm_log, fams, final_fit=False, mapper=_reversed_eager)
    for name in ("family", "best", "score", "excess", "excess_se", "rule", "criterion", "signs", "ranks", "pairs"):
        assert getattr(other, name) == getattr(ref, name), name
    for name in ("per_move", "per_move_output_error", "fold_fits"):
        a, b = getattr(ref, name), getattr(other, name)
        assert list(a) == list(b) and all(np.array_equal(a[k], b[k]) for k in a), name
    assert set(other.cpu) == set(fams) and all(v > 0 for v in other.cpu.values())
    with pytest.raises(ValueError, match="mapper"):
        choose_family(tm_log, fams, final_fit=False, mapper=None)


def test_choose_family_restart_changes_nothing_when_no_fold_is_stuck(tm_log, monkeypatch):
    """``restart=True`` (issue 25's tenth session) re-fits a fold only when its first multimode fit
    costs more than ``_RESTART_FACTOR`` times the refit's: on this log no fold is stuck, and the
    choice, scores and fold fits equal the default's bit for bit. With the factor at 0 every fold
    is re-fitted from the refit's core (two passes, each fold), and the result still names a family
    with finite scores."""
    import dataclasses

    import plant.identification.fit as F

    fams = ["multimode", "two-mass"]
    _, ref = choose_family(tm_log, fams, final_fit=False)
    _, other = choose_family(tm_log, fams, final_fit=False, restart=True)
    for name in ("family", "best", "score", "excess", "excess_se", "rule", "criterion", "signs", "ranks", "pairs"):
        assert getattr(other, name) == getattr(ref, name), name
    for name in ("per_move", "per_move_output_error", "fold_fits"):
        a, b = getattr(ref, name), getattr(other, name)
        assert list(a) == list(b) and all(np.array_equal(a[k], b[k]) for k in a), name
    passes = []
    replace = dataclasses.replace
    monkeypatch.setattr(F, "_RESTART_FACTOR", 0.0)

    def counted(obj, **kw):        # dataclasses.replace of a _FoldFits is the restart (Params use it too)
        if isinstance(obj, F._FoldFits):
            passes.append(kw.get("core"))
        return replace(obj, **kw)
    monkeypatch.setattr(F.dataclasses, "replace", counted)
    _, forced = choose_family(tm_log, fams, final_fit=False, restart=True)
    assert len(passes) == 2 and all(c is not None and c.shape == (4,) for c in passes)
    assert forced.family in fams and all(np.isfinite(v) for v in forced.score.values())
    with pytest.raises(ValueError, match="restart"):
        choose_family(tm_log, fams, final_fit=False, restart="yes")


def test_worker_count_default_and_cap(monkeypatch):
    """Default: the cores this process may use; never more than the work (replicates, and auto's
    two folds); at least 1."""
    import os

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    assert fit_workers(None, "lugre", 20) == 4
    assert fit_workers(None, "lugre", 0) == 1
    assert fit_workers(None, "auto", 0) == 2
    assert fit_workers(None, "multimode", 3) == 3
    assert fit_workers(2, "multimode", 20) == 2
    assert fit_workers(1, "auto", 20) == 1


def test_identify_workers_on_a_real_pool_equals_one_process(mm_log, tmp_path):
    """``identify --workers 2`` in a fresh process (a forkserver pool of 2: the replicates pickled
    to the workers, the numba kernels loaded there) writes the same matrix file, byte for byte, as
    ``--workers 1`` (everything in this process); a bad --workers is one line, exit 2."""
    write_log(mm_log, tmp_path / "log.csv")
    args = ["identify", str(tmp_path / "log.csv"), "--family", "multimode", "--bootstrap", "6"]
    one = CliRunner().invoke(app, args + ["--out", str(tmp_path / "one.toml"), "--workers", "1"])
    assert one.exit_code == 0, one.stderr
    two = subprocess.run([sys.executable, "-m", "reports.cli", *args, "--out", str(tmp_path / "two.toml"),
                          "--workers", "2"], capture_output=True, text=True, timeout=300)
    assert two.returncode == 0, two.stderr
    assert (tmp_path / "two.toml").read_text() == (tmp_path / "one.toml").read_text()
    assert "6 logs simulated" in (tmp_path / "one.toml").read_text()
    for bad in ("0", "-1"):
        r = CliRunner().invoke(app, args + ["--workers", bad])
        assert r.exit_code == 2 and "--workers" in r.stderr and len(r.stderr.strip().splitlines()) == 1
