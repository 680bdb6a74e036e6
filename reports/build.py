"""Build the self-contained HTML report.

:func:`build_report` takes the run's data in memory; :func:`build_report_from_dir` reads a run
directory in the layout documented in :mod:`reports.inputs`. Both write ``out_dir/report.html``
atomically (temporary file in the same directory, then ``os.replace``) and return its path.

The page embeds plotly.js once, inline, and draws every figure with it in the browser. It loads
nothing from the network: no CDN, no web fonts, no images by URL.
"""

from __future__ import annotations

import base64
import datetime as _dt
import gzip
import json
import math
import platform
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
import pandas as pd
import plotly
import plotly.offline

from reports import answer as _answer
from reports import claims as _claims
from reports import figures as _fig
from reports import frontier as _frontier
from reports import robustness as _robustness
from reports.plants import plants_context
from reports.inputs import (ReportInputs, SeriesRun, attribute_series,
                            load_inputs, normalise_bound, normalise_hunting, normalise_results,
                            normalise_speed)
from reports.limits import PlantLimits, limits_from_config, scenario_limits
from reports.settings import settings_rows
from reports.stats import METHOD_TEXT, median_ci
from bench.store import write_atomic

__all__ = ["build_report", "build_report_from_dir", "render_html", "REPORT_NAME"]

REPORT_NAME = "report.html"

# (column, label, scale) of the per-cell table; errors are shown in µrad.
_RESULT_COLUMNS = (
    ("peak_error_rad", "peak |x1| [µrad]", 1e6),
    ("rms_error_rad", "RMS x1 [µrad]", 1e6),
    ("p99_error_rad", "p99 |x1| [µrad]", 1e6),
    ("mean_abs_current", "mean |i| [ozf·in]", 1.0),
    ("rms_current", "RMS i [ozf·in]", 1.0),
    ("supply_charge_rate", "supply charge rate [ozf·in]", 1.0),
    ("runtime_s", "runtime [s]", 1.0),
    ("realtime_factor", "real-time factor", 1.0),
    ("n_events", "events", 1.0),
    ("n_corrections", "corrections", 1.0),
)

_FIGURE_QUOTES = {
    "7-2": ("The largest positional error was about 25.7 micro-radians, and it occurred about "
            "five seconds after the controller was started.",),
    "7-3": ("The system was operating consistently with peak errors of 0.94, 1.4, and 2.0 "
            "micro-radians for the small, medium, and large Δc's, respectively.",
            "The minimum obtainable peak error for this plant using a classical, linear, "
            "time-invariant controller is given by equation (2-6) as about seven micro-radians."),
    "7-4": ("The estimates for k_s and k_c were 71 and 102 percent of their correct values, "
            "respectively. [20 s]",
            "The estimate for k_s was equal to about 95 percent of its true value. [54 s]",
            "The correlation between the two estimates was -0.65 according to the covariance "
            "matrix in the filter."),
    "7-5": ("The first cost-function computation and Δt_u,inc adjustment occurred at 20 seconds.",
            "At 54 seconds, the controller computed the cost functions for the fourteenth time.",
            "[The controller] had adjusted the size ratio for the large and small positional "
            "corrections to 2.1."),
}
_FIGURE_CLAIMS = {
    "7-2": ("largest_error", "largest_error_time", "leave_startup_sizes"),
    "7-3": ("peak_small", "peak_medium", "peak_large", "two_sevenths"),
    "7-4": ("ks_at_20", "kc_at_20", "ks_at_54", "kc_at_54", "within_6pct_54",
            "ks_kc_correlation"),
    "7-5": ("first_cost_update", "fourteenth_cost_update", "size_ratio"),
}


# --------------------------------------------------------------------------- formatting

def _num(x: Any, digits: int = 3) -> str:
    if x is None:
        return "—"
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(v):
        return "—"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    if v == int(v) and abs(v) < 1e6:
        return f"{int(v):d}".replace("-", "−")
    return f"{v:.{digits}g}".replace("-", "−")


def _sortkey(x: Any) -> str:
    """Value for the ``data-v`` attribute used by the sorting script ('' sorts last)."""
    if x is None:
        return ""
    if isinstance(x, (int, float, np.integer, np.floating)):
        v = float(x)
        return "" if math.isnan(v) else repr(v)
    return str(x)


def _cell(text: Any, sort: Any = None, cls: str = "") -> dict[str, str]:
    return {"text": str(text), "v": _sortkey(text if sort is None else sort), "cls": cls}


# --------------------------------------------------------------------------- tables

def _results_table(results: pd.DataFrame) -> dict[str, Any]:
    present = [(c, lbl, k) for c, lbl, k in _RESULT_COLUMNS if c in results.columns]
    missing = [c for c, _, _ in _RESULT_COLUMNS if c not in results.columns]
    header = ["controller", "scenario", "seed", "status", "message"] + [l for _, l, _ in present]
    rows, ids = [], []
    for _, r in results.sort_values(["scenario", "controller", "seed"]).iterrows():
        ids.append(str(r["cell"]) if "cell" in results.columns and pd.notna(r["cell"]) else "")
        cells = [_cell(r["controller"]), _cell(r["scenario"]), _cell(r["seed"], float(r["seed"])),
                 _cell(r["status"], cls="ok" if r["status"] == "ok" else "bad"),
                 _cell(r["message"], cls="msg")]
        for col, _, k in present:
            v = r[col] * k if pd.notna(r[col]) else math.nan
            cells.append(_cell(_num(v), v, "num"))
        rows.append(cells)
    return {"header": header, "rows": rows, "missing": missing, "ids": ids,
            "numeric_from": 5}


def _aggregate_table(results: pd.DataFrame) -> dict[str, Any]:
    if results.empty:
        return {"header": [], "rows": []}
    header = ["controller", "scenario", "ok / cells"]
    has_peak = "peak_error_rad" in results.columns
    if has_peak:
        header += ["peak median [95 % CI] [µrad]", "peak mean [µrad]", "peak worst [µrad]",
                   "peak spread (sd) [µrad]"]
    means = [(c, lbl, k) for c, lbl, k in _RESULT_COLUMNS[1:] if c in results.columns]
    header += [f"{lbl} (mean)" for _, lbl, _ in means]
    rows = []
    for (ctrl, scen), g in results.groupby(["controller", "scenario"], sort=True):
        ok = g[g["status"] == "ok"]
        cells = [_cell(ctrl), _cell(scen),
                 _cell(f"{len(ok)} / {len(g)}", len(ok) / len(g),
                       "num" if len(ok) == len(g) else "num bad")]
        if has_peak:
            p = ok["peak_error_rad"].dropna() * 1e6
            ci = median_ci(p.to_numpy())
            cells.append(_cell(f"{_num(ci.median)} [{_num(ci.low)}, {_num(ci.high)}]" if ci.n else "—",
                               ci.median, "num"))
            sd = float(p.std(ddof=1)) if len(p) > 1 else math.nan
            for v in (p.mean() if len(p) else math.nan, p.max() if len(p) else math.nan, sd):
                cells.append(_cell(_num(v), v, "num"))
        for col, _, k in means:
            s = ok[col].dropna() * k
            v = float(s.mean()) if len(s) else math.nan
            cells.append(_cell(_num(v), v, "num"))
        rows.append(cells)
    return {"header": header, "rows": rows}


def _speed_table(speed: Mapping[str, Any] | None) -> list[list[dict[str, str]]]:
    if not speed:
        return []
    return [[_cell(_fig.method_label(r["method"])), _cell(r["setting"]), _cell(_num(r["error"]), r["error"], "num"),
             _cell(_num(r["wall_s"]), r["wall_s"], "num"),
             _cell(_num(r["realtime_factor"]), r["realtime_factor"], "num")]
            for r in speed["rows"]]


def _weak_table(speed: Mapping[str, Any] | None) -> list[list[dict[str, str]]]:
    """Rows of the noisy weak-error comparison (speed.json ``weak_error``), µrad and µs."""
    weak = (speed or {}).get("weak_error")
    if not isinstance(weak, Mapping):
        return []
    rows = []
    for r in weak.get("rows", []):
        def urad(key: str) -> float:
            v = r.get(key)
            return math.nan if v is None else float(v) * 1e6

        def ci(w: str) -> str:
            c = r.get(f"{w}_error_ci_rad")
            return "—" if not c else f"[{_num(c[0] * 1e6)}, {_num(c[1] * 1e6)}]"
        step = r.get("step_s")
        wall = math.nan if r.get("wall_per_path_s") is None else float(r["wall_per_path_s"]) * 1e6
        rows.append([_cell("exact (multimode)" if step is None else "Euler–Maruyama"),
                     _cell("—" if step is None else f"h = {_num(step)} s"),
                     _cell(_num(urad("mean_rad")), urad("mean_rad"), "num"), _cell(ci("mean")),
                     _cell(_num(urad("p95_rad")), urad("p95_rad"), "num"), _cell(ci("p95")),
                     _cell(_num(wall), wall, "num")])
    return rows


def _coupled_table(speed: Mapping[str, Any] | None) -> list[list[dict[str, str]]]:
    """Rows of the coupled weak-error study (speed.json ``weak_error_coupled``): errors in % of
    the exact mean Δc with their 95 % CIs, and EM's wall per path [µs]."""
    coupled = (speed or {}).get("weak_error_coupled")
    if not isinstance(coupled, Mapping) or not coupled.get("exact_mean_rad"):
        return []
    m = float(coupled["exact_mean_rad"])

    def pct(v: Any) -> float:
        return math.nan if v is None else 100.0 * float(v) / m

    def ci(c: Any) -> str:
        return "—" if not c else f"[{_num(pct(c[0]))}, {_num(pct(c[1]))}]"

    rows = []
    for r in coupled.get("rows", []):
        wall = float(r["wall_per_path_s"]) * 1e6
        rows.append([_cell(f"h = {_num(r['step_s'])} s"),
                     _cell(_num(pct(r["mean_error_rad"])), pct(r["mean_error_rad"]), "num"),
                     _cell(ci(r["mean_error_ci_rad"])), _cell(ci(r["vs_fine_mean_ci_rad"])),
                     _cell(ci(r["vs_fine_p95_ci_rad"])), _cell(ci(r["vs_fine_w1_ci_rad"])),
                     _cell(_num(wall), wall, "num")])
    return rows


def _closed_loop_table(speed: Mapping[str, Any] | None) -> list[list[dict[str, str]]]:
    """Rows of the closed-loop EM study (speed.json ``closed_loop_em``): peak error over seeds in
    µrad with bootstrap CIs, EM − exact in % of the exact statistic with its CI, CPU per cell."""
    closed = (speed or {}).get("closed_loop_em")
    if not isinstance(closed, Mapping) or not closed.get("rows"):
        return []
    ex = closed["rows"][0]

    def urad(c: Any) -> str:
        return "—" if not c else f"[{_num(float(c[0]) * 1e6)}, {_num(float(c[1]) * 1e6)}]"

    def pct(r: Mapping[str, Any], w: str) -> str:
        c = r.get(f"{w}_diff_ci_rad")
        if not c:
            return "—"
        ref = float(ex[f"{w}_rad"])
        return f"{_num(r[f'{w}_diff_pct'])} [{_num(100 * float(c[0]) / ref)}, {_num(100 * float(c[1]) / ref)}]"

    rows = []
    for r in closed["rows"]:
        step = r.get("step_s")
        cpu = float(r["cpu_per_cell_s"])
        ratio = r.get("cost_ratio")
        rows.append([_cell("exact (multimode)" if step is None else f"Euler–Maruyama, h = {_num(step)} s"),
                     _cell(_num(float(r["median_rad"]) * 1e6), float(r["median_rad"]) * 1e6, "num"),
                     _cell(urad(r["median_ci_rad"])), _cell(pct(r, "median")),
                     _cell(_num(float(r["p95_rad"]) * 1e6), float(r["p95_rad"]) * 1e6, "num"),
                     _cell(urad(r["p95_ci_rad"])), _cell(pct(r, "p95")),
                     _cell(_num(cpu), cpu, "num"), _cell("1" if ratio is None else _num(ratio)),
                     _cell(r.get("verdict", "reference"))])
    return rows


def _hunting_table(hunting: pd.DataFrame | None) -> list[list[dict[str, str]]]:
    if hunting is None:
        return []
    rows = []
    for _, r in hunting.sort_values("ks_over_kc").iterrows():
        onset = r["onset_L"]
        rel = onset / r["lmax"] if pd.notna(onset) else math.nan
        rows.append([_cell(_num(r["ks_over_kc"]), r["ks_over_kc"], "num"),
                     _cell(_num(r["lmax"]), r["lmax"], "num"),
                     _cell(_num(onset) if pd.notna(onset) else "none found", onset, "num"),
                     _cell(_num(rel), rel, "num")])
    return rows


def _bound_summary(bound: pd.DataFrame | None) -> dict[str, Any] | None:
    """Counts of the (2-6) check that agree with its claim row: runs, stable designs, scored
    (stable with a measured θ/θb), and the stable ones not scored by status (skipped = did not
    fit the sweep's time cap, unsteady = no breakaway in the scoring window)."""
    if bound is None:
        return None
    st = bound[bound["stable"]]
    scored = st[st["ratio"].notna()]
    status = (st.loc[st["ratio"].isna(), "status"].fillna("unknown").astype(str)
              if "status" in st.columns else pd.Series(["not scored"] * int(st["ratio"].isna().sum())))
    return {"n": len(bound), "n_stable": len(st), "n_unstable": len(bound) - len(st),
            "n_scored": len(scored),
            "not_scored": sorted(status.value_counts().items()),
            "n_violations": int((scored["ratio"] < 1.0).sum()),
            "omega_range": f"{_num(bound['omega_c'].min())}–{_num(bound['omega_c'].max())}",
            "lag_values": ", ".join(_num(x) for x in sorted(bound["lag_ratio"].dropna().unique())),
            "ratios": ", ".join(_num(x) for x in sorted(bound["ks_over_kc"].dropna().unique())),
            "inertias": ", ".join(_num(x) for x in sorted(bound["inertia"].dropna().unique()))}


# --------------------------------------------------------------------------- provenance

def _git_revision_from_files(start: Path) -> str | None:
    """HEAD commit of the repository holding ``start``, read from ``.git`` files (no git call)."""
    for d in (start, *start.parents):
        git = d / ".git"
        if git.is_file():
            text = git.read_text().strip()
            if not text.startswith("gitdir:"):
                return None
            git = (d / text.split(":", 1)[1].strip()).resolve()
        if git.is_dir():
            try:
                head = (git / "HEAD").read_text().strip()
            except OSError:
                return None
            if not head.startswith("ref:"):
                return head
            ref = head.split(":", 1)[1].strip()
            common = git
            if (git / "commondir").exists():
                common = (git / (git / "commondir").read_text().strip()).resolve()
            for base in (git, common):
                if (base / ref).exists():
                    return (base / ref).read_text().strip()
            packed = common / "packed-refs"
            if packed.exists():
                for line in packed.read_text().splitlines():
                    parts = line.split()
                    if len(parts) == 2 and parts[1] == ref:
                        return parts[0]
            return f"{ref} (no commit yet)"
    return None


def _build_info() -> dict[str, str]:
    here = Path(__file__).resolve().parent
    return {
        "report built (UTC)": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "report code revision": _git_revision_from_files(here) or "unknown (not a git checkout)",
        "python": platform.python_version(),
        "plotly (python / embedded plotly.js)": f"{plotly.__version__} / {_plotly_js_version()}",
        "pandas": pd.__version__,
        "numpy": np.__version__,
    }


# The partial "basic" plotly.js bundle (scatter, bar, pie; the report draws scatter traces only),
# vendored from npm plotly.js-basic-dist-min at the plotly.js version of the installed plotly
# package: 1.2 MB instead of the full 4.8 MB bundle. The full bundle is the fallback when the
# versions differ.
_BASIC_BUNDLE = Path(__file__).resolve().parent / "vendor" / "plotly-basic.min.js"


@lru_cache(maxsize=1)
def _plotly_js() -> str:
    full = plotly.offline.get_plotlyjs()
    js = full
    if _BASIC_BUNDLE.exists():
        basic = _BASIC_BUNDLE.read_text(encoding="utf-8")
        if _bundle_version(basic) == _bundle_version(full):
            js = basic
    if "</script" in js.lower():  # cannot happen with plotly's bundle; guard the inlining
        raise RuntimeError("plotly.js bundle contains '</script' and cannot be inlined")
    return js


def _bundle_version(js: str) -> str:
    for token in js[:200].split():
        if token.startswith("v") and token[1:2].isdigit():
            return token
    return "unknown"


@lru_cache(maxsize=1)
def _plotly_bundle_b64() -> str:
    """The bundle gzip-compressed (level 9, mtime 0: reproducible) and base64-encoded; the page
    unpacks it with the browser's DecompressionStream (0.53 MB instead of 1.19 MB)."""
    return base64.b64encode(gzip.compress(_plotly_js().encode("utf-8"), compresslevel=9,
                                          mtime=0)).decode("ascii")


@lru_cache(maxsize=1)
def _plotly_js_version() -> str:
    js = _plotly_js()
    kind = "basic partial bundle" if "(basic" in js[:200] else "full bundle"
    return (f"{_bundle_version(js)} ({kind}, {len(js.encode()) / 1e6:.2f} MB, inlined gzip+base64 "
            f"{len(_plotly_bundle_b64()) / 1e6:.2f} MB)")


# --------------------------------------------------------------------------- rendering

@lru_cache(maxsize=1)
def _environment() -> jinja2.Environment:
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("reports", "templates"),
        autoescape=jinja2.select_autoescape(["html", "j2"], default=True),
        undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.filters["num"] = _num
    env.filters["tojson_pretty"] = lambda v: json.dumps(v, indent=2, sort_keys=True, default=str,
                                                        ensure_ascii=False)
    return env


def _typical_run(series: Mapping[str, SeriesRun], sel: _claims.Selection) -> SeriesRun | None:
    if not series:
        return None
    if sel.typical_cell is not None:
        if sel.typical_cell not in series:
            raise ValueError(f"config.report.typical_cell {sel.typical_cell!r} has no series; "
                             f"available: {sorted(series)}")
        return series[sel.typical_cell]
    runs = sorted(series.values(), key=lambda r: (r.controller != sel.solnic,
                                                  r.scenario != sel.thesis_scenario,
                                                  r.seed if r.seed is not None else 0, r.cell))
    return runs[0]


def _plants_tables(config: Mapping[str, Any], results: pd.DataFrame) -> dict[str, Any]:
    """:func:`reports.plants.plants_context` as table cells."""
    ctx = plants_context(config, results)
    scen = [[_cell(r["name"]), _cell(r["family"]), _cell(r["told"]), _cell(r["mismatch"])] for r in ctx["scenarios"]]
    factors = [[_cell(c) for c in row] for row in ctx["factors"]["rows"]]
    return {"all_default": ctx["all_default"], "scenarios": scen, "factors_header": ctx["factors"]["header"],
            "factors": factors}


def render_html(inputs: ReportInputs) -> str:
    """The report page for normalised ``inputs`` (see :func:`reports.inputs.load_inputs`)."""
    config, meta = inputs.config, inputs.meta
    limits: PlantLimits = limits_from_config(config)
    selection = _claims.Selection.from_config(config)
    warmup = float(config.get("warmup_s", 20.0))
    rows = _claims.evaluate_claims(results=inputs.results, limits=limits, series=inputs.series,
                                   bound=inputs.bound, hunting=inputs.hunting,
                                   speed=inputs.speed, selection=selection, warmup_s=warmup)
    frontier = _frontier.frontier_context(inputs.results, config)
    if frontier is not None:
        rows = list(rows) + list(frontier["claims"])
    robustness = _robustness.robustness_context(inputs.results, config)
    if robustness is not None:
        rows = list(rows) + list(robustness["claims"])
    by_key = {r.key: r for r in rows}
    typical = _typical_run(inputs.series, selection)

    figs: dict[str, str | None] = {}

    def add(name: str, fig: Any, height: int = 440) -> None:
        figs[name] = None if fig is None else _fig.figure_div(fig, f"fig-{name}", height)

    scen_limits = scenario_limits(config)
    n_scen = inputs.results["scenario"].nunique() if len(inputs.results) else 0
    add("peak-vs-current", _fig.accuracy_vs_current(inputs.results, scen_limits, limits),
        460 + 300 * max(0, math.ceil(n_scen / 3) - 1))
    n_ctrl = inputs.results["controller"].nunique() if len(inputs.results) else 0
    add("peak-intervals", _fig.peak_intervals(inputs.results, scen_limits, limits),
        160 + 28 * n_ctrl)
    add("7-2", _fig.error_vs_time(typical, limits, 1))
    add("7-3", _fig.error_vs_time(typical, limits, 2))
    add("7-4", _fig.friction_estimates(typical))
    add("7-5", _fig.cost_and_ratio(typical))
    add("bound-omega", _fig.bound_vs_crossover(inputs.bound), 480)
    add("bound-lag", _fig.bound_vs_lag(inputs.bound), 480)
    add("hunting", _fig.hunting_onset(inputs.hunting))
    add("speed", _fig.work_precision(inputs.speed), 480)

    counts = {v: sum(r.verdict == v for r in rows)
              for v in (_claims.REPRODUCED, _claims.NOT_REPRODUCED, _claims.INCONCLUSIVE, _claims.NOT_MEASURED)}
    figure_panels = [
        {"id": fid, "title": title, "div": figs[fid], "quotes": _FIGURE_QUOTES[fid],
         "claims": [by_key[k] for k in _FIGURE_CLAIMS[fid]], "needs": needs}
        for fid, title, needs in (
            ("7-2", "Figure 7-2 — error versus time", "series column x1"),
            ("7-3", "Figure 7-3 — error versus time, continued", "series column x1"),
            ("7-4", "Figure 7-4 — friction estimates versus time",
             "series columns ks_hat_pct, kc_hat_pct"),
            ("7-5", "Figure 7-5 — cost and Δc ratio versus time",
             "series columns cost_small, cost_medium, cost_large, dc_ratio"))]
    speedup = inputs.speed.get("speedup_vs_fixed_step_at_1e-6") if inputs.speed else None
    sp = inputs.speed or {}
    fixed_need = ((sp.get("equal_accuracy") or {}).get("fixed_step")) or {}
    speed_lower = sp.get("speedup_vs_fixed_step_at_1e-6_lower_bound")
    answers = _answer.scenario_answers(inputs.results)
    picks = _answer.budget_picks(inputs.results)
    limit_of = {k: v.classical_limit_rad * 1e6 for k, v in scen_limits.items()}
    budget_groups = [(scen, [p for p in picks if p.scenario == scen])
                     for scen in dict.fromkeys(p.scenario for p in picks)]
    modes = {"matrix": ((config.get("matrix") or {}).get("description") or "not recorded"),
             "bound": inputs.modes.get("bound", "not recorded"),
             "speed": str(sp.get("mode", "not recorded"))}
    sections = [("answer", "The answer"), ("plots", "Accuracy and current")]
    if frontier:
        sections.append(("frontier", "Frontier"))
    if robustness is not None:
        sections.append(("robustness", "Robustness"))
    sections += [("claims", "Claims"), ("figures", "Figures 7-2…7-5"), ("inequality", "Inequality (2-6)"),
                 ("speed", "Speed"), ("controllers", "Controllers"), ("plants", "Plants"),
                 ("results", "Per-cell results"), ("glossary", "Glossary"), ("provenance", "Provenance")]
    controller_settings = settings_rows(inputs.results)
    for row in controller_settings:
        spec = (config.get("controllers") or {}).get(row["controller"]) or {}
        opts = dict(spec.get("options") or {})
        row["configured"] = ", ".join(
            [f"design {spec['base']}" if spec.get("base") and spec.get("base") != row["controller"] else ""]
            + [f"preset {spec['preset']}" if spec.get("preset") else ""]
            + [f"{k} = {v}" for k, v in sorted(opts.items())]).strip(", ").replace(", , ", ", ") or "defaults"

    context = {
        "title": "solnic-bench report",
        "plotly_b64": _plotly_bundle_b64(),
        "deferred_script": _fig.DEFERRED_SCRIPT,
        "synthetic": bool(meta.get("synthetic", False)),
        "meta": meta,
        "meta_items": sorted((str(k), v) for k, v in meta.items()),
        "config": config,
        "build_info": _build_info(),
        "notes": list(inputs.notes),
        "limits": limits,
        "classical_limit_urad": limits.classical_limit_rad * 1e6,
        "warmup_s": warmup,
        "selection": selection,
        "claims": rows,
        "claim": by_key,
        "counts": counts,
        "results_table": _results_table(inputs.results),
        "aggregate_table": _aggregate_table(inputs.results),
        "stats_method": METHOD_TEXT,
        "frontier": frontier,
        "robustness": robustness,
        "plants": _plants_tables(config, inputs.results),
        "n_cells": len(inputs.results),
        "n_ok": int((inputs.results["status"] == "ok").sum()) if len(inputs.results) else 0,
        "figs": figs,
        "figure_panels": figure_panels,
        "typical": typical,
        "series_cells": sorted(inputs.series),
        "bound_summary": _bound_summary(inputs.bound),
        "hunting_rows": _hunting_table(inputs.hunting),
        "speed": inputs.speed,
        "speed_rows": _speed_table(inputs.speed),
        "weak_rows": _weak_table(inputs.speed),
        "coupled_rows": _coupled_table(inputs.speed),
        "closed_loop_rows": _closed_loop_table(inputs.speed),
        "speedup": None if speedup is None or math.isnan(speedup) else speedup,
        "speed_how": fixed_need,
        "speed_lower": speed_lower,
        "method_label": _fig.method_label,
        "answers": answers,
        "budget_groups": budget_groups,
        "limit_of": limit_of,
        "modes": modes,
        "sections": sections,
        "controller_settings": controller_settings,
        "n_controllers": n_ctrl,
        "n_scenarios": n_scen,
        "config_shown": {k: v for k, v in config.items() if k != "cells"},
        "n_config_cells": len(config.get("cells") or ()),
    }
    return _environment().get_template("report.html.j2").render(**context)


def build_report(out_dir: Path | str, *, results: pd.DataFrame | None,
                 series: Mapping[str, Any] | None = None, bound: pd.DataFrame | None = None,
                 hunting: pd.DataFrame | None = None, speed: Mapping[str, Any] | None = None,
                 config: Mapping[str, Any] | None = None,
                 meta: Mapping[str, Any] | None = None) -> Path:
    """Write ``out_dir/report.html`` from in-memory data and return its path.

    Parameters
    ----------
    out_dir : path
        Directory of the run (created if needed).
    results : DataFrame or None
        One row per cell (columns in :mod:`reports.inputs`); None or empty = matrix not run.
    series : mapping of cell id → DataFrame (or :class:`~reports.inputs.SeriesRun`), optional
        Solnic time series for figures 7-2…7-5, keyed by the results' ``cell``.
    bound, hunting : DataFrame, optional
        The (2-6) check (``bound.csv`` columns) and the hunting check (``hunting.csv``).
    speed : dict, optional
        The speed comparison (``speed.json`` layout).
    config, meta : dict
        Run configuration (``"plant"`` sets the classical limit) and provenance.

    Raises
    ------
    ValueError
        If a piece is malformed; the message names it and the column.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    res = normalise_results(results)
    notes = () if len(res) else ("No results: the benchmark matrix was not run.",)
    inputs = ReportInputs(results=res, series=attribute_series(series, res),
                          bound=normalise_bound(bound), hunting=normalise_hunting(hunting),
                          speed=normalise_speed(speed), config=dict(config or {}),
                          meta=dict(meta or {}), notes=notes)
    path = out / REPORT_NAME
    write_atomic(path, render_html(inputs))
    return path


def build_report_from_dir(out_dir: Path | str) -> Path:
    """Rebuild ``out_dir/report.html`` from whatever the run stored in ``out_dir``.

    See :mod:`reports.inputs` for the file names and columns. Missing pieces are shown as
    "not measured in this run".
    """
    out = Path(out_dir)
    inputs = load_inputs(out)
    path = out / REPORT_NAME
    write_atomic(path, render_html(inputs))
    return path
