"""Empirical check of inequality (2-6) and of the lag limit (2-1) (SPEC §6).

Two sweeps of the lag-compensated linear design of :mod:`controllers.linear`:

* **Bound sweep (2-6).** A cell is one LTI design — crossover ωc, lag ratio L or the pure
  integral — on one plant (k̄s/k̄c with k̄c = 1.4 ozf·in, inertia J), noise on or off, tracking a
  ramp x4 = 30 µrad/s. Its measured steady peak error θ (the continuous-time peak |x1| of
  :func:`bench.runner.run_closed_loop` over a window after the transient) is compared with

      θb = (k̄s − k̄c)/(2·J·ωc²)   (2-6)

  at the design's own crossover. The verdict: does θ ≥ θb hold for every stable design?
* **Hunting sweep (2-1).** At a stationary set-point, noise off, L is swept around
  Lmax = 2k̄s/(k̄s − k̄c)  (2-1); the onset is the smallest tested L from which every larger tested
  L ends in a sustained stick-slip limit cycle (:func:`bench.hunting.detect_hunting`).

Ramp runs
    x4 is held at exactly 30 µrad/s (VAR(x4) = 0 and τ4 = 1e9 s, so it neither wanders nor
    decays). x5(0) = 0 in every run so that the plant's mean friction ratio is the labelled one;
    with noise on, w1, w2 and w5 act as in Table 2-1.

Durations
    Everything here is slow because the ramp is: while the shaft is stuck the error grows at
    v = 30 µrad/s only. Two time scales set a run:

    * t_s = k̄s/(J·ωc²·v), the time the ramp needs to cover the error at which the crossover
      stiffness J·ωc² balances stiction; the stick-slip periods of lag loops with L ≤ Lmax are
      1–3·t_s here (much shorter with larger L or the pure integral);
    * t_first = k̄s/(S·v), S = |C(1)| the static stiffness: a stuck lag (type-0) loop first
      breaks away when the wound-up lag torque reaches k̄s (0 for the pure integral).

    warm-up = t_first + 0.5·t_s + 5 s and window = 1.5·t_s + t_first + 10 s (:class:`SweepPlan`):
    the window starts after the first breakaway and its aftermath, and a stick-slip cycle of a
    lag loop (at most ~2·t_first long) normally fits in it. A run is never cut short: a cell that
    does not fit the sweep's cap is not run (status ``skipped``). A run whose window holds no
    breakaway and no steady sliding has a peak that is still rising; it is not scored (status
    ``unsteady``, its window peak kept in ``theta_window_rad``). ``n_slips_window`` and the peaks
    of the window's two halves let a reader check the rest. Because t_s ∝ 1/ωc², the lowest
    crossover swept on every plant is 20 rad/s (30 in ``--quick``); 10 rad/s is probed on two
    heavy (J = 1) plants only, where one stick-slip cycle still takes 10–30 simulated minutes.

Hunting runs
    A perfectly quiet set-point starting at x1 = 0 never moves. Each run instead starts from an
    initial error: the compensator sees y − e0 (a set-point step of e0 at t = 0), which — the
    plant being invariant to a shift of c — is the same as starting stuck at x1 = −e0 from a
    stationary set-point. Whether a limit cycle is reached depends on e0, so several
    e0 = f·k̄s/(J·ωc²) are tried; an L hunts when any of them ends hunting. The crossover is the
    benchmark's (:func:`controllers.linear.highest_crossover` for Table 2-1), fixed over L.

Modules by idea: :mod:`~bench.bound.plan` (what is swept), :mod:`~bench.bound.cells` (the runs
of a plan), :mod:`~bench.bound.run` (one run, scored), :mod:`~bench.bound.verdict` (the
verdicts), :mod:`~bench.bound.check` (all of it, written to files), :mod:`~bench.bound.tables`
and :mod:`~bench.bound.command` (``solnic-bench check-bound``).
"""

# The names below load on first use (PEP 562), so that ``solnic-bench --help`` and ``list`` do
# not import numba, scipy and the plant to compose the ``check-bound`` command.
_EXPORTS = {
    "bench.bound.cells": ("BoundCell", "HuntingCell", "bound_cells", "hunting_cells"),
    "bench.bound.check": ("BoundResult", "check_bound"),
    "bench.bound.command": ("check_bound_command",),
    "bench.bound.plan": ("COULOMB", "RAMP_VELOCITY", "SweepPlan", "highest_stable_crossover", "sweep_plan"),
    "bench.bound.run": ("run_bound_cell", "run_hunting_cell"),
    "bench.bound.verdict": ("BOUND_COLUMNS", "HUNTING_COLUMNS", "bound_verdict", "hunting_onsets"),
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str) -> object:
    """Import the submodule that defines ``name`` on first access (PEP 562)."""
    if name not in _WHERE:
        raise AttributeError(f"module 'bench.bound' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(_WHERE[name]), name)
    globals()[name] = value
    return value


__all__ = [
    "RAMP_VELOCITY", "COULOMB", "BOUND_COLUMNS", "HUNTING_COLUMNS", "SweepPlan", "BoundCell",
    "HuntingCell", "BoundResult", "sweep_plan", "highest_stable_crossover", "bound_cells",
    "hunting_cells", "run_bound_cell", "run_hunting_cell", "hunting_onsets", "bound_verdict",
    "check_bound", "check_bound_command",
]
