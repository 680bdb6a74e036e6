"""The solnic controller: options, protocol, and closed-loop behaviour on the exact plant."""

import math

import numpy as np
import pytest

from controllers import available_controllers, get_controller
from controllers.solnic import SolnicController
from plant import DriveType, PlantParams

INTERNALS = {"ks_hat", "kc_hat", "P_kc_kc", "P_ks_ks", "P_kc_ks", "dtu_opt", "dtu_inc", "cost_small",
             "cost_medium", "cost_large", "dc_ratio", "cycle_size", "x1_hat", "x4_hat",
             "ks_kc_corr", "dt_opt_rel_error", "n_cost_updates",  # for the report series
             "m2_x1", "m2_x4", "m2_P11", "m2_P14", "m2_P44"}


def test_registered_on_the_bridge():
    assert "solnic" in available_controllers()
    cls = get_controller("solnic")
    assert cls is SolnicController and cls.drive == DriveType.BRIDGE


@pytest.mark.parametrize("kw,match", [
    (dict(preset="nope"), "preset"),
    (dict(a_c=-1.0), "a_c"),
    (dict(a_cov=1.5), "a_cov"),
    (dict(bogus=1), "bogus"),
    (dict(motion_confidence=1.2), "motion_confidence"),
    (dict(dce_variance="maybe"), "dce_variance"),
    (dict(dc_measurement="x"), "dc_measurement"),
    (dict(friction_noise_in_filter=1), "friction_noise_in_filter"),
    (dict(initial_increment_factor=math.nan), "initial_increment_factor"),
    (dict(motion_decision="four-way"), "motion_decision"),
    (dict(max_undecided_cycles=0), "max_undecided_cycles"),
    (dict(evaluation_samples=1.5), "evaluation_samples"),
    (dict(friction_constraints="soft"), "friction_constraints"),
    (dict(no_motion_power=1.0), "no_motion_power"),
    (dict(friction_grid=True), "friction_grid"),                   # needs the joint filter
    (dict(friction_estimator="joint-ekf", grid_points=0), "grid_points"),
    (dict(friction_estimator="joint-ekf", grid_points=1), "grid_points"),   # no neighbour for the cell spread
    (dict(grid_memory=0.0), "grid_memory"),
    (dict(grid_memory=math.nan), "grid_memory"),
    (dict(grid_model_error=-0.1), "grid_model_error"),
    (dict(grid_handover_sets=-1), "grid_handover_sets"),
    (dict(grid_handover_inflation=0.5), "grid_handover_inflation"),
])
def test_options_are_validated(kw, match):
    with pytest.raises(ValueError, match=match):
        SolnicController(**kw)


def test_step_commands_and_internals():
    p = PlantParams()
    c = SolnicController()
    c.reset(p, np.random.default_rng(0))
    assert set(c.internals()) == INTERNALS
    assert math.isnan(c.internals()["cost_small"])
    levels = set()
    for n in range(50):
        cmd = c.step(-30e-6 * n * p.sample_period)
        assert cmd.drive == DriveType.BRIDGE
        levels |= {v for _, v in cmd.segments}
        assert all(0 <= o < p.sample_period for o, _ in cmd.segments)
    assert levels <= {0.0, p.u_max, -p.u_max} and p.u_max in levels
    assert all(isinstance(v, float) for v in c.internals().values())
    s = c.summary()
    assert s["pulses"] > 0 and s["ks_hat"] > 0


def test_initial_estimates_follow_section_7_3():
    p = PlantParams()
    c = SolnicController()
    c.reset(p, np.random.default_rng(0))
    i = c.internals()
    assert i["ks_hat"] == pytest.approx(0.5 * p.stiction) and i["kc_hat"] == pytest.approx(0.5 * p.coulomb)
    assert i["x1_hat"] == 0.0 and i["x4_hat"] == 0.0 and i["dtu_opt"] == 0.0
    assert i["dtu_inc"] == pytest.approx(4 * c.summary()["dtu_inc_adjusted"])


# ---------------------------------------------------------------- closed loop (exact plant)
run_closed_loop = pytest.importorskip("bench.runner").run_closed_loop
NOISE_FREE_FRICTION = PlantParams().replace(friction_noise_psd=0.0, correlated_friction_std=0.0)


@pytest.fixture(scope="module")
def deterministic_run():
    """No noise at all (runner noise=False), friction noise parameters 0, k̂ from 0.5×."""
    return run_closed_loop(NOISE_FREE_FRICTION, SolnicController(), duration_s=60.0, seed=0,
                           noise=False, record=True)


@pytest.mark.slow
def test_identification_without_friction_noise(deterministic_run):
    r = deterministic_run
    assert r.status == "ok"
    ks, kc = r.internals["ks_hat"][-1], r.internals["kc_hat"][-1]
    ks_true, kc_true = r.samples["ks_true"][-1], r.samples["kc_true"][-1]
    # the text: within 6 % at 54 s; measured 2.2 % (1.99 % before the set-boundary fix)
    assert abs(kc / kc_true - 1) < 0.03
    # started 50 % low; ends on the identification ridge within 10 % (the text: 5.7 % low at 54 s)
    assert abs(ks / ks_true - 1) < 0.10
    assert r.internals["ks_hat"][0] == pytest.approx(0.5 * ks_true)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="identification singularity (section 6.2): k̂s settles 7.5 % (6 % before the set-boundary fix) "
                                       "low at 60 s, as in the text's run (5.7 % low at 54 s)")
def test_ks_within_two_percent_by_60s(deterministic_run):
    ks, ks_true = deterministic_run.internals["ks_hat"][-1], deterministic_run.samples["ks_true"][-1]
    assert abs(ks / ks_true - 1) < 0.02


def _quiet_friction(warmup_s):
    p = PlantParams().replace(friction_noise_psd=0.0)
    out = []
    for seed in (0, 1, 2):
        r = run_closed_loop(p, SolnicController(), duration_s=100.0, warmup_s=warmup_s, seed=seed)
        lin = run_closed_loop(p, get_controller("linear")(), duration_s=100.0, warmup_s=warmup_s, seed=seed)
        assert r.status == "ok" and lin.status == "ok", (r.message, lin.message)
        out.append((r.metrics, lin.metrics))
    return p.classical_bound(), out


@pytest.mark.slow
def test_quiet_friction_beats_the_classical_limit_scored_from_20s():
    """The issue's criterion as written: σ2 = 0, three seeds, 100 s, scored from 20 s.

    Before the set-boundary fix seed 1 left a 36.1 µrad peak (a stale large-size trigger);
    with it the peaks are 2.75, 2.71, 3.57 µrad (issue 13).
    """
    bound, runs = _quiet_friction(20.0)
    assert all(m["peak_error_rad"] < bound for m, _ in runs)


@pytest.mark.slow
def test_modern_quiet_friction_beats_the_classical_limit_scored_from_20s():
    """solnic-modern, the issue's criterion on three seeds (100 s, σ2 = 0, scored from 20 s);
    seed 2 was 25.7 µrad before the grid posterior (the start-up on the k_s/k_c ridge)."""
    p = PlantParams().replace(friction_noise_psd=0.0)
    for seed in (0, 1, 2):
        r = run_closed_loop(p, get_controller("solnic-modern")(), duration_s=100.0, warmup_s=20.0, seed=seed)
        assert r.status == "ok", r.message
        assert r.metrics["peak_error_rad"] < p.classical_bound()


@pytest.mark.slow
def test_quiet_friction_beats_the_classical_limit_after_start_up_and_uses_less_current():
    """σ2 = 0, three seeds, 100 s, scored from 40 s — after the start-up transient.

    Like the text's run (first cost evaluation at 20 s, steady at ~54 s), the start-up from
    0.5× estimates and Δt_u,opt = 0 lasts beyond 20 s. Mean |current| is compared with the
    linear controller on the same seeds and window.
    """
    bound, runs = _quiet_friction(40.0)
    for solnic, linear in runs:
        assert solnic["peak_error_rad"] < bound
        assert solnic["mean_abs_current"] < linear["mean_abs_current"]


@pytest.mark.slow
def test_thesis_scenario_completes():
    r = run_closed_loop(PlantParams(), SolnicController(), duration_s=100.0, warmup_s=20.0, seed=0)
    assert r.status == "ok", r.message
    for key in ("peak_error_rad", "rms_error_rad", "mean_abs_current", "rms_current"):
        assert math.isfinite(r.metrics[key]) and r.metrics[key] > 0
    assert r.summary["pulses"] > 100 and r.summary["cost_evaluations"] > 5


# ---------------------------------------------------------------- protocol v2 options
def test_options_protocol_presets_and_knob():
    from controllers.solnic import SolnicOptions
    from controllers.solnic.options import A_C_HIGH_ERROR_COST, A_C_THESIS
    assert SolnicController().options == SolnicOptions() and SolnicController().options.a_c == A_C_THESIS
    assert SolnicController(preset="high-error-cost").options.a_c == A_C_HIGH_ERROR_COST
    assert SolnicController(SolnicOptions(a_cov=1.0)).options.a_cov == 1.0
    assert SolnicController(preset="thesis", a_c=1).options.a_c == 1.0
    assert min(SolnicController.knobs["a_c"]) < 0.1 * A_C_HIGH_ERROR_COST    # toward a_c → 0
    modern = get_controller("solnic-modern")
    assert modern.family == SolnicController.family == "solnic"
    assert modern(preset="high-error-cost").options.a_c == A_C_HIGH_ERROR_COST
    assert modern().options.motion_decision == "three-way" and SolnicController().options.motion_decision == "two-way"
    with pytest.raises(ValueError, match="a_cov"):
        SolnicOptions(a_cov=0.0)


# ---------------------------------------------------------------- set-boundary regression
@pytest.fixture(scope="module")
def set_boundary_runs():
    """Noise-free plant, 20 s, estimates started right so that sets complete early.

    Returns, for the legacy (buggy) and the fixed controller, |x̂1(t_a)| / (Δc_p/2) at the
    first pulse of every new set: the trigger rule (section 7.2) fires at x̂1 = −Δc_p/2 of the
    pulse being launched, i.e. a ratio of 1.
    """
    out = {}
    for legacy in (True, False):
        c = SolnicController(initial_friction_factor=1.0, initial_increment_factor=1.0,
                             legacy_set_boundary=legacy)
        r = run_closed_loop(NOISE_FREE_FRICTION, c, duration_s=20.0, seed=0, noise=False)
        assert r.status == "ok", r.message
        ratios = [abs(e["x1_a"]) / (0.5 * e["dc_p"]) for prev, e in zip(c.log, c.log[1:])
                  if e["size"] == 1 and prev["size"] == 3]
        out[legacy] = ratios
    return out


def test_set_boundary_stale_trigger_reproduced_with_legacy_flag(set_boundary_runs):
    """The bug: the first trigger after a set is planned with the finished set's large size."""
    ratios = set_boundary_runs[True]
    assert len(ratios) >= 3 and min(ratios) > 2.0


def test_set_boundary_trigger_uses_the_new_size(set_boundary_runs):
    ratios = set_boundary_runs[False]
    assert len(ratios) >= 3 and max(ratios) < 1.1


# ---------------------------------------------------------------- consistency (NEES)
NEES_SEEDS = (0, 1, 2, 3, 4)


@pytest.fixture(scope="module")
def thesis_runs_20s():
    """Both variants on thesis, 20 s, seeds 0-4: (NEES per seed, summary of seed 0)."""
    from controllers.solnic.diagnostics import mode2_nees
    out = {}
    for name in ("solnic", "solnic-modern"):
        nees, summary = [], None
        for seed in NEES_SEEDS:
            r = run_closed_loop(PlantParams(), get_controller(name)(), duration_s=20.0, warmup_s=5.0,
                                seed=seed, record=True)
            assert r.status == "ok", r.message
            nees.append(mode2_nees(r.samples, r.internals, 5.0))
            summary = summary or r.summary
        out[name] = (nees, summary)
    return out


def test_modern_mode2_filter_is_consistent_on_thesis(thesis_runs_20s):
    """NEES of (x̂1, x̂4) against the true state, stuck samples from 5 s: ≈ 1 when honest.

    The statistic is the median over seeds 0-4: one seed's NEES over 20 s moves by several
    units with the closed loop's chaotic path (seed 0: 0.8 before, 4.4 after a 0.5 % change in
    the noise model's push term). The faithful filter (noise-free internal model, no w2 term in
    (5-9)) is far from it; the test states that too, so that a change making it honest shows up.
    """
    nees, summary = thesis_runs_20s["solnic-modern"]
    assert all(n["n"] > 500 for n in nees)
    assert 0.5 <= np.median([n["nees"] for n in nees]) <= 2.0
    assert 0.5 <= np.median([n["nees_x1"] for n in nees]) <= 2.0
    assert np.median([n["nees"] for n in thesis_runs_20s["solnic"][0]]) > 10.0


# ---------------------------------------------------------------- start-up on the k_s/k_c ridge
def test_grid_posterior_starts_up_off_the_ridge():
    """Quiet-friction seed 2 (true k_s 2.21, k_c 1.51) from the section-7.3 start: the joint
    EKF alone runs onto the k_s/k_c ridge (k̂s ≈ 3.8) and fires ~70 µrad pulses past 20 s; with
    the grid posterior (solnic-modern) the 20–30 s window stays under the classical limit and
    k̂ ends near the truth. 30 s runs, scored from 20 s."""
    p = PlantParams().replace(friction_noise_psd=0.0)
    bound = p.classical_bound()
    modern = get_controller("solnic-modern")
    with_grid = run_closed_loop(p, modern(), duration_s=30.0, warmup_s=20.0, seed=2)
    without = run_closed_loop(p, modern(friction_grid=False), duration_s=30.0, warmup_s=20.0, seed=2)
    assert with_grid.status == "ok" and without.status == "ok"
    assert with_grid.metrics["peak_error_rad"] < bound < without.metrics["peak_error_rad"]
    assert without.summary["ks_hat"] > 3.0
    assert abs(with_grid.summary["ks_hat"] - 2.21) < 0.5
