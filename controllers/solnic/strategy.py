"""Choosing the pulse: the size schedule, the optimiser of Δt_u and the trigger (ch. 6, 7.2).

Sizes (figure 7-1's NSIZE):

* −1 and 0, start-up (section 7.2): size −1 raises Δt_u by Δt_u,inc every cycle until a cycle
  gives significant motion; then size 0 lowers Δt_u by less than it was raised (inc/2) and, if
  that still moves the shaft significantly, normal operation starts with Δt_u,opt = that Δt_u;
  if not, size 0 raises Δt_u by inc/4 and tries again. (The text fixes only "decreased less
  than it was increased"; the halves and quarters are our choice.) Any insignificant cycle
  sends the controller back to size −1 from the Δt_u just used.
* 1, 2, 3: small, medium, large = Δt_u,opt − inc, Δt_u,opt, Δt_u,opt + inc (6-6)–(6-8), four
  cycles each; then the costs of the three sizes are evaluated and Δt_u,opt, Δt_u,inc updated.

Updates after each set of twelve cycles:

* Δt_u,opt moves to the vertex of the parabola through the three costs (6-10), limited to
  ±Δt_u,inc; where the sampled costs are convex upward (concave) it makes the largest step
  (inc) downhill, toward the cheaper end. The text prints (J_large − J_small) in the
  numerator of (6-10): that is the sign of the maximum of a convex parabola, and it would
  climb the cost; the vertex of the parabola through (−1, J_s), (0, J_m), (1, J_l) is at
  (J_s − J_l)/(2(J_s + J_l) − 4J_m), which we use.
* Δt_u,inc ← Δt_u,inc·[1 − a_gain(Δc_large/Δc_small − a_ratio)] (6-9), with the factor
  clipped to [``min_inc_factor``, 2]: the raw factor turns negative for ratios above
  a_ratio + 1/a_gain (5.3), which the text's statement "converged as long as Δt_u,inc > 0"
  excludes. When the small size does not move the shaft at all the ratio is undefined and
  the increment is left alone.
* A size whose Δt_u does not move the shaft has J = +inf: if the small size is infinite the
  step is +inc when J_large < J_medium (else 0); if all are infinite the step is +inc (the
  minimum lies above breakaway).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["parabola_step", "increment_update", "optimise_cost_curve", "SizeSchedule",
           "Trigger", "plan_trigger", "SMALL", "MEDIUM", "LARGE", "STARTUP_RAISE", "STARTUP_SETTLE"]

STARTUP_RAISE, STARTUP_SETTLE, SMALL, MEDIUM, LARGE = -1, 0, 1, 2, 3
CYCLES_PER_SIZE = 4


def parabola_step(J_small: float, J_medium: float, J_large: float, dtu_inc: float) -> float:
    """Change of Δt_u,opt from the three sampled costs  (6-10) with its constraints [s]."""
    fin = [math.isfinite(J) for J in (J_small, J_medium, J_large)]
    if not any(fin):
        return dtu_inc
    if not fin[0] or not fin[1]:
        # the lower sizes do not move the shaft: go up if that is downhill
        if fin[1]:
            return dtu_inc if J_large < J_medium else 0.0
        return dtu_inc if fin[2] else 0.0
    if not fin[2]:
        return -dtu_inc if J_small < J_medium else 0.0
    denom = 2.0 * (J_small + J_large) - 4.0 * J_medium
    if denom <= 0.0:                                        # convex upward: max step downhill
        if J_small == J_large:
            return 0.0
        return -dtu_inc if J_small < J_large else dtu_inc
    step = (J_small - J_large) / denom * dtu_inc            # vertex (6-10)
    return max(-dtu_inc, min(dtu_inc, step))


def increment_update(dtu_inc: float, dc_ratio: float, a_gain: float = 0.3, a_ratio: float = 2.0,
                     min_factor: float = 0.5, max_factor: float = 2.0) -> float:
    """Δt_u,inc·[1 − a_gain(Δc_large/Δc_small − a_ratio)]  (6-9), factor clipped [s]."""
    if not math.isfinite(dc_ratio) or dc_ratio <= 0:
        return dtu_inc
    factor = 1.0 - a_gain * (dc_ratio - a_ratio)
    return dtu_inc * min(max_factor, max(min_factor, factor))


@dataclass
class OptimiserRound:
    """One set of twelve cycles of the deterministic optimiser test."""

    dtu_opt: float
    dtu_inc: float
    costs: tuple[float, float, float]
    dc_ratio: float


def optimise_cost_curve(cost: Callable[[float], float], motion: Callable[[float], float],
                        dtu_opt: float, dtu_inc: float, rounds: int = 60, *,
                        a_gain: float = 0.3, a_ratio: float = 2.0,
                        min_inc_factor: float = 0.5) -> list[OptimiserRound]:
    """Run (6-9), (6-10) on a deterministic cost curve, as the text did before the simulation.

    ``cost(Δt_u)`` is J (inf where the shaft does not move), ``motion(Δt_u)`` is |Δc_p|.
    Returns the history; the last entry holds the final Δt_u,opt and Δt_u,inc.
    """
    history = []
    for _ in range(rounds):
        sizes = (dtu_opt - dtu_inc, dtu_opt, dtu_opt + dtu_inc)
        J = tuple(cost(d) if d > 0 else math.inf for d in sizes)
        dc_s = motion(sizes[0]) if sizes[0] > 0 else 0.0
        dc_l = motion(sizes[2])
        ratio = dc_l / dc_s if dc_s > 0 else math.inf
        step = parabola_step(*J, dtu_inc)
        dtu_opt = max(0.0, dtu_opt + step)
        dtu_inc = increment_update(dtu_inc, ratio, a_gain, a_ratio, min_inc_factor)
        history.append(OptimiserRound(dtu_opt, dtu_inc, J, ratio))
    return history


@dataclass
class SizeSchedule:
    """NSIZE and the Δt_u of the next pulse (figure 7-1, sections 6.2 and 7.2).

    Parameters
    ----------
    dtu_opt, dtu_inc : float
        Initial Δt_u,opt and Δt_u,inc [s].
    """

    dtu_opt: float
    dtu_inc: float
    size: int = STARTUP_RAISE
    dtu_startup: float = 0.0
    cycles_done: int = 0                       # cycles launched in the current set of 12
    set_sizes: list = field(default_factory=list)

    def __post_init__(self) -> None:
        self.dtu_startup = max(self.dtu_opt, 0.0)

    def normal_dtu(self, size: int) -> float:
        """Δt_u of a normal size (6-6)–(6-8)."""
        return self.dtu_opt + (size - MEDIUM) * self.dtu_inc

    def next_dtu(self) -> float:
        """Δt_u of the pulse about to be planned (size −1 raises by inc at each launch)."""
        if self.size == STARTUP_RAISE:
            return self.dtu_startup + self.dtu_inc
        if self.size == STARTUP_SETTLE:
            return self.dtu_startup
        return self.normal_dtu(self.size)

    def launched(self, dtu: float) -> None:
        """A pulse of the current size has been applied."""
        if self.size == STARTUP_RAISE:
            self.dtu_startup = dtu
        elif self.size >= SMALL:
            self.set_sizes.append(self.size)
            self.cycles_done += 1
            if self.cycles_done % CYCLES_PER_SIZE == 0 and self.size < LARGE:
                self.size += 1

    def skip_size(self) -> None:
        """The current normal size cannot be applied (Δt_u ≤ 0): count its cycles as done."""
        if self.size >= SMALL:
            self.cycles_done = CYCLES_PER_SIZE * self.size
            if self.size < LARGE:
                self.size += 1

    @property
    def set_complete(self) -> bool:
        return self.size >= SMALL and self.cycles_done >= 3 * CYCLES_PER_SIZE

    def evaluated(self, significant: bool, size_of_cycle: int, dtu_of_cycle: float) -> None:
        """React to the significance test of the last cycle (section 7.2)."""
        if size_of_cycle == STARTUP_RAISE:
            if significant:
                self.size = STARTUP_SETTLE
                self.dtu_startup = max(dtu_of_cycle - self.dtu_inc / 2.0, 0.0)
            return
        if size_of_cycle == STARTUP_SETTLE:
            if significant:
                self.dtu_opt = dtu_of_cycle
                self._new_set()
            else:
                self.dtu_startup = dtu_of_cycle + self.dtu_inc / 4.0
            return
        if not significant and self.size >= SMALL:
            # restart from the larger of the failed Δt_u and Δt_u,opt, so that repeated
            # failures of a too-small "small" size ratchet Δt_u,opt upward, never down
            self.size = STARTUP_RAISE
            self.dtu_startup = max(dtu_of_cycle, self.dtu_opt)
            self.cycles_done = 0

    def undecided(self, size_of_cycle: int, dtu_of_cycle: float) -> None:
        """The last cycle's outcome is undecided (three-way decision): keep the schedule.

        A normal size goes on with its set; a start-up size repeats the same Δt_u.
        """
        if size_of_cycle == STARTUP_RAISE:
            self.dtu_startup = max(dtu_of_cycle - self.dtu_inc, 0.0)
        elif size_of_cycle == STARTUP_SETTLE:
            self.dtu_startup = dtu_of_cycle

    def _new_set(self) -> None:
        self.size = SMALL
        self.cycles_done = 0
        self.set_sizes = []

    def reoptimise(self, J_small: float, J_medium: float, J_large: float, dc_ratio: float,
                   a_gain: float = 0.3, a_ratio: float = 2.0, min_inc_factor: float = 0.5) -> None:
        """(6-10) then (6-9) after a set of twelve cycles; starts the next set."""
        step = parabola_step(J_small, J_medium, J_large, self.dtu_inc)
        self.dtu_opt = max(0.0, self.dtu_opt + step)
        self.dtu_inc = increment_update(self.dtu_inc, dc_ratio, a_gain, a_ratio, min_inc_factor)
        self._new_set()


@dataclass(frozen=True)
class Trigger:
    """A planned correction: drive direction and start offset in the sample interval [s]."""

    sign: int
    offset: float
    overshoot: bool


def plan_trigger(x1: float, x4: float, x4_std: float, delta_c: float, *, horizon: float,
                 earliest: float, duration: float, overshoot_factor: float = 1.5,
                 x4_significance: float = 2.0) -> Trigger | None:
    """When, within [0, horizon), to start a correction of motion |Δc_p| (sections 6.1, 7.2).

    The test is unsymmetrical. With a known drift direction d = sign(x̂4) (x̂1 falls at x̂4):

    * normal correction, drive +d, when d·x̂1 reaches −|Δc_p|/2; x̂1 moves at −x̂4, so the
      crossing time is predicted and the pulse may start inside the interval;
    * overshoot correction, drive −d, only when d·x̂1 ≥ overshoot_factor·|Δc_p|.

    While x̂4 is not significant (|x̂4| < x4_significance·std) the test is |x̂1| ≥ |Δc_p|/2.
    The pulse must be over (current back to zero, ``duration`` after its start) before the
    next sample, and must not start before ``earliest``; otherwise it waits for the next
    sample. Returns None when no correction starts in this interval.
    """
    half = abs(delta_c) / 2.0
    fits = lambda o: o >= earliest and o + duration <= horizon
    if not (abs(x4) >= x4_significance * x4_std and x4 != 0.0):
        if abs(x1) >= half and x1 != 0.0:
            o = max(0.0, earliest)
            return Trigger(-1 if x1 > 0 else 1, o, False) if fits(o) else None
        return None
    d = 1 if x4 > 0 else -1
    if d * x1 >= overshoot_factor * abs(delta_c) and abs(delta_c) > 0:
        o = max(0.0, earliest)
        return Trigger(-d, o, True) if fits(o) else None
    wait = (d * x1 + half) / abs(x4)          # time until d·x̂1 = −|Δc|/2
    o = max(0.0, wait, earliest)
    return Trigger(d, o, False) if fits(o) else None
