"""solnic's and solnic-modern's Python samples inside the compiled loop (:mod:`controllers.solnic.idle_step`).

Where the idle step (the faithful :func:`~controllers.solnic.idle_step.idle_step` or the joint
EKF's :func:`~controllers.solnic.idle_step.joint_idle_step`) cannot do a sample (a pulse launch, a cycle's evaluation, a plan the
cache cannot give) it restores the sample's entry state and calls the controller's Python step
from the loop (numba ``objmode``) instead of handing the sample back to the runner. The
reference is the runner's own Python loop (``compiled=False``, which never enters the compiled
step) and the hand-back path (``python_in_loop = False``): every metric and the summary must be
equal bit for bit, also where the loop redoes a sample (more noise or more event-log room), where
the Python step raises, and where it returns a command the loop would reject.
"""

from __future__ import annotations

import pytest

import plant.law_driver as law_driver
from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from controllers.base import ControllerDiverged
from controllers.solnic.controller import SolnicController
from plant.drive import DriveCommand

RUNTIME = ("runtime_s", "realtime_factor")


def _row(r):
    return r.status, r.message, {k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.summary


def _run(scenario, seed, duration, *, in_loop=True, name="solnic-modern", **kw):
    sc = builtin_scenarios()[scenario]
    c = make_controller(name)
    c.python_in_loop = in_loop
    calls = []
    step, staged = c.step, c._staged_step
    c.step = lambda y: calls.append(1) or step(y)            # counts the controller's Python samples
    c._staged_step = lambda: calls.append(1) or staged()     # (those the joint step began: filters done)
    r = run_closed_loop(sc.params, c, duration_s=duration, warmup_s=duration / 5, seed=seed, family=sc.family,
                        model=sc.model, **kw)
    return r, len(calls), c


@pytest.mark.parametrize("name, scenario, seed", [("solnic-modern", "thesis", 1), ("solnic-modern", "delayed", 2),
                                                  ("solnic-modern", "disturbed", 3), ("solnic", "thesis", 4),
                                                  ("solnic", "quantized", 5), ("solnic", "disturbed", 6)])
def test_samples_in_the_loop_are_the_python_rows(name, scenario, seed, monkeypatch):
    """In the loop, handed back, and the runner's Python loop: the same rows; the loop makes no
    hand-back at all (one compiled run), the hand-back path one per Python sample."""
    runs = []
    orig = law_driver.run_law_chunks

    def counting(*a, **k):
        runs.append(1)
        return orig(*a, **k)

    for mod in ("plant.multimode.law_loop", "plant.multimode.disturbed_loop"):
        monkeypatch.setattr(f"{mod}.run_law_chunks", counting, raising=False)
    in_loop, n_in, c = _run(scenario, seed, 10.0, name=name)
    n_runs_in, runs[:] = len(runs), []
    back, n_back, _ = _run(scenario, seed, 10.0, in_loop=False, name=name)
    n_runs_back = len(runs)
    python, _, _ = _run(scenario, seed, 10.0, compiled=False, name=name)
    assert in_loop.status == "ok" and in_loop.summary["pulses"] > 10
    assert _row(in_loop) == _row(back) == _row(python)
    assert n_in == n_back and 0 < n_in < 300                 # the same Python samples, few of them
    if scenario != "disturbed":                               # (its loop is plant.multimode.disturbed_loop's)
        assert n_runs_in == 1 and n_runs_back == n_back + 1   # no hand-back in the loop; one per sample before
    assert c._in_loop is not None and c._replay is None


def test_a_sample_the_loop_redoes_is_not_a_second_python_sample(monkeypatch):
    """A tiny noise margin and a tiny event scratch make the loop undo and redo samples after
    their step (plant.law_driver.run_law_chunks): the command and state of the first call are
    reused, so the rows stay the Python loop's."""
    monkeypatch.setattr(law_driver, "NOISE_MARGIN", 4)
    init = law_driver.X1Log.__init__

    def small_scratch(self, n):
        init(self, n)
        self.scratch = self.scratch[:1]

    monkeypatch.setattr(law_driver.X1Log, "__init__", small_scratch)
    redo = []
    orig = SolnicController._sample_in_loop

    def spy(self, y, offs, levs):
        redo.append(self._in_loop is not None and self._in_loop[0] == self._loop_sample()[1])
        return orig(self, y, offs, levs)

    monkeypatch.setattr(SolnicController, "_sample_in_loop", spy)
    in_loop, n_in, _ = _run("thesis", 4, 8.0, x1_log=True)
    python, n_py, _ = _run("thesis", 4, 8.0, x1_log=True, compiled=False)
    assert sum(redo) >= 2                                     # redone samples happened (scratch 1 -> 4 -> 16)
    assert _row(in_loop) == _row(python)
    assert n_in == len(redo) - sum(redo)                      # one Python sample per first call only
    assert (in_loop.samples["x1"] == python.samples["x1"]).all()
    assert (in_loop.events["t"] == python.events["t"]).all()


@pytest.mark.parametrize("name, in_loop, kind", [("solnic-modern", True, "diverged"), ("solnic-modern", True, "error"),
                                                  ("solnic-modern", False, "error"), ("solnic", True, "error")])
def test_an_exception_in_the_python_sample_ends_the_run_as_the_python_loop(name, in_loop, kind, monkeypatch):
    """The fifth launch raises: the same status, message (an error's names the raising line) and
    summary."""
    launch = SolnicController._launch
    n = []

    def failing(self, *a):
        n.append(1)
        if len(n) == 5:
            raise (ControllerDiverged if kind == "diverged" else ZeroDivisionError)("test: the fifth launch")
        return launch(self, *a)

    monkeypatch.setattr(SolnicController, "_launch", failing)
    r, _, c = _run("thesis", 0, 6.0, in_loop=in_loop, name=name)
    n.clear()
    python, _, _ = _run("thesis", 0, 6.0, compiled=False, name=name)
    assert r.status == kind and "the fifth launch" in r.message
    assert ("test_solnic_in_loop.py" in r.message) == (kind == "error")
    assert _row(r) == _row(python)
    assert c.summary()["pulses"] == 4


def test_a_command_the_loop_rejects_is_handed_back_and_applied_by_the_runner(monkeypatch):
    """A launch whose pulse runs past the sample period (the plant rejects it): in the loop it is
    kept, handed back and returned by the runner's step call — the same error as the Python loop."""
    launch = SolnicController._launch
    n = []

    def late(self, *a):
        n.append(1)
        cmd = launch(self, *a)
        return DriveCommand(((0.0, 0.0), (0.5, cmd.segments[-2][1])), cmd.drive) if len(n) == 3 else cmd

    monkeypatch.setattr(SolnicController, "_launch", late)
    r, n_in, c = _run("thesis", 2, 6.0)
    n.clear()
    python, _, _ = _run("thesis", 2, 6.0, compiled=False)
    assert r.status == "error" and _row(r) == _row(python)
    assert c._replay is None and c._in_loop is None           # the kept command was used


def test_the_planner_reads_the_steps_bias_of_the_same_plan(monkeypatch):
    """At a sample the step gives to Python with a pending cycle, the planner's first trigger
    test needs the w2 bias of the plan the step has just solved for: it is read from the step's
    array (key-matched), not solved again. Each value read equals ``noise_model.pulse_bias``
    solved for that prediction (bit for bit), and the rows are the runner's Python loop's."""
    import controllers.solnic.controller as ctl
    solves, reads = [], []
    solve, read = ctl.pulse_bias, SolnicController._pulse_bias

    def checked(self, pred, dtu):
        got = read(self, pred, dtu)
        ks = min(self.friction.ks, pred.peak_torque * (1.0 - 1e-6))
        want = solve(self.params, ks, min(self.friction.kc, ks), dtu, pred.t_breakaway, pred.t_current_zero,
                     pred.t_nominal, braked=pred.t_off is not None)
        reads.append(got.hex() == want.hex())
        return got

    monkeypatch.setattr(ctl, "pulse_bias", lambda *a, **k: solves.append(1) or solve(*a, **k))
    monkeypatch.setattr(SolnicController, "_pulse_bias", checked)
    in_loop, _, _ = _run("thesis", 7, 20.0)
    n_solves = len(solves)
    python, _, _ = _run("thesis", 7, 20.0, compiled=False)
    assert len(reads) > 40 and all(reads)
    assert n_solves == 0 and len(solves) > 20                     # solved only on the Python loop
    assert _row(in_loop) == _row(python)


def test_a_command_only_the_plants_test_rejects_is_not_a_second_python_sample():
    """The model's u_max 1 % above the plant's: the controller's mirror of the loop's command test
    accepts its pulses, the loop (the plant's u_max) rejects the first and hands it back; the
    runner's step call returns that command, not a second Python sample — the same row, the same
    summary and the same number of Python samples as the hand-back path."""
    sc = builtin_scenarios()["thesis"]
    model = (sc.model or sc.params).replace(u_max=1.01 * sc.params.u_max)
    rows = []
    for in_loop in (True, False):
        c = make_controller("solnic-modern")
        c.python_in_loop = in_loop
        calls = []
        tail = c._step_tail
        c._step_tail = lambda *a: calls.append(1) or tail(*a)   # the controller's Python samples
        r = run_closed_loop(sc.params, c, duration_s=6.0, warmup_s=1.0, seed=2, family=sc.family, model=model)
        rows.append((_row(r), len(calls)))
    assert rows[0][0][0] == "error" and "level" in rows[0][0][1]
    assert rows[0] == rows[1]


def test_a_sample_given_to_python_keeps_the_steps_filter_updates_and_fired_trigger(monkeypatch):
    """The joint step gives a sample to Python after its filter updates (J_STAGE 1) and, where its
    trigger test fired, after that test (J_STAGE 2): Python does not update the joint EKF again
    (only samples the step gives back before its update, e.g. a k̂ outside the valid set, do),
    and a fired first test with a pending cycle goes straight to the evaluation, so the planner
    tests a trigger a second time only where the step could not plan (the grid's predictive not
    yet cached); the rows stay the runner's Python loop's. (b0b4871, before: 116 updates and 189
    trigger tests for 119 Python samples and 87 evaluations; now 1 and 128.)"""
    import controllers.solnic.controller as ctl
    from controllers.solnic.joint_filter import JointFilter
    updates, triggers = [], []
    update, trigger = JointFilter.update, ctl.plan_trigger
    monkeypatch.setattr(JointFilter, "update", lambda self, y: updates.append(1) or update(self, y))
    monkeypatch.setattr(ctl, "plan_trigger", lambda *a, **k: triggers.append(1) or trigger(*a, **k))
    in_loop, n_in, c = _run("thesis", 1, 10.0)
    n_updates, n_triggers = len(updates), len(triggers)
    python, _, _ = _run("thesis", 1, 10.0, compiled=False)
    assert _row(in_loop) == _row(python)
    assert n_in > 50 and c.counts["cycles_evaluated"] > 30
    assert n_updates <= 0.1 * n_in                              # the old path: one per Python sample
    assert n_triggers < n_in + 0.25 * c.counts["cycles_evaluated"]   # the old path: + one per evaluation at a trigger


_FIRST_CELL = r"""
import numpy as np
from numba.core import event
from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from plant.params import PlantParams
names = ("solnic", "solnic-modern")
for name in names:                      # what the forkserver's warm-up does: one reset each
    make_controller(name).reset(PlantParams(), np.random.default_rng(0))
sc = builtin_scenarios()["thesis"]
with event.install_recorder("numba:compile") as rec:
    for name in names:
        c = make_controller(name)
        r = run_closed_loop(sc.params, c, duration_s=4.0, warmup_s=1.0, seed=0, family=sc.family, model=sc.model)
        assert r.status == "ok" and c.counts["pulses"] > 5, (name, r.status, r.message)
print(sum(1 for _, ev in rec.buffer if ev.is_start))
"""


def test_the_first_reset_in_a_process_compiles_the_in_loop_sample():
    """numba compiles a step's ``objmode`` block (the Python sample inside the loop) at its first
    execution in each process and does not cache it (~0.07 s, plus the Python sample's kernels
    loaded from the cache: a worker process's first solnic-modern cell cost 0.33 s against
    0.19). The first reset of each idle-step kind in a process now runs a throwaway twin
    through it (the forkserver's warm-up resets every controller), so in a fresh process whose
    controllers were reset once, a solnic and a solnic-modern cell compile nothing (before: the
    two blocks, in the cells)."""
    import subprocess
    import sys
    from pathlib import Path

    out = subprocess.run([sys.executable, "-c", _FIRST_CELL], cwd=Path(__file__).resolve().parents[1],
                         capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    assert int(out.stdout.split()[-1]) == 0
