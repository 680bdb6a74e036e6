"""solnic's compiled idle sample (:mod:`controllers.solnic.idle_step`) against the Python path.

The reference is the runner's Python loop with the controller's own Python logic: a recorded
run (``record=True``, which never takes the compiled loop) and ``compiled=False``. The compiled
run must give every metric and the whole summary (counters, estimates, the predictor's model
runs) bit for bit, on every family the compiled loop serves, with the quantized sensor and the
compute delay, and the disturbed plant (its own compiled loop, plant/multimode/disturbed_loop.py). The
compiled transition of the mode-2 filter is compared with
:func:`~controllers.solnic.mode2_filter.mode2_transition` on random steps.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from controllers import law
from controllers.solnic import idle_step as idle
from controllers.solnic.mode2_filter import Mode2Filter, mode2_transition

RUNTIME = ("runtime_s", "realtime_factor")


def _row(r):
    return r.status, r.message, {k: v for k, v in r.metrics.items() if k not in RUNTIME}, r.summary


def _run(name, scenario, seed, duration, **kw):
    sc = builtin_scenarios()[scenario]
    c = make_controller(name) if isinstance(name, str) else name
    calls = []
    step = c.step
    c.step = lambda y: calls.append(1) or step(y)          # counts the Python samples
    r = run_closed_loop(sc.params, c, duration_s=duration, warmup_s=duration / 5, seed=seed, family=sc.family,
                        model=sc.model, **kw)
    return r, len(calls), c


@pytest.mark.parametrize("scenario, seed", [("thesis", 0), ("thesis", 1), ("quantized", 2), ("delayed", 3),
                                            ("stribeck", 4), ("compliant", 0), ("disturbed", 1)])
def test_compiled_solnic_rows_are_the_python_rows(scenario, seed):
    compiled, n_python, c = _run("solnic", scenario, seed, 12.0)
    recorded, n_recorded, _ = _run("solnic", scenario, seed, 12.0, record=True)
    python, _, _ = _run("solnic", scenario, seed, 12.0, compiled=False)
    assert compiled.status == "ok"
    assert _row(compiled) == _row(recorded) == _row(python)       # every metric and the summary, exactly
    assert n_recorded == 1200
    pulses = compiled.summary["pulses"]
    assert 10 < pulses and n_python <= 3 * pulses + 5              # hand-backs per pulse cycle, not per sample


@pytest.mark.parametrize("scenario, seed, duration", [("thesis", 0, 20.0), ("quantized", 1, 12.0),
                                                      ("delayed", 2, 12.0), ("stribeck", 3, 12.0),
                                                      ("compliant", 4, 12.0)])
def test_compiled_solnic_modern_rows_are_the_python_rows(scenario, seed, duration):
    """The joint EKF's idle step, through the grid's start-up and (thesis, 20 s) past its
    hand-over to the joint EKF with braking pulses; the predictor's model runs included."""
    compiled, n_python, c = _run("solnic-modern", scenario, seed, duration)
    recorded, _, _ = _run("solnic-modern", scenario, seed, duration, record=True)
    python, _, cp = _run("solnic-modern", scenario, seed, duration, compiled=False)
    assert compiled.status == "ok"
    assert _row(compiled) == _row(recorded) == _row(python)
    assert n_python < 0.3 * duration * 100                        # most samples ran compiled
    if scenario == "thesis":
        assert c.summary()["grid_handover_cycle"] > 0 and c.grid is None      # past the hand-over
        assert c.summary()["braked_pulses"] > 0
    assert c.predictor.n_model_runs == cp.predictor.n_model_runs
    assert c.joint._since == cp.joint._since                      # what no_motion would replay


def test_options_the_idle_step_does_not_cover_keep_the_python_path():
    c = make_controller("solnic-modern", noise_aware_model=False)
    compiled, n_python, _ = _run(c, "thesis", 0, 3.0)
    python, _, _ = _run(make_controller("solnic-modern", noise_aware_model=False), "thesis", 0, 3.0, compiled=False)
    assert n_python == 300 and _row(compiled) == _row(python)


def test_the_state_after_a_compiled_run_is_the_controllers_own():
    """What the Python reporting reads after a compiled run (internals, the cycle log, the
    launch instants) is what the Python path leaves."""
    a, _, ca = _run("solnic", "thesis", 5, 8.0)
    b, _, cb = _run("solnic", "thesis", 5, 8.0, compiled=False)
    assert ca.internals() == cb.internals() and ca._n == cb._n == 800
    assert ca.log == cb.log and len(ca.log) > 5
    ea, eb = ca.event_times(), cb.event_times()
    assert ea.keys() == eb.keys() and all(np.array_equal(ea[k], eb[k]) for k in ea)


def test_compiled_mode2_transition_is_the_filters():
    """The idle step's predict (Φ (3-22), COV[N] (4-11), the anchor and motion covariances)
    equals Mode2Filter.predict bit for bit, over steps across the series/closed-form switch."""
    rng = np.random.default_rng(7)
    tau4, s4 = 0.37, 2.3e-9
    p = np.zeros(idle.N_PARAMS)
    p[idle.TS], p[idle.R] = 1.0, 1e-12
    p[idle.TAU4:idle.Q44C + 1] = idle.mode2_coefficients(tau4, s4)
    p[idle.EVAL_SAMPLES] = 1e9
    offs, levs = np.zeros(1), np.zeros(1)
    for h in np.concatenate([rng.uniform(1e-6, 0.2, 300), [1e-3, 0.01, 0.037, 0.037000001, 0.5]]):
        f = Mode2Filter(tau4, s4, 1e-6, [3e-6, -2e-5], [[4e-10, 1e-11], [1e-11, 3e-9]])
        f.set_anchor()
        f.add_motion(2e-5, 1e-11)
        s = np.zeros(idle.N_STATE)
        s[idle.X1], s[idle.X4], s[idle.P11], s[idle.P14], s[idle.P44] = f.moments()
        s[idle.HAS_ANCHOR], (s[idle.C0], s[idle.C1]) = 1.0, f._anchor
        s[idle.HAS_MOTION], (s[idle.M0], s[idle.M1]) = 1.0, f._motion
        s[idle.N], s[idle.T_MAX] = h, np.inf            # t = n·τs = h; no sample used
        f.predict(h)
        assert idle.idle_step(s, p, np.nan, offs, levs) == 0       # no plan cached: handed back
        assert (s[idle.X1], s[idle.X4], s[idle.P11], s[idle.P14], s[idle.P44]) == f.moments()
        assert (s[idle.C0], s[idle.C1]) == f._anchor and (s[idle.M0], s[idle.M1]) == f._motion
        Phi, Q = mode2_transition(h, tau4, s4)
        assert Phi[0, 1] != 0.0 and Q[0, 0] > 0.0      # the step did something


@pytest.mark.parametrize("name, options", [
    ("solnic", {"braking_pulse": True}),
    ("solnic", {"dce_variance": "independent", "dc_measurement": "data-only"}),
    ("solnic", {"friction_constraints": "distribution", "motion_decision": "three-way"}),
    ("solnic", {"legacy_set_boundary": True, "a_c": 1e-6}),
    ("solnic", {"preset": "high-error-cost"}),
    ("solnic-modern", {"friction_grid": False}),
    ("solnic-modern", {"braking_pulse": False, "censored_no_motion": True}),
])
def test_option_variants_compiled_are_the_python_rows(name, options):
    compiled, n_python, _ = _run(make_controller(name, **options), "thesis", 6, 10.0)
    python, _, _ = _run(make_controller(name, **options), "thesis", 6, 10.0, compiled=False)
    assert compiled.status == "ok" and n_python < 500
    assert _row(compiled) == _row(python)


def _full_moments_bias(self, pred, dtu):
    """The planner's bias as it was before issue 27's bias-only path: from the full moments."""
    return self._pulse_noise(pred, dtu)[0]


@pytest.mark.parametrize("scenario", ["thesis", "disturbed", "quantized", "delayed", "stribeck", "compliant"])
def test_solnic_modern_rows_are_the_rows_before_the_bias_only_paths(scenario, monkeypatch):
    """The mean-only backward solve, the plan cache of the compiled step and the planner's
    bias-only path change no row: the compiled run against the Python path with every bias
    taken from the full moments (the code before them), seeds 0–4, every metric and the summary."""
    duration = 20.0 if scenario == "thesis" else 8.0          # thesis: past the grid's hand-over
    new = [_run("solnic-modern", scenario, seed, duration) for seed in range(5)]
    monkeypatch.setattr("controllers.solnic.controller.SolnicController._pulse_bias", _full_moments_bias)
    for seed, (compiled, n_python, c) in enumerate(new):
        before, _, cb = _run("solnic-modern", scenario, seed, duration, compiled=False)
        assert compiled.status == "ok"
        assert _row(compiled) == _row(before), seed
        assert c.predictor.n_model_runs == cb.predictor.n_model_runs
        if scenario != "disturbed":
            assert n_python < 0.3 * duration * 100


@pytest.mark.parametrize("options", [{"friction_grid": False}, {"braking_pulse": False},
                                     {"preset": "high-error-cost"}])
def test_solnic_modern_variants_are_the_rows_before_the_bias_only_paths(options, monkeypatch):
    """As above for option sets that plan with the point estimate from the start (no grid),
    without braking pulses, and the high-error-cost preset; thesis, seeds 0–2, 10 s."""
    new = [_run(make_controller("solnic-modern", **options), "thesis", seed, 10.0) for seed in range(3)]
    monkeypatch.setattr("controllers.solnic.controller.SolnicController._pulse_bias", _full_moments_bias)
    for seed, (compiled, n_python, _) in enumerate(new):
        before, _, _ = _run(make_controller("solnic-modern", **options), "thesis", seed, 10.0, compiled=False)
        assert compiled.status == "ok" and n_python < 300
        assert _row(compiled) == _row(before), seed


def test_a_numba_without_the_wrapper_address_helper_gives_the_same_rows(monkeypatch):
    """``StepAddress`` rests on numba's semi-internal ``_get_wrapper_address``; without it the
    dispatcher itself is the step (typed at every entry): the rows must not change."""
    addressed, _, _ = _run("solnic", "thesis", 5, 8.0)
    monkeypatch.setattr(law, "_get_wrapper_address", None)
    monkeypatch.setattr(idle, "_ADDRESS", [])
    plain, n_python, _ = _run("solnic", "thesis", 5, 8.0)
    assert not isinstance(idle.idle_step_address(), law.StepAddress)
    assert _row(plain) == _row(addressed)
    assert plain.summary["pulses"] > 5 and n_python <= 3 * plain.summary["pulses"] + 5   # still the compiled loop
