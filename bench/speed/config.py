"""What one speed comparison runs: :class:`SpeedConfig` and the ``QUICK`` and ``FULL`` presets."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from bench.speed.closed_loop import FULL_CLOSED_LOOP, QUICK_CLOSED_LOOP, ClosedLoopEMConfig
from bench.weak_coupled import FULL_COUPLED, QUICK_COUPLED, CoupledConfig
from bench.weak_error import FULL_WEAK, QUICK_WEAK, WeakErrorConfig

__all__ = ["TARGET_ERROR", "SpeedConfig", "QUICK", "FULL", "Progress"]


TARGET_ERROR = 1e-6

_AT = "1e-6"                  # TARGET_ERROR as it appears in the result keys


Progress = Callable[[str], None]


@dataclass(frozen=True)
class SpeedConfig:
    """What one comparison runs.

    Attributes
    ----------
    record_s : float
        Closed-loop recording length [s].
    window_s : float
        Replayed window [s], the last ``window_s`` of the recording.
    fixed_steps : tuple of float
        Euler step sizes [s], coarse to fine.
    rtols : tuple of float
        solve_ivp relative tolerances, loose to tight.
    reference_rtol : float
        solve_ivp tolerance of the cross-check of the reference.
    python_fixed_steps : tuple of float
        Step sizes [s] also run with the Euler kernel uncompiled (CPython).
    noisy_fixed_steps : tuple of float
        Step sizes [s] of the noisy Euler–Maruyama real-time-factor runs.
    probe_pulses : int
        Moving pulses in the per-pulse probe (spread evenly over the window).
    probe_steps : tuple of float
        Step sizes [s] of the probe, below the finest of ``fixed_steps``.
    exact_processes : int
        Fresh processes timing the exact simulator; the best cold time is kept.
    linear_sequence : bool
        Also compare on the linear controller's held levels.
    weak : WeakErrorConfig or None
        The uncoupled noisy weak-error comparison (:mod:`bench.weak_error`).
    coupled : CoupledConfig or None
        The coupled one that resolves EM's weak error (:mod:`bench.weak_coupled`).
    closed_loop : ClosedLoopEMConfig or None
        The closed-loop statistic: solnic's peak error over seeds, exact vs EM
        (:mod:`bench.speed.closed_loop`).
    """

    record_s: float
    window_s: float
    fixed_steps: tuple[float, ...] = (1e-4, 1e-5, 1e-6, 1e-7)
    rtols: tuple[float, ...] = (1e-3, 1e-6, 1e-9, 1e-12)
    reference_rtol: float = 1e-13
    python_fixed_steps: tuple[float, ...] = (1e-4,)
    noisy_fixed_steps: tuple[float, ...] = (1e-5, 1e-6)
    probe_pulses: int = 20
    probe_steps: tuple[float, ...] = (1e-8,)
    exact_processes: int = 1
    linear_sequence: bool = False
    weak: WeakErrorConfig | None = None
    coupled: CoupledConfig | None = None
    closed_loop: ClosedLoopEMConfig | None = None

    def __post_init__(self) -> None:
        if not (0 < self.window_s <= self.record_s):
            raise ValueError(f"SpeedConfig.window_s must be in (0, record_s], got {self.window_s!r}")
        if not self.fixed_steps or any(not (0 < h <= 1e-3) for h in self.fixed_steps):
            raise ValueError(f"SpeedConfig.fixed_steps must be steps in (0, 1e-3] s, got {self.fixed_steps!r}")
        if not self.rtols or any(not (0 < r < 1) for r in self.rtols):
            raise ValueError(f"SpeedConfig.rtols must be in (0, 1), got {self.rtols!r}")
        if self.probe_pulses < 0:
            raise ValueError(f"SpeedConfig.probe_pulses must be >= 0, got {self.probe_pulses!r}")
        if self.exact_processes < 1:
            raise ValueError(f"SpeedConfig.exact_processes must be >= 1, got {self.exact_processes!r}")


QUICK = SpeedConfig(record_s=50.0, window_s=10.0, rtols=(1e-3, 1e-5, 1e-7, 1e-9, 1e-12), probe_pulses=12,
                    probe_steps=(1e-8, 1e-9), weak=QUICK_WEAK, coupled=QUICK_COUPLED,
                    closed_loop=QUICK_CLOSED_LOOP)

FULL = SpeedConfig(record_s=100.0, window_s=100.0, rtols=(1e-3, 1e-4, 1e-5, 1e-6, 1e-8, 1e-10, 1e-12),
                   probe_pulses=40, probe_steps=(1e-8, 1e-9), exact_processes=3, linear_sequence=True,
                   weak=FULL_WEAK, coupled=FULL_COUPLED, closed_loop=FULL_CLOSED_LOOP)
