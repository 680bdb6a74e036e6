"""Plant parameters of the gimbal shaft with stiction and Coulomb friction (Table 2-1).

Units follow the dissertation: torque in ozf·in, inertia in ozf·in·s², angles in rad.
The drive voltage ``u`` is normalised by the torque-motor scale factor, so it is stated
in ozf·in as well (section 2.6).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["PlantParams", "KERNEL_RECORD", "PLAUSIBLE", "as_definition", "bohacek_tuteur_limit", "lti_peak_bound"]

# The one parameter record the compiled kernels read (plant.multimode.interval, plant.multimode.reference): a
# numpy structured dtype, so a kernel reads ``prm[0].alpha`` by name and numba dispatches on it
# as fast as on any array. Built once per PlantParams by :meth:`PlantParams.kernel_record`.
KERNEL_RECORD = np.dtype([
    ("alpha", np.float64),       # 1/J  (3-1)
    ("beta3", np.float64),       # 1/τ3 (3-2)
    ("beta4", np.float64),       # 1/τ4 (3-3)
    ("beta5", np.float64),       # 1/τ5 (3-4)
    ("sigma2_sq", np.float64),   # σ2², w2 intensity
    ("sigma4_sq", np.float64),   # σ4² = 2 VAR(x4)/τ4
    ("sigma5_sq", np.float64),   # σ5² = 2 VAR(x5)/τ5
    ("tau3", np.float64),        # τ3 [s]
    ("u_max", np.float64),       # u_max [ozf·in]
    ("coulomb", np.float64),     # k̄c [ozf·in]
    ("stiction", np.float64),    # k̄s [ozf·in]
])


# Plausible ranges [low, high] of each field (checked after the signs): wide enough for any
# precision servo, narrow enough that a run never overflows a float (a drive of 1e308 ozf·in,
# a sample period of 5e-324 s or a noise of 1e200 is a typing error, not a plant).
PLAUSIBLE = {
    "inertia": (1e-9, 1e6, "ozf·in·s²"),
    "motor_time_constant": (1e-7, 10.0, "s"),
    "u_max": (0.0, 1e6, "ozf·in"),
    "coulomb": (0.0, 1e6, "ozf·in"),
    "stiction": (0.0, 1e6, "ozf·in"),
    "sample_period": (1e-6, 10.0, "s"),
    "measurement_noise_std": (0.0, 1.0, "rad"),
    "friction_noise_psd": (0.0, 1e6, "ozf²·in²·s"),
    "correlated_friction_std": (0.0, 1e6, "ozf·in"),
    "correlated_friction_tau": (1e-6, 1e12, "s"),
    "command_velocity_std": (0.0, 1e3, "rad/s"),
    "command_velocity_tau": (1e-6, 1e12, "s"),
    "command_velocity_initial": (-1e3, 1e3, "rad/s"),
    "disturbance_torque_std": (0.0, 1e6, "ozf·in"),
    "disturbance_torque_tau": (0.0, 1e12, "s"),
}


def _require(condition: bool, field: str, message: str) -> None:
    if not condition:
        raise ValueError(f"PlantParams.{field} {message}")


@dataclass(frozen=True)
class PlantParams:
    """Parameters of the multimode plant, figure (2-1) and Table (2-1).

    Attributes
    ----------
    inertia : float
        Load inertia J [ozf·in·s²].
    motor_time_constant : float
        Torque-motor time constant τ3 [s].
    u_max : float
        Maximum drive level, voltage × torque scale [ozf·in].
    coulomb : float
        Mean Coulomb friction k̄c [ozf·in].
    stiction : float
        Mean stiction k̄s [ozf·in].
    sample_period : float
        Sensor sample period τs [s].
    measurement_noise_std : float
        σ1, standard deviation of the position measurement noise w1 [rad per sample].
    friction_noise_psd : float
        σ2², intensity of the white friction-torque noise w2 [ozf²·in²·s].
    correlated_friction_std : float
        √VAR(x5), stationary std of the correlated friction noise x5 [ozf·in].
    correlated_friction_tau : float
        τ5, correlation time of x5 [s].
    command_velocity_std : float
        √VAR(x4), stationary std of the commanded velocity x4 [rad/s].
    command_velocity_tau : float
        τ4, correlation time of x4 [s].
    command_velocity_initial : float
        x4(0) of a benchmark run [rad/s].
    quantization : float
        q, the sensor's resolution: y(n) = q·round((x1(nτs) + w1(n))/q) [rad], ties up
        (:mod:`plant.sensor`); 0 (default) is the ideal sensor of section 2 (SPEC §11).
    command_delay : float
        δ, compute delay: the command computed from y(n) takes effect at nτs + δ and the
        previous one holds until then [s], 0 ≤ δ < τs (:mod:`plant.delay`); 0 (default) is
        section 2 (SPEC §11).

    disturbance_torque_std : float
        Stationary std of the Ornstein–Uhlenbeck torque d on the load [ozf·in], acting in every
        mode: ḋ = −d/τd + √(2/τd)·std·w (SPEC §11; :mod:`plant.multimode.disturbed`); 0
        (default) is section 2.
    disturbance_torque_tau : float
        τd, correlation time of d [s]; > 0 when ``disturbance_torque_std`` > 0 (0 = unset).

    Quantization and delay are options of every family's observation and command path, so a
    controller is told them through its model (and the disturbance with them). The four
    options' ``omit_default`` metadata keeps them out of :func:`as_definition` while off, so a
    run defined before they existed keeps its hash.
    """

    inertia: float = 0.5
    motor_time_constant: float = 8e-3
    u_max: float = 20.0
    coulomb: float = 1.4
    stiction: float = 2.1
    sample_period: float = 0.01
    measurement_noise_std: float = 5e-6
    friction_noise_psd: float = 4e-4
    correlated_friction_std: float = 0.3
    correlated_friction_tau: float = 1000.0
    command_velocity_std: float = 3e-6
    command_velocity_tau: float = 1000.0
    command_velocity_initial: float = 30e-6
    quantization: float = field(default=0.0, metadata={"omit_default": True})
    command_delay: float = field(default=0.0, metadata={"omit_default": True})
    disturbance_torque_std: float = field(default=0.0, metadata={"omit_default": True})
    disturbance_torque_tau: float = field(default=0.0, metadata={"omit_default": True})

    def __post_init__(self) -> None:
        for name in _FIELD_NAMES:
            value = getattr(self, name)
            if type(value) is not float:
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise ValueError(f"PlantParams.{name} must be a real number, got {value!r}")
                value = float(value)
                object.__setattr__(self, name, value)
            if not math.isfinite(value):
                raise ValueError(f"PlantParams.{name} must be finite{_RANGE_HINTS.get(name, '')}, got {value!r}")
        for name in ("inertia", "motor_time_constant", "u_max", "sample_period",
                     "correlated_friction_tau", "command_velocity_tau"):
            _require(getattr(self, name) > 0, name, f"must be > 0, got {getattr(self, name)!r}")
        _require(self.coulomb >= 0, "coulomb", f"must be >= 0, got {self.coulomb!r}")
        _require(self.stiction >= self.coulomb, "stiction",
                 f"must be >= coulomb ({self.coulomb!r}), got {self.stiction!r}")
        _require(self.u_max > self.stiction, "u_max",
                 f"must be > stiction ({self.stiction!r}), got {self.u_max!r}")
        for name in ("measurement_noise_std", "friction_noise_psd", "correlated_friction_std",
                     "command_velocity_std"):
            _require(getattr(self, name) >= 0, name, f"must be >= 0, got {getattr(self, name)!r}")
        _require(self.quantization >= 0, "quantization",
                 f"must be >= 0 rad (0 = ideal sensor), got {self.quantization!r}")
        _require(0 <= self.command_delay < self.sample_period, "command_delay",
                 f"must be in [0, sample_period = {self.sample_period!r}) s (0 = no delay), "
                 f"got {self.command_delay!r}")
        _require(self.disturbance_torque_std >= 0, "disturbance_torque_std",
                 f"must be >= 0 ozf·in (0 = no disturbance torque), got {self.disturbance_torque_std!r}")
        _require(self.disturbance_torque_tau >= 0, "disturbance_torque_tau",
                 f"must be >= 0 s, got {self.disturbance_torque_tau!r}")
        _require(self.disturbance_torque_std == 0 or self.disturbance_torque_tau >= 1e-6, "disturbance_torque_tau",
                 f"must be in [1e-06, 1e+12] s when disturbance_torque_std > 0, got {self.disturbance_torque_tau!r}")
        for name, (low, high, unit) in PLAUSIBLE.items():
            value = getattr(self, name)
            _require(low <= value <= high, name, f"must be in [{low:g}, {high:g}] {unit} (a plausible "
                                                 f"servo), got {value!r}")

    # Derived symbols of chapter 3.
    @property
    def alpha(self) -> float:
        """α = 1/J  (3-1) [rad/s² per ozf·in]."""
        return 1.0 / self.inertia

    @property
    def beta3(self) -> float:
        """β3 = 1/τ3  (3-2) [1/s]."""
        return 1.0 / self.motor_time_constant

    @property
    def beta4(self) -> float:
        """β4 = 1/τ4  (3-3) [1/s]."""
        return 1.0 / self.command_velocity_tau

    @property
    def beta5(self) -> float:
        """β5 = 1/τ5  (3-4) [1/s]."""
        return 1.0 / self.correlated_friction_tau

    @property
    def sigma2_sq(self) -> float:
        """σ2², white friction-noise intensity [ozf²·in²·s]."""
        return self.friction_noise_psd

    @property
    def sigma4_sq(self) -> float:
        """σ4² = 2·VAR(x4)/τ4, intensity of w4 [rad²/s³] (white noise in rad/s², (rad/s²)²·s)."""
        return 2.0 * self.command_velocity_std**2 / self.command_velocity_tau

    @property
    def sigma5_sq(self) -> float:
        """σ5² = 2·VAR(x5)/τ5, intensity of w5 [ozf²·in²/s]."""
        return 2.0 * self.correlated_friction_std**2 / self.correlated_friction_tau

    @property
    def breakaway_time(self) -> float:
        """Noise-free breakaway time from rest under +u_max: −τ3·ln(1 − k̄s/u_max) [s]."""
        return -self.motor_time_constant * math.log1p(-self.stiction / self.u_max)

    @property
    def lag_ratio_limit(self) -> float:
        """Bohacek–Tuteur limit Lmax = 2k̄s/(k̄s − k̄c)  (2-1); inf when k̄s = k̄c."""
        return bohacek_tuteur_limit(self.stiction, self.coulomb)

    def classical_bound(self, bandwidth: float | None = None) -> float:
        """Minimum LTI peak error θe ≥ (k̄s − k̄c)/(2·J·ωb²)  (2-6) [rad].

        ``bandwidth`` is ωb [rad/s]; the default is the Nyquist frequency π/τs used by the
        thesis's "classical limit" (7.09 µrad for Table 2-1).
        """
        omega = math.pi / self.sample_period if bandwidth is None else float(bandwidth)
        if not (omega > 0 and math.isfinite(omega)):
            raise ValueError(f"bandwidth must be a finite positive number, got {bandwidth!r}")
        return lti_peak_bound(self.stiction, self.coulomb, self.inertia, omega)

    def kernel_record(self) -> np.ndarray:
        """The parameters as a one-element :data:`KERNEL_RECORD` array (read-only, cached)."""
        rec = self.__dict__.get("_kernel_record")
        if rec is None:
            rec = np.array([(self.alpha, self.beta3, self.beta4, self.beta5, self.sigma2_sq, self.sigma4_sq,
                             self.sigma5_sq, self.motor_time_constant, self.u_max, self.coulomb,
                             self.stiction)], dtype=KERNEL_RECORD)
            rec.flags.writeable = False
            object.__setattr__(self, "_kernel_record", rec)
        return rec

    def replace(self, **changes: float) -> "PlantParams":
        """A copy with some fields changed; unknown names raise ``ValueError``."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise ValueError(f"PlantParams has no field {unknown[0]!r}; fields are {sorted(names)}")
        return dataclasses.replace(self, **changes)

    def with_friction(self, stiction: float, coulomb: float) -> "PlantParams":
        """``replace(stiction=..., coulomb=...)`` that re-checks only the friction fields.

        The solnic predictor builds a plant per friction estimate (thousands per run); the other
        fields are already valid. Invalid friction falls back to :meth:`replace`, which raises
        the usual error naming the field.
        """
        ks, kc = float(stiction), float(coulomb)
        if not (math.isfinite(ks) and math.isfinite(kc) and 0.0 <= kc <= ks < self.u_max):
            return self.replace(stiction=ks, coulomb=kc)
        new = object.__new__(PlantParams)
        fields = new.__dict__
        mine = self.__dict__
        for name in _FIELD_NAMES:
            fields[name] = mine[name]
        fields["stiction"], fields["coulomb"] = ks, kc
        return new

    def noise_free(self) -> "PlantParams":
        """The same plant with every noise source switched off."""
        return self.replace(measurement_noise_std=0.0, friction_noise_psd=0.0,
                            correlated_friction_std=0.0, command_velocity_std=0.0)


_FIELD_NAMES = tuple(f.name for f in dataclasses.fields(PlantParams))
# The allowed range of an option whose non-finite value is reported (SPEC §11).
_RANGE_HINTS = {"quantization": " and >= 0 rad", "command_delay": " and in [0, sample_period) s",
                "disturbance_torque_std": " and >= 0 ozf·in", "disturbance_torque_tau": " and >= 0 s"}


def as_definition(params: Any) -> dict[str, Any]:
    """The parameters as plain data for a run's definition (and its hash).

    Every field of ``params`` (a :class:`PlantParams` or a family's subclass), except a field
    marked ``omit_default`` (an option added after runs were defined, e.g. ``quantization``)
    while it has its default value: a scenario that does not use the option keeps the
    definition, and so the cell hashes, it had before the option existed.
    """
    out = dataclasses.asdict(params)
    for f in dataclasses.fields(params):
        if f.metadata.get("omit_default") and out[f.name] == f.default:
            del out[f.name]
    return out


def bohacek_tuteur_limit(stiction: float, coulomb: float) -> float:
    """Largest lag ratio without hunting, Lmax = 2k̄s/(k̄s − k̄c)  (2-1) [–]; inf when k̄s = k̄c.

    ``stiction``, ``coulomb`` are k̄s, k̄c [ozf·in] (or any common scale: only k̄s/k̄c matters).
    The single home of (2-1): :attr:`PlantParams.lag_ratio_limit` and the report call it.
    """
    gap = stiction - coulomb
    return math.inf if gap == 0 else 2.0 * stiction / gap


def lti_peak_bound(stiction: float, coulomb: float, inertia: float, bandwidth: float) -> float:
    """Minimum peak error of an LTI loop, θe ≥ (k̄s − k̄c)/(2·J·ωb²)  (2-6) [rad].

    k̄s, k̄c [ozf·in], J [ozf·in·s²], ωb = ``bandwidth`` [rad/s] (not checked here:
    :meth:`PlantParams.classical_bound` checks it). The single home of (2-6).
    """
    return (stiction - coulomb) / (2.0 * inertia * bandwidth**2)
