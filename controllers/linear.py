"""Lag-compensated linear controller, ``linear`` (SPEC §4, section 2.2).

A sampled-data lead/lag design on the *discretized* loop. The plant
from drive level u [ozf·in] to shaft angle c [rad] is

    G(s) = 1/(τ3·s + 1) · 1/(J·s²)

(motor lag, then pure inertia), discretized with a zero-order hold at τs. The runner applies the
command computed from y(n·τs) over [n·τs, (n+1)·τs), so the loop has no computation delay beyond
the ZOH and none is modelled. The compensator acts on the measured error y = x1 + w1 [rad]:

    u(n) = −C(z)·y(n),   C(z) = K · Π lead_i(z) · lag(z)

* ``lead_i`` — identical lead stages (1 + s/ωl)/(1 + s/ωh), ωl·ωh = ωc², each giving at most
  ``max_lead_phase_deg`` of phase at ωc; together they place the phase margin at ωc exactly.
* ``lag`` — (s + ωz)/(s + ωz/L): DC gain L, unit high-frequency gain, upper corner
  ωz = ``lag_corner_fraction``·ωc. L defaults to the Bohacek–Tuteur limit
  Lmax = 2k̄s/(k̄s − k̄c)  (2-1). ``integral=True`` replaces it by the pure integral (s + ωz)/s.
  When k̄s = k̄c, Lmax is infinite and the default is the finite cap :data:`LAG_RATIO_CAP`.
* Every section is discretized by Tustin's method prewarped at ωc, so its phase at ωc is the
  continuous one exactly; K then puts the discrete gain crossover at ωc.

The default crossover is the highest ωc that :func:`highest_crossover` finds feasible: phase
margin ≥ target, gain margin ≥ 6 dB, at most two lead stages, no negative-real (sign-alternating)
compensator pole, and an RMS drive noise from w1 ≤ 5 % of u_max. For Table 2-1 the gain margin
— that is, the sample rate — is the binding limit; the measurement noise is far from it.

Every number of a design (the ZOH plant, the Tustin sections, K, the margins) is computed by
:mod:`controllers.discrete_tf` in closed forms and fixed-order float sums, not by python-control
or BLAS/LAPACK, so a design has the same bits on every machine (python-control only holds the
transfer functions; ``np.roots`` decides the stability flag alone). The H2 noise figures are
integrated on a grid with numpy.
"""

from __future__ import annotations

import cmath
import dataclasses
import functools
import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
import scipy.integrate

from controllers.base import Controller, register
from controllers.discrete_tf import margins, poly_add, poly_eval, poly_mul, tustin_first_order, zoh_gimbal
from controllers.law import LinearLaw
from plant.drive import DriveCommand, DriveType
from plant.linear_drive import compensator_step as _compensate
from plant.params import PlantParams


class _Control:
    """python-control, imported on first use: it costs ~1 s (scipy.signal, matplotlib) that a
    process which never designs a linear controller (a CLI error, a plugin-only matrix) saves."""

    def __getattr__(self, name: str) -> Any:
        import control

        return getattr(control, name)


ct = _Control()

__all__ = ["LAG_RATIO_CAP", "compensator_step", "LinearDesign", "design_linear", "highest_crossover", "LinearOptions",
           "LinearController"]

#: Lag ratio used when Lmax = 2k̄s/(k̄s − k̄c) is infinite (k̄s = k̄c): any ratio is allowed by
#: (2-1) then, and 10 keeps the lag network's phase cost and wind-up time moderate.
LAG_RATIO_CAP = 10.0

_MIN_GAIN_MARGIN_DB = 6.0
_MAX_LEAD_STAGES = 2
_MAX_NOISE_DRIVE_FRACTION = 0.05  # RMS drive noise from w1, as a fraction of u_max


@dataclass(frozen=True, eq=False)
class LinearDesign:
    """A discrete lead/lag design and its loop properties.

    Attributes
    ----------
    params : PlantParams
        The plant it was designed for.
    crossover_target_rad_s : float
        Requested gain-crossover frequency ωc [rad/s].
    lag_ratio : float
        Lag corner ratio L (``inf`` for the pure integral).
    integral : bool
        Whether the lag network is the pure integral (s + ωz)/s.
    lag_corner_rad_s : float
        Upper lag corner ωz [rad/s].
    lead_stages : int
        Number of identical lead stages.
    lead_ratio : float
        Pole/zero ratio a = ωh/ωl of each lead stage.
    gain : float
        K [ozf·in/rad].
    plant : control.TransferFunction
        ZOH-discretized plant Pd(z), u [ozf·in] → c [rad].
    sections : tuple of control.TransferFunction
        Discrete unit-gain sections; ``compensator = gain · Π sections``.
    compensator : control.TransferFunction
        C(z); the drive level is u(n) = −C(z)·y(n) [ozf·in per rad].
    open_loop : control.TransferFunction
        C(z)·Pd(z).
    crossover_rad_s, phase_margin_deg : float
        Gain crossover [rad/s] and phase margin [deg] of the discrete loop
        (control.stability_margins, worst crossover).
    gain_margin_db : float
        Gain increase to instability [dB], at ``phase_crossover_rad_s`` (inf when none).
    phase_crossover_rad_s : float
        Frequency of the gain margin [rad/s] (nan when none).
    gain_reduction_margin_db : float
        Gain decrease to instability [dB, negative] of the conditionally stable loop
        (nan when none).
    static_stiffness : float
        |C(z=1)|, drive torque per rad of steady error [ozf·in/rad] (inf for the integral).
    closed_loop_poles : numpy.ndarray
        Roots of the characteristic polynomial of 1 + C·Pd.
    stable : bool
        All closed-loop poles strictly inside the unit circle.
    noise_drive_rms : float
        RMS drive level caused by the measurement noise w1 [ozf·in].
    noise_error_rms : float
        RMS shaft error caused by w1 [rad].
    """

    params: PlantParams
    crossover_target_rad_s: float
    lag_ratio: float
    integral: bool
    lag_corner_rad_s: float
    phase_margin_target_deg: float
    lead_stages: int
    lead_ratio: float
    gain: float
    plant: ct.TransferFunction
    sections: tuple
    compensator: ct.TransferFunction
    open_loop: ct.TransferFunction
    crossover_rad_s: float
    phase_margin_deg: float
    gain_margin_db: float
    phase_crossover_rad_s: float
    gain_reduction_margin_db: float
    static_stiffness: float
    closed_loop_poles: np.ndarray
    stable: bool
    noise_drive_rms: float
    noise_error_rms: float

    @functools.cached_property
    def state_space(self) -> tuple[np.ndarray, ...]:
        """(A, B, C, D) realization of C(z) as a cascade of the first-order sections."""
        return _cascade_ss(self.gain, self.sections)

    @property
    def lag_ratio_limit(self) -> float:
        """Lmax = 2k̄s/(k̄s − k̄c)  (2-1)."""
        return self.params.lag_ratio_limit

    def summary(self) -> dict[str, Any]:
        """Design report: crossover, margins, static stiffness, L and the (2-6) bounds."""
        p = self.params
        return {
            "crossover_rad_s": self.crossover_rad_s,
            "phase_margin_deg": self.phase_margin_deg,
            "gain_margin_db": self.gain_margin_db,
            "gain_reduction_margin_db": self.gain_reduction_margin_db,
            "static_stiffness": self.static_stiffness,
            "lag_ratio": self.lag_ratio,
            "lag_ratio_limit": p.lag_ratio_limit,
            "integral": self.integral,
            "lead_stages": self.lead_stages,
            "lead_ratio": self.lead_ratio,
            "lag_corner_rad_s": self.lag_corner_rad_s,
            "gain": self.gain,
            "stable": self.stable,
            "noise_drive_rms": self.noise_drive_rms,
            "noise_error_rms_rad": self.noise_error_rms,
            "bound_at_crossover_rad": p.classical_bound(self.crossover_target_rad_s),  # (2-6)
            "bound_at_nyquist_rad": p.classical_bound(),
        }


def _eval_tf(sys: ct.TransferFunction, z: complex | np.ndarray) -> complex | np.ndarray:
    """H(z): Horner in Python complex for a scalar z (the bits every design number depends on,
    :func:`controllers.discrete_tf.poly_eval`), numpy's polyval on an array (the H2 grid)."""
    num, den = sys.num[0][0], sys.den[0][0]
    if np.ndim(z) == 0:
        z = complex(z)
        return poly_eval(num, z) / poly_eval(den, z)
    return np.polyval(num, z) / np.polyval(den, z)


def _tf(num, den, tau_s: float) -> ct.TransferFunction:
    return ct.tf(list(num), list(den), tau_s)


@functools.lru_cache(maxsize=64)
def _discrete_plant(params: PlantParams) -> ct.TransferFunction:
    """Pd(z): G(s) = 1/((τ3 s + 1)·J s²), motor lag then pure inertia (figure 2-1), behind a
    zero-order hold, in closed form (:func:`controllers.discrete_tf.zoh_gimbal`)."""
    return _tf(*zoh_gimbal(params.inertia, params.motor_time_constant, params.sample_period), params.sample_period)


def _plant_phase(plant: ct.TransferFunction, omega: float, tau_s: float) -> float:
    """Unwrapped phase of Pd(e^{jωτs}) [rad], on the branch that starts at −π at low ω: the
    branch counted on a grid, the value from the scalar response at ω."""
    w = np.linspace(omega * 1e-3, omega, 2048)
    ph = np.unwrap(np.angle(_eval_tf(plant, np.exp(1j * w * tau_s))))
    end = cmath.phase(_eval_tf(plant, cmath.exp(1j * omega * tau_s)))
    turns = round((float(ph[-1]) - end) / (2 * math.pi)) - round((float(ph[0]) + math.pi) / (2 * math.pi))
    return end + 2 * math.pi * turns


def _tustin(num: list[float], den: list[float], tau_s: float, omega: float) -> ct.TransferFunction:
    return _tf(*tustin_first_order(num, den, tau_s, omega), tau_s)


def _cascade_ss(gain: float, sections: tuple) -> tuple[np.ndarray, ...]:
    """(A, B, C, D) of gain·Π sections, realised as a cascade of first-order blocks."""
    sys = ct.ss(ct.tf([gain], [1.0], sections[0].dt))
    for sec in sections:
        sys = ct.series(sys, ct.ss(sec))
    return tuple(np.array(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))


def _h2_norm(sys: ct.TransferFunction, n_grid: int = 1 << 14) -> float:
    """Discrete H2 norm √Σh(n)² = √((1/π)∫₀^π |H(e^{jθ})|² dθ) (Parseval), for a stable H."""
    theta = np.linspace(0.0, np.pi, n_grid + 1)
    power = np.abs(_eval_tf(sys, np.exp(1j * theta))) ** 2
    return float(np.sqrt(scipy.integrate.simpson(power, x=theta) / np.pi))


def _margins(open_loop: ct.TransferFunction) -> dict[str, float]:
    """Phase margin (worst gain crossover), upper gain margin and gain-reduction margin.

    A lag network on a double integrator makes the loop conditionally stable: the phase dips
    below −180° under ωc, so reducing the gain also destabilises it. python-control's default
    reports the smallest gain ratio, which is that lower margin; both are reported here.
    """
    gm, pm, w_pc, w_gc = (np.asarray(a, dtype=float) for a in
                          margins(open_loop.num[0][0], open_loop.den[0][0], open_loop.dt))
    if pm.size == 0:
        return dict(crossover_rad_s=math.nan, phase_margin_deg=math.nan, gain_margin_db=math.nan,
                    phase_crossover_rad_s=math.nan, gain_reduction_margin_db=math.nan)
    i = int(np.argmin(pm))
    w_c = float(w_gc[i])
    upper = (w_pc > w_c) & (gm > 0)
    lower = (w_pc < w_c) & (gm > 1e-9)  # gm ≈ 0 entries are the ω → 0 limit of the 1/s² plant
    j = int(np.argmin(np.where(upper, gm, np.inf))) if upper.any() else -1
    return dict(
        crossover_rad_s=w_c, phase_margin_deg=float(pm[i]),
        gain_margin_db=float(20 * np.log10(gm[j])) if j >= 0 else math.inf,
        phase_crossover_rad_s=float(w_pc[j]) if j >= 0 else math.nan,
        gain_reduction_margin_db=float(20 * np.log10(gm[lower].max())) if lower.any() else math.nan)


def _check_options(params: PlantParams, crossover: float | None, lag_ratio: float | None,
                   phase_margin_deg: float, lag_corner_fraction: float,
                   max_lead_phase_deg: float, integral: bool) -> None:
    nyquist = math.pi / params.sample_period
    if crossover is not None and not (0 < crossover < nyquist):
        raise ValueError(f"crossover must be in (0, π/τs = {nyquist:.6g}) rad/s, got {crossover!r}")
    if lag_ratio is not None:
        if integral:
            raise ValueError("lag_ratio must be None when integral=True (the ratio is infinite)")
        if not (math.isfinite(lag_ratio) and lag_ratio >= 1):
            raise ValueError(f"lag_ratio must be a finite number >= 1, got {lag_ratio!r}")
    if not (0 < phase_margin_deg < 90):
        raise ValueError(f"phase_margin_deg must be in (0, 90), got {phase_margin_deg!r}")
    if not (0 < lag_corner_fraction < 1):
        raise ValueError(f"lag_corner_fraction must be in (0, 1), got {lag_corner_fraction!r}")
    if not (0 < max_lead_phase_deg < 90):
        raise ValueError(f"max_lead_phase_deg must be in (0, 90), got {max_lead_phase_deg!r}")


def design_linear(params: PlantParams, crossover: float | None = None,
                  lag_ratio: float | None = None, *, integral: bool = False,
                  phase_margin_deg: float = 45.0, lag_corner_fraction: float = 0.1,
                  max_lead_phase_deg: float = 60.0) -> LinearDesign:
    """Lead/lag design on the ZOH-discretized loop (cached; the result is immutable).

    Parameters
    ----------
    params : PlantParams
        The plant.
    crossover : float, optional
        Gain-crossover frequency ωc [rad/s]; default :func:`highest_crossover`.
    lag_ratio : float, optional
        Lag corner ratio L ≥ 1; default Lmax (2-1), or :data:`LAG_RATIO_CAP` when Lmax = inf.
    integral : bool
        Use the pure integral (s + ωz)/s instead of a lag network.
    phase_margin_deg : float
        Phase margin placed at ωc [deg].
    lag_corner_fraction : float
        Upper lag corner ωz as a fraction of ωc.
    max_lead_phase_deg : float
        Most phase one lead stage may add [deg]; the stage count follows.

    Raises
    ------
    ValueError
        On an option out of range, or an ωc that needs more than four lead stages.
    """
    _check_options(params, crossover, lag_ratio, phase_margin_deg, lag_corner_fraction,
                   max_lead_phase_deg, integral)
    if crossover is None:
        crossover = highest_crossover(params, lag_ratio, integral=integral,
                                      phase_margin_deg=phase_margin_deg,
                                      lag_corner_fraction=lag_corner_fraction,
                                      max_lead_phase_deg=max_lead_phase_deg)
    if lag_ratio is None and not integral:
        limit = params.lag_ratio_limit
        lag_ratio = LAG_RATIO_CAP if math.isinf(limit) else limit
    return _design(params, float(crossover), math.inf if integral else float(lag_ratio),
                   bool(integral), float(phase_margin_deg), float(lag_corner_fraction),
                   float(max_lead_phase_deg))


@functools.lru_cache(maxsize=512)
def _design(params: PlantParams, omega_c: float, lag_ratio: float, integral: bool,
            pm_deg: float, lag_corner_fraction: float, max_lead_phase_deg: float) -> LinearDesign:
    tau_s = params.sample_period
    z_c = cmath.exp(1j * omega_c * tau_s)
    plant = _discrete_plant(params)

    omega_z = lag_corner_fraction * omega_c
    lag_den = [1.0, 0.0] if integral else [1.0, omega_z / lag_ratio]
    lag = _tustin([1.0, omega_z], lag_den, tau_s, omega_c)  # DC gain L, HF gain 1

    # lead phase that puts ∠(C·Pd) = −180° + PM at ωc
    need = (-math.pi + math.radians(pm_deg) - _plant_phase(plant, omega_c, tau_s)
            - cmath.phase(_eval_tf(lag, z_c)))
    stages = max(1, math.ceil(need / math.radians(max_lead_phase_deg) - 1e-12))
    if need <= 0 or stages > 4:
        raise ValueError(f"crossover {omega_c!r} rad/s needs {math.degrees(need):.1f}° of lead; "
                         "choose a lower crossover")
    phi = need / stages
    a = (1 + math.sin(phi)) / (1 - math.sin(phi))  # lead ratio for maximum phase φ at ωc
    lead = _tustin([1.0 / (omega_c / math.sqrt(a)), 1.0], [1.0 / (omega_c * math.sqrt(a)), 1.0],
                   tau_s, omega_c)
    sections = (lag,) + (lead,) * stages

    shape_num, shape_den = (1.0,), (1.0,)
    for sec in sections:
        shape_num, shape_den = poly_mul(shape_num, sec.num[0][0]), poly_mul(shape_den, sec.den[0][0])
    pd_c = _eval_tf(plant, z_c)
    gain = 1.0 / abs((poly_eval(shape_num, z_c) / poly_eval(shape_den, z_c)) * pd_c)
    comp_num = tuple(gain * c for c in shape_num)
    comp = _tf(comp_num, shape_den, tau_s)
    p_num, p_den = plant.num[0][0], plant.den[0][0]
    ol_num, ol_den = poly_mul(comp_num, p_num), poly_mul(shape_den, p_den)
    open_loop = _tf(ol_num, ol_den, tau_s)

    loop_margins = _margins(open_loop)
    char = poly_add(ol_den, ol_num)                    # 1 + C·Pd = 0
    poles = np.roots(char)                             # only the stability flag reads them
    stable = bool(np.all(np.abs(poles) < 1.0))
    stiffness = math.inf if integral else float(abs(_eval_tf(comp, 1.0)))
    if stable:   # w1 → u: C/(1 + C·Pd); w1 → c: C·Pd/(1 + C·Pd)
        drive_rms = params.measurement_noise_std * _h2_norm(_tf(poly_mul(comp_num, p_den), char, tau_s))
        error_rms = params.measurement_noise_std * _h2_norm(_tf(ol_num, char, tau_s))
    else:
        drive_rms = error_rms = math.inf
    return LinearDesign(
        params=params, crossover_target_rad_s=omega_c, lag_ratio=lag_ratio, integral=integral,
        lag_corner_rad_s=omega_z, phase_margin_target_deg=pm_deg, lead_stages=stages,
        lead_ratio=a, gain=gain, plant=plant, sections=sections, compensator=comp,
        open_loop=open_loop,
        **loop_margins,
        static_stiffness=stiffness, closed_loop_poles=poles, stable=stable,
        noise_drive_rms=drive_rms, noise_error_rms=error_rms)


def _feasible(params: PlantParams, omega_c: float, lag_ratio: float | None, integral: bool,
              pm_deg: float, lag_corner_fraction: float, max_lead_phase_deg: float,
              min_gain_margin_db: float) -> bool:
    try:
        d = design_linear(params, omega_c, lag_ratio, integral=integral, phase_margin_deg=pm_deg,
                          lag_corner_fraction=lag_corner_fraction,
                          max_lead_phase_deg=max_lead_phase_deg)
    except ValueError:
        return False
    poles = np.concatenate([np.roots(s.den[0][0]) for s in d.sections])
    return (d.stable and d.lead_stages <= _MAX_LEAD_STAGES
            and d.phase_margin_deg >= pm_deg - 1e-6
            and d.gain_margin_db >= min_gain_margin_db
            and bool(np.all(poles.real >= 0))
            and d.noise_drive_rms <= _MAX_NOISE_DRIVE_FRACTION * params.u_max)


# The fields of the plant that highest_crossover's search reads (the loop G(s) = 1/((τ3 s + 1)·J s²)
# sampled at τs, the Bohacek–Tuteur lag ratio, the drive-noise limit): its cache key.
_CROSSOVER_FIELDS = ("inertia", "motor_time_constant", "sample_period", "stiction", "coulomb",
                     "measurement_noise_std", "u_max")


def highest_crossover(params: PlantParams, lag_ratio: float | None = None, *,
                      integral: bool = False, phase_margin_deg: float = 45.0,
                      lag_corner_fraction: float = 0.1, max_lead_phase_deg: float = 60.0,
                      min_gain_margin_db: float = _MIN_GAIN_MARGIN_DB) -> float:
    """Highest feasible ωc [rad/s], to 0.1 rad/s (see the module docstring for the criteria).

    The search (~0.1–0.2 s: some 24 designs) reads only the fields
    :data:`_CROSSOVER_FIELDS` of ``params``; it runs on a :class:`PlantParams` with those fields
    (the rest at their defaults) and is cached on it, so plants that differ elsewhere (friction
    noise, x4, quantization, another family's own fields) share one search per process — the
    same numbers, since nothing else enters (tests/test_linear_design.py compares).

    Raises
    ------
    ValueError
        If no crossover between 1 rad/s and the Nyquist frequency is feasible.
    """
    key = PlantParams(**{name: getattr(params, name) for name in _CROSSOVER_FIELDS})
    return _highest_crossover(key, lag_ratio, integral=integral, phase_margin_deg=phase_margin_deg,
                              lag_corner_fraction=lag_corner_fraction, max_lead_phase_deg=max_lead_phase_deg,
                              min_gain_margin_db=min_gain_margin_db)


@functools.lru_cache(maxsize=64)
def _highest_crossover(params: PlantParams, lag_ratio: float | None = None, *,
                       integral: bool = False, phase_margin_deg: float = 45.0,
                       lag_corner_fraction: float = 0.1, max_lead_phase_deg: float = 60.0,
                       min_gain_margin_db: float = _MIN_GAIN_MARGIN_DB) -> float:
    """:func:`highest_crossover` on ``params`` as given (cached on all of it)."""
    args = (lag_ratio, integral, phase_margin_deg, lag_corner_fraction, max_lead_phase_deg,
            min_gain_margin_db)
    nyquist = math.pi / params.sample_period
    grid = np.geomspace(1.0, 0.99 * nyquist, 12)
    ok = [_feasible(params, float(w), *args) for w in grid]
    if not any(ok):
        raise ValueError("no feasible crossover: relax phase_margin_deg or min_gain_margin_db")
    i = max(k for k, flag in enumerate(ok) if flag)
    if i == len(grid) - 1:
        return float(np.floor(grid[i] * 10) / 10)
    lo, hi = float(grid[i]), float(grid[i + 1])
    while hi - lo > 0.02:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if _feasible(params, mid, *args) else (lo, mid)
    return float(np.floor(lo * 10) / 10)


def _finite(name: str, value: Any, *, allow_none: bool = True) -> None:
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")


@dataclass(frozen=True)
class LinearOptions:
    """Options of :class:`LinearController` (all validated in ``__post_init__``).

    Attributes
    ----------
    crossover : float or None
        Gain-crossover frequency ωc [rad/s], > 0; None (default) is the highest feasible one for
        the plant (:func:`highest_crossover`, 48.7 rad/s for Table 2-1).
    lag_ratio : float or None
        Lag corner ratio L ≥ 1 [–]; None (default) is Lmax = 2k̄s/(k̄s − k̄c)  (2-1).
    phase_margin_deg : float
        Phase-margin target at ωc [deg], in (0, 90); default 45.
    integral : bool
        Pure integral (s + ωz)/s instead of the lag network (then ``lag_ratio`` must be None).
    lag_corner_fraction : float
        Upper lag corner ωz as a fraction of ωc [–], in (0, 1); default 0.1.
    """

    crossover: float | None = None
    lag_ratio: float | None = None
    phase_margin_deg: float = 45.0
    integral: bool = False
    lag_corner_fraction: float = 0.1

    def __post_init__(self) -> None:
        _finite("crossover", self.crossover)
        if self.crossover is not None and self.crossover <= 0:
            raise ValueError(f"crossover must be > 0 rad/s, got {self.crossover!r}")
        _finite("lag_ratio", self.lag_ratio)
        if self.lag_ratio is not None and self.lag_ratio < 1:
            raise ValueError(f"lag_ratio must be >= 1, got {self.lag_ratio!r}")
        _finite("phase_margin_deg", self.phase_margin_deg, allow_none=False)
        if not 0 < self.phase_margin_deg < 90:
            raise ValueError(f"phase_margin_deg must be in (0, 90), got {self.phase_margin_deg!r}")
        if not isinstance(self.integral, bool):
            raise ValueError(f"integral must be a bool, got {self.integral!r}")
        if self.integral and self.lag_ratio is not None:
            raise ValueError("lag_ratio must be None when integral=True (the ratio is infinite)")
        _finite("lag_corner_fraction", self.lag_corner_fraction, allow_none=False)
        if not 0 < self.lag_corner_fraction < 1:
            raise ValueError(f"lag_corner_fraction must be in (0, 1), got {self.lag_corner_fraction!r}")

    def design(self, params: PlantParams) -> LinearDesign:
        """The lead/lag design of these options for ``params`` (cached)."""
        return design_linear(params, self.crossover, self.lag_ratio, integral=self.integral,
                             phase_margin_deg=self.phase_margin_deg,
                             lag_corner_fraction=self.lag_corner_fraction)


_LINEAR_DEFAULTS = LinearOptions()


def compensator_step(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray):
    """``law(x, y) -> (C·x + D·y, A·x + B·y)`` for a single-input single-output realization.

    ``x`` is a sequence of the compensator's state (a tuple of zeros at the start), the new
    state a float64 array. The arithmetic is :func:`plant.linear_drive.compensator_step`'s, the
    code the compiled closed loop runs, so the two give the same bits.
    """
    A, B, C, D = (np.ascontiguousarray(m, dtype=np.float64) for m in (A, B, C, D))
    n = A.shape[0]

    def law(x, y):
        x = np.asarray(x, dtype=np.float64)
        x_next = np.empty(n)
        return _compensate(A, B, C, D, x, x_next, float(y)), x_next

    return law


@register("linear")
class LinearController(Controller):
    """Lag-compensated linear controller on the linear amplifier: u(n) = −C(z)·y(n).

    Options: :class:`LinearOptions` (``LinearController(crossover=30.0)``, a preset, or an
    options object). Presets: ``"integral"`` (pure integral instead of the lag network) and
    ``"no-lag"`` (L = 1, no lag network gain).

    Knobs (:attr:`knobs`): the crossover ωc [rad/s] and the lag ratio L; the swept values span
    the feasible crossovers of Table 2-1 (≤ 48.7 rad/s, the sample-rate limit) and L from 1 to
    above Lmax = 6, the ranges of the inequality check (``solnic-bench check-bound``).
    """

    drive = DriveType.LINEAR
    description = "Lead/lag sampled-data design at the Bohacek–Tuteur lag limit (2-1)"
    Options = LinearOptions
    presets = MappingProxyType({
        "default": _LINEAR_DEFAULTS,
        "integral": dataclasses.replace(_LINEAR_DEFAULTS, integral=True),
        "no-lag": dataclasses.replace(_LINEAR_DEFAULTS, lag_ratio=1.0),
    })
    knobs = MappingProxyType({"crossover": (10.0, 20.0, 30.0, 40.0, 48.0),
                              "lag_ratio": (1.0, 2.0, 4.0, 6.0, 8.0)})

    def __init__(self, options: Any = None, /, *, preset: str | None = None, **fields: Any) -> None:
        super().__init__(options, preset=preset, **fields)
        self.design: LinearDesign | None = None
        self._u_max = math.inf

    def reset(self, params: PlantParams, rng: np.random.Generator) -> None:
        """Design for ``params`` (cached) and zero the compensator state."""
        self.design = self.options.design(params)
        self._law = compensator_step(*self.design.state_space)
        self._x = (0.0,) * self.design.state_space[0].shape[0]
        self._u_max = params.u_max
        self._level = 0.0

    def control_level(self, y: float) -> float:
        """Advance the compensator with y(n) [rad]; the clipped level u(n) [ozf·in].

        u(n) = −(C·x(n) + D·y(n)), x(n+1) = A·x(n) + B·y(n): the realization of C(z).
        """
        if self.design is None:
            raise RuntimeError("LinearController.reset must be called before step")
        u, self._x = self._law(self._x, y)
        self._level = min(max(-u, -self._u_max), self._u_max)
        return self._level

    def step(self, y: float) -> DriveCommand:
        """Hold −C(z)·y(n), clipped to ±u_max, over the next interval."""
        return DriveCommand.hold(self.control_level(y), DriveType.LINEAR)

    def linear_law(self) -> LinearLaw | None:
        """The law of :meth:`step` (None for a subclass that overrides ``step``)."""
        if self.design is None or type(self).step is not LinearController.step:
            return None
        return LinearLaw(*self.design.state_space, u_max=self._u_max)

    def internals(self) -> dict[str, float]:
        return {"u_linear": self._level}

    def summary(self) -> dict[str, Any]:
        return {} if self.design is None else self.design.summary()
