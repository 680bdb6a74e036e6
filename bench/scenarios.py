"""Benchmark scenarios: a true plant, the model controllers are told, a run length and a warm-up.

A scenario's **truth** is a plant family (:mod:`plant.protocol`) with its parameters; its
**model** is the :class:`~plant.params.PlantParams` that every controller receives in
``reset`` (default: the truth's own PlantParams fields, so a controller knows the plant
exactly, as in the dissertation); an optional **mismatch** gives per-seed lognormal errors of
the truth around its nominal values: for each listed field with relative standard deviation
s, the truth's value is multiplied by f = exp(σ·z − σ²/2), σ² = ln(1 + s²) (so E f = 1 and
sd f = s), z ~ N(0, 1) drawn from the run seed's own stream (child 4 of
``SeedSequence(seed)``, fields in name order) — the same factors for every controller and on
every executor. A stiction that a draw puts below the Coulomb level is raised to it (ks ≥ kc).

Built in:

* ``thesis`` — Table 2-1 (:class:`~plant.params.PlantParams` defaults), 100 s, warm-up 20 s;
* ``quiet-friction`` — the same with no white friction noise, σ2² = 0;
* ``ratio-2`` — k̄s/k̄c = 2 (stiction 2.8, Coulomb 1.4 ozf·in);
* ``quantized`` — Table 2-1 read through a 1 µrad encoder (``quantization`` = 1e-6 rad);
* ``delayed`` — Table 2-1 with a 2 ms compute delay (``command_delay`` = 2e-3 s, τs = 10 ms);
* ``disturbed`` — Table 2-1 plus an Ornstein–Uhlenbeck torque on the load (SPEC §11), sd
  0.28 ozf·in = 20 % of k̄c, correlation time 20 ms (two samples); the controllers are told
  Table 2-1 (no controller models the disturbance);
* ``mismatch`` — the controllers are told Table 2-1; the truth's k̄c, k̄s, J and τ3 are off
  by a lognormal factor of relative sd 20 % per seed.

A custom scenario is a base scenario plus overrides of the truth (``plant = "family"`` and the
family's fields), of the model and of the mismatch (see :func:`derive_scenario`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from plant.params import PlantParams, as_definition
from plant.protocol import BUILTIN_FAMILIES, DEFAULT_FAMILY, get_family, model_of

__all__ = ["Scenario", "builtin_scenarios", "derive_scenario", "SCENARIO_KEYS", "mismatch_factors"]

# Keys of a custom scenario that are not plant fields (``model`` and ``mismatch`` are sub-tables).
SCENARIO_KEYS = ("base", "description", "duration_s", "warmup_s", "plant", "model", "mismatch")
_MISMATCH_STREAM = 4      # SeedSequence(seed).spawn(5)[4]; children 0-3 are the runner's
_MAX_MISMATCH = 2.0       # relative standard deviation
# PlantParams fields a controller cannot be wrong about, and why.
_SHARED_EXACTLY = {
    "sample_period": "the controller runs at the plant's sample rate",
    "u_max": "the switched bridge applies the plant's own supply (controllers command ±u_max)",
}


def mismatch_factors(seed: int, mismatch: tuple[tuple[str, float], ...]) -> dict[str, float]:
    """Lognormal factors (mean 1, relative sd s) for ``mismatch`` = ((field, s), ...) at ``seed``."""
    if not mismatch:
        return {}
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(_MISMATCH_STREAM + 1)[_MISMATCH_STREAM])
    z = rng.standard_normal(len(mismatch))
    out = {}
    for (name, rel), zi in zip(mismatch, z):
        var = math.log1p(rel * rel)
        out[name] = math.exp(math.sqrt(var) * float(zi) - 0.5 * var)
    return out


@dataclass(frozen=True)
class Scenario:
    """A true plant, its model, and how long to run it.

    Attributes
    ----------
    name : str
        Scenario name (part of the cell id).
    params : PlantParams
        The true plant's parameters (an instance of its family's ``Params``).
    duration_s : float
        Simulated length of a run [s].
    warmup_s : float
        Start of the scoring window [s], in [0, duration_s).
    description : str
        One line for ``solnic-bench list``.
    base : str
        The built-in scenario this one derives from (its own name for a built-in).
    family : str
        The true plant's family (registered in :mod:`plant.protocol`).
    model : PlantParams or None
        What controllers are told; None means the truth's own PlantParams fields.
    mismatch : tuple of (field, relative sd)
        Per-seed lognormal errors of the truth (module docstring), sorted by field.
    """

    name: str
    params: PlantParams
    duration_s: float
    warmup_s: float
    description: str = ""
    base: str = ""
    family: str = DEFAULT_FAMILY
    model: PlantParams | None = None
    mismatch: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        for field in ("duration_s", "warmup_s"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"Scenario.{field} must be a finite number, got {value!r}")
            object.__setattr__(self, field, float(value))
        if not self.duration_s >= self.params.sample_period:
            raise ValueError(f"Scenario.duration_s must be at least one sample period "
                             f"({self.params.sample_period!r} s), got {self.duration_s!r}")
        if not 0 <= self.warmup_s < self.duration_s:
            raise ValueError(f"Scenario.warmup_s must be in [0, duration_s = {self.duration_s!r}), "
                             f"got {self.warmup_s!r}")
        if not self.base:
            object.__setattr__(self, "base", self.name)
        family = get_family(self.family)
        if not isinstance(self.params, family.Params):
            raise ValueError(f"Scenario.params must be {family.Params.__name__} for plant family "
                             f"{self.family!r}, got {type(self.params).__name__}")
        if self.model is not None:
            if type(self.model) is not PlantParams:
                raise ValueError(f"Scenario.model must be a PlantParams, got {type(self.model).__name__}")
            for name in _SHARED_EXACTLY:
                if getattr(self.model, name) != getattr(self.params, name):
                    raise ValueError(f"Scenario.model.{name} must equal the truth's ({getattr(self.params, name)!r}), "
                                     f"got {getattr(self.model, name)!r}: {_SHARED_EXACTLY[name]}")
            if self.model == model_of(self.params):
                object.__setattr__(self, "model", None)    # one spelling of "the model is the truth"
        fields = {f.name for f in dataclasses.fields(self.params)}
        for name, rel in self.mismatch:
            if name in _SHARED_EXACTLY:
                raise ValueError(f"Scenario.mismatch.{name}: cannot differ from the model: {_SHARED_EXACTLY[name]}")
            if name not in fields or not isinstance(getattr(self.params, name), (int, float)) \
                    or isinstance(getattr(self.params, name), bool):
                raise ValueError(f"Scenario.mismatch.{name}: not a numeric field of {type(self.params).__name__}")
            if isinstance(rel, bool) or not isinstance(rel, (int, float)) or not 0 <= rel <= _MAX_MISMATCH:
                raise ValueError(f"Scenario.mismatch.{name}: relative standard deviation must be in "
                                 f"[0, {_MAX_MISMATCH}], got {rel!r}")
        object.__setattr__(self, "mismatch", tuple(sorted((n, float(r)) for n, r in self.mismatch)))

    @property
    def default_plant(self) -> bool:
        """True when the truth is Acker's plant, the model is the truth and nothing is mismatched."""
        return self.family == DEFAULT_FAMILY and self.model is None and not self.mismatch

    def model_params(self) -> PlantParams:
        """What controllers are told."""
        return model_of(self.params) if self.model is None else self.model

    def realise(self, seed: int) -> tuple[PlantParams, dict[str, float]]:
        """(the truth of the run with ``seed``, its mismatch factors by field)."""
        factors = mismatch_factors(seed, self.mismatch)
        if not factors:
            return self.params, {}
        p = self.params
        changes = {name: getattr(p, name) * f for name, f in factors.items()}
        kc = changes.get("coulomb", p.coulomb)
        if changes.get("stiction", p.stiction) < kc:
            changes["stiction"] = kc                    # ks ≥ kc (module docstring)
        return dataclasses.replace(p, **changes), factors

    def with_durations(self, duration_s: float | None = None, warmup_s: float | None = None) -> "Scenario":
        """A copy with the run length and/or warm-up replaced (validated)."""
        changes: dict[str, Any] = {}
        if duration_s is not None:
            changes["duration_s"] = duration_s
        if warmup_s is not None:
            changes["warmup_s"] = warmup_s
        return dataclasses.replace(self, **changes) if changes else self

    def definition(self) -> dict[str, Any]:
        """What determines a run of this scenario, as plain JSON data. The family, model and
        mismatch appear only when they differ from the default plant, so that a scenario of
        Acker's plant keeps the definition (and the cell hashes) it always had; likewise an option
        added later (``quantization``, ``command_delay``) appears only when it is on."""
        out: dict[str, Any] = {"name": self.name, "base": self.base, "plant": as_definition(self.params)}
        if self.family != DEFAULT_FAMILY:
            out["family"] = self.family
        if self.model is not None:
            out["model"] = as_definition(self.model)
        if self.mismatch:
            out["mismatch"] = dict(self.mismatch)
        return out

    def to_json(self) -> dict[str, Any]:
        out = {"base": self.base, "description": self.description, "duration_s": self.duration_s,
               "warmup_s": self.warmup_s, **self.definition()}
        del out["name"]
        return out


def builtin_scenarios() -> dict[str, Scenario]:
    """The built-in scenarios by name."""
    table = PlantParams()
    return {
        "thesis": Scenario("thesis", table, 100.0, 20.0,
                           "Table 2-1, the initial estimates of section 7.3"),
        "quiet-friction": Scenario("quiet-friction", table.replace(friction_noise_psd=0.0), 100.0, 20.0,
                                   "Table 2-1 without white friction noise (σ2 = 0)"),
        "ratio-2": Scenario("ratio-2", table.replace(stiction=2.8, coulomb=1.4), 100.0, 20.0,
                            "k̄s/k̄c = 2 (stiction 2.8, Coulomb 1.4 ozf·in)"),
        "quantized": Scenario("quantized", table.replace(quantization=1e-6), 100.0, 20.0,
                              "Table 2-1 read through a 1 µrad encoder (quantization 1e-6 rad)"),
        "delayed": Scenario("delayed", table.replace(command_delay=2e-3), 100.0, 20.0,
                            "Table 2-1 with a 2 ms compute delay: each command acts 2 ms after its sample (τs 10 ms)"),
        "disturbed": Scenario("disturbed", table.replace(disturbance_torque_std=0.28, disturbance_torque_tau=0.02),
                              100.0, 20.0,
                              "a gimbal's cable and bearing torque noise: an Ornstein-Uhlenbeck load torque, "
                              "sd 0.28 ozf·in (20 % of k̄c), correlation time 20 ms; controllers told Table 2-1",
                              model=table),
        "mismatch": Scenario("mismatch", table, 100.0, 20.0,
                             "controllers told Table 2-1; the true k̄c, k̄s, J, τ3 off by lognormal 20 % per seed",
                             mismatch=(("coulomb", 0.2), ("stiction", 0.2), ("inertia", 0.2),
                                       ("motor_time_constant", 0.2))),
        **_family_scenarios(table),
    }


def _family_scenarios(table: PlantParams) -> dict[str, Scenario]:
    """The scenarios the built-in families contribute (``PlantFamily.scenarios``): Table 2-1 in the
    family's law, with the family's fields at their defaults except those the scenario sets."""
    shared = dataclasses.asdict(table)
    return {name: Scenario(name, get_family(family).Params(**shared).replace(**fields), 100.0, 20.0, story,
                           family=family)
            for family in BUILTIN_FAMILIES for name, (fields, story) in get_family(family).scenarios.items()}


def derive_scenario(name: str, base: Scenario, overrides: dict[str, Any]) -> Scenario:
    """``base`` with overrides: ``plant`` (a family name), the truth's fields, ``model`` (a dict of
    PlantParams fields, applied to the base's model), ``mismatch`` (field → relative sd,
    replacing the base's), and ``duration_s``/``warmup_s``/``description``.

    A new family keeps the base's PlantParams fields and takes its own fields' defaults.

    Raises
    ------
    ValueError
        Naming the field (``PlantParams.<field> ...``, ``<Family>Params.<field> ...`` or
        ``Scenario.<field> ...``) or the unknown key.
    """
    plant = {k: v for k, v in overrides.items() if k not in SCENARIO_KEYS}
    family_name = overrides.get("plant", base.family)
    if not isinstance(family_name, str):
        raise ValueError(f"Scenario.plant must name a plant family, got {family_name!r}")
    family = get_family(family_name)
    if family_name != base.family:
        shared = {f.name: getattr(base.params, f.name) for f in dataclasses.fields(PlantParams)}
        params = family.Params(**shared).replace(**plant)
    else:
        params = base.params.replace(**plant) if plant else base.params
    model = base.model
    if "model" in overrides:
        changes = overrides["model"]
        if not isinstance(changes, dict):
            raise ValueError(f"Scenario.model must be a table of PlantParams fields, got {changes!r}")
        start = model_of(params) if base.model is None else base.model   # the truth's fields by default
        model = start.replace(**changes)
    mismatch = base.mismatch
    if "mismatch" in overrides:
        table = overrides["mismatch"]
        if not isinstance(table, dict):
            raise ValueError(f"Scenario.mismatch must be a table of field = relative sd, got {table!r}")
        mismatch = tuple(table.items())
    if "description" in overrides:
        description = overrides["description"]
    elif plant:
        description = f"{base.name} with " + ", ".join(f"{k} = {v!r}" for k, v in sorted(plant.items()))
    else:
        description = base.description
    if not isinstance(description, str):
        raise ValueError(f"Scenario.description must be a string, got {description!r}")
    return Scenario(name, params, overrides.get("duration_s", base.duration_s),
                    overrides.get("warmup_s", base.warmup_s), description, base.base, family_name, model, mismatch)
