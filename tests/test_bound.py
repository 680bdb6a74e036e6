"""The empirical check of (2-6) and (2-1): bound formula, aggregation, and check-bound end to end."""

import json
import math

import control as ct
import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from bench.bound import (BOUND_COLUMNS, BoundCell, SweepPlan, bound_verdict,
                         check_bound_command, hunting_onsets, run_bound_cell)
from bench.bound.run import _durations
from controllers.linear import design_linear
from plant import PlantParams


def test_classical_limit_is_7_09_microradians_for_table_2_1():
    # (2-6) at ωb = π/τs: (ks − kc)/(2·J·ωb²) with Table 2-1's ks = 2.1, kc = 1.4, J = 0.5, τs = 0.01
    omega_b = math.pi / 0.01
    expected = (2.1 - 1.4) / (2 * 0.5 * omega_b * omega_b)
    assert PlantParams().classical_bound() == pytest.approx(expected, rel=1e-14)
    assert round(PlantParams().classical_bound() * 1e6, 2) == 7.09          # the thesis's figure
    # at another crossover, with another plant: 0.7·1.4/(2·1.0·50²)
    assert PlantParams(inertia=1.0, stiction=2.38).classical_bound(50.0) == pytest.approx(
        (2.38 - 1.4) / (2 * 1.0 * 2500.0), rel=1e-14)


def _runs(rows):
    return pd.DataFrame([dict(ks_over_kc=1.5, lmax=6.0, omega_c=48.7, inertia=0.5, integral=False,
                              offset_factor=f, lag_ratio=lag, hunting=h) for lag, f, h in rows])


def test_hunting_onset_is_the_lowest_L_above_which_every_L_hunts():
    runs = _runs([(6, 0.8, False), (6, 1.7, False), (9, 0.8, True), (9, 1.7, False),
                  (12, 0.8, False), (12, 1.7, True), (18, 0.8, True), (18, 1.7, True)])
    row = hunting_onsets(runs).iloc[0]
    assert row["onset_L"] == 9 and row["onset_over_lmax"] == pytest.approx(1.5)
    assert row["highest_quiet_L"] == 6 and row["lowest_hunting_L"] == 9
    assert row["n_initial_errors"] == 2


def test_isolated_hunting_below_a_quiet_L_does_not_set_the_onset():
    runs = _runs([(6, 1.0, True), (9, 1.0, False), (12, 1.0, True), (18, 1.0, True)])
    row = hunting_onsets(runs).iloc[0]
    assert row["onset_L"] == 12 and row["lowest_hunting_L"] == 6 and row["highest_quiet_L"] == 9


def test_no_hunting_at_the_largest_L_gives_no_onset():
    row = hunting_onsets(_runs([(6, 1.0, True), (18, 1.0, False)])).iloc[0]
    assert math.isnan(row["onset_L"])


def _bound_rows():
    base = dict(omega_c=50.0, lag_ratio=6.0, ks_over_kc=1.5, inertia=0.5, theta_b_rad=1e-4,
                n_slips_window=3)
    rows = [("a", False, 3e-4, True, "ok"), ("b", True, 8e-5, True, "ok"),
            ("c", False, np.nan, False, "unstable"), ("d", False, 1e-6, True, "diverged")]
    return pd.DataFrame([{**base, "design": d, "noise": noise, "theta_rad": theta,
                          "ratio": theta / base["theta_b_rad"], "stable": stable, "status": status}
                         for d, noise, theta, stable, status in rows])


def test_verdict_reports_a_violation_with_its_design():
    v = bound_verdict(_bound_rows())
    assert v["holds"] is False and v["n_violations"] == 1
    assert v["min_ratio"] == pytest.approx(0.8) and v["min_ratio_design"]["design"] == "b"
    assert v["n_scored"] == 2 and v["n_unstable"] == 1 and v["n_failed"] == 1


def test_verdict_holds_when_every_scored_ratio_is_at_least_one():
    v = bound_verdict(_bound_rows().drop(index=1))
    assert v["holds"] is True and v["min_ratio"] == pytest.approx(3.0)


def test_a_run_longer_than_the_cap_is_skipped_not_truncated():
    cell = BoundCell(1.5, 0.5, 48.7, 1.0, False, False, cap_s=100.0, seed=0)
    warmup, duration, note = _durations(cell, static_stiffness=300.0)
    # first breakaway at ks/(S·v) = 2.1/(300·30e-6) = 233 s > cap
    assert duration == 0.0 and warmup > 2.1 / (300.0 * 30e-6) and "more than the cap" in note
    roomy = BoundCell(1.5, 0.5, 48.7, 1.0, False, False, cap_s=1e5, seed=0)
    warmup, duration, _ = _durations(roomy, static_stiffness=300.0)
    assert warmup > 2.1 / (300.0 * 30e-6) and duration - warmup > 2.1 / (300.0 * 30e-6)


def test_a_window_without_a_breakaway_is_not_scored():
    # L = 1 at 110.7 rad/s: first breakaway near ks/(S·v) (~54 s); with no window margins the
    # 10 s window after it holds no second breakaway (the cycle is tens of seconds long).
    cell = BoundCell(1.5, 1.0, 110.7, 1.0, False, False, cap_s=1e4, seed=0, warmup_ts=0.0,
                     window_ts=0.0, window_tf=0.0)
    row = run_bound_cell(cell)
    assert row["status"] == "unsteady" and row["n_slips_window"] == 0
    assert math.isnan(row["theta_rad"]) and math.isnan(row["ratio"])
    assert 0 < row["theta_window_rad"] < 1.4 * 1.5 / row["static_stiffness"]


@pytest.mark.parametrize("changes, match", [
    (dict(mode="huge"), "SweepPlan.mode"),
    (dict(plants=((1.0, 0.5),)), "ks_over_kc"),
    (dict(lag_absolute=(0.5,)), "lag_absolute"),
    (dict(crossovers=()), "crossovers"),
    (dict(cap_s=0.0), "cap_s"),
])
def test_plan_validation_names_the_field(changes, match):
    good = dict(mode="tiny", crossovers=(48.7,), lag_absolute=(), lag_multiples=(1.0,), integral=True,
                plants=((1.5, 0.5),), noise=(False,), cap_s=300.0, hunting_ratios=(1.5,),
                hunting_crossover=48.7, hunting_multiples=(1.0,), hunting_offsets=(1.0,))
    with pytest.raises(ValueError, match=match):
        SweepPlan(**{**good, **changes})


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    import typer

    out = tmp_path_factory.mktemp("check-bound")
    app = typer.Typer()
    app.command("check-bound")(check_bound_command)
    app.command("noop")(lambda: None)      # two commands, so the name is part of the command line
    result = CliRunner().invoke(app, ["check-bound", "--tiny", "--out", str(out), "--workers", "2"])
    return out, result


def test_check_bound_end_to_end_writes_the_tables(tiny_run):
    out, result = tiny_run
    assert result.exit_code == 0, result.output
    assert "verdict" in result.output
    bound = pd.read_csv(out / "bound.csv")
    assert list(bound.columns[:len(BOUND_COLUMNS)]) == list(BOUND_COLUMNS)
    hunting = pd.read_csv(out / "hunting.csv")
    assert {"ks_over_kc", "lmax", "onset_L"} <= set(hunting.columns)
    runs = pd.read_csv(out / "hunting_runs.csv")
    assert len(runs) >= 2 and runs["status"].eq("ok").all()
    verdict = json.loads((out / "bound_verdict.json").read_text())
    assert verdict["classical_limit_rad"] == pytest.approx(0.7 / (2 * 0.5 * (100 * math.pi) ** 2))
    assert verdict["n_scored"] == int((bound["stable"] & bound["status"].eq("ok")).sum()) > 0
    assert not list(out.glob("*.tmp"))


def test_bound_column_is_the_formula_at_each_design_crossover(tiny_run):
    bound = pd.read_csv(tiny_run[0] / "bound.csv")
    ks = 1.4 * bound["ks_over_kc"]
    expected = (ks - 1.4) / (2 * bound["inertia"] * bound["omega_c"] ** 2)      # (2-6)
    np.testing.assert_allclose(bound["theta_b_rad"], expected, rtol=1e-12)
    ok = bound[bound["status"] == "ok"]
    np.testing.assert_allclose(ok["ratio"], ok["theta_rad"] / ok["theta_b_rad"], rtol=1e-12)


def test_hunting_table_compares_with_the_lag_limit(tiny_run):
    hunting = pd.read_csv(tiny_run[0] / "hunting.csv")
    r = hunting["ks_over_kc"]
    np.testing.assert_allclose(hunting["lmax"], 2 * r / (r - 1), rtol=1e-12)   # (2-1)
    runs = pd.read_csv(tiny_run[0] / "hunting_runs.csv")
    np.testing.assert_allclose(sorted(runs["lag_ratio"] / runs["lmax"]), [1.0, 3.0], rtol=1e-12)


def test_noise_free_lag_loop_peaks_at_stiction_over_static_stiffness(tiny_run):
    # (2-2): a stuck type-0 loop on a slow ramp breaks away when its static stiffness times the
    # error reaches ks, so the peak of each stick-slip cycle is ks/S.S. (S.S. = |C(z=1)|).
    bound = pd.read_csv(tiny_run[0] / "bound.csv")
    row = bound[(bound["lag_ratio"] < np.inf) & ~bound["noise"] & (bound["status"] == "ok")].iloc[0]
    ks = 1.4 * row["ks_over_kc"]
    params = PlantParams(inertia=row["inertia"], stiction=ks)
    stiffness = abs(ct.dcgain(design_linear(params, row["omega_c"], row["lag_ratio"]).compensator))
    assert row["theta_rad"] == pytest.approx(ks / stiffness, rel=0.05)
