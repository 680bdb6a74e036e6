"""``speed --quick --json`` end to end, and the equal-accuracy arithmetic on closed-form curves."""

import json
import math

import pytest
import typer
from typer.testing import CliRunner

from bench.speed import SpeedConfig, speed_command
from bench.speed.accuracy import _fixed_step_at, _lower_bound, _tolerance_at
from reports.inputs import normalise_speed

pytestmark = pytest.mark.slow


def _speed_app() -> typer.Typer:
    """The lead's CLI if it registers ``speed``, otherwise a one-command app around speed_command."""
    try:
        from reports.cli import app
    except ImportError:
        app = None
    if app is not None and any(c.name == "speed" for c in app.registered_commands):
        return app
    app = typer.Typer()
    app.command("speed")(speed_command)

    @app.callback()
    def _main() -> None:
        """Keep ``speed`` a sub-command."""

    return app


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("speed")
    result = CliRunner().invoke(_speed_app(), ["speed", "--quick", "--json", "--out", str(out)])
    assert result.exit_code == 0, result.output
    return json.loads(result.stdout), json.loads((out / "speed.json").read_text())


def test_json_has_the_keys_the_report_reads(quick):
    data, written = quick
    assert written == data
    for key in ("rows", "speedup_vs_fixed_step_at_1e-6", "speedup_vs_solve_ivp_at_1e-6",
                "speedup_vs_fixed_step_python_at_1e-6", "error_metric", "reference", "technology",
                "reference_disagreement", "equal_accuracy", "sequence", "noisy"):
        assert key in data
    assert "numba" in data["technology"]["caveat"] and "FORTRAN" in data["technology"]["caveat"]
    normalised = normalise_speed(data)                   # the report's own validation
    methods = {r["method"] for r in normalised["rows"]}
    assert {"multimode", "fixed_step", "solve_ivp", "solve_ivp_reference", "fixed_step_python"} <= methods
    for r in data["rows"]:
        assert r["realtime_factor"] == pytest.approx(data["sequence"]["duration_s"] / r["wall_s"])
    for k in ("speedup_vs_fixed_step_at_1e-6", "speedup_vs_solve_ivp_at_1e-6"):
        assert data[k] is not None and math.isfinite(data[k]) and data[k] > 0


def test_exact_simulator_agrees_with_solve_ivp_at_rtol_1e_13(quick):
    data, _ = quick
    check = data["reference_disagreement"]
    assert check["solve_ivp_rtol"] == 1e-13
    assert check["error_x1"] < 1e-8 and check["error_dc"] < 1e-8
    assert data["sequence"]["n_moving_pulses"] > 10


def test_fixed_step_error_falls_as_the_step_shrinks(quick):
    data, _ = quick
    rows = sorted((r for r in data["rows"] if r["method"] == "fixed_step"), key=lambda r: -r["step_s"])
    assert len(rows) >= 3
    for coarse, fine in zip(rows, rows[1:]):
        assert fine["error_dc"] < coarse["error_dc"] and fine["error_x1"] < coarse["error_x1"]
    # Euler is first order: a decade of step buys about a decade of error at the fine end.
    order = math.log10(rows[-2]["error_dc"] / rows[-1]["error_dc"])
    assert 0.5 < order < 1.5


def test_solve_ivp_error_falls_with_the_tolerance(quick):
    data, _ = quick
    rows = [r for r in data["rows"] if r["method"] == "solve_ivp"]
    assert rows[-1]["error"] < 1e-3 * rows[0]["error"]


def test_uncompiled_fixed_step_is_the_same_arithmetic(quick):
    data, _ = quick
    python = next(r for r in data["rows"] if r["method"] == "fixed_step_python")
    numba = next(r for r in data["rows"] if r["method"] == "fixed_step" and r["step_s"] == python["step_s"])
    assert python["jit_disabled"] is True
    assert python["error_dc"] == pytest.approx(numba["error_dc"], rel=1e-6)


def _power_law_rows(steps, c, order, ns_per_step, T=10.0):
    return [{"step_s": h, "error": c * h ** order, "wall_s": ns_per_step * 1e-9 * T / h} for h in steps]


def test_fixed_step_extrapolation_is_exact_on_a_power_law():
    rows = _power_law_rows([1e-4, 1e-5, 1e-6], c=1e2, order=1.0, ns_per_step=10.0)   # error 1e-2 … 1e-4
    need = _fixed_step_at(rows, 1e-6)
    assert need["how"] == "extrapolated"
    assert need["step_s"] == pytest.approx(1e-8, rel=1e-9)
    assert need["wall_s"] == pytest.approx(10e-9 * 10.0 / 1e-8, rel=1e-9)


def test_fixed_step_interpolation_is_exact_on_a_power_law():
    rows = _power_law_rows([1e-4, 1e-5, 1e-6, 1e-7], c=1e6, order=2.0, ns_per_step=5.0)  # 1e-2 … 1e-8
    need = _fixed_step_at(rows, 1e-6)
    assert need["how"] == "interpolated"
    assert need["step_s"] == pytest.approx(1e-6, rel=1e-9)


def test_tolerance_interpolation_in_log_log():
    rows = [{"rtol": 1e-3, "error": 1e-4, "wall_s": 1.0}, {"rtol": 1e-7, "error": 1e-8, "wall_s": 16.0}]
    need = _tolerance_at(rows, 1e-6)
    assert need["how"] == "interpolated"
    assert need["wall_s"] == pytest.approx(4.0) and need["rtol"] == pytest.approx(1e-5)


def test_no_convergence_gives_no_speedup():
    rows = [{"step_s": 1e-4, "error": 1e-2, "wall_s": 1.0}, {"step_s": 1e-5, "error": 1e-2, "wall_s": 10.0}]
    assert _fixed_step_at(rows, 1e-6)["wall_s"] is None


@pytest.mark.parametrize("kwargs, field", [
    ({"record_s": 10.0, "window_s": 20.0}, "window_s"),
    ({"record_s": 10.0, "window_s": 5.0, "fixed_steps": (1e-2,)}, "fixed_steps"),
    ({"record_s": 10.0, "window_s": 5.0, "rtols": (0.0,)}, "rtols"),
    ({"record_s": 10.0, "window_s": 5.0, "exact_processes": 0}, "exact_processes"),
    ({"record_s": 10.0, "window_s": 5.0, "probe_pulses": -1}, "probe_pulses"),
])
def test_config_validation_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"SpeedConfig.{field}"):
        SpeedConfig(**kwargs)


def test_probe_goes_below_the_finest_full_step_and_bounds_the_speedup(quick):
    data, _ = quick
    full = min((r for r in data["rows"] if r["method"] == "fixed_step"), key=lambda r: r["step_s"])
    probe = data["fixed_step_probe"]["rows"]
    assert probe and probe[-1]["step_s"] < full["step_s"]
    assert probe[-1]["error_dc"] < full["error_dc"]
    bound = data["speedup_vs_fixed_step_at_1e-6_lower_bound"]
    assert bound is not None and 0 < bound < math.inf


def test_lower_bound_uses_the_finest_missing_step():
    rows = [{"step_s": 1e-5, "error": 1e-3, "error_dc": 1e-3, "wall_s": 1.0, "n_steps": 1_000_000},
            {"step_s": 1e-6, "error": 1e-4, "error_dc": 1e-4, "wall_s": 10.0, "n_steps": 10_000_000}]
    probe = {"n_pulses": 3, "rows": [{"step_s": 1e-7, "error_dc": 2e-6}, {"step_s": 1e-8, "error_dc": 5e-7}]}
    bound = _lower_bound(rows, probe, exact_wall=0.5, T=10.0)
    assert bound["step_s"] == 1e-7                       # 1e-8 already meets 1e-6
    assert bound["wall_s"] == pytest.approx(1e-6 * 10.0 / 1e-7)   # 1 µs per step × 1e8 steps
    assert bound["speedup"] == pytest.approx(bound["wall_s"] / 0.5)
