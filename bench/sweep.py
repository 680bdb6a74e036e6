"""Sweeps as data: ``[sweep.<controller>]`` and ``[sweep.scenario]`` tables of a matrix file.

A sweep turns one controller (a registered name or a variant listed in ``matrix.controllers``)
into one ordinary controller variant per point of the grid, and a scenario into one scenario
per point. Every point is an ordinary cell (same store, resume, executors, traces policy)::

    [sweep.solnic]                  # one or two option fields; two give the cross product
    a_c = [1e-6, 1e-5, 1e-4]
    include_default = true          # optional: also keep the unswept controller (its defaults)

    [sweep.linear]
    crossover = [40.0, 60.0]
    lag_ratio = [3.0, 6.0]

    [sweep.scenario]                # PlantParams fields
    base = "thesis"                 # optional: sweep only this scenario (default: every one)
    combine = "separate"            # "product" (default) or "separate" (one field at a time)
    friction_noise_psd = [0.0, 2e-4, 8e-4]
    measurement_noise_std = [1e-6, 2e-5]

A controller point is named ``<controller>[field=value,...]`` (e.g. ``solnic[a_c=1e-05]``) and
built with the swept fields as keyword overrides of the controller's (or variant's) options, so
protocol-v2 controllers type-check them in :func:`controllers.base.resolve_options` and legacy
``**kwargs`` controllers validate them in their constructor; either failure is a
:class:`~bench.matrix.MatrixError` naming ``sweep.<controller>.<field>`` (and the line).

A swept controller is *replaced* by its points (preceded by itself with
``include_default = true``). Scenario points are *added* after the matrix's
scenarios (named ``<scenario>[field=value,...]``); a point whose plant equals a scenario already in
the matrix is that scenario and is not run twice.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable

from bench.cells import ControllerSpec
from bench.scenarios import Scenario, derive_scenario

__all__ = ["SweepPlan", "expand_sweeps", "point_name", "format_value", "locate_key"]

_SCENARIO_TABLE = "scenario"
_SCENARIO_RESERVED = ("base", "combine")
MAX_FIELDS = 2


def format_value(value: Any) -> str:
    """A short, exact label for a swept value (``1e-05``, ``40``, ``true``)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if not value.is_integer() or abs(value) >= 1e16 else str(int(value))
    return str(value)


def point_name(parent: str, point: dict[str, Any]) -> str:
    """``parent[field=value,...]`` in the order of the sweep's fields."""
    return f"{parent}[{','.join(f'{k}={format_value(v)}' for k, v in point.items())}]"


def locate_key(text: str, table: str | tuple[str, ...], key: str | None = None) -> int | None:
    """1-based line of ``key`` inside ``[table]`` of TOML ``text`` (of the header if ``key`` is
    None or not found); None if the table is not written as a header (e.g. inline). ``table``
    is ``"kind.name"`` (split at the first dot: names may hold dots) or the header's parts."""
    parts = list(table) if isinstance(table, tuple) else _split_dotted(table)
    header = re.compile(r"^\s*\[\s*" + r"\s*\.\s*".join(r'(?:' + re.escape(p) + r'|"' + re.escape(p) + r'")'
                                                      for p in parts)
                        + r"\s*\]\s*(#.*)?$")
    any_header = re.compile(r"^\s*\[")
    key_re = re.compile(r"^\s*(" + re.escape(key) + r'|"' + re.escape(key) + r'")\s*=') if key else None
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if header.match(line):
            if key_re is None:
                return i + 1
            for j in range(i + 1, len(lines)):
                if any_header.match(lines[j]):
                    break
                if key_re.match(lines[j]):
                    return j + 1
            return i + 1
    return None


def _split_dotted(table: str) -> list[str]:
    head, _, rest = table.partition(".")
    return [head, rest] if rest else [head]


@dataclass
class SweepPlan:
    """The expanded sweep: the matrix's controllers and scenarios plus what each point is.

    ``controller_points`` maps a point's name to ``{"parent": name, "knobs": {field: value}}``;
    ``scenario_points`` maps a scenario point to ``{"parent": name, "params": {field: value}}``
    (and ``"same_as"`` when it coincides with a scenario already in the matrix).
    """

    controllers: list[ControllerSpec]
    scenarios: list[Scenario]
    controller_points: dict[str, dict[str, Any]] = field(default_factory=dict)
    scenario_points: dict[str, dict[str, Any]] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"controllers": self.controller_points, "scenarios": self.scenario_points}


def _grid(fail: Callable[[str, str], Exception], key: str, table: dict[str, Any],
          combine: str) -> list[dict[str, Any]]:
    if not table:
        raise fail(key, "must list at least one field = [values]")
    for name, values in table.items():
        if not isinstance(values, list) or not values:
            raise fail(f"{key}.{name}", f"must be a non-empty list of values, got {values!r}")
        for v in values:
            if isinstance(v, (dict, list)) or (isinstance(v, float) and not math.isfinite(v)):
                raise fail(f"{key}.{name}", f"values must be finite scalars, got {v!r}")
        if len({format_value(v) for v in values}) != len(values):   # 40 and 40.0: one point name
            raise fail(f"{key}.{name}", f"lists a value more than once: {values!r}")
    names = list(table)
    if combine == "separate":
        return [{n: v} for n in names for v in table[n]]
    return [dict(zip(names, combo)) for combo in itertools.product(*(table[n] for n in names))]


def expand_sweeps(sweep: Any, controllers: list[ControllerSpec], scenarios: list[Scenario],
                  fail: Callable[[str, str], Exception]) -> SweepPlan:
    """Expand the ``[sweep.*]`` tables over the matrix's chosen ``controllers`` and ``scenarios``.

    ``fail(key, message)`` builds the caller's user error (it names the file and line).
    """
    plan = SweepPlan(list(controllers), list(scenarios))
    if sweep is None:
        return plan
    if not isinstance(sweep, dict):
        raise fail("sweep", "must be a table of [sweep.NAME] tables")
    by_name = {c.name: c for c in controllers}
    for name, table in sweep.items():
        key = f"sweep.{name}"
        if not isinstance(table, dict):
            raise fail(key, "must be a table of field = [values]")
        if name == _SCENARIO_TABLE:
            continue
        if name not in by_name:
            raise fail(key, f"sweeps {name!r}, which is not in matrix.controllers {sorted(by_name)}")
        table = dict(table)
        keep = table.pop("include_default", False)
        if not isinstance(keep, bool):
            raise fail(f"{key}.include_default", f"must be true or false, got {keep!r}")
        if len(table) > MAX_FIELDS:
            raise fail(key, f"sweeps {len(table)} fields; at most {MAX_FIELDS} (their cross product)")
        parent = by_name[name]
        points = [parent] if keep else []
        if keep:
            plan.controller_points[name] = {"parent": name, "base": parent.base, "knobs": {}}
        for point in _grid(fail, key, table, "product"):
            spec = ControllerSpec(point_name(name, point), parent.base, {**parent.options, **point})
            try:
                spec.build()
            except (ValueError, TypeError) as exc:
                msg = str(exc)
                named = [f for f in point if re.search(rf"\b{re.escape(f)}\b", msg)]
                bad = named[0] if named else next(iter(point))
                raise fail(f"{key}.{bad}", f"{point_name(name, point)}: {msg}") from None
            points.append(spec)
            plan.controller_points[spec.name] = {"parent": name, "base": parent.base, "knobs": point}
        i = plan.controllers.index(parent)
        plan.controllers[i:i + 1] = points
    if _SCENARIO_TABLE in sweep:
        _expand_scenarios(sweep[_SCENARIO_TABLE], plan, fail)
    return plan


def _plant_of(scenario) -> dict[str, Any]:
    """What a scenario runs: its definition without its names."""
    return {k: v for k, v in scenario.definition().items() if k not in ("name", "base")}


def _expand_scenarios(table: dict[str, Any], plan: SweepPlan, fail: Callable[[str, str], Exception]) -> None:
    from plant.params import PlantParams

    key = f"sweep.{_SCENARIO_TABLE}"
    table = dict(table)
    base = table.pop("base", None)
    combine = table.pop("combine", "product")
    if combine not in ("product", "separate"):
        raise fail(f"{key}.combine", f"must be \"product\" or \"separate\", got {combine!r}")
    parents_all = [s for s in plan.scenarios if base is None or s.name == base]
    plant_fields = set.intersection(*({f.name for f in dataclasses.fields(s.params)} for s in parents_all)) \
        if parents_all else {f.name for f in dataclasses.fields(PlantParams)}
    unknown = sorted(set(table) - plant_fields)
    if unknown:
        raise fail(f"{key}.{unknown[0]}", f"unknown key; expected {list(_SCENARIO_RESERVED)} or a "
                                          f"field of the swept scenarios' plant {sorted(plant_fields)}")
    if combine == "product" and len(table) > MAX_FIELDS:
        raise fail(key, f"sweeps {len(table)} fields as a product; at most {MAX_FIELDS} "
                        f"(or combine = \"separate\")")
    names = [s.name for s in plan.scenarios]
    if base is not None and base not in names:
        raise fail(f"{key}.base", f"must name a scenario of matrix.scenarios {names}, got {base!r}")
    parents = [s for s in plan.scenarios if base is None or s.name == base]
    grid = _grid(fail, key, table, combine)
    for parent in parents:
        for point in grid:
            name = point_name(parent.name, point)
            try:
                scenario = derive_scenario(name, parent, {**point, "description":
                                           f"{parent.name} with " + ", ".join(
                                               f"{k} = {format_value(v)}" for k, v in point.items())})
            except ValueError as exc:
                msg = str(exc)
                named = [f for f in point if f in msg]
                raise fail(f"{key}.{named[0] if named else next(iter(point))}", f"{name}: {msg}") from None
            plant = _plant_of(scenario)
            same = next((s for s in plan.scenarios if _plant_of(s) == plant
                         and (s.duration_s, s.warmup_s) == (scenario.duration_s, scenario.warmup_s)), None)
            info = {"parent": parent.name, "params": point}
            if same is not None:
                info["same_as"] = same.name
            else:
                plan.scenarios.append(scenario)
            plan.scenario_points[name] = info
