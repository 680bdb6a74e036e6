"""The families ``identify`` can fit and the fields it fits beyond k̄c, k̄s, J and τ3 (a light
module: the CLI reads it for ``--family``'s help without importing scipy)."""

from __future__ import annotations

__all__ = ["FAMILY_FREE"]

# The fitted fields of each family beyond k̄c, k̄s, J, τ3 (fields the plan excites).
FAMILY_FREE: dict[str, tuple[str, ...]] = {
    "multimode": (),
    "stribeck": ("stribeck_velocity", "viscous"),
    "lugre": ("stribeck_velocity", "bristle_stiffness"),
    "two-mass": ("shaft_stiffness",),
}
