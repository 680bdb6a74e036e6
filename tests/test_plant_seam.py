"""The plant seam: truth and model, per-seed mismatch, and the TOML that describes them.

* A controller is told the model, never the truth; the plant runs with the truth (checked by the
  breakaway instant of a held torque, whose closed form t_b = −τ3·ln(1 − ks/u) depends on the
  true stiction only).
* Mismatch factors are lognormal with mean 1 and the stated relative sd, drawn from the seed
  alone: the same for every controller and executor, reproducible by hand.
* A malformed ``plant``, ``model`` or ``mismatch`` is exit 2 naming the file, line and key.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from bench.cells import Cell, ControllerSpec, run_cell
from bench.matrix import MatrixError, load_matrix
from bench.scenarios import mismatch_factors
from controllers.base import _REGISTRY, Controller, register
from plant import DriveCommand, DriveType, PlantParams
from plant.state import EventKind
from tests.cli_helpers import cli

_SEEN: list[PlantParams] = []


class _Spy(Controller):
    """Holds a linear-amplifier torque of 2.5 ozf·in and remembers what ``reset`` was told."""

    drive = DriveType.LINEAR
    description = "test spy"

    def reset(self, params, rng):
        _SEEN.append(params)

    def step(self, y):
        return DriveCommand.hold(2.5, DriveType.LINEAR)


_SPY_MATRIX = """
[matrix]
controllers = ["seam-spy"]
scenarios = ["told-wrong"]
seeds = [0]
duration_s = 0.05
warmup_s = 0

[scenarios.told-wrong]
base = "quiet-friction"
stiction = 2.4                 # the truth breaks away under 2.5 ozf·in ...
correlated_friction_std = 0.0
[scenarios.told-wrong.model]
stiction = 2.8                 # ... the model says it never would
"""


@pytest.fixture
def spy_registered():
    register("seam-spy")(_Spy)
    yield
    _REGISTRY.pop("seam-spy")


def test_the_controller_is_told_the_model_and_the_plant_runs_the_truth(tmp_path, spy_registered):
    (tmp_path / "m.toml").write_text(_SPY_MATRIX)
    matrix = load_matrix(tmp_path / "m.toml", check_resets=False)
    scenario = matrix.scenarios[0]
    assert scenario.params.stiction == 2.4 and scenario.model_params().stiction == 2.8
    from bench.runner import run_closed_loop
    _SEEN.clear()
    truth, factors = scenario.realise(0)
    result = run_closed_loop(truth, _Spy(), family=scenario.family, model=scenario.model_params(),
                             duration_s=0.05, seed=0, noise=False, record=True)
    assert _SEEN == [scenario.model_params()] and _SEEN[0] != truth and factors == {}
    p = truth
    t_b = -p.motor_time_constant * math.log(1.0 - p.stiction / 2.5)          # the truth's breakaway
    brk = result.events["t"][result.events["kind"] == int(EventKind.BREAKAWAY)]
    assert brk.size >= 1 and brk[0] == pytest.approx(t_b, abs=1e-12)
    assert np.all(result.samples["ks_true"] == 2.4)
    # through a matrix cell too: the row says the model was not exact
    _SEEN.clear()
    row = run_cell(Cell(ControllerSpec("seam-spy", "seam-spy"), scenario, 0), tmp_path / "out", traces=False)
    assert row["status"] == "ok" and _SEEN == [scenario.model_params()]
    assert row["plant_family"] == "multimode" and row["model_exact"] is False


def test_the_default_scenario_keeps_its_definition():
    """Acker's plant told exactly: no new keys in the cell definition (hashes as before)."""
    matrix = load_matrix(_builtin("quick.toml"), check_resets=False)
    for cell in matrix.cells()[:3]:
        assert set(cell.definition()["scenario"]) == {"name", "base", "plant"}


def _builtin(name):
    from importlib import resources
    return str(resources.files("bench").joinpath("matrices", name))


def test_mismatch_factors_are_lognormal_with_the_stated_spread():
    """Monte-Carlo over 4000 seeds: mean 1 and sd s of each factor within 4 standard errors,
    and the factors of one seed are the independent formula exp(σz − σ²/2), σ² = ln(1 + s²)."""
    spec = (("coulomb", 0.2), ("inertia", 0.1))
    f = np.array([[mismatch_factors(seed, spec)[k] for k, _ in spec] for seed in range(4000)])
    for j, (_, s) in enumerate(spec):
        assert abs(f[:, j].mean() - 1.0) < 4 * s / math.sqrt(len(f))
        assert abs(f[:, j].std() - s) < 4 * s / math.sqrt(2 * len(f)) * 1.5   # sd of a lognormal's sd, loosely
        assert np.all(f[:, j] > 0)
    z = np.random.default_rng(np.random.SeedSequence(7).spawn(5)[4]).standard_normal(2)
    for (k, s), zi in zip(spec, z):
        var = math.log(1 + s * s)
        assert mismatch_factors(7, spec)[k] == math.exp(math.sqrt(var) * zi - var / 2)


_MISMATCH_MATRIX = """
[matrix]
controllers = ["linear", "dithered"]
scenarios = ["off"]
seeds = [0, 1, 2]
duration_s = 0.3
warmup_s = 0.1

[scenarios.off]
base = "thesis"
[scenarios.off.mismatch]
coulomb = 0.2
stiction = 0.2
inertia = 0.2
motor_time_constant = 0.2
"""


@pytest.mark.slow
def test_mismatch_is_paired_across_controllers_and_executors(tmp_path):
    (tmp_path / "m.toml").write_text(_MISMATCH_MATRIX)
    frames = []
    for executor in ("local", "dask"):
        proc = cli("run", "--matrix", tmp_path / "m.toml", "--out", tmp_path / executor, "--no-traces",
                   "--executor", executor, "--workers", "1")
        assert proc.returncode == 0, proc.stderr
        frames.append(pd.read_csv(tmp_path / executor / "results.csv").set_index("cell").sort_index())
    local, dask = frames
    cols = [c for c in local.columns if c.startswith("mismatch_")]
    assert sorted(cols) == ["mismatch_coulomb", "mismatch_inertia", "mismatch_motor_time_constant",
                            "mismatch_stiction"]
    pd.testing.assert_frame_equal(local[cols], dask[cols])
    for seed in (0, 1, 2):
        a, b = local.loc[f"linear__off__s{seed}", cols], local.loc[f"dithered__off__s{seed}", cols]
        assert (a == b).all()
        want = mismatch_factors(seed, (("coulomb", 0.2), ("inertia", 0.2), ("motor_time_constant", 0.2),
                                       ("stiction", 0.2)))
        assert all(a[f"mismatch_{k}"] == v for k, v in want.items())
    assert local["mismatch_coulomb"].nunique() == 3
    assert (local["model_exact"] == False).all()  # noqa: E712
    html = (tmp_path / "local" / "report.html").read_text(encoding="utf-8")   # shown in the report
    assert 'id="plants"' in html and "coulomb ±20 %" in html
    for seed in (0, 1, 2):
        assert f"{local.loc[f'linear__off__s{seed}', 'mismatch_coulomb']:.4f}" in html


@pytest.mark.parametrize("body, key, line", [
    ('plant = "lugre-typo"', "scenarios.x.plant", 8),
    ("bristle = 1.0", "scenarios.x.bristle", 8),
    ("[scenarios.x.model]\ncoulomb = -1.0", "scenarios.x.model.coulomb", 9),
    ("[scenarios.x.model]\nviscous = 1.0", "scenarios.x.model.viscous", 9),
    ("[scenarios.x.mismatch]\ncoulomb = -0.2", "scenarios.x.mismatch.coulomb", 9),
    ("[scenarios.x.mismatch]\nfriction = 0.2", "scenarios.x.mismatch.friction", 9),
    ("[scenarios.x.mismatch]\ncoulomb = \"lots\"", "scenarios.x.mismatch.coulomb", 9),
    ("model = 3", "scenarios.x.model", 8),
])
def test_malformed_plant_model_or_mismatch_names_file_line_and_key(tmp_path, body, key, line):
    text = f"""[matrix]
controllers = ["linear"]
scenarios = ["x"]
seeds = [0]

[scenarios.x]
base = "thesis"
{body}
"""
    path = tmp_path / "m.toml"
    path.write_text(text)
    with pytest.raises(MatrixError) as info:
        load_matrix(path, check_resets=False)
    assert str(info.value).startswith(f"{path}:{line}: {key}: "), str(info.value)


@pytest.mark.slow
def test_malformed_mismatch_is_exit_2_through_the_cli(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(_MISMATCH_MATRIX.replace("inertia = 0.2", "inertia = 9.0"))
    proc = cli("run", "--matrix", path, "--out", tmp_path / "out")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}:14: scenarios.off.mismatch.inertia:" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out").exists()


class _RunsAway(Controller):
    """Its 'estimate' halves every step; below 1e-3 it is out of range (a synthetic diverger)."""

    drive = DriveType.LINEAR

    def reset(self, params, rng):
        self.estimate = 1.0

    def step(self, y):
        from controllers.base import EstimateOutOfRange
        self.estimate *= 0.5
        if self.estimate < 1e-3:
            raise EstimateOutOfRange(f"estimate {self.estimate:.3g} below its range [1e-3, 1]")
        return DriveCommand.hold(0.0, DriveType.LINEAR)


def test_a_controller_whose_estimate_leaves_its_range_ends_diverged_with_the_reason():
    from bench.runner import run_closed_loop
    r = run_closed_loop(PlantParams(), _RunsAway(), duration_s=1.0, seed=0)
    assert r.status == "diverged"
    assert r.message == "controller diverged: estimate 0.000977 below its range [1e-3, 1]"
    assert math.isnan(r.metrics["peak_error_rad"])
    assert r.simulated_s == pytest.approx(9 * 0.01)     # stopped at the 10th step
