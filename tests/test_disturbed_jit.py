"""The compiled disturbed plant (plant.multimode.disturbed_jit, disturbed_loop) against the Python
reference (plant.multimode.disturbed.advance_python), bit for bit.

* the sub-step's matrix-vector product (the one routine that keeps a BLAS kernel's order) equals
  numpy's bit for bit where numpy's OpenBLAS is that kernel (the factorizations are
  plant.fixed_linalg's, checked against LAPACK in tests/test_fixed_linalg.py);
* pulse trains (bridge and linear drives, noisy and noise-free, a strong disturbance that keeps
  the shaft breaking loose) give identical states, integrals, counts and event records;
* closed loops: the runner's Python loop with the Python step, with the compiled step, and the
  compiled linear-law loop give identical rows;
* the zero-width crossing probability warns no more and is still 0.

Both paths do their linear algebra with the same fixed-order routines (no BLAS or LAPACK), so the
path comparisons hold on every CPU. The product equals numpy's only where this machine's OpenBLAS
sums as the kernel does (Haswell/Zen dgemv order): :func:`_blas_sums_as_the_kernel` probes that
once; elsewhere (e.g. an AVX-512 SkylakeX kernel, tried here with OPENBLAS_CORETYPE unset) it is
checked to 1e-13 of the terms' scale. The compiled path's law is checked against Euler–Maruyama
in tests/test_disturbance_torque.py.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from bench.runner import run_closed_loop
from bench.scenarios import builtin_scenarios
from controllers import make_controller
from plant import DriveCommand, DriveType, PlantParams
from plant.multimode import disturbed, disturbed_jit, disturbed_loop
from plant.protocol import get_family
from plant.randomness import NoiseStream
from plant.state import SimOptions

_SCEN = builtin_scenarios()["disturbed"]


def _blas_sums_as_the_kernel() -> bool:
    """Whether numpy's BLAS on this machine sums a matrix-vector product in the kernel's order."""
    rng = np.random.default_rng(2)
    for n in (2, 3, 5, 8):
        for _ in range(50):
            A = rng.standard_normal((n, n)) * np.exp(3.0 * rng.standard_normal((n, n)))
            x = rng.standard_normal(n)
            out = np.empty(n)
            disturbed_jit._gemv(A, x, out)
            if not np.array_equal(out, A @ x):
                return False
    return True


_SAME_BLAS = _blas_sums_as_the_kernel()
_STRONG = PlantParams(disturbance_torque_std=1.2, disturbance_torque_tau=0.005)


def _train(adv, p, seed, n, drive, opts, x5=0.1):
    ns = NoiseStream.from_seed(seed)
    s = disturbed.initial_state(p, x5)
    out = []
    for k in range(n):
        if drive is DriveType.BRIDGE:
            lvl = p.u_max if k % 7 == 0 else -p.u_max if k % 7 == 3 else 0.0
            cmd = DriveCommand.hold(lvl, drive) if k % 5 else DriveCommand(
                ((0.0, lvl), (0.3 * p.sample_period, -lvl), (0.7 * p.sample_period, 0.0)), drive)
        else:
            cmd = DriveCommand.hold(p.u_max * np.sin(0.37 * k) * (1.2 if k % 9 == 0 else 0.6), drive)
        r = adv(s, cmd, p, ns if opts.noise else None, opts, record=True)
        out.append((r.state.t, r.state.x.tobytes(), r.state.mode, r.state.flyback, r.status, r.message,
                    r.peak_abs_error, r.int_abs_current, r.int_sq_current, r.supply_charge, r.duration, r.n_events,
                    r.n_breakaways, r.n_sticks, r.n_substeps, {k: v.tobytes() for k, v in r.events.items()}))
        s = r.state
    return out


@pytest.mark.parametrize("p", [_SCEN.params, _STRONG], ids=["disturbed", "strong"])
@pytest.mark.parametrize("drive", [DriveType.BRIDGE, DriveType.LINEAR])
def test_pulse_trains_are_the_python_path_bit_for_bit(p, drive):
    events = 0
    for seed in range(6):
        fast = _train(disturbed.advance, p, seed, 60, drive, SimOptions())
        assert fast == _train(disturbed.advance_python, p, seed, 60, drive, SimOptions()), seed
        events += sum(r[11] for r in fast)
    quiet = SimOptions(noise=False)
    assert _train(disturbed.advance, p, 0, 40, drive, quiet) == _train(disturbed.advance_python, p, 0, 40, drive, quiet)
    assert events > 20          # the trains do break loose, stick and reverse


@pytest.mark.parametrize("controller", ["linear", "pulse-width"])
def test_closed_loops_are_the_python_path_bit_for_bit(controller, monkeypatch):
    fam = get_family("multimode")
    assert fam.law_loop(_SCEN.params) is disturbed_loop.run_law
    kw = dict(duration_s=0.6, warmup_s=0.1, family=_SCEN.family, model=_SCEN.model)
    events = 0
    for seed in (0, 3):
        fast = run_closed_loop(_SCEN.params, make_controller(controller), seed=seed, **kw)
        plain = run_closed_loop(_SCEN.params, make_controller(controller), seed=seed, compiled=False, **kw)
        with monkeypatch.context() as m:
            m.setattr(disturbed, "advance", disturbed.advance_python)
            ref = run_closed_loop(_SCEN.params, make_controller(controller), seed=seed, compiled=False, **kw)
        for res in (fast, plain):
            assert (res.status, res.message, res.summary, res.simulated_s) == (ref.status, ref.message, ref.summary,
                                                                              ref.simulated_s)
            assert _untimed(res.metrics) == _untimed(ref.metrics), (controller, seed)
        events += ref.metrics["n_events"]
    assert events > 0 or controller == "linear"     # linear holds the shaft moving: no event in 0.6 s


def _untimed(metrics):
    return {k: v for k, v in metrics.items() if k not in ("runtime_s", "realtime_factor")}


def test_zero_width_crossing_probability_is_0_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert disturbed._cross_prob(np.float64(0.3), np.float64(0.2), 0.0, 1.0) == 0.0
        assert disturbed._cross_prob(np.float64(0.3), np.float64(-0.2), 0.0, 1.0) == 1.0
        assert disturbed_jit._cross_prob(0.3, 0.2, 0.0, 1.0) == 0.0


def test_chatter_divergence_and_bad_levels_are_the_python_paths():
    statuses = set()
    for opts in (SimOptions(max_events=3), SimOptions(diverge_error=2e-3)):
        for seed in range(3):
            fast = _train(disturbed.advance, _STRONG, seed, 40, DriveType.BRIDGE, opts)
            assert fast == _train(disturbed.advance_python, _STRONG, seed, 40, DriveType.BRIDGE, opts)
            statuses |= {r[4].value for r in fast}
    assert {"chatter", "diverged"} <= statuses
    s = disturbed.initial_state(_STRONG, 0.0)
    bad = DriveCommand.hold(0.5 * _STRONG.u_max, DriveType.BRIDGE)
    for adv in (disturbed.advance, disturbed.advance_python):
        with pytest.raises(ValueError, match="bridge drive levels must be 0 or ±u_max"):
            adv(s, bad, _STRONG, NoiseStream.from_seed(0), SimOptions())


def test_kernel_matrix_vector_product_is_numpys_bit_for_bit():
    """The sub-step's hand-written dgemv order (disturbed_jit._gemv) against numpy's A @ x: bit for
    bit where the BLAS sums as the kernel does, to 1e-13 of the terms' scale everywhere."""
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 4, 5, 6, 7, 8):
        out = np.empty(n)
        for _ in range(500):
            A = rng.standard_normal((n, n)) * np.exp(3.0 * rng.standard_normal((n, n)))
            x = rng.standard_normal(n) * np.exp(3.0 * rng.standard_normal(n))
            disturbed_jit._gemv(A, x, out)
            if _SAME_BLAS:
                assert np.array_equal(out, A @ x), n
            else:
                assert np.all(np.abs(out - A @ x) <= 1e-13 * (np.abs(A) @ np.abs(x))), n


def test_transition_cache_slots_separate_widths_that_differ_in_low_bits():
    """An interval's last sub-step has width t_end − t, which differs from a ladder width only in
    mantissa bits below ulp(t) (whose own last bits are zeros). Hashing only the top 30 mantissa
    bits put all such widths in one slot, where they evicted each other. 64 such widths next to
    0.4 ms (t near 50 s) and the 12 ladder widths must spread over the 1024 slots as random keys
    would (the expected number of distinct slots for 76 random keys is ~73)."""
    ulp = np.spacing(50.0)
    widths = [4e-4 + k * ulp for k in range(1, 65)] + [1e-4 * 2.0 ** j for j in range(12)]
    slots = {disturbed_jit._slot(2, w, disturbed_jit._NT_BITS) for w in widths}
    assert all(0 <= k < disturbed_jit._NT for k in slots)
    assert len(slots) >= 66
    # the mode is part of the key: the same width in the three modes
    assert len({disturbed_jit._slot(m, 4e-4, disturbed_jit._NT_BITS) for m in (1, 2, 3)}) == 3


# --- the compiled loop of a controller step (disturbed_loop.run_compiled_law) --------------------

def _loop(controller, params, seed, duration, **kw):
    """A run and the number of samples the controller's Python ``step`` did."""
    calls = []
    step = controller.step
    controller.step = lambda y: calls.append(1) or step(y)
    r = run_closed_loop(params, controller, duration_s=duration, warmup_s=0.5, seed=seed, family=_SCEN.family,
                        model=_SCEN.model, **kw)
    return r, len(calls)


def _delayed_quantized():
    import dataclasses
    return dataclasses.replace(_SCEN.params, command_delay=2e-3, quantization=1e-6)


@pytest.mark.parametrize("name", ["pulse-width", "reset-pid", "observer-pid", "friction-ff-pid", "linear", "solnic",
                                  "pulses"])
def test_compiled_steps_on_the_disturbed_plant_are_the_python_rows(name):
    """Every controller with a compiled step (a linear law through CompiledLaw, solnic's idle step
    with its hand-backs, bridge pulses) runs on the disturbed plant with a 2 ms delay and a 1 µrad
    quantizer in the compiled loop, and its row, x1 log and final state are those of the runner's
    Python loop (plant.multimode.disturbed.advance per sample), exactly."""
    from tests.test_compiled_law import _Pulses
    p = _delayed_quantized()
    make = _Pulses if name == "pulses" else (lambda: make_controller(name))
    fam = get_family("multimode")
    assert fam.law_loop(p) is None and fam.compiled_loop(p) is disturbed_loop.run_compiled_law
    fast, n_fast = _loop(make(), p, 7, 3.0)
    logged, n_logged = _loop(make(), p, 7, 3.0, x1_log=True)
    plain, n_plain = _loop(make(), p, 7, 3.0, compiled=False)
    recorded, _ = _loop(make(), p, 7, 3.0, record=True)
    assert n_plain == 300
    if name == "solnic":                     # hands its pulse cycles back, the idle samples compiled
        assert 0 < n_fast < 150 and n_logged == n_fast
    else:
        assert n_fast == n_logged == 0
    assert fast.status == "ok" and plain.metrics["n_events"] > 0
    for res in (fast, logged, recorded):
        assert (res.status, res.message, res.summary, res.simulated_s) == (plain.status, plain.message, plain.summary,
                                                                          plain.simulated_s)
        assert _untimed(res.metrics) == _untimed(plain.metrics), name
    for part in ("samples", "events"):
        for key in ("t", "x1"):
            np.testing.assert_array_equal(getattr(logged, part)[key], getattr(recorded, part)[key])


def test_the_compiled_step_loop_is_the_python_reference_kernel(monkeypatch):
    """Anchored on the plain Python kernel (advance_python): pulse-width on the disturbed plant,
    delayed and quantized, and on the built-in scenario."""
    for p in (_SCEN.params, _delayed_quantized()):
        fast, n_fast = _loop(make_controller("pulse-width"), p, 5, 0.8)
        with monkeypatch.context() as m:
            m.setattr(disturbed, "advance", disturbed.advance_python)
            ref, _ = _loop(make_controller("pulse-width"), p, 5, 0.8, compiled=False)
        assert n_fast == 0 and ref.metrics["n_events"] > 0
        assert (fast.status, fast.summary, _untimed(fast.metrics)) == (ref.status, ref.summary, _untimed(ref.metrics))


def test_a_compiled_step_that_diverges_ends_as_the_python_loop():
    """A divergence inside the compiled loop: the same status, message and row as the Python loop."""
    from tests.test_compiled_law import _Handing
    opts = SimOptions(diverge_error=2e-5)
    rows = []
    for compiled in (True, False):
        r, _ = _loop(_Handing(hand_at=-1.0), _SCEN.params, 3, 3.0, options=opts, compiled=compiled)
        rows.append((r.status, r.message, r.summary, _untimed(r.metrics)))
    assert rows[0][0] == "diverged" and rows[0] == rows[1]


def test_the_x1_log_of_a_strong_disturbance_grows_its_scratch_and_redoes_the_sample(monkeypatch):
    """A strong disturbance (σd = 1.2 ozf·in, τd = 5 ms) under bridge pulses: intervals with several
    plant events overflow a one-row event scratch (disturbed_jit.RecordFull); the compiled loop
    undoes the sample, grows the scratch and redoes it, and the log is the recorded run's."""
    import bench.runner as runner
    from plant.law_driver import X1Log
    from tests.test_compiled_law import _Pulses

    made = []

    class _Tiny(X1Log):
        def __init__(self, n):
            super().__init__(n)
            self.events, self.scratch = np.empty((2, 2)), np.empty((1, self.scratch.shape[1]))
            made.append(self)

    monkeypatch.setattr(runner, "X1Log", _Tiny)
    rec, _ = _loop(_Pulses(), _STRONG, 2, 2.0, record=True)
    log, n_python = _loop(_Pulses(), _STRONG, 2, 2.0, x1_log=True)
    assert n_python == 0 and log.status == rec.status == "ok"
    assert made[0].scratch.shape[0] > 1 and made[0].events.shape[0] > 2      # both growth paths taken
    for part in ("samples", "events"):
        for key in ("t", "x1"):
            np.testing.assert_array_equal(getattr(log, part)[key], getattr(rec, part)[key])
    assert _untimed(log.metrics) == _untimed(rec.metrics)


def test_the_crossing_probability_skips_exp_only_where_exp_is_zero():
    """_cross_prob returns 0.0 without exp below _EXP_ZERO: exp is exactly +0 there (and at the
    next doubles above −745.1332… it is not yet 0, so the cut lies in exp's zero range)."""
    import math
    assert disturbed_jit._EXP_ZERO < -745.1332191019412
    for x in (disturbed_jit._EXP_ZERO, np.nextafter(disturbed_jit._EXP_ZERO, 0.0), -745.14, -1e4, -1e300):
        assert math.exp(x) == 0.0 and math.copysign(1.0, math.exp(x)) == 1.0
    assert math.exp(-745.13) > 0.0
    rng = np.random.default_rng(5)
    for _ in range(20000):
        va, vb = np.exp(rng.uniform(-30, 5, 2))
        w, sig2 = np.exp(rng.uniform(-25, 0)), np.exp(rng.uniform(-30, 5))
        fast = disturbed_jit._cross_prob(va, vb, w, sig2)
        assert fast == disturbed._cross_prob(float(va), float(vb), float(w), float(sig2))
        assert fast == math.exp(-2.0 * va * vb / (sig2 * w))


def test_a_far_rungs_crossing_stand_in_decides_as_the_crossing_probability():
    """On a far rung a sub-step crosses only when the probability is ≥ 1 (no uniform is drawn).
    _cross_prob_far returns _cross_prob's value whenever that can be 1.0 and a stand-in 0.0
    (without exp) only where the exponent is below −1: the decision prob ≥ 1 of one barrier and of
    a stuck shaft's two (1 − (1 − up)(1 − dn)), and the barrier chosen (up ≥ dn), are the same on
    random and edge inputs (end values ≤ 0, tiny, an exponent within ulps of 0, zero variance)."""
    import math
    rng = np.random.default_rng(11)
    far, exact = disturbed_jit._cross_prob_far, disturbed_jit._cross_prob
    edge = [0.0, -0.0, -1e-300, 5e-324, 1e-300, 1e-160, 1.0, 1e300, math.inf, -3.0]
    cases = [(a, b, 1e-3, 1e-6) for a in edge for b in edge] + [(1.0, 1.0, 0.0, 1.0), (1.0, 1.0, 1.0, 0.0)]
    for _ in range(30000):
        va, vb = rng.choice([-1.0, 1.0], 2) * np.exp(rng.uniform(-40, 5, 2))
        cases.append((va, vb, np.exp(rng.uniform(-25, 0)), np.exp(rng.uniform(-30, 5))))
    stand_ins = 0
    for va, vb, w, sig2 in cases:
        f, x = far(va, vb, w, sig2), exact(va, vb, w, sig2)
        assert (f >= 1.0) == (x >= 1.0) and (f == x or (f == 0.0 and x < 1.0))
        stand_ins += f != x
    assert stand_ins > 500                              # the stand-in is really taken
    for (a, b, w, s2), (c, d, _, _) in zip(cases[::2], cases[1::2]):
        up, dn, upf, dnf = exact(a, b, w, s2), exact(c, d, w, s2), far(a, b, w, s2), far(c, d, w, s2)
        crossed = 1.0 - (1.0 - up) * (1.0 - dn) >= 1.0
        assert crossed == (1.0 - (1.0 - upf) * (1.0 - dnf) >= 1.0)
        if crossed:
            assert (up >= dn) == (upf >= dnf)


def test_the_memoized_decay_and_torque_integrals_are_the_plain_ones_bit_for_bit():
    """_decay_memo (the last width's exp(−w/τ3) and torque_integrals' f1, f2) with _torque_f give
    the bits of exp and of plant.multimode.segments.torque_integrals, on memo hits and misses
    (widths repeated and alternated, x3 crossing zero or not, bridge and linear charge)."""
    import math
    from numba import njit
    from plant.multimode.segments import torque_integrals

    @njit
    def memo_step(x3, u, h, bridge, dp, lad, S):
        decay, f1, f2 = disturbed_jit._decay_memo(h, dp[disturbed_jit._TAU3], lad)
        disturbed_jit._torque_f(S, x3, u, h, bridge, dp, f1, f2)
        return decay

    dp = disturbed_jit._constants(_SCEN.params).copy()
    tau3, umax = dp[disturbed_jit._TAU3], dp[disturbed_jit._UMAX]
    lad = np.zeros(disturbed_jit._LAD_LEN)
    lad[disturbed_jit._MEMO] = np.nan
    rng = np.random.default_rng(12)
    widths = list(np.exp(rng.uniform(-14, -3, 6))) + [0.0]
    for i in range(6000):
        h = widths[(i // 3) % len(widths)] if i % 4 else widths[rng.integers(len(widths))]
        x3, u = rng.normal(0, 10, 2)
        if i % 5 == 0:
            u = -x3 * rng.uniform(0.1, 3.0)                # x3 crosses zero inside the width
        bridge = bool(i % 2)
        S = np.zeros(disturbed_jit.SHEET_SIZE)
        assert memo_step(x3, u, h, bridge, dp, lad, S) == math.exp(-h / tau3)
        integral, absolute, square = torque_integrals(x3, u, h, tau3)
        want = np.zeros(disturbed_jit.SHEET_SIZE)
        if h > 0:
            want[disturbed_jit._IABS], want[disturbed_jit._ISQ] = absolute, square
            want[disturbed_jit._CHG] = (u / umax) * integral if bridge else absolute
            want[disturbed_jit._DUR] = h
        assert S.tobytes() == want.tobytes(), i
