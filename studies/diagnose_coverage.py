"""Study: do the intervals `geoback diagnose` reports for the missing physics hold the truth? (issue 13)

Concealed cases as in the accuracy benchmark (``benchmarks/diagnosis_accuracy.py``: a random
tunnel, instrument layout and effect of each kind, readings from the truth on a mesh twice as fine
with noise drawn from each instrument's C_x; the case describes only the baseline). For every case
whose first accepted hypothesis is the concealed kind, each extra parameter's 95 % interval - as the
verdict reports it: the final joint fit, profile likelihood where the linearised interval is not
reliable, a boundary's depth by profile likelihood over a continuous depth and its modulus with the
depth profiled out - is checked against the truth:

    stiffness-gradient  Egrad[clay]          layer-boundary  E[clay_below] and depth[clay]
    anisotropy          n[clay]              K0-gradient     K0grad
    integration-const.  B[I1]                stress-release  beta
    bias-shift          bias[I1]             depth-offset    zoff[I1]

Nominal coverage 95 %; the acceptance band is 93-97 %. 'Correctly named' is the kind accepted first,
whatever its grade; the last column counts only the causes graded 'named' (claims.py), the intervals the
verdict reports as found (a cause explained but not singled out gets its estimate without an interval). Coverage is conditional on the effect
having been detected and named: near the detection threshold the named cases are those whose
noise happened to enlarge the effect, so their estimates are biased away from zero (the winner's
curse); the table shows coverage by effect-size band as well (effect size as in the benchmark:
sqrt(J_min) of the baseline fitted to the noise-free readings, in sigma units). The readings also
carry the baseline mesh's discretisation error (the truth is meshed twice as finely), which the
stated sigma's do not include.

Outputs (``studies/out``): diagnose_coverage.csv (one row per interval), diagnose_coverage_summary.csv
(per kind and band) and diagnose_coverage.png (coverage per kind with binomial error bars; the
standardised errors (estimate - truth) / half-width * 1.96 per kind).

    python studies/diagnose_coverage.py [--per-kind N] [--kinds a,b] [--seed S] [--workers W] [--small]
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor, as_completed  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common as C  # noqa: E402

HERE = Path(__file__).resolve().parent
OUT = HERE / "out"
NAME = "diagnose_coverage"
KINDS = ["stiffness-gradient", "layer-boundary", "anisotropy", "K0-gradient", "integration-constant",
         "stress-release", "bias-shift", "depth-offset"]
BANDS = ((3.0, 5.0), (5.0, 10.0), (10.0, math.inf))
SMALL_KINDS = ["bias-shift", "anisotropy", "depth-offset"]


def _bench():
    """The accuracy benchmark's case generator and runner (one source of concealed cases)."""
    return C.script("benchmarks/diagnosis_accuracy.py")


def _run(spec: dict, folder: str) -> dict:
    return _bench().run_one(spec, folder)


def intervals(rows: list[dict]) -> list[dict]:
    """One row per checked interval."""
    out = []
    for r in rows:
        for c in r.get("coverage") or []:
            half = 0.5 * (c["high"] - c["low"])
            z = (c["estimate"] - c["truth"]) / (half / 1.959964) if half > 0 and np.isfinite(half) else float("nan")
            out.append({"case": r["case"], "kind": r["kind"], "parameter": c["name"], "truth": c["truth"],
                        "estimate": c["estimate"], "std": c["std"], "low": c["low"], "high": c["high"],
                        "covered": c["covered"], "covered_adjusted": c.get("covered_adjusted", c["covered"]),
                        "adjusted": c.get("adjusted", False), "standardised_error": z, "effect_size": r["effect_size"],
                        "tentative": c["tentative"], "grade": r.get("grade", ""), "accepted": r["accepted"],
                        "layout": r["layout"],
                        "noise_seed": r["noise_seed"]})
    return out


def _rate(items: list[dict]) -> dict:
    n = len(items)
    k = sum(bool(i["covered"]) for i in items)
    ka = sum(bool(i["covered_adjusted"]) for i in items)
    p = k / n if n else float("nan")
    pa = ka / n if n else float("nan")
    named = [i for i in items if i["grade"] == "named"]  # the intervals the verdict reports as found
    kn = sum(bool(i["covered"]) for i in named)
    return {"intervals": n, "covered": k, "coverage": p,
            "se": math.sqrt(max(p * (1 - p), 0.0) / n) if n else float("nan"),
            "covered_adjusted": ka, "coverage_adjusted": pa,
            "intervals_named": len(named), "covered_named": kn,
            "coverage_named": kn / len(named) if named else float("nan")}


def summarise(rows: list[dict]) -> list[dict]:
    """Coverage per kind (and all), per effect-size band, and the naming counts behind it."""
    ivs = intervals(rows)
    table = []
    for kind in KINDS + ["all"]:
        sub_rows = [r for r in rows if kind == "all" or r["kind"] == kind]
        if not sub_rows:
            continue
        sub = [i for i in ivs if kind == "all" or i["kind"] == kind]
        named = sum(bool(r["correct"]) for r in sub_rows)
        big = [r for r in sub_rows if isinstance(r["effect_size"], float) and r["effect_size"] > 3]
        table.append({"kind": kind, "band": "all", "cases": len(sub_rows), "named": named,
                      "cases_effect_gt3": len(big), "named_effect_gt3": sum(bool(r["correct"]) for r in big),
                      **_rate(sub)})
        for lo, hi in BANDS:
            part = [i for i in sub if isinstance(i["effect_size"], float) and lo < i["effect_size"] <= hi]
            if part:
                table.append({"kind": kind, "band": f"({lo:g}, {hi:g}]", "cases": "", "named": "",
                              "cases_effect_gt3": "", "named_effect_gt3": "", **_rate(part)})
    return table


def _write_csv(path: Path, rows: list[dict]) -> None:
    if not rows:
        path.write_text("")
        return
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def figure(rows: list[dict], table: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ivs = intervals(rows)
    kinds = [t["kind"] for t in table if t["band"] == "all"]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 5.2))
    ys = np.arange(len(kinds))
    cov = [next(t for t in table if t["kind"] == k and t["band"] == "all") for k in kinds]
    ax.axvspan(93, 97, color="#2ca02c", alpha=0.15, label="acceptance 93-97 %")
    ax.axvline(95, color="#2ca02c", lw=1)
    ax.errorbar([100 * c["coverage"] for c in cov], ys, xerr=[200 * c["se"] for c in cov], fmt="o", color="k",
                capsize=3, label="coverage ± 2 s.e.")
    for y, c in zip(ys, cov):
        ax.text(101, y, f"{c['covered']}/{c['intervals']}", va="center", fontsize=8)
    ax.set_yticks(ys, kinds)
    ax.invert_yaxis()
    ax.set_xlim(min(50, 100 * min(c["coverage"] for c in cov) - 10), 108)
    ax.set_xlabel("95 % intervals holding the truth [%]")
    ax.set_title("coverage per kind (correctly named cases)")
    ax.legend(loc="lower left", fontsize=8)
    for y, k in enumerate(kinds):
        z = [i["standardised_error"] for i in ivs if (k == "all" or i["kind"] == k) and np.isfinite(i["standardised_error"])]
        z = np.clip(z, -6, 6)
        bx.plot(z, y + np.random.default_rng(y).uniform(-0.25, 0.25, len(z)), "o", ms=3, alpha=0.6)
    bx.axvspan(-1.96, 1.96, color="0.85", zorder=0, label="inside the 95 % interval")
    bx.set_yticks(ys, kinds)
    bx.invert_yaxis()
    bx.set_xlabel("(estimate - truth) / (half-width / 1.96), clipped at ±6")
    bx.set_title("standardised errors")
    bx.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-kind", type=int, default=40, help="concealed cases of each kind")
    ap.add_argument("--kinds", default=",".join(KINDS))
    ap.add_argument("--seed", type=int, default=13)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--small", action="store_true", help=f"3 cases of {', '.join(SMALL_KINDS)} (a smoke test)")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    kinds = SMALL_KINDS if args.small else [k for k in args.kinds.split(",") if k]
    per_kind = 3 if args.small else args.per_kind
    bench = _bench()
    specs = [bench.random_case(1000 * (KINDS.index(k) + 1) + i, k, args.seed, strong=True)
             for k in kinds for i in range(per_kind)]
    work = Path(tempfile.mkdtemp(prefix="geoback-coverage-"))
    os.environ.setdefault("GEOBACK_CACHE", str(work / "cache"))
    t0 = time.perf_counter()
    rows = []
    try:
        if args.workers > 1:
            with ProcessPoolExecutor(args.workers) as pool:
                futures = [pool.submit(_run, s, str(work)) for s in specs]
                for fut in as_completed(futures):
                    rows.append(fut.result())
                    _progress(rows[-1], len(rows), len(specs))
        else:
            for s in specs:
                rows.append(bench.run_one(s, str(work)))
                _progress(rows[-1], len(rows), len(specs))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    rows.sort(key=lambda r: r["case"])
    table = summarise(rows)
    args.out.mkdir(parents=True, exist_ok=True)
    _write_csv(args.out / f"{NAME}.csv", intervals(rows))
    _write_csv(args.out / f"{NAME}_summary.csv", table)
    figure(rows, table, args.out / f"{NAME}.png")
    seconds = time.perf_counter() - t0
    print(f"\n{len(rows)} cases ({per_kind} per kind, seed {args.seed}) in {seconds:.0f} s")
    print(f"{'kind':<22}{'band':<13}{'cases':>6}{'named':>6}{'intervals':>10}{'covered':>8}  coverage"
          f"     allowing for selection (diagnosis/selection.py)   the verdict's own (grade 'named')")
    for t in table:
        own = (f"{t['covered_named']}/{t['intervals_named']} = {100 * t['coverage_named']:5.1f} %"
               if t["intervals_named"] else "-")
        print(f"{t['kind']:<22}{t['band']:<13}{t['cases']!s:>6}{t['named']!s:>6}{t['intervals']:>10}{t['covered']:>8}"
              f"  {100 * t['coverage']:5.1f} % ± {100 * t['se']:.1f}   {100 * t['coverage_adjusted']:5.1f} %"
              f"{'':<37}{own}")
    errors = [r for r in rows if r["error"]]
    for r in errors:
        print(f"error in {r['case']}: {r['error']}")
    return {"rows": rows, "table": table, "seconds": seconds}


def _progress(r: dict, k: int, n: int) -> None:
    cov = " ".join(f"{c['name']}:{'in' if c['covered'] else 'OUT'}"
                   + (f"/{'in' if c['covered_adjusted'] else 'OUT'}" if c.get("adjusted") else "")
                   for c in r.get("coverage") or [])
    eff = r["effect_size"] if isinstance(r["effect_size"], float) else float("nan")
    print(f"[{k:3d}/{n}] {r['case']:<34} effect {eff:7.2f} -> {r['named']:<20} {cov}", flush=True)


if __name__ == "__main__":
    main()
