"""``--family auto``'s rule as a classifier, tuned on dev logs (issue 25, ninth session).

One process per log: :func:`choose_family` (``bootstrap=0``, no final point fit: the pick does not
depend on it) on the ``case``-th axis of ``default_rng([seed, f])`` (:func:`tests.identify_power.dev_log`)
under a plan of ``repeats`` pulses per width and direction; while it runs, every held-out score
(:func:`plant.identification.fit._predictive_scores`) is also read with the finer feature set
(:data:`~plant.identification.fit._FINER_WINDOW_SPEC`) off the *same* noisy replicates, so both
score sets come from one set of fold fits. Per log one JSON line (the per-move scores of each
family under each feature set, the choice's CPU seconds) is appended to ``OUT``; :func:`pick`
applies a rule (feature set, significance threshold) to it offline.

Run: ``python -m tests.identify_dev OUT SEED REPEATS FAMILY CASE [OPTION …]`` (each OPTION a boolean keyword of
:func:`~plant.identification.fit.choose_family` set True, e.g. ``shaft_profile``, or NAME=INT a field of the plan's
:class:`~plant.identification.ExperimentOptions`, e.g. ``doublets=6``).
"""

from __future__ import annotations

import json
import math
import sys
import time

import numpy as np

from plant.identification import fit as F
from plant.identification.families import FAMILY_FREE

from tests.identify_power import scores

SPECS = {"today": F._WINDOW_SPEC, "finer": F._FINER_WINDOW_SPEC}


def _replicates(log, family, base, z, test, seed, n):
    """As :func:`tests.identify_power.replicates` (the streams of :func:`F._predictive_features`),
    (model, None) when the plant fails at z."""
    from plant.randomness import NoiseStream

    model = F._Model(log, family, base, only=test)
    sims = []
    for i in range(n):
        def streams(g, i=i):
            return NoiseStream(np.random.default_rng(np.random.SeedSequence([seed, int(test[g]), i])), block=1024)
        pred = model.predict(z, streams)
        if pred is None:
            return model, None
        sims.append(pred)
    return model, np.array(sims)


def run(seed: int, repeats: int, family: str, case: int, plan: dict | None = None, **options) -> dict:
    """The choice on one dev log, with its per-move scores under both feature sets (``options``:
    keywords of :func:`~plant.identification.fit.choose_family`; ``plan``: more fields of the plan's options)."""
    from plant.identification import ExperimentOptions

    from tests.identify_power import dev_log

    log, _, _ = dev_log(family, case, seed, ExperimentOptions(repeats=repeats, **(plan or {})))
    stash: dict = {}
    original = F._predictive_scores

    def both(log, fam, base, z, test, sigma1, seed=0, n=F._MC):
        model, sims = _replicates(log, fam, base, z, test, seed, n)
        if sims is None:      # the plant failed at z: every move infinite, as the original
            out = {name: np.full(len(test), math.inf) for name in SPECS}
        else:
            out = {name: scores(log, model, sims, spec, sigma1) for name, spec in SPECS.items()}
        stash[fam, int(test[0])] = (list(map(int, test)), out)    # the last call per fold stands (as choose_family)
        return out["today"]

    F._predictive_scores = both
    try:
        c0 = time.process_time()
        _, choice = F.choose_family(log, bootstrap=0, final_fit=False, **options)
        cpu = time.process_time() - c0
    finally:
        F._predictive_scores = original
    G = len(F.moves(log))
    per = {name: {f: np.empty(G) for f in FAMILY_FREE} for name in SPECS}
    for (fam, _), (test, out) in stash.items():
        for name in SPECS:
            per[name][fam][test] = out[name]
    assert all(np.array_equal(per["today"][f], choice.per_move[f], equal_nan=True) for f in FAMILY_FREE)
    return {"seed": seed, "repeats": repeats, "family": family, "case": case, "options": sorted(options), "plan": plan or {},
            "picked": choice.family,
            "picked_pairwise": F._rule_pairwise(list(choice.score), choice.score, choice.pairs),
            "cpu": cpu, "moves": G, "fold_cpu": {f: float(c) for f, c in choice.cpu.items()},
            "fold_fits": {f"{f} {k}": [float(x) for x in z] for (f, k), z in choice.fold_fits.items()},
            "per_move": {name: {f: [float(x) for x in v] for f, v in d.items()} for name, d in per.items()}}


def pick(per_move: dict, threshold: float) -> tuple[str, dict]:
    """:func:`plant.identification.fit._rule` with the signed-rank test at ``threshold`` null sd
    (``per_move``: family → per-move scores): (picked family, family → z against the best)."""
    fams = [f for f in F._SIMPLER if f in per_move]
    pm = {f: np.asarray(per_move[f], dtype=float) for f in fams}
    score = {f: float(np.mean(v)) for f, v in pm.items()}
    best = min(fams, key=lambda f: score[f])
    ranks = {f: F._signed_rank(pm[f], pm[best]) for f in fams}
    chosen = F._rule(fams, score, {f: w for f, (w, _) in ranks.items()}, {f: sd for f, (_, sd) in ranks.items()},
                     threshold)
    return chosen, {f: (w / sd if sd else 0.0) for f, (w, sd) in ranks.items()}


if __name__ == "__main__":
    out, seed, repeats, family, case = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], int(sys.argv[5])
    res = run(seed, repeats, family, case, {a.split("=")[0]: int(a.split("=")[1]) for a in sys.argv[6:] if "=" in a},
              **dict.fromkeys([a for a in sys.argv[6:] if "=" not in a], True))
    with open(out, "a") as fh:
        fh.write(json.dumps(res) + "\n")
    print(family, case, repeats, res["picked"], f"cpu {res['cpu']:.0f}", flush=True)
