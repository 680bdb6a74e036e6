"""Detection of a sustained stick-slip hunting limit cycle in a run's trace (SPEC §6).

A slip is a maximal run of trace points where the shaft moves (mode 1 or 3, or |x2| above a
tolerance). The trace is *hunting* when, in the tail window of the run,

* at least ``min_cycles`` slips start,
* the slip starts are roughly periodic: the interquartile range of their spacing is at most
  ``max_period_spread`` times its median (a robust measure: the noisy plant's hunting cycle
  has occasional long sticks; a Poisson stream of slips has ln 3/ln 2 ≈ 1.58),
* the slips keep coming up to the end: the last one ends within ``max_quiet_periods`` median
  slip periods of the end of the trace,
* and, with ``require_reversals``, most consecutive slips go in opposite directions
  (the back-and-forth hunting of a stationary set-point; a ramp's stick-slip is one-way).

Otherwise it has *settled*. Use the event trace when there is one: slips of a hunting cycle can
be shorter than a sample period, and samples at 100 Hz can miss them. Slips in the same
direction separated by a stick shorter than ``min_stick_s`` count as one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["HuntingVerdict", "detect_hunting", "slip_episodes", "merged_trace"]


@dataclass(frozen=True)
class HuntingVerdict:
    """Result of :func:`detect_hunting`.

    Attributes
    ----------
    sustained : bool
        A hunting limit cycle runs through the tail window.
    n_slips : int
        Slips that start in the tail window.
    period_s : float
        Median spacing of those slip starts [s] (nan with fewer than two).
    period_spread : float
        Interquartile range / median of the spacing (nan with fewer than three slips).
    reversal_fraction : float
        Fraction of consecutive tail slips with opposite directions (nan with fewer than two).
    amplitude_rad : float
        Half the peak-to-peak x1 over the tail window [rad].
    last_motion_s : float
        Time of the last moving trace point [s] (nan if the shaft never moved).
    reason : str
        Why the verdict was reached.
    """

    sustained: bool
    n_slips: int
    period_s: float
    period_spread: float
    reversal_fraction: float
    amplitude_rad: float
    last_motion_s: float
    reason: str


def _direction(t: np.ndarray, mode: np.ndarray | None, velocity: np.ndarray | None,
               velocity_tol: float) -> np.ndarray:
    """Per-point motion direction: +1 (mode 3), −1 (mode 1), 0 (stuck)."""
    if mode is not None:
        m = np.asarray(mode)
        if m.shape != t.shape:
            raise ValueError(f"mode must have the shape of t {t.shape}, got {m.shape}")
        if not np.isin(m, (1, 2, 3)).all():
            raise ValueError("mode values must be 1, 2 or 3")
        return np.where(m == 3, 1, np.where(m == 1, -1, 0))
    v = np.asarray(velocity, dtype=float)
    if v.shape != t.shape:
        raise ValueError(f"velocity must have the shape of t {t.shape}, got {v.shape}")
    return np.where(v > velocity_tol, 1, np.where(v < -velocity_tol, -1, 0))


def slip_episodes(t: np.ndarray, direction: np.ndarray, min_stick_s: float = 0.0,
                  ) -> list[tuple[float, float, int]]:
    """Moving runs as (start time, end time, direction of their first point).

    Runs in the same direction separated by a stick shorter than ``min_stick_s`` [s] merge.
    """
    moving = direction != 0
    edges = np.diff(moving.astype(np.int8), prepend=0, append=0)
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1) - 1
    out: list[tuple[float, float, int]] = []
    for a, b in zip(starts, ends):
        start, end, d = float(t[a]), float(t[b]), int(direction[a])
        if out and out[-1][2] == d and start - out[-1][1] < min_stick_s:
            out[-1] = (out[-1][0], end, d)
        else:
            out.append((start, end, d))
    return out


def detect_hunting(t: np.ndarray, x1: np.ndarray, mode: np.ndarray | None = None, *,
                   velocity: np.ndarray | None = None, velocity_tol: float = 0.0,
                   tail_fraction: float = 0.5, min_cycles: int = 3,
                   max_period_spread: float = 1.0, max_quiet_periods: float = 4.0,
                   min_stick_s: float = 0.05, require_reversals: bool = False) -> HuntingVerdict:
    """Decide whether a trace ends in a sustained stick-slip (hunting) limit cycle.

    Parameters
    ----------
    t : array
        Nondecreasing trace times [s] (sample instants, events, or both merged).
    x1 : array
        Error x1 = c − r at those times [rad].
    mode : array of {1, 2, 3}, optional
        Plant mode at those times; alternatively give ``velocity`` (x2 [rad/s]).
    velocity_tol : float
        |x2| at or below this counts as stuck when ``velocity`` is used [rad/s].
    tail_fraction : float
        The tail window is the last ``tail_fraction`` of the time span, in (0, 1].
    min_cycles : int
        Least number of slips starting in the tail window, ≥ 3.
    max_period_spread : float
        Largest interquartile-range/median of the slip spacing that counts as periodic.
    max_quiet_periods : float
        The last slip must end within this many median periods of the trace's end.
    min_stick_s : float
        Same-direction slips separated by a shorter stick [s] count as one.
    require_reversals : bool
        Also require at least half the consecutive slips to reverse direction.

    Raises
    ------
    ValueError
        On inconsistent arrays or options out of range.
    """
    t = np.asarray(t, dtype=float)
    x1 = np.asarray(x1, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t must be a 1-D array with at least 2 points, got shape {t.shape}")
    if x1.shape != t.shape:
        raise ValueError(f"x1 must have the shape of t {t.shape}, got {x1.shape}")
    if np.any(np.diff(t) < 0) or not np.all(np.isfinite(t)):
        raise ValueError("t must be finite and nondecreasing")
    if (mode is None) == (velocity is None):
        raise ValueError("give exactly one of mode and velocity")
    if not 0 < tail_fraction <= 1:
        raise ValueError(f"tail_fraction must be in (0, 1], got {tail_fraction!r}")
    if not (isinstance(min_cycles, int) and min_cycles >= 3):
        raise ValueError(f"min_cycles must be an integer >= 3, got {min_cycles!r}")
    if not max_period_spread > 0:
        raise ValueError(f"max_period_spread must be > 0, got {max_period_spread!r}")
    if not min_stick_s >= 0:
        raise ValueError(f"min_stick_s must be >= 0, got {min_stick_s!r}")
    if not max_quiet_periods > 0:
        raise ValueError(f"max_quiet_periods must be > 0, got {max_quiet_periods!r}")
    if not velocity_tol >= 0:
        raise ValueError(f"velocity_tol must be >= 0, got {velocity_tol!r}")

    direction = _direction(t, mode, velocity, velocity_tol)
    slips = slip_episodes(t, direction, min_stick_s)
    moving_idx = np.flatnonzero(direction)
    last_motion = float(t[moving_idx[-1]]) if moving_idx.size else math.nan
    t_end = float(t[-1])
    t_tail = t_end - tail_fraction * (t_end - float(t[0]))
    in_tail = t >= t_tail
    amplitude = 0.5 * float(np.ptp(x1[in_tail])) if in_tail.any() else 0.0
    tail = [s for s in slips if s[0] >= t_tail]
    starts = np.array([s[0] for s in tail])
    gaps = np.diff(starts)
    period = float(np.median(gaps)) if gaps.size else math.nan
    spread = (float(np.subtract(*np.percentile(gaps, [75, 25])) / period)
              if gaps.size >= 2 and period > 0 else math.nan)
    dirs = np.array([s[2] for s in tail])
    reversals = float(np.mean(dirs[1:] != dirs[:-1])) if dirs.size >= 2 else math.nan

    def verdict(sustained: bool, reason: str) -> HuntingVerdict:
        return HuntingVerdict(sustained, len(tail), period, spread, reversals, amplitude,
                              last_motion, reason)

    if len(tail) < min_cycles:
        return verdict(False, f"{len(tail)} slips in the tail window, fewer than {min_cycles}")
    if not spread <= max_period_spread:
        return verdict(False, f"slip spacing not periodic: spread {spread:.3g} > "
                              f"{max_period_spread}")
    quiet = t_end - tail[-1][1]
    if quiet > max_quiet_periods * period:
        return verdict(False, f"no motion for the last {quiet:.4g} s "
                              f"(> {max_quiet_periods} × period {period:.4g} s): settled")
    if require_reversals and not reversals >= 0.5:
        return verdict(False, f"only {reversals:.0%} of consecutive slips reverse direction")
    return verdict(True, f"{len(tail)} slips, period {period:.4g} s, spread {spread:.3g}, "
                         f"reversals {reversals:.0%}")


def merged_trace(samples: dict[str, np.ndarray], events: dict[str, np.ndarray] | None = None,
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, x1, mode) of a recorded run: sample instants and plant events, in time order.

    ``samples`` and ``events`` are the ``RunResult`` dicts of ``run_closed_loop(record=True)``.
    """
    parts = [samples] + ([events] if events is not None and len(events["t"]) else [])
    t = np.concatenate([np.asarray(p["t"], dtype=float) for p in parts])
    x1 = np.concatenate([np.asarray(p["x1"], dtype=float) for p in parts])
    mode = np.concatenate([np.asarray(p["mode"]).astype(int) for p in parts])
    order = np.argsort(t, kind="stable")
    return t[order], x1[order], mode[order]
