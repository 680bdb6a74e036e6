"""The closed loop: sensor → controller → plant, one sample interval at a time.

The plant is reached only through its family's protocol (:mod:`plant.protocol`): at every
sample instant n·τs the family's sensor returns y(n) (``observe``: x1(n·τs) + w1(n) for an
ideal sensor, quantized when the plant's sensor is); the controller returns the drive command
for [n·τs, (n+1)·τs), which takes effect after the plant's compute delay (``delayed_step``,
carrying the pending command from one interval to the next); the family's pure step returns
the state at the next instant with the interval's exact integrals, which the scoring window
sums (:class:`bench.metrics.WindowTotals`).

Truth and model: the plant runs with the true parameters; the controller's ``reset`` gets the
model (a :class:`~plant.params.PlantParams`, by default the truth's own fields). Only a
``privileged`` bound sees the truth, through ``observe_truth(state, plant)`` before each step,
or, in the compiled loop, through a compiled step that declares ``CompiledLaw.truth`` (refused
for any other class: the run ends with status ``error``).

A controller that describes its step as a fixed linear law (the ``linear_law`` hook) runs, when
nothing is recorded and the family offers one for the plant (``PlantFamily.law_loop``: not with
a quantized sensor or a delay), in the family's compiled loop with bit-identical results. A
controller that declares a compiled step (the ``compiled_law`` hook; a linear law where its own
loop does not apply) runs, when nothing is recorded, in the family's ``compiled_law_loop``
(``PlantFamily.compiled_loop``: any sensor and delay, no disturbance torque), also
bit-identical; a sample its step hands back is done here, then the compiled loop resumes. Every
other run calls ``step`` here.

Randomness has one root (STYLE §5): ``SeedSequence(seed)`` spawns four child generators —
plant noise, sensor noise, controller, and the initial draw of x5 from N(0, VAR(x5)).

Recording: a *recorder* receives the run as it happens, in time order — ``sample(row)`` at
every sample instant (keys :data:`SAMPLE_FIELDS`), ``events(ev)`` once per interval with that
interval's plant events (keys :data:`plant.state.EVENT_FIELDS`), ``internals(values)`` after
every controller step, and ``close()`` at the end. ``record=True`` collects everything in
memory (:class:`MemoryRecorder`) and returns it as arrays in the :class:`RunResult`; a
streaming recorder (``bench.traces``) writes it to disk instead.
``x1_log=True`` keeps only t and x1 at the samples and plant events (what the per-phase peaks
of :mod:`bench.series` read), also on the compiled loop of a family with ``compiled_loop_logs``.
"""

from __future__ import annotations

import dataclasses
import math
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from bench.metrics import WindowTotals, run_metrics, unphysical
from controllers.base import Controller, ControllerDiverged
from plant.law_driver import X1Log
from plant.params import PlantParams
from plant.protocol import DEFAULT_FAMILY, TRUTH_FIELDS, PlantFamily, TruePlant, get_family, model_of
from plant.drive import DriveCommand
from plant.randomness import NoiseStream
from plant.state import EVENT_FIELDS, IntervalResult, SimOptions, Status, X1

__all__ = ["RunResult", "run_closed_loop", "spawn_streams", "PlantLoop", "Recorder", "MemoryRecorder",
           "SAMPLE_FIELDS"]

SAMPLE_FIELDS = ("t", "y", *TRUTH_FIELDS)


@dataclass
class RunResult:
    """Outcome of one closed-loop run.

    ``samples`` (with ``record=True``): arrays at the sample instants — :data:`SAMPLE_FIELDS`
    (u is the level in force just before the instant; ks_true, kc_true the effective friction)
    and any further truth the family reports.
    ``events``: :data:`plant.state.EVENT_FIELDS` at every plant event. ``internals``: the
    controller's ``internals()`` after each step, as arrays.
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


class Recorder(Protocol):
    """What the runner streams a run into (see the module docstring)."""

    def sample(self, row: dict[str, float]) -> None: ...
    def events(self, ev: dict[str, np.ndarray]) -> None: ...
    def internals(self, values: dict[str, float]) -> None: ...
    def close(self) -> None: ...


class MemoryRecorder:
    """Collects samples, events and controller internals as lists; ``arrays()`` at the end."""

    def __init__(self) -> None:
        self.s: dict[str, list[float]] = {k: [] for k in SAMPLE_FIELDS}
        self.e: list[dict[str, np.ndarray]] = []
        self.i: dict[str, list[float]] = {}
        self.n_steps = 0

    def sample(self, row: dict[str, float]) -> None:
        for k, v in row.items():
            lst = self.s.get(k)
            if lst is None:          # a family's own truth (SAMPLE_FIELDS are always there)
                lst = self.s[k] = []
            lst.append(v)

    def events(self, ev: dict[str, np.ndarray]) -> None:
        if len(ev["t"]):
            self.e.append(ev)

    def internals(self, values: dict[str, float]) -> None:
        series = self.i
        for k, v in values.items():
            lst = series.get(k)
            if lst is None:          # a key first reported now: NaN for the steps before
                lst = series[k] = [math.nan] * self.n_steps
            lst.append(float(v))
        self.n_steps += 1
        for lst in self.i.values():
            if len(lst) < self.n_steps:
                lst.append(math.nan)

    def close(self) -> None:
        pass

    def arrays(self) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, np.ndarray]]:
        samples = {k: np.asarray(v, dtype=float) for k, v in self.s.items()}
        if self.e:
            events = {k: np.concatenate([e[k] for e in self.e]) for k in EVENT_FIELDS}
        else:
            events = {k: np.empty(0) for k in EVENT_FIELDS}
        return samples, events, {k: np.asarray(v) for k, v in self.i.items()}


def spawn_streams(seed: int) -> dict[str, np.random.Generator]:
    """The run's four generators, spawned from ``SeedSequence(seed)``."""
    children = np.random.SeedSequence(seed).spawn(4)
    names = ("plant", "sensor", "controller", "initial")
    return {n: np.random.default_rng(c) for n, c in zip(names, children)}


class PlantLoop:
    """The plant side of one closed-loop run: the true plant, its noise and its command path.

    Built from the run's seed exactly as :func:`run_closed_loop` needs it (the four generators
    of :func:`spawn_streams`; x5(0) drawn from N(0, VAR(x5)) unless given; the sensor noise
    w1(0..n_measurements-1) drawn at once). ``measure()`` is y(n) at the current instant,
    ``advance(command)`` the interval to the next one (:meth:`PlantFamily.delayed_step`, the
    pending command carried over). The runner and the Gymnasium environment (:mod:`bench.gym_env`)
    both step a plant through this one class.
    """

    def __init__(self, family: PlantFamily, params: PlantParams, *, seed: int, n_measurements: int,
                 noise: bool, options: SimOptions, x5_initial: float | None = None) -> None:
        self.family, self.params, self.options = family, params, options
        self.streams = spawn_streams(seed)
        if x5_initial is None:
            x5_initial = self.streams["initial"].normal(0.0, params.correlated_friction_std) if noise else 0.0
        self.state = family.initial_state(params, x5_initial)
        self.plant_noise = NoiseStream(self.streams["plant"]) if noise else None
        self.sensor = self.streams["sensor"].standard_normal(n_measurements) * params.measurement_noise_std \
            if noise else np.zeros(n_measurements)
        self.pending: DriveCommand | None = None    # the compute delay's carry-over
        self.n = 0                                  # index of the current sample instant

    def measure(self) -> float:
        """y(n) [rad]: the family's sensor at the current instant with w1(n)."""
        return self.family.observe(self.params, self.state, self.sensor[self.n])

    def truth(self) -> dict[str, float]:
        """The family's truth at the current instant (:data:`~plant.protocol.TRUTH_FIELDS` and its own)."""
        return self.family.truth(self.params, self.state)

    def advance(self, command: DriveCommand, *, record: bool = False) -> IntervalResult:
        """The interval [n·τs, (n+1)·τs) under ``command`` (after the compute delay); the state moves on."""
        step, self.pending = self.family.delayed_step(self.state, self.pending, command, self.params,
                                                      self.plant_noise, self.options, record=record)
        self.state = step.state
        self.n += 1
        return step


def run_closed_loop(params: PlantParams, controller: Controller, *, duration_s: float,
                    warmup_s: float = 0.0, seed: int = 0, noise: bool = True, record: bool = False,
                    options: SimOptions | None = None, x5_initial: float | None = None,
                    time_limit_s: float | None = None, recorder: Recorder | None = None,
                    compiled: bool = True, family: str | PlantFamily = DEFAULT_FAMILY,
                    model: PlantParams | None = None, x1_log: bool = False) -> RunResult:
    """Run ``controller`` on the plant for ``duration_s`` seconds and score from ``warmup_s``.

    Parameters
    ----------
    params : PlantParams
        The true plant's parameters (the family's ``Params``).
    family : str or PlantFamily
        The true plant's family (default: Acker's plant).
    model : PlantParams, optional
        What the controller's ``reset`` is told; default the truth's :class:`PlantParams` fields.
    noise : bool
        False switches off every noise source: process noise, sensor noise and the random
        initial x5 (then 0).
    record : bool
        Keep samples, events and internals in memory and return them as arrays.
    recorder : Recorder, optional
        Receives the same data as it happens instead (e.g. a trace written to disk); closed
        at the end of the run, also when it fails.
    x5_initial : float, optional
        Override the initial correlated friction x5(0) [ozf·in].
    time_limit_s : float, optional
        Wall-clock budget [s]; checked at every sample (every ``CHUNK`` (1000)
        samples on the compiled path), a run over budget stops with status ``error``. None
        (default) means no limit.
    x1_log : bool
        Keep only t and x1 at every sample instant and plant event (:class:`plant.law_driver.X1Log`)
        and return them as ``samples`` and ``events`` (keys ``t``, ``x1``; ``bench.series.phase_peaks``
        needs no more), on the compiled loop of a ``compiled_law`` too (a ``linear_law`` then runs
        in that loop, not in its own). Ignored with ``record=True``.
    compiled : bool
        Run a controller that describes its step as a linear law (``linear_law`` hook) or
        declares a compiled step (``compiled_law`` hook) in one compiled loop (the family's
        ``linear_law_loop`` or ``compiled_law_loop``, bit-identical) when nothing is recorded.
        False always calls ``step`` from Python.

    Returns
    -------
    RunResult
        Never raises for a failing run: a controller or plant exception gives status ``error``.
    """
    fam = get_family(family) if isinstance(family, str) else family
    if not isinstance(params, fam.Params):
        raise ValueError(f"params must be {fam.Params.__name__} for plant family {fam.name!r}, "
                         f"got {type(params).__name__}")
    model = model_of(params) if model is None else model
    tau = params.sample_period
    if not math.isfinite(duration_s):
        raise ValueError(f"duration_s must be finite, got {duration_s!r}")
    n_samples = int(round(duration_s / tau))
    n_warm = int(round(warmup_s / tau))
    if n_samples <= 0:
        raise ValueError(f"duration_s must be at least one sample period ({tau} s), got {duration_s!r}")
    if not (0 <= n_warm < n_samples):
        raise ValueError(f"warmup_s must be in [0, duration_s) in whole samples, got {warmup_s!r}")
    if time_limit_s is not None and not (time_limit_s > 0 and math.isfinite(time_limit_s)):
        raise ValueError(f"time_limit_s must be a finite number > 0 or None, got {time_limit_s!r}")
    if record and recorder is not None:
        raise ValueError("record=True and a recorder are exclusive")
    deadline = math.inf if time_limit_s is None else time.perf_counter() + time_limit_s
    opts = options or SimOptions(noise=noise)
    if not noise and opts.noise:
        opts = dataclasses.replace(opts, noise=False)
    if x5_initial is not None and not math.isfinite(x5_initial):
        raise ValueError(f"x5_initial must be a finite friction [ozf·in], got {x5_initial!r}")
    loop = PlantLoop(fam, params, seed=seed, n_measurements=n_samples, noise=noise, options=opts,
                     x5_initial=x5_initial)
    state = loop.state
    memory = MemoryRecorder() if record else None
    rec = memory if record else recorder
    log = X1Log(n_samples) if x1_log and not record else None
    totals = WindowTotals()
    x1_window = np.empty(n_samples - n_warm + 1)
    n_window = 0
    status, message = Status.OK, ""
    wall0 = time.perf_counter()
    privileged = controller.privileged
    truth = TruePlant(fam, params) if privileged else None
    in_compiled = arithmetic_in_compiled = False
    try:
        controller.reset(model, loop.streams["controller"])
        n, law, claw, cloop, done = 0, None, None, None, False
        if rec is None and compiled:
            fast, cloop = fam.law_loop(params), fam.compiled_loop(params)
            if log is not None and not fam.compiled_loop_logs:
                cloop = None                 # a family loop that cannot keep the x1 log: Python
            law = controller.linear_law() if (fast or cloop) and not privileged else None
            if law is not None and fast and log is None:
                in_compiled = True
                state, sums, window, status, message = fast(law, params, opts, state, loop.sensor, n_warm,
                                                            loop.plant_noise, deadline)
                in_compiled = False
                totals = WindowTotals(**sums)
                n_window = window.shape[0]
                x1_window[:n_window] = window
                n, done = n_samples, True
                if status is Status.ERROR:
                    message = f"time limit of {time_limit_s:g} s exceeded at t = {state.t:.2f} s"
            elif cloop is not None:
                claw = controller.compiled_law()
                if claw is None and law is not None:
                    claw = law.compiled(params.sample_period)
                if claw is not None and getattr(claw, "truth", False) and not privileged:
                    raise ValueError(f"controller {controller.name!r} is not privileged: its compiled step "
                                     f"may not read the true state (CompiledLaw.truth)")
        while not done and n < n_samples and status is Status.OK:
            if claw is not None:             # compiled from sample n; a handed-back sample is done below
                pending = loop.pending
                if pending is not None and pending.drive is not claw.drive:
                    claw = None              # the Python path's delay raises at the next sample
                    continue
                in_compiled = True
                run = cloop(claw, params, opts, state, loop.sensor, n_warm, loop.plant_noise, deadline, n0=n,
                            sums=vars(totals).copy(), x1_window=x1_window,
                            pending=None if pending is None else pending.arrays(), **({} if log is None else {"log": log}))
                in_compiled = False
                state = loop.state = run.state
                n = loop.n = run.n_done
                loop.pending = None if run.pending is None else DriveCommand(tuple(zip(*run.pending)), claw.drive)
                totals = WindowTotals(**run.sums)
                n_window = max(0, n - n_warm)
                status, message = run.status, run.message
                if status is Status.ERROR:
                    message = f"time limit of {time_limit_s:g} s exceeded at t = {state.t:.2f} s"
                if not run.handed_back:
                    break
            for n in range(n, n + 1 if claw is not None else n_samples):
                y = loop.measure()
                if log is not None:
                    log.sample(n, state.t, state.x[X1])
                if n >= n_warm:
                    x1_window[n_window] = state.x[X1]
                    n_window += 1
                if rec is not None:
                    rec.sample({"t": state.t, "y": y, **loop.truth()})
                if privileged:
                    controller.observe_truth(state, truth)
                command = controller.step(y)
                if rec is not None:
                    rec.internals(controller.internals())
                step = loop.advance(command, record=rec is not None or log is not None)
                if rec is not None:
                    rec.events(step.events)
                if log is not None:
                    log.add_events(step.events["t"], step.events["x1"])
                if n >= n_warm:
                    totals.add(step)
                state = step.state
                if step.status is not Status.OK:
                    status, message = step.status, step.message
                    break
                if time.perf_counter() > deadline:
                    status = Status.ERROR
                    message = f"time limit of {time_limit_s:g} s exceeded at t = {state.t:.2f} s"
                    break
            n += 1
        if not done and n >= n_samples and status is Status.OK:
            x1_window[n_window] = state.x[X1]
            n_window += 1
    except ControllerDiverged as exc:   # the controller's estimates left their range: a result
        status = Status.DIVERGED
        message = f"controller diverged: {exc}"
    except Exception as exc:  # a failing controller is a result, not a crash (STYLE §8)
        arithmetic_in_compiled = in_compiled and isinstance(exc, ArithmeticError)
        status = Status.ERROR
        message = f"{type(exc).__name__}: {exc}"
        tb = traceback.extract_tb(exc.__traceback__)
        if tb:
            message += f" (at {tb[-1].filename.split('/')[-1]}:{tb[-1].lineno})"
    finally:
        if rec is not None:
            rec.close()
    if arithmetic_in_compiled:
        # A division by zero in a compiled loop cannot say where (the plant's law, a controller's
        # step): the Python path, bit-identical up to that point, stops on the same sample with a
        # message naming the cause. Only failing cells pay for the second run.
        left = None if time_limit_s is None else max(deadline - time.perf_counter(), 1e-3)
        again = run_closed_loop(params, controller, duration_s=duration_s, warmup_s=warmup_s, seed=seed,
                                noise=noise, options=options, x5_initial=x5_initial, time_limit_s=left,
                                recorder=recorder, compiled=False, family=family, model=model, x1_log=x1_log)
        if again.status != str(Status.OK):
            wall = time.perf_counter() - wall0     # both runs
            return dataclasses.replace(again, runtime_s=wall, metrics={
                **again.metrics, "runtime_s": wall,
                "realtime_factor": again.simulated_s / wall if wall > 0 else math.inf})
        # the Python path ran through: keep the compiled path's own message (cannot happen if the
        # two paths agree; kept so that a disagreement is visible rather than hidden)
        message += " (the Python path ran through this cell)"
    wall = time.perf_counter() - wall0
    metrics = run_metrics(totals, x1_window[:n_window])
    if status is Status.OK and (why := unphysical(state.x, metrics, params.u_max)) is not None:
        status, message = Status.DIVERGED, why
    if status is not Status.OK:
        metrics = {k: (math.nan if isinstance(v, float) else v) for k, v in metrics.items()}
    metrics["runtime_s"] = wall
    metrics["realtime_factor"] = state.t / wall if wall > 0 else math.inf
    try:
        summary = dict(controller.summary())
    except Exception as exc:
        summary = {"summary_error": f"{type(exc).__name__}: {exc}"}
    samples = events = internals = None
    if memory is not None:
        samples, events, internals = memory.arrays()
    elif log is not None:
        samples, events = log.arrays()
    return RunResult(str(status), message, metrics, summary, samples, events, internals, wall, state.t)

