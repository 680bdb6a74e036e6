"""The report's answer block: which controller, for which scenario and current budget, how sure.

Computed from whatever rows the run holds (a matrix, a sweep or a frontier); nothing here knows a
controller by name.

* **Candidates.** A controller is a candidate in a scenario only if it is not a privileged bound
  and *every* seed the scenario ran for it finished ``ok`` with a finite peak error; a controller
  that diverged on some seeds is left out (and listed as "k of n seeds not ok"), never ranked on
  its surviving seeds.
* **Most accurate per scenario.** Among the candidates, the controller with the lowest median
  peak error |x1| (µrad) over seeds, with its 95 % bootstrap CI (:func:`reports.stats.median_ci`).
  Equal medians are a tie: every tied controller is named.
* **Runner-up** — the candidate with the lowest median among the *other families* (results
  column ``controller_family``, else ``controller_base``, else the name; see
  :func:`reports.selection.family_of`), so the best is never compared with its own knob points.
  The paired ratio best / runner-up is over the seeds both ran, with P(better) = share of those
  seeds on which the best is lower (:func:`reports.stats.paired_ratio`). The best is
  *separable* from the runner-up only when at least two seeds pair, the ratio's CI lies below 1
  and P(better) ≥ ½.
* **Best within a current budget.** Each candidate (controller, scenario) is a point (median mean
  |i|, median peak |x1|). The budgets are the mean currents of the scenario's Pareto set of those
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

from reports.selection import family_of
from reports.stats import median_ci, paired_ratio, pareto_front

__all__ = ["LeftOut", "ScenarioAnswer", "BudgetPick", "privileged_mask", "left_out", "eligible_rows",
           "scenario_answers", "default_budgets", "budget_picks"]


@dataclass(frozen=True)
class LeftOut:
    """A controller left out of a scenario's ranking: ``not_ok`` of its ``n`` seeds were not ok."""

    controller: str
    not_ok: int
    n: int


@dataclass(frozen=True)
class ScenarioAnswer:
    """The most accurate controller of one scenario (errors in µrad).

    ``best`` is empty when no controller of the scenario was ok on every seed.
    """

    scenario: str
    best: tuple[str, ...]          # one name, or every controller tied at the lowest median
    median: float
    low: float
    high: float
    n: int
    runner_up: str | None          # the best candidate of another family
    runner_median: float
    ratio: float                   # geometric mean of best/runner-up per seed
    ratio_low: float
    ratio_high: float
    p_better: float                # share of paired seeds on which the best is lower (ties ½)
    n_pairs: int
    n_controllers: int             # candidates ranked
    runner_family: str | None = None
    left_out: tuple[LeftOut, ...] = ()

    @property
    def separable(self) -> bool:
        """Whether the best is told apart from the runner-up: ≥ 2 paired seeds, the paired
        ratio's CI below 1 and P(better) ≥ ½."""
        return (self.runner_up is not None and self.n_pairs >= 2 and self.ratio_high < 1
                and self.p_better >= 0.5)

    @property
    def separation_note(self) -> str:
        """Why the best is not separable from the runner-up ("" when it is, or has no runner-up)."""
        if self.runner_up is None or not self.best or self.separable:
            return ""
        if self.n_pairs < 2:
            why = f"{self.n_pairs} paired seed{'s' if self.n_pairs != 1 else ''}"
        elif not self.ratio_high < 1:
            why = "paired ratio CI contains 1" if self.ratio_low <= 1 else "paired ratio CI above 1"
        else:
            why = "P(better) below 50 %"
        return f"not separable from the runner-up ({why})"


@dataclass(frozen=True)
class BudgetPick:
    """The most accurate controller whose median mean |i| is within ``budget`` [ozf·in]."""

    scenario: str
    budget: float
    best: str | None               # None: no controller's median current fits the budget
    median: float                  # its median peak |x1| [µrad]
    current: float                 # its median mean |i| [ozf·in]
    cheapest: float                # the scenario's lowest median current [ozf·in]


def privileged_mask(results: pd.DataFrame) -> pd.Series:
    """True on the rows of privileged bounds (column ``privileged``; absent = none)."""
    if "privileged" not in results.columns:
        return pd.Series(False, index=results.index)
    return results["privileged"].astype(object).eq(True)


def _ok_mask(results: pd.DataFrame) -> pd.Series:
    """``ok`` status and a finite peak error."""
    peak = pd.to_numeric(results["peak_error_rad"], errors="coerce").astype(float)
    return (results["status"] == "ok") & np.isfinite(peak)


def _completeness(results: pd.DataFrame) -> pd.DataFrame:
    """Per (scenario, controller) of the non-privileged rows: ``n`` rows and ``not_ok`` of them."""
    r = results[~privileged_mask(results)]
    bad = (~_ok_mask(r)).astype(int)
    g = bad.groupby([r["scenario"], r["controller"]])
    return pd.DataFrame({"n": g.size(), "not_ok": g.sum()})


def left_out(results: pd.DataFrame) -> dict[str, tuple[LeftOut, ...]]:
    """Per scenario, the non-privileged controllers not ok on every seed (sorted by name)."""
    if results.empty or "peak_error_rad" not in results.columns:
        return {}
    c = _completeness(results)
    c = c[c["not_ok"] > 0]
    out: dict[str, list[LeftOut]] = {}
    for (scen, ctrl), row in c.sort_index().iterrows():
        out.setdefault(str(scen), []).append(LeftOut(str(ctrl), int(row["not_ok"]), int(row["n"])))
    return {k: tuple(v) for k, v in out.items()}


def eligible_rows(results: pd.DataFrame) -> pd.DataFrame:
    """The candidates' rows: not privileged bounds, and only controllers that are ``ok`` with a
    finite peak on every seed the scenario ran for them."""
    if results.empty or "peak_error_rad" not in results.columns:
        return results.iloc[0:0]
    c = _completeness(results)
    complete = set(c.index[c["not_ok"] == 0])
    keys = list(zip(results["scenario"], results["controller"]))
    keep = pd.Series([k in complete for k in keys], index=results.index)
    return results[keep & ~privileged_mask(results)]


def _no_answer(scen: str, left: tuple[LeftOut, ...]) -> ScenarioAnswer:
    nan = math.nan
    return ScenarioAnswer(scen, (), nan, nan, nan, 0, None, nan, nan, nan, nan, nan, 0, 0,
                          None, left)


def scenario_answers(results: pd.DataFrame) -> list[ScenarioAnswer]:
    """One :class:`ScenarioAnswer` per scenario with a non-privileged row, sorted by name; a
    scenario whose controllers all failed some seed has ``best == ()``."""
    if results.empty or "peak_error_rad" not in results.columns:
        return []
    ok = eligible_rows(results)
    left = left_out(results)
    fam = family_of(ok) if len(ok) else pd.Series(dtype=str)
    out = []
    for scen in sorted(set(left) | {str(s) for s in ok["scenario"]}):
        g = ok[ok["scenario"] == scen]
        if g.empty:
            out.append(_no_answer(scen, left.get(scen, ())))
            continue
        meds = (g.groupby("controller")["peak_error_rad"].median() * 1e6).sort_index()
        order = sorted(meds.index, key=lambda c: (meds[c], c))
        low = meds[order[0]]
        best = tuple(c for c in order if meds[c] == low)
        first = best[0]
        ci = median_ci(g.loc[g["controller"] == first, "peak_error_rad"].to_numpy() * 1e6)
        fam_of = fam[g.index].groupby(g["controller"]).first()
        best_fams = {fam_of[c] for c in best}
        rest = [c for c in order if c not in best and fam_of[c] not in best_fams]
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
                                  *ratio, n_controllers=len(order),
                                  runner_family=str(fam_of[runner]) if runner is not None else None,
                                  left_out=left.get(scen, ())))
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
