"""``solnic-bench experiment`` and ``solnic-bench identify``: the axis loop (SPEC §11).

``experiment`` writes the plan a user plays on the hardware (:mod:`plant.identification.experiment`);
``identify LOG`` fits a plant family to the recorded log (:mod:`plant.identification.fit`), prints
the estimates ± sd (rich), and writes a matrix TOML with the scenario ``axis`` (truth = the fit)
plus an HTML page with measured against simulated y (plotly, offline).
"""

from __future__ import annotations

import contextlib
import math
import os
import tomllib
from html import escape
from pathlib import Path
from typing import TYPE_CHECKING

import typer
from rich.table import Table

import bench
from bench.cli import out_console, user_errors
from bench.errors import UserError
from plant.identification.experiment import ExperimentOptions, design_experiment
from plant.identification.families import DEFAULT_BUDGET_S, FAMILY_FREE, NOT_IDENTIFIED_RULE
from plant.identification.log import LogError, read_log, write_log
from plant.drive import DriveType
from plant.identification.experiment import WHY

if TYPE_CHECKING:
    from plant.identification.fit import AxisFit, FamilyChoice

__all__ = ["experiment_command", "identify_command", "fitted_matrix_toml", "fit_page", "choice_lines", "fit_workers",
           "fit_map", "FIT_PRELOAD"]

_UNITS = {"coulomb": "ozf·in", "stiction": "ozf·in", "inertia": "ozf·in·s²", "motor_time_constant": "s",
          "measurement_noise_std": "rad", "stribeck_velocity": "rad/s", "viscous": "ozf·in·s/rad",
          "bristle_stiffness": "ozf·in/rad", "shaft_stiffness": "ozf·in/rad"}


@user_errors
def experiment_command(
    drive: str = typer.Option(DriveType.LINEAR.value, "--drive", help="linear (amplifier) or bridge (switched, ±u_max)."),
    out: Path = typer.Option(Path("plan.csv"), "--out", help="Plan file (.csv or .parquet)."),
    max_torque: float = typer.Option(20.0, "--max-torque", help="Largest |u| [ozf·in]; the bridge's supply level."),
    ramp_fraction: float = typer.Option(0.15, "--ramp-fraction",
                                        help="Ramp peak / max torque: about 1.2-1.5x the stiction you expect."),
    ramp_time: float = typer.Option(0.15, "--ramp-time", help="Seconds from 0 to the ramp peak."),
    repeats: int = typer.Option(6, "--repeats", help="Pulses per width and direction (the plan's length)."),
    max_angle: float = typer.Option(0.2, "--max-angle", help="|y - y(0)| [rad] at which the player must abort."),
    sample_period: float = typer.Option(0.01, "--sample-period", help="τs [s]."),
    holds: int = typer.Option(2, "--holds", help="Torque holds per ladder level and direction (linear drive; "
                                                 "0: the plan without holds)."),
    hold_time: float = typer.Option(0.15, "--hold-time", help="Seconds each torque hold lasts."),
    doublets: int = typer.Option(0, "--doublets", help="Torque doublets (+max torque, then -max torque, 2 and 2.5 ms "
                                                       "each) per width and direction (linear drive; 0: none): they "
                                                       "excite a compliant shaft."),
    reversals: int = typer.Option(0, "--reversals", help="Slow reversals (a 2.5-ms kick at max torque, then "
                                                         "+/-level for the hold time each way; levels 0.35, 0.45, "
                                                         "0.55 of the ramp peak) per level and direction (linear "
                                                         "drive; 0: none): slides where a Stribeck law acts."),
) -> None:
    """Write the identification plan: u at each sample instant, to be played on the axis.

    Rests measure the noise σ1; slow torque ramps both ways show the breakaway level (stiction) and,
    by the slide after it, Coulomb friction against inertia; pulse trains of several widths both
    ways give the pulse law (its onset: stiction and the motor lag τ3; its slope: inertia and
    Coulomb friction); torque holds on a ladder of levels tell the friction laws apart (LuGre's
    elastic pre-sliding below stiction, a compliant shaft's early breakaway, the speed-dependent
    friction of constant-torque runs). Record y at every t and run `solnic-bench identify LOG`.
    """
    try:
        opts = ExperimentOptions(drive=drive, sample_period=sample_period, max_torque=max_torque,
                                 ramp_fraction=ramp_fraction, ramp_time=ramp_time, repeats=repeats,
                                 max_angle=max_angle, holds=holds, hold_time=hold_time,
                                 doublets=doublets, reversals=reversals)
    except ValueError as exc:
        raise UserError(str(exc).replace("ExperimentOptions.", "--").replace("_", "-")) from None
    plan = design_experiment(opts)
    try:
        write_log(plan, out)
    except OSError as exc:
        raise UserError(f"{out}: cannot write: {exc.strerror or exc}") from None
    out_console.print(f"plan: {out} ({plan.n} samples, {plan.n * plan.sample_period:.1f} s, {drive} drive)")
    out_console.print(" ".join(WHY.split()))


def _default_controllers() -> list[str]:
    with open(Path(bench.__file__).parent / "matrices" / "quick.toml", "rb") as fh:
        return list(tomllib.load(fh)["matrix"]["controllers"])


def fitted_matrix_toml(fit: AxisFit, log_name: str) -> str:
    """A matrix file with the scenario ``axis``: truth = the fit (``run``/``frontier`` accept it)."""
    p = fit.params
    fields = list(fit.estimates)
    if p.sample_period != 0.01:
        fields.append("sample_period")
    if p.u_max != 20.0:
        fields.append("u_max")
    lines = [f"# Fitted by `solnic-bench identify {log_name} --family {fit.family}`: {fit.method}.",
             "# Not identified by the experiment, kept at Table 2-1: friction noise, correlated friction, reference.",
             "[matrix]",
             f'description = "the identified axis ({fit.family}) from {log_name}"',
             f"controllers = {_default_controllers()!r}".replace("'", '"'),
             'scenarios = ["axis"]', "seeds = [0, 1]", "duration_s = 100", "warmup_s = 20", "",
             "[scenarios.axis]", 'base = "thesis"', f'plant = "{fit.family}"',
             f'description = "the identified axis from {log_name}"']
    for name in fields:
        sd = fit.std.get(name)
        note = f"   # ± {sd:.3g} (1 sd)" if sd is not None else ""
        if name in fit.not_identified:
            note += ", not identified (kept as fitted; the log does not pin it)"
        lines.append(f"{name} = {float(getattr(p, name))!r}{note}")
    return "\n".join(lines) + "\n"


def choice_lines(choice: FamilyChoice) -> list[str]:
    """One line per family: held-out score, paired excess over the best ± its standard error, and
    (predictive criterion) the moves it predicts worse and better than the best and the rule's
    signed-rank statistic W against its null sd (separably worse when W > 2 sd)."""
    unit = "ln rad²" if choice.criterion == "output-error" else "−2 ln p per move"

    def signs(f):
        w, b = choice.signs.get(f, (None, None))
        out = "" if w is None else f", worse on {w} moves, better on {b}"
        if f in choice.ranks:
            rank, sd = choice.ranks[f]
            out += f", signed rank W = {rank:+.0f} (sd {sd:.0f})"
        return out
    return [f"{f}: held-out score {choice.score[f]:.3f} {unit}, excess over {choice.best} "
            f"{choice.excess[f]:+.3f} ± {choice.excess_se[f]:.3f}{signs(f)}" + ("  (chosen)" if f == choice.family else "")
            for f in sorted(choice.score, key=choice.score.get)]


def fit_page(fit: AxisFit, log, log_name: str, choice: FamilyChoice | None) -> str:
    """Self-contained HTML: the estimates and measured against simulated y."""
    t = log.t
    import plotly
    import plotly.graph_objects as go

    fig = go.Figure()
    fig.add_trace(go.Scattergl(x=t, y=log.y * 1e6, mode="lines", name="measured y"))
    fig.add_trace(go.Scattergl(x=t, y=fit.y_model * 1e6, mode="lines", name=f"simulated y ({fit.family})"))
    fig.update_layout(xaxis_title="t [s]", yaxis_title="y [µrad]", height=520,
                      title=f"{log_name}: measured against the fitted {fit.family} plant (noise-free, per move)")
    weak = fit.not_identified
    rows = "".join(f"<tr><td>{n}</td><td>{fit.estimates[n]:.6g}</td><td>{fit.std[n]:.3g}</td>"
                   f"<td>[{fit.interval[n][0]:.6g}, {fit.interval[n][1]:.6g}]</td><td>{_UNITS.get(n, '')}</td>"
                   f"<td>{'not identified' if n in weak else 'yes'}</td></tr>"
                   for n in fit.estimates)
    budget = f"<p><b>{escape(fit.budget_note)}</b></p>" if fit.budget_note else ""
    bic = "" if not choice else (f"<h2>Family choice (--family auto)</h2><p>Rule: {escape(choice.rule)}.</p><ul>"
                                 + "".join(f"<li>{escape(line)}</li>" for line in choice_lines(choice)) + "</ul>")
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>identify {log_name}</title>"
            f"<script>{plotly.offline.get_plotlyjs()}</script></head><body>"
            f"<h1>Identified axis: {fit.family}</h1><p>{fit.method}; {fit.n_moves} moves, {fit.n_samples} samples, "
            f"{fit.seconds:.1f} s.</p>{budget}<table border='1'><tr><th>field</th><th>estimate</th><th>sd</th>"
            f"<th>95 % interval</th><th>unit</th><th>identified</th></tr>{rows}</table>"
            f"<p>{escape(NOT_IDENTIFIED_RULE)}.</p>{bic}"
            f"{fig.to_html(full_html=False, include_plotlyjs=False)}</body></html>")


# What the forkserver of identify's worker pool imports once (each worker is forked with the fit's
# modules loaded; the numba kernels load from numba's cache at their first call in a worker).
FIT_PRELOAD = ["plant.identification.fit"]


def fit_workers(requested: int | None, family: str, bootstrap: int) -> int:
    """Worker processes for ``identify``: ``requested``, or the cores this process may run on
    (``os.sched_getaffinity``), capped at the work there is to share — the bootstrap's replicates,
    and for ``auto`` also the two held-out folds (at least 1)."""
    cores = requested if requested is not None else len(os.sched_getaffinity(0))
    tasks = max(bootstrap, 2) if family == "auto" else bootstrap
    return max(1, min(cores, tasks))


@contextlib.contextmanager
def fit_map(workers: int):
    """The ``mapper`` of :func:`~plant.identification.fit.fit_log` and ``choose_family``: the builtin
    ``map`` for one worker (everything in this process, the sequential code path), else the ``map``
    of a process pool of ``workers`` processes forked from a forkserver (the start method of the
    cell processes, :mod:`bench.isolation`; preloading :data:`FIT_PRELOAD`). The forkserver is one
    per process and keeps the preload of whoever starts it first."""
    if workers <= 1:
        yield map
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(FIT_PRELOAD)
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        yield pool.map


@user_errors
def identify_command(
    log_path: Path = typer.Argument(..., metavar="LOG", help="The recorded log (CSV or Parquet, SPEC §11)."),
    family: str = typer.Option(None, "--family", show_default=False,
                               help=f"{'|'.join(FAMILY_FREE)}|auto (auto: held-out predictive density of each move under "
                                    "the family's own friction noise, the simpler family when not separable by a "
                                    "sign test over moves); default: Acker's exact plant."),
    out: Path = typer.Option(Path("axis.toml"), "--out", help="Matrix file with the scenario 'axis'."),
    html: Path = typer.Option(None, "--html", help="Fit page (default: OUT with .html)."),
    bootstrap: int = typer.Option(20, "--bootstrap", help="Parametric-bootstrap replicates (0: Gauss-Newton only)."),
    seed: int = typer.Option(0, "--seed", help="Root seed of the bootstrap."),
    budget: float = typer.Option(DEFAULT_BUDGET_S, "--budget",
                                 help="Nominal CPU seconds of simulation work for the final fit (point fit + "
                                      "bootstrap), counted, so the fit is the same on every machine; "
                                      "when hit, the output says what was cut short."),
    workers: int = typer.Option(None, "--workers", show_default=False,
                                help="Processes for the bootstrap's replicates and auto's two folds (default: the "
                                     "cores available, capped at that work; 1: all in this process). The "
                                     "results are the same, bit for bit, for any N."),
    separable: float = typer.Option(None, "--separable", show_default=False,
                                    help="auto only: a family is separably worse than the best when its signed-rank "
                                         "z over moves exceeds this (default: the rule's, docs/axis.md)."),
    rule: str = typer.Option("mean", "--rule",
                             help="auto only: mean (the best by the mean score, the others tested against it) or "
                                  "pairwise (every pair tested; the simplest family no other is separably better "
                                  "than; docs/axis.md, 'Tenth session: auto')."),
) -> None:
    """Fit a plant family to LOG; print estimates ± sd; write OUT (matrix TOML) and the fit page."""
    from plant.identification.fit import choose_family, fit_log
    from plant.protocol import DEFAULT_FAMILY

    family = DEFAULT_FAMILY if family is None else family

    if family != "auto" and family not in FAMILY_FREE:
        raise UserError(f"--family: {family!r} is not one of {', '.join(FAMILY_FREE)}, auto")
    if not (bootstrap == 0 or 5 <= bootstrap <= 1000):
        raise UserError(f"--bootstrap: must be 0 or in [5, 1000], got {bootstrap}")
    if not (math.isfinite(budget) and budget > 0):
        raise UserError(f"--budget: must be > 0 nominal CPU seconds, got {budget}")
    if workers is not None and workers < 1:
        raise UserError(f"--workers: must be an integer >= 1, got {workers}")
    if separable is not None and not (math.isfinite(separable) and 0.0 <= separable <= 10.0):
        raise UserError(f"--separable: must be in [0, 10], got {separable}")
    if rule not in ("mean", "pairwise"):
        raise UserError(f"--rule: must be mean or pairwise, got {rule!r}")
    try:
        log = read_log(log_path)
    except LogError as exc:
        raise UserError(str(exc)) from None
    choice = None
    try:
        with fit_map(fit_workers(workers, family, bootstrap)) as mapper:
            if family == "auto":
                fit, choice = choose_family(log, bootstrap=bootstrap, seed=seed, budget_s=budget, mapper=mapper,
                                            separable=separable, rule=rule)
            else:
                fit = fit_log(log, family, bootstrap=bootstrap, seed=seed, budget_s=budget, mapper=mapper)
    except (ValueError, RuntimeError) as exc:
        raise UserError(f"{log_path}: {exc}") from None
    table = Table(title=f"{log_path.name}: {fit.family} ({fit.method})")
    for col in ("field", "estimate", "± sd", "95 % interval", "unit", "identified"):
        table.add_column(col)
    weak = fit.not_identified
    for n in fit.estimates:
        lo, hi = fit.interval[n]
        table.add_row(n, f"{fit.estimates[n]:.6g}", f"{fit.std[n]:.2g}", f"[{lo:.5g}, {hi:.5g}]", _UNITS.get(n, ""),
                      "not identified" if n in weak else "yes")
    out_console.print(table)
    if weak:
        out_console.print(f"not identified: {', '.join(weak)} ({NOT_IDENTIFIED_RULE})")
    if fit.budget_note:
        out_console.print(f"budget: {fit.budget_note}")
    if choice:
        out_console.print(f"family: {choice.family} ({choice.rule})")
        for line in choice_lines(choice):
            out_console.print("  " + line)
    html = html or out.with_suffix(".html")
    try:
        out.write_text(fitted_matrix_toml(fit, log_path.name))
        html.write_text(fit_page(fit, log, log_path.name, choice))
    except OSError as exc:
        raise UserError(f"{out}: cannot write: {exc.strerror or exc}") from None
    out_console.print(f"matrix: {out} (scenario 'axis'; fit in {fit.seconds:.1f} s)\nfit page: {html}")
    if not all(math.isfinite(v) for v in fit.std.values()):
        out_console.print("warning: some uncertainties are not finite")
