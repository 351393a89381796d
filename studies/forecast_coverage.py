"""Study: do the forecasts' 95 % bands hold the truth 95 % of the time?

Paper case (inclinometer I1, extensometer X1 with their C_x; identify E and K0) with a forecast of
the surface settlement trough (31 points from the axis to 30 m) and of the crown's settlement. The
truth is the model on a mesh twice as fine (no inverse crime) at E = 10 MPa, K0 = 1: its readings
and its forecasts. Each replicate adds a draw from N(0, C_x) to the readings, identifies E and K0
on the case's mesh, forecasts with the first-order band q +- 1.96 sqrt(diag F C_p F^t) at that
replicate's estimate, and checks whether the fine mesh's forecast lies inside. Coverage is
reported per forecast point with its binomial standard error, and for the point of largest
settlement; the forecasts' own discretisation bias (the fit of noise-free readings, its forecast
against the fine mesh's) is printed in units of their std.

`--case staged` does the same for cases/staged-forecast.yaml (advance readings; forecast of the
trough after the lined stage), a Bayesian check: each replicate's true release beta is drawn
from the case's prior N(0.5, 0.15^2) (E = 40 MPa, K0 = 0.7 fixed), so the band is tested in the
sense the prior gives it.

    python studies/forecast_coverage.py [--replicates 1000] [--case paper|staged] [--small]
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

if __name__ == "__main__":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common as C  # noqa: E402

NAME = "forecast_coverage"
Z = 1.959963984540054
TROUGH = {"name": "trough", "kind": "line", "start": [0.0, 0.0], "end": [30.0, 0.0], "points": 31, "component": "uy"}
CROWN = {"name": "crown", "kind": "points", "points": [[0.0, -6.5]], "components": ["uy"]}


def paper_case(mesh_scale: float = 1.0):
    data = C.without_readings(C.case_dict(mesh_scale=mesh_scale, weighting="full", name="forecast-coverage"))
    data["forecasts"] = [TROUGH, CROWN]
    return C.loaded_case(data)


def staged_case():
    from geoback.case import load_case

    loaded = load_case(C.ROOT / "cases" / "staged-forecast.yaml")
    data = loaded.case.model_dump(exclude_none=True)
    for ins in data["instruments"]:
        ins.pop("readings_file", None)
    data.pop("design", None)
    data["forecasts"] = [f for f in data["forecasts"] if f["name"] == "trough"]
    return C.loaded_case(data)


def run(replicates: int, which: str = "paper", seed: int = 1) -> dict:
    from geoback.forecast import forecast_model
    from geoback.identification import identify, identify_replicates, prepare
    from geoback.simulate import refined_case

    loaded = paper_case() if which == "paper" else staged_case()
    coarse = prepare(loaded, with_readings=False)
    fine = prepare(loaded.with_case(refined_case(loaded.case, 2.0)), with_readings=False)
    names = coarse.parameters.names
    rng = np.random.default_rng(seed)
    if which == "paper":
        truths = [dict(fine.values, **{"E[clay]": C.E_TRUE, "K0": C.K0_TRUE})] * replicates
    else:
        beta = np.clip(0.5 + 0.15 * rng.standard_normal(replicates), 0.06, 0.99)
        truths = [dict(fine.values, **{"E[clay]": 40000.0, "K0": 0.7, "beta[advance]": b}) for b in beta]
    fmodel = forecast_model(fine)
    clean, q_true = [], []
    with fmodel.reading():
        for t in truths[:1] if which == "paper" else truths:
            q_true.append(fmodel(t)[0])
    for t in truths[:1] if which == "paper" else truths:
        clean.append(fine.simulation.predict(t).x)
    clean, q_true = np.array(clean), np.array(q_true)
    if which == "paper":
        clean, q_true = np.repeat(clean, replicates, 0), np.repeat(q_true, replicates, 0)
    problem = coarse.with_readings(clean[0])
    model = forecast_model(coarse)
    # the forecasts' discretisation bias: noise-free readings fitted, forecast against the fine mesh's
    res0 = identify(problem, require_dof=False, profile="none")
    with model.reading():
        q0, F0 = model(coarse.values_at(res0.fit.p), names, True)
    s0 = np.sqrt(np.einsum("ij,jk,ik->i", F0, res0.reliability.covariance, F0))
    bias = (q0 - q_true[0]) / s0
    noisy = clean + np.array([problem.misfit.data.noise(rng) for _ in range(replicates)])
    t0 = time.perf_counter()
    rep = identify_replicates(problem, noisy)
    inside = np.zeros((replicates, len(q0)), bool)
    with model.reading():
        for k in range(replicates):
            q, F = model(coarse.values_at(rep.p[k]), names, True)
            s = np.sqrt(np.einsum("ij,jk,ik->i", F, rep.covariance[k], F))
            inside[k] = np.abs(q - q_true[k]) <= Z * s
    seconds = time.perf_counter() - t0
    ok = rep.converged
    cover = inside[ok].mean(axis=0)
    n = int(ok.sum())
    big = int(np.argmax(np.abs(q_true[0])))
    return {"which": which, "replicates": replicates, "converged": n, "coverage": cover,
            "se": np.sqrt(cover * (1 - cover) / n), "largest": big, "bias_std": bias, "q_true": q_true[0],
            "labels": [f"{lab}" for lab in range(len(q0))], "seconds": seconds, "x": _positions(loaded)}


def _positions(loaded) -> list[str]:
    out = []
    for f in loaded.case.forecasts:
        if f.kind == "line":
            out += [f"{f.name} x={f.start[0] + (f.end[0] - f.start[0]) * k / (f.points - 1):g}" for k in range(f.points)]
        else:
            out += [f"{f.name} ({p[0]:g}, {p[1]:g}) {c}" for p in f.points for c in f.components]
    return out


def main() -> None:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=1000)
    ap.add_argument("--case", choices=["paper", "staged"], default="paper")
    args = ap.parse_args()
    n = 100 if args.small else args.replicates
    r = run(n, args.case, args.seed)
    rows = [[lab, r["q_true"][i] * 1e3, r["bias_std"][i], r["coverage"][i], r["se"][i]]
            for i, lab in enumerate(r["x"])]
    header = ["forecast point", "truth [mm]", "mesh bias [std]", "coverage", "se"]
    C.write_csv(args.out / f"{NAME}_{args.case}.csv", header, rows)
    print(C.format_table(header, rows))
    i = r["largest"]
    print(f"\n{r['which']}: {r['converged']} of {r['replicates']} replicates converged; coverage of the 95 % band at "
          f"the largest settlement ({r['x'][i]}): {r['coverage'][i]:.3f} +- {r['se'][i]:.3f}; over all points "
          f"{r['coverage'].min():.3f} to {r['coverage'].max():.3f} (mean {r['coverage'].mean():.3f}); "
          f"{r['seconds']:.1f} s")
    plt = C.pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    k = np.arange(len(rows))
    ax.errorbar(k, 100 * r["coverage"], yerr=196 * r["se"], fmt="o", ms=3, capsize=2)
    ax.axhspan(93, 97, color="0.85", label="93-97 %")
    ax.axhline(95, color="0.4", lw=0.8)
    ax.set_xticks(k[::5], [r["x"][j] for j in k[::5]], rotation=30, ha="right")
    ax.set_ylabel("truth inside the 95 % band [%]")
    ax.set_title(f"Forecast coverage over {r['converged']} noisy replicates")
    ax.legend(frameon=False)
    fig.tight_layout()
    fig.savefig(args.out / f"{NAME}_{args.case}.png", dpi=150)


if __name__ == "__main__":
    main()
