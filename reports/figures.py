"""Plotly figures of the report. Each builder returns a ``go.Figure``, or ``None`` when the
data it needs is not in the run (the report then says "not measured in this run").

Every figure is rendered in the browser by the plotly.js embedded once in the page
(:func:`figure_div`); no figure is a static image. SVG traces only (no WebGL), so they render
in headless browsers without a GPU.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
import plotly.graph_objects as go
from plotly.subplots import make_subplots

from reports.inputs import SeriesRun
from reports.limits import PlantLimits, lag_ratio_limit

__all__ = [
    "controller_colour", "figure_div", "peak_vs_current", "error_vs_time",
    "friction_estimates", "cost_and_ratio", "bound_vs_crossover", "bound_vs_lag",
    "hunting_onset", "work_precision", "decimate_minmax", "accuracy_vs_current", "peak_intervals",
    "method_label",
]

_PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
            "#7f7f7f", "#bcbd22", "#17becf")
_SERIES_COLOUR = "#2ca02c"
_SYMBOLS = ("circle", "square", "diamond", "triangle-up", "cross", "x", "star", "hexagon")
_TEMPLATE = "plotly_white"
DEFERRED_SCRIPT = "text/x-plotly-deferred"   # a figure's script type: run after plotly.js loads
_CONFIG = {"displaylogo": False, "responsive": True,
           "modeBarButtonsToRemove": ["sendDataToCloud"]}


def controller_colour(name: str, known: Sequence[str] = ()) -> str:
    """Stable colour per controller: its position in ``known`` (the run's controllers in matrix
    order), else a hash of the name; no controller has a colour of its own."""
    idx = list(known).index(name) if name in known else sum(map(ord, name))
    return _PALETTE[idx % len(_PALETTE)]


def figure_div(fig: go.Figure, div_id: str, height: int = 440) -> str:
    """The figure as an HTML ``<div>`` plus a ``Plotly.newPlot`` script; plotly.js not included."""
    fig.update_layout(height=height, template=_TEMPLATE, margin=dict(l=70, r=30, t=50, b=60))
    html = fig.to_html(full_html=False, include_plotlyjs=False, include_mathjax=False,
                       div_id=div_id, config=_CONFIG, default_width="100%",
                       default_height=f"{height}px")
    # Deferred: the page runs these once its compressed plotly.js is unpacked (report.html.j2).
    return re.sub(r'<script(\s+type="text/javascript")?>', f'<script type="{DEFERRED_SCRIPT}">', html)


def _hline_log(fig: go.Figure, y: float, text: str, *, colour: str = "#b00", dash: str = "dash",
               width: float = 2, right: bool = False, below: bool = False) -> None:
    """Horizontal line on a log y axis with a label: shapes take data values there, while
    annotations take log10 values (plotly's rule), so the label is placed by hand."""
    fig.add_hline(y=y, line=dict(color=colour, dash=dash, width=width))
    fig.add_annotation(x=1 if right else 0, xref="paper", y=math.log10(y), yref="y", text=text,
                       showarrow=False, xanchor="right" if right else "left",
                       yanchor="top" if below else "bottom", font=dict(color=colour, size=11))


def _vline_log(fig: go.Figure, x: float, text: str) -> None:
    """Vertical line on a log x axis, labelled at the top (see :func:`_hline_log`)."""
    fig.add_vline(x=x, line=dict(color="#888", dash="dot", width=1))
    fig.add_annotation(x=math.log10(x), xref="x", y=1, yref="paper", text=text, showarrow=False,
                       yanchor="bottom", font=dict(size=10, color="#555"))


def decimate_minmax(t: np.ndarray, y: np.ndarray, max_points: int = 6000
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Thin a trace to about ``max_points`` keeping each bucket's min and max, so peaks survive."""
    t, y = np.asarray(t, float), np.asarray(y, float)
    n = t.size
    if n <= max_points:
        return t, y
    buckets = max_points // 2
    edges = np.linspace(0, n, buckets + 1).astype(int)
    keep = []
    yy = np.where(np.isnan(y), 0.0, y)
    for a, b in zip(edges[:-1], edges[1:]):
        if b <= a:
            continue
        seg = yy[a:b]
        keep.extend((a + int(np.argmin(seg)), a + int(np.argmax(seg))))
    idx = np.unique(np.array(keep))
    return t[idx], y[idx]


def peak_vs_current(results: pd.DataFrame, limits: PlantLimits) -> go.Figure | None:
    """Peak error against mean |current|, one colour per controller, one point per ok cell."""
    need = {"peak_error_rad", "mean_abs_current"}
    if results.empty or not need <= set(results.columns):
        return None
    ok = results[(results["status"] == "ok") & results["peak_error_rad"].notna()
                 & results["mean_abs_current"].notna()]
    if ok.empty:
        return None
    scenarios = sorted(ok["scenario"].unique())
    controllers = sorted(ok["controller"].unique())
    fig = go.Figure()
    for ctrl in controllers:
        d = ok[ok["controller"] == ctrl]
        fig.add_trace(go.Scatter(
            x=d["mean_abs_current"], y=d["peak_error_rad"] * 1e6, mode="markers", name=ctrl,
            marker=dict(color=controller_colour(ctrl, controllers), size=10,
                        symbol=[_SYMBOLS[scenarios.index(s) % len(_SYMBOLS)]
                                for s in d["scenario"]],
                        line=dict(width=0.5, color="#333")),
            customdata=np.stack([d["scenario"], d["seed"].astype(str)], axis=-1),
            hovertemplate=(f"<b>{ctrl}</b><br>scenario %{{customdata[0]}}, seed "
                           "%{customdata[1]}<br>peak %{y:.3g} µrad<br>mean |i| %{x:.3g} ozf·in"
                           "<extra></extra>")))
    lim = limits.classical_limit_rad * 1e6
    _hline_log(fig, lim, f"classical limit (2-6): {lim:.3g} µrad")
    _hline_log(fig, lim / 10, "limit / 10", dash="dot", width=1, below=True)
    fig.update_layout(
        title="Peak error vs mean |current| (symbol = scenario: " +
              ", ".join(f"{_SYMBOLS[i % len(_SYMBOLS)]} {s}" for i, s in enumerate(scenarios)) +
              ")",
        xaxis_title="mean |x3|, torque-equivalent current [ozf·in]",
        yaxis_title="peak |x1| in scoring window [µrad]", yaxis_type="log",
        legend_title="controller")
    return fig


def _run_label(run: SeriesRun) -> str:
    """A trace's plain name: controller, scenario and seed (the cell id only when unknown)."""
    if run.controller and run.scenario is not None:
        return f"{run.controller}, scenario {run.scenario}, seed {run.seed}"
    return str(run.cell)


def _need(run: SeriesRun | None, cols: Sequence[str]) -> bool:
    return run is not None and all(c in run.frame.columns and run.frame[c].notna().any()
                                   for c in cols)


def error_vs_time(run: SeriesRun | None, limits: PlantLimits, part: int) -> go.Figure | None:
    """Figures 7-2 (first half of the run) and 7-3 (second half): error x1 vs time."""
    if not _need(run, ("x1",)):
        return None
    f = run.frame
    t_end = float(f["t"].iloc[-1])
    mid = t_end / 2
    sel = f[(f["t"] <= mid)] if part == 1 else f[(f["t"] >= mid)]
    t, y = decimate_minmax(sel["t"].to_numpy(), sel["x1"].to_numpy() * 1e6)
    fig = go.Figure(go.Scatter(x=t, y=y, mode="lines", name="x1 (true error)",
                               line=dict(color=_SERIES_COLOUR, width=1)))
    lim = limits.classical_limit_rad * 1e6
    for sign in (1, -1):
        fig.add_hline(y=sign * lim, line=dict(color="#b00", dash="dash", width=1))
    fig.add_annotation(x=1, xref="paper", y=lim, text=f"±classical limit {lim:.3g} µrad",
                       showarrow=False, xanchor="right", yanchor="bottom",
                       font=dict(color="#b00"))
    fig.update_layout(title=f"Figure 7-{2 if part == 1 else 3}: error versus time"
                            f"{'' if part == 1 else ', continued'} — {_run_label(run)}",
                      xaxis_title="time [s]", yaxis_title="x1 = c − r [µrad]", showlegend=False)
    return fig


def friction_estimates(run: SeriesRun | None) -> go.Figure | None:
    """Figure 7-4: k̂s and k̂c as % of the true effective friction vs time."""
    if not _need(run, ("ks_hat_pct",)) and not _need(run, ("kc_hat_pct",)):
        return None
    f = run.frame
    fig = go.Figure()
    for col, name, colour in (("ks_hat_pct", "k̂s / ks", "#d62728"),
                              ("kc_hat_pct", "k̂c / kc", "#1f77b4")):
        if col in f.columns:
            t, y = decimate_minmax(f["t"].to_numpy(), f[col].to_numpy(), 4000)
            fig.add_trace(go.Scatter(x=t, y=y, mode="lines", name=name, line=dict(color=colour)))
    fig.add_hrect(y0=94, y1=106, fillcolor="#2ca02c", opacity=0.08, line_width=0,
                  annotation_text="±6 % (§1.2)", annotation_position="bottom right")
    fig.add_hline(y=100, line=dict(color="#444", width=1))
    fig.add_trace(go.Scatter(x=[20, 54, 20, 54], y=[71, 95, 102, 101.4], mode="markers",
                             name="thesis values (§7.3, §1.2)",
                             marker=dict(symbol="x", size=11, color="#000"),
                             text=["k̂s 71 %", "k̂s 95 %", "k̂c 102 %", "k̂c 101.4 %"],
                             hovertemplate="%{text} at %{x} s<extra>thesis</extra>"))
    fig.update_layout(title=f"Figure 7-4: friction estimates versus time — {_run_label(run)}",
                      xaxis_title="time [s]", yaxis_title="estimate / truth [%]")
    return fig


def cost_and_ratio(run: SeriesRun | None) -> go.Figure | None:
    """Figure 7-5: cost of each correction size and the Δc ratio vs time."""
    cost_cols = [c for c in ("cost_small", "cost_medium", "cost_large")
                 if _need(run, (c,))]
    has_ratio = _need(run, ("dc_ratio",))
    if not cost_cols and not has_ratio:
        return None
    f = run.frame
    fig = make_subplots(specs=[[{"secondary_y": True}]])
    colours = {"cost_small": "#9467bd", "cost_medium": "#2ca02c", "cost_large": "#ff7f0e"}
    for col in cost_cols:
        d = _steps(f["t"], f[col])
        fig.add_trace(go.Scatter(x=d.index, y=d.values, mode="lines", line_shape="hv",
                                 name=col.replace("cost_", "cost, ") + " Δc",
                                 line=dict(color=colours[col])), secondary_y=False)
    if has_ratio:
        d = _steps(f["t"], f["dc_ratio"])
        fig.add_trace(go.Scatter(x=d.index, y=d.values, mode="lines", line_shape="hv",
                                 name="Δc ratio (large/small)",
                                 line=dict(color="#000", dash="dot")), secondary_y=True)
        fig.add_trace(go.Scatter(x=[54], y=[2.1], mode="markers", name="thesis: 2.1 at 54 s",
                                 marker=dict(symbol="x", size=11, color="#000")),
                      secondary_y=True)
    fig.update_layout(title=f"Figure 7-5: cost and Δc ratio versus time — {_run_label(run)}",
                      xaxis_title="time [s]")
    fig.update_yaxes(title_text="cost J (6-5)", secondary_y=False)
    fig.update_yaxes(title_text="Δc ratio [–]", secondary_y=True)
    return fig


def _steps(t: pd.Series, v: pd.Series) -> pd.Series:
    """The change points of a held (step) signal, plus its last sample."""
    s = pd.Series(v.to_numpy(), index=t.to_numpy()).dropna()
    if s.empty:
        return s
    keep = np.r_[True, s.to_numpy()[1:] != s.to_numpy()[:-1]]
    keep[-1] = True
    return s[keep]


def _bound_scatter(bound: pd.DataFrame, x: str, title: str, xtitle: str,
                   colour_by: str, colour_title: str) -> go.Figure:
    fig = go.Figure()
    integral = ~np.isfinite(bound["lag_ratio"])
    for noise in (False, True):
        for is_int in (False, True):
            d = bound[bound["stable"] & (bound["noise"] == noise) & bound["ratio"].notna()
                      & (integral == is_int)]
            if d.empty:
                continue
            name = f"{'pure integral' if is_int else 'lead/lag'}, noise {'on' if noise else 'off'}"
            colour = d[colour_by].where(np.isfinite(d[colour_by]))
            marker = dict(size=9, symbol=("star" if is_int else "circle") + ("" if noise else
                                                                              "-open"))
            if colour.notna().all():
                marker.update(color=colour, coloraxis="coloraxis")
            else:
                marker.update(color="#000")
            fig.add_trace(go.Scatter(
                x=d[x], y=d["ratio"], mode="markers", name=name, marker=marker, text=d["design"],
                customdata=np.stack([d["omega_c"], d["lag_ratio"], d["ks_over_kc"],
                                     d["inertia"], d["theta_rad"] * 1e6], axis=-1),
                hovertemplate=("%{text}<br>ωc %{customdata[0]:.3g} rad/s, L %{customdata[1]:.3g}"
                               "<br>ks/kc %{customdata[2]:.3g}, J %{customdata[3]:.3g}"
                               "<br>θ %{customdata[4]:.3g} µrad, θ/θb %{y:.3g}"
                               "<extra></extra>")))
    un = bound[~bound["stable"]]
    if not un.empty and un["ratio"].notna().any():
        fig.add_trace(go.Scatter(
            x=un[x], y=un["ratio"], mode="markers",
            name="unstable / hunting (excluded from verdict)",
            marker=dict(symbol="x", color="#999", size=7), text=un["design"],
            hovertemplate="%{text} (unstable)<extra></extra>"))
    _hline_log(fig, 1.0, "θ = θb (2-6)", right=True, below=True)
    fig.update_layout(title=title, xaxis_title=xtitle, yaxis_title="θ / θb [–]",
                      yaxis_type="log", legend=dict(orientation="h", y=-0.25),
                      coloraxis=dict(colorscale="Viridis", colorbar=dict(title=colour_title)))
    return fig


def bound_vs_crossover(bound: pd.DataFrame | None) -> go.Figure | None:
    """θ/θb against the design's crossover ωc (colour = lag ratio L)."""
    if bound is None or bound.empty:
        return None
    fig = _bound_scatter(bound, "omega_c", "Inequality (2-6): θ/θb vs crossover ωc",
                         "crossover ωc [rad/s]", "lag_ratio", "L")
    fig.update_xaxes(type="log")
    return fig


def bound_vs_lag(bound: pd.DataFrame | None) -> go.Figure | None:
    """θ/θb against the lag ratio L (colour = k̄s/k̄c); pure integral plotted at the right edge."""
    if bound is None or bound.empty:
        return None
    b = bound.copy()
    finite_max = b.loc[np.isfinite(b["lag_ratio"]), "lag_ratio"].max()
    edge = (finite_max if np.isfinite(finite_max) else 1.0) * 2
    b["lag_x"] = b["lag_ratio"].where(np.isfinite(b["lag_ratio"]), edge)
    fig = _bound_scatter(b, "lag_x", "Inequality (2-6): θ/θb vs lag ratio L "
                         f"(pure integral drawn at L = {edge:.3g})", "lag ratio L [–]",
                         "ks_over_kc", "ks/kc")
    for r in sorted(b["ks_over_kc"].dropna().unique()):
        lm = lag_ratio_limit(r)
        if math.isfinite(lm):
            _vline_log(fig, lm, f"Lmax({r:g})")
    fig.update_xaxes(type="log")
    return fig


def hunting_onset(hunting: pd.DataFrame | None) -> go.Figure | None:
    """Onset of hunting vs k̄s/k̄c, with the (2-1) curve Lmax = 2r/(r−1)."""
    if hunting is None or hunting.empty:
        return None
    h = hunting.sort_values("ks_over_kc")
    r = np.linspace(max(1.05, h["ks_over_kc"].min() * 0.95), h["ks_over_kc"].max() * 1.05, 200)
    fig = go.Figure()
    fig.add_trace(go.Scatter(x=r, y=[lag_ratio_limit(x) for x in r], mode="lines",
                             name="Lmax = 2ks/(ks−kc) (2-1)", line=dict(color="#b00")))
    fig.add_trace(go.Scatter(x=h["ks_over_kc"], y=h["lmax"], mode="markers", name="Lmax (run)",
                             marker=dict(symbol="circle-open", size=12, color="#b00")))
    found = h[h["onset_L"].notna()]
    fig.add_trace(go.Scatter(x=found["ks_over_kc"], y=found["onset_L"], mode="markers",
                             name="measured hunting onset", marker=dict(size=10,
                                                                        color="#1f77b4")))
    none = h[h["onset_L"].isna()]
    if not none.empty:
        fig.add_trace(go.Scatter(x=none["ks_over_kc"], y=none["lmax"], mode="markers",
                                 name="no hunting found in swept range",
                                 marker=dict(symbol="x", size=10, color="#999")))
    fig.update_layout(title="Hunting onset vs the Bohacek–Tuteur limit (2-1)",
                      xaxis_title="ks/kc [–]", yaxis_title="lag ratio L [–]", yaxis_type="log")
    return fig


from bench.exact import EXACT_METHOD as _EXACT  # noqa: E402  (the exact simulator's label)

_METHOD_LABELS = {_EXACT: "multimode linearization (exact)", "fixed_step": "fixed-step Euler (compiled)",
                  "fixed_step_python": "fixed-step Euler (plain Python)", "solve_ivp": "scipy solve_ivp",
                  "solve_ivp_reference": "scipy solve_ivp (reference)"}


def method_label(method: str) -> str:
    """Plain name of a speed-study method (the stored id when unknown)."""
    return _METHOD_LABELS.get(method, str(method).replace("_", " "))


def work_precision(speed: Mapping[str, Any] | None) -> go.Figure | None:
    """Work-precision diagram: error against wall time, per method."""
    if not speed or not speed.get("rows"):
        return None
    df = pd.DataFrame(speed["rows"])
    df = df[(df["error"] > 0) & (df["wall_s"] > 0)]
    if df.empty:
        return None
    fig = go.Figure()
    methods = list(dict.fromkeys(df["method"]))
    for i, m in enumerate(methods):
        d = df[df["method"] == m].sort_values("wall_s")
        fig.add_trace(go.Scatter(x=d["wall_s"], y=d["error"], mode="lines+markers+text",
                                 name=method_label(m), text=d["setting"], textposition="top center",
                                 marker=dict(size=9, symbol=_SYMBOLS[i % len(_SYMBOLS)]),
                                 hovertemplate=(f"<b>{method_label(m)}</b> %{{text}}<br>wall %{{x:.3g}} s"
                                                "<br>error %{y:.3g} (relative)<extra></extra>")))
    _hline_log(fig, 1e-6, "1e-6 relative (speed-up reference)", colour="#888", dash="dot", width=1,
               right=True)
    fig.update_layout(title="Work-precision: error vs wall time (same command sequence)",
                      xaxis_title="wall time [s]", xaxis_type="log",
                      yaxis_title=f"error (relative) — {speed.get('error_metric', 'error')}",
                      yaxis_type="log")
    return fig


def _scenario_limit_urad(limits: Mapping[str, PlantLimits], scenario: str,
                         default: PlantLimits) -> float:
    return (limits.get(scenario) or default).classical_limit_rad * 1e6


def _peak_rows(results: pd.DataFrame) -> pd.DataFrame:
    """The rows every peak median of the report is taken over (answer block, aggregate table and
    both accuracy figures): status ``ok`` with a finite peak error."""
    peak = pd.to_numeric(results["peak_error_rad"], errors="coerce").astype(float)
    return results[(results["status"] == "ok") & np.isfinite(peak)]


def _not_ok_note(left: Mapping[str, Sequence[Any]], scen: str, ctrl: str) -> str:
    """Hover text for a controller that was not ok on every seed of ``scen`` ("" when it was);
    ``left`` is :func:`reports.answer.left_out` of the results."""
    for o in left.get(scen, ()):
        if o.controller == ctrl:
            return (f"<br>{o.not_ok} of {o.n} seeds not ok: median over the ok ones; "
                    "not a candidate in the answer")
    return ""


def accuracy_vs_current(results: pd.DataFrame, limits: Mapping[str, PlantLimits],
                        default: PlantLimits) -> go.Figure | None:
    """Median peak |x1| against median mean |i| on log–log axes, one panel per scenario: per
    controller the median with its 95 % bootstrap CI as whiskers (both axes), every ok cell as a
    faint point, and the scenario's own classical limit (2-6) as a dashed line.

    The peak median and its CI are over the same rows as the answer block and the aggregate
    table (:func:`_peak_rows`); only the x position (median current) and the faint points leave
    out the seeds with zero current, which a log axis cannot place (the hover says how many).
    """
    from reports.answer import left_out, privileged_mask
    from reports.stats import median_ci

    need = {"peak_error_rad", "mean_abs_current"}
    if results.empty or not need <= set(results.columns):
        return None
    ok = _peak_rows(results)
    cur = pd.to_numeric(ok["mean_abs_current"], errors="coerce").astype(float)
    placeable = ok["peak_error_rad"].gt(0) & cur.gt(0) & np.isfinite(cur)
    if not placeable.any():
        return None
    scenarios = sorted(ok.loc[placeable, "scenario"].unique())
    controllers = list(dict.fromkeys(results["controller"]))
    n = len(scenarios)
    cols = min(n, 3)
    rows = math.ceil(n / cols)
    fig = make_subplots(rows=rows, cols=cols, subplot_titles=[f"scenario {s}" for s in scenarios],
                        shared_yaxes=True, horizontal_spacing=0.04, vertical_spacing=0.12)
    bounds = set(ok.index[privileged_mask(ok)])
    left = left_out(results)
    shown: set[str] = set()
    for k, scen in enumerate(scenarios):
        r, c = k // cols + 1, k % cols + 1
        d_s = ok[ok["scenario"] == scen]
        for ctrl in controllers:
            d = d_s[d_s["controller"] == ctrl]
            dx = d[placeable[d.index]]
            if dx.empty:
                continue
            colour = controller_colour(ctrl, controllers)
            fig.add_trace(go.Scatter(
                x=dx["mean_abs_current"], y=dx["peak_error_rad"] * 1e6, mode="markers",
                marker=dict(color=colour, size=5, opacity=0.25), legendgroup=ctrl, showlegend=False,
                customdata=dx["seed"].astype(str),
                hovertemplate=(f"<b>{ctrl}</b>, {scen}, seed %{{customdata}}<br>peak %{{y:.3g}} µrad"
                               "<br>mean |i| %{x:.3g} ozf·in<extra></extra>")), row=r, col=c)
            py = median_ci(d["peak_error_rad"].to_numpy() * 1e6)
            px = median_ci(dx["mean_abs_current"].to_numpy())
            zero = len(d) - len(dx)
            x_note = (f" over the {px.n} of {len(d)} seeds with current > 0 (log axis)" if zero else "")
            label = ctrl + (" (bound)" if set(d.index) & bounds else "")
            fig.add_trace(go.Scatter(
                x=[px.median], y=[py.median], mode="markers", name=label, legendgroup=ctrl,
                showlegend=ctrl not in shown,
                marker=dict(color=colour, size=11, symbol=_SYMBOLS[controllers.index(ctrl) % len(_SYMBOLS)],
                            line=dict(width=1, color="#222")),
                error_y=dict(type="data", symmetric=False, array=[py.high - py.median],
                             arrayminus=[py.median - py.low], color=colour, thickness=1.5),
                error_x=dict(type="data", symmetric=False, array=[px.high - px.median],
                             arrayminus=[px.median - px.low], color=colour, thickness=1),
                hovertemplate=(f"<b>{ctrl}</b>, {scen}: median over {py.n} seeds<br>peak %{{y:.3g}} µrad "
                               f"[{py.low:.3g}, {py.high:.3g}]<br>mean |i| %{{x:.3g}} ozf·in "
                               f"[{px.low:.3g}, {px.high:.3g}]{x_note}"
                               f"{_not_ok_note(left, scen, ctrl)}<extra></extra>")), row=r, col=c)
            shown.add(ctrl)
        lim = _scenario_limit_urad(limits, scen, default)
        fig.add_hline(y=lim, line=dict(color="#b00", dash="dash", width=1.5), row=r, col=c)
        xref = "x domain" if k == 0 else f"x{k + 1} domain"
        yref = "y" if k == 0 else f"y{k + 1}"
        fig.add_annotation(x=0.02, xref=xref, y=math.log10(lim), yref=yref, showarrow=False,
                           text=f"(2-6) limit {lim:.3g} µrad", xanchor="left", yanchor="bottom",
                           font=dict(color="#b00", size=11))
    fig.update_xaxes(type="log", title_text="mean |current| [ozf·in]")
    fig.update_yaxes(type="log")
    for r in range(1, rows + 1):
        fig.update_yaxes(title_text="peak |error| [µrad]", row=r, col=1)
    fig.update_layout(title="Accuracy vs current: median over seeds with 95 % CI (faint: each seed)",
                      legend=dict(orientation="h", yanchor="top", y=-0.18, x=0),
                      legend_title_text="controller")
    return fig


def peak_intervals(results: pd.DataFrame, limits: Mapping[str, PlantLimits],
                   default: PlantLimits) -> go.Figure | None:
    """Median peak |x1| per controller with its 95 % bootstrap CI, one panel per scenario,
    controllers sorted by their median in the first scenario; the scenario's limit (2-6) dashed."""
    from reports.answer import left_out
    from reports.stats import median_ci

    if results.empty or "peak_error_rad" not in results.columns:
        return None
    ok = _peak_rows(results)          # the answer block's rows: its medians and CIs are these
    if not ok["peak_error_rad"].gt(0).any():
        return None
    left = left_out(results)
    scenarios = sorted(ok["scenario"].unique())
    controllers = list(dict.fromkeys(results["controller"]))
    fig = make_subplots(rows=1, cols=len(scenarios), shared_yaxes=True, horizontal_spacing=0.03,
                        subplot_titles=[f"scenario {s}" for s in scenarios])
    order = ok[ok["scenario"] == scenarios[0]].groupby("controller")["peak_error_rad"].median()
    cats = sorted(set(ok["controller"]), key=lambda c: (-order.get(c, -math.inf), c))
    for k, scen in enumerate(scenarios):
        d_s = ok[ok["scenario"] == scen]
        for ctrl in cats:
            v = d_s.loc[d_s["controller"] == ctrl, "peak_error_rad"].to_numpy() * 1e6
            if v.size == 0:
                continue
            ci = median_ci(v)
            if not ci.median > 0:     # a log axis cannot place it
                continue
            colour = controller_colour(ctrl, controllers)
            fig.add_trace(go.Scatter(
                x=[ci.median], y=[ctrl], mode="markers", showlegend=False,
                marker=dict(color=colour, size=10, line=dict(width=1, color="#222")),
                error_x=dict(type="data", symmetric=False, array=[ci.high - ci.median],
                             arrayminus=[ci.median - ci.low], color=colour, thickness=2, width=6),
                hovertemplate=(f"<b>{ctrl}</b>, {scen}<br>median %{{x:.3g}} µrad [{ci.low:.3g}, "
                               f"{ci.high:.3g}] over {ci.n} seeds{_not_ok_note(left, scen, ctrl)}"
                               "<extra></extra>")), row=1, col=k + 1)
        lim = _scenario_limit_urad(limits, scen, default)
        fig.add_vline(x=lim, line=dict(color="#b00", dash="dash", width=1.5), row=1, col=k + 1)
        xref = "x" if k == 0 else f"x{k + 1}"
        fig.add_annotation(x=math.log10(lim), xref=xref, y=1, yref="paper", showarrow=False,
                           text=f"(2-6) {lim:.3g}", yanchor="bottom", font=dict(color="#b00", size=10))
    fig.update_xaxes(type="log", title_text="peak |error| [µrad]")
    fig.update_yaxes(categoryorder="array", categoryarray=cats)
    fig.update_layout(title="Peak error per controller: median over seeds and its 95 % CI")
    return fig
