"""The two-mass kernel's root-search work and its price on the fit's work clock (issue 25, ninth
session: held-out seed 6571 two-mass case 8, 150.8 CPU s of point fit priced 7.5 nominal s).

A stiff shaft with k̄s = k̄c under a short full-torque pulse chattered at one instant (stick,
reflect, stick … at t ≈ 1.6 ms, a Zeno point), each event costing ~2·10⁴ counted steps: work
that samples and events do not show. ``root_steps`` counts the searches' steps and
``fit._WorkClock`` prices them (``fit._ROOT_STEP_COST_S``). The chatter and its cost were
removed in the tenth session (tests/test_two_mass_zeno.py). LAPACK's modal form (np.linalg.eig,
inv; until 2026-11-28) also left spurious rounding terms near the level that cost the searches
~1.7·10⁴ steps per event; the closed form (plant.two_mass.eigen) replaced it. Counts only,
never a timed test."""

from __future__ import annotations

import numpy as np
import pytest

from plant.drive import DriveCommand, DriveType
from plant.identification import fit
from plant.protocol import get_family
from plant.state import SimOptions, Status
from plant.two_mass.interval import root_steps

FAM = get_family("two-mass")
# a point the case-8 point fit visited (k̄s = k̄c, k_sh = 5000 ozf·in/rad, x4 off as in the fit)
CHATTER = FAM.Params().replace(inertia=0.8793840585261529, motor_time_constant=0.0037404330173091676,
                               coulomb=0.5881306837875517, stiction=0.5881306837875517, shaft_stiffness=5000.0,
                               shaft_damping=2.5, motor_inertia=0.05, u_max=20.0, sample_period=0.01,
                               command_velocity_std=0.0, command_velocity_initial=0.0)
PULSE = DriveCommand(((0.0, 20.0), (0.0012, 0.0)), DriveType.LINEAR)


def _one_interval(params, command, max_events):
    r0 = root_steps()
    step = FAM.step(FAM.initial_state(params, 0.0), command, params, None,
                    SimOptions(noise=False, max_events=max_events))
    return step, root_steps() - r0


def test_former_zeno_point_is_cheap_counted_and_priced():
    """The point that chattered (2001 events at t ≈ 1.6 ms, ~2·10⁴ counted steps per event, 12–18 CPU
    s per prediction) until issue 25's tenth session: its 2·10⁴ "steps" per event were
    ``interval._x1_peak`` going round its loop on zero-length steps, and the stop itself was a
    rounding-level slope (tests/test_two_mass_zeno.py checks the state against solve_ivp). Now
    the interval ends ok after one breakaway, with few counted steps; the count is deterministic
    and the clock prices it at ``fit._ROOT_STEP_COST_S`` per step on top of the other units."""
    step, roots = _one_interval(CHATTER, PULSE, 20)
    assert step.status is Status.OK and step.n_events == 2
    assert 1 <= roots < 100
    old = fit._WorkClock()
    old.add("two-mass", 1, step.n_events, step.n_substeps)
    new = fit._WorkClock()
    new.add("two-mass", 1, step.n_events, step.n_substeps, roots)
    assert new.spent == old.spent + fit._ROOT_STEP_COST_S["two-mass"] * roots
    # deterministic: the same count again
    assert _one_interval(CHATTER, PULSE, 20)[1] == roots


def test_compliant_shaft_ramp_price_barely_changes():
    """An ordinary move (the family's compliant scenario, a torque ramp through breakaway): the
    root steps add little to the charge (case 2 of seed 6571: ~730 steps for 180 samples and
    34 events per prediction, +6 %)."""
    p = FAM.Params().replace(**FAM.scenarios["compliant"][0], command_velocity_std=0.0, command_velocity_initial=0.0)
    state = FAM.initial_state(p, 0.0)
    samples = events = roots = 0
    opts = SimOptions(noise=False)
    for k in range(1, 40):
        r0 = root_steps()
        step = FAM.step(state, DriveCommand.hold(0.1 * k * p.stiction), p, None, opts)
        assert step.status is Status.OK
        roots += root_steps() - r0
        samples += 1
        events += step.n_events
        state = step.state
    assert events >= 1 and roots >= 1          # the shaft broke away: the searches ran
    base = fit._WorkClock()
    base.add("two-mass", samples, events, 0)
    priced = fit._WorkClock()
    priced.add("two-mass", samples, events, 0, roots)
    assert priced.spent <= 1.25 * base.spent


def test_other_families_clock_unchanged():
    """roots = 0 (every family but two-mass): the clock adds the old sum, bit for bit."""
    for fam, (a, b, c) in fit._UNIT_COST_S.items():
        clock = fit._WorkClock()
        clock.add(fam, 1234, 56, 789)
        assert clock.spent == a * 1234 + b * 56 + c * 789


def test_two_mass_prediction_charges_its_root_steps():
    """fit._Model.predict (noise-free, the path the point fit and the bootstrap use) hands each
    simulated move's root steps to the clock, and their sum is the kernel's count."""
    from plant.identification import ExperimentOptions, design_experiment, simulate_log

    p = FAM.Params().replace(**FAM.scenarios["compliant"][0])
    log, _ = simulate_log(design_experiment(ExperimentOptions(repeats=1)), "two-mass", p, 5)
    u_max = max(float(log.u_max), FAM.Params().u_max)
    model = fit._Model(log, "two-mass", FAM.Params().replace(u_max=u_max, sample_period=log.sample_period))
    seen = []

    class _Clock(fit._WorkClock):
        def add(self, family, *work):
            seen.append(work)
            super().add(family, *work)

    model.clock = _Clock()
    # z: ln of k̄c, k̄s − k̄c, J, τ3, k_sh (fit._Model.params)
    z = np.log([p.coulomb, p.stiction - p.coulomb, p.inertia, p.motor_time_constant, p.shaft_stiffness])
    r0 = root_steps()
    y = model.predict(z)
    assert y is not None and seen and all(len(w) == 4 for w in seen)
    assert sum(w[3] for w in seen) == root_steps() - r0 > 0
    assert model.clock.spent > sum(4.0e-6 * w[0] + 88e-6 * w[1] for w in seen)
