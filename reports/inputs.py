"""What a report is built from, and how it is stored on disk.

On-disk layout of a run directory ``DIR`` (every piece is optional; whatever is missing is
shown in the report as "not measured in this run", never as a number):

``DIR/results.parquet`` (or ``DIR/results.csv`` if there is no parquet, or the stored
``DIR/cells/*.json`` of a run killed before it rebuilt the tables)
    One row per cell of the matrix. Required columns: ``controller, scenario, seed, status``.
    Metric columns, each optional (a missing column is "not measured"):

    ==========================  ================================================================
    ``message``                 status message (str)
    ``cell``                    cell id; default :func:`cell_id` (``controller__scenario__seed``)
    ``peak_error_rad``          max |x1| over the continuous trajectory in the window [rad]
    ``rms_error_rad``           RMS of x1 at the samples in the window [rad]
    ``p99_error_rad``           99th percentile of |x1| at the samples in the window [rad]
    ``mean_abs_current``        (1/T)∫|x3|dt, torque-equivalent [ozf·in]
    ``rms_current``             √((1/T)∫x3²dt) [ozf·in]
    ``supply_charge_rate``      net supply charge per second, torque-equivalent [ozf·in]
    ``runtime_s``               wall-clock seconds of the cell [s]
    ``realtime_factor``         simulated seconds per wall second [–]
    ``n_events``                plant events [–]
    ``n_corrections``           corrections (pulses) [–]
    ``peak_error_small_rad``    solnic only: peak |x1| in the window while the cycle size is
    ``peak_error_medium_rad``   small / medium / large (sizes 1, 2, 3 of (6-6)–(6-8)) [rad]
    ``peak_error_large_rad``
    ==========================  ================================================================

``DIR/series/<cell>.parquet``
    Time series of one run of a controller with a ``report_series`` hook (solnic's give
    figures 7-2…7-5; see :mod:`bench.series` for the layout) (write it with :func:`write_series`,
    which checks the column names); ``<cell>`` is the ``cell`` value of its results row. Rows at every sample instant (events may be added), increasing ``t``.
    Only ``t`` is required; every other column is optional and the figure or claim that needs
    it says so when it is missing. Step quantities (estimates, costs) are held between updates;
    NaN means "not yet defined" (e.g. costs before the first cost computation).

    ===================  =======================================================================
    ``t``                time since start [s]
    ``x1``               true error c − r [rad]
    ``ks_hat_pct``       k̂s as % of the true effective ks at that moment [%]
    ``kc_hat_pct``       k̂c as % of the true effective kc at that moment [%]
    ``cost_small``       cost J (6-5) of the small / medium / large size, last computation [–]
    ``cost_medium``
    ``cost_large``
    ``dc_ratio``         size ratio Δc_large/Δc_small [–]
    ``x4_hat_pct``       x̂4 as % of the true x4 [%]
    ``cycle_size``       NSIZE of the current correction cycle, −1, 0, 1, 2, 3 [–]
    ``n_cost_updates``   number of cost-function computations so far [–]
    ``ks_kc_corr``       correlation of the k̂s and k̂c errors from the filter covariance [–]
    ``dc_large_rad``     Δc of the large size [rad]
    ``dt_opt_rel_error`` |Δt_u,opt − optimum|/optimum [–]
    ``dc_rel_mismatch``  |Δc_e − Δc_p|/|Δc_p| of the last correction [–]
    ===================  =======================================================================

``DIR/bound.csv``
    The empirical check of (2-6), one row per (design, plant, noise) run:
    ``design, omega_c, lag_ratio, ks_over_kc, inertia, noise, theta_rad, theta_b_rad, ratio,
    stable`` — ``omega_c`` [rad/s], ``lag_ratio`` L [–] (inf or empty for pure integral),
    ``theta_rad`` measured steady peak error, ``theta_b_rad`` = (ks−kc)/(2Jωc²), ``ratio`` =
    θ/θb, ``noise`` and ``stable`` booleans.

``DIR/hunting.csv``
    Hunting onset versus (2-1): ``ks_over_kc, lmax, onset_L`` (``onset_L`` empty if no hunting
    was found in the swept range). Extra columns are kept.

``DIR/speed.json``
    ``{"rows": [{"method", "setting", "error", "wall_s", "realtime_factor"}, ...],
    "speedup_vs_fixed_step_at_1e-6": float | null, "error_metric": str (optional),
    "reference": str (optional)}`` — ``error`` [rad], ``wall_s`` [s].

``DIR/config.json``
    The run configuration. ``"plant"`` holds the thesis scenario's ``PlantParams`` fields
    (used for the classical limit); ``"warmup_s"`` the scoring window's warm-up (default 20);
    ``"report"`` optional report settings: ``{"typical_cell": str, "selection": {...}}``
    (see :class:`reports.selection.Selection`).

``DIR/meta.json``
    Provenance: ``git_revision``, ``git_dirty``, ``created_utc``, ``command``, ``host``,
    package versions, ... (all shown verbatim). ``"synthetic": true`` marks demo data.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from bench.kernels import mixed_kernels_note
from reports.selection import Selection, plain

__all__ = [
    "RESULT_REQUIRED", "RESULT_METRICS", "SIZE_PEAK_COLUMNS", "SERIES_COLUMNS", "BOUND_COLUMNS", "HUNTING_COLUMNS",
    "SPEED_ROW_KEYS", "SeriesRun", "ReportInputs", "cell_id", "load_inputs",
    "normalise_results", "normalise_bound", "normalise_hunting", "normalise_speed",
    "attribute_series", "write_series",
]

RESULT_REQUIRED = ("controller", "scenario", "seed", "status")
RESULT_METRICS = (
    "peak_error_rad", "rms_error_rad", "p99_error_rad", "mean_abs_current", "rms_current",
    "supply_charge_rate", "runtime_s", "realtime_factor", "n_events", "n_corrections",
)
SIZE_PEAK_COLUMNS = {"small": "peak_error_small_rad", "medium": "peak_error_medium_rad",
                     "large": "peak_error_large_rad"}
SERIES_COLUMNS = (
    "t", "x1", "ks_hat_pct", "kc_hat_pct", "cost_small", "cost_medium", "cost_large",
    "dc_ratio", "x4_hat_pct", "cycle_size", "n_cost_updates", "ks_kc_corr", "dc_large_rad",
    "dt_opt_rel_error", "dc_rel_mismatch",
)
BOUND_COLUMNS = ("design", "omega_c", "lag_ratio", "ks_over_kc", "inertia", "noise",
                 "theta_rad", "theta_b_rad", "ratio", "stable")
HUNTING_COLUMNS = ("ks_over_kc", "lmax", "onset_L")
SPEED_ROW_KEYS = ("method", "setting", "error", "wall_s", "realtime_factor")

_TRUE = {"true", "1", "yes", "on", "y", "t"}
_FALSE = {"false", "0", "no", "off", "n", "f", ""}


def cell_id(controller: str, scenario: str, seed: int) -> str:
    """Default cell id ``controller__scenario__s<seed>`` (as bench.cells writes it), used
    when results carry no ``cell`` column."""
    return f"{controller}__{scenario}__s{int(seed)}"


@dataclass(frozen=True)
class SeriesRun:
    """One solnic time series and the cell it belongs to (``None`` where unknown)."""

    cell: str
    frame: pd.DataFrame
    controller: str | None = None
    scenario: str | None = None
    seed: int | None = None


@dataclass(frozen=True)
class ReportInputs:
    """Everything a report shows, normalised. ``None`` means "not measured in this run"."""

    results: pd.DataFrame
    series: dict[str, SeriesRun] = field(default_factory=dict)
    bound: pd.DataFrame | None = None
    hunting: pd.DataFrame | None = None
    speed: dict[str, Any] | None = None
    config: dict[str, Any] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    modes: dict[str, str] = field(default_factory=dict)    # "bound": the check's --quick/full mode


def _missing(columns: set[str], required: tuple[str, ...], what: str) -> None:
    absent = [c for c in required if c not in columns]
    if absent:
        raise ValueError(f"{what} is missing required column(s) {absent}; "
                         f"required: {list(required)}")


def _as_bool(series: pd.Series, what: str) -> pd.Series:
    def conv(v: Any) -> bool:
        if isinstance(v, (bool, np.bool_)):
            return bool(v)
        if isinstance(v, (int, float, np.integer, np.floating)) and not pd.isna(v):
            return bool(v)
        s = str(v).strip().lower()
        if s in _TRUE:
            return True
        if s in _FALSE or s == "nan":
            return False
        raise ValueError(f"{what} must be boolean (true/false, 1/0, on/off), got {v!r}")
    return series.map(conv).astype(bool)


def normalise_results(results: pd.DataFrame | None) -> pd.DataFrame:
    """Check the required columns, coerce metric columns to float and add ``cell``."""
    if results is None:
        results = pd.DataFrame(columns=list(RESULT_REQUIRED))
    if not isinstance(results, pd.DataFrame):
        raise ValueError(f"results must be a pandas DataFrame, got {type(results).__name__}")
    _missing(set(results.columns), RESULT_REQUIRED, "results")
    df = results.copy().reset_index(drop=True)
    for col in ("controller", "scenario", "status"):
        df[col] = df[col].astype(str)
    df["seed"] = pd.to_numeric(df["seed"], errors="raise").astype("int64")
    if "message" not in df.columns:
        df["message"] = ""
    df["message"] = df["message"].fillna("").astype(str)
    for col in (*RESULT_METRICS, *SIZE_PEAK_COLUMNS.values()):
        if col in df.columns:
            df[col] = pd.to_numeric(df[col], errors="coerce").astype(float)
    if "privileged" in df.columns:   # the row's own flag: a plugin's bound is known without its plugin
        flag = df["privileged"].astype(object)
        known = flag.notna()
        df["privileged"] = flag.where(known, None)
        if known.any():
            df.loc[known, "privileged"] = _as_bool(flag[known], "results column privileged")
    if "cell" not in df.columns:
        df["cell"] = [cell_id(c, s, n) for c, s, n in
                      zip(df["controller"], df["scenario"], df["seed"])]
    df["cell"] = df["cell"].astype(str)
    return df


def normalise_bound(bound: pd.DataFrame | None) -> pd.DataFrame | None:
    """Validate the (2-6) check table; ``ratio`` is recomputed where it is missing."""
    if bound is None:
        return None
    required = ("omega_c", "lag_ratio", "ks_over_kc", "theta_rad", "theta_b_rad", "stable")
    _missing(set(bound.columns), required, "bound.csv")
    df = bound.copy().reset_index(drop=True)
    for col in ("omega_c", "lag_ratio", "ks_over_kc", "inertia", "theta_rad", "theta_b_rad",
                "ratio"):
        if col in df.columns:
            df[col] = pd.to_numeric(df[col], errors="coerce").astype(float)
    if "ratio" not in df.columns:
        df["ratio"] = df["theta_rad"] / df["theta_b_rad"]
    df["ratio"] = df["ratio"].where(df["ratio"].notna(), df["theta_rad"] / df["theta_b_rad"])
    df["stable"] = _as_bool(df["stable"], "bound.csv column 'stable'")
    df["noise"] = (_as_bool(df["noise"], "bound.csv column 'noise'") if "noise" in df.columns
                   else False)
    if "design" not in df.columns:
        df["design"] = [f"ωc={w:g}, L={lag:g}" for w, lag in zip(df["omega_c"], df["lag_ratio"])]
    df["design"] = df["design"].astype(str)
    if "inertia" not in df.columns:
        df["inertia"] = np.nan
    return df


def normalise_hunting(hunting: pd.DataFrame | None) -> pd.DataFrame | None:
    """Validate the hunting-onset table (``onset_L`` NaN = no hunting found)."""
    if hunting is None:
        return None
    _missing(set(hunting.columns), HUNTING_COLUMNS, "hunting.csv")
    df = hunting.copy().reset_index(drop=True)
    for col in HUNTING_COLUMNS:
        df[col] = pd.to_numeric(df[col], errors="coerce").astype(float)
    return df


def normalise_speed(speed: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """Validate speed.json: every row needs the keys of :data:`SPEED_ROW_KEYS`."""
    if speed is None:
        return None
    if not isinstance(speed, Mapping):
        raise ValueError(f"speed must be a JSON object, got {type(speed).__name__}")
    rows = speed.get("rows", [])
    if not isinstance(rows, list):
        raise ValueError("speed.json 'rows' must be a list of objects")
    clean = []
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise ValueError(f"speed.json rows[{i}] must be an object, got {row!r}")
        absent = [k for k in SPEED_ROW_KEYS if k not in row]
        if absent:
            raise ValueError(f"speed.json rows[{i}] is missing key(s) {absent}")
        r = dict(row)
        for k in ("error", "wall_s", "realtime_factor"):
            r[k] = _float_or_nan(r[k])
        r["method"], r["setting"] = str(r["method"]), str(r["setting"])
        clean.append(r)
    out = dict(speed)
    out["rows"] = clean
    out["speedup_vs_fixed_step_at_1e-6"] = _float_or_nan(
        speed.get("speedup_vs_fixed_step_at_1e-6"))
    return out


def _float_or_nan(v: Any) -> float:
    try:
        return math.nan if v is None else float(v)
    except (TypeError, ValueError):
        return math.nan


def _normalise_series(frame: pd.DataFrame, cell: str) -> pd.DataFrame:
    if not isinstance(frame, pd.DataFrame):
        raise ValueError(f"series {cell!r} must be a pandas DataFrame")
    _missing(set(frame.columns), ("t",), f"series {cell!r}")
    df = frame.copy()
    for col in df.columns:
        df[col] = pd.to_numeric(df[col], errors="coerce").astype(float)
    return df.sort_values("t", kind="stable").reset_index(drop=True)


_CELL_RE = re.compile(r"^(?P<controller>.+?)__(?P<scenario>.+)__(?P<seed>-?\d+)$")


def attribute_series(series: Mapping[str, Any] | None,
                     results: pd.DataFrame) -> dict[str, SeriesRun]:
    """Attach controller/scenario/seed to each series, from the results row with that ``cell``.

    Values may be DataFrames or :class:`SeriesRun`. A cell with no results row is parsed as
    :func:`cell_id`; failing that its attribution stays ``None``.
    """
    out: dict[str, SeriesRun] = {}
    by_cell = {c: i for i, c in enumerate(results["cell"])} if "cell" in results else {}
    for cell, value in (series or {}).items():
        if isinstance(value, SeriesRun):
            frame, ctrl, scen, seed = value.frame, value.controller, value.scenario, value.seed
        else:
            frame, ctrl, scen, seed = value, None, None, None
        if ctrl is None and cell in by_cell:
            row = results.iloc[by_cell[cell]]
            ctrl, scen, seed = row["controller"], row["scenario"], int(row["seed"])
        elif ctrl is None and (m := _CELL_RE.match(cell)):
            ctrl, scen, seed = m["controller"], m["scenario"], int(m["seed"])
        out[str(cell)] = SeriesRun(str(cell), _normalise_series(frame, str(cell)), ctrl, scen,
                                   seed)
    return out


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path.name} is not valid JSON: {exc}") from exc


def _series_read(files: Mapping[str, Path], results: pd.DataFrame, config: Any) -> set[str]:
    """The series cells the report reads, out of ``files`` (cell → path).

    The claims read the series of the selection's identification controller itself on the
    thesis scenario (:func:`reports.claims.evaluate_claims`), the typical run is the configured
    cell or the first in :func:`reports.build._typical_run`'s order, and a series without a
    results row is attributed by name. Only those are read: a frontier run stores thousands of
    series (3.8 GB for the full frontier) that no part of the report shows. Without usable
    results or with a malformed selection every file is read (the report then says what it can).
    """
    if results is None or results.empty or "cell" not in results.columns or not isinstance(config, dict):
        return set(files)
    try:
        sel = Selection.from_config(config)
    except (TypeError, ValueError):
        return set(files)
    known = set(results["cell"].astype(str))
    keep = {c for c in files if c not in known}
    used = results.loc[plain(results, sel.solnic) & (results["scenario"] == sel.thesis_scenario), "cell"]
    keep |= set(used.astype(str)) & set(files)
    if sel.typical_cell in files:
        keep.add(sel.typical_cell)
    stored = results[results["cell"].astype(str).isin(files)]
    if not stored.empty:
        first = min(zip(stored["controller"] != sel.solnic, stored["scenario"] != sel.thesis_scenario,
                        stored["seed"].astype(int), stored["cell"].astype(str)))
        keep.add(first[3])
    return keep


def _stored_cells(out_dir: Path, config: Any) -> tuple[pd.DataFrame | None, str]:
    """The rows of ``out_dir/cells/*.json`` when the tables are missing (a run killed before it
    rebuilt them), in the order of ``config.json``'s cells; unreadable files are skipped."""
    from bench.store import results_frame

    rows = []
    for path in sorted((out_dir / "cells").glob("*.json")):
        try:
            row = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(row, dict) and isinstance(row.get("cell"), str):
            rows.append(row)
    if not rows:
        return None, "No results.parquet or results.csv: the benchmark matrix was not run."
    order = config.get("cells") if isinstance(config, dict) else None
    if isinstance(order, list):
        rank = {str(c): i for i, c in enumerate(order)}
        rows.sort(key=lambda r: (rank.get(r["cell"], len(rank)), r["cell"]))
    return results_frame(rows), (f"No results.parquet or results.csv (the run stopped before it rebuilt "
                                 f"them): the results are the {len(rows)} stored cell files in cells/.")


def load_inputs(out_dir: Path | str) -> ReportInputs:
    """Read whatever exists in ``out_dir`` (see the module docstring) into :class:`ReportInputs`.

    Raises
    ------
    FileNotFoundError
        If ``out_dir`` does not exist.
    ValueError
        If a file exists but is malformed (the message names the file and the column).
    """
    out_dir = Path(out_dir)
    if not out_dir.is_dir():
        raise FileNotFoundError(f"run directory {str(out_dir)!r} does not exist")
    notes: list[str] = []
    if (out_dir / "results.parquet").exists():
        results = pd.read_parquet(out_dir / "results.parquet")
    elif (out_dir / "results.csv").exists():
        results = pd.read_csv(out_dir / "results.csv", keep_default_na=True)
    else:
        results = None
    config = _read_json(out_dir / "config.json") if (out_dir / "config.json").exists() else {}
    if results is None:
        results, note = _stored_cells(out_dir, config)
        notes.append(note)
    results = normalise_results(results)

    series: dict[str, pd.DataFrame] = {}
    sdir = out_dir / "series"
    if sdir.is_dir():
        files = {p.stem: p for p in sorted(sdir.glob("*.parquet"))}
        for cell in sorted(_series_read(files, results, config)):
            series[cell] = pd.read_parquet(files[cell])

    bound = pd.read_csv(out_dir / "bound.csv") if (out_dir / "bound.csv").exists() else None
    hunting = (pd.read_csv(out_dir / "hunting.csv") if (out_dir / "hunting.csv").exists()
               else None)
    speed = _read_json(out_dir / "speed.json") if (out_dir / "speed.json").exists() else None
    meta = _read_json(out_dir / "meta.json") if (out_dir / "meta.json").exists() else {}
    mixed = mixed_kernels_note(results)
    if mixed:
        notes.append(mixed[0].upper() + mixed[1:] + ".")
    if not (out_dir / "config.json").exists():
        notes.append("No config.json: the configuration of this run is unknown.")
    if not (out_dir / "meta.json").exists():
        notes.append("No meta.json: the git revision and date of this run are unknown.")
    if not isinstance(config, dict) or not isinstance(meta, dict):
        raise ValueError("config.json and meta.json must each hold a JSON object")
    return ReportInputs(
        results=results,
        series=attribute_series(series, results),
        bound=normalise_bound(bound),
        hunting=normalise_hunting(hunting),
        speed=normalise_speed(speed),
        config=config,
        meta=meta,
        notes=tuple(notes),
        modes=_modes(out_dir),
    )


def _modes(out_dir: Path) -> dict[str, str]:
    """The (2-6) check's sweep mode (``quick``/``full``) from ``bound_verdict.json``, if stored."""
    path = out_dir / "bound_verdict.json"
    try:
        mode = _read_json(path).get("mode") if path.exists() else None
    except (ValueError, AttributeError):
        mode = None
    return {"bound": str(mode)} if mode else {}


def write_series(out_dir: Path | str, cell: str, frame: pd.DataFrame) -> Path:
    """Write one solnic series to ``out_dir/series/<cell>.parquet`` (for the runner).

    Raises
    ------
    ValueError
        If ``t`` is missing or not increasing, or a column is not one of
        :data:`SERIES_COLUMNS` (catches misspelt names before a report silently omits them).
    """
    if not isinstance(frame, pd.DataFrame) or "t" not in frame.columns:
        raise ValueError(f"series {cell!r} must be a DataFrame with a 't' column")
    unknown = sorted(set(frame.columns) - set(SERIES_COLUMNS))
    if unknown:
        raise ValueError(f"series {cell!r} has unknown column(s) {unknown}; "
                         f"known: {list(SERIES_COLUMNS)}")
    t = frame["t"].to_numpy(dtype=float)
    if t.size and (np.isnan(t).any() or np.any(np.diff(t) < 0)):
        raise ValueError(f"series {cell!r} column 't' must be finite and non-decreasing")
    if not cell or "/" in cell or cell.startswith("."):
        raise ValueError(f"series cell id {cell!r} must be a plain file name")
    sdir = Path(out_dir) / "series"
    sdir.mkdir(parents=True, exist_ok=True)
    path = sdir / f"{cell}.parquet"
    tmp = sdir / f".{cell}.parquet.tmp"
    frame.to_parquet(tmp, index=False)
    tmp.replace(path)
    return path
