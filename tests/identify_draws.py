"""Random axes for the identification studies (tests/test_identify*.py), one function per family.

The region is stated. It was chosen to make each family's extra law large (meant to be
distinguishable). On the default plan with Table 2-1 friction noise the laws leave a trace far
above the noise at the region's points measured (noise-free distance to the best multimode fit,
Mahalanobis against the friction noise, summed over moves: 3e3–5e6 for stribeck and lugre, 4e2–6e2 for
two-mass, seed 4242); the held-out output-error rule could not use it, the predictive one of
issue 25's fourth session mostly does; docs/axis.md has the measurement:

* core (every family): k̄c ∈ [0.9, 1.6], k̄s/k̄c ∈ [1.2, 1.6], J ∈ [0.3, 0.9], τ3 ∈ [6, 11] ms;
* stribeck: v_s ∈ [10, 30] mrad/s (pulses slide near k̄s; v_s ≪ 4 mrad/s is multimode), b ∈ [0.5, 2];
* lugre: σ0 ∈ [1e5, 3e5] ozf·in/rad (pre-sliding k̄s/σ0 = 4–25 µrad ≫ σ1 = 5 µrad), v_s ∈ [4, 10] mrad/s;
* two-mass: k_sh ∈ [1e4, 2.5e4] ozf·in/rad (shaft resonance 70–115 Hz, J_m = 0.05).
"""

from __future__ import annotations

from plant.protocol import get_family

__all__ = ["draw", "REGION"]

REGION = __doc__.split("docs/axis.md has the measurement:")[1].strip()


def draw(family: str, rng):
    """The family's Params at one random point of the stated region (Table 2-1 noise)."""
    kc = rng.uniform(0.9, 1.6)
    fields = dict(coulomb=kc, stiction=kc * rng.uniform(1.2, 1.6), inertia=rng.uniform(0.3, 0.9),
                  motor_time_constant=rng.uniform(0.006, 0.011))
    if family == "stribeck":
        fields.update(stribeck_velocity=rng.uniform(0.01, 0.03), viscous=rng.uniform(0.5, 2.0))
    elif family == "lugre":
        fields.update(bristle_stiffness=rng.uniform(1e5, 3e5), stribeck_velocity=rng.uniform(0.004, 0.01))
    elif family == "two-mass":
        fields.update(shaft_stiffness=rng.uniform(1e4, 2.5e4))
    return get_family(family).Params().replace(**fields)
