"""The families ``identify`` can fit and the fields it fits beyond k̄c, k̄s, J and τ3 (a light
module: the CLI reads it for ``--family``'s help without importing scipy)."""

from __future__ import annotations

__all__ = ["FAMILY_FREE", "NOT_IDENTIFIED_RULE", "DEFAULT_BUDGET_S"]

# A fitted field is marked "not identified" when its 95 % interval reaches 0 (AxisFit.not_identified).
NOT_IDENTIFIED_RULE = ("not identified: the 95 % interval is wider than the estimate on either side "
                       "(half-width ≥ |estimate|, so it reaches 0), or not finite")
DEFAULT_BUDGET_S = 300.0   # nominal CPU seconds of counted simulation work for the final fit (point fit and bootstrap)

# The fitted fields of each family beyond k̄c, k̄s, J, τ3 (fields the plan excites).
FAMILY_FREE: dict[str, tuple[str, ...]] = {
    "multimode": (),
    "stribeck": ("stribeck_velocity", "viscous"),
    "lugre": ("stribeck_velocity", "bristle_stiffness"),
    "two-mass": ("shaft_stiffness",),
}
