"""``solnic-modern``: the solnic structure with estimators that are honest about friction noise.

Same family ("solnic"), same presets (``thesis``, ``high-error-cost``), same knob (a_c); the
options differ from the faithful defaults only in the flags of
:class:`~controllers.solnic.options.SolnicOptions` listed in :data:`MODERN_FLAGS`, chosen by
measurement (README, "solnic-modern"; tuned on seeds 100–109, reported on 0–9):

* ``motion_decision="three-way"``: moved / no motion only when the 0.98 test had power against
  the predicted Δc / undecided (schedule kept, no k̂ update), at most ``max_undecided_cycles``
  undecided cycles in a row;
* ``noise_aware_model``: Δc_p carries the w2 bias and variance over the moving time
  (:mod:`controllers.solnic.noise_model`), in the trigger, in (5-6)/(5-9) and in the friction
  filter's R;
* ``dc_measurement="data-only"``: the friction filter gets the samples' own evidence (no double
  use of the prediction);
* ``friction_constraints="distribution"`` and ``censored_no_motion``: constraints and "no
  motion" condition N(k̂, P_b) instead of clipping the mean.
"""

from __future__ import annotations

import dataclasses
import types

from controllers.base import register
from controllers.solnic.controller import SolnicController
from controllers.solnic.options import PRESETS

__all__ = ["SolnicModernController", "MODERN_FLAGS"]

MODERN_FLAGS = types.MappingProxyType(dict(
    motion_decision="three-way",
    noise_aware_model=True,
    dc_measurement="data-only",
    friction_constraints="distribution",
    censored_no_motion=True,
))


@register("solnic-modern")
class SolnicModernController(SolnicController):
    """:class:`SolnicController` with :data:`MODERN_FLAGS` on (see the module docstring)."""

    description = "solnic-modern: solnic with noise-aware, consistent estimators"
    presets = types.MappingProxyType({name: dataclasses.replace(o, **MODERN_FLAGS)
                                      for name, o in PRESETS.items()})
