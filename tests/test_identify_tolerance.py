"""The fit's looser LuGre tolerance (issue 25, tenth session) against independent truth.

The identification's noise-free lugre model integrates at RTOL 1e-8 (``fit._LUGRE_TOLERANCES``, the
plant's 1e-10 loosened 100×). The bound it must keep: with δ the change of a prediction, a
converged weighted least-squares estimate moves by at most ‖δ‖/σ1 of its formal (Gauss–Newton)
standard error (the projection of δ/σ1 onto the Jacobian's column space); over the default plan's
N ≈ 7000 rows a per-sample |δ| ≤ 0.01·σ1/√N = 6e-10 rad (σ1 = 5 µrad, Table 2-1) keeps that
below 0.01 of a standard error. Checked here:

* moves of the default plan (ramps, holds, pulses of each width, both directions), predicted by
  the fit's model at three points of the lugre draws' region and at a stiff σ0 = 1e6, against
  ``solve_ivp`` (Radau, rtol 1e-12, plant.lugre.reference.event_driven) from rest, every sample;
* the whole prediction against the same model at the plant's own tolerance (the path before), and
  that the looser tolerance does fewer Dormand–Prince steps (else it buys nothing).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from plant.identification import design_experiment
from plant.identification.fit import _LUGRE_TOLERANCES, _Model, _WorkClock
from plant.lugre.integrate import TOLERANCES
from plant.lugre.reference import event_driven
from plant.protocol import get_family

SIGMA1 = 5e-6       # rad, Table 2-1's encoder noise
ROWS = 7000         # about the default plan's fitted samples
BOUND = 0.01 * SIGMA1 / math.sqrt(ROWS)     # 6e-10 rad: an estimate moves < 0.01 standard error

# (k̄c, k̄s − k̄c, J, τ3, v_s, σ0): the draws' region (tests/identify_draws.py) and a stiff bristle
POINTS = ([1.2, 0.5, 0.5, 0.008, 0.006, 2e5], [0.95, 0.45, 0.35, 0.0065, 0.0095, 1.1e5],
          [1.55, 0.8, 0.85, 0.0105, 0.0042, 2.9e5], [1.2, 0.5, 0.5, 0.008, 0.004, 1e6])


def _model():
    plan = design_experiment()
    log = plan.with_y(np.zeros(plan.n))     # predictions do not depend on y (offsets 0)
    fam = get_family("lugre")
    base = fam.Params().replace(u_max=max(float(log.u_max), fam.Params().u_max), sample_period=log.sample_period)
    return _Model(log, "lugre", base)


def worst_against_radau(model, point):
    """The fit model's prediction at ``point`` (k̄c, k̄s − k̄c, J, τ3, v_s, σ0) against ``solve_ivp``
    (Radau, rtol 1e-12) from rest on every other kind of move of the plan (each mirror pair once):
    (the largest |difference| over their samples [rad], how many kinds were checked)."""
    z = np.log(point)
    pred = model.predict(z)
    assert pred is not None
    p = model.params(z)
    log = model.log
    kinds, worst, checked = set(), 0.0, 0
    for g, (s, e) in enumerate(model.segs):
        key = model.mirror[g][0]
        if key in kinds:             # each kind of move once (a mirror pair once)
            continue
        kinds.add(key)
        if len(kinds) % 2 != 1:      # every other kind: ramps, holds, pulses of each width (time)
            continue
        n_out = model.index[g].size
        ref, _ = event_driven(p, get_family("lugre").initial_state(p, 0.0).x, log.commands[s:s + n_out],
                              method="Radau", rtol=1e-12)
        worst = max(worst, float(np.max(np.abs(pred[model.groups == g] - ref))))
        checked += 1
    return worst, checked


def test_the_fit_tolerance_is_the_plant_one_loosened_100_times():
    assert np.array_equal(_LUGRE_TOLERANCES, TOLERANCES * 100.0)
    assert _LUGRE_TOLERANCES[0] == pytest.approx(1e-8)
    assert np.array_equal(_Model.lugre_tolerances, _LUGRE_TOLERANCES)


@pytest.mark.parametrize("point", [POINTS[0]] + [pytest.param(q, marks=pytest.mark.slow) for q in POINTS[1:]],
                         ids=["mid", "light-fast", "heavy-slow", "stiff"])
def test_prediction_against_radau_within_the_bound(point):
    worst, checked = worst_against_radau(_model(), point)
    assert checked >= 8
    print(f"worst |prediction − Radau| {worst:.3g} rad over {checked} kinds of move")
    assert worst <= BOUND, f"{worst:.3g} rad > {BOUND:.3g} rad"


def test_prediction_moves_far_below_the_bound_and_takes_fewer_steps():
    fast, plant = _model(), _model()
    plant.lugre_tolerances = TOLERANCES
    for point in POINTS:
        z = np.log(point)
        fast.clock, plant.clock = _WorkClock(), _WorkClock()
        a, b = fast.predict(z), plant.predict(z)
        assert a is not None and b is not None
        assert np.max(np.abs(a - b)) <= BOUND
        # the clock prices Dormand–Prince steps (and events): fewer steps, less nominal work
        assert fast.clock.spent < 0.8 * plant.clock.spent
