"""One call in a fresh process, watched from outside: the crash barrier of every executor.

:func:`call_isolated` runs ``fn(*args)`` in a new child process (forked from a forkserver that
has the simulator imported) and waits for its answer, its death or its deadline, whichever comes
first. Whatever happens inside the child — ``os._exit``, a segfault, an OOM kill, a hang in C
code that never returns to Python, a ``SystemExit`` or ``KeyboardInterrupt`` raised by a
controller — the caller gets either the result or a :class:`CellFailure` naming what happened;
no other call is affected, because no process is shared between calls.

The child

* ignores SIGINT (Ctrl-C reaches the whole process group; the parent decides what stops);
* asks the kernel to SIGKILL it when its parent dies (``PR_SET_PDEATHSIG``), so a killed run
  leaves no orphan computing and writing into the run directory;
* sends ``("ok", result)`` or ``("raised", message)`` over a pipe.

The deadline is wall-clock from the child's start; past it the child is SIGKILLed.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import threading
import time
from multiprocessing.connection import wait
from typing import Any, Callable

__all__ = ["CellFailure", "call_isolated", "kill_all", "reopen", "ready", "PRELOAD"]

# What the forkserver imports once, so that each child starts with the simulator loaded.
# bench.warm compiles the plant's kernels there once (not in every cell's time limit).
PRELOAD = ["bench.cells", "bench.runner", "bench.series", "bench.traces", "controllers", "control", "bench.warm"]
_PR_SET_PDEATHSIG = 1

_live: set[multiprocessing.process.BaseProcess] = set()
_live_lock = threading.Lock()
_closing = threading.Event()


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


def _child(conn, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
    _die_with_parent()
    _release_forkserver()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_DFL)
    try:
        answer: tuple[str, Any] = ("ok", fn(*args))
    except BaseException as exc:  # noqa: BLE001 — anything that escapes is reported, not lost
        answer = ("raised", f"{type(exc).__name__}: {exc}")
    try:
        conn.send(answer)
    except Exception as exc:  # an unpicklable result
        conn.send(("raised", f"result not transferable: {type(exc).__name__}: {exc}"))
    conn.close()


def _death(exitcode: int | None) -> str:
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"cell process killed by {name}"
    return f"cell process exited with code {exitcode} before returning a result"


def call_isolated(fn: Callable[..., Any], args: tuple[Any, ...], deadline_s: float | None) -> Any:
    """``fn(*args)`` in a fresh child process, killed after ``deadline_s`` wall seconds.

    Raises
    ------
    CellFailure
        The child died, overran ``deadline_s`` or let an exception escape ``fn``.
    """
    if _closing.is_set():
        raise CellFailure("crash", "run is stopping")
    ctx = _context()
    receiver, sender = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(sender, fn, args), daemon=True)
    with _live_lock:
        if _closing.is_set():
            raise CellFailure("crash", "run is stopping")
        proc.start()
        _live.add(proc)
    sender.close()
    t0 = time.monotonic()
    try:
        ready = wait([receiver, proc.sentinel], timeout=deadline_s)
        if receiver in ready:
            try:
                status, value = receiver.recv()
            except (EOFError, OSError):
                proc.join(5.0)
                raise CellFailure("crash", _death(proc.exitcode)) from None
            proc.join(2.0)   # it exits right after sending; if not, the finally kills it
            if status == "ok":
                return value
            raise CellFailure("raised", value)
        if proc.sentinel in ready:
            proc.join()
            raise CellFailure("crash", _death(proc.exitcode))
        proc.kill()
        proc.join()
        raise CellFailure("time_limit", f"time limit exceeded: cell process killed after "
                                        f"{time.monotonic() - t0:.1f} s (wall-clock limit {deadline_s:g} s)")
    finally:
        if proc.is_alive():
            proc.kill()
            proc.join()
        receiver.close()
        with _live_lock:
            _live.discard(proc)
        proc.close()


def kill_all() -> int:
    """SIGKILL every live child and refuse new ones (the run is stopping). Returns how many."""
    _closing.set()
    with _live_lock:
        procs = list(_live)
    for p in procs:
        try:
            p.kill()
        except (ValueError, OSError):
            pass
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
        call_isolated(int, (), None)
        _ready = True
