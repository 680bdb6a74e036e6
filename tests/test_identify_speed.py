"""The speed-ups of the identification's noise-free model (issue 25, fifth session) change no number.

* a move and its mirror (nonzero levels negated) share one simulation: predictions bit-identical to
  simulating each kind of move (the path before), on all four families at points near and far from
  the truth, and equal to an independent per-move simulation through the family's step (no sharing,
  no settle freeze) to 1e-9 rad;
* a move in one compiled call (lugre since the fifth session, multimode since the ninth) and a whole
  lugre prediction in one compiled call (ninth session, plant.lugre.move_loop.play_all): the same
  predictions and the same work-clock counts, checks and budget cuts, bit for bit, as the Python loop
  over the family's step or a call per move.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from plant.identification import design_experiment
from plant.identification.families import FAMILY_FREE
from plant.identification.fit import _OPTS, _Model, _OutOfTime, _TraceClock
from plant.lugre.integrate import TOLERANCES
from plant.protocol import get_family


def _model(family):
    fam = get_family(family)
    params = fam.Params().replace(coulomb=1.2, stiction=1.7, inertia=0.5, motor_time_constant=0.008)
    plan = design_experiment()
    log = plan.with_y(np.zeros(plan.n))     # the predictions do not depend on y (offsets 0)
    base = fam.Params().replace(u_max=max(float(log.u_max), fam.Params().u_max), sample_period=log.sample_period)
    return _Model(log, family, base), params


@pytest.mark.parametrize("family", list(FAMILY_FREE))
def test_mirror_sharing_is_bit_identical(family):
    model, params = _model(family)
    kinds = {k for k in model.keys}
    shared = {canon for canon, _ in model.mirror}
    assert len(shared) < len(kinds)          # the plan has mirror pairs (else the test tests nothing)
    z0 = np.log([params.coulomb, params.stiction - params.coulomb, params.inertia, params.motor_time_constant]
                + [getattr(params, f) for f in FAMILY_FREE[family]])
    old = _Model(model.log, family, model.base)
    old.share_mirror = False
    for shift in (0.0, 0.4, -0.7):
        z = z0 + shift * np.linspace(-1.0, 1.0, z0.size)
        a, b = model.predict(z), old.predict(z)
        assert a is not None and b is not None
        assert np.array_equal(a, b)


@pytest.mark.parametrize("family", ["multimode", "lugre"])
def test_prediction_equals_an_independent_per_move_simulation(family):
    """Every move simulated on its own from rest through the family's step for its whole length
    (no kind sharing, no mirror, no settle freeze) and offset by its rest mean: the prediction
    agrees to 1e-9 rad (the freeze stops a settled lugre shaft within 1e-10 rad of its end)."""
    model, params = _model(family)
    z = np.log([1.1, 0.45, 0.45, 0.007] + [getattr(params, f) for f in FAMILY_FREE[family]])
    pred = model.predict(z)
    p = model.params(z)
    fam, log = model.fam, model.log
    for g in range(0, len(model.segs), 7):          # every 7th move: both directions, every part
        s, e = model.segs[g]
        state = fam.initial_state(p, 0.0)
        x1 = []
        for n in range(s, e):
            state = fam.step(state, log.commands[n], p, None, _OPTS).state
            x1.append(state.x[0])
        n_out = model.index[g].size
        ref = model.offsets[g] + np.array(x1)[:n_out]
        assert np.max(np.abs(pred[model.groups == g] - ref)) <= 1e-9


def test_designed_starts_recover_a_noise_free_two_mass_log():
    """The designed starts (multimode's fit, then the grid of k_sh, the least-cost start refitted):
    a noise-free two-mass log at a shaft stiffness between the grid's points is recovered to 1e-4,
    and the method line says how the point fit started."""
    from plant.identification import ExperimentOptions, fit_log, simulate_log

    truth = dict(coulomb=1.2, stiction=1.7, inertia=0.55, motor_time_constant=0.0085, shaft_stiffness=1.5e4)
    p = get_family("two-mass").Params().replace(**truth)
    log, _ = simulate_log(design_experiment(ExperimentOptions(repeats=1)), "two-mass", p, None)
    fit = fit_log(log, "two-mass", bootstrap=0)
    for k, v in truth.items():
        assert fit.estimates[k] == pytest.approx(v, rel=1e-4), k
    assert "designed points" in fit.method


@pytest.mark.parametrize("whole", [False, True])
def test_compiled_lugre_moves_are_bit_identical_to_the_python_loop(whole):
    """plant.lugre.move_loop (a call per move, or the whole prediction in one call) against the
    Python loop over the family's step (and no mirror sharing: the path before issue 25's fifth
    session), at the truth, a stiffer and slower bristle point, one of long slides (k̄c small) and
    one where the plant leaves ok (both None)."""
    model, params = _model("lugre")
    model.whole_moves = whole
    model.lugre_tolerances = TOLERANCES     # the plant's own (the Python loop's); the fit's are looser
    model.lugre_stiff = 0.0                 # Dormand–Prince alone, the plant's step (the fit's stiff-sliding
                                            # step is checked against Radau: tests/test_identify_stiff.py)
    old = _Model(model.log, "lugre", model.base)
    old.share_mirror = old.compiled_moves = False
    for point in ([1.2, 0.5, 0.5, 0.008, 0.004, 1e6], [0.9, 0.8, 0.35, 0.006, 0.012, 1e5],
                  [1.0, 0.6, 0.8, 0.011, 0.002, 3e5]):
        z = np.log(point)
        a, b = model.predict(z), old.predict(z)
        assert a is not None and b is not None
        assert np.array_equal(a, b)
    z = np.log([0.3, 1.2, 0.8, 0.011, 0.002, 3e5])     # wanders past 1 rad
    assert model.predict(z) is None and old.predict(z) is None
    if whole:
        assert model._whole[True] is not None and not model._prepared     # the whole-prediction path ran
    else:
        assert len(model._prepared) > 0 and not model._whole              # the per-move compiled path ran


def test_compiled_lugre_moves_count_the_work_the_python_loop_counts():
    """The work budget's counts (samples, events, integrator steps: fit._WorkClock) of a compiled
    move equal the Python loop's, summed from each step's IntervalResult, so a budget stops a fit
    at the same point on either path — including a move where the plant leaves ok."""
    model, _ = _model("lugre")
    model.lugre_tolerances = TOLERANCES     # the plant's own (the Python loop's); the fit's are looser
    model.lugre_stiff = 0.0                 # Dormand–Prince alone, the plant's step (see above)
    python = _Model(model.log, "lugre", model.base)
    python.compiled_moves = False
    from plant.identification.fit import _WorkClock

    class Recording(_WorkClock):
        __slots__ = ("seen",)

        def add(self, family, *work):
            self.seen.append(work)
    for m in (model, python):
        m.clock = Recording()
        m.clock.seen = []
    for point in ([1.2, 0.5, 0.5, 0.008, 0.004, 1e6], [0.3, 1.2, 0.8, 0.011, 0.002, 3e5]):
        model.predict(np.log(point))
        python.predict(np.log(point))
    compiled, loop = model.clock.seen, python.clock.seen
    assert compiled == loop and len(compiled) > 10
    assert all(s > 0 and sub > s for s, _, sub in compiled)     # LuGre: several integrator steps per sample


def _traced(model, points, deadline=math.inf):
    """Each point's prediction (or "out of time") on a fresh _TraceClock with ``deadline``, and the
    clock's trace (every increment and every deadline check, in order) and total."""
    out = []
    for point in points:
        model.clock, model.deadline = _TraceClock("lugre"), deadline
        try:
            out.append(model.predict(np.log(point)))
        except _OutOfTime:
            out.append("out of time")
        out.append((model.clock.trace, model.clock.spent, model.clock.first_past))
    return out


def _same(a, b):
    assert len(a) == len(b)
    for x, y in zip(a, b):
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and np.array_equal(x, y)
        else:
            assert x == y


@pytest.mark.parametrize("drive", ["linear", "bridge"])
def test_whole_lugre_prediction_replays_the_work_clock_of_the_per_move_path(drive):
    """The whole prediction in one compiled call (plant.lugre.move_loop.play_all) against a call
    per move: the same predictions, bit for bit, and the same work-clock trace (every increment and
    every deadline check, in order: what fit._replayed and the budget read) — without a budget, and
    with deadlines that cut a prediction after its first, a middle and its last but one simulated move
    (both paths raise _OutOfTime at the same check: before the second, a middle and the last move).
    Linear drive and the bridge's flyback."""
    from plant.identification import ExperimentOptions

    plan = design_experiment(ExperimentOptions(drive=drive, repeats=1))
    log = plan.with_y(np.zeros(plan.n))
    fam = get_family("lugre")
    base = fam.Params().replace(u_max=max(float(log.u_max), fam.Params().u_max) if drive == "linear" else log.u_max,
                                sample_period=log.sample_period)
    whole, per_move = _Model(log, "lugre", base), _Model(log, "lugre", base)
    per_move.whole_moves = False
    whole.lugre_stiff = 0.0      # the per-move path has the plant's Dormand–Prince step alone
    points = ([1.2, 0.5, 0.5, 0.008, 0.004, 1e6], [0.9, 0.8, 0.35, 0.006, 0.012, 1e5],
              [0.3, 1.2, 0.8, 0.011, 0.002, 3e5])          # the last leaves ok (None)
    free = _traced(per_move, points)
    _same(_traced(whole, points), free)
    assert free[0] is not None and free[-2] is None
    increments = [w for w in free[1][0] if w >= 0.0]
    assert len(increments) > 5
    for cut in (0.5 * increments[0], 0.5 * sum(increments), sum(increments[:-1]) - 0.5 * increments[-2]):
        a, b = _traced(whole, points[:1], cut), _traced(per_move, points[:1], cut)
        _same(a, b)
        assert a[0] == "out of time"


def test_compiled_multimode_moves_are_bit_identical_to_the_python_loop():
    """plant.multimode.move_loop (the nested multimode fit of lugre and two-mass, and every multimode
    fit) against the Python loop over the family's step: the same predictions, bit for bit, and the
    same work counts per move (fit._WorkClock: samples, events, sub-steps), at the truth, a heavy
    slow shaft, a light fast one and a stiction-dominated one; both paths on the bridge plan too."""
    from plant.identification import ExperimentOptions
    from plant.identification.fit import _WorkClock

    class Recording(_WorkClock):
        __slots__ = ("seen",)

        def add(self, family, *work):
            self.seen.append(work)
    for drive in ("linear", "bridge"):
        plan = design_experiment(ExperimentOptions(drive=drive, repeats=1))
        log = plan.with_y(np.zeros(plan.n))
        fam = get_family("multimode")
        base = fam.Params().replace(u_max=log.u_max, sample_period=log.sample_period)
        compiled, python = _Model(log, "multimode", base), _Model(log, "multimode", base)
        python.compiled_moves = False
        for m in (compiled, python):
            m.clock = Recording()
            m.clock.seen = []
        for point in ([1.2, 0.5, 0.5, 0.008], [0.9, 0.8, 1.5, 0.011], [1.5, 0.3, 0.2, 0.006], [0.4, 1.6, 0.6, 0.009]):
            a, b = compiled.predict(np.log(point)), python.predict(np.log(point))
            assert a is not None and b is not None
            assert np.array_equal(a, b)
        assert compiled.clock.seen == python.clock.seen and len(compiled.clock.seen) > 10
        assert len(compiled._prepared) > 0 and not python._prepared     # the compiled path ran
