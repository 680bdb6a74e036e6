"""The terminal tables of ``speed``."""

from __future__ import annotations

from typing import Any

from bench.exact import EXACT_METHOD
from controllers import roles


def _fmt(v: Any, digits: int = 3) -> str:
    if v is None:
        return "—"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def _ci_urad(ci: list[float]) -> str:
    return f"[{_fmt(ci[0] * 1e6)}, {_fmt(ci[1] * 1e6)}]"


def _ci_pct(ci: list[float], ref: float) -> str:
    return f"[{_fmt(100 * ci[0] / ref)}, {_fmt(100 * ci[1] / ref)}]"


def _print_table(result: dict[str, Any], console: Any) -> None:
    from rich.table import Table

    for name, block in ((roles.IDENTIFICATION, result), (roles.CLASSICAL, result.get("linear_hold"))):
        if not block or "rows" not in block:
            continue
        seq = block["sequence"]
        table = Table(title=f"Work-precision on the {name} sequence: {seq['source']}; "
                            f"{seq['duration_s']:g} s from t={seq['t_start_s']:g} s, {seq['n_pulses']} pulses")
        for col in ("method", "setting", "error", "x1 err", "Δc err", "wall [s]", "real-time ×"):
            table.add_column(col, justify="left" if col in ("method", "setting") else "right")
        for r in block["rows"]:
            table.add_row(r["method"], r["setting"], _fmt(r["error"]), _fmt(r["error_x1"]), _fmt(r["error_dc"]),
                          _fmt(r["wall_s"]), _fmt(r["realtime_factor"]))
        console.print(table)
        key = "" if block is result else " (linear)"
        for label, k in (("fixed-step (numba)", "fixed_step"), ("solve_ivp", "solve_ivp"),
                         ("fixed-step (CPython)", "fixed_step_python")):
            sp = block.get(f"speedup_vs_{k}_at_1e-6")
            how = block["equal_accuracy"][k].get("how", "")
            console.print(f"speed-up at equal accuracy 1e-6 vs {label}{key}: [bold]{_fmt(sp)}×[/bold]  ({how})")
        probe = block.get("fixed_step_probe")
        if probe and probe["rows"]:
            steps = ", ".join(f"h={r['step_s']:g}: {_fmt(r['error_dc'])}" for r in probe["rows"])
            console.print(f"per-pulse probe ({probe['n_pulses']} pulses), max Δc error {steps}")
        lb = block["equal_accuracy"]["fixed_step_lower_bound"]
        console.print(f"measured lower bound vs fixed-step (numba){key}: [bold]{_fmt(lb['speedup'])}×[/bold]  "
                      f"({lb['how']})")
        d = block["reference_disagreement"]
        console.print(f"reference check: exact vs solve_ivp rtol={d['solve_ivp_rtol']:g}: "
                      f"x1 {_fmt(d['error_x1'])}, Δc {_fmt(d['error_dc'])} (relative)")
    noisy = result.get("noisy")
    if noisy:
        for r in noisy["rows"]:
            console.print(f"noisy {r['method']} {r['setting']}: wall {_fmt(r['wall_s'])} s, "
                          f"real-time × {_fmt(r['realtime_factor'])}")
    weak = result.get("weak_error")
    if weak:
        console.print(f"noisy: Δc of a {weak['dt_u_s'] * 1e3:g} ms pulse, {weak['n_paths']} paths per method "
                      f"(mean and p95, weak error with 95 % CI)")
        for r in weak["rows"]:
            if r["method"] == EXACT_METHOD:
                console.print(f"  exact: mean {_fmt(r['mean_rad'] * 1e6)} µrad, p95 {_fmt(r['p95_rad'] * 1e6)} µrad, "
                              f"{_fmt(r['wall_per_path_s'] * 1e6)} µs per path")
            else:
                console.print(f"  EM h={_fmt(r['step_s'])}: mean error {_fmt(r['mean_error_rad'] * 1e6)} µrad "
                              f"(resolved: {r['mean_error_resolved']}), p95 error {_fmt(r['p95_error_rad'] * 1e6)} µrad "
                              f"(resolved: {r['p95_error_resolved']}), {_fmt(r['wall_per_path_s'] * 1e6)} µs per path")
        bound = "≥ " if result.get("noisy_speedup_is_lower_bound") else ""
        console.print(f"  exact vs EM at equal weak error (mean Δc): {bound}"
                      f"{_fmt(result['noisy_speedup_at_equal_weak_error'])}×")
    coupled = result.get("weak_error_coupled")
    if coupled:
        m = coupled["exact_mean_rad"]
        console.print(f"noisy, resolved: EM on shared Brownian paths ({coupled['n_coupled']} paths, fine step "
                      f"{_fmt(coupled['dt_fine_s'])} s), anchored by {coupled['n_anchor']} exact paths; "
                      f"mean Δc {_fmt(m * 1e6)} µrad; errors in % of it with 95 % CI")
        for r in coupled["rows"]:
            pct = [_fmt(100 * x / m) for x in r["mean_error_ci_rad"]]
            fine = [_fmt(100 * x / m) for x in r["vs_fine_mean_ci_rad"]]
            console.print(f"  EM h={_fmt(r['step_s'])}: weak error vs exact {_fmt(100 * r['mean_error_rad'] / m)} % "
                          f"[{pct[0]}, {pct[1]}]; vs finest EM: mean [{fine[0]}, {fine[1]}] %, "
                          f"W1 {_fmt(100 * r['vs_fine_w1_rad'] / m)} %; {_fmt(r['wall_per_path_s'] * 1e6)} µs per path")
        for tol, c in coupled["cost_at_tolerance"].items():
            console.print(f"  tolerance {float(tol):.1%} of the mean: {c['verdict']}")
    closed = result.get("closed_loop_em")
    if closed:
        ex = closed["rows"][0]
        console.print(f"closed loop with noise: {closed['controller']} on {closed['scenario']}, peak error over "
                      f"{closed['n_seeds']} seeds ({closed['duration_s']:g} s cells, scored from "
                      f"{closed['warmup_s']:g} s); median and p95 with bootstrap 95 % CI; independent samples")
        console.print(f"  exact: median {_fmt(ex['median_rad'] * 1e6)} µrad {_ci_urad(ex['median_ci_rad'])}, "
                      f"p95 {_fmt(ex['p95_rad'] * 1e6)} µrad {_ci_urad(ex['p95_ci_rad'])}, "
                      f"{_fmt(ex['cpu_per_cell_s'])} s CPU per cell")
        for r in closed["rows"][1:]:
            console.print(f"  EM h={_fmt(r['step_s'])}: median {_fmt(r['median_rad'] * 1e6)} µrad, "
                          f"EM − exact {_fmt(r['median_diff_pct'])} % {_ci_pct(r['median_diff_ci_rad'], ex['median_rad'])}; "
                          f"p95 {_fmt(r['p95_rad'] * 1e6)} µrad, EM − exact {_fmt(r['p95_diff_pct'])} % "
                          f"{_ci_pct(r['p95_diff_ci_rad'], ex['p95_rad'])}; {_fmt(r['cpu_per_cell_s'])} s CPU per cell "
                          f"({_fmt(r['cost_ratio'])}× exact); {r['verdict']}")
    console.print(f"[yellow]technology:[/yellow] {result['technology']['caveat']}")
    console.print(f"error: {result['error_definition']}; elapsed {_fmt(result['elapsed_s'])} s, "
                  f"load average {_fmt(result['load_average_1min'])}")
