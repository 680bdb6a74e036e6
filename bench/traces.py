"""One rerun recording per cell (rerun-sdk 0.41, ``send_columns``).

Timeline ``time``: seconds since the start of the run (a duration timeline, nanosecond
resolution). Entity paths, each logged as ``Scalars``:

=====================  ======================================================  ===================
entity                 value                                                   instants
=====================  ======================================================  ===================
``plant/error``        x1 = c − r [rad]                                        samples and events
``plant/velocity``     x2 [rad/s]                                              samples and events
``plant/torque``       x3, motor torque ∝ current [ozf·in]                     samples and events
``plant/mode``         1 moving −, 2 stuck, 3 moving +                         samples and events
``drive/u``            drive level u [ozf·in]                                  samples and events
``sensor/y``           measurement y(n) [rad]                                  samples
``controller/<key>``   each key of the controller's ``internals()``            samples
=====================  ======================================================  ===================

Samples and events are merged and sorted by time (samples first at equal times). At a sample
instant ``drive/u`` is the level in force just before it; at an event, the level after it.
Open a trace with ``rerun DIR/traces/<cell>.rrd`` (several files open as several recordings).
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np

from bench.runner import RunResult

__all__ = ["write_trace", "PLANT_ENTITIES", "TIMELINE", "APPLICATION_ID"]

TIMELINE = "time"
APPLICATION_ID = "solnic-bench"
# entity → (sample key, event key)
PLANT_ENTITIES = {
    "plant/error": ("x1", "x1"),
    "plant/velocity": ("x2", "x2"),
    "plant/torque": ("x3", "x3"),
    "plant/mode": ("mode", "mode"),
    "drive/u": ("u", "u"),
}


def _ns(t: np.ndarray) -> np.ndarray:
    """Seconds → the timeline's nanoseconds, rounded to nearest (0.3 s is 300000000 ns, not
    299999999 from a truncated 0.30000000000000004)."""
    return np.round(np.asarray(t, dtype=float) * 1e9).astype(np.int64).astype("timedelta64[ns]")


def _merged(samples: dict[str, np.ndarray], events: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Time order of samples followed by events: (times, permutation)."""
    t = np.concatenate([samples["t"], events["t"]]) if len(events.get("t", ())) else np.asarray(samples["t"])
    source = np.r_[np.zeros(len(samples["t"])), np.ones(len(t) - len(samples["t"]))]
    order = np.lexsort((source, t))
    return t[order], order


def write_trace(path: str | Path, result: RunResult, *, recording_id: str) -> Path:
    """Write the recorded run ``result`` to ``path`` (temporary file, then ``os.replace``).

    Raises
    ------
    ValueError
        If ``result`` was not recorded (``record=True``).
    """
    import rerun as rr

    if result.samples is None or result.events is None:
        raise ValueError("write_trace needs a recorded run (run_closed_loop(record=True))")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{threading.get_ident()}.tmp")
    samples, events = result.samples, result.events
    n = len(samples["t"])
    internals = {k: np.asarray(v, dtype=float) for k, v in (result.internals or {}).items()}
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
    try:
        rec.save(tmp)
        t, order = _merged(samples, events)
        index = [rr.TimeColumn(TIMELINE, duration=_ns(t))]
        for entity, (skey, ekey) in PLANT_ENTITIES.items():
            values = np.concatenate([np.asarray(samples[skey], float)[:n],
                                     np.asarray(events.get(ekey, ()), float)])[order]
            rec.send_columns(entity, indexes=index, columns=rr.Scalars.columns(scalars=values))
        sample_t = _ns(samples["t"])
        rec.send_columns("sensor/y", indexes=[rr.TimeColumn(TIMELINE, duration=sample_t)],
                         columns=rr.Scalars.columns(scalars=np.asarray(samples["y"], float)))
        for key, values in sorted(internals.items()):
            m = min(len(values), n)
            if m:
                rec.send_columns(f"controller/{key}", indexes=[rr.TimeColumn(TIMELINE, duration=sample_t[:m])],
                                 columns=rr.Scalars.columns(scalars=values[:m]))
        rec.flush()
        rec.disconnect()
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path
