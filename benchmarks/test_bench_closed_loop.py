"""A 100 s ``thesis`` cell per controller, and the ``--quick`` matrix.

Targets (issue #10): CPU per 100 s thesis cell on an idle 2-core machine — linear ≤ 0.1 s,
dithered ≤ 0.5 s, solnic ≤ 0.4 s; ratios against an older revision: benchmarks/compare_revision.py.
Slow bodies use ``benchmark.pedantic`` with few rounds so ``make benchmark`` stays bounded; under
``--benchmark-disable`` each body runs once.
"""


import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from plant.state import Status

THESIS = builtin_scenarios()["thesis"]


@pytest.mark.parametrize("controller", ["linear", "dithered", "solnic"])
def test_thesis_cell(benchmark, controller):
    def cell():
        return run_closed_loop(THESIS.params, make_controller(controller), duration_s=THESIS.duration_s,
                               warmup_s=THESIS.warmup_s, seed=0)

    result = benchmark.pedantic(cell, rounds=3, iterations=1, warmup_rounds=0)
    assert result.status == Status.OK, result.message
    assert result.simulated_s == pytest.approx(THESIS.duration_s)
    benchmark.extra_info["realtime_factor"] = result.metrics["realtime_factor"]
    benchmark.extra_info["peak_error_rad"] = result.metrics["peak_error_rad"]


def test_quick_matrix(benchmark, tmp_path):
    if benchmark.disabled:   # `make test`: tests/test_cli_run.py runs and checks the quick matrix already
        pytest.skip("a timing only (make benchmark); the quick run is tested in tests/test_cli_run.py")
    from typer.testing import CliRunner

    from reports.cli import app

    runner = CliRunner()
    counter = iter(range(1_000_000))

    def quick():
        out = tmp_path / f"quick-{next(counter)}"        # a fresh DIR: no resumed cells
        return runner.invoke(app, ["run", "--quick", "--no-traces", "--out", str(out)]), out

    result, out = benchmark.pedantic(quick, rounds=1, iterations=1, warmup_rounds=0)
    assert result.exit_code == 0, result.output
    assert (out / "results.csv").exists()
