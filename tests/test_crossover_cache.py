"""highest_crossover is cached on the plant fields its search reads, not on the whole plant.

The search (~0.1–0.3 s of python-control per plant) ran again in every cell process for every
plant that differed only in fields it never reads (friction noise, x4, the sensor, another
family's own fields): the linear-design controllers' frontier cells paid most of their CPU there
(issue 27). The answer on the reduced key must be the search on the full plant, exactly.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from bench.scenarios import builtin_scenarios
from controllers import linear
from controllers.linear import _CROSSOVER_FIELDS, _highest_crossover, highest_crossover


def _plants():
    sc = builtin_scenarios()
    th = sc["thesis"].params
    out = [(name, sc[name].realise(1)[0]) for name in ("quiet-friction", "mismatch", "stribeck")]
    return out + [("sigma1", th.replace(measurement_noise_std=2e-5))]


@pytest.mark.parametrize("integral", [False, True])
def test_the_cached_crossover_is_the_search_on_the_whole_plant(integral):
    for name, plant in _plants():
        full = _highest_crossover.__wrapped__(plant, integral=integral)   # uncached, every field present
        assert highest_crossover(plant, integral=integral) == full, name


def test_a_field_the_search_reads_changes_the_key():
    th = builtin_scenarios()["thesis"].params
    slow = th.replace(sample_period=2.0 * th.sample_period)                # half the Nyquist frequency
    assert highest_crossover(slow) == _highest_crossover.__wrapped__(slow)
    assert highest_crossover(slow) < 0.75 * highest_crossover(th)


def test_the_key_holds_every_plant_field_the_module_reads():
    # every params.<field> read in controllers/linear.py is a key field or derived from them
    tree = ast.parse(Path(linear.__file__).read_text(encoding="utf-8"))
    read = {node.attr for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "params"}
    derived = {"lag_ratio_limit": {"stiction", "coulomb"}}
    assert read, "the scan found no field"
    for field in read:
        assert set(derived.get(field, {field})) <= set(_CROSSOVER_FIELDS), field


def test_the_forkserver_warm_up_leaves_table_2_1s_searches_cached():
    # bench.warm (imported by the forkserver) resets every controller on Table 2-1, so a cell
    # process forked from it finds both searches (lag and integral) in the cache
    import bench.warm
    from plant.params import PlantParams

    _highest_crossover.cache_clear()
    bench.warm.warm_designs()
    misses = _highest_crossover.cache_info().misses
    assert misses >= 2
    for integral in (False, True):
        highest_crossover(PlantParams(), integral=integral)
    assert _highest_crossover.cache_info().misses == misses
