"""Study: would one pooled test per inclinometer for its errors find them more often? (issue 24)

`geoback diagnose` tests each hypothesis of its library once per round, at alpha / K (Bonferroni over the
K tests of the round: one per row of the ranking, the depths of a layer boundary one test, and the
hypotheses screened by refit). An inclinometer brings three rows of instrument error (its reference end
moved: B, a bias shift, a depth offset), so it costs every other test in the family. The alternative
considered: the errors of one instrument tested together, as ONE test of the family, at the exact level
of their largest statistic,

    P(max_i |Z_i| > c_g) = alpha / K',    Z ~ N(0, R),   K' = K - sum_g (n_g - 1),

R the correlation of the members' score statistics under the null (that of their whitened sensitivities
the baseline cannot mimic, ``Scored.m2``: the statistics are z_i = m_i . r / |m_i|). That is one test
fewer per member beyond the first, and a member is then accepted at |z| > c_g instead of the c of
alpha / K. Which is larger decides: with strongly correlated members (a bias nearly collinear with a
reference-end rotation) c_g is close to a single test's critical value at alpha / K' and the pooled test
gains; with nearly independent members it is close to Sidak's over n_g tests and loses.

For each shipped concealed tunnel case with inclinometers (they share one layout) and for --random N null
cases of the accuracy benchmark (a random tunnel and instrument layout each, readings from a mesh twice as
fine with noise: ``benchmarks/diagnosis_accuracy.py``), one round of the diagnosis (its family K, its
score tests) and printed: the correlations within each instrument, c and c_g, and the power of a test
of one parameter (|z| > c for an effect of mu standard deviations) for an instrument error, pooled or
not, and for a ground hypothesis, whose level alpha / K' rises when the instruments are pooled.

    python studies/instrument_pooling.py [--alpha 0.05] [--random 20] [--seed 2024]
"""
from __future__ import annotations

import argparse
import csv
import itertools
import os
import sys
from pathlib import Path

if __name__ == "__main__":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy import optimize, stats  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common as C  # noqa: E402

NAME = "instrument_pooling"
CASES = ["bias-shift", "depth-offset", "toe-moved", "null-1", "null-2", "null-3"]
EFFECTS = (3.0, 3.5, 4.0)  # mu: an effect of that many standard deviations of its statistic


def p_largest(c: float, R: np.ndarray) -> float:
    """P(max_i |Z_i| > c) for Z ~ N(0, R)."""
    if len(R) == 1:
        return float(2 * stats.norm.sf(c))
    inside = stats.multivariate_normal(np.zeros(len(R)), R, allow_singular=True).cdf(
        np.full(len(R), c), lower_limit=np.full(len(R), -c))
    return float(1.0 - inside)


def pooled_critical(level: float, R: np.ndarray) -> float:
    """c_g with P(max |Z_i| > c_g) = level."""
    return float(optimize.brentq(lambda c: p_largest(c, R) - level, 0.5, 10.0, xtol=1e-6))


def power(c: float, mu: float) -> float:
    """P(|N(mu, 1)| > c)."""
    return float(stats.norm.sf(c - mu) + stats.norm.cdf(-c - mu))


def instrument_groups(ranking: list) -> dict[str, list]:
    """Instrument -> its testable one-parameter error hypotheses (hypotheses.INSTRUMENT_KINDS)."""
    from geoback.diagnosis.hypotheses import INSTRUMENT_KINDS

    groups: dict[str, list] = {}
    for s in ranking:
        h = s.hypothesis
        if h.kind in INSTRUMENT_KINDS and s.collinear_with is None and s.m2 is not None and s.dof == 1:
            groups.setdefault(h.key.split("[", 1)[1].rstrip("]"), []).append(s)
    return groups


def correlation(members: list) -> np.ndarray:
    M = np.column_stack([s.m2[:, 0] / np.linalg.norm(s.m2[:, 0]) for s in members])
    return M.T @ M


def _problems(random: int, seed: int):
    """(name, case) of the shipped cases, then of `random` null cases of the accuracy benchmark."""
    for name in CASES:
        yield name, str(C.ROOT / "cases" / "concealed" / f"{name}.yaml")
    if random:
        import tempfile

        bench = C.script("benchmarks/diagnosis_accuracy.py")
        with tempfile.TemporaryDirectory() as folder:
            for i in range(random):
                case = bench.random_case(i, "null", seed)
                yield f"random null {i} ({case['layout']})", bench.truth_readings(case, folder)[2]


def study(alpha: float, random: int = 0, seed: int = 2024) -> list[dict]:
    from geoback.diagnosis import diagnose

    rows = []
    for name, case in _problems(random, seed):
        d = diagnose(case, alpha=alpha, max_rounds=0)
        rnd = d.rounds[0]
        K = rnd.family
        groups = {g: m for g, m in instrument_groups(rnd.ranking).items() if len(m) > 1}
        K_pooled = K - sum(len(m) - 1 for m in groups.values())
        c = float(stats.norm.isf(alpha / K / 2))
        c_ground = float(stats.norm.isf(alpha / K_pooled / 2))
        print(f"\n{name}: family {K} tests; with each inclinometer's errors one test: {K_pooled}")
        for g, members in groups.items():
            R = correlation(members)
            c_g = pooled_critical(alpha / K_pooled, R)
            labels = [s.hypothesis.kind for s in members]
            off = [R[i, j] for i, j in itertools.combinations(range(len(R)), 2)]
            print(f"  {g}: {', '.join(labels)}; correlations {', '.join(f'{x:+.2f}' for x in off)}")
            print(f"    a member accepted at |z| > {c:.3f} (level {alpha / K:.2g}), pooled at |z| > {c_g:.3f} "
                  f"(level {2 * stats.norm.sf(c_g):.2g} each)")
            for mu in EFFECTS:
                row = {"case": name, "instrument": g, "members": len(members),
                       "largest_correlation": max(abs(x) for x in off), "family": K, "family_pooled": K_pooled,
                       "c": c, "c_pooled": c_g, "mu": mu, "power_instrument": power(c, mu),
                       "power_instrument_pooled": power(c_g, mu), "power_ground": power(c, mu),
                       "power_ground_pooled": power(c_ground, mu)}
                rows.append(row)
                print(f"    effect {mu:g} sd: an instrument error found with probability {row['power_instrument']:.3f} "
                      f"-> {row['power_instrument_pooled']:.3f} pooled; a one-parameter ground cause "
                      f"{row['power_ground']:.3f} -> {row['power_ground_pooled']:.3f}")
    return rows


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--alpha", type=float, default=0.05)
    ap.add_argument("--random", type=int, default=20, help="null cases of the accuracy benchmark (random layouts)")
    ap.add_argument("--seed", type=int, default=2024, help="the benchmark's master seed for them")
    ap.add_argument("--out", type=Path, default=C.OUT)
    a = ap.parse_args(argv)
    rows = study(a.alpha, a.random, a.seed)
    a.out.mkdir(parents=True, exist_ok=True)
    with open(a.out / f"{NAME}.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    gain = [r["power_instrument_pooled"] - r["power_instrument"] for r in rows]
    print(f"\nlargest correlation within an instrument: {max(r['largest_correlation'] for r in rows):.2f}")
    for mu in EFFECTS:
        sub = [r for r in rows if r["mu"] == mu]
        print(f"effect {mu:g} sd, medians over {len(sub)} instruments: an instrument error found with probability "
              + " -> ".join(f"{np.median([r[k] for r in sub]):.3f}" for k in ("power_instrument", "power_instrument_pooled"))
              + " pooled; a one-parameter ground cause "
              + " -> ".join(f"{np.median([r[k] for r in sub]):.3f}" for k in ("power_ground", "power_ground_pooled")))
    print(f"pooling changes an instrument error's power by {min(gain):+.3f} to {max(gain):+.3f} "
          f"over {len(rows)} (instrument, effect) rows; rows in {a.out / (NAME + '.csv')}")
    return rows


if __name__ == "__main__":
    main()
