"""The answer block (reports/answer.py) on hand-built rows whose answers are known by
construction, and the rendered page's text hygiene and count consistency."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest

from reports import build_report, build_report_from_dir
from reports.answer import LeftOut, budget_picks, scenario_answers
from reports.synthetic import write_synthetic_run


def _rows(spec: dict[tuple[str, str], tuple[list[float], float]], privileged=(),
          family: dict[str, str] | None = None) -> pd.DataFrame:
    """spec: (controller, scenario) -> (peaks in µrad by seed, mean current); a NaN peak is a
    seed that diverged (status "diverged"). ``family``: controller -> its base and family
    (default: its own name)."""
    rows = []
    for (ctrl, scen), (peaks, cur) in spec.items():
        fam = (family or {}).get(ctrl, ctrl)
        for seed, p in enumerate(peaks):
            rows.append(dict(cell=f"{ctrl}__{scen}__s{seed}", controller=ctrl, scenario=scen, seed=seed,
                             status="ok" if np.isfinite(p) else "diverged",
                             peak_error_rad=p * 1e-6, mean_abs_current=cur,
                             controller_base=fam, controller_family=fam,
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


NAN = math.nan


def test_a_controller_not_ok_on_every_seed_is_no_candidate():
    """The reviewer's case: x diverged on 4 of 5 seeds and was ok on one at 1 µrad. It must not
    be named most accurate (nor runner-up, nor at any budget); it is listed as left out."""
    df = _rows({("x", "s"): ([1.0, NAN, NAN, NAN, NAN], 0.1),
                ("a", "s"): ([3.0, 4.0, 5.0, 6.0, 7.0], 1.0),
                ("b", "s"): ([6.0, 8.0, 10.0, 12.0, 14.0], 0.5),
                ("oracle", "s"): ([0.1, NAN, 0.1, 0.1, 0.1], 0.1),      # a bound: never listed
                ("x", "t"): ([NAN, NAN], 1.0)}, privileged=("oracle",))
    ans = {a.scenario: a for a in scenario_answers(df)}
    s = ans["s"]
    assert s.best == ("a",) and s.median == pytest.approx(5.0) and s.n == 5
    assert s.runner_up == "b" and s.ratio == pytest.approx(0.5) and s.n_controllers == 2
    assert s.left_out == (LeftOut("x", 4, 5),)
    # a scenario where no controller was ok on every seed names nobody
    assert ans["t"].best == () and ans["t"].left_out == (LeftOut("x", 2, 2),)
    # x's one surviving seed (0.1 ozf·in) would win every budget; it is not a candidate
    picks = budget_picks(df, [0.2, 0.7, 5.0])
    assert [(p.budget, p.best) for p in picks] == [(0.2, None), (0.7, "b"), (5.0, "a")]
    assert picks[0].cheapest == pytest.approx(0.5)
    # an "ok" row without a finite peak is not ok either
    df2 = df[df["scenario"] == "s"].copy()
    df2.loc[(df2["controller"] == "a") & (df2["seed"] == 2), "peak_error_rad"] = np.nan
    s2 = scenario_answers(df2)[0]
    assert s2.best == ("b",) and LeftOut("a", 1, 5) in s2.left_out


def test_runner_up_is_of_another_family_not_the_best_at_another_knob_point():
    # a@1 and a@2 are knob points of one controller; b is another family
    fam = {"a@1": "a", "a@2": "a", "b": "b"}
    df = _rows({("a@1", "s"): ([1.0, 2.0, 3.0], 1.0), ("a@2", "s"): ([1.1, 2.1, 3.1], 1.0),
                ("b", "s"): ([4.0, 5.0, 6.0], 1.0)}, family=fam)
    s = scenario_answers(df)[0]
    assert s.best == ("a@1",)
    assert s.runner_up == "b" and s.runner_family == "b" and s.runner_median == pytest.approx(5.0)
    assert s.ratio == pytest.approx(math.exp(np.mean(np.log([1 / 4, 2 / 5, 3 / 6]))))
    # only one family: no runner-up, no ratio
    solo = scenario_answers(df[df["controller"] != "b"])[0]
    assert solo.runner_up is None and solo.n_pairs == 0 and solo.separation_note == ""


def test_not_separable_when_the_paired_ratio_ci_contains_1_or_p_better_is_below_half():
    # medians 1 < 2, but per seed a/b is 1/2 on three seeds and 2 on two: geometric mean 2^-0.2
    df = _rows({("a", "s"): ([1.0, 1.0, 1.0, 8.0, 8.0], 1.0), ("b", "s"): ([2.0, 2.0, 2.0, 4.0, 4.0], 1.0)})
    s = scenario_answers(df)[0]
    assert s.best == ("a",) and s.ratio == pytest.approx(2 ** -0.2) and s.p_better == pytest.approx(0.6)
    assert s.ratio_low < 1 < s.ratio_high
    assert not s.separable
    assert s.separation_note == "not separable from the runner-up (paired ratio CI contains 1)"
    # median 3 < 9, but a is lower on one seed of five: P(better) = 0.2
    df = _rows({("a", "s"): ([1.0, 2.0, 3.0, 10.0, 10.0], 1.0), ("b", "s"): ([0.9, 1.9, 9.0, 9.0, 9.0], 1.0)})
    s = scenario_answers(df)[0]
    assert s.best == ("a",) and s.p_better == pytest.approx(0.2) and not s.separable
    assert s.separation_note.startswith("not separable from the runner-up (")
    # every seed's ratio exactly 1/2: separable, no note
    df = _rows({("a", "s"): ([1.0, 2.0, 3.0], 1.0), ("b", "s"): ([2.0, 4.0, 6.0], 1.0)})
    s = scenario_answers(df)[0]
    assert s.separable and s.separation_note == ""
    # one paired seed: no interval, not separable
    s = scenario_answers(_rows({("a", "s"): ([1.0], 1.0), ("b", "s"): ([2.0], 1.0)}))[0]
    assert not s.separable and s.separation_note == "not separable from the runner-up (1 paired seed)"


def test_figures_take_the_peak_median_over_the_answer_tables_rows():
    """z has one seed with zero current: its peak median (2 µrad, over all three seeds, as in the
    answer table) must not become the median over the two seeds a log x axis can place (6)."""
    from reports.figures import accuracy_vs_current, peak_intervals
    from reports.limits import limits_from_config

    df = _rows({("z", "s"): ([1.0, 2.0, 10.0], 1.0), ("w", "s"): ([3.0, 4.0, 5.0], 2.0)})
    df.loc[(df["controller"] == "z") & (df["seed"] == 0), "mean_abs_current"] = 0.0
    ans = scenario_answers(df)[0]
    assert ans.best == ("z",) and ans.median == pytest.approx(2.0)
    lim = limits_from_config({})
    fig = accuracy_vs_current(df, {}, lim)
    marker = [t for t in fig.data if t.name == "z"][0]
    assert marker.y[0] == pytest.approx(np.median([1.0, 2.0, 10.0]))
    assert marker.x[0] == pytest.approx(1.0)                      # x: the seeds with current > 0
    assert "2 of 3 seeds with current > 0" in marker.hovertemplate
    faint = [t for t in fig.data if t.name is None and "<b>z</b>" in t.hovertemplate][0]
    assert len(faint.x) == 2                                       # zero current cannot sit on a log axis
    w = [t for t in fig.data if t.name == "w"][0]
    assert "current > 0" not in w.hovertemplate
    iv = [t for t in peak_intervals(df, {}, lim).data if list(t.y) == ["z"]][0]
    assert iv.x[0] == pytest.approx(ans.median)


def _answer_block(page: str) -> str:
    return re.search(r'<section class="answer" id="answer">(.*?)</section>', page, flags=re.S).group(1)


def test_rendered_answer_names_no_bound_no_partial_controller_and_no_ci_from_one_seed(tmp_path):
    fam = {"a@1": "a", "a@2": "a"}
    df = _rows({("oracle", "s"): ([0.1, 0.1, 0.1], 0.1),                     # lowest, privileged
                ("x", "s"): ([0.5, NAN, NAN], 0.2),                          # lowest of the rest, 1 of 3 ok
                ("a@1", "s"): ([1.0, 2.0, 3.0], 1.0), ("a@2", "s"): ([1.1, 2.1, 3.1], 1.0),
                ("b", "s"): ([4.0, 5.0, 6.0], 1.0),
                ("c", "u"): ([2.0], 1.0), ("d", "u"): ([3.0], 1.0)},           # one seed each
               privileged=("oracle",), family=fam)
    page = build_report(tmp_path / "run", results=df).read_text(encoding="utf-8")
    block = _answer_block(page)
    assert re.search(r'data-scenario="s" data-best="a@1"', block)
    row = re.search(r'<tr id="answer-s"[^>]*>(.*?)</tr>', block, flags=re.S).group(1)
    assert "oracle" not in row and "x" not in re.sub(r"<[^>]+>", " ", row).replace("×", "")
    assert "b (family b;" in row and "a@2" not in row
    left = re.search(r'<tr class="left-out" data-scenario="s">(.*?)</tr>', block, flags=re.S).group(1)
    assert "x (2 of 3 seeds not ok)" in left and "oracle" not in left
    assert "ok on every seed" in block                                       # the rule is stated
    row_u = re.search(r'<tr id="answer-u"[^>]*>(.*?)</tr>', block, flags=re.S).group(1)
    cells = [re.sub(r"<[^>]+>", "", c).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", row_u, flags=re.S)]
    assert cells[2] == "2 — (1 seed)"                                         # no CI from one seed
    assert cells[5] == "0.667× —"
    assert "not separable from the runner-up (1 paired seed)" in cells[1]
    budgets = re.search(r'<ul id="budget-list">(.*?)</ul>', block, flags=re.S).group(1)
    assert "oracle" not in budgets and "x" not in re.sub(r"<[^>]+>", " ", budgets).replace("×", "")


@pytest.fixture(scope="module")
def html(tmp_path_factory):
    """The synthetic run plus a privileged bound with the lowest peak of every scenario."""
    run = write_synthetic_run(tmp_path_factory.mktemp("answer-run"))
    res = pd.read_parquet(run / "results.parquet")
    bound = res[res["controller"] == res["controller"].iloc[0]].copy()
    bound["controller"] = bound["controller_base"] = bound["controller_family"] = "bound"
    bound["cell"] = bound["cell"].str.replace(res["controller"].iloc[0], "bound", regex=False)
    bound["peak_error_rad"] = res["peak_error_rad"].min() / 10
    res["privileged"] = False
    bound["privileged"] = True
    pd.concat([res, bound], ignore_index=True).to_parquet(run / "results.parquet", index=False)
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
    """Per scenario: the lowest median among controllers that are no privileged bound and are ok
    on every seed; a privileged row with the lowest peak is never named."""
    page, run = html
    res = pd.read_parquet(run / "results.parquet")
    priv = res["privileged"].astype(object).eq(True)
    assert priv.any()
    complete = res.groupby(["scenario", "controller"])["status"].transform(lambda s: (s == "ok").all())
    cand = res[complete & ~priv]
    assert (~complete & ~priv & (res["status"] == "ok")).any()   # the run has a partial controller
    for scen, g in cand.groupby("scenario"):
        best = g.groupby("controller")["peak_error_rad"].median().idxmin()
        m = re.search(rf'data-scenario="{re.escape(scen)}" data-best="([^"]*)"', page)
        assert m and best in m.group(1).split(","), scen
        assert "bound" not in m.group(1).split(",")   # the privileged rows have the lowest peak


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
