"""A small run of the closed-loop EM study (bench.speed.closed_loop, issue 27 item 2)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.exact import fixed_step_family
from bench.runner import run_closed_loop
from bench.speed.closed_loop import ClosedLoopEMConfig, closed_loop_em
from controllers import make_controller, roles
from plant.params import PlantParams

CFG = ClosedLoopEMConfig(steps=(1e-4,), n_seeds=6, duration_s=2.0, warmup_s=0.5, n_resamples=200)


@pytest.fixture(scope="module")
def study():
    return closed_loop_em(CFG)


def test_study_reports_the_runner_peaks_of_each_method(study):
    exact_row, em_row = study["rows"]
    assert study["statuses"] == {k: ["ok"] for k in study["peaks_rad"]}
    assert len(study["rows"]) == 2 and em_row["step_s"] == 1e-4
    p = PlantParams()
    for seed in (0, 5):          # the study's cells are closed-loop runs through the same seam
        exact = run_closed_loop(p, make_controller(roles.IDENTIFICATION), duration_s=2.0, warmup_s=0.5, seed=seed)
        em = run_closed_loop(p, make_controller(roles.IDENTIFICATION), duration_s=2.0, warmup_s=0.5, seed=seed,
                             family=fixed_step_family(1e-4))
        peaks = list(study["peaks_rad"].values())
        assert peaks[0][seed] == exact.metrics["peak_error_rad"]
        assert peaks[1][seed] == em.metrics["peak_error_rad"]
        assert peaks[0][seed] != peaks[1][seed]      # different plant noise paths
    assert exact_row["median_rad"] == pytest.approx(np.median(peaks[0]))
    assert em_row["p95_rad"] == pytest.approx(np.quantile(peaks[1], 0.95))


def test_study_intervals_and_verdict_are_consistent(study):
    exact_row, em_row = study["rows"]
    peaks = [np.array(v) for v in study["peaks_rad"].values()]
    for row, x in zip(study["rows"], peaks):
        for w in ("median", "p95"):
            lo, hi = row[f"{w}_ci_rad"]
            assert x.min() <= lo <= row[f"{w}_rad"] <= hi <= x.max()
    for w in ("median", "p95"):
        lo, hi = em_row[f"{w}_diff_ci_rad"]
        assert lo <= em_row[f"{w}_diff_rad"] <= hi
        assert em_row[f"{w}_resolved"] == (not lo <= 0.0 <= hi)
        assert em_row[f"{w}_resolution_pct"] == pytest.approx(100 * (hi - lo) / 2 / exact_row[f"{w}_rad"])
    distinct = em_row["median_resolved"] or em_row["p95_resolved"]
    assert em_row["verdict"].startswith("distinguishable" if distinct else "not distinguishable")
    # noise-free, EM at 0.1 ms is close to the exact peak but not equal (Euler's O(h) error)
    assert 0.0 < em_row["noise_free_rel_diff"] < 0.2
    assert em_row["cost_ratio"] == pytest.approx(em_row["cpu_per_cell_s"] / exact_row["cpu_per_cell_s"])


def test_config_rejects_bad_fields():
    with pytest.raises(ValueError, match="n_seeds"):
        ClosedLoopEMConfig(n_seeds=2)
    with pytest.raises(ValueError, match="steps"):
        ClosedLoopEMConfig(steps=(0.1,))
    with pytest.raises(ValueError, match="warmup_s"):
        ClosedLoopEMConfig(duration_s=1.0, warmup_s=1.0)


def test_study_reaches_the_report_the_claim_row_and_the_terminal(study, tmp_path):
    from rich.console import Console

    from bench.speed.tables import _print_table
    from reports import build_report
    from reports.synthetic import synthetic_inputs

    data = synthetic_inputs(0)
    data["speed"] = {**data["speed"], "closed_loop_em": study}
    html = build_report(tmp_path, **data).read_text(encoding="utf-8")
    assert 'id="closed-loop-em-table"' in html
    table = html[html.index('id="closed-loop-em-table"'):]
    table = table[:table.index("</table>")]
    assert table.count("<tr") == 1 + len(study["rows"])          # header, exact, one row per step
    assert "h = 0.0001 s" in table and study["rows"][1]["verdict"].split(" (")[0].split(" at")[0] in table

    console = Console(record=True, width=250)
    _print_table({"closed_loop_em": study, "technology": {"caveat": "-"}, "error_definition": "-",
                  "elapsed_s": 1.0, "load_average_1min": 1.0}, console)
    text = console.export_text()
    assert text.count("EM h=") == 1 and f"{study['n_seeds']} seeds" in text


def test_claim_row_names_the_coarsest_step_not_distinguishable():
    from reports.claims import _closed_loop_note

    rows = [{"method": "exact", "step_s": None},
            {"step_s": 1e-4, "median_resolved": True, "p95_resolved": False},
            {"step_s": 1e-5, "median_resolved": False, "p95_resolved": False, "median_resolution_pct": 12.0,
             "cost_ratio": 3.5},
            {"step_s": 3e-6, "median_resolved": False, "p95_resolved": False, "median_resolution_pct": 11.0,
             "cost_ratio": 9.0}]
    note = _closed_loop_note({"closed_loop_em": {"controller": "c", "n_seeds": 50, "rows": rows}})
    assert "h = 1e−05 s" in note and "±12 %" in note and "3.5×" in note
    rows[2]["p95_resolved"] = True
    assert "h = 3e−06 s" in _closed_loop_note({"closed_loop_em": {"rows": rows}})
    assert _closed_loop_note({}) == "" and _closed_loop_note(None) == ""
