"""The contestants and their timing: the exact simulator (timed in a fresh process), fixed-step
Euler and the kernels' warm-up (module doc of :mod:`bench.speed`, item 2, and "Timing")."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from bench.metrics import WindowTotals
from plant.drive import DriveCommand, DriveType
from bench.exact import Schedule, advance, event_driven, fixed_step
from plant.params import PlantParams
from plant.randomness import NoiseStream
from plant.state import X1, PlantState, SimOptions, Status, initial_state


def _exact_replay(params: PlantParams, state0: PlantState, commands: list[DriveCommand], *,
                  noise: bool = False, seed: int = 0, metrics: bool = False
                  ) -> tuple[float, np.ndarray, str, WindowTotals]:
    """Replay ``commands`` with :func:`plant.advance`; (wall_s, x1 at samples, status, totals).

    ``metrics`` sums the intervals' integrals (the pure step always computes them)."""
    opts = SimOptions(noise=noise)
    rng = NoiseStream.from_seed(seed) if noise else None
    acc = WindowTotals()
    x1 = np.empty(len(commands) + 1)
    state = state0
    x1[0] = state.x[X1]
    status = Status.OK
    t0 = time.perf_counter()
    for k, command in enumerate(commands):
        step = advance(state, command, params, rng, opts)
        state, status = step.state, step.status
        if metrics:
            acc.add(step)
        if status != Status.OK:
            x1[k + 1:] = np.nan
            break
        x1[k + 1] = state.x[X1]
    wall = time.perf_counter() - t0
    return wall, x1, status, acc


def _warm_up_exact(params: PlantParams) -> None:
    """Touch every code path (and numba kernel) on a sequence unlike the measured ones."""
    widths = 1.05e-3 + 1.7e-5 * np.arange(12)
    commands = []
    for k, w in enumerate(widths):
        level = params.u_max if k % 2 == 0 else -params.u_max
        commands.append(DriveCommand.pulse(3.3e-4, float(w), level))
        commands.append(DriveCommand(((0.0, 0.0),), DriveType.BRIDGE))
    commands += [DriveCommand.hold(1.37 * (k % 5 - 2), DriveType.LINEAR) for k in range(20)]   # ±2.74 > ks
    state = initial_state(params, x5=0.0)
    for noise in (False, True):
        _exact_replay(params, state, commands[:24], noise=noise, seed=12345)
        _exact_replay(params, state, commands[24:], noise=noise, seed=12345)


def _exact_child(params: PlantParams, state0: PlantState, commands: list[DriveCommand], seed: int,
                 noisy: bool) -> dict[str, Any]:
    """Runs in a fresh process: warm up elsewhere, then time the replay cold, warm, noisy."""
    _warm_up_exact(params)
    cold, x1, status, _ = _exact_replay(params, state0, commands)
    warm = min(_exact_replay(params, state0, commands)[0] for _ in range(2))
    with_metrics = _exact_replay(params, state0, commands, metrics=True)[0]
    out = {"cold_s": cold, "warm_s": warm, "with_metrics_s": with_metrics, "x1": x1, "status": status}
    if noisy:
        wall, _, nstatus, acc = _exact_replay(params, state0, commands, noise=True, seed=seed, metrics=True)
        out.update(noisy_s=wall, noisy_status=nstatus, noisy_events=acc.n_events, noisy_substeps=acc.n_substeps)
    return out


def _fixed_step_child(params: PlantParams, schedule: Schedule, dt: float, x0: np.ndarray) -> dict[str, Any]:
    """Runs in a fresh process (for the uncompiled kernel): one timed Euler run."""
    t0 = time.perf_counter()
    res = fixed_step(params, schedule, dt, x0=x0, sample_every=params.sample_period)
    return {"wall_s": time.perf_counter() - t0, "x1": res.x1_samples[:, 0], "n_steps": res.n_steps,
            "jit_disabled": os.environ.get("NUMBA_DISABLE_JIT") == "1"}


def _in_fresh_process(fn: Callable[..., Any], *args: Any, env: dict[str, str] | None = None) -> Any:
    """Call ``bench.speed.contestants.<fn>(*args)`` in a new interpreter and return its result (pickled)."""
    with tempfile.TemporaryDirectory(prefix="solnic-speed-") as tmp:
        src, dst = Path(tmp) / "in.pkl", Path(tmp) / "out.pkl"
        src.write_bytes(pickle.dumps((fn.__name__, args)))
        code = "import sys, bench.speed.contestants as s; s._child_main(sys.argv[1], sys.argv[2])"
        proc = subprocess.run([sys.executable, "-c", code, str(src), str(dst)], capture_output=True, text=True,
                              env={**os.environ, **(env or {})}, check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"{fn.__name__} failed in a child process:\n{proc.stderr[-2000:]}")
        return pickle.loads(dst.read_bytes())


def _child_main(src: str, dst: str) -> None:
    name, args = pickle.loads(Path(src).read_bytes())
    if name not in ("_exact_child", "_fixed_step_child"):
        raise ValueError(f"unknown child task {name!r}")
    Path(dst).write_bytes(pickle.dumps(globals()[name](*args)))


def _best_time(run: Callable[[], tuple[float, Any]], budget_s: float = 2.0,
               max_repeats: int = 3) -> tuple[float, Any, int]:
    """Best wall time of up to ``max_repeats`` runs, repeating only while under ``budget_s``."""
    wall, value = run()
    best, n, spent = wall, 1, wall
    while n < max_repeats and spent + wall < budget_s:
        w, value = run()
        best, n, spent = min(best, w), n + 1, spent + w
    return best, value, n


def _warm_up_references(params: PlantParams) -> None:
    """Compile / load the Euler kernel and import solve_ivp's machinery (not timed)."""
    for drive, levels in ((DriveType.BRIDGE, [params.u_max, 0.0]), (DriveType.LINEAR, [0.5, -0.5])):
        sched = Schedule(np.array([0.0, 1.1e-3]), np.array(levels), drive, 0.02)
        fixed_step(params, sched, 1e-5, sample_every=params.sample_period)
        fixed_step(params, sched, 1e-5, sample_every=params.sample_period, rng=np.random.default_rng(0))
        event_driven(params, sched, rtol=1e-6, sample_times=np.array([0.0, 0.01, 0.02]))


def _timed(fn: Callable[[], Any]) -> tuple[float, Any]:
    t0 = time.perf_counter()
    value = fn()
    return time.perf_counter() - t0, value
