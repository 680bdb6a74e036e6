"""The power ceiling of ``--family auto``'s rule before any fitting (issue 25, eighth session).

On a dev log of a family, the generating family *at its true parameters* (effective k̄c, k̄s, no
fit) and multimode at its own fold fits (:func:`choose_family` with ``families=["multimode"]``)
predict every held-out move; for each feature set (:data:`plant.identification.fit._WINDOW_SPEC`
form) the per-move −2 ln p and Wilcoxon's signed-rank z of multimode against the truth is what the
rule could see with a perfect fit of the richer law. The noisy replicates are simulated once per
(family, parameters, fold) and every feature set is read off the same ones (common random numbers,
as :func:`_predictive_features`). Run: ``python -m tests.identify_power SEED FAMILY CASE …``.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from plant.identification import design_experiment, simulate_log
from plant.identification import fit as F
from plant.identification.families import FAMILY_FREE
from plant.protocol import get_family

# candidate feature sets: (pieces of the on-span, windows after it, last window)
SPECS = {
    "today": (2, (5,), 10),
    "after1x5": (2, (1, 1, 1, 1, 1), 10),
    "after1x5+5+5": (2, (1, 1, 1, 1, 1, 5, 5), 10),
    "on4": (4, (5,), 10),
    "on4+after1x5": (4, (1, 1, 1, 1, 1), 10),
    "on4+after2x5": (4, (2, 2, 2, 2, 2), 10),
}


def dev_log(family: str, case: int, seed: int, options=None):
    """The ``case``-th axis of ``default_rng([seed, f])`` (tests/identify_draws.py), its log (log
    seed seed·1000 + 100·f + case, the plan of ``options`` — default: the default plan —, Table
    2-1 noise), the base params and the true z."""
    from plant.identification import ExperimentOptions

    from tests.identify_draws import draw

    f = list(FAMILY_FREE).index(family)
    rng = np.random.default_rng([seed, f])
    for _ in range(case + 1):
        p = draw(family, rng)
    log, truth = simulate_log(design_experiment(options or ExperimentOptions()), family, p, seed * 1000 + 100 * f + case)
    fam = get_family(family)
    base = fam.Params().replace(u_max=max(float(log.u_max), fam.Params().u_max), sample_period=log.sample_period)
    z = [math.log(truth["coulomb"]), math.log(truth["stiction"] - truth["coulomb"]), math.log(p.inertia),
         math.log(p.motor_time_constant)] + [math.log(getattr(p, k)) for k in FAMILY_FREE[family]]
    return log, base, np.array(z)


def replicates(log, family, base, z, test, seed=0, n=F._MC):
    """Noisy replicates of the moves ``test`` at z: (model, array [n × rows])."""
    from plant.randomness import NoiseStream

    model = F._Model(log, family, base, only=test)
    sims = []
    for i in range(n):
        def streams(g, i=i):
            return NoiseStream(np.random.default_rng(np.random.SeedSequence([seed, int(test[g]), i])), block=1024)
        sims.append(model.predict(z, streams))
    return model, np.array(sims)


def scores(log, model, sims, spec, sigma1):
    """Per move of ``model``: −2 ln p of the measured features under the replicates' t predictive."""
    wins = F._windows(model, spec)
    feats, start = [], 0
    for g, idx in enumerate(model.index):
        rows = slice(start, start + idx.size)
        start += idx.size
        y = log.y[model.rows[rows]]
        feats.append((np.array([y[w].mean() for w in wins[g]]),
                      np.array([[s[rows][w].mean() for w in wins[g]] for s in sims]),
                      np.array([w.size for w in wins[g]])))
    return F._score_features(feats, sigma1, F._NU)


def ceiling(family: str, case: int, seed: int, specs=SPECS, mm_spec=None, options=None):
    """Per feature set: (mean excess of multimode over the truth per move, signed-rank z, moves
    worse / better), multimode at its fold fits under ``mm_spec`` (default: today's)."""
    log, base, z = dev_log(family, case, seed, options)
    sigma1 = max(F._sigma1(log, F.moves(log))[0], 1e-12)
    keep = F._WINDOW_SPEC
    if mm_spec is not None:
        F._WINDOW_SPEC = mm_spec
    try:
        _, choice = F.choose_family(log, ["multimode"], bootstrap=0, final_fit=False)
    finally:
        F._WINDOW_SPEC = keep
    fold = F._folds(log)
    G = len(F.moves(log))
    out = {}
    per = {name: {"truth": np.empty(G), "multimode": np.empty(G)} for name in specs}
    mm_base = get_family("multimode").Params().replace(u_max=base.u_max, sample_period=log.sample_period)
    for k in (0, 1):
        test = list(np.flatnonzero(fold == k))
        mt, st = replicates(log, family, base, z, test)
        mm, sm = replicates(log, "multimode", mm_base, choice.fold_fits["multimode", k], test)
        for name, spec in specs.items():
            per[name]["truth"][test] = scores(log, mt, st, spec, sigma1)
            per[name]["multimode"][test] = scores(log, mm, sm, spec, sigma1)
    for name in specs:
        a, b = per[name]["multimode"], per[name]["truth"]
        w, sd = F._signed_rank(a, b)
        worse, better = F._sign_counts(a, b)
        out[name] = (float(np.mean(a - b)), w / sd if sd else 0.0, worse, better)
    return out, per


if __name__ == "__main__":
    seed = int(sys.argv[1])
    for family, case in zip(sys.argv[2::2], sys.argv[3::2]):
        c0 = time.process_time()
        res, _ = ceiling(family, int(case), seed)
        print(family, case, f"cpu {time.process_time() - c0:.0f}", flush=True)
        for name, (ex, zz, worse, better) in res.items():
            print(f"  {name:14s} excess {ex:+8.2f}  z {zz:5.2f}  ({worse}, {better})", flush=True)
