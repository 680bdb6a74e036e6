"""The report's answer block: which controller, for which scenario and current budget, how sure.

Computed from whatever rows the run holds (a matrix, a sweep or a frontier); nothing here knows a
controller by name.

* **Most accurate per scenario.** Over the ``ok`` rows of controllers that are not privileged
  bounds, the controller with the lowest median peak error |x1| (µrad) over seeds, with its 95 %
  bootstrap CI (:func:`reports.stats.median_ci`), and the paired ratio best / runner-up over the
  seeds both finished, with P(better) = share of those seeds on which the best is lower
  (:func:`reports.stats.paired_ratio`). Equal medians are a tie: every tied controller is named.
* **Best within a current budget.** Each (controller, scenario) is a point (median mean |i|,
  median peak |x1|). The budgets are the mean currents of the scenario's Pareto set of those
  points (:func:`reports.stats.pareto_front`), rounded up to two significant figures, plus one
  budget at half the cheapest point, where no controller qualifies. Within a budget the best is
  the point with the lowest median peak among those whose median current is at most the budget.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from reports.stats import median_ci, paired_ratio, pareto_front

__all__ = ["ScenarioAnswer", "BudgetPick", "eligible_rows", "scenario_answers", "default_budgets",
           "budget_picks"]


@dataclass(frozen=True)
class ScenarioAnswer:
    """The most accurate controller of one scenario (errors in µrad)."""

    scenario: str
    best: tuple[str, ...]          # one name, or every controller tied at the lowest median
    median: float
    low: float
    high: float
    n: int
    runner_up: str | None
    runner_median: float
    ratio: float                   # geometric mean of best/runner-up per seed
    ratio_low: float
    ratio_high: float
    p_better: float                # share of paired seeds on which the best is lower (ties ½)
    n_pairs: int
    n_controllers: int


@dataclass(frozen=True)
class BudgetPick:
    """The most accurate controller whose median mean |i| is within ``budget`` [ozf·in]."""

    scenario: str
    budget: float
    best: str | None               # None: no controller's median current fits the budget
    median: float                  # its median peak |x1| [µrad]
    current: float                 # its median mean |i| [ozf·in]
    cheapest: float                # the scenario's lowest median current [ozf·in]


def eligible_rows(results: pd.DataFrame) -> pd.DataFrame:
    """``ok`` rows with a finite peak error, privileged bounds left out."""
    if results.empty or "peak_error_rad" not in results.columns:
        return results.iloc[0:0]
    ok = results[(results["status"] == "ok") & np.isfinite(results["peak_error_rad"].astype(float))]
    if "privileged" in ok.columns:
        ok = ok[~ok["privileged"].astype(object).eq(True)]
    return ok


def scenario_answers(results: pd.DataFrame) -> list[ScenarioAnswer]:
    """One :class:`ScenarioAnswer` per scenario with at least one eligible row, sorted by name."""
    ok = eligible_rows(results)
    out = []
    for scen, g in ok.groupby("scenario", sort=True):
        meds = (g.groupby("controller")["peak_error_rad"].median() * 1e6).sort_index()
        order = sorted(meds.index, key=lambda c: (meds[c], c))
        low = meds[order[0]]
        best = tuple(c for c in order if meds[c] == low)
        first = best[0]
        ci = median_ci(g.loc[g["controller"] == first, "peak_error_rad"].to_numpy() * 1e6)
        rest = [c for c in order if c not in best]
        runner = rest[0] if rest else None
        ratio = (math.nan,) * 4 + (0,)
        if runner is not None:
            a = g[g["controller"] == first].set_index("seed")["peak_error_rad"]
            b = g[g["controller"] == runner].set_index("seed")["peak_error_rad"]
            seeds = sorted(set(a.index) & set(b.index))
            pr = paired_ratio(a.loc[seeds].to_numpy(), b.loc[seeds].to_numpy())
            ratio = (pr.ratio, pr.low, pr.high, pr.p_improvement, pr.n)
        out.append(ScenarioAnswer(str(scen), best, ci.median, ci.low, ci.high, ci.n, runner,
                                  float(meds[runner]) if runner is not None else math.nan,
                                  *ratio, n_controllers=len(order)))
    return out


def _points(ok: pd.DataFrame) -> pd.DataFrame:
    g = ok[np.isfinite(ok["mean_abs_current"].astype(float))].groupby(["scenario", "controller"])
    return pd.DataFrame({"current": g["mean_abs_current"].median(),
                         "peak": g["peak_error_rad"].median() * 1e6}).reset_index()


def _round_up(x: float) -> float:
    """``x`` rounded up to two significant figures (0 stays 0)."""
    if not x > 0:
        return 0.0
    e = math.floor(math.log10(x)) - 1
    return float(f"{math.ceil(round(x / 10 ** e, 9)) * 10 ** e:.2g}")


def default_budgets(points: pd.DataFrame, max_budgets: int = 4) -> list[float]:
    """Budgets for one scenario's points: the Pareto set's currents (rounded up to 2 significant
    figures, at most ``max_budgets`` spread over the set) and half the cheapest current."""
    if points.empty:
        return []
    front = pareto_front(points["current"].to_numpy(), points["peak"].to_numpy())
    cur = sorted({_round_up(float(points["current"].iloc[i])) for i in front})
    if len(cur) > max_budgets:
        cur = [cur[int(round(k))] for k in np.linspace(0, len(cur) - 1, max_budgets)]
    cheapest = float(points["current"].min())
    below = _round_up(cheapest / 2)
    if below >= cheapest:
        below = cheapest / 2
    return [below] + cur


def budget_picks(results: pd.DataFrame,
                 budgets: Mapping[str, Sequence[float]] | Sequence[float] | None = None
                 ) -> list[BudgetPick]:
    """The best controller within each budget, per scenario.

    ``budgets``: one list for every scenario, a mapping scenario → list, or None for
    :func:`default_budgets`. Ties in median peak go to the lower current, then the name.
    """
    ok = eligible_rows(results)
    if ok.empty or "mean_abs_current" not in ok.columns:
        return []
    pts = _points(ok)
    out = []
    for scen, p in pts.groupby("scenario", sort=True):
        if budgets is None:
            bs = default_budgets(p)
        elif isinstance(budgets, Mapping):
            bs = list(budgets.get(scen, ()))
        else:
            bs = list(budgets)
        cheapest = float(p["current"].min())
        for b in sorted(bs):
            fit = p[p["current"] <= b].sort_values(["peak", "current", "controller"])
            if fit.empty:
                out.append(BudgetPick(str(scen), float(b), None, math.nan, math.nan, cheapest))
            else:
                r = fit.iloc[0]
                out.append(BudgetPick(str(scen), float(b), str(r["controller"]), float(r["peak"]),
                                      float(r["current"]), cheapest))
    return out
