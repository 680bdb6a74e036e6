"""Synthetic report inputs, for the report's tests and for previewing the layout.

Nothing here is a measurement: the numbers are shaped like a benchmark run (same columns and
orders of magnitude) but come from closed-form toys and a seeded generator. Reports built from
them carry ``meta["synthetic"] = True`` and show a banner saying so.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from bench.exact import EXACT_METHOD
from controllers import roles
from plant.params import lti_peak_bound
from reports.inputs import cell_id
from reports.limits import lag_ratio_limit

__all__ = ["synthetic_inputs", "write_synthetic_run"]

# The made-up run's controllers: the two the claims are about (by role) and a made-up peer.
_SUBJECT, _CLASSICAL, _PEER = roles.IDENTIFICATION, roles.CLASSICAL, "peer"
_HIGH_COST = f"{_SUBJECT}-high-cost"

_PLANT = {"inertia": 0.5, "motor_time_constant": 8e-3, "u_max": 20.0, "coulomb": 1.4,
          "stiction": 2.1, "sample_period": 0.01, "measurement_noise_std": 5e-6,
          "friction_noise_psd": 4e-4, "correlated_friction_std": 0.3,
          "correlated_friction_tau": 1000.0, "command_velocity_std": 3e-6,
          "command_velocity_tau": 1000.0, "command_velocity_initial": 30e-6}


def _results(rng: np.random.Generator, seeds: list[int]) -> pd.DataFrame:
    base = {  # controller: (peak µrad, mean |i|, rms i, supply, events per s)
        _CLASSICAL: (9.5, 1.60, 1.75, 1.60, 100),
        _PEER: (5.0, 4.0, 6.0, 4.0, 300),
        _SUBJECT: (2.0, 0.9, 2.5, 0.6, 60),
        _HIGH_COST: (0.6, 1.3, 3.5, 0.9, 120),
    }
    rows = []
    for scenario, factor in (("thesis", 1.0), ("quiet-friction", 0.8), ("ratio-2", 1.6)):
        for ctrl, (peak, iabs, irms, supply, ev) in base.items():
            if ctrl == _HIGH_COST and scenario != "thesis":
                continue
            for seed in seeds:
                p = peak * factor * rng.uniform(0.85, 1.15) * 1e-6
                family = _SUBJECT if ctrl == _HIGH_COST else ctrl   # the variant's base and family
                row = dict(controller=ctrl, controller_base=family, controller_family=family,
                           scenario=scenario, seed=seed, status="ok",
                           message="", peak_error_rad=p, rms_error_rad=p * 0.35,
                           p99_error_rad=p * 0.8, mean_abs_current=iabs * rng.uniform(0.9, 1.1),
                           rms_current=irms * rng.uniform(0.9, 1.1),
                           supply_charge_rate=supply * rng.uniform(0.9, 1.1),
                           runtime_s=rng.uniform(0.5, 3.0), n_events=int(ev * 100),
                           n_corrections=int(ev * 20))
                row["realtime_factor"] = 100.0 / row["runtime_s"]
                if ctrl == _SUBJECT and scenario == "thesis":
                    row.update(peak_error_small_rad=0.95e-6 * rng.uniform(0.9, 1.1),
                               peak_error_medium_rad=1.4e-6 * rng.uniform(0.9, 1.1),
                               peak_error_large_rad=p)
                rows.append(row)
    fail = dict(controller=_PEER, controller_base=_PEER, controller_family=_PEER,
                scenario="ratio-2", seed=max(seeds) + 1,
                status="chatter", message="event-count guard: 10000 events in 1e-6 s")
    rows.append(fail)
    df = pd.DataFrame(rows)
    df["cell"] = [cell_id(c, s, n) for c, s, n in zip(df["controller"], df["scenario"],
                                                      df["seed"])]
    return df


def _series(rng: np.random.Generator, seed: int, duration: float = 100.0) -> pd.DataFrame:
    t = np.round(np.arange(0.0, duration + 1e-9, 0.01), 10)
    # Sawtooth error whose amplitude decays from the start-up transient to ~1–2 µrad.
    period = np.where(t < 20, 1.5, 0.1)
    phase = np.mod(t / period, 1.0)
    amp = 1.0e-6 + 24e-6 * np.exp(-((t - 5.0) / 4.0) ** 2) + 8e-6 * np.exp(-t / 15)
    x1 = amp * (phase - 0.5) * 2 + rng.normal(0, 0.05e-6, t.size)
    ks = 100 - 50 * np.exp(-t / 12) - 4.5 * (1 - np.exp(-t / 30))
    kc = 100 - 50 * np.exp(-t / 3) + 1.6 * (1 - np.exp(-t / 10))
    x4 = 100 + 20 * np.exp(-t / 0.3) + 0.02 * rng.standard_normal(t.size)
    n_upd = np.where(t < 20, 0, 1 + np.floor((t - 20) / 2.5)).astype(float)
    costs = {}
    for name, c0 in (("small", 3.0), ("medium", 2.2), ("large", 2.6)):
        c = c0 * (1 + 0.8 * np.exp(-n_upd / 4)) + 0.05 * rng.standard_normal(t.size)
        step = np.where(n_upd > 0, c, np.nan)
        # Hold each value between updates.
        df = pd.Series(step).where(np.r_[True, np.diff(n_upd) > 0] & (n_upd > 0)).ffill()
        costs[f"cost_{name}"] = df.to_numpy()
    dc_ratio = np.where(n_upd > 0, 2.1 + 1.9 * np.exp(-n_upd / 3), np.nan)
    size = np.where(t < 4, -1, np.where(t < 9.5, 0, 1 + (np.floor(t / 0.1) % 3)))
    return pd.DataFrame({
        "t": t, "x1": x1, "ks_hat_pct": ks, "kc_hat_pct": kc, **costs, "dc_ratio": dc_ratio,
        "x4_hat_pct": x4, "cycle_size": size.astype(float), "n_cost_updates": n_upd,
        "ks_kc_corr": -0.65 + 0.3 * np.exp(-t / 20),
        "dc_large_rad": np.where(t < 20, 45e-6, 2.1e-6),
    })


def _bound(rng: np.random.Generator) -> pd.DataFrame:
    rows = []
    for ratio in (1.25, 1.5, 2.0):
        kc = 1.4
        ks = kc * ratio
        for inertia in (0.25, 0.5):
            for wc in (30.0, 60.0, 120.0, 240.0):
                for lag in (1.0, 2.0, 4.0, lag_ratio_limit(ratio), 2 * lag_ratio_limit(ratio),
                            math.inf):
                    for noise in (False, True):
                        theta_b = lti_peak_bound(ks, kc, inertia, wc)   # (2-6)
                        stable = lag <= lag_ratio_limit(ratio) * 1.05
                        theta = theta_b * rng.uniform(1.2, 6.0) if stable else math.nan
                        design = "integral" if math.isinf(lag) else f"lead-lag L={lag:.3g}"
                        rows.append(dict(design=design, omega_c=wc, lag_ratio=lag,
                                         ks_over_kc=ratio, inertia=inertia, noise=noise,
                                         theta_rad=theta, theta_b_rad=theta_b,
                                         ratio=theta / theta_b, stable=stable))
    return pd.DataFrame(rows)


def _hunting(rng: np.random.Generator) -> pd.DataFrame:
    r = np.array([1.25, 1.5, 2.0, 3.0])
    lmax = np.array([lag_ratio_limit(x) for x in r])
    return pd.DataFrame({"ks_over_kc": r, "lmax": lmax,
                         "onset_L": lmax * rng.uniform(0.85, 1.2, r.size)})


def _speed() -> dict[str, Any]:
    rows = [dict(method=EXACT_METHOD, setting="exact", error=2e-9, wall_s=0.8,
                 realtime_factor=125.0)]
    for h in (1e-4, 1e-5, 1e-6, 1e-7):
        rows.append(dict(method="fixed_step", setting=f"h={h:g} s", error=3e-2 * h,
                         wall_s=0.02 / h, realtime_factor=100 * h / 0.02))
    for tol in (1e-6, 1e-8, 1e-10):
        rows.append(dict(method="solve_ivp", setting=f"rtol={tol:g}", error=tol * 5,
                         wall_s=40.0 * (1 - math.log10(tol) / 4), realtime_factor=1.0))
    return {"rows": rows, "speedup_vs_fixed_step_at_1e-6": 3.7e3,
            "error_metric": "max |x1 − x1_exact| over the run [rad]",
            "reference": "multimode, noise-free, same command sequence"}


def synthetic_inputs(seed: int = 0, *, seeds: tuple[int, ...] = (0, 1, 2),
                     series_seeds: tuple[int, ...] = (0, 1),
                     duration: float = 100.0) -> dict[str, Any]:
    """Keyword arguments for :func:`reports.build_report`, all synthetic."""
    rng = np.random.default_rng(seed)
    results = _results(rng, list(seeds))
    series = {cell_id(_SUBJECT, "thesis", s): _series(rng, s, duration) for s in series_seeds}
    config = {"plant": dict(_PLANT), "warmup_s": 20.0, "duration_s": duration,
              "matrix": {"controllers": sorted(results["controller"].unique()),
                         "scenarios": sorted(results["scenario"].unique()),
                         "seeds": list(seeds)}}
    meta = {"synthetic": True, "git_revision": "synthetic-0000000",
            "created_utc": "2026-01-01T00:00:00Z", "command": "reports.synthetic"}
    return dict(results=results, series=series, bound=_bound(rng), hunting=_hunting(rng),
                speed=_speed(), config=config, meta=meta)


def write_synthetic_run(out_dir: Path | str, seed: int = 0, **kwargs: Any) -> Path:
    """Write synthetic inputs in the on-disk layout of :mod:`reports.inputs`; returns ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    data = synthetic_inputs(seed, **kwargs)
    data["results"].to_parquet(out / "results.parquet", index=False)
    (out / "series").mkdir(exist_ok=True)
    for cell, frame in data["series"].items():
        frame.to_parquet(out / "series" / f"{cell}.parquet", index=False)
    data["bound"].to_csv(out / "bound.csv", index=False)
    data["hunting"].to_csv(out / "hunting.csv", index=False)
    (out / "speed.json").write_text(json.dumps(data["speed"], indent=2))
    (out / "config.json").write_text(json.dumps(data["config"], indent=2))
    (out / "meta.json").write_text(json.dumps(data["meta"], indent=2))
    return out
