"""Where cells run: a local pool of per-cell processes (default) or a dask.distributed cluster.

Both call the same pure :func:`bench.cells.run_cell` on the same :class:`~bench.cells.Cell`
objects, and every random number comes from the cell's own seed, so the results are identical
(apart from the runtime columns) whichever executor runs them and in whatever order.

Crash isolation (both executors): every cell runs in a fresh child process
(:func:`bench.isolation.call_isolated`) watched from outside with a wall-clock deadline, so a
cell that dies (``os._exit``, segfault, OOM kill), hangs (also in C code) or raises anything
yields a :class:`~bench.isolation.CellFailure` for that cell only; the other cells go on.

* ``local``: a :class:`concurrent.futures.ThreadPoolExecutor` with ``workers`` threads, each of
  which waits on one cell process at a time (default ``os.cpu_count()`` processes at once).
  The idle cell processes are stopped when the executor closes.
* ``dask``: ``Client(address)`` for a running scheduler (``--scheduler``), else a
  ``LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)`` (nanny-managed,
  non-daemonic workers so that they may start the cell process). Tasks are submitted with
  ``retries=0``. A worker that dies under a task (remote daemonic workers run the cell in the
  worker itself) gives a failure for that cell; the nanny restarts the worker. A scheduler with no
  worker after :data:`WORKER_WAIT_S` seconds is an :class:`ExecutorError`. Workers write the
  artifacts (traces, series) into the run directory themselves, so with a remote cluster ``DIR``
  must be on a file system the workers share, and the workers need this package.
"""

from __future__ import annotations

import abc
import logging
import multiprocessing
import os
import re
from collections.abc import Callable, Hashable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from typing import Any

from bench.isolation import CellFailure, call_isolated, kill_all, ready, reopen, retire_idle

from bench.errors import UserError

__all__ = ["Executor", "LocalExecutor", "DaskExecutor", "ExecutorError", "make_executor", "EXECUTORS",
           "CellFailure", "WORKER_WAIT_S"]

EXECUTORS = ("local", "dask")
# How long a scheduler may have no worker before the run gives up [s] (env SOLNIC_BENCH_WORKER_WAIT_S).
WORKER_WAIT_S = 60.0
# Schemes of distributed.comm's backends; a bare host:port means tcp.
_SCHEDULER = re.compile(r"^(?:(tcp|tls|ws|wss|ucx|inproc)://)?(\[[0-9a-fA-F:.]+\]|[A-Za-z0-9_.-]+)(?::(\d{1,5}))?/?$")


class ExecutorError(UserError):
    """A bad executor setting, or a scheduler that cannot be reached (a user error)."""


class Executor(abc.ABC):
    """Runs ``fn(*args)`` for many argument tuples and yields the outcomes as they finish."""

    kind: str = ""

    def __init__(self, workers: int) -> None:
        self.workers = workers

    @abc.abstractmethod
    def start(self) -> None:
        """Acquire the workers (raises :class:`ExecutorError` if that is impossible)."""
        raise NotImplementedError

    @abc.abstractmethod
    def map_unordered(self, fn: Callable[..., Any], calls: Sequence[tuple[Any, ...]],
                      deadlines: Sequence[float | None] | None = None,
                      keys: Sequence[Hashable] | None = None,
                      ) -> Iterator[tuple[int, Any, BaseException | None]]:
        """Yield ``(index, result, None)`` or ``(index, None, exception)`` per call, as they finish.

        Each call runs in a cell process; ``deadlines[i]`` (wall seconds, None = none) is enforced
        from outside it; only calls with equal ``keys[i]`` share a process. A failed call's
        exception is a :class:`CellFailure` (or, on dask, what the cluster raised for a lost
        worker).
        """
        raise NotImplementedError

    @abc.abstractmethod
    def close(self, cancel: bool = False) -> None:
        """Release the workers; ``cancel`` drops calls that have not started."""
        raise NotImplementedError

    def describe(self) -> dict[str, Any]:
        return {"executor": self.kind, "workers": self.workers}

    def __enter__(self) -> "Executor":
        self.start()
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(cancel=exc_type is not None)


class LocalExecutor(Executor):
    """Per-cell processes on this machine, ``workers`` at a time."""

    kind = "local"

    def start(self) -> None:
        reopen()
        ready()
        self._pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="cell")

    def map_unordered(self, fn, calls, deadlines=None, keys=None):
        deadlines = list(deadlines) if deadlines is not None else [None] * len(calls)
        keys = list(keys) if keys is not None else [None] * len(calls)
        futures = {self._pool.submit(call_isolated, fn, tuple(args), limit, key): i
                   for i, (args, limit, key) in enumerate(zip(calls, deadlines, keys))}
        for fut in as_completed(futures):
            exc = fut.exception()
            yield futures[fut], (None if exc else fut.result()), exc

    def close(self, cancel: bool = False) -> None:
        pool = getattr(self, "_pool", None)
        if pool is not None:
            if cancel:
                kill_all()    # the waiting threads see their process die and return
            pool.shutdown(wait=True, cancel_futures=cancel)
            self._pool = None
        retire_idle()


def _dask_task(fn, args, deadline, key=None):
    """Runs on a dask worker: the cell in a cell process when the worker may have children
    (the worker keeps its idle cell process for the next task with the same key). On a daemonic
    worker (one started without ``DASK_DISTRIBUTED__WORKER__DAEMON=False``) the cell runs in the
    worker itself: its result is the same, but ``deadline`` is not enforced and a crash takes the
    worker with it (docs/dask.md)."""
    if multiprocessing.current_process().daemon:
        return ("ok", fn(*args))
    try:
        ready()
        return ("ok", call_isolated(fn, tuple(args), deadline, key))
    except CellFailure as exc:
        return ("failed", exc.kind, exc.message)


class DaskExecutor(Executor):
    """A dask.distributed cluster: the scheduler at ``address``, or a new LocalCluster."""

    kind = "dask"

    def __init__(self, workers: int, address: str | None = None) -> None:
        super().__init__(workers)
        self.address = address
        self._client = self._cluster = None

    def start(self) -> None:
        import dask
        from distributed import Client, LocalCluster

        wait_s = float(os.environ.get("SOLNIC_BENCH_WORKER_WAIT_S", WORKER_WAIT_S))
        if self.address:
            try:
                self._client = Client(self.address, timeout="15s", set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ExecutorError(f"--scheduler {self.address}: cannot connect: {exc}") from None
            try:
                self._client.wait_for_workers(1, timeout=wait_s)
            except (TimeoutError, OSError):
                self.close()
                raise ExecutorError(f"--scheduler {self.address}: no worker joined within {wait_s:g} s; "
                                    f"start one with `DASK_DISTRIBUTED__WORKER__DAEMON=False dask worker {self.address}` "
                                    f"(docs/dask.md)") from None
            self.workers = len(self._client.scheduler_info().get("workers", {})) or self.workers
        else:
            with dask.config.set({"distributed.worker.daemon": False}):
                self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                             dashboard_address=None, silence_logs=logging.ERROR)
            self._client = Client(self._cluster, set_as_default=False)

    def map_unordered(self, fn, calls, deadlines=None, keys=None):
        from distributed import as_completed as dask_as_completed

        deadlines = list(deadlines) if deadlines is not None else [None] * len(calls)
        keys = list(keys) if keys is not None else [None] * len(calls)
        futures = {self._client.submit(_dask_task, fn, args, limit, key, pure=False, retries=0): i
                   for i, (args, limit, key) in enumerate(zip(calls, deadlines, keys))}
        for fut in dask_as_completed(list(futures), loop=self._client.loop):
            try:
                answer = fut.result()
            except Exception as exc:  # a lost worker (KilledWorker) or an error outside the cell
                yield futures[fut], None, CellFailure("crash", f"dask: {type(exc).__name__}: {exc}")
                continue
            if answer[0] == "ok":
                yield futures[fut], answer[1], None
            else:
                yield futures[fut], None, CellFailure(answer[1], answer[2])

    def close(self, cancel: bool = False) -> None:
        if self._client is not None:
            try:
                self._client.close()
            except Exception:  # closing a half-connected client must not mask the real error
                pass
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "scheduler": self.address or "LocalCluster"}


def make_executor(kind: str, workers: int | None = None, scheduler: str | None = None) -> Executor:
    """Validate the settings and build (not start) an executor.

    Raises
    ------
    ExecutorError
        Unknown ``kind``, ``workers`` < 1, or ``scheduler`` without ``kind="dask"``.
    """
    if kind not in EXECUTORS:
        raise ExecutorError(f"--executor must be one of {list(EXECUTORS)}, got {kind!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ExecutorError(f"--workers must be an integer >= 1, got {workers!r}")
    if scheduler is not None and kind != "dask":
        raise ExecutorError("--scheduler needs --executor dask")
    if scheduler is not None:
        m = _SCHEDULER.match(scheduler)
        if not m or (m.group(3) is not None and not 0 < int(m.group(3)) < 65536):
            raise ExecutorError(f"--scheduler {scheduler!r}: expected [tcp|tls|ws|wss|ucx|inproc://]HOST[:PORT], "
                                f"e.g. tcp://127.0.0.1:8786")
    n = workers if workers is not None else (os.cpu_count() or 1)
    return DaskExecutor(n, scheduler) if kind == "dask" else LocalExecutor(n)
