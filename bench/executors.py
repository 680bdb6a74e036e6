"""Where cells run: a local process pool (default) or a dask.distributed cluster.

Both call the same pure :func:`bench.cells.run_cell` on the same :class:`~bench.cells.Cell`
objects, and every random number comes from the cell's own seed, so the results are identical
(apart from the runtime columns) whichever executor runs them and in whatever order.

* ``local``: :class:`concurrent.futures.ProcessPoolExecutor` with ``workers`` processes
  (default ``os.cpu_count()``), started by a forkserver that has the simulator imported.
* ``dask``: ``Client(address)`` for a running scheduler (``--scheduler``), else a
  ``LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)``. Workers write the
  artifacts (traces, series) into the run directory themselves, so with a remote cluster
  ``DIR`` must be on a file system the workers share, and the workers need this package.
"""

from __future__ import annotations

import abc
import logging
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

from bench.errors import UserError

__all__ = ["Executor", "LocalExecutor", "DaskExecutor", "ExecutorError", "make_executor", "EXECUTORS"]

EXECUTORS = ("local", "dask")
# What the forkserver imports once, so that each worker starts with the simulator loaded.
_PRELOAD = ["bench.cells", "bench.runner", "bench.series", "bench.traces", "controllers"]


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
                      ) -> Iterator[tuple[int, Any, BaseException | None]]:
        """Yield ``(index, result, None)`` or ``(index, None, exception)`` per call, as they finish."""
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
    """A process pool on this machine."""

    kind = "local"

    def start(self) -> None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(_PRELOAD)
        self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx)

    def map_unordered(self, fn, calls):
        futures = {self._pool.submit(fn, *args): i for i, args in enumerate(calls)}
        for fut in as_completed(futures):
            exc = fut.exception()
            yield futures[fut], (None if exc else fut.result()), exc

    def close(self, cancel: bool = False) -> None:
        pool = getattr(self, "_pool", None)
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=cancel)
            self._pool = None


class DaskExecutor(Executor):
    """A dask.distributed cluster: the scheduler at ``address``, or a new LocalCluster."""

    kind = "dask"

    def __init__(self, workers: int, address: str | None = None) -> None:
        super().__init__(workers)
        self.address = address
        self._client = self._cluster = None

    def start(self) -> None:
        from distributed import Client, LocalCluster

        if self.address:
            try:
                self._client = Client(self.address, timeout="15s", set_as_default=False)
            except (OSError, TimeoutError, ValueError) as exc:
                raise ExecutorError(f"--scheduler {self.address}: cannot connect: {exc}") from None
            self.workers = len(self._client.scheduler_info().get("workers", {})) or self.workers
        else:
            self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                         dashboard_address=None, silence_logs=logging.ERROR)
            self._client = Client(self._cluster, set_as_default=False)

    def map_unordered(self, fn, calls):
        from distributed import as_completed as dask_as_completed

        futures = {self._client.submit(fn, *args, pure=False): i for i, args in enumerate(calls)}
        for fut in dask_as_completed(list(futures), loop=self._client.loop):
            try:
                yield futures[fut], fut.result(), None
            except Exception as exc:  # a lost worker; the cell is left for the next run
                yield futures[fut], None, exc

    def close(self, cancel: bool = False) -> None:
        if self._client is not None:
            self._client.close()
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
    if scheduler and kind != "dask":
        raise ExecutorError("--scheduler needs --executor dask")
    n = workers if workers is not None else (os.cpu_count() or 1)
    return DaskExecutor(n, scheduler) if kind == "dask" else LocalExecutor(n)
