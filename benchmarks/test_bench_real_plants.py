"""CPU per 100 s cell on ``disturbed``, ``quantized`` and ``delayed`` against the same controller on
``thesis``, measured in the same run (issue #22 goal: ≤ 1.5×).

Seed 0; compiled code warmed first by a 1 s cell of each, so the ratio is of simulation, not of
compilation. ``make benchmark`` runs it (skipped under ``--benchmark-disable``). Pairs known to
miss the goal are marked xfail with the reason (the assertion stays the goal):

* ``disturbed``: compiled since 2026-11-27 (plant/multimode/disturbed_jit.py, and the linear law's
  loop plant/multimode/disturbed_loop.py), bit-identical to the Python path. The noisy d needs
  exact Gaussian sub-steps where thesis has closed forms: linear's thesis cell is a noise-free
  closed-form slide (0.7 µs per 10 ms sample) against ~5 sub-steps and a new Φ(h) per sample;
  dithered's reflection regime runs in 10 µs sub-steps (316 k per 10 s against 120 k).
* ``delayed`` with ``linear``: since issue 27 the linear law runs on ``quantized`` and ``delayed``
  in the compiled-law loop (plant/law_step.py; before, the per-sample Python path: 10.5× and
  13.5×); the delay adds a segment boundary, hence plant work, to every interval, and the ratio
  measured 0.99–1.6× over three runs (loaded machine, 2026-11-27 04:30–05:15 UTC; quantized
  1.2–1.4×): at the goal, within the noise, so left marked.

* ``disturbed`` again (2026-11-27 07:58, helper distfast): the sub-step no longer cuts array views
  or passes the tuple of twenty cache tables (numba's atomic reference counts were ~⅓ of the
  cell's CPU), the common sub-step runs in a function compiled without reference counting
  (``_fast_segment``), and the transition cache hashes all mantissa bits (interval-end widths had
  evicted the ladder's: 6707 misses per linear cell, now ~350). Bit-identical. One run, all
  pairs in one process (08:00), per 100 s cell: linear 0.023 s against 0.007 s (3.2×, was 12.5×
  in the same morning's run), pulse-width 0.165 against 0.098 s (1.7×, was 2.4×), solnic-modern
  0.99× (was 0.71×; noise), dithered 2.1 against 0.40 s (5.3×, was 8.3×); quantized 1.10 /
  0.98 / 1.02×, delayed 1.48 / 1.00 / 1.45× (linear / solnic-modern / pulse-width). linear,
  pulse-width and dithered still miss: ~8 (linear) and ~20 (pulse-width) exact sub-steps per
  sample, and pulse-width's per-sample Python wrapper (~11 µs per interval against the
  kernel's ~3 µs); see docs/plant.md.

* ``disturbed`` a third time (2026-11-27 09:50, helper disturb): every controller with a compiled
  step now runs on the disturbed plant in its compiled loop (``disturbed_loop.run_compiled_law``;
  before, pulse-width paid the per-sample Python wrapper), the bisection reads its cached laws by
  offset without allocating, and a crossing probability whose exponent is below −746 is 0.0
  without calling exp (libm's underflow path was ~⅕ of a linear cell). Bit-identical (120 rows:
  disturbed and delayed, 6 controllers, seeds 0–4, with and without the x1 log, against main
  77118a2). Per 100 s cell, one process, best of three (10:00; before: 77118a2 at 09:48):
  linear 0.0178 s against 0.0066 s (2.7×; 3.1× before), pulse-width 0.054 against 0.019 s
  (2.7–2.8×; 6.7× before: thesis's pulse-width had become compiled, the disturbed one had not),
  solnic-modern 0.91× (1.23×). The floor of the method:
  a linear cell draws ~347 k normals (thesis: 66 k) at 16 ns each, 5.7 ms — 0.86 of thesis's
  whole cell — and runs ~80 k exact sub-steps (≥ one 8 × 8 product, one exp, the torque
  integrals: ~80 ns each, 6.4 ms): 1.8× thesis's whole cell before the per-sample loop that
  thesis runs too (~4 ms), so ≥ ~2.4×: linear's miss is certain (strict). pulse-width draws ~723 k normals (11.9 ms) and runs ~108 k sub-steps (8.6 ms) and
  each pulse's unique widths miss the transition cache (a closed form and a Cholesky factor):
  ≥ ~1.5×, measured 2.7×. ``delayed``: the delay's cost is the second segment of every
  interval in the plain kernel (plant/multimode/interval.py), not the chunk's copies (removing
  them measured nothing) nor the Python path (the compiled-law loop runs it): linear 1.47×
  (three-run best), reset-pid 1.25×, pulse-width 1.0×.

* ``disturbed`` a fourth time (2026-11-27 13:15, helper distfloor): ``interval_k`` and the rarer
  paths (``_segment``, ``_tail``, ``_bisect``) compiled without reference counting (only what
  allocates keeps it), a far rung's crossing test without exp where its value cannot be 1, the
  last width's decay and torque-integral factors memoized. Bit-identical (100 rows: disturbed and
  compliant × 5 controllers × seeds 0–4, with and without the x1 log, against 578603d). Both
  trees in one run, best of 2 × 3 (13:26): linear 3.99 → 2.91×, pulse-width 4.30 → 3.48×,
  dithered 6.28 → 5.77×, solnic-modern 1.01 → 0.97×; this file once (13:17): 3.04×, 3.51×,
  5.64×, 0.89×. linear and pulse-width are now strict: their extra
  normals alone (262 k and 486 k at 8.3 ns) take all (linear) or 4.0 of the 6.3 ms (pulse-width)
  that the goal leaves over thesis, so the 80 k / 85 k extra sub-steps would have to cost
  nothing, or ≤ 27 ns each (docs/plant.md, "the floors").

Measured on the shared, heavily loaded 2-core machine (one run): quantized/thesis linear 10.5,
solnic-modern 0.88, pulse-width 1.02; delayed/thesis linear 13.5, solnic-modern 0.99, pulse-width
1.39. ``disturbed``/thesis, CPU per 100 s cell, one process, 2026-11-27 (loaded machine):
before the compiled path linear ~115×, pulse-width 16×, dithered 78×; compiled, final version
(through this file, 05:20): linear 0.089 s against 0.007 s (12.7×), solnic-modern 0.48 against
0.44 s (1.09×, meets the goal; 0.44–1.29× over five runs), pulse-width 0.24 against 0.10 s
(2.5×), dithered 3.4 against 0.44 s (7.6×). The cost is inside the compiled loop; the sub-step
count is the method's (exact Gaussian sub-steps while d is noisy).
"""

import pytest

from bench.scenarios import builtin_scenarios
from benchmarks.cell_cost import cell_cpu

pytestmark = pytest.mark.slow

_GOAL = 1.5
# pair -> (strict, last measured ratio): a certain miss (the method's floor is above the goal) is strict
_MISSES = {("disturbed", "linear"): (True, "2.91-3.04x"), ("disturbed", "pulse-width"): (True, "3.48-3.51x"),
           ("disturbed", "dithered"): (True, "5.64-5.77x"), ("delayed", "linear"): (False, "0.99-1.6x")}


def _marks(pair):
    if pair not in _MISSES:
        return ()
    strict, measured = _MISSES[pair]
    return pytest.mark.xfail(reason=f"known miss (measured {measured}), see module docstring", strict=strict)


_CASES = [pytest.param(s, c, marks=_marks((s, c)))
          for s in ("disturbed", "quantized", "delayed") for c in ("linear", "solnic-modern", "pulse-width")] + [
    pytest.param("disturbed", "dithered", marks=_marks(("disturbed", "dithered")))]


@pytest.mark.parametrize("name, controller", _CASES)
def test_real_plant_cell_cost_ratio(benchmark, name, controller):
    if benchmark.disabled:   # `make test`: 100 s cells only to time them; `make benchmark` runs it
        pytest.skip("a timing only (make benchmark)")
    scen = builtin_scenarios()
    thesis, other = scen["thesis"], scen[name]
    for sc in (thesis, other):
        cell_cpu(sc, controller, 1.0)

    def both():
        return cell_cpu(thesis, controller, thesis.duration_s), cell_cpu(other, controller, other.duration_s)

    cpu_thesis, cpu_other = benchmark.pedantic(both, rounds=1, iterations=1, warmup_rounds=0)
    ratio = cpu_other / cpu_thesis
    benchmark.extra_info.update(cpu_thesis_s=cpu_thesis, cpu_other_s=cpu_other, ratio=ratio)
    print(f"{controller} on {name}: thesis {cpu_thesis:.3f} s, {name} {cpu_other:.3f} s CPU, ratio {ratio:.2f}")
    assert ratio <= _GOAL
