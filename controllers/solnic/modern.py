"""``solnic-modern``: the solnic structure with estimators that are honest about friction noise.

Same family ("solnic"), same presets (``thesis``, ``high-error-cost``), same knob (a_c); the
options differ from the faithful defaults only in the flags of
:class:`~controllers.solnic.options.SolnicOptions` listed in :data:`MODERN_FLAGS`, chosen by
measurement (thesis and quiet-friction, 100 s scored from 20 s; the first three flags on seeds
100–109, the grid on seeds 0–4) and reported on seeds 0–9 (README, "solnic and solnic-modern"):

* ``friction_estimator="joint-ekf"``: one Gaussian on (x1, x4, k_c, k_s, d)
  (:mod:`controllers.solnic.joint_filter`): the prediction is used once, the friction is
  identified from the samples through the correlation each pulse creates, and the constraints
  act on the distribution. With it the mode-2 NEES on thesis is ≈ 1 (0.61–1.92 on the ten
  tuning seeds); the text's two filters give 3.5–230 with the same other flags;
* ``noise_aware_model``: Δc_p carries the w2 bias and variance over the moving time
  (:mod:`controllers.solnic.noise_model`), in the trigger, in (5-6)/(5-9) and in the costs;
* ``motion_decision="three-way"``: moved / no motion only when the 0.98 test had power against
  the predicted Δc (its spread included) / undecided (schedule kept), at most
  ``max_undecided_cycles`` = 3 undecided cycles in a row before falling back to start-up;
* ``friction_grid`` with ``grid_handover_sets=3`` (issue 13, second round): for the start-up
  the friction posterior is a grid over (k_c, k_s) updated with each pulse's exact
  pulse-response likelihood (:mod:`controllers.solnic.grid_posterior`; "no motion" is its
  censored evidence, the constraints its support), the pulse's Δc, spread and t_max come from
  its posterior predictive; after three sets of twelve cycles it hands its mean and covariance
  to the joint EKF, which goes on alone. From the section-7.3 start the joint EKF alone runs
  onto the k_s/k_c ridge on quiet-friction seed 2 (k̂s ≈ 3.8 against 2.2, ~70 µrad pulses
  until ~25 s, peak 25.7 µrad scored from 20 s); with the grid the start-up is over in ~5 s.
  Tuned on seeds 0–4 only (100 s scored from 20 s; quiet-friction peak median/worst [µrad],
  thesis peak median/worst [µrad], thesis mode-2 NEES median [range]):

  ==========================  ==============  ==============  ===================
  grid_handover_sets          quiet           thesis          thesis NEES
  ==========================  ==============  ==============  ===================
  no grid (before)            3.14 / 25.7     —               —
  0 (grid all run)            2.79 / 3.16     16.5 / 48.0     1.33 [0.70, 5.30]
  1                           2.94 / 3.39     27.6 / 46.8     0.70 [0.58, 3.14]
  2                           3.07 / 3.22     20.5 / 36.3     0.84 [0.54, 2.00]
  **3**                       2.89 / 3.43     19.3 / 36.8     0.73 [0.61, 1.74]
  6                           2.81 / 2.93     22.7 / 37.1     1.94 [0.62, 9.61]
  ==========================  ==============  ==============  ===================

  Kept all run, the grid treats each pulse's evidence as independent although all of it
  leans on the same x̂4: it becomes confident in a Δc that is a little off and x̂4 absorbs
  the difference (quiet-friction NEES median 394, x̂4 biased by ~7 µrad/s at σ 0.25). The
  joint EKF carries the k–x4 correlation and stays honest once it starts near the truth.
  Also measured on seeds 0–4 with the grid all run and not turned on: ``grid_memory`` 30, 100,
  300 pulses (exponential forgetting; quiet NEES still 72–385, thesis NEES up to 5.4) and
  ``grid_model_error`` 0.05, 0.15 (quiet NEES 101–279; thesis up to 14.3). With the hand-over
  after 3 sets, ``grid_handover_inflation`` 4 and 16 (the handed-over covariance × that):
  quiet 2.87/3.36 and 2.91/3.03 µrad, thesis 22.2/30.5 and 20.4/60.2 µrad with NEES
  0.64 [0.62, 2.12] and 1.74 [1.02, 6.72] — not better than 1.

The first three flags were chosen on seeds 100–109 (issue 13, first round); the grid and its
hand-over on seeds 0–4. Reported on seeds 0–9 in the README ("solnic and solnic-modern").

Measured and not turned on: ``censored_no_motion`` (a wrong "no motion" after a badly
predicted pulse pins k̂s above the peak torque: seed 100 peak 17 → 36 µrad, measured with the
earlier d = 0 pseudo-measurement); ``joint_correction_limit``
(tuning seeds: thesis median 18.4 vs 17.6 µrad, NEES above 2 on 4 of 10 seeds); six undecided
cycles instead of three (one 45 µrad outlier in five seeds); the text's two filters with
``dc_measurement="data-only"`` and ``friction_constraints="distribution"`` (lower thesis peaks
on the tuning seeds, median 13.9 vs 17.6 µrad, but x̂4 inconsistent, NEES 3.5–230).
"""

from __future__ import annotations

import dataclasses
import types

from controllers.base import register
from controllers.solnic.controller import SolnicController
from controllers.solnic.options import PRESETS

__all__ = ["SolnicModernController", "MODERN_FLAGS"]

MODERN_FLAGS = types.MappingProxyType(dict(
    friction_estimator="joint-ekf",
    noise_aware_model=True,
    motion_decision="three-way",
    friction_grid=True,
    grid_handover_sets=3,
))


@register("solnic-modern")
class SolnicModernController(SolnicController):
    """:class:`SolnicController` with :data:`MODERN_FLAGS` on (see the module docstring)."""

    description = "solnic-modern: solnic with noise-aware, consistent estimators"
    presets = types.MappingProxyType({name: dataclasses.replace(o, **MODERN_FLAGS)
                                      for name, o in PRESETS.items()})
