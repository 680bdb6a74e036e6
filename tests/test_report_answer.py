"""The answer block (reports/answer.py) on hand-built rows whose answers are known by
construction, and the rendered page's text hygiene and count consistency."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

from reports import build_report_from_dir
from reports.answer import budget_picks, scenario_answers
from reports.synthetic import write_synthetic_run


def _rows(spec: dict[tuple[str, str], tuple[list[float], float]], privileged=()) -> pd.DataFrame:
    """spec: (controller, scenario) -> (peaks in µrad by seed, mean current)."""
    rows = []
    for (ctrl, scen), (peaks, cur) in spec.items():
        for seed, p in enumerate(peaks):
            rows.append(dict(cell=f"{ctrl}__{scen}__s{seed}", controller=ctrl, scenario=scen, seed=seed,
                             status="ok", peak_error_rad=p * 1e-6, mean_abs_current=cur,
                             privileged=ctrl in privileged))
    return pd.DataFrame(rows)


def test_best_per_scenario_runner_up_ratio_and_tie():
    df = _rows({("a", "s1"): ([1.0, 2.0, 3.0], 1.0), ("b", "s1"): ([2.0, 4.0, 6.0], 0.5),
                ("c", "s1"): ([9.0, 9.0, 9.0], 0.1),
                ("a", "s2"): ([5.0, 5.0, 5.0], 1.0), ("b", "s2"): ([4.0, 5.0, 6.0], 1.0),
                ("c", "s2"): ([7.0, 8.0, 9.0], 1.0),
                ("oracle", "s1"): ([0.1, 0.1, 0.1], 0.1)}, privileged=("oracle",))
    ans = {a.scenario: a for a in scenario_answers(df)}
    s1 = ans["s1"]
    assert s1.best == ("a",)                         # the privileged bound is no candidate
    assert s1.median == pytest.approx(2.0) and s1.n == 3
    assert s1.low <= 2.0 <= s1.high
    assert s1.runner_up == "b" and s1.runner_median == pytest.approx(4.0)
    assert s1.ratio == pytest.approx(0.5)            # every seed's ratio is exactly 1/2
    assert s1.p_better == 1.0 and s1.n_pairs == 3
    s2 = ans["s2"]
    assert s2.best == ("a", "b")                     # equal medians: a tie names both
    assert s2.runner_up == "c" and s2.runner_median == pytest.approx(8.0)
    # the paired ratio against c, by hand: geometric mean of 5/7, 5/8, 5/9
    assert s2.ratio == pytest.approx(math.exp(np.mean(np.log([5 / 7, 5 / 8, 5 / 9]))))


def test_budgets_pick_the_most_accurate_that_fits_and_none_below_the_cheapest():
    df = _rows({("a", "s"): ([1.0, 1.0], 1.0), ("b", "s"): ([4.0, 4.0], 0.5),
                ("c", "s"): ([9.0, 9.0], 0.1), ("d", "s"): ([10.0, 10.0], 2.0)})
    picks = budget_picks(df, [0.05, 0.1, 0.7, 5.0])
    assert [(p.budget, p.best) for p in picks] == [(0.05, None), (0.1, "c"), (0.7, "b"), (5.0, "a")]
    assert picks[0].cheapest == pytest.approx(0.1) and math.isnan(picks[0].median)
    assert picks[2].median == pytest.approx(4.0) and picks[2].current == pytest.approx(0.5)
    # default budgets: the Pareto set's currents (d is dominated by a) and half the cheapest
    auto = budget_picks(df)
    assert [(p.budget, p.best) for p in auto] == [(0.05, None), (0.1, "c"), (0.5, "b"), (1.0, "a")]


@pytest.fixture(scope="module")
def html(tmp_path_factory):
    run = write_synthetic_run(tmp_path_factory.mktemp("answer-run"))
    return build_report_from_dir(run).read_text(encoding="utf-8"), run


def _visible_text_outside_cell_table(page: str) -> str:
    page = re.sub(r"<script\b.*?</script>", " ", page, flags=re.S)
    page = re.sub(r"<style\b.*?</style>", " ", page, flags=re.S)
    page = re.sub(r'<table class="sortable" id="results-table">.*?</table>', " ", page, flags=re.S)
    page = re.sub(r"<[^>]+>", " ", page)
    return page


def test_no_cell_id_or_escape_in_the_text_outside_the_cell_table(html):
    page, run = html
    cells = pd.read_csv(run / "results.csv")["cell"] if (run / "results.csv").exists() \
        else pd.read_parquet(run / "results.parquet")["cell"]
    text = _visible_text_outside_cell_table(page)
    assert not [c for c in cells if c in text]
    assert not re.search(r"\\u[0-9a-fA-F]{4}", text)
    assert "fixed_step_python" not in text and "∞–∞" not in text and "SPEC §" not in text
    assert "University of Florida" in text


def test_answer_names_the_lowest_median_of_the_rows(html):
    page, run = html
    res = pd.read_parquet(run / "results.parquet")
    ok = res[res["status"] == "ok"]
    for scen, g in ok.groupby("scenario"):
        best = g.groupby("controller")["peak_error_rad"].median().idxmin()
        m = re.search(rf'data-scenario="{re.escape(scen)}" data-best="([^"]*)"', page)
        assert m and best in m.group(1).split(","), scen


def test_inequality_counts_agree_with_the_claim_row(tmp_path):
    run = write_synthetic_run(tmp_path / "run")
    bound = pd.read_csv(run / "bound.csv")
    # two stable runs not scored (skipped by the time cap): ratio and θ unknown
    idx = bound.index[bound["stable"].astype(bool)][:2]
    bound.loc[idx, ["theta_rad", "ratio"]] = np.nan
    bound["status"] = "ok"
    bound.loc[idx, "status"] = "skipped"
    bound.to_csv(run / "bound.csv", index=False)
    page = build_report_from_dir(run).read_text(encoding="utf-8")
    n, n_stable = len(bound), int(bound["stable"].astype(bool).sum())
    box = re.search(r'<div class="box" id="bound-verdict">(.*?)</div>', page, flags=re.S).group(1)
    box = re.sub(r"<[^>]+>", "", box)
    assert f"{n} runs" in box and f"{n_stable} stable" in box
    assert f"{n_stable - 2} scored" in box and "2 skipped" in box
    row = re.search(r'<tr id="claim-bound_sweep">(.*?)</tr>', page, flags=re.S).group(1)
    assert f"{n_stable - 2} stable of {n} runs" in row or f"{n_stable - 2} stable" in row
