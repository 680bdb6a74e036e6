"""Reference simulators for validation and for the speed claim (SPEC §2 "Reference simulators").

* :func:`fixed_step` — "standard fixed-increment numerical integration": Euler–Maruyama with
  the same mode logic checked once per step (breakaway, reflection, reversal, sticking), the
  flyback end checked once per step. Step size is a parameter. The kernel is compiled with
  numba; its unit normals come in chunks from a ``numpy.random.Generator``, so the random
  stream has the same single root as everything else.
* :func:`event_driven` — noise-free, ``scipy.integrate.solve_ivp`` with terminal events at tight
  tolerance, one call per mode segment. This is what a user would reach for today.

Both take the same command schedule as the exact simulator: a list of
:class:`~plant.drive.DriveCommand`, one per sample interval of length ``interval``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from plant.drive import DriveCommand, DriveType
from plant.params import PlantParams

__all__ = ["Schedule", "schedule_from_commands", "fixed_step", "fixed_step_pulses", "coupled_step_pulses",
           "event_driven", "FixedStepResult"]


@dataclass(frozen=True)
class Schedule:
    """Piecewise-constant command levels: ``levels[k]`` holds on [times[k], times[k+1])."""

    times: np.ndarray
    levels: np.ndarray
    drive: DriveType
    t_end: float


def schedule_from_commands(commands: list[DriveCommand], interval: float, t0: float = 0.0) -> Schedule:
    """Flatten per-interval commands (interval ``interval`` s each) into one schedule."""
    if not commands:
        raise ValueError("commands must not be empty")
    drive = commands[0].drive
    times, levels = [], []
    for n, cmd in enumerate(commands):
        if cmd.drive is not drive:
            raise ValueError("all commands of a schedule must use the same drive")
        base = t0 + n * interval
        for off, lvl in cmd.segments:
            if off < interval:
                times.append(base + off)
                levels.append(lvl)
    return Schedule(np.array(times), np.array(levels), drive, t0 + len(commands) * interval)


def _param_vector(p: PlantParams) -> np.ndarray:
    return np.array([p.alpha, p.beta3, p.beta4, p.beta5, math.sqrt(p.sigma2_sq), math.sqrt(p.sigma4_sq),
                     math.sqrt(p.sigma5_sq), p.u_max, p.coulomb, p.stiction])


@njit(cache=True)
def _em_chunk(S, n_steps, t0, dt, times, levels, bridge, prm, z, peak, acc):
    """Advance every path (rows of S) by n_steps Euler–Maruyama steps.

    S columns: x1, x2, x3, x4, x5, u, mode, k (schedule index). z: (n_steps, n_paths, 3).
    ``acc`` (n_paths, 3), or (0, 3) to skip: adds the left-point rectangle sums Σ|x3|·dt,
    Σx3²·dt and the supply charge Σ(u/u_max)·x3·dt (bridge) or Σ|x3|·dt (linear stage), the
    first-order counterparts of the exact interval integrals (plant.state.IntervalResult).
    """
    alpha, b3, b4, b5, s2, s4, s5, umax, kcb, ksb = prm
    sq = math.sqrt(dt)
    n_paths = S.shape[0]
    n_sched = times.shape[0]
    sums = acc.shape[0] > 0
    for j in range(n_paths):
        x1, x2, x3, x4, x5, u, mode, k = S[j, 0], S[j, 1], S[j, 2], S[j, 3], S[j, 4], S[j, 5], S[j, 6], int(S[j, 7])
        pk = peak[j]
        for i in range(n_steps):
            t = t0 + i * dt
            while k + 1 < n_sched and times[k + 1] <= t + 1e-15:
                k += 1
            lvl = levels[k]
            if bridge:
                if lvl > 0:
                    u = umax
                elif lvl < 0:
                    u = -umax
                elif u != 0.0:
                    u = -umax if x3 > 0 else (umax if x3 < 0 else 0.0)
            else:
                u = min(max(lvl, -umax), umax)
            if sums:
                acc[j, 0] += abs(x3) * dt
                acc[j, 1] += x3 * x3 * dt
                acc[j, 2] += (u / umax * x3 if bridge else abs(x3)) * dt
            x3n = x3 + (u - x3) * b3 * dt
            if bridge and lvl == 0.0 and u != 0.0 and (x3n == 0.0 or (x3n > 0) != (x3 > 0)):
                x3n = 0.0          # flyback diodes stop conducting
                u = 0.0
            x4n = x4 - b4 * x4 * dt + s4 * sq * z[i, j, 1]
            if mode == 2:
                x1 = x1 - x4 * dt
                ks = max(ksb + x5, 0.0)
                if x3n > ks:
                    mode = 3.0
                elif x3n < -ks:
                    mode = 1.0
                x2 = 0.0
            else:
                s = 1.0 if mode == 3.0 else -1.0
                kc = max(kcb + x5, 0.0)
                x2n = x2 + alpha * (x3 - s * kc) * dt + alpha * s2 * sq * z[i, j, 0]
                x1 = x1 + (x2 - x4) * dt
                x5 = x5 - b5 * x5 * dt + s5 * sq * z[i, j, 2]
                ks = max(ksb + x5, 0.0)
                if s * x2n <= 0.0:
                    if s * x3n > ks:
                        x2n = -x2n                   # reflect: torque still breaks stiction
                    elif -s * x3n > ks:
                        mode = 1.0 if mode == 3.0 else 3.0
                    else:
                        x2n = 0.0
                        mode = 2.0
                x2 = x2n
            x3 = x3n
            x4 = x4n
            if abs(x1) > pk:
                pk = abs(x1)
        S[j, 0], S[j, 1], S[j, 2], S[j, 3], S[j, 4], S[j, 5], S[j, 6], S[j, 7] = x1, x2, x3, x4, x5, u, mode, k
        peak[j] = pk


@dataclass(frozen=True)
class FixedStepResult:
    """Final states (rows: paths; columns x1, x2, x3, x4, x5, u, mode) and sampled x1."""

    final: np.ndarray
    sample_times: np.ndarray
    x1_samples: np.ndarray
    peak_abs_x1: np.ndarray
    n_steps: int


_CHUNK = 4096
_NO_SUMS = np.zeros((0, 3))


def fixed_step(params: PlantParams, schedule: Schedule, dt: float, *, x0: np.ndarray | None = None,
               n_paths: int = 1, rng: np.random.Generator | None = None,
               sample_every: float | None = None, stop_at_rest: bool = False) -> FixedStepResult:
    """Euler–Maruyama with the plant's mode logic, fixed step ``dt`` [s].

    ``x0`` is (x1, x2, x3, x4, x5, mode) for every path (default: rest, mode 2, x4 =
    command_velocity_initial). ``rng=None`` runs noise-free. ``sample_every`` [s] records x1
    at multiples of it (e.g. the sample period). ``stop_at_rest`` ends the run early, after
    the last schedule change, once every path is stuck with zero drive and current.
    """
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"dt must be a finite positive step in seconds, got {dt!r}")
    t_end = schedule.t_end
    n_total = int(round((t_end - schedule.times[0]) / dt))
    S = np.zeros((n_paths, 8))
    if x0 is None:
        S[:, 3] = params.command_velocity_initial
        S[:, 6] = 2.0
    else:
        x0 = np.asarray(x0, dtype=float)
        S[:, [0, 1, 2, 3, 4, 6]] = x0
    peak = np.abs(S[:, 0]).copy()
    prm = _param_vector(params)
    bridge = schedule.drive is DriveType.BRIDGE
    every = n_total if sample_every is None else max(1, int(round(sample_every / dt)))
    samples, stimes = [S[:, 0].copy()], [schedule.times[0]]
    done = 0
    t0 = schedule.times[0]
    while done < n_total:
        n = min(_CHUNK, n_total - done, every - (done % every))
        if rng is None:
            z = np.zeros((n, n_paths, 3))
        else:
            z = rng.standard_normal((n, n_paths, 3))
        _em_chunk(S, n, t0 + done * dt, dt, schedule.times, schedule.levels, bridge, prm, z, peak, _NO_SUMS)
        done += n
        if done % every == 0:
            samples.append(S[:, 0].copy())
            stimes.append(t0 + done * dt)
        if (stop_at_rest and t0 + done * dt > schedule.times[-1]
                and np.all(S[:, 6] == 2.0) and np.all(S[:, 5] == 0.0) and np.all(S[:, 2] == 0.0)):
            break
    return FixedStepResult(S[:, :7].copy(), np.array(stimes), np.array(samples), peak, n_total)


def fixed_step_pulses(params: PlantParams, dt_u: float, dt: float, n_paths: int, seed: int,
                      horizon: float = 0.01, sign: int = 1) -> np.ndarray:
    """Δc of ``n_paths`` independent pulses of ``dt_u`` seconds by Euler–Maruyama (x4 ≡ 0)."""
    p = params.replace(command_velocity_std=0.0, command_velocity_initial=0.0)
    sched = Schedule(np.array([0.0, dt_u]), np.array([sign * p.u_max, 0.0]), DriveType.BRIDGE, horizon)
    x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 2.0])
    res = fixed_step(p, sched, dt, x0=x0, n_paths=n_paths, rng=np.random.default_rng(np.random.SeedSequence(seed)),
                     stop_at_rest=True)
    moving = res.final[:, 6] != 2.0
    if np.any(moving):
        raise RuntimeError(f"{int(moving.sum())} paths still moving at the horizon {horizon} s")
    return res.final[:, 0]



def coupled_step_pulses(params: PlantParams, dt_u: float, dt_fine: float, factors: tuple[int, ...],
                        n_paths: int, seed: int, horizon: float = 0.01, sign: int = 1,
                        batch: int = 2000) -> np.ndarray:
    """Δc of ``n_paths`` pulses by Euler–Maruyama at every step ``dt_fine·f`` (f in ``factors``),
    all on the SAME Brownian path per pulse; shape (len(factors), n_paths).

    The fine grid draws the unit normals z (3 per step, as :func:`fixed_step_pulses`); the step
    f·dt_fine uses ΔW = √dt_fine·Σ of f consecutive z, i.e. the unit normal Σz/√f — the
    Brownian increments of the coarse grid are sums of the fine ones (the multilevel coupling,
    Giles 2008 §3). Each row alone is distributed exactly as :func:`fixed_step_pulses` at that
    step; a paired difference of rows has the small variance of the strong error.

    Raises
    ------
    ValueError
        If a factor is not a positive integer, or ``dt_fine`` or ``n_paths`` is not positive.
    """
    if not (dt_fine > 0 and math.isfinite(dt_fine)):
        raise ValueError(f"dt_fine must be a finite positive step in seconds, got {dt_fine!r}")
    if not factors or any(int(f) != f or f < 1 for f in factors):
        raise ValueError(f"factors must be positive integers, got {factors!r}")
    if n_paths < 1 or batch < 1:
        raise ValueError(f"n_paths and batch must be >= 1, got {n_paths!r}, {batch!r}")
    factors = tuple(int(f) for f in factors)
    p = params.replace(command_velocity_std=0.0, command_velocity_initial=0.0)
    times = np.array([0.0, dt_u])
    levels = np.array([sign * p.u_max, 0.0])
    prm = _param_vector(p)
    lcm = math.lcm(*factors)
    chunk = lcm * max(1, 1024 // lcm)
    n_total = int(round(horizon / dt_fine)) // lcm * lcm
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    out = np.empty((len(factors), n_paths))
    for start in range(0, n_paths, batch):
        m = min(batch, n_paths - start)
        states = []
        for _ in factors:
            S = np.zeros((m, 8))
            S[:, 6] = 2.0
            states.append(S)
        peak = np.zeros(m)
        done = 0
        while done < n_total:
            n = min(chunk, n_total - done)
            z = rng.standard_normal((n, m, 3))
            for f, S in zip(factors, states):
                zf = z if f == 1 else z.reshape(n // f, f, m, 3).sum(axis=1) / math.sqrt(f)
                _em_chunk(S, n // f, done * dt_fine, f * dt_fine, times, levels, True, prm, zf, peak, _NO_SUMS)
            done += n
            if done * dt_fine > dt_u and all(np.all(S[:, 6] == 2.0) and np.all(S[:, 5] == 0.0)
                                             and np.all(S[:, 2] == 0.0) for S in states):
                break
        for i, S in enumerate(states):
            if np.any(S[:, 6] != 2.0):
                raise RuntimeError(f"{int((S[:, 6] != 2.0).sum())} paths still moving at the horizon {horizon} s")
            out[i, start:start + m] = S[:, 0]
    return out


# --- solve_ivp with events --------------------------------------------------------------------

def event_driven(params: PlantParams, schedule: Schedule, *, rtol: float = 1e-12, atol: float = 1e-20,
                 x0: np.ndarray | None = None, sample_times: np.ndarray | None = None,
                 dense_step: float | None = None, max_events: int = 10_000_000,
                 peak_from: float = 0.0) -> dict[str, np.ndarray]:
    """Noise-free reference: ``solve_ivp`` (DOP853) with terminal events per mode segment.

    Returns ``x1_at`` (x1 at ``sample_times``), ``final`` (x1..x5), ``n_segments``,
    ``peak_abs_x1`` — max |x1| over [peak_from, end] at segment ends and at the interior extrema
    of x1, located by solve_ivp as non-terminal events of ẋ1 = x2 − x4 = 0 (x1 is monotone while
    stuck) — and, with ``dense_step``, ``dense_t``/``dense_x1`` on a uniform grid of that step.
    """
    p = params
    a, b3, b4, b5, U_, kcb, ksb = p.alpha, p.beta3, p.beta4, p.beta5, p.u_max, p.coulomb, p.stiction
    bridge = schedule.drive is DriveType.BRIDGE
    x = np.array([0.0, 0.0, 0.0, p.command_velocity_initial, 0.0]) if x0 is None else np.array(x0[:5], float)
    mode = 2 if x0 is None else int(x0[5])
    t = float(schedule.times[0])
    t_end = schedule.t_end
    bounds = list(schedule.times[1:]) + [t_end]
    sample_times = np.array([]) if sample_times is None else np.asarray(sample_times, float)
    x1_at = np.full(sample_times.shape, np.nan)
    dense_t, dense_x1 = [], []
    u = 0.0
    n_seg = 0
    peak = abs(x[0]) if t >= peak_from else 0.0

    def rhs_factory(mode: int, u: float):
        def rhs(_t, y):
            x1, x2, x3, x4, x5 = y
            kc = max(kcb + x5, 0.0)
            if mode == 2:
                return [-x4, 0.0, (u - x3) * b3, -b4 * x4, 0.0]
            s = 1.0 if mode == 3 else -1.0
            return [x2 - x4, a * (x3 - s * kc), (u - x3) * b3, -b4 * x4, -b5 * x5]
        return rhs

    for k, lvl in enumerate(schedule.levels):
        seg_end = bounds[k]
        if bridge:
            if lvl > 0:
                u, fly = U_, False
            elif lvl < 0:
                u, fly = -U_, False
            else:
                fly = x[2] != 0.0
                u = -math.copysign(U_, x[2]) if fly else 0.0
        else:
            u, fly = min(max(lvl, -U_), U_), False
        split = False              # the segment was already cut at ẋ2 = 0 (see "acc")
        while t < seg_end:
            n_seg += 1
            if n_seg > max_events:
                raise RuntimeError("too many segments")
            ks = max(ksb + x[4], 0.0)
            events = []
            if fly:
                ev = lambda _t, y: y[2]
                ev.terminal, ev.direction = True, 0
                events.append(("fly", ev))
            if mode == 2:
                up = lambda _t, y, ks=ks: y[2] - ks
                up.terminal, up.direction = True, 1
                dn = lambda _t, y, ks=ks: y[2] + ks
                dn.terminal, dn.direction = True, -1
                events += [("up", up), ("dn", dn)]
            else:
                s = 1.0 if mode == 3 else -1.0
                vz = lambda _t, y: y[1]
                vz.terminal, vz.direction = True, -s
                events.append(("vz", vz))
                if not split:
                    # ẋ2 = α(x3 − s·kc) changes sign where x3 crosses s·kc (once per segment: x3 is
                    # monotone). Stopping there makes x2 monotone on each piece, so a dip of x2
                    # through 0 and back cannot fall inside one solver step and be missed.
                    acc = lambda _t, y, s=s: y[2] - s * max(kcb + y[4], 0.0)
                    acc.terminal, acc.direction = True, 0
                    events.append(("acc", acc))
                ext = lambda _t, y: y[1] - y[3]
                ext.terminal, ext.direction = False, 0
                events.append(("ext", ext))
            sol = solve_ivp(rhs_factory(mode, u), (t, seg_end), x, method="DOP853", rtol=rtol, atol=atol,
                            events=[e for _, e in events], dense_output=True)
            t_stop = sol.t[-1]
            end = sol.y[:, -1]
            hit = None
            for (name, _), te, ye in zip(events, sol.t_events, sol.y_events):
                if name != "ext" and len(te):
                    hit = name
            if hit == "acc" and s * end[1] < 0.0:
                # x2 is monotone on [t, t_stop] (ẋ2 keeps its sign until x3 = s·kc) and changed sign
                # there: it crossed 0 once inside a solver step that also held the crossing back,
                # so the vz event saw no sign change. Locate that zero on the dense output.
                t_stop = brentq(lambda tt: float(sol.sol(tt)[1]), t, t_stop, xtol=1e-16, rtol=1e-15)
                end = sol.sol(t_stop)
                hit = "vz"
            for (name, _), te, ye in zip(events, sol.t_events, sol.y_events):
                if name == "ext":
                    keep = (te >= peak_from) & (te <= t_stop)
                    if keep.any():
                        peak = max(peak, float(np.max(np.abs(ye[keep, 0]))))
            if t_stop >= peak_from:
                peak = max(peak, abs(float(end[0])))
            mask = (sample_times >= t) & (sample_times <= t_stop)
            if mask.any():
                x1_at[mask] = sol.sol(sample_times[mask])[0]
            if dense_step:
                grid = np.arange(math.ceil(t / dense_step), math.floor(t_stop / dense_step) + 1) * dense_step
                grid = grid[(grid >= t) & (grid <= t_stop)]
                if grid.size:
                    dense_t.append(grid)
                    dense_x1.append(sol.sol(grid)[0])
            x = np.array(end, dtype=float)
            t = t_stop
            if hit is None:
                t = seg_end
                continue
            split = hit == "acc"       # after any other event x3's course or the direction changes
            if hit == "acc":
                pass
            elif hit == "fly":
                x[2], u, fly = 0.0, 0.0, False
            elif hit in ("up", "dn"):
                x[2] = ks if hit == "up" else -ks
                mode = 3 if hit == "up" else 1
            else:
                x[1] = 0.0
                s = 1.0 if mode == 3 else -1.0
                ks = max(ksb + x[4], 0.0)
                if s * x[2] > ks:
                    pass
                elif -s * x[2] > ks:
                    mode = 1 if mode == 3 else 3
                else:
                    mode = 2
    out = {"x1_at": x1_at, "final": x, "mode": mode, "n_segments": n_seg, "peak_abs_x1": peak}
    if dense_step:
        out["dense_t"] = np.concatenate(dense_t) if dense_t else np.array([])
        out["dense_x1"] = np.concatenate(dense_x1) if dense_x1 else np.array([])
    return out
