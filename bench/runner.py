"""The closed loop: sensor → controller → exact plant, one sample interval at a time.

At every sample instant n·τs the sensor returns y(n) = x1(n·τs) + w1(n); the controller
returns the drive command for [n·τs, (n+1)·τs); the plant advances exactly over that interval.

Randomness has one root (STYLE §5): ``SeedSequence(seed)`` spawns four child generators —
plant noise, sensor noise, controller, and the initial draw of x5 from N(0, VAR(x5)).
"""

from __future__ import annotations

import math
import time
import traceback
import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bench.metrics import run_metrics
from controllers.base import Controller
from plant.multimode import Accumulator, SimOptions, Status, advance, initial_state
from plant.params import PlantParams
from plant.transition import U, X1, X2, X3, X4, X5

__all__ = ["RunResult", "run_closed_loop", "spawn_streams"]


@dataclass
class RunResult:
    """Outcome of one closed-loop run.

    ``samples`` (with ``record=True``): arrays at the sample instants — t, y, x1, x2, x3, x4,
    x5, mode, u (u is the level in force just before the instant), ks_true, kc_true.
    ``events``: t, x1, x2, x3, mode, u at every plant event. ``internals``: the controller's
    ``internals()`` after each step, as arrays.
    """

    status: str
    message: str
    metrics: dict[str, float]
    summary: dict[str, Any] = field(default_factory=dict)
    samples: dict[str, np.ndarray] | None = None
    events: dict[str, np.ndarray] | None = None
    internals: dict[str, np.ndarray] | None = None
    runtime_s: float = 0.0
    simulated_s: float = 0.0


def spawn_streams(seed: int) -> dict[str, np.random.Generator]:
    """The run's four generators, spawned from ``SeedSequence(seed)``."""
    children = np.random.SeedSequence(seed).spawn(4)
    names = ("plant", "sensor", "controller", "initial")
    return {n: np.random.default_rng(c) for n, c in zip(names, children)}


def run_closed_loop(params: PlantParams, controller: Controller, *, duration_s: float,
                    warmup_s: float = 0.0, seed: int = 0, noise: bool = True, record: bool = False,
                    options: SimOptions | None = None, x5_initial: float | None = None,
                    time_limit_s: float | None = None) -> RunResult:
    """Run ``controller`` on the plant for ``duration_s`` seconds and score from ``warmup_s``.

    Parameters
    ----------
    noise : bool
        False switches off every noise source: process noise, sensor noise and the random
        initial x5 (then 0).
    x5_initial : float, optional
        Override the initial correlated friction x5(0) [ozf·in].
    time_limit_s : float, optional
        Wall-clock budget [s]; checked at every sample, a run over budget stops with status
        ``error``. None (default) means no limit.

    Returns
    -------
    RunResult
        Never raises for a failing run: a controller exception gives status ``error``.
    """
    tau = params.sample_period
    n_samples = int(round(duration_s / tau))
    n_warm = int(round(warmup_s / tau))
    if n_samples <= 0 or not math.isfinite(duration_s):
        raise ValueError(f"duration_s must be at least one sample period ({tau} s), got {duration_s!r}")
    if not (0 <= n_warm < n_samples):
        raise ValueError(f"warmup_s must be in [0, duration_s), got {warmup_s!r}")
    if time_limit_s is not None and not time_limit_s > 0:
        raise ValueError(f"time_limit_s must be > 0 or None, got {time_limit_s!r}")
    deadline = math.inf if time_limit_s is None else time.perf_counter() + time_limit_s
    opts = options or SimOptions(noise=noise)
    if not noise and opts.noise:
        opts = dataclasses.replace(opts, noise=False)
    streams = spawn_streams(seed)
    if x5_initial is None:
        x5_initial = streams["initial"].normal(0.0, params.correlated_friction_std) if noise else 0.0
    state = initial_state(params, x5=x5_initial)
    plant_rng = streams["plant"] if noise else None
    sigma1 = params.measurement_noise_std if noise else 0.0
    acc = Accumulator(active=(n_warm == 0))

    rec = _Recording(record)
    status, message = Status.OK, ""
    x1_window: list[float] = []
    wall0 = time.perf_counter()
    try:
        controller.reset(params, streams["controller"])
        for n in range(n_samples):
            if n == n_warm:
                acc.active = True
            X = state.X
            y = X[X1] + sigma1 * streams["sensor"].standard_normal()
            if n >= n_warm:
                x1_window.append(X[X1])
            rec.sample(state.t, y, X, state.mode, params)
            command = controller.step(float(y))
            if record:
                rec.internals(controller.internals())
            state, status, message = advance(state, command, tau, params, plant_rng, options=opts, acc=acc,
                                             recorder=rec.event if record else None)
            if status != Status.OK:
                break
            if time.perf_counter() > deadline:
                status = Status.ERROR
                message = f"time limit of {time_limit_s:g} s exceeded at t = {state.t:.2f} s"
                break
        else:
            acc.merge_peak(abs(state.X[X1]))
            x1_window.append(state.X[X1])
    except Exception as exc:  # a failing controller is a result, not a crash (STYLE §8)
        status = Status.ERROR
        message = f"{type(exc).__name__}: {exc}"
        tb = traceback.extract_tb(exc.__traceback__)
        if tb:
            message += f" (at {tb[-1].filename.split('/')[-1]}:{tb[-1].lineno})"
    wall = time.perf_counter() - wall0
    metrics = run_metrics(acc, np.asarray(x1_window))
    metrics["runtime_s"] = wall
    metrics["realtime_factor"] = state.t / wall if wall > 0 else math.inf
    try:
        summary = dict(controller.summary())
    except Exception as exc:
        summary = {"summary_error": f"{type(exc).__name__}: {exc}"}
    return RunResult(status, message, metrics, summary, rec.samples_arrays(), rec.events_arrays(),
                     rec.internals_arrays(), wall, state.t)


class _Recording:
    """Collects samples, events and controller internals when recording is on."""

    def __init__(self, on: bool) -> None:
        self.on = on
        self.s: dict[str, list[float]] = {k: [] for k in ("t", "y", "x1", "x2", "x3", "x4", "x5", "mode", "u",
                                                          "ks_true", "kc_true")}
        self.e: dict[str, list[float]] = {k: [] for k in ("t", "x1", "x2", "x3", "mode", "u")}
        self.i: dict[str, list[float]] = {}
        self.n_steps = 0

    def sample(self, t: float, y: float, X: np.ndarray, mode: int, p: PlantParams) -> None:
        if not self.on:
            return
        s = self.s
        for key, val in (("t", t), ("y", y), ("x1", X[X1]), ("x2", X[X2]), ("x3", X[X3]), ("x4", X[X4]),
                         ("x5", X[X5]), ("mode", mode), ("u", X[U]),
                         ("ks_true", max(p.stiction + X[X5], 0.0)), ("kc_true", max(p.coulomb + X[X5], 0.0))):
            s[key].append(float(val))

    def event(self, t: float, X: np.ndarray, mode: int) -> None:
        e = self.e
        e["t"].append(t); e["x1"].append(X[X1]); e["x2"].append(X[X2]); e["x3"].append(X[X3])
        e["mode"].append(mode); e["u"].append(X[U])

    def internals(self, values: dict[str, float]) -> None:
        for k, v in values.items():
            self.i.setdefault(k, [math.nan] * self.n_steps).append(float(v))
        self.n_steps += 1
        for k, lst in self.i.items():
            if len(lst) < self.n_steps:
                lst.append(math.nan)

    def samples_arrays(self) -> dict[str, np.ndarray] | None:
        return {k: np.asarray(v) for k, v in self.s.items()} if self.on else None

    def events_arrays(self) -> dict[str, np.ndarray] | None:
        return {k: np.asarray(v) for k, v in self.e.items()} if self.on else None

    def internals_arrays(self) -> dict[str, np.ndarray] | None:
        return {k: np.asarray(v) for k, v in self.i.items()} if self.on else None
