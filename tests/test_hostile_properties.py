"""The CLI's promises on generated hostile matrices (issue 28): a property-based harness.

hypothesis generates a matrix file and, for some examples, a plugin, from these classes:

* **names** — of a plugin's registered controller, a variant, a custom scenario, a swept string
  value: plain, ``../`` paths, ``a__b``, ``/``, spaces, emoji, control characters, empty, 1-300
  characters;
* **values** — run length, warm-up, time limit, plant fields (torque scale, sample period,
  inertia, friction, noise) and swept numbers: ordinary, zero, negative, subnormal, 1e20, 1e300,
  1e308, inf, nan, strings and booleans where a number belongs, duplicates that print alike;
* **plugins** — a controller that holds, raises in ``reset``, raises in ``step``, or returns a
  non-finite drive.

Each example runs ``solnic-bench run`` (``reports.cli.main``, in this process, so that the cells'
processes and the reset check's process come from one warm forkserver) and checks:

* exit 0 with every planned cell stored (``cells/<id>.json``, one row each in ``results.csv``),
  each ``ok``/``chatter``/``diverged`` or an ``error`` row with a message and an error kind — or
  exit 2 with one line ``error: <matrix file>...`` and no run directory;
* nothing written outside ``--out`` (the matrix and plugin sit four directories deep);
* no process left behind (no descendant of this process but the forkserver and its resource
  tracker, and the forkserver has no child);
* no traceback.

A fixed number of examples (:data:`EXAMPLES`), derandomized, no example database: the same cases
on every machine, within the ``make test`` budget (tiny runs, ``--no-traces``; about 10 s of CPU).
``HOSTILE28_EXAMPLES=500`` explores with that many random examples instead.
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import json
import math
import os
import tempfile
from pathlib import Path

import psutil
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

EXAMPLES = 40
_UNIQUE = itertools.count()

NAMES = st.one_of(
    st.sampled_from(["ctl", "v1", "a.b-c+d_e", "x[k=1]", "../../../escaped", "a__b", "a/b", "/abs", ".hidden",
                     "sp ace", "ctl\U0001F642", "tab\there", "", "-lead", "é", "con", "x" * 80, "x" * 81,
                     "y" * 236, "z" * 300, "linear[crossover=40]"]),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), min_size=1, max_size=12),
)
NUMBERS = st.sampled_from([0.1, 0.3, 0.5, 0, -1, -0.0, 5e-324, 1e-300, 1e20, 1e300, 1e308, math.inf, -math.inf,
                           math.nan, 200000.01, 1e6, 2.0, 40, 40.0, "s", True])
PLANT_FIELDS = ["u_max", "sample_period", "inertia", "stiction", "coulomb", "measurement_noise_std",
                "motor_time_constant", "friction_noise_psd"]
BEHAVIOURS = {
    "hold": "",
    "reset-raises": "    def reset(self, params, rng):\n        raise ValueError('bad plant for me')\n",
    "step-raises": "    def step(self, y):\n        raise RuntimeError('boom')\n",
    "nan-drive": "    def step(self, y):\n        return DriveCommand.hold(float('nan'))\n",
}
PLUGIN = '''
import dataclasses
from controllers.base import Controller, register, _REGISTRY
from plant.drive import DriveCommand

NAME = {name!r}
old = _REGISTRY.get(NAME)
if old is not None and old.__module__.startswith("hostile28_prop_"):
    del _REGISTRY[NAME]          # an earlier example's plugin: this one replaces it


@dataclasses.dataclass(frozen=True)
class Opts:
    label: str = "a"
    level: float = 0.0


@register(NAME)
class Generated(Controller):
    Options = Opts

    def reset(self, params, rng):
        pass

    def step(self, y):
        return DriveCommand.hold(self.options.level)

{behaviour}'''


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value == math.inf else "-inf" if value == -math.inf
                                                 else repr(value))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(value)


def _key(name: str) -> str:
    return json.dumps(name, ensure_ascii=False)


GOOD_NAMES = st.sampled_from(["ctl", "v1", "a.b-c+d_e", "Z9", "x" * 80])
GOOD_NUMBERS = st.sampled_from([0.2, 0.3, 0.5])
ASPECTS = ("registered", "variant", "scenario-name", "swept", "option", "plant", "duration", "warmup",
           "time-limit", "seeds", "sweep-numbers")


@st.composite
def hostile_matrix(draw):
    """(matrix text, plugin source or None, the plugin's module name). One or two aspects are
    hostile (drawn from their hostile classes), the others ordinary, so that examples reach every
    stage: parsing, planning, the reset check, the cells and the report."""
    hostile = draw(st.sets(st.sampled_from(ASPECTS), max_size=2))

    def pick(aspect, good, bad):
        return draw(bad if aspect in hostile else good)

    module = f"hostile28_prop_{os.getpid()}_{next(_UNIQUE)}"
    lines = ["[matrix]"]
    controllers = [draw(st.sampled_from(["linear", "pulse-width"]))]
    plugin = None
    tables: list[str] = []
    if draw(st.booleans()):
        name = pick("registered", GOOD_NAMES.map(lambda n: "p-" + n[:70]), NAMES)
        behaviour = draw(st.sampled_from(sorted(BEHAVIOURS)))
        plugin = PLUGIN.format(name=name, behaviour=BEHAVIOURS[behaviour])
        lines.append(f"plugins = [{_toml(module)}]")
        controllers.append(name)
        if draw(st.booleans()):
            values = pick("swept", st.lists(GOOD_NAMES.map(lambda n: n[:20]), min_size=1, max_size=2, unique=True),
                          st.lists(st.one_of(NAMES, NUMBERS), min_size=1, max_size=3))
            tables.append(f"[sweep.{_key(name)}]\nlabel = {_toml(values)}\n")
    if draw(st.booleans()):
        vname = pick("variant", GOOD_NAMES.map(lambda n: "v-" + n[:70]), NAMES)
        controllers.append(vname)
        crossover = pick("option", st.sampled_from([30.0, 48.0]), NUMBERS)
        tables.append(f"[controllers.{_key(vname)}]\nbase = \"linear\"\ncrossover = {_toml(crossover)}\n")
    if "linear" in controllers and draw(st.booleans()):
        values = pick("sweep-numbers", st.lists(st.sampled_from([24.0, 40.0, 48.0]), min_size=1, max_size=2,
                                                 unique=True), st.lists(NUMBERS, min_size=1, max_size=3))
        tables.append(f"[sweep.linear]\ncrossover = {_toml(values)}\n")
    scenarios = ["thesis"]
    if draw(st.booleans()):
        sname = pick("scenario-name", GOOD_NAMES.map(lambda n: "s-" + n[:70]), NAMES)
        scenarios.append(sname)
        field = draw(st.sampled_from(PLANT_FIELDS))
        value = pick("plant", st.sampled_from([None]), NUMBERS)
        override = "" if value is None else f"{field} = {_toml(value)}\n"
        tables.append(f"[scenarios.{_key(sname)}]\nbase = \"thesis\"\n{override}inertia = 0.6\n")
    lines.append(f"controllers = {_toml(controllers)}")
    lines.append(f"scenarios = {_toml(scenarios)}")
    seeds = pick("seeds", st.lists(st.integers(0, 3), min_size=1, max_size=2, unique=True),
                 st.one_of(st.lists(st.integers(-2, 2**64), min_size=0, max_size=3), NUMBERS))
    lines.append(f"seeds = {_toml(seeds)}")
    lines.append(f"duration_s = {_toml(pick('duration', GOOD_NUMBERS, NUMBERS))}")
    lines.append(f"warmup_s = {_toml(pick('warmup', st.just(0.1), NUMBERS))}")
    limit = pick("time-limit", st.sampled_from([30, 30.0]), st.sampled_from([0, -1, 1e300, math.nan, "x", 0.001]))
    lines.append(f"time_limit_s = {_toml(limit)}")
    return "\n".join(lines) + "\n\n" + "\n".join(tables), plugin, module


def _snapshot(root: Path, out: Path) -> set[str]:
    return {str(p) for p in root.rglob("*") if out not in p.parents and p != out and "__pycache__" not in p.parts}


def _left_behind() -> list[str]:
    """Descendants of this process other than the forkserver and its resource tracker, and any
    child of the forkserver (a cell process that outlived its run)."""
    me = psutil.Process()
    left = []
    for child in me.children(recursive=True):
        try:
            if child.status() == psutil.STATUS_ZOMBIE:
                continue
            cmd = " ".join(child.cmdline())
            parent = child.ppid()
        except psutil.NoSuchProcess:
            continue
        if parent == me.pid and ("multiprocessing.forkserver" in cmd or "multiprocessing.resource_tracker" in cmd):
            continue
        left.append(f"{child.pid} (parent {parent}): {cmd[:120]}")
    return left


def _check_example(text: str, plugin: str | None, module: str) -> None:
    from bench.cells import ERROR_KINDS
    from reports.cli import main

    with tempfile.TemporaryDirectory(prefix="hostile28-") as tmp:
        root = Path(tmp)
        work = root / "a" / "b" / "c" / "d"
        work.mkdir(parents=True)
        if plugin is not None:
            (work / f"{module}.py").write_text(plugin, encoding="utf-8")
        m = work / "m.toml"
        m.write_text(text, encoding="utf-8")
        out = work / "out"
        before = _snapshot(root, out)
        err, std = io.StringIO(), io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
            try:
                main(["run", "--matrix", str(m), "--out", str(out), "--no-traces", "--workers", "1"])
                code = 0
            except SystemExit as stop:
                code = stop.code
        stderr = err.getvalue()
        case = f"\n--- matrix\n{text}\n--- plugin\n{plugin}\n--- stderr\n{stderr}"
        assert "Traceback" not in stderr and "Traceback" not in std.getvalue(), case
        assert code in (0, 2), f"exit {code}{case}"
        assert _snapshot(root, out) == before, f"written outside --out{case}"
        assert not _left_behind(), f"left behind: {_left_behind()}{case}"
        if code == 2:
            event(f"exit 2: {stderr.split(':')[2].strip() if stderr.count(':') > 2 else stderr[:30]}")
            lines = [ln for ln in stderr.splitlines() if ln.strip()]
            assert len(lines) == 1 and lines[0].startswith(f"error: {m}"), case
            assert not out.exists(), f"a user error wrote {sorted(os.listdir(out))}{case}"
            return
        planned = json.loads((out / "config.json").read_text())["cells"]
        event(f"exit 0: {len(planned)} cells")
        stored = {p.stem for p in (out / "cells").glob("*.json")}
        assert stored == set(planned) and len(planned) == len(set(planned)), case
        with open(out / "results.csv", newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
        assert sorted(r["cell"] for r in rows) == sorted(planned), case
        for r in rows:
            assert r["status"] in ("ok", "chatter", "diverged", "error"), case
            if r["status"] == "error":
                assert r["message"] and r["error_kind"] in ERROR_KINDS, case


@pytest.mark.slow
@settings(max_examples=int(os.environ.get("HOSTILE28_EXAMPLES", EXAMPLES)),     # more, random: exploration
          derandomize="HOSTILE28_EXAMPLES" not in os.environ, database=None, deadline=None, print_blob=False,
          suppress_health_check=list(HealthCheck))
@given(hostile_matrix())
def test_the_cli_keeps_its_promises_on_generated_hostile_matrices(case):
    _check_example(*case)
