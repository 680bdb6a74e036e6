"""Errors against the exact simulator and the cost of equal accuracy: interpolated along a
contestant's error curve, and the measured lower bound (module doc of :mod:`bench.speed`,
items 3 and 4)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from bench.speed.config import TARGET_ERROR
from bench.speed.sequence import _Sequence


# |Δc_ref| above this counts as motion; pulses below breakaway give exactly 0 (up to ~1e-21
# rounding in x1 + r) in the exact simulator.
_MOVING_DC_RAD = 1e-15


def _errors(x1: np.ndarray, ref_x1: np.ndarray, seq: _Sequence) -> dict[str, float | None]:
    """Relative errors of a contestant's x1 at the sample instants (module docstring, item 3)."""
    if not np.all(np.isfinite(x1)):
        return {"error": math.inf, "error_x1": math.inf, "error_dc": math.inf, "error_x1_abs_rad": math.inf}
    diff = x1 - ref_x1
    scale = float(np.max(np.abs(ref_x1)))
    err_x1 = float(np.max(np.abs(diff))) / scale if scale > 0 else math.nan
    err_dc = None
    if seq.n_pulses:
        b = seq.pulse_bounds
        c_ref = ref_x1 + seq.command_motion()
        dc_ref = c_ref[b[1:]] - c_ref[b[:-1]]
        dc_err = diff[b[1:]] - diff[b[:-1]]
        moving = np.abs(dc_ref) > _MOVING_DC_RAD
        if moving.any():
            err_dc = float(np.max(np.abs(dc_err[moving]) / np.abs(dc_ref[moving])))
    error = err_x1 if err_dc is None else err_dc
    return {"error": error, "error_x1": err_x1, "error_dc": err_dc, "error_x1_abs_rad": float(np.max(np.abs(diff)))}


def _log_interp(x: float, x0: float, x1: float, y0: float, y1: float) -> float:
    """y at x on the straight line through (x0, y0), (x1, y1) in log-log."""
    f = (math.log(x) - math.log(x0)) / (math.log(x1) - math.log(x0))
    return math.exp(math.log(y0) + f * (math.log(y1) - math.log(y0)))


def _fixed_step_at(rows: list[dict[str, Any]], target: float) -> dict[str, Any]:
    """Step and wall time at which Euler's error reaches ``target`` (rows coarse to fine).

    The wall time at the needed step is the per-step cost of the nearest finer-or-finest
    measured run times the steps needed (a fixed-step run's cost is linear in its steps).
    """
    pts = [(r["step_s"], r["error"], r["wall_s"]) for r in rows if r["error"] and math.isfinite(r["error"])]
    if len(pts) < 2:
        return {"wall_s": None, "how": "fewer than two finite error points"}
    for i, (h, e, w) in enumerate(pts):
        if e <= target:
            if i == 0:
                return {"wall_s": w, "step_s": h, "how": "reached at the coarsest step (upper bound)"}
            hp, ep, _ = pts[i - 1]
            h_need = _log_interp(target, ep, e, hp, h)
            return {"wall_s": w * h / h_need, "step_s": h_need, "how": "interpolated",
                    "between": [hp, h]}
    (hp, ep, _), (h, e, w) = pts[-2], pts[-1]
    order = math.log(ep / e) / math.log(hp / h)
    if not order > 0.1:
        return {"wall_s": None, "how": f"error does not fall with the step (observed order {order:.2f})"}
    h_need = h * (target / e) ** (1.0 / order)
    return {"wall_s": w * h / h_need, "step_s": h_need, "how": "extrapolated", "order": order, "between": [hp, h],
            "note": "assumes the observed order holds down to the needed step; double-precision "
                    "round-off over that many steps may prevent reaching the target at all, so "
                    "this wall time is a lower bound"}


def _tolerance_at(rows: list[dict[str, Any]], target: float) -> dict[str, Any]:
    """Wall time at which solve_ivp's error reaches ``target`` (rows loose to tight), log-log."""
    pts = [(r["rtol"], r["error"], r["wall_s"]) for r in rows if r["error"] and math.isfinite(r["error"])]
    if not pts:
        return {"wall_s": None, "how": "no finite error points"}
    for i, (tol, e, w) in enumerate(pts):
        if e <= target:
            if i == 0:
                return {"wall_s": w, "rtol": tol, "how": "reached at the loosest rtol (upper bound)"}
            tp, ep, wp = pts[i - 1]
            return {"wall_s": _log_interp(target, ep, e, wp, w), "rtol": _log_interp(target, ep, e, tp, tol),
                    "how": "interpolated", "between": [tp, tol]}
    if len(pts) < 2:
        return {"wall_s": None, "how": "target not reached"}
    (tp, ep, wp), (tol, e, w) = pts[-2], pts[-1]
    if not e < ep:
        return {"wall_s": None, "how": "target not reached and error no longer falls"}
    return {"wall_s": _log_interp(target, ep, e, wp, w), "how": "extrapolated", "between": [tp, tol]}


def _ratio(wall: float | None, exact_wall: float) -> float | None:
    return None if wall is None else wall / exact_wall


def _lower_bound(fixed_rows: list[dict[str, Any]], probe: dict[str, Any] | None, exact_wall: float,
                 T: float) -> dict[str, Any]:
    """No extrapolation: the finest measured step that still misses the target, costed over the window."""
    finest = fixed_rows[-1]
    per_step = finest["wall_s"] / finest["n_steps"]
    misses = [(r["step_s"], r["error_dc"] if r.get("error_dc") is not None else r["error"], "full window")
              for r in fixed_rows]
    misses += [(r["step_s"], r["error_dc"], f"probe, {probe['n_pulses']} pulses")
               for r in (probe or {}).get("rows", [])]
    misses = [m for m in misses if m[1] is not None and m[1] > TARGET_ERROR]
    if not misses:
        return {"speedup": None, "how": "every measured step reaches the target"}
    h, e, where = min(misses)
    wall = per_step * T / h
    return {"speedup": wall / exact_wall, "wall_s": wall, "step_s": h, "error": e, "where": where,
            "how": f"at h={h:g} s the error is still {e:.3g} ({where}), so fixed-step needs a smaller step: "
                   f"at least {T / h:.3g} steps at the full run's {per_step * 1e9:.3g} ns per step"}
