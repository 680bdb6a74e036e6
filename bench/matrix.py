"""The benchmark matrix: a TOML file (parsed with ``tomllib``) → controllers × scenarios × seeds.

Schema (public API, documented in the README)::

    [matrix]
    controllers = ["linear", "dithered", "solnic"]   # registered names or variants below
    scenarios = ["thesis", "quiet-friction"]         # built-in names or custom ones below
    seeds = [0, 1, 2]                                # non-negative integers
    duration_s = 100          # optional, overrides every scenario's run length [s]
    warmup_s = 20             # optional, overrides every scenario's warm-up [s]
    time_limit_s = 600        # optional, wall-clock limit per cell [s] (default 600)
    plugins = ["my_module"]   # optional, modules imported first (they may register controllers);
                              # the matrix file's directory is searched before sys.path
    plugin_dirs = ["../lib"]  # optional, where to search instead (relative to the matrix file)

    [scenarios.heavy-load]    # optional custom scenario: a base plus PlantParams overrides
    base = "thesis"           # (also duration_s, warmup_s, description)
    inertia = 1.0

    [controllers.solnic-hi]   # optional controller variant: a base plus ``preset`` and fields
    base = "solnic"           # of the base's ``Options`` dataclass (controller protocol v2)
    preset = "high-error-cost"

    [sweep.solnic]            # optional sweeps (see bench.sweep): each point is an ordinary cell
    a_c = [1e-6, 1e-5]

    [frontier]                # optional settings of the report's frontier section (bench.frontier)
    crossing_family = "solnic"

    [robustness]              # optional settings of the report's robustness section (bench.robustness):
    reference = "thesis"      # reference, best_source, best, told_nominal, bounds (see _ROBUSTNESS_KEYS)

Every error is a :class:`MatrixError` whose message names the file, the key path and the field,
e.g. ``matrix.toml: scenarios.heavy-load.inertia: PlantParams.inertia must be > 0, got -1.0`` or
``matrix.toml: controllers.lin.crossuver: unknown option 'crossuver' of 'linear'; options: [...]``.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from bench.cells import Cell, ControllerSpec, load_plugins, plugin_digest
from bench.errors import UserError
from bench.names import name_problem
from bench.scenarios import SCENARIO_KEYS, Scenario, builtin_scenarios, derive_scenario
from plant.params import PlantParams

__all__ = ["MatrixError", "Matrix", "load_matrix", "parse_matrix", "builtin_matrix_path",
           "DEFAULT_TIME_LIMIT_S"]

DEFAULT_TIME_LIMIT_S = 600.0
MAX_TIME_LIMIT_S = 7 * 86400.0     # a week of wall clock per cell
MAX_SAMPLES = 20_000_000           # samples of one run (~16 bytes each in the runner: 320 MB)
_MAX_MATRIX_BYTES = 1_000_000
_MATRIX_KEYS = ("controllers", "scenarios", "seeds", "duration_s", "warmup_s", "time_limit_s", "plugins",
                "plugin_dirs", "description")
_PLANT_FIELDS = {f.name for f in dataclasses.fields(PlantParams)}


class MatrixError(UserError):
    """A user error in a matrix file; the message names the file, key path and field."""


@dataclass(frozen=True)
class Matrix:
    """A parsed and validated matrix.

    ``scenarios`` already carry the matrix-level ``duration_s``/``warmup_s`` overrides.
    """

    source: str
    controllers: tuple[ControllerSpec, ...]
    scenarios: tuple[Scenario, ...]
    seeds: tuple[int, ...]
    time_limit_s: float = DEFAULT_TIME_LIMIT_S
    plugins: tuple[str, ...] = ()
    plugin_dirs: tuple[str, ...] = ()
    duration_s: float | None = None
    warmup_s: float | None = None
    description: str = ""
    variants: dict[str, ControllerSpec] = field(default_factory=dict)
    sweep: dict[str, Any] = field(default_factory=dict)
    frontier: dict[str, Any] = field(default_factory=dict)
    robustness: dict[str, Any] = field(default_factory=dict)

    def cells(self) -> list[Cell]:
        """Every cell, in matrix order: controller, then scenario, then seed. A cell of a
        controller that a plugin provides carries the plugins and a digest of their source (an
        edited plugin gives new config hashes); a built-in controller's cell does not depend on
        them, so a run directory may grow by a plugin controller."""
        source = plugin_digest(self.plugins, self.plugin_dirs)
        cells = []
        for c in self.controllers:
            plugins = self.plugins if self.plugins and not _builtin(c.base) else ()
            dirs, digest = (self.plugin_dirs, source) if plugins else ((), "")
            cells += [Cell(c, s, seed, self.time_limit_s, plugins, dirs, plugin_source=digest)
                      for s in self.scenarios for seed in self.seeds]
        return cells

    def to_json(self) -> dict[str, Any]:
        """The resolved matrix, for ``DIR/config.json``."""
        return {
            "source": self.source, "description": self.description,
            "controllers": [c.name for c in self.controllers],
            "scenarios": [s.name for s in self.scenarios], "seeds": list(self.seeds),
            "duration_s": self.duration_s, "warmup_s": self.warmup_s,
            "time_limit_s": self.time_limit_s, "plugins": list(self.plugins),
            "sweep": self.sweep, "frontier": self.frontier,
            **({"robustness": self.robustness} if self.robustness else {}),
        }


def _builtin(base: str) -> bool:
    """Whether the registered controller ``base`` ships with the package (not from a plugin)."""
    from controllers.base import get_controller

    module = get_controller(base).__module__
    return module == "controllers" or module.startswith("controllers.")


def builtin_matrix_path(quick: bool = False) -> Path:
    """``bench/matrices/quick.toml`` or ``default.toml`` (package data)."""
    name = "quick.toml" if quick else "default.toml"
    return Path(str(resources.files("bench").joinpath("matrices", name)))


def load_matrix(path: str | Path, *, check_resets: bool = True) -> Matrix:
    """Read and validate a matrix file (``check_resets=False`` skips the dry controller resets,
    for listings).

    Raises
    ------
    MatrixError
        For an unreadable file, a TOML syntax error (with its line) or an invalid entry.
    """
    path = Path(path)
    label = str(path)
    try:
        if not path.is_file():   # a directory, /dev/zero, a FIFO: never read
            why = "not a regular file" if path.exists() else "no such file"
            raise MatrixError(f"{label}: cannot read the matrix file: {why}")
        with path.open("rb") as fh:
            raw = fh.read(_MAX_MATRIX_BYTES + 1)
        if len(raw) > _MAX_MATRIX_BYTES:
            raise MatrixError(f"{label}: larger than {_MAX_MATRIX_BYTES} bytes; not a matrix file")
        text = raw.decode("utf-8-sig")   # a UTF-8 byte-order mark is allowed
    except (OSError, UnicodeDecodeError) as exc:
        raise MatrixError(f"{label}: cannot read the matrix file: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        line = re.search(r"line (\d+)", str(exc))
        if line:
            where = f"{label}:{line.group(1)}"
        elif "end of document" in str(exc):
            where = f"{label}:{max(1, len(text.splitlines()))}"
        else:
            where = label
        raise MatrixError(f"{where}: invalid TOML: {exc}") from None
    return parse_matrix(data, label, base_dir=path.resolve().parent, check_resets=check_resets, text=text)


def _fail(source: str, key: str, message: str) -> MatrixError:
    return MatrixError(f"{source}: {key}: {message}")


def _number(source: str, key: str, value: Any, *, positive: bool = False, allow_zero: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(source, key, f"must be a finite number, got {value!r}")
    if positive and not (value > 0 or (allow_zero and value == 0)):
        raise _fail(source, key, f"must be {'>= 0' if allow_zero else '> 0'}, got {value!r}")
    return float(value)


def _names(source: str, key: str, value: Any) -> tuple[str, ...]:
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        raise _fail(source, key, f"must be a non-empty list of names, got {value!r}")
    dup = sorted({v for v in value if value.count(v) > 1})
    if dup:
        raise _fail(source, key, f"lists {dup[0]!r} more than once")
    return tuple(value)


def _check_name(source: str, key: str, name: str) -> None:
    problem = name_problem(name)
    if problem:
        raise _fail(source, key, problem)


def _field_of(message: str, prefix: str) -> str | None:
    m = re.search(rf"{prefix}\.(\w+)", message)
    return m.group(1) if m else None


def _plugin_dirs(source: str, m: dict[str, Any], base_dir: Path | None) -> tuple[str, ...]:
    """The directories searched for ``plugins``: ``plugin_dirs`` relative to the matrix file's
    directory (absolute ones as they are), by default that directory itself."""
    dirs = m.get("plugin_dirs", ["."])
    if not isinstance(dirs, list) or not dirs or not all(isinstance(d, str) and d for d in dirs):
        raise _fail(source, "matrix.plugin_dirs", f"must be a non-empty list of directories, got {dirs!r}")
    if base_dir is None and "plugin_dirs" not in m:
        return ()
    out = []
    for i, d in enumerate(dirs):
        path = Path(d) if Path(d).is_absolute() or base_dir is None else Path(base_dir) / d
        if not path.is_dir():
            raise _fail(source, f"matrix.plugin_dirs[{i}]", f"{d!r}: no such directory ({path})")
        out.append(str(path.resolve()) if "plugin_dirs" in m else str(path))
    return tuple(out)


def parse_matrix(data: dict[str, Any], source: str = "<matrix>", *, base_dir: Path | None = None,
                 check_resets: bool = True, text: str | None = None) -> Matrix:
    """Validate parsed TOML ``data`` (see the module docstring). ``source`` labels messages;
    with the file's ``text``, errors in ``[sweep.*]`` tables also name the line."""
    unknown = sorted(set(data) - {"matrix", "scenarios", "controllers", "sweep", "frontier", "robustness"})
    if unknown:
        raise _fail(source, unknown[0], "unknown table; expected [matrix], [scenarios.NAME], "
                                        "[controllers.NAME], [sweep.NAME], [frontier] or [robustness]")
    m = data.get("matrix")
    if not isinstance(m, dict):
        raise _fail(source, "matrix", "missing [matrix] table")
    bad = sorted(set(m) - set(_MATRIX_KEYS))
    if bad:
        raise _fail(source, f"matrix.{bad[0]}", f"unknown key; expected one of {list(_MATRIX_KEYS)}")
    for key in ("controllers", "scenarios", "seeds"):
        if key not in m:
            raise _fail(source, f"matrix.{key}", "is required")

    plugins = m.get("plugins", [])
    if not isinstance(plugins, list) or not all(isinstance(p, str) and p for p in plugins):
        raise _fail(source, "matrix.plugins", f"must be a list of module names, got {plugins!r}")
    plugin_dirs = _plugin_dirs(source, m, base_dir) if plugins or "plugin_dirs" in m else ()
    limit = _number(source, "matrix.time_limit_s", m.get("time_limit_s", DEFAULT_TIME_LIMIT_S),
                    positive=True, allow_zero=False)
    if limit > MAX_TIME_LIMIT_S:
        raise _fail(source, "matrix.time_limit_s", f"must be <= {MAX_TIME_LIMIT_S:g} s (a week), got {limit!r}")
    for i, module in enumerate(plugins):
        if check_resets:
            _check_plugin_import(source, i, module, plugin_dirs, limit)
        try:
            load_plugins((module,), plugin_dirs)
        except Exception as exc:
            raise _fail(source, f"matrix.plugins[{i}]", f"cannot import {module!r}: "
                                                         f"{type(exc).__name__}: {exc}") from None

    seeds = m["seeds"]
    if (not isinstance(seeds, list) or not seeds
            or not all(isinstance(s, int) and not isinstance(s, bool) and 0 <= s < 2**63 for s in seeds)):
        raise _fail(source, "matrix.seeds", f"must be a non-empty list of integers in [0, 2**63), got {seeds!r}")
    if len(set(seeds)) != len(seeds):
        raise _fail(source, "matrix.seeds", "lists a seed more than once")

    duration = _number(source, "matrix.duration_s", m["duration_s"], positive=True, allow_zero=False) \
        if "duration_s" in m else None
    warmup = _number(source, "matrix.warmup_s", m["warmup_s"], positive=True) if "warmup_s" in m else None
    description = m.get("description", "")
    if not isinstance(description, str):
        raise _fail(source, "matrix.description", f"must be a string, got {description!r}")

    scenarios = _scenarios(source, data.get("scenarios", {}), text)
    variants = _variants(source, data.get("controllers", {}))

    from controllers.base import available_controllers
    registered = available_controllers()
    chosen_controllers = []
    for i, name in enumerate(_names(source, "matrix.controllers", m["controllers"])):
        if name in variants:
            chosen_controllers.append(variants[name])
        elif name in registered:
            _check_name(source, f"matrix.controllers[{i}]", name)   # a plugin may register any string
            chosen_controllers.append(ControllerSpec(name, name, {}))
        else:
            known = sorted(set(registered) | set(variants))
            raise _fail(source, f"matrix.controllers[{i}]", f"unknown controller {name!r}; known: {known}")
    chosen_scenarios = []
    for i, name in enumerate(_names(source, "matrix.scenarios", m["scenarios"])):
        if name not in scenarios:
            raise _fail(source, f"matrix.scenarios[{i}]", f"unknown scenario {name!r}; known: {sorted(scenarios)}")
        try:
            chosen_scenarios.append(scenarios[name].with_durations(duration, warmup))
        except ValueError as exc:
            key = "matrix.warmup_s" if warmup is not None else "matrix.duration_s"
            raise _fail(source, key, f"scenario {name!r}: {exc}") from None
    from bench.sweep import expand_sweeps, locate_key

    def sweep_fail(key: str, message: str) -> MatrixError:
        parts = key.split(".")
        line = locate_key(text, ".".join(parts[:2]), parts[2] if len(parts) > 2 else None) if text else None
        return _fail(f"{source}:{line}" if line else source, key, message)

    plan = expand_sweeps(data.get("sweep"), chosen_controllers, chosen_scenarios, sweep_fail)
    frontier = data.get("frontier", {})
    if not isinstance(frontier, dict):
        raise _fail(source, "frontier", "must be a table (settings of the report's frontier section)")
    robustness = data.get("robustness", {})
    if not isinstance(robustness, dict):
        raise _fail(source, "robustness", "must be a table (settings of the report's robustness section)")
    _check_plan_names(source, plan, sweep_fail)
    _check_robustness(source, text, robustness, [c.name for c in plan.controllers], [s.name for s in plan.scenarios])
    for scenario in plan.scenarios:
        _check_samples(source, scenario, duration is not None, warmup is not None)
    if check_resets:
        _check_resets(source, plan.controllers, plan.scenarios, set(variants), tuple(plugins), plugin_dirs, limit)
    return Matrix(source, tuple(plan.controllers), tuple(plan.scenarios), tuple(seeds), limit,
                  tuple(plugins), plugin_dirs, duration, warmup, description, variants, plan.to_json(),
                  frontier, robustness)


#: The ``[robustness]`` keys (written by ``bench.robustness.robustness_matrix_data``, read by
#: ``reports.robustness``) and what each must be.
_ROBUSTNESS_KEYS = {
    "reference": "the name of a scenario of this matrix",
    "best_source": "a string (where the best points come from)",
    "best": "a table of controller row = parent name (the rows that are best points)",
    "told_nominal": "a table of scenario = built-in scenario name (the scenarios told Table 2-1)",
    "bounds": "true or false (whether the privileged bounds run)",
}


def _check_robustness(source: str, text: str | None, table: dict[str, Any], controllers: list[str],
                      scenarios: list[str]) -> None:
    """The ``[robustness]`` table: known keys only, each of its type (:data:`_ROBUSTNESS_KEYS`);
    ``reference``, the rows of ``best`` and the scenarios of ``told_nominal`` are of this matrix."""
    def fail(key: str, message: str, sub: str | None = None) -> MatrixError:
        where = _at(source, text, ("robustness", key), sub) if sub is not None else None
        if where is None or where == source:
            where = _at(source, text, ("robustness",), key)
        return _fail(where, f"robustness.{key}" + (f".{sub}" if sub is not None else ""), message)

    for key in table:
        if key not in _ROBUSTNESS_KEYS:
            raise fail(key, f"unknown key; expected one of {list(_ROBUSTNESS_KEYS)}")
    for key in ("reference", "best_source"):
        if key in table and not isinstance(table[key], str):
            raise fail(key, f"must be {_ROBUSTNESS_KEYS[key]}, got {table[key]!r}")
    if "reference" in table and table["reference"] not in scenarios:
        raise fail("reference", f"must be {_ROBUSTNESS_KEYS['reference']}, got {table['reference']!r}; "
                                f"scenarios: {scenarios}")
    if "bounds" in table and not isinstance(table["bounds"], bool):
        raise fail("bounds", f"must be {_ROBUSTNESS_KEYS['bounds']}, got {table['bounds']!r}")
    for key, known, kind in (("best", controllers, "controller row"), ("told_nominal", scenarios, "scenario")):
        if key not in table:
            continue
        value = table[key]
        if not isinstance(value, dict):
            raise fail(key, f"must be {_ROBUSTNESS_KEYS[key]}, got {value!r}")
        for name, target in value.items():
            if name not in known:
                raise fail(key, f"{name!r} is not a {kind} of this matrix; {kind}s: {known}", name)
            if not isinstance(target, str) or not target:
                raise fail(key, f"must be a name, got {target!r}", name)


def _check_plan_names(source: str, plan: Any, sweep_fail: Any) -> None:
    """Every controller and scenario name of the expanded matrix (sweep points and their swept
    values included) is a safe, short file-name part (:func:`bench.names.name_problem`), and no
    two controllers or scenarios share a name (so no cell is planned twice)."""
    from bench.sweep import point_name

    for kind, items, points in (("controller", [c.name for c in plan.controllers], plan.controller_points),
                                ("scenario", [s.name for s in plan.scenarios], plan.scenario_points)):
        seen: set[str] = set()
        for name in items:
            point = points.get(name)
            knobs = (point or {}).get("knobs" if kind == "controller" else "params") or {}
            table = "scenario" if kind == "scenario" else (point or {}).get("parent", "")
            problem = name_problem(name)
            if name in seen:
                problem = f"plans the {kind} {name!r} twice (values that print alike, e.g. 40 and 40.0?)"
            if problem:
                if knobs:
                    bad = [k for k, v in knobs.items() if name_problem(point_name(point["parent"], {k: v}))]
                    raise sweep_fail(f"sweep.{table}.{(bad or list(knobs))[0]}", problem)
                key = f"controllers.{name}" if kind == "controller" else f"scenarios.{name}"
                raise _fail(source, key, problem)
            seen.add(name)


def _check_samples(source: str, scenario: Scenario, matrix_duration: bool, matrix_warmup: bool) -> None:
    """The run length and warm-up in whole samples, as the runner counts them: at least one
    sample, a scoring window of at least one sample, and at most :data:`MAX_SAMPLES` samples."""
    tau = scenario.params.sample_period
    where = "matrix" if matrix_duration or matrix_warmup else f"scenarios.{scenario.name}"
    ratio = scenario.duration_s / tau      # both finite and tau >= 1e-6 s (PlantParams): no overflow to round
    if not ratio <= MAX_SAMPLES:
        raise _fail(source, f"{where}.duration_s",
                    f"scenario {scenario.name!r}: duration_s = {scenario.duration_s!r} s is {ratio:.3g} samples of "
                    f"{tau} s; at most {MAX_SAMPLES} samples (duration_s <= {MAX_SAMPLES * tau:g} s at this "
                    f"sample period; the runner holds ~16 bytes per sample)")
    n = round(ratio)
    n_warm = round(scenario.warmup_s / tau)
    if n < 1:
        raise _fail(source, f"{where}.duration_s", f"scenario {scenario.name!r}: {scenario.duration_s!r} s is "
                                                   f"less than half a sample period ({tau} s)")
    if n_warm >= n:
        raise _fail(source, f"{where}.warmup_s", f"scenario {scenario.name!r}: warmup_s = {scenario.warmup_s!r} s "
                                                 f"leaves no sample to score before duration_s = "
                                                 f"{scenario.duration_s!r} s (sample period {tau} s)")


RESET_CHECK_GRACE_S = 5.0    # the reset check: plugin imports and first-call compilation, beyond a cell's limit


def _check_resets(source: str, controllers: list[ControllerSpec], scenarios: list[Scenario],
                  variants: set[str], plugins: tuple[str, ...] = (), plugin_dirs: tuple[str, ...] = (),
                  limit_s: float = DEFAULT_TIME_LIMIT_S) -> None:
    """Build and reset every controller on every scenario's plant once, so that an option the
    controller rejects against the plant (e.g. a dither amplitude >= u_max) is a user error now,
    not an ``error`` row in every cell later.

    Each build and reset runs in a supervised cell process (:func:`bench.isolation.call_isolated`,
    one process reused while it stays healthy) within one cell's time limit plus
    :data:`RESET_CHECK_GRACE_S`: a reset that loops, exits the process or leaves a thread running
    cannot hang or end the CLI; it is a user error naming the controller.
    """
    from bench.isolation import CellFailure, call_isolated, ready, reopen, retire_idle

    reopen()      # a previous run in this process may have closed the pool
    ready()       # the forkserver's start and imports are not part of the limit
    try:
        for cs in controllers:
            key = f"controllers.{cs.name}" if cs.name in variants else "matrix.controllers"
            for scenario in scenarios:
                try:
                    failure = call_isolated(_first_reset_failure, ([cs], [scenario], plugins, plugin_dirs),
                                            limit_s + RESET_CHECK_GRACE_S, key=("reset-check", plugins, plugin_dirs))
                except CellFailure as exc:
                    raise _fail(source, key, f"controller {cs.name!r} on scenario {scenario.name!r}: "
                                             f"{_reset_failure_text(exc, limit_s)}") from None
                if failure is not None:
                    _, _, kind, msg = failure
                    named = [o for o in cs.options if re.search(rf"\b{re.escape(o)}\b", msg)]
                    if named and cs.name in variants:
                        key += f".{named[0]}"
                    raise _fail(source, key, f"rejected on scenario {scenario.name!r}: {kind}: {msg}")
    finally:
        retire_idle()


def _check_plugin_import(source: str, i: int, module: str, plugin_dirs: tuple[str, ...], limit_s: float) -> None:
    """Import plugin ``module`` first in a supervised cell process: an import that loops or ends
    the process, or that leaves a non-daemon thread running (it would keep the CLI alive), is a
    user error before the CLI imports it itself."""
    from bench.isolation import CellFailure, call_isolated, ready, reopen, retire_idle

    key = f"matrix.plugins[{i}]"
    reopen()
    ready()
    try:
        threads = call_isolated(_import_probe, (module, plugin_dirs), limit_s + RESET_CHECK_GRACE_S,
                                key=("plugin-check", module, plugin_dirs))
    except CellFailure as exc:
        what = (f"did not finish within {limit_s + RESET_CHECK_GRACE_S:g} s (matrix.time_limit_s + "
                f"{RESET_CHECK_GRACE_S:g} s)" if exc.kind == "time_limit" else f"failed: {exc.message}")
        raise _fail(source, key, f"importing {module!r} {what}") from None
    finally:
        retire_idle()
    if threads:
        raise _fail(source, key, f"importing {module!r} starts non-daemon thread(s) {threads}, which would keep "
                                 f"the command from exiting; make them daemon threads or start them in reset")


def _import_probe(module: str, plugin_dirs: tuple[str, ...]) -> list[str]:
    """Import ``module`` (in the plugin check's process); the names of the non-daemon threads it
    left running. An import error is left to the caller's own import, which reports it."""
    import threading

    before = set(threading.enumerate())
    try:
        load_plugins((module,), plugin_dirs)
    except Exception:
        return []
    return [t.name for t in threading.enumerate() if t not in before and t.is_alive() and not t.daemon]


def _reset_failure_text(exc: Any, limit_s: float) -> str:
    if exc.kind == "time_limit":
        return (f"construction or reset did not return within {limit_s + RESET_CHECK_GRACE_S:g} s "
                f"(matrix.time_limit_s + {RESET_CHECK_GRACE_S:g} s)")
    return f"construction or reset failed: {exc.message}"


def _first_reset_failure(controllers: list[ControllerSpec], scenarios: list[Scenario], plugins: tuple[str, ...],
                         plugin_dirs: tuple[str, ...]) -> tuple[str, str, str, str] | None:
    """(controller, scenario, exception type, message) of the first build or reset that raises an
    Exception, or None (runs in the reset check's cell process)."""
    import numpy as np

    load_plugins(plugins, plugin_dirs)
    for cs in controllers:
        for scenario in scenarios:
            try:
                cs.build().reset(scenario.model_params(), np.random.default_rng(0))
            except Exception as exc:   # the controller's own validation message
                return cs.name, scenario.name, type(exc).__name__, str(exc)
    return None


def _scenarios(source: str, table: Any, text: str | None = None) -> dict[str, Scenario]:
    if not isinstance(table, dict):
        raise _fail(source, "scenarios", "must be a table of [scenarios.NAME] tables")
    known = builtin_scenarios()
    pending = dict(table)
    for name in pending:
        key = f"scenarios.{name}"
        _check_name(source, key, name)
        if name in known:
            raise _fail(source, key, f"redefines the built-in scenario {name!r}; choose another name")
        if not isinstance(pending[name], dict):
            raise _fail(source, key, "must be a table")
    resolving: list[str] = []

    def resolve(name: str) -> Scenario:
        if name in known:
            return known[name]
        key = f"scenarios.{name}"
        if name in resolving:
            raise _fail(source, key, f"base chain loops: {' -> '.join(resolving + [name])}")
        spec = dict(pending[name])
        base = spec.pop("base", None)
        if not isinstance(base, str):
            raise _fail(source, f"{key}.base", f"is required and must name a scenario, got {base!r}")
        if base not in known and base not in pending:
            raise _fail(source, f"{key}.base", f"unknown scenario {base!r}; known: {sorted(set(known) | set(pending))}")
        resolving.append(name)
        base_scenario = resolve(base)
        resolving.pop()
        _check_plant_keys(source, text, name, spec, base_scenario)
        try:
            scenario = derive_scenario(name, base_scenario, spec)
        except ValueError as exc:
            raise _scenario_error(source, text, name, spec, str(exc)) from None
        known[name] = scenario
        return scenario

    for name in list(pending):
        resolve(name)
    return known


def _at(source: str, text: str | None, parts: tuple[str, ...], key: str | None) -> str:
    """``source`` with the line of ``key`` in the table ``[parts]`` when the text shows it."""
    from bench.sweep import locate_key

    line = locate_key(text, parts, key) if text else None
    return f"{source}:{line}" if line else source


def _check_plant_keys(source: str, text: str | None, name: str, spec: dict[str, Any], base: Scenario) -> None:
    """The truth's family and keys, the ``model`` and ``mismatch`` tables: every key known, before
    any value is used (each error names the file, the line and the key)."""
    from plant.protocol import available_families, get_family

    table = ("scenarios", name)
    family_name = spec.get("plant", base.family)
    if not isinstance(family_name, str) or family_name not in available_families():
        raise _fail(_at(source, text, table, "plant"), f"scenarios.{name}.plant",
                    f"unknown plant family {family_name!r}; known: {available_families()}")
    fields = {f.name for f in dataclasses.fields(get_family(family_name).Params)}
    unknown = sorted(set(spec) - set(SCENARIO_KEYS) - fields)
    if unknown:
        raise _fail(_at(source, text, table, unknown[0]), f"scenarios.{name}.{unknown[0]}",
                    f"unknown key; expected one of {list(SCENARIO_KEYS)} or a field of plant family "
                    f"{family_name!r}: {sorted(fields)}")
    for sub, allowed, what in (("model", _PLANT_FIELDS, "a PlantParams field (what controllers are told)"),
                               ("mismatch", fields, f"a field of plant family {family_name!r}")):
        if sub not in spec:
            continue
        values = spec[sub]
        if not isinstance(values, dict):
            raise _fail(_at(source, text, table, sub), f"scenarios.{name}.{sub}",
                        f"must be a table [scenarios.{name}.{sub}] of field = value, got {values!r}")
        bad = sorted(set(values) - allowed)
        if bad:
            raise _fail(_at(source, text, (*table, sub), bad[0]), f"scenarios.{name}.{sub}.{bad[0]}",
                        f"unknown key; expected {what}: {sorted(allowed)}")


def _scenario_error(source: str, text: str | None, name: str, spec: dict[str, Any], message: str) -> MatrixError:
    """A scenario's ValueError as a MatrixError naming the table, key and line it comes from."""
    table = ("scenarios", name)
    m = re.match(r"Scenario\.(model|mismatch)\.(\w+)", message)
    if m:
        return _fail(_at(source, text, (*table, m.group(1)), m.group(2)), f"scenarios.{name}.{m.group(1)}.{m.group(2)}",
                     message)
    fld = re.search(r"\b\w*Params\.(\w+)", message)
    if fld and isinstance(spec.get("model"), dict) and fld.group(1) in spec["model"] \
            and fld.group(1) not in spec:
        return _fail(_at(source, text, (*table, "model"), fld.group(1)), f"scenarios.{name}.model.{fld.group(1)}",
                     message)
    key = fld.group(1) if fld else _field_of(message, "Scenario")
    return _fail(_at(source, text, table, key), f"scenarios.{name}.{key}" if key else f"scenarios.{name}", message)


def _variants(source: str, table: Any) -> dict[str, ControllerSpec]:
    if not isinstance(table, dict):
        raise _fail(source, "controllers", "must be a table of [controllers.NAME] tables")
    from controllers.base import available_controllers
    registered = available_controllers()
    out: dict[str, ControllerSpec] = {}
    for name, spec in table.items():
        key = f"controllers.{name}"
        _check_name(source, key, name)
        if not isinstance(spec, dict):
            raise _fail(source, key, "must be a table")
        if name in registered:
            raise _fail(source, key, f"a variant cannot reuse the registered name {name!r}; choose another name")
        options = dict(spec)
        base = options.pop("base", None)
        if base not in registered:
            raise _fail(source, f"{key}.base", f"must name a registered controller, got {base!r}; "
                                               f"registered: {sorted(registered)}")
        cs = ControllerSpec(name, base, options)
        _check_variant(source, key, registered[base], options, cs)
        out[name] = cs
    return out


def _check_variant(source: str, key: str, cls: Any, options: dict[str, Any], cs: ControllerSpec) -> None:
    """Map a variant's options onto the base's ``Options`` fields (protocol v2): an unknown
    preset or field, an ill-typed value or one its ``__post_init__`` rejects is a
    :class:`MatrixError` naming ``controllers.NAME.field``. A base without an ``Options``
    dataclass is checked by building it."""
    from controllers.base import resolve_options

    fields = dict(options)
    preset = fields.pop("preset", None)
    if preset is not None and not isinstance(preset, str):
        raise _fail(source, f"{key}.preset", f"must be a preset name, got {preset!r}")
    try:
        if cls.Options is not None:
            resolve_options(cls, None, preset, fields)
        else:
            cs.build()
    except Exception as exc:  # the options validate themselves (ValueError, TypeError)
        msg = str(exc)
        quoted = re.search(r"option '(\w+)'", msg)
        if quoted and quoted.group(1) in fields:
            named = [quoted.group(1)]
        else:
            named = [o for o in fields if re.search(rf"\b{re.escape(o)}\b", msg)]
        if not named and preset is not None and "preset" in msg:
            named = ["preset"]
        where = f"{key}.{named[0]}" if named else key
        raise _fail(source, where, f"{type(exc).__name__}: {msg}" if not isinstance(exc, ValueError)
                    else msg) from None
