"""A controller's report series and its peak error per labelled phase, from the protocol hooks.

Which controllers get a series: those that override
:meth:`~controllers.base.Controller.report_series`, on the cells whose series the report reads
(:func:`bench.driver.reads_series`; every cell when the caller does not say). Nothing here
knows a controller by name.

Which runs are recorded: a cell whose series is written. Every other cell runs unrecorded, so
a controller with a compiled step takes the compiled loop; for a controller that may label
phases (it overrides ``event_times``) the run keeps t and x1 at the samples and plant events
(``run_closed_loop(x1_log=True)``, also in the compiled loop), which is all :func:`phase_peaks`
reads, so the row is the recorded run's, bit for bit (:func:`logs_x1`).

Layout (``DIR/series/<cell>.parquet``, read by :mod:`reports.inputs`), one row per sample
instant:

* ``t`` [s], ``x1`` [rad] — from the run's samples;
* every scalar of the controller's ``internals()`` after the step at that instant (held
  between updates), under its own key;
* ``<q>_hat_pct`` for every internal named ``<q>_hat`` whose truth the runner records (a
  sample field ``<q>_true`` or ``<q>``, e.g. ``ks_hat`` → ``ks_true``, ``x4_hat`` → ``x4``;
  not the error x1 itself): the estimate as % of the true value at that instant;
* the columns of ``report_series(t, warmup_s)`` (controller-derived series such as values
  held from logged events).

Peak error per phase: ``event_times()`` labels of the form ``"phase:<name>"`` mark the start
instants of the controller's phases. A phase owns [its start, the next start of any phase); the
last one owns the rest of the run. ``peak_error_<name>_rad`` is the largest |x1| at the samples
and plant events inside the scoring window owned by phases called ``<name>``. Interior extrema
between events are not included; they lie within x4²/(2α·kc) ≈ 2e-10 rad of the nearest
velocity-zero event for Table 2-1.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from bench.runner import RunResult

__all__ = ["wants_series", "logs_x1", "figure_series", "phase_peaks", "PHASE_PREFIX"]

PHASE_PREFIX = "phase:"
_NO_PERCENT = {"x1", "y"}


def wants_series(controller: Any) -> bool:
    """True when the controller's class overrides ``report_series`` (the base returns {})."""
    from controllers.base import Controller

    return type(controller).report_series is not Controller.report_series


def logs_x1(controller: Any) -> bool:
    """Whether an unrecorded cell of ``controller`` keeps t and x1 at its samples and plant events:
    it has a report series and its class overrides ``event_times`` (it may label phases, whose
    peaks :func:`phase_peaks` takes from those points)."""
    from controllers.base import Controller

    return wants_series(controller) and type(controller).event_times is not Controller.event_times


def _ratio_pct(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den != 0, 100.0 * num / den, np.nan)


def figure_series(result: RunResult, controller: Any, warmup_s: float = 0.0,
                  ) -> tuple[pd.DataFrame, dict[str, float]]:
    """The series frame and the per-phase peaks of a recorded run (see module docstring).

    ``warmup_s`` [s] is the start of the scoring window, for the peaks.
    """
    s, internals = result.samples or {}, result.internals or {}
    n = len(s.get("t", ()))
    if internals:
        n = min(n, min(len(v) for v in internals.values()))
    t = np.asarray(s.get("t", ()), dtype=float)[:n]
    frame = pd.DataFrame({"t": t, "x1": np.asarray(s.get("x1", np.full(n, np.nan)), dtype=float)[:n]})
    for key, values in internals.items():
        col = np.asarray(values, dtype=float)[:n]
        frame[key] = col
        if key.endswith("_hat"):
            q = key[:-4]
            # x1 is the error itself: a percentage of a zero-mean quantity means nothing
            truth = s.get(f"{q}_true", s.get(q) if q not in _NO_PERCENT else None)
            if truth is not None:
                frame[f"{key}_pct"] = _ratio_pct(col, np.asarray(truth, dtype=float)[:n])
    for key, values in controller.report_series(t, warmup_s).items():
        frame[key] = np.asarray(values, dtype=float)
    return frame, phase_peaks(result, controller.event_times(), warmup_s)


def phase_peaks(result: RunResult, event_times: dict[str, np.ndarray],
                warmup_s: float) -> dict[str, float]:
    """``peak_error_<name>_rad`` for every ``"phase:<name>"`` label (NaN if it owns no point)."""
    labels = [(k[len(PHASE_PREFIX):], np.asarray(v, dtype=float).ravel())
              for k, v in event_times.items() if k.startswith(PHASE_PREFIX)]
    peaks = {f"peak_error_{name}_rad": math.nan for name, _ in labels}
    starts = np.concatenate([v for _, v in labels]) if labels else np.empty(0)
    if starts.size == 0:
        return peaks
    names = np.concatenate([np.full(v.size, i) for i, (_, v) in enumerate(labels)])
    order = np.argsort(starts, kind="stable")
    starts, names = starts[order], names[order]
    parts_t, parts_x = [], []
    for arrays in (result.samples, result.events):
        if arrays and len(arrays.get("t", ())):
            parts_t.append(np.asarray(arrays["t"], dtype=float))
            parts_x.append(np.abs(np.asarray(arrays["x1"], dtype=float)))
    if not parts_t:
        return peaks
    t, x = np.concatenate(parts_t), np.concatenate(parts_x)
    owner = np.searchsorted(starts, t, side="right") - 1   # phase i owns [start_i, start_i+1)
    valid = (owner >= 0) & (t >= warmup_s)
    for i, (name, _) in enumerate(labels):
        mask = valid.copy()
        mask[valid] = names[owner[valid]] == i
        if mask.any():
            peaks[f"peak_error_{name}_rad"] = float(x[mask].max())
    return peaks
