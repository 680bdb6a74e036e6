"""``solnic-bench robustness``: every controller, untuned per plant, on every real plant (issue 24).

Does the ranking survive a plant that is not the model? The built-in matrices
``bench/matrices/robustness.toml`` and ``robustness-quick.toml`` declare the shared seeds and
run lengths; :func:`robustness_matrix_data` completes them from the registries:

* **controllers** — every registered controller at its defaults, and at its *best frontier
  point on the reference plant* (thesis) when that is not its default: the knob point with the
  lowest median peak error over the frontier's seeds, every seed ``ok``
  (:func:`best_points`). No retuning per plant. The points come from the committed table
  ``bench/matrices/robustness-best.toml`` (its header says which frontier run produced it), or
  from a frontier run directory (``--frontier DIR``); a controller the table does not know runs
  at its defaults only. A privileged bound (the oracle) runs at its best point only, as the
  floor (as in the frontier); the report never ranks it. ``--quick`` leaves the bounds out
  (``[robustness] bounds = false`` in its file): at its 0.5 µrad band the oracle is half the cost.
* **scenarios** — the reference (``thesis``) and every built-in *real-plant* scenario
  (:func:`real_plant_scenarios`), collected from :func:`bench.scenarios.builtin_scenarios`
  (which includes the plant families' own ``scenarios``), so a scenario added there joins.
* **model** — controllers are told the reference's model (Table 2-1), never the truth: a
  real-plant scenario that tells its controllers anything else (``quantized`` and ``delayed``
  tell them the encoder step and the delay) runs as ``<name>-nominal``, the same truth with
  ``[scenarios.<name>-nominal.model]`` set back to Table 2-1 (:func:`nominal_changes`).

The seeds (20–39) are disjoint from the tuning seeds (0–4) and from the frontier's (0–19) that
chose the best points, so the thesis reference is out of sample for every point. The completed
matrix is written to ``DIR/robustness-matrix.toml`` and run like any matrix (same store,
resume, executors); its ``[robustness]`` table tells the report which scenario is the
reference and which rows are best points.
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Callable, Optional

import typer

from bench.cli import out_dir, user_errors, writable_dir
from bench.errors import UserError
from bench.frontier import to_toml, write_completed_matrix

__all__ = ["REFERENCE", "robustness_matrix_path", "best_table_path", "is_real_plant", "real_plant_scenarios",
           "nominal_changes", "best_points", "load_best_table", "frontier_best", "robustness_matrix_data",
           "make_robustness_command"]

#: The reference plant: Table 2-1 told exactly, the plant the best points were chosen on.
REFERENCE = "thesis"
NOMINAL_SUFFIX = "-nominal"


def robustness_matrix_path(quick: bool = False) -> Path:
    """``bench/matrices/robustness-quick.toml`` or ``robustness.toml`` (package data)."""
    name = "robustness-quick.toml" if quick else "robustness.toml"
    return Path(str(resources.files("bench").joinpath("matrices", name)))


def best_table_path() -> Path:
    """``bench/matrices/robustness-best.toml``: the committed best frontier points."""
    return Path(str(resources.files("bench").joinpath("matrices", "robustness-best.toml")))


def _option_fields(params: Any) -> set[str]:
    """Fields of ``params`` marked ``omit_default``: plant options beyond Acker's model
    (``quantization``, ``command_delay``, ...), off at their default."""
    return {f.name for f in dataclasses.fields(params) if f.metadata.get("omit_default")}


def is_real_plant(scenario: Any, reference: Any) -> bool:
    """Whether ``scenario``'s truth departs from the model the way a real plant does: another
    plant family than the reference's, per-seed parameter errors (``mismatch``), or a plant
    option (a field marked ``omit_default``) switched on. Acker's plant with other Table 2-1
    values told exactly (``quiet-friction``, ``ratio-2``) is not one."""
    if scenario.family != reference.family or scenario.mismatch:
        return True
    return any(getattr(scenario.params, f) != getattr(reference.params, f, None) for f in _option_fields(scenario.params))


def real_plant_scenarios(scenarios: dict[str, Any] | None = None, reference: str = REFERENCE) -> list[str]:
    """The built-in real-plant scenarios (:func:`is_real_plant`), in registry order, without the
    reference."""
    from bench.scenarios import builtin_scenarios

    scenarios = builtin_scenarios() if scenarios is None else scenarios
    ref = scenarios[reference]
    return [n for n, s in scenarios.items() if n != reference and is_real_plant(s, ref)]


def nominal_changes(scenario: Any, nominal: Any) -> dict[str, Any]:
    """The model fields that ``scenario`` tells its controllers differently from ``nominal`` (a
    PlantParams), with ``nominal``'s values: the ``[scenarios.X.model]`` table that tells them
    ``nominal`` instead (empty when it already does)."""
    told = scenario.model_params()
    return {f.name: getattr(nominal, f.name) for f in dataclasses.fields(nominal)
            if getattr(told, f.name) != getattr(nominal, f.name)}


def best_points(results: Any, config: dict[str, Any], reference: str = REFERENCE) -> dict[str, dict[str, Any]]:
    """Each registered controller's best knob point on ``reference`` in a frontier run: the point
    (``config.json`` ``matrix.sweep.controllers``: parent, knobs) or the default with the lowest
    median ``peak_error_rad`` over its seeds, among those whose every cell on ``reference`` is
    ``ok``. Returns parent → knob values, only for parents whose best point is not the default
    (ties go to the default, then to the first point). Raises ``ValueError`` naming the entry for
    a ``config`` of another shape, or a best point whose knobs its controller does not take."""
    from controllers.base import available_controllers

    registered = available_controllers()
    points = _sweep_points(config)
    r = results[results["scenario"] == reference]
    best: dict[str, tuple[float, int, dict[str, Any]]] = {}
    for order, (name, g) in enumerate(r.groupby("controller", sort=False)):
        info = points.get(name)
        parent, knobs = (info["parent"], dict(info.get("knobs") or {})) if info else (name, {})
        if parent not in registered or (info and info.get("base", parent) != parent):
            continue
        if not (g["status"] == "ok").all() or g["peak_error_rad"].isna().any():
            continue
        median = float(g["peak_error_rad"].median())
        key = (median, 0 if not knobs else 1 + order)
        if parent not in best or key < best[parent][:2]:
            best[parent] = (median, key[1], knobs)
    out = {}
    for p, (_, _, k) in sorted(best.items()):
        try:
            if k and not _is_default(registered[p], k):
                out[p] = k
        except (ValueError, TypeError) as exc:    # a knob the controller does not take, or a bad value
            raise ValueError(f"the best point of {p} {k}: {exc}") from None
    return out


def _sweep_points(config: Any) -> dict[str, Any]:
    """``config["matrix"]["sweep"]["controllers"]`` (point → parent, knobs; empty when absent),
    checked for its shape: ``ValueError`` naming the entry otherwise."""
    node: Any = config
    path = []
    for key in ("matrix", "sweep", "controllers", None):
        if not isinstance(node, dict):
            where = "config.json" + (": " + ".".join(path) if path else "")
            raise ValueError(f"{where}: must be a JSON object, got {type(node).__name__}")
        if key is None:
            break
        node = node.get(key) or {}
        path.append(key)
    for name, info in node.items():
        if (not isinstance(info, dict) or not isinstance(info.get("parent"), str)
                or not isinstance(info.get("knobs") or {}, dict)):
            raise ValueError(f"config.json: matrix.sweep.controllers.{name}: must be an object with parent "
                             "(a name) and knobs (an object)")
    return node


def _is_default(cls: Any, knobs: dict[str, Any]) -> bool:
    """Whether ``knobs`` leave ``cls``'s default options unchanged."""
    from controllers.base import resolve_options

    if cls.Options is None:
        return not knobs
    return resolve_options(cls, None, None, knobs) == resolve_options(cls)


def load_best_table(path: Path) -> tuple[dict[str, dict[str, Any]], str]:
    """(parent → knob values, provenance) from a best-points table (``robustness-best.toml``)."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise UserError(f"{path}: cannot read the best-points table: {exc}") from None
    points, source = data.get("points", {}), data.get("source", "")
    if not isinstance(points, dict) or not all(isinstance(v, dict) for v in points.values()):
        raise UserError(f"{path}: points: must be tables [points.<controller>] of knob = value")
    if not isinstance(source, str):
        raise UserError(f"{path}: source: must be a string")
    return {k: dict(v) for k, v in points.items()}, source


def frontier_best(run_dir: Path, reference: str = REFERENCE) -> tuple[dict[str, dict[str, Any]], str]:
    """(best points, provenance) from a frontier run directory (``results.parquet`` and
    ``config.json`` as ``solnic-bench frontier`` writes them)."""
    import pandas as pd

    flag = f"--frontier {run_dir}"
    try:
        config = json.loads((run_dir / "config.json").read_text(encoding="utf-8"))
        results = pd.read_parquet(run_dir / "results.parquet")
    except (OSError, ValueError) as exc:
        raise UserError(f"{flag}: not a finished run directory (config.json, results.parquet): {exc}") from None
    missing = {"controller", "scenario", "status", "peak_error_rad", "seed"} - set(results.columns)
    if missing:
        raise UserError(f"{flag}: results.parquet lacks column(s) {sorted(missing)}")
    if not (results["scenario"] == reference).any():
        raise UserError(f"{flag}: holds no cell of the reference scenario {reference!r}")
    ref = results[results["scenario"] == reference]
    seeds = sorted(int(s) for s in ref["seed"].unique())
    source = (f"best thesis points of the frontier run {run_dir.resolve()} ({len(ref)} {reference} cells, "
              f"seeds {_span(seeds)}, {_fmt(ref['duration_s'].iloc[0]) if 'duration_s' in ref else '?'} s runs)")
    try:
        return best_points(results, config, reference), source
    except ValueError as exc:
        raise UserError(f"{flag}: {exc}") from None


def _span(seeds: list[int]) -> str:
    if seeds and seeds == list(range(seeds[0], seeds[-1] + 1)):
        return f"{seeds[0]}–{seeds[-1]}"
    return ", ".join(map(str, seeds))


def _fmt(v: Any) -> str:
    return f"{float(v):g}"


def _float(v: Any) -> Any:
    return float(v) if isinstance(v, int) and not isinstance(v, bool) else v


def robustness_matrix_data(quick: bool = False, best: dict[str, dict[str, Any]] | None = None,
                           best_source: str | None = None) -> dict[str, Any]:
    """The robustness matrix as TOML data, completed from the registries (module doc).

    ``best`` (parent → knob values) replaces the committed table; the quick matrix runs the
    same points as the full one."""
    from controllers.base import available_controllers
    from bench.scenarios import builtin_scenarios
    from bench.sweep import point_name

    data = tomllib.loads(robustness_matrix_path(quick).read_text(encoding="utf-8"))
    where = best_source or "best points"
    if best is None:
        where = str(best_table_path())
        best, best_source = load_best_table(best_table_path())
    matrix = data["matrix"]
    table = data.setdefault("robustness", {})
    registered = available_controllers()
    if not table.get("bounds", True):                 # --quick: no privileged bound (half the cost)
        registered = {n: c for n, c in registered.items() if not c.privileged}
    controllers: list[str] = []
    variants: dict[str, dict[str, Any]] = {}
    best_rows: dict[str, str] = {}
    for name, cls in registered.items():
        knobs = best.get(name)
        try:
            has_point = bool(knobs) and not _is_default(cls, knobs)
        except ValueError as exc:           # a knob the controller does not have, or a bad value
            raise UserError(f"{where}: points.{name}: {exc}") from None
        if not (has_point and cls.privileged):      # a bound is its floor: the best point only
            controllers.append(name)
        if has_point:
            point = point_name(name, knobs)
            controllers.append(point)
            variants[point] = {"base": name, **{k: _float(v) for k, v in knobs.items()}}
            best_rows[point] = name
    matrix["controllers"] = controllers
    if variants:
        data["controllers"] = variants

    scenarios = builtin_scenarios()
    nominal = scenarios[REFERENCE].model_params()
    names, custom, renamed = [REFERENCE], {}, {}
    for name in real_plant_scenarios(scenarios):
        changes = nominal_changes(scenarios[name], nominal)
        if changes:
            derived = name + NOMINAL_SUFFIX
            custom[derived] = {"base": name, "description": f"{scenarios[name].description}; controllers told "
                                                            f"Table 2-1 ({', '.join(sorted(changes))} as in Table 2-1)",
                               "model": {k: _float(v) for k, v in changes.items()}}
            renamed[derived] = name
            name = derived
        names.append(name)
    matrix["scenarios"] = names
    if custom:
        data["scenarios"] = custom
    table["reference"] = REFERENCE
    table["best_source"] = best_source or ""
    if best_rows:
        table["best"] = best_rows
    if renamed:
        table["told_nominal"] = renamed
    return data


def make_robustness_command(run: Callable[..., None]) -> Callable[..., None]:
    """The ``robustness`` command: writes the completed matrix, then runs it with ``run`` (the
    ``run`` command of :func:`bench.run_command.make_run_command`)."""

    @user_errors
    def robustness_command(
        quick: bool = typer.Option(False, "--quick", help="The quick robustness matrix (at most 3 min on 2 cores)."),
        out_value: str = typer.Option("robustness", "--out", help="Run directory; a re-run resumes it."),
        frontier: Optional[Path] = typer.Option(None, "--frontier", help="Take the best thesis points from this "
                                                "frontier run directory (default: bench/matrices/robustness-best.toml)."),
        executor: str = typer.Option("local", "--executor", help="local (process pool) or dask."),
        scheduler: Optional[str] = typer.Option(None, "--scheduler", help="dask scheduler address (default: a LocalCluster)."),
        workers: Optional[int] = typer.Option(None, "--workers", help="Worker processes (default: CPU count)."),
        traces: bool = typer.Option(False, "--traces", help="Also write a rerun trace per cell (off by default)."),
    ) -> None:
        """Every registered controller, at its default and its best thesis frontier point, told
        Table 2-1, on every real-plant scenario: DIR/results.{parquet,csv}, DIR/robustness-matrix.toml,
        DIR/report.html with a robustness section."""
        from bench.executors import make_executor
        from bench.matrix import parse_matrix

        make_executor(executor, workers, scheduler)    # the flags first: nothing is written on a bad one
        out = out_dir(out_value)
        if frontier is not None:
            if not frontier.is_dir():
                raise UserError(f"--frontier {frontier}: no such run directory")
            best, source = frontier_best(frontier)
            data = robustness_matrix_data(quick, best, source)
        else:
            data = robustness_matrix_data(quick)
        path_in = robustness_matrix_path(quick)
        parse_matrix(data, str(path_in), check_resets=False)    # run() checks the resets
        writable_dir(out)
        path = write_completed_matrix(out, "robustness-matrix.toml", to_toml(
            data, f"# Generated by `solnic-bench robustness{' --quick' if quick else ''}` from "
                  f"{path_in.name}, the registries and {'--frontier' if frontier else best_table_path().name}."))
        run(matrix=path, quick=False, out_value=str(out), executor=executor, scheduler=scheduler, workers=workers,
            traces_policy="all" if traces else "none", no_traces=False)

    return robustness_command

