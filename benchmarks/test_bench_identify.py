"""The identification's noise-free model (issue 25): one prediction of the default plan's 120 moves.

``_Model.predict`` is what every least-squares evaluation and every finite-difference Jacobian
column of ``fit_log`` and ``choose_family`` costs. Lugre: the whole prediction in one compiled call
(``plant.lugre.move_loop.play_all``) against a compiled call per move (the path before); multimode
(lugre's and two-mass's nested fit, and every multimode fit): a compiled call per move
(``plant.multimode.move_loop``) against the Python loop over ``advance``. Both paths give the same
numbers, bit for bit (tests/test_identify_speed.py). ``make test`` runs each body once;
``test_prediction_speedup`` (``make benchmark`` only) asserts the ratio, both paths timed
alternately in this process (the machine may be loaded: a ratio, not a time).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from plant.identification import design_experiment
from plant.identification.fit import _Model
from plant.protocol import get_family

_POINTS = {"lugre": [1.2, 0.5, 0.5, 0.008, 0.004, 2e5], "multimode": [1.2, 0.5, 0.5, 0.008]}


def _model(family: str, fast: bool) -> tuple[_Model, np.ndarray]:
    plan = design_experiment()
    log = plan.with_y(np.zeros(plan.n))
    fam = get_family(family)
    base = fam.Params().replace(u_max=max(float(log.u_max), fam.Params().u_max), sample_period=log.sample_period)
    model = _Model(log, family, base)
    if family == "lugre":
        model.whole_moves = fast
    else:
        model.compiled_moves = fast
    z = np.log(_POINTS[family])
    model.predict(z)          # compiled code loaded, the move tables built
    return model, z


@pytest.mark.parametrize("family", ["lugre", "multimode"])
@pytest.mark.parametrize("fast", [True, False], ids=["fast", "before"])
def test_prediction(benchmark, family, fast):
    model, z = _model(family, fast)
    pred = benchmark(model.predict, z)
    assert pred is not None and pred.shape == model.rows.shape


# lugre: measured 1.45–1.7× (2026-11-27, loaded 2-core machine); multimode 1.4–1.6×
_GOAL = {"lugre": 1.3, "multimode": 1.2}


@pytest.mark.parametrize("family", ["lugre", "multimode"])
def test_prediction_speedup(benchmark, family):
    if benchmark.disabled:
        pytest.skip("a timing only (make benchmark)")
    fast, z = _model(family, True)
    before, _ = _model(family, False)
    spent = {True: [], False: []}
    for _ in range(7):
        for flag, m in ((True, fast), (False, before)):
            t0 = time.process_time()
            for _ in range(3):
                m.predict(z)
            spent[flag].append(time.process_time() - t0)
    ratio = float(np.median(spent[False]) / np.median(spent[True]))
    benchmark.extra_info["speedup"] = ratio
    benchmark.pedantic(fast.predict, args=(z,), rounds=1, iterations=1)
    assert ratio >= _GOAL[family], f"{family}: {ratio:.2f}x"


# The fit's lugre tolerance (issue 25, tenth session, fit._LUGRE_TOLERANCES: RTOL 1e-8) against the plant's
# own (1e-10, the path before): one default-plan prediction in the draws' region (σ0 = 2e5) and at σ0 = 1e6,
# both timed alternately in this process. Measured 1.76–2.19× (dev log B's truth and a stiffer / softer
# point, σ0 ≤ 6.8e5) and, in this benchmark's first run, 1.64× at 2e5 and 1.22× at 1e6 (there the step
# is partly stability-bound, which no tolerance shortens); loaded 2-core machine. Asserted ≥ 1.4 at 2e5
# only; the 1e6 ratio is recorded.
_TOL_GOAL = 1.4


def test_prediction_tolerance_speedup(benchmark):
    if benchmark.disabled:
        pytest.skip("a timing only (make benchmark)")
    from plant.lugre.integrate import TOLERANCES

    fit, _ = _model("lugre", True)
    plant, _ = _model("lugre", True)
    plant.lugre_tolerances = TOLERANCES
    fit.lugre_stiff = plant.lugre_stiff = 0.0     # the tolerance alone (the stiff-sliding step: tests/test_identify_stiff.py)
    ratios = []
    for point in ([1.2, 0.5, 0.5, 0.008, 0.006, 2e5], _POINTS["lugre"][:5] + [1e6]):
        z = np.log(point)
        fit.predict(z)
        plant.predict(z)
        spent = {True: [], False: []}
        for _ in range(5):
            for flag, m in ((True, fit), (False, plant)):
                t0 = time.process_time()
                for _ in range(3):
                    m.predict(z)
                spent[flag].append(time.process_time() - t0)
        ratios.append(float(np.median(spent[False]) / np.median(spent[True])))
    benchmark.extra_info["speedup"] = ratios
    benchmark.pedantic(fit.predict, args=(np.log(_POINTS["lugre"]),), rounds=1, iterations=1)
    assert ratios[0] >= _TOL_GOAL, ratios


# The fit's stiff-sliding step (issue 25, eleventh session): one prediction on a low-friction axis at the fit's
# σ0 cap, with it and with Dormand–Prince alone, alternately. Measured 23× (131.7 / 5.6 ms, load ≈ 5); asserted ≥ 5.
_STIFF_POINT = [0.665, 0.55, 0.8, 0.008, 0.0052, 3e6]
_STIFF_GOAL = 5.0


def test_prediction_stiff_step_speedup(benchmark):
    if benchmark.disabled:
        pytest.skip("a timing only (make benchmark)")
    stiff, _ = _model("lugre", True)
    explicit, _ = _model("lugre", True)
    explicit.lugre_stiff = 0.0
    z = np.log(_STIFF_POINT)
    stiff.predict(z)
    explicit.predict(z)
    spent = {True: [], False: []}
    for _ in range(3):
        for flag, m in ((True, stiff), (False, explicit)):
            t0 = time.process_time()
            m.predict(z)
            spent[flag].append(time.process_time() - t0)
    ratio = float(np.median(spent[False]) / np.median(spent[True]))
    benchmark.extra_info["speedup"] = ratio
    benchmark.pedantic(stiff.predict, args=(z,), rounds=1, iterations=1)
    assert ratio >= _STIFF_GOAL, ratio
