"""Accuracy of `geoback diagnose` on a propped excavation: what goes wrong in excavations, concealed.

The cases are those of cases/concealed/generate_excavation.py (a 0.8 m diaphragm wall propped at two levels,
three lifts, read after every stage by the wall inclinometer, settlement points and two prop load cells; the
baseline identifies E[soft], E[stiff], K0): a cracked wall (wall-stiffness), a slack prop level
(support-stiffness), a preload lost (preload-lost), the soft clay reaching below formation (soft-formation:
the library's layer-boundary is the right name), the soft clay yielding (yielding) and nothing (null). With
--seeds N each is also drawn with N further noise seeds (the same truth, new noise).

For each: the effect's size (sqrt of the baseline's J on the truth's noise-free readings: in sigma), what
the diagnosis accepted first, right / wrong / nothing, its grade (named: the claim checks passed; explained:
not singled out), whether its interval holds the truth, and CPU seconds. The summary counts the right kind
accepted first, the right kind *named* (the issue-24 sense) and a wrong kind named (a confident wrong cause).

    python benchmarks/diagnosis_excavation.py [--seeds 0] [--csv out.csv]
"""
from __future__ import annotations

import argparse
import copy
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "cases" / "concealed"))

import generate_excavation as gen  # noqa: E402
from table import print_table  # noqa: E402

# the right names: a soft layer reaching below formation is the ground stiffer with depth (a stratum below or a
# modulus gradient: one family of the library, told apart by AIC)
RIGHT = {"wall-stiffness": {"wall-stiffness"}, "support-stiffness": {"support-stiffness"},
         "preload-lost": {"preload-lost"}, "soft-formation": {"layer-boundary", "stiffness-gradient"},
         "yielding": {"yielding"}, "null": {"nothing"}}
TRUE = {"wall-stiffness": ("E[wall]", 1.0e7), "support-stiffness": ("k[P1]", 1.2e4), "preload-lost": ("preload[P2]", 0.0)}


def one(name: str, seed: int) -> dict:
    from geoback.case.loading import LoadedCase, case_from_data
    from geoback.diagnosis import diagnose
    from geoback.inference.estimate import fit
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings

    values, change, _, _ = gen.TRUTH[name]
    base = gen.case_data(name)
    for ins in base["instruments"]:
        ins.pop("readings_file")
    truth = copy.deepcopy(base)
    if change is not None:
        change(truth)
    loaded = LoadedCase(case_from_data(base), None, {})
    tl = LoadedCase(case_from_data(truth), None, {})
    vals = {**gen.TRUTH_VALUES, **values}
    clean = synthetic_readings(tl, refine=2.0, values=vals, by_stage=True)
    noisy = synthetic_readings(tl, refine=2.0, values=vals, noise_seed=seed, by_stage=True)
    problem = prepare(loaded, with_readings=False)
    order = [(b.name, b.stage) for b in problem.simulation.survey.blocks]
    x_clean = np.concatenate([clean[n][s] for n, s in order])
    x = np.concatenate([noisy[n][s] for n, s in order])
    problem = problem.with_readings(x)
    effect = math.sqrt(max(fit(problem.misfit.with_measured(x_clean), problem.settings).J, 0.0))
    c0 = time.process_time()
    d = diagnose(problem)
    cpu = time.process_time() - c0
    kinds = [s.hypothesis.kind for s in d.accepted]
    named = kinds[0] if kinds else "nothing"
    held = ""
    if name in TRUE and named in RIGHT[name]:
        p, v = TRUE[name]
        for n, est, sd, lo, hi in d.estimates(d.accepted[0]):
            if n == p:
                held = "yes" if lo <= v <= hi else f"NO ({lo:.4g}..{hi:.4g})"
    verdict = "right" if named in RIGHT[name] else ("nothing" if named == "nothing" else "wrong")
    return dict(case=name, seed=seed, effect=effect, named=named, verdict=verdict, held=held, cpu=cpu,
                grade=d.grade)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=0, help="further noise seeds per case")
    ap.add_argument("--cases", nargs="*", default=list(gen.TRUTH))
    ap.add_argument("--csv", type=Path, default=None)
    args = ap.parse_args(argv)
    rows = []
    for name in args.cases:
        for k in range(args.seeds + 1):
            r = one(name, gen.TRUTH[name][2] + 1000 * k)
            print(f"{r['case']} (seed {r['seed']}): effect {r['effect']:.1f} sigma, accepted {r['named']} "
                  f"({r['grade']}) -> {r['verdict']}"
                  f"{', interval holds the truth: ' + r['held'] if r['held'] else ''}; {r['cpu']:.0f} s CPU", flush=True)
            rows.append(r)
    table = [(f"{r['case']} seed {r['seed']}", f"{r['effect']:.1f} sigma: {r['named']}, {r['grade']} ({r['verdict']})"
              f"{'; interval ' + r['held'] if r['held'] else ''}; {r['cpu']:.0f} s CPU") for r in rows]
    big = [r for r in rows if r["case"] != "null" and r["effect"] > 3]
    table.append(("the right kind accepted first, effect > 3 sigma",
                  f"{sum(r['verdict'] == 'right' for r in big)} of {len(big)}"))
    table.append(("the right kind named (claim checks passed), effect > 3 sigma",
                  f"{sum(r['verdict'] == 'right' and r['grade'] == 'named' for r in big)} of {len(big)}"))
    table.append(("a wrong kind named (a confident wrong cause), effect > 3 sigma",
                  f"{sum(r['verdict'] == 'wrong' and r['grade'] == 'named' for r in big)} of {len(big)}"))
    table.append(("a wrong kind accepted first (named or explained), effect > 3 sigma",
                  f"{sum(r['verdict'] == 'wrong' for r in big)} of {len(big)}"))
    nulls = [r for r in rows if r["case"] == "null"]
    table.append(("null: false alarms", f"{sum(r['verdict'] != 'right' for r in nulls)} of {len(nulls)}"))
    return print_table(table, args.csv)


if __name__ == "__main__":
    main(sys.argv[1:])
