"""Which cells of a matrix run recorded and write a report series (issue 27).

The reference ("before") is every cell run as :func:`bench.cells.run_cell` ran it before the
rule: recorded, with its series written (``series=True``). A matrix run now writes only the
series the report reads (:func:`bench.driver.reads_series`) and runs every other cell of a
controller without phase labels unrecorded, so its compiled step takes the compiled loop.
Every result column but the timing ones, and every series file still written, must be the
reference's exactly.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from numba import njit

from bench.cells import RUNTIME_COLUMNS, Cell, ControllerSpec, run_cell
from bench.driver import run_matrix
from bench.executors import Executor
from bench.matrix import Matrix
from bench.scenarios import builtin_scenarios
from bench.store import results_frame
from controllers import base, roles
from controllers.base import Controller, get_controller
from controllers.law import CompiledLaw, law_command
from plant.drive import DriveType

DURATION, WARMUP = 3.0, 1.0
_PHASES = {"phase:near": [0.0, 1.7523], "phase:far": [1.2001, 2.4], "phase:none": []}


@njit(cache=True)
def _phased_step(s, p, y, offs, levs):
    """u = clip(−K·y) for the first half of the interval, then half of it."""
    s[0] += 1.0
    level = min(max(-p[0] * y, -p[1]), p[1])
    offs[0], levs[0] = 0.0, level
    offs[1], levs[1] = p[2], 0.5 * level
    return 2


class _Phased(Controller):
    """A plugin-like controller with phases, a report series and a compiled step (test only)."""

    name = family = "series-phased-test"

    def reset(self, params, rng):
        self._s = np.zeros(1)
        self._p = np.array([300.0, params.u_max, 0.5 * params.sample_period])
        self._offs, self._levs = np.zeros(2), np.zeros(2)

    def step(self, y):
        return law_command(_phased_step(self._s, self._p, y, self._offs, self._levs), self._offs, self._levs,
                           DriveType.LINEAR)

    def compiled_law(self):
        return CompiledLaw(_phased_step, self._s, self._p, DriveType.LINEAR, 2)

    def internals(self):
        return {"steps": float(self._s[0])}

    def event_times(self):
        return {k: np.asarray(v, dtype=float) for k, v in _PHASES.items()}

    def report_series(self, t, warmup_s):
        return {"after_warmup": (np.asarray(t) >= warmup_s).astype(float)}

    def summary(self):
        return {"steps": int(self._s[0])}


class _InProcess(Executor):
    """Runs the cells in this process, one after another (so that a spy sees them)."""

    kind = "in-process"

    def start(self):
        pass

    def map_unordered(self, fn, calls, deadlines=None, keys=None):
        for i, args in enumerate(calls):
            yield i, fn(*args), None

    def close(self, cancel=False):
        pass


@pytest.fixture
def phased(monkeypatch):
    monkeypatch.setitem(base._REGISTRY, _Phased.name, _Phased)
    return _Phased


def _matrix(names, seeds=(2, 0, 1)) -> Matrix:
    sc = builtin_scenarios()
    scenarios = tuple(sc[s].with_durations(DURATION, WARMUP) for s in ("thesis", "stribeck"))
    return Matrix(source="test", controllers=tuple(ControllerSpec(n, n) for n in names), scenarios=scenarios,
                  seeds=seeds, time_limit_s=None)


def _comparable(frame: pd.DataFrame) -> pd.DataFrame:
    frame = frame.drop(columns=list(RUNTIME_COLUMNS)).set_index("cell").sort_index()
    return frame[sorted(frame.columns)]


def test_matrix_rows_and_written_series_are_the_recorded_runs(tmp_path, phased):
    names = ("observer-pid", phased.name, roles.IDENTIFICATION)
    matrix = _matrix(names)
    before_dir, after_dir = tmp_path / "before", tmp_path / "after"
    before = [run_cell(c, before_dir, False) for c in matrix.cells()]       # every cell recorded, as before
    assert all(r["status"] == "ok" for r in before)
    outcome = run_matrix(matrix, after_dir, executor=_InProcess(1), traces="none")

    old, new = _comparable(results_frame(before)), _comparable(outcome.results)
    assert list(new.index) == list(old.index) and list(new.columns) == list(old.columns)
    pd.testing.assert_frame_equal(new, old, check_exact=True)      # every value exactly, NaN where NaN
    # the phase plugin keeps its per-phase peaks; they are numbers where its phases own points
    peaks = new.loc[new["controller"] == phased.name, ["peak_error_near_rad", "peak_error_far_rad",
                                                        "peak_error_none_rad"]]
    assert peaks[["peak_error_near_rad", "peak_error_far_rad"]].gt(0).all().all()
    assert peaks["peak_error_none_rad"].isna().all()

    written = {p.stem for p in (after_dir / "series").glob("*.parquet")}
    lowest = {f"{n}__{s}__s0" for n in names for s in ("thesis", "stribeck")}
    claims = {f"{roles.IDENTIFICATION}__thesis__s{seed}" for seed in (0, 1, 2)}
    assert written == lowest | claims
    for stem in written:
        a = pd.read_parquet(before_dir / "series" / f"{stem}.parquet")
        b = pd.read_parquet(after_dir / "series" / f"{stem}.parquet")
        pd.testing.assert_frame_equal(a, b, check_exact=True)
        assert (before_dir / "series" / f"{stem}.parquet").read_bytes() == \
            (after_dir / "series" / f"{stem}.parquet").read_bytes()


def _counting_steps(monkeypatch, cls) -> list[int]:
    calls: list[int] = []
    step = cls.step
    monkeypatch.setattr(cls, "step", lambda self, y: calls.append(1) or step(self, y))
    return calls


def test_a_non_figure_cell_takes_the_compiled_loop_with_the_same_row(tmp_path, monkeypatch):
    cls = get_controller("observer-pid")
    calls = _counting_steps(monkeypatch, cls)
    sc = builtin_scenarios()["thesis"].with_durations(DURATION, WARMUP)
    cell = Cell(ControllerSpec("observer-pid", "observer-pid"), sc, 1)
    figure = run_cell(cell, tmp_path / "a", False, True)
    n_recorded = len(calls)
    other = run_cell(cell, tmp_path / "b", False, False)
    assert n_recorded == 300 and len(calls) == n_recorded          # the second run stepped no sample in Python
    assert (tmp_path / "a" / "series" / f"{cell.cell_id}.parquet").exists()
    assert not (tmp_path / "b" / "series").exists()
    strip = {k: v for k, v in figure.items() if k not in RUNTIME_COLUMNS}
    assert strip == {k: v for k, v in other.items() if k not in RUNTIME_COLUMNS}


def test_a_phase_controller_takes_the_compiled_loop_and_keeps_its_peaks(tmp_path, monkeypatch, phased):
    """Its per-phase peaks come from the x1 log of the compiled loop: the recorded run's values."""
    sc = builtin_scenarios()["stribeck"].with_durations(DURATION, WARMUP)
    cell = Cell(ControllerSpec(phased.name, phased.name), sc, 1)
    recorded = run_cell(cell, tmp_path / "a", False, True)
    calls = _counting_steps(monkeypatch, phased)
    row = run_cell(cell, tmp_path / "b", False, False)
    assert len(calls) == 0 and row["status"] == "ok" and row["peak_error_near_rad"] > 0
    assert not (tmp_path / "b" / "series").exists()
    strip = lambda r: {k: v for k, v in r.items() if k not in RUNTIME_COLUMNS}   # noqa: E731
    assert strip(row) == {k: v for k, v in strip(recorded).items() if k != "peak_error_none_rad"} | \
        {"peak_error_none_rad": row["peak_error_none_rad"]}
    assert math.isnan(row["peak_error_none_rad"]) and math.isnan(recorded["peak_error_none_rad"])


@pytest.mark.parametrize("scenario, tiny", [("thesis", ""), ("stribeck", "events"), ("lugre", ""),
                                            ("compliant", "events"), ("delayed", "scratch"), ("quantized", ""),
                                            ("disturbed", "events")])
def test_the_x1_log_is_the_recorded_samples_and_events(scenario, tiny, monkeypatch):
    """t and x1 of every sample and plant event, compiled, equal the recorded run's exactly; with
    tiny buffers the log grows, and where an interval has two events the kernel's one-row event
    scratch overflows and the sample is redone."""
    import bench.runner as runner
    from plant.law_driver import X1Log

    made = []

    class _Tiny(X1Log):
        def __init__(self, n):
            super().__init__(n)
            self.events, self.scratch = np.empty((2, 2)), np.empty((1, self.scratch.shape[1]))
            made.append(self)

    if tiny:
        monkeypatch.setattr(runner, "X1Log", _Tiny)
    sc = builtin_scenarios()[scenario]
    kw = dict(duration_s=DURATION, warmup_s=WARMUP, seed=3, family=sc.family, model=sc.model)
    rec = runner.run_closed_loop(sc.params, _Phased(), record=True, **kw)
    c = _Phased()
    calls = []
    step = c.step
    c.step = lambda y: calls.append(1) or step(y)
    log = runner.run_closed_loop(sc.params, c, x1_log=True, **kw)
    assert calls == [] and log.status == rec.status == "ok"
    assert rec.events["t"].size > 10                                   # the plant had events to log
    for part in ("samples", "events"):
        a, b = getattr(rec, part), getattr(log, part)
        assert set(b) == {"t", "x1"}
        np.testing.assert_array_equal(b["t"], a["t"])
        np.testing.assert_array_equal(b["x1"], a["x1"])
    assert {k: v for k, v in log.metrics.items() if k not in RUNTIME_COLUMNS} == \
        {k: v for k, v in rec.metrics.items() if k not in RUNTIME_COLUMNS}
    if tiny:                                                           # the growth paths were taken
        assert made[0].events.shape[0] > 2 and (made[0].scratch.shape[0] > 1) == (tiny == "scratch")


def test_a_family_loop_without_the_log_leaves_the_run_to_python(monkeypatch):
    """A family whose compiled loop cannot keep the x1 log (``compiled_loop_logs`` False, e.g. a
    plugin family's): the run steps every sample from Python and logs the same points."""
    from bench.runner import run_closed_loop
    from plant.protocol import get_family

    sc = builtin_scenarios()["thesis"]
    monkeypatch.setattr(get_family(sc.family), "compiled_loop_logs", False)
    kw = dict(duration_s=DURATION, warmup_s=WARMUP, seed=4, family=sc.family, model=sc.model)
    rec = run_closed_loop(sc.params, _Phased(), record=True, **kw)
    calls = _counting_steps(monkeypatch, _Phased)
    log = run_closed_loop(sc.params, _Phased(), x1_log=True, **kw)
    assert len(calls) == 300 and log.status == "ok"
    for part in ("samples", "events"):
        for key in ("t", "x1"):
            np.testing.assert_array_equal(getattr(log, part)[key], getattr(rec, part)[key])
