"""Sweeps as data, the frontier matrix, and the report's frontier section (issue 14)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.driver import run_config
from bench.frontier import frontier_matrix_data, frontier_matrix_path, thin, to_toml
from bench.matrix import MatrixError, load_matrix, parse_matrix
from reports.stats import crossing_ci, crossing_level
from controllers.base import available_controllers

ROOT = Path(__file__).resolve().parent.parent

SWEEP = """\
[matrix]
controllers = ["linear", "oracle-pulse"]
scenarios = ["thesis", "quiet-friction"]
seeds = [0, 1]
duration_s = 1.5
warmup_s = 0.5

[sweep.linear]
include_default = true
crossover = [24.0, 48.0]
lag_ratio = [3.0, 6.0]

[sweep.oracle-pulse]
band = [1e-6, 4e-6]

[sweep.scenario]
base = "thesis"
combine = "separate"
friction_noise_psd = [0.0, 8e-4]
measurement_noise_std = [2e-5]
"""


def write(tmp_path, text, name="m.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_sweep_points_are_ordinary_cells_with_options_as_overrides(tmp_path):
    m = load_matrix(write(tmp_path, SWEEP))
    names = [c.name for c in m.controllers]
    assert names == ["linear", "linear[crossover=24,lag_ratio=3]", "linear[crossover=24,lag_ratio=6]",
                     "linear[crossover=48,lag_ratio=3]", "linear[crossover=48,lag_ratio=6]",
                     "oracle-pulse[band=1e-06]", "oracle-pulse[band=4e-06]"]
    spec = m.controllers[2]
    assert (spec.base, spec.options) == ("linear", {"crossover": 24.0, "lag_ratio": 6.0})
    assert m.controllers[5].build().options.band == 1e-6          # v2: resolved, typed options
    # σ2 = 0 is quiet-friction already in the matrix: not run twice, recorded as the same point
    assert [s.name for s in m.scenarios] == ["thesis", "quiet-friction", "thesis[friction_noise_psd=0.0008]",
                                             "thesis[measurement_noise_std=2e-05]"]
    assert m.sweep["scenarios"]["thesis[friction_noise_psd=0]"]["same_as"] == "quiet-friction"
    s = {x.name: x for x in m.scenarios}
    assert s["thesis[friction_noise_psd=0.0008]"].params.friction_noise_psd == 8e-4
    assert s["thesis[friction_noise_psd=0.0008]"].params.measurement_noise_std == 5e-6
    assert len(m.cells()) == 7 * 4 * 2
    assert run_config(m, False)["matrix"]["sweep"] == m.sweep


@pytest.mark.parametrize("body, line, key, message", [
    ('[sweep.linear]\ncrossover = [24.0, "fast"]\n', 7, "sweep.linear.crossover", "crossover"),
    ('[sweep.oracle-pulse]\nband = [1e-6, "x"]\n', 7, "sweep.oracle-pulse.band", "must be a number"),
    ('[sweep.oracle-pulse]\nbandwidth = [1.0]\n', 7, "sweep.oracle-pulse.bandwidth", "unknown option"),
    ('[sweep.linear]\ncrossover = 24.0\n', 7, "sweep.linear.crossover", "non-empty list"),
    ('[sweep.linear]\ncrossover = [1.0, 1.0]\n', 7, "sweep.linear.crossover", "more than once"),
    ('[sweep.solnic]\na_c = [1e-5]\n', 6, "sweep.solnic", "not in matrix.controllers"),
    ('[sweep.linear]\ncrossover = [1.0]\nlag_ratio = [2.0]\nintegral = [false]\n', 6, "sweep.linear", "at most 2"),
    ('[sweep.scenario]\n# noise\ninertial = [1.0]\n', 8, "sweep.scenario.inertial", "unknown key"),
    ('[sweep.scenario]\ninertia = [-1.0]\n', 7, "sweep.scenario.inertia", "must be > 0"),
    ('[sweep.scenario]\ncombine = "zip"\ninertia = [1.0]\n', 7, "sweep.scenario.combine", "product"),
])
def test_malformed_sweeps_name_file_line_and_key(tmp_path, body, line, key, message):
    head = '[matrix]\ncontrollers = ["linear", "oracle-pulse"]\nscenarios = ["thesis"]\nseeds = [0]\n\n'
    path = write(tmp_path, head + body)
    with pytest.raises(MatrixError, match=message) as info:
        load_matrix(path)
    assert str(info.value).startswith(f"{path}:{line}: {key}:")


def test_malformed_sweep_is_exit_2_one_line(tmp_path):
    path = write(tmp_path, '[matrix]\ncontrollers = ["oracle-pulse"]\nscenarios = ["thesis"]\nseeds = [0]\n'
                           '[sweep.oracle-pulse]\nband = [-1e-6]\n')
    proc = subprocess.run([sys.executable, "-m", "reports.cli", "run", "--matrix", path, "--out", tmp_path / "o"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}:6: sweep.oracle-pulse.band:" in lines[0] and "Traceback" not in proc.stderr
    assert not (tmp_path / "o" / "results.parquet").exists()


@pytest.mark.parametrize("quick", [False, True])
def test_frontier_matrix_covers_every_registered_controller_with_shared_seeds(quick):
    data = frontier_matrix_data(quick)
    assert tomllib.loads(to_toml(data)) == data                    # what is written is what runs
    m = parse_matrix(data, str(frontier_matrix_path(quick)))
    assert len(m.seeds) >= 20
    registered = available_controllers()
    parents = {p["parent"] for p in m.sweep["controllers"].values()} | {c.name for c in m.controllers}
    assert set(registered) <= parents
    for name, cls in registered.items():
        if cls.knobs:                                              # the class's knobs replace the file's
            field = next(iter(cls.knobs))
            values = [p["knobs"][field] for p in m.sweep["controllers"].values()
                      if p["parent"] == name and p["knobs"]]
            expected = thin(cls.knobs[field]) if quick else list(cls.knobs[field])
            assert sorted(set(values)) == sorted(float(v) for v in expected)
    names = {s.name for s in m.scenarios}
    assert {"thesis", "quiet-friction"} <= names
    levels = {p["params"].get("friction_noise_psd") for p in m.sweep["scenarios"].values()}
    assert max(v for v in levels if v is not None) == pytest.approx(2 * 4e-4)
    if not quick:                                                  # σ1 from 1 to 20 µrad
        sigma1 = {p["params"].get("measurement_noise_std") for p in m.sweep["scenarios"].values()} - {None}
        assert min(sigma1) == pytest.approx(1e-6) and max(sigma1) == pytest.approx(2e-5)


def test_crossing_level_interpolates_and_flags_out_of_range():
    assert crossing_level([0, 1, 2], [1.0, 3.0, 5.0], 4.0) == pytest.approx(1.5)
    assert crossing_level([0, 1], [5.0, 6.0], 4.0) == -math.inf
    assert crossing_level([0, 1], [1.0, 2.0], 4.0) == math.inf
    # peaks = slope·level + noise, same seeds at every level: crossing = threshold/slope
    rng = np.random.default_rng(0)
    levels = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    values = 2.0 * levels[None, :] + rng.normal(0, 0.05, (40, 1))
    point, lo, hi = crossing_ci(levels, values, 5.0)
    assert lo <= point <= hi and lo <= 2.5 <= hi and hi - lo < 0.2


def _synthetic_frontier(tmp_path):
    """A frontier-shaped run dir with made-up numbers whose answers are known."""
    from bench.scenarios import builtin_scenarios
    text = SWEEP.replace("seeds = [0, 1]", f"seeds = {list(range(20))}")
    m = load_matrix(write(tmp_path, text.replace('"oracle-pulse"]', '"oracle-pulse", "solnic"]')
                          + '\n[sweep.solnic]\ninclude_default = true\na_c = [1e-6, 1e-5]\n\n[frontier]\n'
                            'crossing_family = "solnic"\n'))
    rng = np.random.default_rng(1)
    rows = []
    for cell in m.cells():
        p = cell.scenario.params
        name = cell.controller.name
        current = {"linear": 0.5, "oracle-pulse": 0.01, "solnic": 0.02}[cell.controller.base]
        # solnic's peak [µrad] = 4 + 10·σ2²/4e-4, so it reaches 7.09 µrad at σ2² = 1.236e-4
        peak = (4.0 + 10.0 * p.friction_noise_psd / 4e-4) if cell.controller.base == "solnic" else 50.0
        if cell.controller.base == "oracle-pulse":
            peak = 1.0
        peak *= 1e-6 * math.exp(rng.normal(0, 0.02))
        rows.append({"cell": cell.cell_id, "controller": name, "scenario": cell.scenario.name, "seed": cell.seed,
                     "status": "ok", "message": "", "peak_error_rad": peak, "rms_error_rad": peak / 3,
                     "p99_error_rad": peak / 1.5, "mean_abs_current": current * (1 + 0.01 * rng.normal()),
                     "rms_current": current * 2, "runtime_s": 0.1})
    out = tmp_path / "run"
    out.mkdir()
    pd.DataFrame(rows).to_parquet(out / "results.parquet", index=False)
    (out / "config.json").write_text(json.dumps(run_config(m, False)))
    (out / "meta.json").write_text(json.dumps({"synthetic": True}))
    return out


@pytest.fixture(scope="module")
def synthetic_run(tmp_path_factory):
    return _synthetic_frontier(tmp_path_factory.mktemp("frontier"))


def test_report_frontier_section_and_crossing_claim(synthetic_run):
    from reports import build_report_from_dir
    from reports.frontier import frontier_context
    run = synthetic_run
    results = pd.read_parquet(run / "results.parquet")
    config = json.loads((run / "config.json").read_text())
    ctx = frontier_context(results, config)
    assert [f["scenario"] for f in ctx["figures"]] == ["thesis", "quiet-friction"]
    crossing = {r["what"]: r for r in ctx["crossings"]}
    # linear in σ2² between the levels 0 and 4e-4: (7.0925 − 4)/10·4e-4
    limit = (2.1 - 1.4) / (2 * 0.5 * (math.pi / 0.01) ** 2)          # (k̄s−k̄c)/(2Jωb²), Table 2-1
    expected = (limit * 1e6 - 4.0) / 10.0 * 4e-4
    assert crossing["default"]["crossing"] == pytest.approx(expected, rel=0.05)
    assert crossing["default"]["low"] <= expected <= crossing["default"]["high"]
    assert crossing["best over its knob"]["crossing"] == pytest.approx(expected, rel=0.05)
    assert [c.verdict for c in ctx["claims"]] == ["not reproduced"] * 3    # crossing < Table 2-1's σ2²
    budget = ctx["tables"][0]["budget"]
    assert budget[-1]["best"]["controller"].startswith("solnic")        # 4 µrad beats linear's 50
    assert budget[0]["bound"]["controller"].startswith("oracle-pulse")
    html = build_report_from_dir(run).read_text()
    assert 'id="frontier"' in html and "fig-frontier-0" in html and "fig-noise-0" in html
    assert "sigma2_crossing" in html or "stops beating it" in html


def test_report_without_sweeps_has_no_frontier_section(tmp_path):
    from reports import build_report_from_dir
    from reports.synthetic import write_synthetic_run
    html = build_report_from_dir(write_synthetic_run(tmp_path / "plain")).read_text()
    assert 'id="frontier"' not in html


def test_frontier_report_renders_offline_in_a_browser(synthetic_run, tmp_path):
    from reports import build_report_from_dir
    from reports.browser import dump_dom, find_chromium, page_network_requests, plot_render_status
    chromium = find_chromium()
    if chromium is None:
        pytest.skip("Chromium not installed")
    report = build_report_from_dir(synthetic_run)
    netlog = tmp_path / "netlog.json"
    dom = dump_dom(report, netlog=netlog, chromium=chromium)
    status = plot_render_status(dom)
    frontier = {k: v for k, v in status.items() if "frontier" in k or "noise" in k}
    assert len(frontier) == 4 and all(frontier.values()), status
    assert page_network_requests(netlog) == []


def test_crossing_of_the_best_over_points_takes_the_minimum_per_level():
    levels = np.array([0.0, 1.0, 2.0])
    # point 0: 1, 3, 5; point 1: 2, 2.5, 6 → best 1, 2.5, 5 → crosses 4.0 at 1 + 1.5/2.5
    base = np.array([[1.0, 2.0], [3.0, 2.5], [5.0, 6.0]])
    values = np.repeat(base[None], 10, axis=0)
    point, lo, hi = crossing_ci(levels, values, 4.0)
    assert point == pytest.approx(1.6) and lo == hi == pytest.approx(1.6)


def test_frontier_command_runs_its_matrix_through_run(tmp_path, monkeypatch):
    """The `frontier` command end to end on a tiny stand-in of its matrix (the real one is
    minutes): the completed matrix is written, every point is an ordinary cell, a report is made."""
    from typer.testing import CliRunner

    import bench.frontier as F
    from reports.cli import app

    tiny = {"matrix": {"controllers": ["linear", "oracle-pulse"], "scenarios": ["thesis"], "seeds": [0, 1],
                       "duration_s": 1.0, "warmup_s": 0.5},
            "sweep": {"oracle-pulse": {"band": [2e-6, 8e-6]}}}
    monkeypatch.setattr(F, "frontier_matrix_data", lambda quick=False: tiny)
    out = tmp_path / "fr"
    result = CliRunner().invoke(app, ["frontier", "--quick", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert (out / "frontier-matrix.toml").is_file() and (out / "report.html").is_file()
    df = pd.read_parquet(out / "results.parquet")
    assert sorted(df["controller"].unique()) == ["linear", "oracle-pulse[band=2e-06]", "oracle-pulse[band=8e-06]"]
    assert (df["status"] == "ok").all() and len(df) == 6
    assert not (out / "traces").exists() or not any((out / "traces").iterdir())


def test_per_seed_values_stay_paired_when_a_controller_misses_a_seed():
    from reports.frontier import _per_seed
    df = pd.DataFrame([dict(controller=c, scenario="thesis", seed=s, status="ok", peak_error_rad=float(s + 1))
                       for c, seeds in (("a", (0, 1, 2)), ("b", (0, 2))) for s in seeds])
    a = _per_seed(df, "a", ["thesis"], "peak_error_rad")[:, 0]
    b = _per_seed(df, "b", ["thesis"], "peak_error_rad")[:, 0]
    assert a.tolist() == [1.0, 2.0, 3.0]
    assert b[0] == 1.0 and math.isnan(b[1]) and b[2] == 3.0


def test_budget_table_skips_points_that_failed_a_seed():
    """A point ok on 1 of 5 seeds (its surviving median 1 µrad) is never the pick within a budget;
    the point ok on every seed is."""
    from reports.frontier import budget_table

    cols = ["mean_abs_current", "peak_error_rad"]
    def point(name, cur, err, ok, cells=5, bound=False):
        row = {"scenario": "thesis", "controller": name, "bound": bound, "ok": ok, "cells": cells}
        for c, v in zip(cols, (cur, err)):
            row.update({f"{c}_median": v, f"{c}_low": v, f"{c}_high": v})
        return row
    points = pd.DataFrame([point("flaky", 0.01, 1e-6, ok=1), point("good", 0.01, 1e-5, ok=5),
                           point("costly", 0.05, 5e-6, ok=5)])
    rows = budget_table(points, "thesis", n_budgets=2)
    assert [r["best"]["controller"] for r in rows] == ["good", "costly"]


def test_a_completed_user_matrix_still_finds_its_plugins(tmp_path):
    """``frontier --matrix FILE`` writes the completed matrix into DIR; its plugins live next to
    FILE. Before: the completed file searched DIR, so re-running it (``run --matrix
    DIR/frontier-matrix.toml``, a resume, a dask worker) failed with ModuleNotFoundError."""
    name = f"frontier_plugin_{tmp_path.name.replace('-', '_')}"
    home, out = tmp_path / "axis", tmp_path / "out"
    home.mkdir(), out.mkdir()
    (home / f"{name}.py").write_text("from controllers.base import register\n"
                                     "from controllers.linear import LinearController\n\n"
                                     f"@register('{name.replace('_', '-')}')\n"
                                     "class Mine(LinearController):\n    pass\n")
    source = home / "m.toml"
    source.write_text(f'[matrix]\nplugins = ["{name}"]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\n'
                      'seeds = [0]\nduration_s = 1\nwarmup_s = 0.2\n')
    completed = out / "frontier-matrix.toml"
    completed.write_text(to_toml(frontier_matrix_data(True, source)))
    from controllers.base import _REGISTRY

    try:
        sys.modules.pop(name, None)                 # as a fresh process sees it
        _REGISTRY.pop(name.replace("_", "-"), None)
        sys.path[:] = [p for p in sys.path if p not in (str(home), str(home.resolve()))]
        parsed = load_matrix(completed, check_resets=False)
        assert parsed.plugin_dirs == (str(home.resolve()),)
        assert sys.modules[name].__file__ == str((home / f"{name}.py").resolve())
    finally:
        _REGISTRY.pop(name.replace("_", "-"), None)
        sys.modules.pop(name, None)


def test_plugin_dirs_name_a_missing_directory(tmp_path):
    (tmp_path / "m.toml").write_text('[matrix]\nplugins = ["x"]\nplugin_dirs = ["lib", "gone"]\n'
                                     'controllers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\n')
    (tmp_path / "lib").mkdir()
    with pytest.raises(MatrixError, match=r"m\.toml: matrix\.plugin_dirs\[1\]: 'gone': no such directory"):
        load_matrix(tmp_path / "m.toml", check_resets=False)
