"""Hostile inputs and faults of issue 28, each through the real CLI (``bench.cli.main`` in-process
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
    from bench.cli import main

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
    assert f"{m}: scenarios.big.{field}: {fragment}" in line, line
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
    from plant.state import X5

    real = runner.advance
    calls = itertools.count()

    def faulty(state, command, params, noise, opts, record=False):
        step = real(state, command, params, noise, opts, record=record)
        if next(calls) == 10:
            x = np.array(step.state.x)
            x[X5] = math.nan
            step = step._replace(state=step.state._replace(x=x))
        return step

    monkeypatch.setattr(runner, "advance", faulty)
    result = runner.run_closed_loop(PlantParams(), make_controller("pulse-width"), duration_s=0.3, warmup_s=0.1)
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
