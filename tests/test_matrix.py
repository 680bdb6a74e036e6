"""Matrix files: the schema, the built-in matrices, cell ids and config hashes, and the errors."""

from __future__ import annotations

import dataclasses

import pytest

from bench.matrix import MatrixError, builtin_matrix_path, load_matrix
from bench.scenarios import builtin_scenarios
from plant.params import PlantParams


def write(tmp_path, text: str, name: str = "matrix.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_builtin_scenarios_match_the_spec():
    s = builtin_scenarios()
    assert s["thesis"].params == PlantParams() and (s["thesis"].duration_s, s["thesis"].warmup_s) == (100, 20)
    assert s["quiet-friction"].params == PlantParams(friction_noise_psd=0.0)
    assert (s["ratio-2"].params.stiction, s["ratio-2"].params.coulomb) == (2.8, 1.4)


@pytest.mark.parametrize("quick", [False, True])
def test_builtin_matrices_cover_every_controller_and_scenario(quick):
    m = load_matrix(builtin_matrix_path(quick))
    names = [c.name for c in m.controllers]
    from controllers.base import available_controllers
    real = {n for n, c in available_controllers().items() if not c.privileged}
    assert real <= set(names)  # every registered controller runs (bounds run in the frontier)
    if not quick:
        assert "solnic-high" in names                 # the high-error-cost claim needs it
    assert [s.name for s in m.scenarios] == ["thesis", "quiet-friction", "ratio-2"]
    assert len(m.cells()) == 3 * len(names) * len(m.seeds)
    if quick:
        default = load_matrix(builtin_matrix_path(False))
        assert len(m.seeds) < len(default.seeds)
        assert all(s.duration_s < 100 for s in m.scenarios)


def test_schema_variants_custom_scenarios_and_overrides(tmp_path):
    m = load_matrix(write(tmp_path, """
[matrix]
controllers = ["solnic-hi", "linear"]
scenarios = ["heavy-load", "heavier", "thesis"]
seeds = [3, 1]
duration_s = 12
warmup_s = 2

[scenarios.heavy-load]
base = "thesis"
inertia = 1.0

[scenarios.heavier]
base = "heavy-load"
inertia = 2.0
coulomb = 1.0

[controllers.solnic-hi]
base = "solnic"
preset = "high-error-cost"
"""))
    hi, lin = m.controllers
    assert (hi.name, hi.base, hi.options) == ("solnic-hi", "solnic", {"preset": "high-error-cost"})
    assert (lin.name, lin.base, lin.options) == ("linear", "linear", {})
    heavy, heavier, thesis = m.scenarios
    assert heavy.params == PlantParams(inertia=1.0)
    assert heavier.params == PlantParams(inertia=2.0, coulomb=1.0) and heavier.base == "thesis"
    assert {(s.duration_s, s.warmup_s) for s in m.scenarios} == {(12.0, 2.0)}
    cells = m.cells()
    assert [c.cell_id for c in cells[:3]] == ["solnic-hi__heavy-load__s3", "solnic-hi__heavy-load__s1",
                                              "solnic-hi__heavier__s3"]
    assert len(cells) == 12 and len({c.config_hash for c in cells}) == 12


def test_config_hash_is_stable_and_follows_what_determines_the_numbers(tmp_path):
    text = '[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\nduration_s = 5\nwarmup_s = 1\n'
    a = load_matrix(write(tmp_path, text, "a.toml")).cells()[0]
    b = load_matrix(write(tmp_path, text + "time_limit_s = 99\n", "b.toml")).cells()[0]
    assert a.config_hash == b.config_hash                       # the time limit is not part of it
    assert a.config_hash == dataclasses.replace(a).config_hash
    for changed in (dataclasses.replace(a, seed=1),
                    dataclasses.replace(a, scenario=a.scenario.with_durations(duration_s=6.0)),
                    dataclasses.replace(a, scenario=dataclasses.replace(a.scenario, params=PlantParams(inertia=0.6))),
                    dataclasses.replace(a, controller=dataclasses.replace(a.controller, options={"lag_ratio": 3.0}))):
        assert changed.config_hash != a.config_hash


@pytest.mark.parametrize("text, message", [
    ('[matrix]\ncontrollers = ["linear"\n', r"^matrix\.toml:2: invalid TOML: Unclosed array"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\n', r"matrix\.toml: matrix\.seeds: is required"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\nseed = 1\n',
     r"matrix\.toml: matrix\.seed: unknown key"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0, 0]\n',
     r"matrix\.toml: matrix\.seeds: lists a seed more than once"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [true]\n',
     r"matrix\.toml: matrix\.seeds: must be a non-empty list of integers in \[0, 2\*\*63\)"),
    ('[matrix]\ncontrollers = ["pid"]\nscenarios = ["thesis"]\nseeds = [0]\n',
     r"matrix\.toml: matrix\.controllers\[0\]: unknown controller 'pid'; known: \[.*'linear'.*'solnic'"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["mars"]\nseeds = [0]\n',
     r"matrix\.toml: matrix\.scenarios\[0\]: unknown scenario 'mars'; known: \[.*'ratio-2'"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\nwarmup_s = 200\n',
     r"matrix\.toml: matrix\.warmup_s: scenario 'thesis': Scenario\.warmup_s must be in \[0, duration_s"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["h"]\nseeds = [0]\n[scenarios.h]\nbase = "thesis"\n'
     'inertia = -1.0\n', r"matrix\.toml:7: scenarios\.h\.inertia: PlantParams\.inertia must be > 0, got -1\.0"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["h"]\nseeds = [0]\n[scenarios.h]\nbase = "thesis"\n'
     'coulomb = 3.0\n', r"matrix\.toml:5: scenarios\.h\.stiction: PlantParams\.stiction must be >= coulomb"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["h"]\nseeds = [0]\n[scenarios.h]\nbase = "thesis"\n'
     'inertai = 1.0\n', r"matrix\.toml:7: scenarios\.h\.inertai: unknown key"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["h"]\nseeds = [0]\n[scenarios.h]\nbase = "h2"\n'
     '[scenarios.h2]\nbase = "h"\n', r"matrix\.toml: scenarios\.h\d?: base chain loops"),
    ('[matrix]\ncontrollers = ["lin"]\nscenarios = ["thesis"]\nseeds = [0]\n[controllers.lin]\nbase = "linear"\n'
     'lag_ratio = 0.5\n', r"matrix\.toml: controllers\.lin\.lag_ratio: lag_ratio must be >= 1, got 0\.5"),
    ('[matrix]\ncontrollers = ["lin"]\nscenarios = ["thesis"]\nseeds = [0]\n[controllers.lin]\nbase = "linear"\n'
     'crossuver = 30.0\n', r"matrix\.toml: controllers\.lin\.crossuver: unknown option 'crossuver' of 'linear'"),
    ('[matrix]\ncontrollers = ["lin"]\nscenarios = ["thesis"]\nseeds = [0]\n[controllers.lin]\nbase = "linear"\n'
     'crossover = "fast"\n', r"matrix\.toml: controllers\.lin\.crossover: option 'crossover' of 'linear' "
                             r"must be a number, got 'fast'"),
    ('[matrix]\ncontrollers = ["d"]\nscenarios = ["thesis"]\nseeds = [0]\n[controllers.d]\nbase = "dithered"\n'
     'random_phase = 1\n', r"matrix\.toml: controllers\.d\.random_phase: option 'random_phase' of 'dithered' "
                           r"must be true or false"),
    ('[matrix]\ncontrollers = ["d"]\nscenarios = ["thesis"]\nseeds = [0]\n[controllers.d]\nbase = "dithered"\n'
     'preset = "loud"\n', r"matrix\.toml: controllers\.d\.preset: unknown preset 'loud' of 'dithered'"),
    ('[matrix]\ncontrollers = ["lin"]\nscenarios = ["thesis"]\nseeds = [0]\n[controllers.lin]\nbase = "pid"\n',
     r"matrix\.toml: controllers\.lin\.base: must name a registered controller, got 'pid'"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["thesis"]\nseeds = [0]\nplugins = ["no_such_module_x"]\n',
     r"matrix\.toml: matrix\.plugins\[0\]: cannot import 'no_such_module_x'"),
    ('[matrix]\ncontrollers = ["linear"]\nscenarios = ["a__b"]\nseeds = [0]\n[scenarios.a__b]\nbase = "thesis"\n',
     r"matrix\.toml: scenarios\.a__b: name 'a__b' must"),
])
def test_errors_name_the_file_key_and_field(tmp_path, monkeypatch, text, message):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, text)
    with pytest.raises(MatrixError, match=message):
        load_matrix("matrix.toml")
