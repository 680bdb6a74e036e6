"""PlantParams: Table 2-1 defaults, derived intensities, and validation naming the field."""

import math

import pytest

from plant import PlantParams


def test_derived_intensities_match_table_2_1():
    p = PlantParams()
    assert p.sigma5_sq == pytest.approx(1.8e-4, rel=1e-12)      # Table 2-1: 1.8(10)^-4
    assert p.sigma4_sq == pytest.approx(1.8e-14, rel=1e-12)     # Table 2-1: 1.8(10)^-14
    assert p.sigma2_sq == pytest.approx(0.02**2, rel=1e-12)
    assert p.alpha == 2.0 and p.beta3 == 125.0


def test_bound_and_lag_limit_closed_forms():
    p = PlantParams()
    # (2-6) at ωb = π/τs: (2.1 − 1.4) / (2 · 0.5 · (100π)²)
    assert p.classical_bound() == pytest.approx(0.7 / (2 * 0.5 * (100 * math.pi) ** 2), rel=1e-14)
    assert p.classical_bound() * 1e6 == pytest.approx(7.09, abs=0.005)
    assert p.lag_ratio_limit == pytest.approx(6.0)                    # (2-1)
    assert PlantParams(stiction=2.8).lag_ratio_limit == pytest.approx(4.0)


def test_breakaway_time_closed_form():
    p = PlantParams()
    assert p.breakaway_time == pytest.approx(-8e-3 * math.log(1 - 2.1 / 20), rel=1e-14)
    assert p.breakaway_time * 1e3 == pytest.approx(0.88745, abs=5e-6)


@pytest.mark.parametrize(
    "field, value",
    [("inertia", 0.0), ("inertia", -1.0), ("motor_time_constant", 0.0), ("u_max", 0.0),
     ("sample_period", -0.01), ("coulomb", -0.1), ("stiction", 1.0), ("u_max", 2.0),
     ("friction_noise_psd", -1e-4), ("measurement_noise_std", -1.0), ("correlated_friction_std", -0.3),
     ("command_velocity_std", -1e-6), ("inertia", math.nan), ("u_max", math.inf),
     ("correlated_friction_tau", 0.0)],
)
def test_bad_values_raise_naming_the_field(field, value):
    with pytest.raises(ValueError, match=rf"PlantParams\.{field}"):
        PlantParams(**{field: value})


def test_non_numbers_and_unknown_fields_are_rejected():
    with pytest.raises(ValueError, match="PlantParams.inertia must be a real number"):
        PlantParams(inertia="heavy")
    with pytest.raises(ValueError, match="no field 'mass'"):
        PlantParams().replace(mass=1.0)


def test_with_friction_equals_replace_and_rejects_what_replace_rejects():
    p = PlantParams()
    q = p.with_friction(2.0, 1.2)
    assert q == p.replace(stiction=2.0, coulomb=1.2)
    assert q.kernel_record().tobytes() == p.replace(stiction=2.0, coulomb=1.2).kernel_record().tobytes()
    assert (p.stiction, p.coulomb) == (PlantParams().stiction, PlantParams().coulomb)  # untouched
    for ks, kc in ((1.0, 1.5), (p.u_max, 1.0), (2.0, -0.1), (float("nan"), 1.0)):
        with pytest.raises(ValueError, match="PlantParams"):
            p.with_friction(ks, kc)
