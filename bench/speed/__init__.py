"""Work-precision comparison behind the dissertation's speed claim (SPEC §8, issue #7).

The dissertation (abstract; §1.2) says multimode linearization is "at least a thousand times
faster than standard, fixed-increment numerical integration" for this plant. This module
measures that claim:

1. **One command sequence.** The registered ``solnic`` controller runs closed loop, noise-free,
   and every :class:`~plant.drive.DriveCommand` it returns is recorded. The full comparison
   replays all 100 s (start-up included); ``--quick`` records 50 s and replays the last 10 s
   (steady pulsing, about ten pulses a second), starting from the exact state at a sample
   instant where the shaft is stuck with no current. If solnic cannot run, a synthetic open-loop
   train of 1.3 ms pulses every 60 ms with alternating sign stands in (``sequence.source`` says
   which). The full run also replays the ``linear`` controller's held levels.
2. **Contestants, noise-free, on that sequence:** the exact simulator
   (:func:`plant.advance`, one compiled call per sample interval); fixed-step Euler
   (the default family's ``fixed_step`` (:mod:`bench.exact`), same mode logic, steps 1e-4 … 1e-7 s, every step size
   run over the whole window — nothing is scaled); ``solve_ivp`` (DOP853) with terminal events
   (``event_driven``) at rtol 1e-3 … 1e-12.
3. **Error** against the exact simulator (closed forms, event times exact to ≤ 1e-12 s; the
   window's clock is restarted at 0 — the plant is time-invariant — so the rounding of
   absolute time does not blur anyone's event times):

   * ``error_x1``: max over sample instants of |x1 − x1_ref|, divided by max |x1_ref|;
   * ``error_dc``: max over pulses of |Δc − Δc_ref| / |Δc_ref|, where a pulse's Δc is the shaft
     motion c = x1 + r from the sample instant opening its interval to the one opening the next
     pulse's interval (or the window end), so motion that spills into later intervals counts;
     only pulses that move the shaft in the reference enter (below breakaway Δc_ref is exactly
     0, and the x1 error still covers them);
   * ``error`` (the headline, dimensionless) = ``error_dc``, or ``error_x1`` for a sequence
     without pulses. Δc is what every solnic correction is built on, and it does not depend on
     the window. ``error_x1`` is harsher on fixed-step: replayed open loop, x1 accumulates every
     pulse's Δc error (a closed loop would correct that drift), and it is scaled by the window's
     peak error. Its equal-accuracy speed-ups are reported too (``speedup_at_1e-6_by_metric``)
     and are larger, so the headline is the conservative reading of the claim.

   The reference itself is cross-checked against ``solve_ivp`` at rtol 1e-13; that disagreement
   is the exact simulator's row error.
4. **Speed-up at equal accuracy** (``error`` = 1e-6): the wall time a contestant needs to reach
   1e-6, interpolated in log-log along its measured error curve (extrapolated from its two most
   accurate points when it never gets there — flagged, with the observed order) divided by the
   exact simulator's wall time.

   Euler's Δc error is dominated by where the pulse edges fall on its grid (each edge moves by
   up to one step), a sawtooth in the edge offset whose envelope is O(h); the max over hundreds
   of pulses follows the envelope. A **per-pulse probe** checks it below the finest full step:
   a spread of the window's moving pulses, each run alone over its own one or two sample
   intervals from its exact start state, at 1e-8 s and 1e-9 s. The probe also
   gives a **measured lower bound**, ``speedup_vs_fixed_step_at_1e-6_lower_bound``: at the
   finest step whose error still misses 1e-6, fixed-step would need at least the whole window
   at that step (its cost per step measured on the full run) — no extrapolation.

Timing: JIT compilation is excluded (every kernel is warmed up on another sequence first). The
exact simulator is timed in a fresh process: the recording run fills its per-process cache of
transition matrices with this very sequence's step lengths, which a replay in the same process
would unfairly reuse (the warm-cache time is reported as ``wall_warm_cache_s``). It runs with
its metric integrals off, as the others compute none (``wall_with_metrics_s``: on). Cheap runs
are repeated and the best time is kept. The machine's load average is recorded with the result.

Implementation technology: the exact simulator and the fixed-step kernel are both
numba-compiled (one compiled call per sample interval for the exact one), so
``speedup_vs_fixed_step_at_1e-6`` is like for like, as the dissertation's FORTRAN-against-FORTRAN
comparison was. ``solve_ivp`` is SciPy with a Python right-hand side.
``speedup_vs_fixed_step_python_at_1e-6`` is kept for reference: the same Euler kernel run
uncompiled (``NUMBA_DISABLE_JIT=1`` in a fresh process).

5. **With noise** (``weak_error``, :mod:`bench.weak_error`). The headline above is noise-free:
   path-by-path errors need identical noise. The dissertation's simulator is for the *noisy*
   plant, where two methods are compared by the statistics a controller uses — the mean and
   95th percentile of one pulse's Δc — with Monte-Carlo confidence intervals. ``weak_error``
   reports, for Euler–Maruyama at each step, the weak error with its 95 % CI and the cost ratio
   (EM wall per path / exact wall per path) at the coarsest step whose error the Monte-Carlo
   sample cannot tell from zero; ``noisy_speedup_at_equal_weak_error`` is that ratio (the exact
   simulator's speed-up, like the noise-free headline: fixed-step time over exact time).

6. **In closed loop** (``closed_loop_em``, :mod:`bench.speed.closed_loop`): the statistic a
   benchmark user depends on — solnic's peak error over seeds on thesis — with the plant
   stepped exactly and by Euler–Maruyama at fixed steps behind the same family seam
   (``fixed_step_family``), compared as independent samples with bootstrap CIs, with the CPU
   per cell of each.

Modules by idea: :mod:`~bench.speed.config` (the presets), :mod:`~bench.speed.sequence` (item
1), :mod:`~bench.speed.contestants` (item 2 and timing), :mod:`~bench.speed.accuracy` (items 3
and 4), :mod:`~bench.speed.compare` (one sequence), :mod:`~bench.speed.comparison` (the whole
comparison), :mod:`~bench.speed.closed_loop` (item 6), :mod:`~bench.speed.tables` and :mod:`~bench.speed.command` (``solnic-bench speed``).
"""

# The names below load on first use (PEP 562), so that ``solnic-bench --help`` and ``list`` do
# not import numba, scipy and pandas to compose the ``speed`` command.
_EXPORTS = {
    "bench.speed.command": ("speed_command",),
    "bench.speed.comparison": ("speed_comparison",),
    "bench.speed.config": ("FULL", "QUICK", "TARGET_ERROR", "SpeedConfig"),
    "bench.speed.sequence": ("record_commands",),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str) -> object:
    """Import the submodule that defines ``name`` on first access (PEP 562)."""
    if name not in _WHERE:
        raise AttributeError(f"module 'bench.speed' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value
    return value


__all__ = ["TARGET_ERROR", "SpeedConfig", "QUICK", "FULL", "speed_comparison", "speed_command",
           "record_commands"]
