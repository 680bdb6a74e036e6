"""Calls in cell processes, watched from outside: the crash barrier of every executor.

:func:`call_isolated` runs ``fn(*args)`` in a cell process (forked from a forkserver that has
the simulator imported) and waits for its answer, its death or its deadline, whichever comes
first. Whatever happens inside — ``os._exit``, a segfault, an OOM kill, a hang in C code that
never returns to Python, a ``SystemExit`` or ``KeyboardInterrupt`` raised by a controller — the
caller gets either the result or a :class:`CellFailure` naming what happened, and that process
is killed and never used again. No other call is affected: a process answers one call at a
time, and only a process whose every call returned normally is given another.

Reuse: a healthy process answers up to :func:`cells_per_process` calls (default
:data:`CELLS_PER_PROCESS`) with the same ``key`` (the executors pass the cell's plugins, so a
process never mixes plugin versions), then it is replaced; the executors stop the idle ones at
the end of a run (:func:`retire_idle`). A fresh process per call costs ~0.05–0.3 s of start-up
and first calls (process start, lazy imports, a linear design's first python-control call),
more than a short cell itself; ``SOLNIC_BENCH_CELLS_PER_PROCESS=1`` restores one process per
call. Results do not depend on it: a cell's numbers come from its own seed and pure functions
(the tests compare both settings bit for bit).

A cell process

* ignores SIGINT (Ctrl-C reaches the whole process group; the parent decides what stops);
* asks the kernel to SIGKILL it when its parent dies (``PR_SET_PDEATHSIG``), so a killed run
  leaves no orphan computing and writing into the run directory;
* leads its own process group, and is killed as a group (``killpg``) whenever it is stopped:
  whatever it started (a ``sleep``, a fork, a multiprocessing resource tracker) dies with it;
* answers each call with ``("ok", result)`` or ``("raised", message)`` over a pipe, and exits
  after a ``raised``.

The deadline is wall-clock from the moment the call is sent; past it the process is SIGKILLed.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import threading
import time
from multiprocessing.connection import wait
from typing import Any, Callable, Hashable

__all__ = ["CellFailure", "call_isolated", "kill_all", "reopen", "ready", "retire_idle", "cells_per_process",
           "PRELOAD", "CELLS_PER_PROCESS"]

# What the forkserver imports once, so that each child starts with the simulator loaded.
# bench.warm compiles the plant's kernels there once (not in every cell's time limit).
PRELOAD = ["bench.cells", "bench.runner", "bench.series", "bench.traces", "controllers", "control", "bench.warm"]
_PR_SET_PDEATHSIG = 1

# A cell process answers this many calls before it is replaced (cells_per_process()).
CELLS_PER_PROCESS = 64

_live: set[multiprocessing.process.BaseProcess] = set()
_live_lock = threading.Lock()
_closing = threading.Event()
_idle: list["_Worker"] = []
_idle_lock = threading.Lock()


class CellFailure(Exception):
    """The isolated call did not return a result.

    ``kind``: ``"crash"`` (the process died), ``"time_limit"`` (killed at its deadline) or
    ``"raised"`` (it raised a BaseException that escaped ``fn``).
    """

    def __init__(self, kind: str, message: str) -> None:
        super().__init__(message)
        self.kind = kind
        self.message = message


def _context():
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    return ctx


def _die_with_parent() -> None:
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the parent's cleanup still kills us
        pass


def _release_forkserver() -> None:
    """Close this child's copy of the run's "alive" pipe to the forkserver: the forkserver exits
    when the run's process dies only if no child holds it, and its exit then kills the children
    (``PR_SET_PDEATHSIG``)."""
    from multiprocessing import forkserver

    server = getattr(forkserver, "_forkserver", None)
    fd = getattr(server, "_forkserver_alive_fd", None)
    if fd is not None:
        try:
            os.close(fd)
        except OSError:
            pass
        server._forkserver_alive_fd = None


def _serve(conn) -> None:
    """The cell process: answer calls ``(fn, args)`` one after another until told to stop."""
    _die_with_parent()
    _release_forkserver()
    try:
        os.setpgid(0, 0)      # its own process group: killed whole, children included (_kill_group)
    except OSError:
        pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)
    while True:
        try:
            call = conn.recv()
        except (EOFError, OSError):
            break
        if call is None:
            break
        fn, args = call
        try:
            answer: tuple[str, Any] = ("ok", fn(*args))
        except BaseException as exc:  # noqa: BLE001 — anything that escapes is reported, not lost
            answer = ("raised", f"{type(exc).__name__}: {exc}")
        try:
            conn.send(answer)
        except Exception as exc:  # an unpicklable result
            answer = ("raised", f"result not transferable: {type(exc).__name__}: {exc}")
            conn.send(answer)
        if answer[0] != "ok":     # whatever escaped may have left this process in a bad state
            break
    conn.close()


def _kill_group(pid: int | None) -> None:
    """SIGKILL the process group that the cell process ``pid`` leads (it and everything it
    started); nothing if the group is gone. A group id is never reused while the group has a
    member, so this cannot hit an unrelated process group."""
    if pid is None:
        return
    try:
        if os.getpgid(pid) != pid:     # not (or no longer) a leader of its own group: only itself
            return
    except OSError:
        pass                           # the leader is gone; its group may still have members
    try:
        os.killpg(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"cell process killed by {name}"
    return f"cell process exited with code {exitcode} before returning a result"


class _Worker:
    """A cell process and the parent's end of its pipe."""

    def __init__(self, key: Hashable) -> None:
        ctx = _context()
        self.conn, child_end = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_serve, args=(child_end,), daemon=True)
        self.key = key
        self.calls = 0
        with _live_lock:
            if _closing.is_set():
                self.conn.close()
                raise CellFailure("crash", "run is stopping")
            self.proc.start()
            _live.add(self.proc)
        child_end.close()

    def retire(self, kill: bool = False) -> None:
        """Stop the process (politely unless ``kill``), kill what it left behind (its process
        group) and forget it."""
        pid = self.proc.pid
        try:
            if kill:
                _kill_group(pid)
            if not kill and self.proc.is_alive():
                try:
                    self.conn.send(None)
                except OSError:
                    pass
                self.proc.join(2.0)
            if self.proc.is_alive():
                self.proc.kill()
                self.proc.join()
            _kill_group(pid)
        finally:
            self.conn.close()
            with _live_lock:
                _live.discard(self.proc)
            self.proc.close()


def cells_per_process() -> int:
    """How many calls one cell process answers before it is replaced (env
    ``SOLNIC_BENCH_CELLS_PER_PROCESS``; 1 = a fresh process for every call)."""
    raw = os.environ.get("SOLNIC_BENCH_CELLS_PER_PROCESS", "")
    try:
        n = int(raw) if raw else CELLS_PER_PROCESS
    except ValueError:
        n = CELLS_PER_PROCESS
    return max(1, n)


def _take(key: Hashable) -> _Worker:
    with _idle_lock:
        for i, w in enumerate(_idle):
            if w.key == key:
                del _idle[i]
                if w.proc.is_alive():
                    return w
                w.retire(kill=True)   # died while idle (e.g. killed from outside): not this call's fault
                break
    return _Worker(key)


def _give_back(worker: _Worker) -> None:
    worker.calls += 1
    if worker.calls >= cells_per_process() or _closing.is_set():
        worker.retire()
        return
    with _idle_lock:
        _idle.append(worker)


def call_isolated(fn: Callable[..., Any], args: tuple[Any, ...], deadline_s: float | None,
                  key: Hashable = None) -> Any:
    """``fn(*args)`` in a cell process, killed after ``deadline_s`` wall seconds.

    The process is reused for later calls with the same ``key`` (e.g. the plugins a cell
    imports) until it has answered :func:`cells_per_process` calls; a process that died, overran
    its deadline or let anything escape ``fn`` is never reused.

    Raises
    ------
    CellFailure
        The process died, overran ``deadline_s`` or let an exception escape ``fn``.
    """
    if _closing.is_set():
        raise CellFailure("crash", "run is stopping")
    worker = _take(key)
    healthy = False
    t0 = time.monotonic()
    try:
        try:
            worker.conn.send((fn, args))
        except (OSError, ValueError):   # it died before this call reached it
            worker.proc.join(5.0)
            raise CellFailure("crash", _death(worker.proc.exitcode)) from None
        ready = wait([worker.conn, worker.proc.sentinel], timeout=deadline_s)
        if worker.conn in ready:
            try:
                status, value = worker.conn.recv()
            except (EOFError, OSError):
                worker.proc.join(5.0)
                raise CellFailure("crash", _death(worker.proc.exitcode)) from None
            if status == "ok":
                healthy = True
                return value
            raise CellFailure("raised", value)
        if worker.proc.sentinel in ready:
            worker.proc.join()
            raise CellFailure("crash", _death(worker.proc.exitcode))
        _kill_group(worker.proc.pid)
        worker.proc.kill()
        worker.proc.join()
        raise CellFailure("time_limit", f"time limit exceeded: cell process killed after "
                                        f"{time.monotonic() - t0:.1f} s (wall-clock limit {deadline_s:g} s)")
    finally:
        if healthy:
            _give_back(worker)
        else:
            worker.retire(kill=True)


def retire_idle() -> int:
    """Stop the idle cell processes (the end of a run: the next run's plugins may differ)."""
    with _idle_lock:
        workers = list(_idle)
        _idle.clear()
    for w in workers:
        w.retire()
    return len(workers)


def kill_all() -> int:
    """SIGKILL every live child and refuse new ones (the run is stopping). Returns how many."""
    _closing.set()
    with _live_lock:
        procs = list(_live)
    for p in procs:
        try:
            _kill_group(p.pid)
            p.kill()
        except (ValueError, OSError):
            pass
    retire_idle()
    return len(procs)


def reopen() -> None:
    """Allow new children again (a new run in the same process, e.g. in tests)."""
    _closing.clear()


_ready = False


def ready() -> None:
    """Start the forkserver and wait until it has imported :data:`PRELOAD` (and compiled the
    kernels): a fresh child costs milliseconds afterwards, and no cell's deadline pays for it."""
    global _ready
    if not _ready:
        call_isolated(int, (), None, key=("ready",))
        retire_idle()
        _ready = True
