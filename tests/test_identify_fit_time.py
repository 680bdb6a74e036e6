"""Where a lugre fit's work is bounded (issue 25, tenth session): the point fit's box caps σ0 at 3e6
ozf·in/rad (fit._FIT_CAP; the other extras and families keep a factor 30 from their start), and a lugre
bootstrap replicate's final least-squares pass stops after 10 evaluations per parameter
(fit._REPLICATE_FINAL_NFEV) while the point fit's keeps 60. The prediction's cost against σ0 (the
reason for the cap) is checked on the work clock, which counts Dormand–Prince steps."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from plant.identification import design_experiment
from plant.identification import fit as fitmod
from plant.protocol import get_family


def _log(family):
    plan = design_experiment()
    fam = get_family(family)
    base = fam.Params().replace(u_max=max(float(plan.u_max), fam.Params().u_max), sample_period=plan.sample_period)
    return plan.with_y(np.random.default_rng(0).standard_normal(plan.n) * 5e-6), base


def _passes(monkeypatch, family, z0, **kw):
    """The (bounds, max_nfev) of every least-squares pass of _point_fit from z0 (the passes stand in: each
    returns its start, so only the wiring is exercised)."""
    seen = []

    def spy(fun, x0, args=(), bounds=None, max_nfev=None, **_):
        seen.append((bounds, max_nfev))
        r = fun(x0, *args)
        return types.SimpleNamespace(x=np.array(x0), fun=r, jac=np.zeros((r.size, x0.size)), cost=0.5 * r @ r)

    monkeypatch.setattr(fitmod.optimize, "least_squares", spy)
    log, base = _log(family)
    fitmod._point_fit(log, family, base, z0=np.array(z0), **kw)
    return seen


def test_lugre_box_caps_sigma0_at_3e6_and_keeps_factor_30_elsewhere(monkeypatch):
    z0 = np.log([1.2, 0.5, 0.5, 0.008, 4e-3, 1e6])
    for (lo, hi), _ in _passes(monkeypatch, "lugre", z0):
        assert hi[5] == pytest.approx(math.log(3e6), abs=1e-12)          # min(1e6·30, 3e6)
        assert lo[5] == pytest.approx(math.log(1e6 / 30), abs=1e-12)
        assert hi[4] == pytest.approx(math.log(4e-3 * 30), abs=1e-12)    # v_s: factor 30, uncapped
        assert np.all(np.isinf(hi[:4]))


def test_two_mass_box_keeps_factor_30(monkeypatch):
    z0 = np.log([1.2, 0.5, 0.5, 0.008, 1.5e4])
    for (lo, hi), _ in _passes(monkeypatch, "two-mass", z0):
        assert hi[4] - lo[4] == pytest.approx(2 * math.log(30.0), abs=1e-12)


def test_final_pass_evaluations(monkeypatch):
    z0 = np.log([1.2, 0.5, 0.5, 0.008, 4e-3, 2e5])
    point = [n for _, n in _passes(monkeypatch, "lugre", z0)]
    assert point == [360, 360, 360]                       # two passes and the final one, 60 per parameter
    replicate = [n for _, n in _passes(monkeypatch, "lugre", z0, final_nfev=fitmod._REPLICATE_FINAL_NFEV["lugre"])]
    assert replicate == [360, 360, 60]                    # the final pass: 10 per parameter


def test_replicates_pass_their_family_cap(monkeypatch):
    """_replicate hands lugre's cap (10) to its point fit; two-mass keeps the point fit's 60."""
    seen = []

    def stand_in(log, family, base, z0=None, deadline=math.inf, points=None, clock=None, final_nfev=60):
        seen.append((family, final_nfev))
        return np.zeros(4 + len(fitmod.FAMILY_FREE[family])), None, 5e-6, 1, None, None, False

    monkeypatch.setattr(fitmod, "_point_fit", stand_in)
    plan = design_experiment()
    for family, extras in (("lugre", [4e-3, 2e5]), ("two-mass", [1.5e4])):
        p = get_family(family).Params().replace(coulomb=1.2, stiction=1.7, inertia=0.5, motor_time_constant=0.008)
        kind, _, _ = fitmod._replicate(plan, family, p, 3, p, None, np.log(extras), None, None, math.inf,
                                       fitmod._WorkClock())
        assert kind == "ok"
    assert seen == [("lugre", 10), ("two-mass", 60)]


def test_prediction_work_grows_with_sigma0():
    """The reason for the cap (tenth session): above ≈ 1e6 the explicit step is stability-bound and a
    prediction's counted Dormand–Prince steps grow ∝ σ0 (plant/lugre/integrate.py: h ≲ 3.3·g/(σ0·|v|)
    while sliding). The fit's stiff-sliding step (eleventh session, ``_Model.lugre_stiff``) removes most
    of that growth: from 3e5 to 3e7 its counted work grows < 5× (measured 3.3×; Dormand–Prince alone 50×)."""
    log, base = _log("lugre")
    model = fitmod._Model(log, "lugre", base)
    explicit = fitmod._Model(log, "lugre", base)
    explicit.lugre_stiff = 0.0        # Dormand–Prince alone (the path the cap was measured on)
    work, work_stiff = {}, {}
    for s0 in (3e5, 3e6, 3e7):
        for m, w in ((explicit, work), (model, work_stiff)):
            m.clock = fitmod._WorkClock()
            assert m.predict(np.log([1.2, 0.5, 0.5, 0.008, 6e-3, s0])) is not None
            w[s0] = m.clock.spent
    assert work[3e7] > 4.0 * work[3e6] > 4.0 * work[3e5]
    print({s0: (round(work[s0], 4), round(work_stiff[s0], 4)) for s0 in work})
    assert work_stiff[3e7] < 5.0 * work_stiff[3e5] and work_stiff[3e7] < 0.1 * work[3e7]
