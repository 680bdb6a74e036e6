"""End to end through the real CLI in a subprocess: ``solnic-bench run --quick``, its traces
(read back with rerun's own reader), its report, the dask executor and the user errors."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.cells import RUNTIME_COLUMNS
from bench.matrix import builtin_matrix_path, load_matrix
from bench.traces import PLANT_ENTITIES, TIMELINE

ROOT = Path(__file__).resolve().parent.parent
REQUIRED_COLUMNS = ("controller", "scenario", "seed", "status", "peak_error_rad", "rms_error_rad",
                    "mean_abs_current", "rms_current", "runtime_s")

pytestmark = pytest.mark.slow


def cli(*args: str, timeout: float = 300, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "reports.cli", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, **kwargs)


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    out = tmp_path_factory.mktemp("quick") / "run"
    proc = cli("run", "--quick", "--out", out)
    assert proc.returncode == 0, proc.stderr
    return out, proc


def _entity_columns(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Entity path → (time [ns], value) from every chunk of the recording, via rerun's reader."""
    from rerun.chunk import RrdReader

    parts: dict[str, list] = {}
    for chunk in RrdReader(path).store().stream().to_chunks():
        if chunk.is_static:
            continue
        rb = chunk.to_record_batch()
        t = rb.column(rb.schema.get_field_index(TIMELINE)).cast("int64").to_numpy()
        v = np.array([x[0] for x in rb.column(rb.schema.get_field_index("Scalars:scalars")).to_pylist()])
        parts.setdefault(chunk.entity_path.lstrip("/"), []).append((t, v))
    out = {}
    for entity, chunks in parts.items():
        t = np.concatenate([c[0] for c in chunks])
        v = np.concatenate([c[1] for c in chunks])
        order = np.argsort(t, kind="stable")
        out[entity] = (t[order], v[order])
    return out


def test_quick_run_has_every_cell_ok(quick):
    out, proc = quick
    m = load_matrix(builtin_matrix_path(quick=True))
    expected = {(c.name, s.name, seed) for c in m.controllers for s in m.scenarios for seed in m.seeds}
    for name in ("results.parquet", "results.csv"):
        df = pd.read_parquet(out / name) if name.endswith("parquet") else pd.read_csv(out / name)
        assert set(REQUIRED_COLUMNS) <= set(df.columns)
        assert {(r.controller, r.scenario, int(r.seed)) for r in df.itertuples()} == expected
        assert len(df) == len(expected)
        assert (df["status"] == "ok").all(), df[["cell", "status", "message"]]
        assert np.isfinite(df["peak_error_rad"]).all() and (df["peak_error_rad"] > 0).all()
        assert df["config_hash"].str.fullmatch("[0-9a-f]{64}").all()
    assert "peak" in proc.stdout and "mean" in proc.stdout          # the aggregate table
    assert (out / "config.json").is_file() and (out / "meta.json").is_file()


def test_quick_run_traces_read_back_with_rerun(quick):
    from rerun.chunk import RrdReader

    out, _ = quick
    df = pd.read_parquet(out / "results.parquet")
    # the default policy, first-seed: one trace per controller x scenario, streamed while it ran
    first = df[df["seed"] == df["seed"].min()]
    assert sorted(p.stem for p in (out / "traces").glob("*.rrd")) == sorted(first["cell"])
    assert len(first) == df["controller"].nunique() * df["scenario"].nunique()
    for cell in first["cell"]:
        schema = RrdReader(out / "traces" / f"{cell}.rrd").store().schema()
        assert [c.name for c in schema.index_columns()] == [TIMELINE]
        paths = {p.lstrip("/") for p in schema.entity_paths()}
        assert set(PLANT_ENTITIES) | {"sensor/y"} <= paths
        assert any(p.startswith("controller/") for p in paths)

    row = first[(first["controller"] == "solnic") & (first["scenario"] == "thesis")].iloc[0]
    data = _entity_columns(out / "traces" / f"{row['cell']}.rrd")
    n_samples = int(round(row["duration_s"] / 0.01))
    t_y, _ = data["sensor/y"]
    assert np.array_equal(t_y, np.arange(n_samples) * 10_000_000)    # every sample, in seconds (ns)
    for entity in PLANT_ENTITIES:
        t, v = data[entity]
        assert np.all(np.diff(t) >= 0)                               # merged and time-sorted
        assert len(t) > n_samples and np.isin(t_y, t).all()           # samples and events
        assert np.isfinite(v).all()
    assert {"controller/ks_hat", "controller/kc_hat", "controller/cycle_size"} <= set(data)
    assert len(data["controller/ks_hat"][0]) == n_samples
    # the trace's |x1| never exceeds the run's exact continuous peak
    assert np.abs(data["plant/error"][1]).max() <= row["peak_error_rad"] * (1 + 1e-12)


def test_quick_run_writes_the_report_and_solnic_series(quick):
    out, proc = quick
    assert (out / "report.html").stat().st_size > 0
    assert "report:" in proc.stdout
    series = sorted(p.stem for p in (out / "series").glob("*.parquet"))
    df = pd.read_parquet(out / "results.parquet")
    from bench.series import wants_series
    from controllers.base import get_controller

    with_series = {c for c in set(df["controller_base"]) if wants_series(get_controller(c)())}
    assert "solnic" in with_series and "linear" not in with_series
    # the series the report reads: the identification controller itself on thesis, every seed; every
    # controller x scenario with a series on the lowest seed (bench.driver.reads_series)
    read = (df["seed"] == df["seed"].min()) | ((df["controller"] == "solnic") & (df["scenario"] == "thesis"))
    assert series == sorted(df.loc[df["controller_base"].isin(with_series) & read, "cell"])
    assert (df.loc[df["controller_base"].isin(with_series) & ~read, "controller_base"] == "observer-pid").any()
    from controllers.base import get_controller
    families = df["controller_base"].map(lambda b: get_controller(b).family)
    assert (df["controller_family"] == families).all()   # no variants in quick: the class's own family
    assert set(df.loc[df["controller_base"] == "solnic-modern", "controller_family"]) == {"solnic"}
    frame = pd.read_parquet(out / "series" / f"{df.loc[df['controller'] == 'solnic', 'cell'].iloc[0]}.parquet")
    assert {"t", "x1", "ks_hat_pct", "kc_hat_pct", "cost_small", "dc_ratio", "cycle_size"} <= set(frame.columns)


def test_dask_local_cluster_gives_the_same_rows_as_the_process_pool(quick, tmp_path):
    out, _ = quick
    m = load_matrix(builtin_matrix_path(quick=True))
    local = pd.read_parquet(out / "results.parquet")
    # a subset of the quick matrix with the same settings: the same cells, the same hashes
    (tmp_path / "sub.toml").write_text(
        "[matrix]\n"
        f"controllers = {[c.name for c in m.controllers]!r}\n"
        f"scenarios = [{m.scenarios[0].name!r}]\n"
        f"seeds = [{m.seeds[0]}]\n"
        f"duration_s = {m.scenarios[0].duration_s!r}\nwarmup_s = {m.scenarios[0].warmup_s!r}\n")
    proc = cli("run", "--matrix", tmp_path / "sub.toml", "--out", tmp_path / "dask", "--executor", "dask",
               "--workers", "2", "--no-traces")
    assert proc.returncode == 0, proc.stderr
    remote = pd.read_parquet(tmp_path / "dask" / "results.parquet")
    assert len(remote) == len(m.controllers)
    same = local.set_index("cell").loc[remote["cell"]].reset_index()
    keep = [c for c in remote.columns if c not in RUNTIME_COLUMNS]
    assert set(keep) <= set(same.columns)
    pd.testing.assert_frame_equal(remote[keep], same[keep], check_exact=True)
    for cell in remote.loc[remote["controller"] == "solnic", "cell"]:
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "dask" / "series" / f"{cell}.parquet"),
                                      pd.read_parquet(out / "series" / f"{cell}.parquet"), check_exact=True)


def _snapshot(directory: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(directory)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in directory.rglob("*") if p.is_file()}


# The user errors of the issue, each through the real CLI (more cases in-process: test_cli_errors.py).
USER_ERRORS = {
    # name: (matrix text or None, extra args, expected message fragments)
    "toml-syntax": ("[matrix]\ncontrollers = [\"linear\"]\nseeds = [0,, 1]\n", (),
                    ["bad.toml:3: invalid TOML", "line 3"]),
    "unknown-controller": ("[matrix]\ncontrollers = [\"linear\", \"nope\"]\nscenarios = [\"thesis\"]\nseeds = [0]\n",
                           (), ["bad.toml: matrix.controllers[1]: unknown controller 'nope'", "solnic"]),
    "unknown-scenario": ("[matrix]\ncontrollers = [\"linear\"]\nscenarios = [\"moon\"]\nseeds = [0]\n",
                         (), ["bad.toml: matrix.scenarios[0]: unknown scenario 'moon'", "ratio-2"]),
    "bad-plant-parameter": ("[matrix]\ncontrollers = [\"linear\"]\nscenarios = [\"heavy-load\"]\nseeds = [0]\n"
                            "[scenarios.heavy-load]\nbase = \"thesis\"\ninertia = -1.0\n", (),
                            ["bad.toml:7: scenarios.heavy-load.inertia: PlantParams.inertia must be > 0, got -1.0"]),
    "bad-controller-option": ("[matrix]\ncontrollers = [\"solnic-x\"]\nscenarios = [\"thesis\"]\nseeds = [0]\n"
                              "[controllers.solnic-x]\nbase = \"solnic\"\npreset = \"nope\"\n", (),
                              ["bad.toml: controllers.solnic-x.preset: unknown preset 'nope'"]),
    "bad-workers": (None, ("--quick", "--workers", "0"), ["--workers must be an integer >= 1, got 0"]),
}


def test_user_errors_exit_2_with_one_line_and_leave_results_untouched(quick, tmp_path):
    out, _ = quick
    before = _snapshot(out)
    procs = {}
    for name, (text, extra, _) in USER_ERRORS.items():
        args = list(extra)
        if text is not None:
            (tmp_path / name).mkdir()
            (tmp_path / name / "bad.toml").write_text(text)
            args = ["--matrix", "bad.toml", *args]
        procs[name] = subprocess.Popen([sys.executable, "-m", "reports.cli", "run", *args, "--out", str(out)],
                                       cwd=tmp_path / name if text is not None else ROOT, env=_env(),
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # an unwritable --out: below a regular file
    (tmp_path / "a-file").write_text("x")
    procs["unwritable-out"] = subprocess.Popen(
        [sys.executable, "-m", "reports.cli", "run", "--quick", "--out", str(tmp_path / "a-file" / "run")],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    expected = {**{k: v[2] for k, v in USER_ERRORS.items()},
                "unwritable-out": [f"--out {tmp_path / 'a-file' / 'run'}: cannot write"]}
    for name, proc in procs.items():
        stdout, stderr = proc.communicate(timeout=120)
        assert proc.returncode == 2, (name, stdout, stderr)
        assert "Traceback" not in stderr, (name, stderr)
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), (name, stderr)
        for fragment in expected[name]:
            assert fragment in lines[0], (name, fragment, lines[0])
    assert _snapshot(out) == before
    assert not (tmp_path / "a-file" / "run").exists()


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env
