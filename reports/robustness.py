"""The report's robustness section: every controller on every real plant, told only the model.

Present only when the run's ``config.json`` records a ``[robustness]`` table (``matrix.robustness``,
written by ``solnic-bench robustness``, :mod:`bench.robustness`): its ``reference`` scenario
(thesis) and which controller rows are best frontier points (``best``: row → parent).

* **Cells** (:func:`cell_table`): one per controller row × scenario, over the ``ok`` seeds — the
  median peak error with its 95 % percentile-bootstrap CI (:func:`reports.stats.median_ci`), the
  mean of ``mean_abs_current``, the *degradation ratio* against the reference paired by seed
  (:func:`reports.stats.paired_ratio`: geometric mean of peak_S/peak_ref over the seeds ok on
  both, BCa CI) and the count of every status other than ``ok``.
* **Heatmap** (:func:`heatmap_figure`): rows × scenarios, colour log10 of the median peak [µrad],
  the CI, ratio and current in the hover, non-ok statuses marked ``⚠`` in the cell text.
* **Verdicts** (:func:`verdicts`): per real-plant scenario, among the real controller rows ok
  on every seed, the one with the lowest median peak (ties within overlapping CIs said so, rows
  left out for failed seeds named), and the row that degrades most.
* **Claims** (:func:`robustness_claims`): on each real plant, the dissertation's "≥ 10× more
  accurate than any LTI servo" and "with less current", and "pulse-width beats solnic"
  (docs/results.md), each a paired ratio with its CI and a verdict from the CI
  (:func:`reports.claims.verdict`), bounded by the seeds either row failed (a failed seed of the
  claim's subject caps it at inconclusive, all failed: not reproduced); the claim names the row
  tested (:func:`_design`). Which families these are comes from
  :class:`reports.selection.Selection` (``controllers/roles.py``); nothing here names a controller.

A privileged bound (the oracle) is shown as a floor and never ranked or claimed about.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd
import plotly.graph_objects as go

from reports.claims import (fmt_g, INCONCLUSIVE, NOT_MEASURED, NOT_REPRODUCED, REPRODUCED, ClaimRow, at_least,
                            below, verdict)
from reports.selection import Selection, family_of
from reports.stats import METHOD_TEXT, median_ci, paired_ratio

__all__ = ["has_robustness", "cell_table", "heatmap_figure", "verdicts", "degradation_ranking", "most_robust",
           "robustness_claims", "robustness_context"]

_ERROR, _CURRENT = "peak_error_rad", "mean_abs_current"


def _table(config: Mapping[str, Any] | None) -> dict[str, Any]:
    return dict((((config or {}).get("matrix") or {}).get("robustness")) or {})


def has_robustness(config: Mapping[str, Any] | None) -> bool:
    """True when the run recorded a ``[robustness]`` table."""
    return bool(_table(config))


def _bound(rows: pd.DataFrame, name: str) -> bool:
    """A privileged bound: the rows' ``privileged`` flag, else the registry (via the base)."""
    if "privileged" in rows.columns:
        flags = rows["privileged"].dropna()
        if len(flags):
            return bool(flags.astype(bool).any())
    base = str(rows["controller_base"].iloc[0]) if "controller_base" in rows.columns else name
    try:
        from controllers.base import get_controller
        return bool(get_controller(base).privileged)
    except (ImportError, ValueError):
        return False


def _per_seed(results: pd.DataFrame, controller: str, scenario: str, column: str) -> pd.Series:
    """``column`` by seed over the ok cells of one controller row × scenario."""
    r = results[(results["controller"] == controller) & (results["scenario"] == scenario)
                & (results["status"] == "ok")]
    if column not in r.columns:
        return pd.Series(dtype=float)
    return r.groupby("seed")[column].mean().dropna()


def _paired(a: pd.Series, b: pd.Series):
    seeds = a.index.intersection(b.index)
    return paired_ratio(a.loc[seeds].to_numpy(), b.loc[seeds].to_numpy())


def cell_table(results: pd.DataFrame, config: Mapping[str, Any]) -> pd.DataFrame:
    """One row per (controller row, scenario) in matrix order (see the module doc). Columns:
    controller, scenario, family, bound, best_of (the parent of a best point, else ""), ok, cells,
    statuses ({status: count} of the non-ok cells), median/low/high [µrad], current (mean of
    mean_abs_current over ok seeds [ozf·in]), ratio/ratio_low/ratio_high/ratio_n (paired
    degradation against the reference; 1 on the reference itself)."""
    if results.empty:
        return pd.DataFrame()
    table = _table(config)
    reference = table.get("reference") or Selection.from_config(config).thesis_scenario
    best = dict(table.get("best") or {})
    m = config.get("matrix") or {}
    controllers = [c for c in m.get("controllers") or [] if c in set(results["controller"])]
    controllers += [c for c in dict.fromkeys(results["controller"]) if c not in controllers]
    scenarios = [s for s in m.get("scenarios") or [] if s in set(results["scenario"])]
    scenarios += [s for s in dict.fromkeys(results["scenario"]) if s not in scenarios]
    fam = family_of(results)
    rows = []
    for ctrl in controllers:
        mine = results[results["controller"] == ctrl]
        bound = _bound(mine, ctrl)
        ref_peaks = _per_seed(results, ctrl, reference, _ERROR)
        for scen in scenarios:
            g = mine[mine["scenario"] == scen]
            if g.empty:
                continue
            ok = g[g["status"] == "ok"]
            ci = median_ci((ok[_ERROR] * 1e6).to_numpy()) if _ERROR in ok.columns else median_ci([])
            cur = ok[_CURRENT].dropna() if _CURRENT in ok.columns else pd.Series(dtype=float)
            bad = g.loc[g["status"] != "ok", "status"].value_counts()
            pr = _paired(_per_seed(results, ctrl, scen, _ERROR), ref_peaks)
            rows.append({"controller": ctrl, "scenario": scen, "family": str(fam[g.index[0]]), "bound": bound,
                         "best_of": best.get(ctrl, ""), "reference": scen == reference,
                         "ok": len(ok), "cells": len(g), "statuses": {str(k): int(v) for k, v in bad.items()},
                         "median": ci.median, "low": ci.low, "high": ci.high,
                         "current": float(cur.mean()) if len(cur) else math.nan,
                         "ratio": pr.ratio, "ratio_low": pr.low, "ratio_high": pr.high, "ratio_n": pr.n})
    return pd.DataFrame(rows)


def _status_text(statuses: Mapping[str, int]) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(statuses.items()))


def heatmap_figure(cells: pd.DataFrame) -> go.Figure | None:
    """Controllers × scenarios, colour = log10 median peak [µrad]; hover: median [CI], paired
    degradation ratio [CI], mean current, ok/cells and the other statuses (marked ``⚠``)."""
    if cells.empty or cells["median"].notna().sum() == 0:
        return None
    rows = list(dict.fromkeys(cells["controller"]))
    cols = list(dict.fromkeys(cells["scenario"]))
    z = np.full((len(rows), len(cols)), np.nan)
    text = [["" for _ in cols] for _ in rows]
    hover = [["no cell" for _ in cols] for _ in rows]
    for _, c in cells.iterrows():
        i, j = rows.index(c["controller"]), cols.index(c["scenario"])
        if c["median"] > 0:
            z[i, j] = math.log10(c["median"])
        mark = " ⚠" if c["statuses"] else ""
        ratio = "" if c["reference"] or not np.isfinite(c["ratio"]) else f"<br>×{fmt_g(c['ratio'], 2)}"
        text[i][j] = f"{fmt_g(c['median'], 3)}{ratio}{mark}"
        hover[i][j] = (f"<b>{c['controller']}</b> on <b>{c['scenario']}</b><br>"
                       f"median peak {fmt_g(c['median'])} µrad [95 % CI {fmt_g(c['low'])}, {fmt_g(c['high'])}]<br>"
                       + ("reference plant" if c["reference"] else
                          f"degradation vs reference, paired by seed: ×{fmt_g(c['ratio'])} "
                          f"[{fmt_g(c['ratio_low'])}, {fmt_g(c['ratio_high'])}], {c['ratio_n']} seeds")
                       + f"<br>mean |i| {fmt_g(c['current'])} ozf·in<br>ok {c['ok']}/{c['cells']}"
                       + (f"<br>⚠ {_status_text(c['statuses'])}" if c["statuses"] else "")
                       + (" (bound: not a controller)" if c["bound"] else ""))
    finite = z[np.isfinite(z)]
    lo, hi = math.floor(finite.min()), math.ceil(finite.max())
    ticks = list(range(lo, hi + 1)) if hi > lo else [lo]
    labels = [rows[i] + (" (bound)" if cells[cells["controller"] == rows[i]]["bound"].any() else "")
              for i in range(len(rows))]
    fig = go.Figure(go.Heatmap(
        z=z, x=cols, y=labels, text=text, texttemplate="%{text}", textfont=dict(size=10),
        customdata=hover, hovertemplate="%{customdata}<extra></extra>", colorscale="Viridis",
        zmin=lo, zmax=hi if hi > lo else lo + 1,
        colorbar=dict(title="median peak [µrad]", tickvals=ticks, ticktext=[fmt_g(10.0 ** t) for t in ticks])))
    fig.update_yaxes(autorange="reversed")
    fig.update_layout(title="Median peak error [µrad] (log colour); ×: degradation vs the reference, paired by seed; "
                            "⚠: a status other than ok", xaxis_title="scenario (truth)", yaxis_title="controller")
    return fig


def _overlap(a: pd.Series, b: pd.Series) -> bool:
    return bool(a["low"] <= b["high"] and b["low"] <= a["high"])


def verdicts(cells: pd.DataFrame) -> list[dict[str, Any]]:
    """One plain-language verdict per non-reference scenario: among the real controller rows ok
    on every seed, the one with the lowest median peak (naming the rows whose CI overlaps its own
    as not separable from it, and the rows with a lower median on their ok seeds that are left out
    for their failed seeds), the row with the largest paired degradation, and the rows not ok on
    every seed."""
    out = []
    if cells.empty:
        return out
    real = cells[~cells["bound"]]
    for scen in dict.fromkeys(real.loc[~real["reference"], "scenario"]):
        here = real[real["scenario"] == scen]
        failing = here[here["ok"] < here["cells"]]
        not_ok = ("; not ok: " + "; ".join(f"{r['controller']} ({_status_text(r['statuses'])} of {r['cells']})"
                                           for _, r in failing.iterrows())) if len(failing) else ""
        measured = here[here["median"].notna()].sort_values("median", kind="stable")
        d = measured[measured["ok"] == measured["cells"]]
        if d.empty:
            text = (f"on {scen}, no controller finished a seed ok" if measured.empty
                    else f"on {scen}, no controller finished every seed ok")
            out.append({"scenario": scen, "text": text + not_ok + "."})
            continue
        best = d.iloc[0]
        tied = [r["controller"] for _, r in d.iloc[1:].iterrows() if _overlap(best, r)]
        text = (f"on {scen}, {best['controller']} holds the axis best: median peak {fmt_g(best['median'])} µrad "
                f"[{fmt_g(best['low'])}, {fmt_g(best['high'])}]")
        if np.isfinite(best["ratio"]):
            text += f", ×{fmt_g(best['ratio'], 2)} [{fmt_g(best['ratio_low'], 2)}, {fmt_g(best['ratio_high'], 2)}] of its reference peak"
        text += (f"; not separable from {', '.join(tied)} (overlapping CIs)" if tied else "")
        lower = measured[(measured["ok"] < measured["cells"]) & (measured["median"] < best["median"])]
        if len(lower):
            text += ("; left out for seeds not ok, though lower on their ok seeds: "
                     + ", ".join(f"{r['controller']} ({fmt_g(r['median'])} µrad over {r['ok']} of {r['cells']} seeds)"
                                 for _, r in lower.iterrows()))
        deg = measured[np.isfinite(measured["ratio"])]
        if len(deg):
            worst = deg.loc[deg["ratio"].idxmax()]
            partial = f", over its {worst['ratio_n']} seeds ok on both" if worst["ok"] < worst["cells"] else ""
            text += (f"; {worst['controller']} degrades most: ×{fmt_g(worst['ratio'], 2)} "
                     f"[{fmt_g(worst['ratio_low'], 2)}, {fmt_g(worst['ratio_high'], 2)}] ({fmt_g(worst['median'])} µrad{partial})")
        out.append({"scenario": scen, "text": text + not_ok + ".", "best": best["controller"]})
    return out


def degradation_ranking(cells: pd.DataFrame) -> list[dict[str, Any]]:
    """Real controller rows by their *worst* paired degradation over the non-reference scenarios,
    smallest first; a row with a non-ok cell or a missing ratio is ranked last (``eligible`` False)."""
    real = cells[~cells["bound"] & ~cells["reference"]] if not cells.empty else cells
    out = []
    for ctrl, g in real.groupby("controller", sort=False):
        finite = g[np.isfinite(g["ratio"])]
        eligible = bool((g["ok"] == g["cells"]).all() and len(finite) == len(g))
        w = finite.loc[finite["ratio"].idxmax()] if len(finite) else None
        ref = cells[(cells["controller"] == ctrl) & cells["reference"]]["median"]
        out.append({"controller": ctrl, "eligible": eligible,
                    "ratio": float(w["ratio"]) if w is not None else math.nan,
                    "low": float(w["ratio_low"]) if w is not None else math.nan,
                    "high": float(w["ratio_high"]) if w is not None else math.nan,
                    "scenario": w["scenario"] if w is not None else "",
                    "reference_median": float(ref.iloc[0]) if len(ref) else math.nan})
    return sorted(out, key=lambda d: (not d["eligible"], d["ratio"] if np.isfinite(d["ratio"]) else math.inf))


def most_robust(cells: pd.DataFrame) -> dict[str, Any] | None:
    """The first eligible row of :func:`degradation_ranking` (None if there is none), ranked by
    its point ratio; ``tied`` lists the other eligible rows whose worst-ratio CI overlaps its own
    (not separable from it at 95 %)."""
    ranking = degradation_ranking(cells)
    if not ranking or not ranking[0]["eligible"]:
        return None
    first = ranking[0]
    tied = [d["controller"] for d in ranking[1:] if d["eligible"] and d["low"] <= first["high"]
            and first["low"] <= d["high"]]
    return {**first, "tied": tied}


def _representative(cells: pd.DataFrame, family: str, reference: str) -> str | None:
    """The family's row with the lowest median peak on the reference: chosen once, on the
    reference, and then run on every plant (no retuning per plant)."""
    d = cells[(cells["family"] == family) & cells["reference"] & ~cells["bound"] & cells["median"].notna()]
    if d.empty:
        return None
    return str(d.loc[d["median"].idxmin(), "controller"])


def _design(family: str, row: str, reference: str) -> str:
    """How a claim names the row it tests: the family's own name when the row is the family's
    registered controller at its defaults, else the design and the row actually run."""
    return family if row == family else f"the {family} design (here {row}, the family's best on {reference})"


def _claim(key: str, claim: str, source: str, claimed: str, criterion, unit: str, value: float | None,
           text: str, basis: str, ci: tuple[float, float] | None) -> ClaimRow:
    return ClaimRow(key=key, claim=claim, source=source, claimed=claimed, measured=text,
                    criterion=criterion.describe(unit), verdict=verdict(value, criterion, ci), value=value, basis=basis)


def _failures(results: pd.DataFrame, ctrl: str, scen: str) -> tuple[int, int, dict[str, int]]:
    """(seeds not ok, seeds, {status: count}) of one controller row × scenario."""
    g = results[(results["controller"] == ctrl) & (results["scenario"] == scen)]
    bad = g.loc[g["status"] != "ok", "status"].value_counts()
    return int(bad.sum()), len(g), {str(k): int(v) for k, v in bad.items()}


def _failure_text(ctrl: str, k: int, n: int, bad: Mapping[str, int]) -> str:
    if not k:
        return ""
    each = ", ".join(f"{s} {c} of {n}" for s, c in sorted(bad.items()))
    return f"; {ctrl} not ok on {k} of {n} seeds ({each}), excluded from the pairs"


def _paired_claim(results: pd.DataFrame, scen: str, column: str, num: str, den: str, subject: str,
                  key: str, claim: str, source: str, claimed: str, criterion, unit: str, label: str,
                  basis: str, extra: str = "") -> ClaimRow:
    """A claim about ``subject`` (``num`` or ``den``) from the paired ratio num/den of ``column``
    on ``scen`` (``extra`` follows the CI in the measured text). The pairs hold only the seeds ok on both, so the failed seeds bound the verdict:
    a seed the subject failed counts against the claim (``reproduced`` becomes ``inconclusive``;
    failed on every seed: ``not reproduced``); a seed the other row failed may count for it
    (``not reproduced`` becomes ``inconclusive``)."""
    other = den if subject == num else num
    pr = _paired(_per_seed(results, num, scen, column), _per_seed(results, den, scen, column))
    k_s, n_s, bad_s = _failures(results, subject, scen)
    k_o, n_o, bad_o = _failures(results, other, scen)
    value = pr.ratio if pr.n else None
    text = (f"{label}, paired by seed: {fmt_g(pr.ratio)}{unit} [95 % CI {fmt_g(pr.low)}–{fmt_g(pr.high)}, {pr.n} seeds]{extra}"
            + _failure_text(num, *_failures(results, num, scen)) + _failure_text(den, *_failures(results, den, scen)))
    v = verdict(value, criterion, (pr.low, pr.high) if pr.n >= 2 else None)
    if n_s and k_s == n_s:
        v, text = NOT_REPRODUCED, text + f"; not reproduced: {subject} finished no seed ok"
    elif k_s and v in (REPRODUCED, NOT_MEASURED):
        v, text = INCONCLUSIVE, text + (f"; inconclusive: {subject}'s {k_s} failed seeds count against the claim "
                                        "and are not in the pairs")
    elif k_o and v in (NOT_REPRODUCED, NOT_MEASURED):
        v, text = INCONCLUSIVE, text + (f"; inconclusive: {other}'s {k_o} failed seeds may count for the claim "
                                        "and are not in the pairs")
    return ClaimRow(key=key, claim=claim, source=source, claimed=claimed, measured=text,
                    criterion=criterion.describe(unit), verdict=v, value=value, basis=basis)


def robustness_claims(results: pd.DataFrame, cells: pd.DataFrame, selection: Selection,
                      reference: str) -> list[ClaimRow]:
    """Per non-reference scenario: ``robust_ten_times.<S>`` (best LTI row on S / the solnic family's
    thesis-chosen row, peak, ≥ 10), ``robust_less_current.<S>`` (that solnic row / that LTI row,
    mean current, < 1) and ``robust_pulse_width.<S>`` (the adaptive-pulse family's thesis-chosen
    row / the solnic row, peak, < 1); paired by seed, verdict from the 95 % CI, bounded by the
    seeds either row failed (:func:`_paired_claim`). The claim text names the row tested."""
    if cells.empty:
        return []
    rows: list[ClaimRow] = []
    subject = _representative(cells, selection.solnic, reference)
    peer = _representative(cells, selection.adaptive_pulse, reference)
    sol = _design(selection.solnic, subject, reference) if subject else selection.solnic
    for scen in dict.fromkeys(cells.loc[~cells["reference"], "scenario"]):
        here = cells[(cells["scenario"] == scen) & ~cells["bound"]]
        lti = here[(here["family"] == selection.linear) & here["median"].notna()]
        whole = lti[lti["ok"] == lti["cells"]]            # rows ok on every seed first
        lti = whole if len(whole) else lti
        lti_row = str(lti.loc[lti["median"].idxmin(), "controller"]) if len(lti) else None
        src = f"§8.1, §8.2 on the real plant {scen!r} (issue 24)"
        ten = f"On {scen}, {sol} is at least ten times more accurate than any LTI servo"
        if subject is None or lti_row is None:
            why = f"needs ok {selection.solnic} and {selection.linear} family cells on {reference} and {scen}"
            rows.append(_claim(f"robust_ten_times.{scen}", ten, src, "≥ 10×", at_least(10.0), "×", None,
                               f"not measured in this run ({why})", "", None))
        else:
            rows.append(_paired_claim(
                results, scen, _ERROR, lti_row, subject, subject, f"robust_ten_times.{scen}", ten, src, "≥ 10×",
                at_least(10.0), "×", f"{lti_row} / {subject} peak",
                f"LTI side: the most accurate {selection.linear}-family row on {scen} (generous to the baseline; "
                f"rows ok on every seed first); solnic side: the {selection.solnic}-family row best on {reference}, "
                "not retuned; told Table 2-1"))
            rows.append(_paired_claim(
                results, scen, _CURRENT, subject, lti_row, subject, f"robust_less_current.{scen}",
                f"On {scen}, {sol} runs at a lower average current than that LTI servo",
                f"abstract; §8.1 on the real plant {scen!r}", "< 1", below(1.0), "", f"{subject} / {lti_row} mean |i|",
                "the rows of the accuracy claim above; mean_abs_current (1/T)∫|x3|dt"))
        pulse = (f"On {scen}, adaptive pulse-width control"
                 + (f" (here {peer}, the {selection.adaptive_pulse} family's best on {reference})" if peer else "")
                 + f" beats {sol}")
        if subject is None or peer is None:
            why = f"needs ok {selection.adaptive_pulse} and {selection.solnic} family cells on {reference} and {scen}"
            rows.append(_claim(f"robust_pulse_width.{scen}", pulse, "docs/results.md (thesis, ratio-2)", "< 1",
                               below(1.0), "×", None, f"not measured in this run ({why})", "", None))
            continue
        pp = _paired(_per_seed(results, peer, scen, _ERROR), _per_seed(results, subject, scen, _ERROR))
        rows.append(_paired_claim(
            results, scen, _ERROR, peer, subject, peer, f"robust_pulse_width.{scen}", pulse,
            "docs/results.md (thesis, ratio-2), tested on a real plant", "< 1", below(1.0), "×",
            f"{peer} / {subject} peak", f"each family's row best on {reference}, not retuned; told Table 2-1",
            f", P({peer} lower) = {fmt_g(pp.p_improvement)}"))
    return rows


def robustness_context(results: pd.DataFrame, config: Mapping[str, Any]) -> dict[str, Any] | None:
    """Everything the template's robustness section shows, or None without a robustness table."""
    from reports.figures import figure_div

    if not has_robustness(config) or results.empty:
        return None
    table = _table(config)
    selection = Selection.from_config(config)
    reference = table.get("reference") or selection.thesis_scenario
    cells = cell_table(results, config)
    if cells.empty:
        return None
    fig = heatmap_figure(cells)
    height = 160 + 28 * cells["controller"].nunique()
    scenarios = list(dict.fromkeys(cells["scenario"]))
    grid = []
    for ctrl, g in cells.groupby("controller", sort=False):
        by = {r["scenario"]: r for _, r in g.iterrows()}
        grid.append({"controller": ctrl, "bound": bool(g["bound"].any()), "best_of": g["best_of"].iloc[0],
                     "cells": [by.get(s) for s in scenarios]})
    return {"reference": reference, "scenarios": scenarios, "grid": grid,
            "div": None if fig is None else figure_div(fig, "fig-robustness", height),
            "verdicts": verdicts(cells), "most_robust": most_robust(cells), "ranking": degradation_ranking(cells),
            "claims": robustness_claims(results, cells, selection, reference),
            "best_source": table.get("best_source", ""), "told_nominal": dict(table.get("told_nominal") or {}),
            "n_seeds": int(results["seed"].nunique()), "method": METHOD_TEXT}
