"""The terminal tables and verdict lines of ``check-bound``."""

from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

from bench.bound.check import BoundResult


def _g(v: Any, digits: int = 3) -> str:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return str(v)
    if math.isnan(x):
        return "—"
    if math.isinf(x):
        return "∞"
    return f"{x:.{digits}g}"


def _tables(result: BoundResult) -> Iterable[Any]:
    from rich import box
    from rich.table import Table

    b = result.bound
    scored = b[b["stable"] & (b["status"] == "ok")]
    t = Table(title="Inequality (2-6): θ/θb per plant and noise (stable designs, status ok)",
              title_justify="left", box=box.SIMPLE_HEAD)
    for name in ("ks/kc", "J", "noise", "runs", "stable", "scored", "min θ/θb", "at design", "θ µrad",
                 "θb µrad", "max θ/θb"):
        t.add_column(name, justify="left" if name == "at design" else "right")
    for (ratio, inertia, noise), g in b.groupby(["ks_over_kc", "inertia", "noise"], sort=True):
        s = scored[(scored["ks_over_kc"] == ratio) & (scored["inertia"] == inertia)
                   & (scored["noise"] == noise)]
        if len(s):
            r = s.loc[s["ratio"].idxmin()]
            best = [_g(r["ratio"]), str(r["design"]), _g(r["theta_rad"] * 1e6, 4),
                    _g(r["theta_b_rad"] * 1e6, 4), _g(s["ratio"].max())]
        else:
            best = ["—"] * 5
        t.add_row(_g(ratio), _g(inertia), "on" if noise else "off", str(len(g)),
                  str(int(g["stable"].sum())), str(len(s)), *best,
                  style="red" if len(s) and s["ratio"].min() < 1 else None)
    yield t
    h = Table(title="Lag limit (2-1): onset of hunting at a stationary set-point (noise off)",
              title_justify="left", box=box.SIMPLE_HEAD)
    for name in ("ks/kc", "Lmax", "onset L", "onset/Lmax", "highest quiet L", "ωc", "tested L",
                 "integral hunts"):
        h.add_column(name, justify="right")
    for _, r in result.hunting.iterrows():
        h.add_row(_g(r["ks_over_kc"]), _g(r["lmax"]), _g(r["onset_L"]), _g(r["onset_over_lmax"]),
                  _g(r["highest_quiet_L"]), _g(r["omega_c"]), str(r["tested_L"]),
                  _g(r["integral_hunts"]) if not isinstance(r["integral_hunts"], (bool, np.bool_))
                  else ("yes" if r["integral_hunts"] else "no"))
    yield h


def _verdict_lines(result: BoundResult) -> list[str]:
    v = result.verdict
    lines = [f"classical limit (2-6) at ωb = π/τs for Table 2-1: {v['classical_limit_rad'] * 1e6:.3g} µrad"]
    if v["n_scored"] == 0:
        lines.append("verdict: no stable design completed; nothing to judge")
        return lines
    d = v["min_ratio_design"]
    word = "HOLDS" if v["holds"] else "VIOLATED"
    lines.append(f"verdict: θ ≥ θb {word} for {v['n_scored']} scored runs "
                 f"({v['n_violations']} below the bound); minimum θ/θb = {v['min_ratio']:.3g} at "
                 f"{d['design']}, ks/kc = {d['ks_over_kc']:g}, J = {d['inertia']:g}, "
                 f"noise {'on' if d['noise'] else 'off'} (θ = {d['theta_rad'] * 1e6:.4g} µrad, "
                 f"θb = {d['theta_b_rad'] * 1e6:.4g} µrad)")
    lines.append(f"not scored: {v['n_unstable']} unstable, {v['n_no_design']} without a design, "
                 f"{v['n_skipped']} over the time cap, {v['n_unsteady']} without a breakaway in "
                 f"the window, {v['n_failed']} failed runs")
    lines.append(f"wall time {result.wall_s:.1f} s on {v['workers']} worker(s); files: "
                 + ", ".join(str(p) for p in result.paths.values()))
    return lines
