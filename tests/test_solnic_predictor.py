"""The solnic internal plant model against the plant's own pulse response."""

import math

import numpy as np
import pytest

from controllers.solnic.predictor import Predictor, peak_torque
from controllers.models.acker import pulse_response  # the model the predictor assumes (checked against the plant in test_acker_model.py)
from plant import PlantParams

P = PlantParams()


@pytest.mark.parametrize("ks,kc", [(2.1, 1.4), (1.05, 0.7), (1.9, 1.6), (3.0, 1.0)])
@pytest.mark.parametrize("dt_u", [0.6e-3, 1.0e-3, 1.36e-3, 1.5e-3, 2.5e-3])
def test_prediction_equals_pulse_response(ks, kc, dt_u):
    pred = Predictor(P).predict(ks, kc, dt_u)
    ref = pulse_response(P.replace(stiction=ks, coulomb=kc), dt_u)
    assert pred.delta_c == ref.delta_c
    assert pred.t_nominal == ref.t_stop
    assert pred.t_current_zero == ref.t_current_zero
    assert pred.t_breakaway == ref.t_breakaway


def test_sign_flips_motion_and_partials():
    pr = Predictor(P)
    plus, minus = pr.predict(2.1, 1.4, 1.4e-3, 1), pr.predict(2.1, 1.4, 1.4e-3, -1)
    assert minus.delta_c == -plus.delta_c
    np.testing.assert_array_equal(minus.H_b, -plus.H_b)
    assert minus.delta_c == pytest.approx(pulse_response(P, 1.4e-3, sign=-1).delta_c, rel=1e-12)


def _central(ks, kc, dt_u, which, h=1e-3):
    def f(dk):
        k = [kc, ks]
        k[which] += dk
        r = pulse_response(P.replace(stiction=k[1], coulomb=k[0]), dt_u)
        return np.array([r.delta_c, r.t_stop])
    return (f(h) - f(-h)) / (2 * h)


@pytest.mark.parametrize("ks,kc,dt_u", [(2.1, 1.4, 1.2745e-3), (2.1, 1.4, 1.36e-3), (2.1, 1.4, 1.443e-3),
                                        (1.7, 1.5, 1.36e-3), (2.1, 1.4, 2.0e-3)])
def test_quasipartials_match_central_differences(ks, kc, dt_u):
    pred = Predictor(P).predict(ks, kc, dt_u)
    for which in (0, 1):
        ref = _central(ks, kc, dt_u, which)
        assert pred.H_b[which] == pytest.approx(ref[0], rel=1e-2)
        assert pred.H_tb[which] == pytest.approx(ref[1], rel=1e-2, abs=1e-9)


def test_quasipartials_backward_step_at_ks_equal_kc():
    pred = Predictor(P).predict(1.5, 1.5, 1.4e-3)          # k̂c + δ would exceed k̂s
    ref = _central(1.5, 1.5 - 2e-3, 1.4e-3, 0)
    assert math.isfinite(pred.H_b[0]) and pred.H_b[0] < 0
    assert pred.H_b[0] == pytest.approx(ref[0], rel=5e-2)


def test_no_motion_below_breakaway_and_conditional_prediction():
    pr = Predictor(P)
    dt_u = 0.85e-3
    assert peak_torque(P, dt_u) == pytest.approx(P.u_max * (1 - math.exp(-dt_u / P.motor_time_constant)))
    pred = pr.predict(2.1, 1.4, dt_u)
    assert pred.delta_c == 0.0 and not pred.moves
    np.testing.assert_array_equal(pred.H_b, [0.0, 0.0])
    cond = pr.conditional(2.1, 1.4, dt_u)
    # given motion, stiction lies just below the peak torque: the smallest motion Δc_min
    ref = pulse_response(P.replace(stiction=peak_torque(P, dt_u) * (1 - 1e-6), coulomb=1.4), dt_u)
    assert cond.delta_c == pytest.approx(ref.delta_c, rel=1e-9) and cond.delta_c > 0


def test_invalid_inputs_raise():
    pr = Predictor(P)
    with pytest.raises(ValueError, match="sign"):
        pr.predict(2.1, 1.4, 1e-3, sign=0)
    with pytest.raises(ValueError, match="dt_u"):
        pr.predict(2.1, 1.4, -1e-3)
    with pytest.raises(ValueError, match="kc <= ks"):
        pr.response(1.0, 1.4, 1e-3)
    with pytest.raises(ValueError, match="fd_step"):
        Predictor(P, fd_step=0.0)


def _outcome(call):
    try:
        return call()
    except (ValueError, RuntimeError) as e:
        return type(e), str(e)


@pytest.mark.parametrize("brake_margin", [None, 0.75, 2.0])
def test_compiled_prediction_equals_the_step_by_step_path_to_the_bit(brake_margin):
    """The compiled predictor (the plant's own model) against the Python path through
    ``response`` (the same model injected), bit for bit, errors included, on random estimates
    around and outside the valid set (k̂c = 0 coasts for ever, k̂c > k̂s is invalid)."""
    rng = np.random.default_rng(7)
    fast = Predictor(P, brake_margin=brake_margin)
    slow = Predictor(P, brake_margin=brake_margin, response_fn=pulse_response)
    kinds = set()
    for i in range(400):
        ks = rng.uniform(0.0, 1.05 * P.u_max)
        kc = (ks, 0.0, rng.uniform(-0.1, 1.1 * ks))[i % 3]
        dt_u = (0.0, rng.uniform(0.0, 4e-3), rng.uniform(0.8e-3, 2e-3))[i % 3]
        for method in ("predict", "conditional"):
            a = _outcome(lambda: getattr(fast, method)(ks, kc, dt_u, sign=1 - 2 * (i % 2)))
            b = _outcome(lambda: getattr(slow, method)(ks, kc, dt_u, sign=1 - 2 * (i % 2)))
            if isinstance(b[0], type):
                kinds.add(b[0].__name__)
                assert a == b
                continue
            kinds.add("brake" if b.t_off is not None else "moves" if b.moves else "none")
            for name in ("dt_u", "sign", "delta_c", "t_nominal", "t_breakaway", "t_current_zero",
                         "peak_torque", "t_off"):
                assert getattr(a, name) == getattr(b, name) or (math.isnan(getattr(a, name))
                                                                and math.isnan(getattr(b, name))), name
            np.testing.assert_array_equal(a.H_b, b.H_b)
            np.testing.assert_array_equal(a.H_tb, b.H_tb)
    assert {"EstimateOutOfRange", "moves", "none"} <= kinds   # EstimateOutOfRange is a ValueError
    assert ("brake" in kinds) == (brake_margin is not None)
