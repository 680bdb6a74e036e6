"""Hostile inputs and faults of issue 28, each through the real CLI (``reports.cli.main`` in-process
for the user errors, the executable in a subprocess for runs): one line and exit 2 before anything
runs, nothing written outside ``--out``, no silent ``ok`` for an absurd plant, no hang, no orphan."""

from __future__ import annotations

import itertools
import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tests.cli_helpers import ROOT, cli

_UNIQUE = itertools.count()

# A plugin controller with a string option (a swept string value reaches the point's name).
PLUGIN = '''
import dataclasses
from controllers.base import Controller, register
from plant.drive import DriveCommand


@dataclasses.dataclass(frozen=True)
class Opts:
    label: str = "a"
    level: float = 0.0


class _Hold(Controller):
    Options = Opts

    def reset(self, params, rng):
        pass

    def step(self, y):
        return DriveCommand.hold(self.options.level)
'''


def _plugin(tmp: Path, names: list[str], body: str = "") -> str:
    """A uniquely named plugin module in ``tmp`` registering ``_Hold`` under each of ``names``."""
    module = f"hostile28_{os.getpid()}_{next(_UNIQUE)}"
    regs = "".join(f"\n\n@register({n!r})\nclass C{i}(_Hold):\n    pass\n" for i, n in enumerate(names))
    (tmp / f"{module}.py").write_text(PLUGIN + textwrap.dedent(body) + regs)
    return module


def _matrix(tmp: Path, body: str, name: str = "m.toml") -> Path:
    path = tmp / name
    path.write_text(textwrap.dedent(body))
    return path


def _files(root: Path) -> set[Path]:
    return {p for p in root.rglob("*")}


def _one_line(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    assert "Traceback" not in stderr and len(lines) == 1 and lines[0].startswith("error: "), stderr
    return lines[0]


def _main_exit2(args: list, capsys) -> str:
    from reports.cli import main

    with pytest.raises(SystemExit) as stop:
        main([str(a) for a in args])
    err = capsys.readouterr().err
    assert stop.value.code == 2, err
    return _one_line(err)


# --------------------------------------------------------------------------- 1. names reaching paths

@pytest.mark.parametrize("registered, fragment", [
    ("../../../escaped", "matrix.controllers[0]: name '../../../escaped' must start with a letter or digit"),
    ("a__b", "matrix.controllers[0]: name 'a__b'"),
    ("ctl\U0001F642", "matrix.controllers[0]: name 'ctl\U0001F642'"),
])
def test_a_registered_name_that_is_not_a_file_name_is_a_user_error(tmp_path, capsys, registered, fragment):
    """Before: a plugin's ``../../../escaped`` wrote cells/escaped__thesis__s0.json two levels above --out."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    module = _plugin(work, [registered])
    m = _matrix(work, f'''
        [matrix]
        plugins = ["{module}"]
        controllers = [{json.dumps(registered, ensure_ascii=False)}]
        scenarios = ["thesis"]
        seeds = [0]
        duration_s = 0.2
        warmup_s = 0.1
    ''')
    before = _files(tmp_path)
    line = _main_exit2(["run", "--matrix", m, "--out", work / "out", "--no-traces"], capsys)
    assert fragment in line and str(m) in line
    assert _files(tmp_path) == before


def test_a_swept_string_value_that_is_not_a_file_name_is_a_user_error(tmp_path, capsys):
    """Before: ``label = ["x/../../../../swept"]`` wrote the cell file four levels above --out."""
    work = tmp_path / "a" / "b" / "c" / "d"
    work.mkdir(parents=True)
    module = _plugin(work, ["t-str"])
    m = _matrix(work, f'''
        [matrix]
        plugins = ["{module}"]
        controllers = ["t-str"]
        scenarios = ["thesis"]
        seeds = [0]
        duration_s = 0.2
        warmup_s = 0.1

        [sweep.t-str]
        label = ["ok", "x/../../../../swept"]
    ''')
    before = _files(tmp_path)
    line = _main_exit2(["run", "--matrix", m, "--out", work / "out", "--no-traces"], capsys)
    assert f"{m}:11: sweep.t-str.label:" in line and "x/../../../../swept" in line
    assert _files(tmp_path) == before


@pytest.mark.parametrize("length", [81, 236, 300])
def test_a_long_variant_name_is_a_user_error_before_anything_runs(tmp_path, capsys, length):
    """Before: names of 236-300 characters were computed, then not stored ("File name too long")."""
    name = "v" * length
    m = _matrix(tmp_path, f'''
        [matrix]
        controllers = ["{name}"]
        scenarios = ["thesis"]
        seeds = [0]
        duration_s = 0.2
        warmup_s = 0.1

        [controllers.{name}]
        base = "linear"
    ''')
    line = _main_exit2(["run", "--matrix", m, "--out", tmp_path / "out", "--no-traces"], capsys)
    assert f"controllers.{name}: name" in line and f"{length} characters; at most 80" in line
    assert not (tmp_path / "out").exists()


def test_a_long_out_is_a_user_error(tmp_path, capsys):
    """Before: ``OSError: File name too long`` with a traceback from bench/store.py."""
    m = _matrix(tmp_path, '''
        [matrix]
        controllers = ["linear"]
        scenarios = ["thesis"]
        seeds = [0]
        duration_s = 0.2
        warmup_s = 0.1
    ''')
    out = tmp_path.joinpath(*["d" * 200] * 25)        # 5000 characters, components under 255
    line = _main_exit2(["run", "--matrix", m, "--out", out, "--no-traces"], capsys)
    assert line.startswith("error: --out ") and "at most 3500" in line
    line = _main_exit2(["run", "--matrix", m, "--out", tmp_path / ("x" * 300), "--no-traces"], capsys)
    assert "path component of 300 bytes; at most 255" in line
    line = _main_exit2(["report", out], capsys)
    assert line.startswith("error: report DIR ") and "at most 3500" in line
    assert _files(tmp_path) == {m}


# --------------------------------------------------------------------------- 2. physical validation

@pytest.mark.parametrize("line_, key, fragment", [
    ("duration_s = 1e308", "matrix.duration_s", "at most 20000000 samples (duration_s <= 200000 s"),
    ("duration_s = 1e300", "matrix.duration_s", "at most 20000000 samples"),
    ("duration_s = 200000.01", "matrix.duration_s", "at most 20000000 samples"),
])
def test_an_absurd_run_length_is_a_user_error(tmp_path, capsys, line_, key, fragment):
    """Before: 1e308 raised OverflowError from round(duration/tau); 1e300 became an error row."""
    m = _matrix(tmp_path, f'''
        [matrix]
        controllers = ["linear"]
        scenarios = ["thesis"]
        seeds = [0]
        {line_}
        warmup_s = 0.1
    ''')
    line = _main_exit2(["run", "--matrix", m, "--out", tmp_path / "out", "--no-traces"], capsys)
    assert f"{m}: {key}: scenario 'thesis'" in line and fragment in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("field, value, fragment", [
    ("sample_period", "5e-324", "PlantParams.sample_period must be in [1e-06, 10] s"),
    ("u_max", "1e308", "PlantParams.u_max must be in [0, 1e+06] ozf·in"),
    ("u_max", "1e20", "PlantParams.u_max must be in [0, 1e+06] ozf·in"),
    ("measurement_noise_std", "1e200", "PlantParams.measurement_noise_std must be in [0, 1] rad"),
    ("inertia", "1e-300", "PlantParams.inertia must be in [1e-09, 1e+06]"),
])
def test_an_implausible_plant_is_a_user_error_with_the_range(tmp_path, capsys, field, value, fragment):
    """Before: u_max = 1e308 gave ``ok`` rows with mean |i| ~ 1.6e306 and a shaft that never moved;
    sample_period = 5e-324 raised OverflowError."""
    m = _matrix(tmp_path, f'''
        [matrix]
        controllers = ["linear"]
        scenarios = ["big"]
        seeds = [0]
        duration_s = 0.2
        warmup_s = 0.1

        [scenarios.big]
        base = "thesis"
        {field} = {value}
    ''')
    line = _main_exit2(["run", "--matrix", m, "--out", tmp_path / "out", "--no-traces"], capsys)
    assert line.startswith(f"error: {m}:") and f": scenarios.big.{field}: {fragment}" in line, line
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- 8. planning

def test_values_that_print_alike_are_one_point(tmp_path, capsys):
    """Before: ``crossover = [40, 40.0]`` planned linear[crossover=40] twice."""
    m = _matrix(tmp_path, '''
        [matrix]
        controllers = ["linear"]
        scenarios = ["thesis"]
        seeds = [0]
        duration_s = 0.2
        warmup_s = 0.1

        [sweep.linear]
        crossover = [40, 40.0]
    ''')
    line = _main_exit2(["run", "--matrix", m, "--out", tmp_path / "out", "--no-traces"], capsys)
    assert f"{m}:10: sweep.linear.crossover: lists a value more than once" in line
    assert not (tmp_path / "out").exists()


def test_a_variant_named_like_a_sweep_point_is_not_planned_twice(tmp_path, capsys):
    m = _matrix(tmp_path, '''
        [matrix]
        controllers = ["linear", "linear[crossover=40]"]
        scenarios = ["thesis"]
        seeds = [0]
        duration_s = 0.2
        warmup_s = 0.1

        [controllers."linear[crossover=40]"]
        base = "linear"

        [sweep.linear]
        crossover = [40]
    ''')
    line = _main_exit2(["run", "--matrix", m, "--out", tmp_path / "out", "--no-traces"], capsys)
    assert "plans the controller 'linear[crossover=40]' twice" in line


# --------------------------------------------------------------------------- 3. no silent "ok"

def test_a_nan_initial_friction_is_rejected():
    """Before: run_closed_loop(..., x5_initial=nan) returned ``ok`` with a NaN friction state."""
    from bench.runner import run_closed_loop
    from controllers.base import make_controller
    from plant.params import PlantParams

    with pytest.raises(ValueError, match=r"x5_initial must be a finite friction \[ozf·in\], got nan"):
        run_closed_loop(PlantParams(), make_controller("linear"), duration_s=0.5, warmup_s=0.1, x5_initial=math.nan)


def test_a_state_that_leaves_the_finite_range_ends_diverged(monkeypatch):
    """A fault injected into the plant step (x5 becomes NaN, x1 stays finite so the plant's own
    |x1| check does not fire) was ``ok`` before; now the run ends ``diverged`` with NaN metrics."""
    import numpy as np

    import bench.runner as runner
    from controllers.base import make_controller
    from plant.params import PlantParams
    from plant.protocol import get_family
    from plant.state import X5

    calls = itertools.count()

    class Faulty(type(get_family("multimode"))):   # the plant step with a fault injected
        def step(self, state, command, params, noise, options, *, duration=None, record=False):
            step = super().step(state, command, params, noise, options, duration=duration, record=record)
            if next(calls) == 10:
                x = np.array(step.state.x)
                x[X5] = math.nan
                step = step._replace(state=step.state._replace(x=x))
            return step

    # compiled=False: the fault is injected in the family's Python step, which pulse-width's
    # compiled loop (its compiled_law) would not call
    result = runner.run_closed_loop(PlantParams(), make_controller("pulse-width"), duration_s=0.3, warmup_s=0.1,
                                    family=Faulty(), compiled=False)
    assert result.status == "diverged" and "plant state left the finite range" in result.message
    assert math.isnan(result.metrics["peak_error_rad"]) and math.isnan(result.metrics["mean_abs_current"])


def test_the_current_metrics_never_exceed_the_drive_limit():
    """The physical bound used by ``unphysical``: |x3| <= u_max, so mean |i| <= RMS i <= u_max,
    on real runs of a saturating controller; and a value above it is reported."""
    from bench.metrics import unphysical
    from bench.runner import run_closed_loop
    from controllers.base import make_controller
    from plant.params import PlantParams

    import numpy as np

    p = PlantParams(u_max=3.0)
    for seed in range(3):
        r = run_closed_loop(p, make_controller("pulse-width"), duration_s=2.0, warmup_s=0.1, seed=seed)
        assert r.status == "ok", r.message
        assert 0 < r.metrics["mean_abs_current"] <= r.metrics["rms_current"] <= p.u_max
    ok = {"mean_abs_current": 1.0, "rms_current": 2.9, "peak_error_rad": 1e-5}
    assert unphysical(np.zeros(6), ok, 3.0) is None
    assert "rms_current = 3.5 ozf·in exceeds u_max = 3.0" in unphysical(np.zeros(6), {**ok, "rms_current": 3.5}, 3.0)
    assert "metric peak_error_rad = inf" in unphysical(np.zeros(6), {**ok, "peak_error_rad": math.inf}, 3.0)


# --------------------------------------------------------------------------- a stored run (items 4, 5, 9)

BOUND = '''

@register("t-bound")
class Bound(_Hold):
    privileged = True

    def observe_truth(self, state, plant):
        pass


@register("t-plain")
class Plain(_Hold):
    pass
'''


def _run_matrix_text(module: str, controllers: list[str], plugins: bool = True) -> str:
    return textwrap.dedent(f'''
        [matrix]
        {f'plugins = ["{module}"]' if plugins else ''}
        controllers = {json.dumps(controllers)}
        scenarios = ["thesis"]
        seeds = [0]
        duration_s = 0.3
        warmup_s = 0.1
    ''')


@pytest.fixture(scope="module")
def stored_run(tmp_path_factory):
    """A finished run (through the executable) of a built-in controller, a plugin controller and a
    plugin bound; the test process never imports the plugin."""
    tmp = tmp_path_factory.mktemp("stored")
    module = f"hostile28_bound_{os.getpid()}"
    (tmp / f"{module}.py").write_text(PLUGIN + BOUND)
    m = tmp / "m.toml"
    m.write_text(_run_matrix_text(module, ["linear", "t-plain", "t-bound"]))
    proc = cli("run", "--matrix", m, "--out", tmp / "out", "--no-traces")
    assert proc.returncode == 0, proc.stderr
    assert module not in sys.modules
    import pandas as pd   # every cell ran (before: the bound's old observe_truth signature errored unseen)

    assert set(pd.read_parquet(tmp / "out" / "results.parquet")["status"]) == {"ok"}, proc.stderr
    return tmp, m, tmp / "out"


def _copy_run(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def test_rows_flag_a_privileged_bound_and_the_report_tells_a_plugin_bound_apart(stored_run):
    """Before: no flag column; the report, which does not import plugins, ranked the plugin bound
    as a controller (frontier ``bound`` False, a peer in the claims)."""
    import pandas as pd

    from reports.claims import _bound_rows
    from reports.frontier import point_table
    from reports.inputs import load_inputs

    _, _, out = stored_run
    stored = pd.read_parquet(out / "results.parquet").set_index("controller")
    assert stored.loc["t-bound", "privileged"] and not stored.loc["t-plain", "privileged"]
    assert not stored.loc["linear", "privileged"]
    inputs = load_inputs(out)
    points = point_table(inputs.results, inputs.config).set_index("controller")["bound"]
    assert points.to_dict() == {"linear": False, "t-plain": False, "t-bound": True}
    flags = _bound_rows(inputs.results)
    assert dict(zip(inputs.results["controller"], flags)) == {"linear": False, "t-plain": False, "t-bound": True}


def test_report_reads_the_stored_cells_when_the_tables_are_missing(stored_run, tmp_path):
    """After a SIGKILL of the main process the cells are stored but the tables are not rebuilt.
    Before: ``report DIR`` wrote "the benchmark matrix was not run"."""
    out = _copy_run(stored_run[2], tmp_path / "killed")
    (out / "results.parquet").unlink()
    (out / "results.csv").unlink()
    (out / "report.html").unlink()
    proc = cli("report", out)
    assert proc.returncode == 0, proc.stderr
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "was not run" not in html and "the 3 stored cell files in cells/" in html
    for name in ("linear", "t-plain", "t-bound"):
        assert f">{name}<" in html


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_while_the_report_is_written(stored_run, tmp_path, sig, code):
    """Every cell is stored, so ``run`` goes straight to the report; the signal arrives while it is
    written. Before: SIGTERM killed it silently (exit -15, a 4 MB temporary file left), SIGINT
    gave no message."""
    tmp, m, src = stored_run
    out = _copy_run(src, tmp_path / "out")
    (out / "report.html").unlink()
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "reports.cli", "run", "--matrix", str(m), "--out", str(out),
                             "--no-traces"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env)
    for line in proc.stdout:                   # the run phase ends with this line; the report follows
        if " cells in " in line:
            break
    time.sleep(0.3)                            # into the report (importing plotly and rendering take ~2 s)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:                   # the report was already written: nothing to test here
        pytest.skip("the report finished before the signal arrived")
    assert proc.returncode == code, err
    assert "Traceback" not in err
    assert "stopped while writing the report; the results are stored" in err
    assert not list(out.glob(".*.tmp")) and not (out / "report.html").exists()


def test_a_run_directory_grows_by_a_plugin_controller(tmp_path, capsys):
    """Before: the plugin list entered every cell's definition, so adding a plugin controller to a
    run of built-in controllers was refused ("run with another definition")."""
    from reports.cli import main
    from bench.matrix import load_matrix

    module = _plugin(tmp_path, ["t-grow"])
    plain, grown = tmp_path / "plain.toml", tmp_path / "grown.toml"
    plain.write_text(_run_matrix_text(module, ["linear"], plugins=False))
    grown.write_text(_run_matrix_text(module, ["linear", "t-grow"]))
    before, after = load_matrix(plain).cells(), load_matrix(grown).cells()
    assert before[0].definition() == after[0].definition() and before[0].config_hash == after[0].config_hash
    assert before[0].definition()["plugins"] == [] and after[1].definition()["plugins"] == [module]
    for m in (plain, grown):
        with pytest.raises(SystemExit) as stop:
            main(["run", "--matrix", str(m), "--out", str(tmp_path / "out"), "--no-traces"])
        assert stop.value.code == 0, capsys.readouterr().err
    rows = sorted(p.stem for p in (tmp_path / "out" / "cells").glob("*.json"))
    assert rows == ["linear__thesis__s0", "t-grow__thesis__s0"]
    meta = json.loads((tmp_path / "out" / "meta.json").read_text())
    assert meta["to_run"] == 1 and meta["computed"] == 1


# --------------------------------------------------------------------------- 6. orphans and supervised resets

FAULTS = '''
import ctypes, os, subprocess, sys, threading, time

PIDS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "pids")


def _note(pid):
    with open(PIDS, "a") as fh:
        fh.write(f"{pid}\\n")


@register("t-spawn-hang")
class SpawnHang(_Hold):
    def step(self, y):          # a child process, then a hang in C until the time-limit kill
        _note(subprocess.Popen(["sleep", "300"]).pid)
        ctypes.CDLL(None).sleep(300)


@register("t-fork")
class Fork(_Hold):
    def reset(self, params, rng):
        self.forked = False

    def step(self, y):          # a fork that outlives the step (and the cell)
        if not self.forked:
            self.forked = True
            pid = os.fork()
            if pid == 0:
                time.sleep(300)
                os._exit(0)
            _note(pid)
        return super().step(y)


@register("t-reset-loop")
class ResetLoop(_Hold):
    def reset(self, params, rng):
        while True:
            pass


@register("t-reset-exit")
class ResetExit(_Hold):
    def reset(self, params, rng):
        os._exit(7)


@register("t-reset-thread")
class ResetThread(_Hold):
    def reset(self, params, rng):
        threading.Thread(target=time.sleep, args=(300,), daemon=False).start()
'''


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "\nState:\tZ" not in state          # a zombie is dead (a container's init may not reap it)


def _faults_run(tmp: Path, controllers: list[str], time_limit: float = 1.0, timeout: float = 120):
    module = f"hostile28_faults_{os.getpid()}_{next(_UNIQUE)}"
    (tmp / f"{module}.py").write_text(PLUGIN + FAULTS)
    m = tmp / "m.toml"
    m.write_text(_run_matrix_text(module, controllers) + f"time_limit_s = {time_limit}\n")
    t0 = time.monotonic()
    proc = cli("run", "--matrix", m, "--out", tmp / "out", "--no-traces", timeout=timeout)
    return proc, time.monotonic() - t0


@pytest.mark.slow
def test_cells_are_killed_with_everything_they_started_and_a_reset_thread_does_not_keep_the_cli(tmp_path):
    """Before: the ``sleep`` of a cell killed at its time limit survived with PPID 1; a step's fork
    survived the run; a non-daemon thread started by ``reset`` in the CLI's own process (the
    matrix check) kept it from exiting after the report."""
    proc, wall = _faults_run(tmp_path, ["t-spawn-hang", "t-fork", "t-reset-thread"], time_limit=1.0)
    assert proc.returncode == 0, proc.stderr
    status = {c: json.loads((tmp_path / "out" / "cells" / f"{c}__thesis__s0.json").read_text())["status"]
              for c in ("t-spawn-hang", "t-fork", "t-reset-thread")}
    assert status == {"t-spawn-hang": "error", "t-fork": "ok", "t-reset-thread": "ok"}
    pids = [int(p) for p in (tmp_path / "pids").read_text().split()]
    assert len(pids) == 2
    time.sleep(0.5)
    assert not [p for p in pids if _alive(p)]
    assert wall < 90


@pytest.mark.slow
@pytest.mark.parametrize("controller, fragment", [
    ("t-reset-loop", "construction or reset did not return within 6 s (matrix.time_limit_s + 5 s)"),
    ("t-reset-exit", "construction or reset failed: cell process exited with code 7"),
])
def test_a_reset_that_loops_or_exits_during_validation_is_a_user_error(tmp_path, controller, fragment):
    """Before: the matrix check reset the controller in the CLI's own process: a looping reset
    hung it for ever, ``os._exit(7)`` ended it with exit 7 and nothing written."""
    proc, wall = _faults_run(tmp_path, [controller])
    assert proc.returncode == 2, proc.stderr
    line = _one_line(proc.stderr)
    assert f"matrix.controllers: controller '{controller}' on scenario 'thesis': {fragment}" in line
    assert not (tmp_path / "out").exists() and wall < 60


# --------------------------------------------------------------------------- 7. the trace writer never blocks a cell

def _trace_cell():
    from bench.cells import Cell, ControllerSpec
    from bench.scenarios import builtin_scenarios

    scenario = builtin_scenarios()["thesis"].with_durations(duration_s=3.0, warmup_s=0.1)
    return Cell(ControllerSpec("pulse-width", "pulse-width"), scenario, 0, time_limit_s=60.0)


def _run_cell_within(cell, out: Path, limit_s: float) -> tuple[dict | None, float]:
    """run_cell on a thread; (row or None if it did not return within ``limit_s``, wall seconds)."""
    import threading

    from bench.cells import run_cell

    box: dict = {}
    t0 = time.monotonic()
    thread = threading.Thread(target=lambda: box.setdefault("row", run_cell(cell, out, traces=True)), daemon=True)
    thread.start()
    thread.join(limit_s)
    return box.get("row"), time.monotonic() - t0


def test_a_hung_trace_sink_gives_an_artifact_row_within_the_writer_timeout(tmp_path, monkeypatch):
    """rerun's sink blocks for ever (a hung or full file system). Before: the cell hung inside
    the sink until the executor's wall-clock kill (636 s with the default limit)."""
    import threading

    import rerun

    import bench.traces

    hang = threading.Event()
    monkeypatch.setattr(rerun.RecordingStream, "send_columns", lambda self, *a, **k: hang.wait())
    monkeypatch.setattr(bench.traces, "WRITER_TIMEOUT_S", 1.0, raising=False)
    row, wall = _run_cell_within(_trace_cell(), tmp_path, 30.0)
    hang.set()
    assert row is not None, "run_cell blocked on its trace"
    assert row["status"] == "error" and row["error_kind"] == "artifact", row["message"]
    assert row["message"].startswith("artifact: trace: the trace writer took no data for 1 s")
    assert wall < 10.0
    assert not list(tmp_path.glob("traces/*"))


def test_a_failing_trace_sink_is_an_artifact_error_retried_on_resume(tmp_path, monkeypatch):
    """rerun's own error on a full disk ("File-writer thread shut down prematurely", measured on a
    1 MB tmpfs). Before: error_kind ``run``, so the cell was final and never retried."""
    import rerun

    from bench.store import ResultsStore

    def full(self, *a, **k):
        raise RuntimeError("File-writer thread shut down prematurely")

    monkeypatch.setattr(rerun.RecordingStream, "send_columns", full)
    cell = _trace_cell()
    row, _ = _run_cell_within(cell, tmp_path, 60.0)
    assert row["status"] == "error" and row["error_kind"] == "artifact"
    assert row["message"] == "artifact: trace: RuntimeError: File-writer thread shut down prematurely"
    assert not [p for p in (tmp_path / "traces").iterdir()]
    store = ResultsStore(tmp_path)
    store.save(row)
    assert not store.is_done(cell, traces=True)


@pytest.mark.slow
@pytest.mark.parametrize("body, fragment", [
    ("while True:\n    pass\n", "did not finish within 6 s (matrix.time_limit_s + 5 s)"),
    ("import os\nos._exit(5)\n", "failed: cell process exited with code 5"),
    ("raise SystemExit(3)\n", "failed: SystemExit: 3"),
    ("import threading, time\nthreading.Thread(target=time.sleep, args=(300,), name='keeper').start()\n",
     "starts non-daemon thread(s) ['keeper']"),
])
def test_a_plugin_whose_import_hangs_exits_or_leaves_a_thread_is_a_user_error(tmp_path, body, fragment):
    """The plugin is imported first in a supervised process. Before: the CLI's own import looped
    for ever, ended the CLI with the plugin's exit code, or never exited (a non-daemon thread)."""
    module = f"hostile28_import_{os.getpid()}_{next(_UNIQUE)}"
    (tmp_path / f"{module}.py").write_text(body)
    m = tmp_path / "m.toml"
    m.write_text(_run_matrix_text(module, ["linear"]) + "time_limit_s = 1\n")
    proc = cli("run", "--matrix", m, "--out", tmp_path / "out", "--no-traces", timeout=120)
    assert proc.returncode == 2, proc.stderr
    line = _one_line(proc.stderr)
    assert f"{m}: matrix.plugins[0]: importing '{module}' {fragment}" in line, line
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_a_signal_after_the_report_does_not_kill_a_finished_command(stored_run, tmp_path):
    """Found by the signal test: a Ctrl-C during the interpreter's shutdown (up to ~1 s after the
    ``report:`` line) killed the finished command (exit -2, no message). Now: exit 0, or 130 with
    the message if it lands before the command returned."""
    tmp, m, src = stored_run
    out = _copy_run(src, tmp_path / "out")
    (out / "report.html").unlink()
    proc = subprocess.Popen([sys.executable, "-m", "reports.cli", "run", "--matrix", str(m), "--out", str(out),
                             "--no-traces"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    for line in proc.stdout:
        if line.startswith("report: "):
            break
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode in (0, 130) and "Traceback" not in err, err     # done, or stopped with a message
    assert proc.returncode == 0 or "interrupted: stopped" in err, err
    assert (out / "report.html").is_file() and not list(out.glob(".*.tmp"))


def test_a_caught_interrupt_inside_a_string_exec_does_not_kill_the_exit(tmp_path):
    """CPython flags a KeyboardInterrupt that leaves an ``exec`` of a string as unhandled, caught or
    not; under ``python -m`` it then re-kills itself with SIGINT at exit. Before: a Ctrl-C that hit
    scipy's lazy import while the report was written (a string ``exec``) exited -2 after printing
    "stopped while writing the report" (CI, once in ~5 runs); now the exit code is the command's."""
    (tmp_path / "ki_then_cli.py").write_text(textwrap.dedent('''
        import reports.cli

        def command(args, standalone_mode):   # a command stopped by Ctrl-C inside a string exec
            try:
                exec("raise KeyboardInterrupt")
            except KeyboardInterrupt:
                return 130

        reports.cli.app = command
        reports.cli.main()
    '''))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}
    proc = subprocess.run([sys.executable, "-m", "ki_then_cli"], cwd=ROOT, capture_output=True, text=True,
                          env=env, timeout=60)
    assert proc.returncode == 130, (proc.returncode, proc.stderr)
