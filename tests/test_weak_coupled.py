"""The coupled Euler–Maruyama ladder (plant.multimode.reference.coupled_step_pulses) and its
study (bench.weak_coupled) against independent truth: the uncoupled simulator's law, the
noise-free path, and the strong convergence of paired paths."""

import math

import numpy as np
import pytest

from bench.weak_coupled import CoupledConfig
from plant import PlantParams
from plant.multimode.reference import coupled_step_pulses, fixed_step_pulses

DT_U = 1.2e-3


def test_each_rung_has_the_law_of_the_uncoupled_simulator():
    # Each row alone must be EM at that step: its mean equals fixed_step_pulses' (independent
    # seeds) within 3.5 combined standard errors (a 1-in-2000 false alarm per comparison).
    p = PlantParams()
    n = 3000
    X = coupled_step_pulses(p, DT_U, 1e-5, (1, 4), n, seed=11)
    for row, h in zip(X, (1e-5, 4e-5)):
        ref = fixed_step_pulses(p, DT_U, h, n, seed=12)
        se = math.hypot(row.std(ddof=1), ref.std(ddof=1)) / math.sqrt(n)
        assert abs(row.mean() - ref.mean()) < 3.5 * se, (h, row.mean(), ref.mean(), se)
        assert row.std(ddof=1) == pytest.approx(ref.std(ddof=1), rel=0.1)


def test_noise_free_rungs_are_the_fixed_step_paths():
    # With every noise intensity zero the Brownian path plays no part: each rung must equal the
    # uncoupled simulator at its step exactly (same kernel, same grid).
    p = PlantParams().replace(friction_noise_psd=0.0, correlated_friction_std=0.0, command_velocity_std=0.0)
    X = coupled_step_pulses(p, DT_U, 1e-6, (1, 3, 10), 3, seed=1)
    for row, h in zip(X, (1e-6, 3e-6, 1e-5)):
        np.testing.assert_array_equal(row, fixed_step_pulses(p, DT_U, h, 3, seed=2))


def test_paired_difference_shrinks_to_zero_with_the_step():
    # Same Brownian path: the RMS difference to the finest rung falls as h -> dt_fine, and is far
    # below the √2·sd of two independent samples (the whole point of the coupling).
    p = PlantParams()
    X = coupled_step_pulses(p, DT_U, 1e-6, (1, 3, 10, 30), 1500, seed=5)
    rms = [float(np.sqrt(np.mean((X[i] - X[0]) ** 2))) for i in (1, 2, 3)]
    assert rms[0] < rms[1] < rms[2]
    assert rms[2] < 0.5 * math.sqrt(2) * X[0].std()
    assert rms[0] < 0.15 * X[0].std()


@pytest.mark.parametrize("field, value", [("dt_fine", 0.0), ("factors", (10, 3)), ("factors", (1,)),
                                          ("n_coupled", 10), ("tolerances", (1.5,))])
def test_config_rejects_bad_fields(field, value):
    with pytest.raises(ValueError, match=field):
        CoupledConfig(**{field: value})


def test_factors_must_be_integers():
    with pytest.raises(ValueError, match="factors"):
        coupled_step_pulses(PlantParams(), DT_U, 1e-6, (1, 2.5), 2, seed=0)


def test_tiny_study_is_consistent_and_reaches_the_report(tmp_path):
    # A tiny run of the whole study: the weak error at the coarsest step is the anchor itself,
    # the errors at finer steps are the anchor plus the coupled differences, and the report's
    # speed section shows the resolved table with one row per step.
    from bench.weak_coupled import coupled_weak_error
    from reports import build_report
    from reports.synthetic import synthetic_inputs

    cfg = CoupledConfig(dt_fine=1e-5, factors=(2, 4), n_coupled=200, n_anchor=200, n_boot=20, n_timing=20)
    r = coupled_weak_error(PlantParams(), cfg, seed=3)
    rows = r["rows"]
    assert [row["step_s"] for row in rows] == pytest.approx([2e-5, 4e-5])
    assert rows[-1]["mean_error_rad"] == pytest.approx(r["anchor_bias_rad"], abs=1e-18)
    for row in rows:
        lo, hi = row["mean_error_ci_rad"]
        assert lo <= row["mean_error_rad"] <= hi
        assert row["vs_fine_w1_raw_rad"] >= abs(row["vs_fine_mean_rad"]) - 1e-18    # W1 ≥ |Δ mean|
    data = synthetic_inputs(0)
    data["speed"] = {**data["speed"], "weak_error_coupled": r}
    html = build_report(tmp_path, **data).read_text(encoding="utf-8")
    assert 'id="coupled-table"' in html
    table = html[html.index('id="coupled-table"'):]
    table = table[:table.index("</table>")]
    assert table.count("<tr") == 1 + len(rows)                 # header and one row per step
    assert "h = 2e−05 s" in table and "h = 4e−05 s" in table

    from rich.console import Console

    from bench.speed.tables import _print_table

    console = Console(record=True, width=200)
    _print_table({"weak_error_coupled": r, "technology": {"caveat": "-"}, "error_definition": "-",
                  "elapsed_s": 1.0, "load_average_1min": 1.0}, console)
    text = console.export_text()
    assert text.count("EM h=") == len(rows)
    assert "tolerance 1.0% of the mean" in text and "tolerance 0.1% of the mean" in text


def test_corrected_w1_is_never_negative():
    """Two samples of one law: the true W1 is 0, the empirical one is positive noise, and the bias
    correction 2·Ŵ − mean(Ŵ*) can fall below 0; reported value and interval are clipped at 0."""
    from bench.weak_coupled import _w1_corrected

    rng = np.random.default_rng(5)
    seen_negative_raw = False
    for k in range(20):
        a, b = rng.normal(size=50), rng.normal(size=50)
        w, (lo, hi) = _w1_corrected(np.random.default_rng(k), a, b, 100)
        assert w >= 0.0 and 0.0 <= lo <= hi
        seen_negative_raw |= lo == 0.0
    assert seen_negative_raw      # the clip was exercised (the unclipped lower end went below 0)
