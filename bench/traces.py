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

:class:`TraceRecorder` is the runner's streaming recorder (``bench.runner.Recorder``): it
buffers at most :data:`CHUNK_SAMPLES` sample intervals and then sends them to rerun's file
sink as columns, so a cell's memory stays constant however long it runs. The file is written
under a temporary name and renamed on :meth:`TraceRecorder.close` (a killed cell leaves no
half-written trace). Every call into rerun runs on a writer thread behind a queue of
:data:`WRITER_QUEUE` chunks: a full or hung file system can stop the trace, never the cell. A
writer that fails or does not take a chunk within :data:`WRITER_TIMEOUT_S` seconds gives up, the
temporary file is removed and :attr:`TraceRecorder.error` says why (the cell's row becomes an
``artifact`` error, retried on resume). :func:`write_trace` writes an already recorded run.
"""

from __future__ import annotations

import math
import os
import queue
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from bench.runner import RunResult

__all__ = ["write_trace", "TraceRecorder", "TeeRecorder", "PLANT_ENTITIES", "TIMELINE", "APPLICATION_ID",
           "CHUNK_SAMPLES", "TRACE_POLICIES", "WRITER_TIMEOUT_S", "WRITER_QUEUE"]

# Sample intervals buffered before a chunk goes to the file (10 s of a 100 Hz run).
CHUNK_SAMPLES = 1000
# The longest a cell waits for its trace writer [s], and the chunks queued for it (memory bound).
WRITER_TIMEOUT_S = 30.0
WRITER_QUEUE = 4
# --traces: every cell, the first seed of each controller x scenario, or none.
TRACE_POLICIES = ("all", "first-seed", "none")

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


class _Writer:
    """Runs jobs (calls into rerun) in order on a daemon thread behind a bounded queue. The first
    job that raises, or a queue that stays full for ``timeout_s``, sets :attr:`error`; later jobs
    are dropped. The caller never waits longer than ``timeout_s`` per call, and after an error not
    at all."""

    def __init__(self, timeout_s: float) -> None:
        self.timeout_s = timeout_s
        self.error: str | None = None
        self._queue: queue.Queue = queue.Queue(maxsize=WRITER_QUEUE)
        self._done = threading.Event()
        threading.Thread(target=self._run, name="trace-writer", daemon=True).start()

    def _run(self) -> None:
        while True:
            job = self._queue.get()
            if job is None:
                break
            if self.error is None:
                try:
                    job()
                except Exception as exc:   # rerun's sink failed (full disk ...): the trace is lost, not the cell
                    self.error = f"{type(exc).__name__}: {exc}"
        self._done.set()

    def submit(self, job: Callable[[], None] | None) -> None:
        if self.error is not None and job is not None:
            return
        try:
            self._queue.put(job, timeout=self.timeout_s)
        except queue.Full:
            self.error = self.error or (f"the trace writer took no data for {self.timeout_s:g} s "
                                        f"(a full or hung file system?)")

    def finish(self) -> None:
        """Wait (at most ``timeout_s``) until every queued job has run."""
        if self.error is not None:
            return
        self.submit(None)
        if self.error is None and not self._done.wait(self.timeout_s):
            self.error = f"the trace writer did not finish within {self.timeout_s:g} s (a full or hung file system?)"


class TraceRecorder:
    """Streams a run into ``path`` as it happens (the runner's ``Recorder`` protocol).

    Memory is bounded by :data:`CHUNK_SAMPLES` sample intervals (their samples, events and
    controller internals), whatever the run length.
    """

    def __init__(self, path: str | Path, *, recording_id: str, chunk: int = CHUNK_SAMPLES,
                 timeout_s: float | None = None) -> None:
        import rerun as rr

        self._rr = rr
        self.path = Path(path)
        self._tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}-{threading.get_ident()}.tmp")
        self._chunk = chunk
        self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)
        self._writer = _Writer(WRITER_TIMEOUT_S if timeout_s is None else timeout_s)
        self._writer.submit(self._open)
        self._samples: dict[str, list[float]] = {}
        self._events: list[dict[str, np.ndarray]] = []
        self._internals: dict[str, tuple[list[int], list[float]]] = {}
        self._n = 0          # samples seen
        self._closed = False

    @property
    def error(self) -> str | None:
        """Why the trace was given up (None while it is being written or once it is in place)."""
        return self._writer.error

    def _open(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._rec.save(self._tmp)

    def _send(self, entity: str, index, values) -> None:
        """Queue one ``send_columns`` (the arrays are this chunk's own, never reused)."""
        rr, rec = self._rr, self._rec
        self._writer.submit(lambda: rec.send_columns(entity, indexes=index, columns=rr.Scalars.columns(scalars=values)))

    def sample(self, row: dict[str, float]) -> None:
        if self._writer.error is not None:     # given up: record nothing more
            return
        if self._samples and len(self._samples["t"]) >= self._chunk:
            self._flush(before=row["t"])
        for k, v in row.items():
            self._samples.setdefault(k, []).append(v)
        self._n += 1

    def events(self, ev: dict[str, np.ndarray]) -> None:
        if len(ev["t"]) and self._writer.error is None:
            self._events.append({k: np.asarray(ev[k]) for k in ("t", *{e for pair in PLANT_ENTITIES.values()
                                                                       for e in pair})})

    def internals(self, values: dict[str, float]) -> None:
        if self._writer.error is not None:
            return
        for k, v in values.items():
            times, vals = self._internals.setdefault(k, ([], []))
            times.append(self._n - 1)
            vals.append(float(v))

    def _flush(self, before: float = math.inf) -> None:
        """Send the buffered samples and the events before ``before`` [s] (the next sample's
        time: events at that instant go after it, as in the merged order)."""
        rr = self._rr
        if not self._samples:
            return
        s = {k: np.asarray(v, dtype=float) for k, v in self._samples.items()}
        if self._events:
            ev = {k: np.concatenate([e[k] for e in self._events]) for k in self._events[0]}
            now = ev["t"] < before
            keep = {k: v[~now] for k, v in ev.items()}
            ev = {k: v[now] for k, v in ev.items()}
            self._events = [keep] if len(keep["t"]) else []
        else:
            ev = {"t": np.empty(0)}
        t, order = _merged(s, ev)
        index = [rr.TimeColumn(TIMELINE, duration=_ns(t))]
        for entity, (skey, ekey) in PLANT_ENTITIES.items():
            values = np.concatenate([s[skey], np.asarray(ev.get(ekey, ()), float)])[order]
            self._send(entity, index, values)
        first = self._n - len(s["t"])
        self._send("sensor/y", [rr.TimeColumn(TIMELINE, duration=_ns(s["t"]))], s["y"])
        for key in sorted(self._internals):
            steps, vals = self._internals[key]
            if steps:
                at = s["t"][np.asarray(steps, dtype=np.int64) - first]
                self._send(f"controller/{key}", [rr.TimeColumn(TIMELINE, duration=_ns(at))], np.asarray(vals, float))
            self._internals[key] = ([], [])
        self._samples = {}

    def close(self) -> None:
        """Send what is buffered and move the file into place (idempotent). Never blocks longer
        than the writer's timeout; a trace given up leaves no file and sets :attr:`error`."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._writer.error is None:
                self._flush()
            self._writer.submit(self._rec.flush)
            self._writer.submit(self._rec.disconnect)
            self._writer.finish()
            if self._writer.error is None:
                os.replace(self._tmp, self.path)
        finally:
            self._tmp.unlink(missing_ok=True)

    def discard(self) -> None:
        """Drop the recording (a cell whose trace must not be kept)."""
        self._closed = True
        try:
            self._writer.submit(self._rec.disconnect)
            self._writer.finish()
        finally:
            self._tmp.unlink(missing_ok=True)


class TeeRecorder:
    """Feeds several recorders (e.g. a trace on disk and the memory a figure series needs)."""

    def __init__(self, *recorders) -> None:
        self.recorders = [r for r in recorders if r is not None]

    def sample(self, row):
        for r in self.recorders:
            r.sample(row)

    def events(self, ev):
        for r in self.recorders:
            r.events(ev)

    def internals(self, values):
        for r in self.recorders:
            r.internals(values)

    def close(self):
        for r in self.recorders:
            r.close()
