"""Study: error scales estimated with the parameters (issue 14; paper eqns 5 and 10).

Two instruments whose stated sigma is known only up to a factor: inclinometer I1 (slope sigma
0.001 rad, toe fixed) and extensometer X1 (sigma 0.5 mm, head survey variance 1e-6 m2). The
truth has scales k = (1, 3): I1 is read as accurately as the case states, X1 three times worse.
Noise-free readings come from a mesh twice as fine as the fitting mesh (no inverse crime); each
realisation adds a draw from N(0, k^2 C_x) per instrument (C_x as stated, eqns 10-20) and is
identified from the paper's start (E = 5 MPa, K0 = 0.5) in two ways:

    free    error_scales: I1 and X1 'estimate' - the scales profiled with the restricted (REML)
            dof, C_p with the estimated scales, 95 % ellipse d^2 < n F(n, nu) (Satterthwaite nu);
            also counted with the naive chi2(n) limit ('free, chi2 limit')
    fixed   the scales wrongly taken as 1 (the stated sigma's): C_p from the stated C_x

The truth (E = 10 MPa, K0 = 1) is inside a fit's 95 % ellipse if d^2 = (p_hat - p)^t C_p^-1
(p_hat - p) is below the limit; the fraction inside is reported with its binomial standard error.
For the scales: the mean of k^2 (the restricted estimate of the variance factor is unbiased) and
of k (biased low by Jensen's inequality, about k var(k^2) / (8 k^4)), each with its Monte Carlo
standard error, the coverage of the 95 % intervals of k, and the mean of the plain
maximum-likelihood k^2 = J_g / m_g at the same fits (biased low by the parameters' share h_g of
the group's readings: the reason geoback uses the restricted correction).

Layouts: 'dense' (I1 23 stations at 1 m, X1 13 stations at 0.5 m: the acceptance layout) and
'paper' (the paper's 7 and 5 stations: X1's scale rests on about 3.6 degrees of freedom, where
every small-sample approximation is stretched; shown for honesty).

    python studies/error_scales.py [--small] [--realisations N] [--out DIR]
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

if __name__ == "__main__":  # thousands of tiny dense solves: OpenBLAS threads only add overhead
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common as C  # noqa: E402

NAME = "error_scales"
TRUE_SCALES = {"I1": 1.0, "X1": 3.0}
LAYOUTS = {"dense": {"I1": dict(spacing=1.0, stations=23), "X1": dict(spacing=0.5, stations=13)},
           "paper": {}}


def case_data(layout: str) -> dict:
    data = C.without_readings(C.case_dict(weighting="full", name=f"error-scales-{layout}"))
    for ins in data["instruments"]:
        ins.update(LAYOUTS[layout].get(ins["name"], {}))
    return data


def run(layout: str, realisations: int, seed: int) -> dict:
    from geoback.inference.identification import identify_replicates, prepare

    data = case_data(layout)
    loaded = C.loaded_case(data)
    fixed = C.problem_with(loaded)  # stated sigma's, scales taken as 1
    clean = C.stack(fixed, C.fine_readings(loaded, refine=2.0))
    blocks = fixed.misfit.data.block_rows()
    rng = np.random.default_rng(seed)
    noisy = np.empty((realisations, len(clean)))
    for i in range(realisations):
        e = fixed.misfit.data.noise(rng)
        for b, rows in blocks:
            e[rows] *= TRUE_SCALES[b.name]
        noisy[i] = clean + e
    scaled = dict(data, error_scales=[{"instruments": [name]} for name in TRUE_SCALES])
    free = prepare(C.loaded_case(C.with_readings(scaled, {b.name: clean[rows] for b, rows in blocks})))
    t0 = time.perf_counter()
    rf = identify_replicates(free, noisy)
    t1 = time.perf_counter()
    rx = identify_replicates(fixed.with_readings(clean), noisy)
    t2 = time.perf_counter()
    return dict(layout=layout, free=rf, fixed=rx, seconds=(t1 - t0, t2 - t1), m=len(clean), N=realisations,
                m_by=[(b.name, b.m) for b, _ in blocks])


def d2_of(rep) -> np.ndarray:
    e = rep.p - C.P_TRUE
    return np.einsum("ki,ki->k", e, np.linalg.solve(rep.covariance, e[..., None])[..., 0])


HEADER = ["layout", "arm", "realisations", "readings", "fraction_inside_95", "binomial_se", "median_ellipse_dof",
          "sample_sd_E_kPa", "mean_std_E_kPa", "sample_sd_K0", "mean_std_K0", "bias_E_in_sd", "bias_K0_in_sd",
          "not_converged_or_at_bound", "seconds"]
SCALE_HEADER = ["layout", "instrument", "true_k", "readings", "mean_k2", "se_mean_k2", "bias_k2_in_se", "mean_k",
                "se_mean_k", "median_k", "interval_coverage_95", "binomial_se", "mean_dof", "mean_k2_ml"]


def summarise(res: dict) -> tuple[list[dict], list[dict]]:
    from geoback.inference.scale_estimates import chi2_ppf

    N = res["N"]
    rows, scale_rows = [], []
    arms = [("free", res["free"], res["free"].inside(C.P_TRUE), res["seconds"][0]),
            ("free, chi2 limit", res["free"], d2_of(res["free"]) < chi2_ppf(0.95, 2), res["seconds"][0]),
            ("fixed at 1", res["fixed"], res["fixed"].inside(C.P_TRUE), res["seconds"][1])]
    for arm, rep, inside, sec in arms:
        f = float(inside.mean())
        sd = rep.p.std(axis=0, ddof=1)
        bias = (rep.p.mean(axis=0) - C.P_TRUE) / sd
        rows.append(dict(layout=res["layout"], arm=arm, realisations=N, readings=res["m"], fraction_inside_95=f,
                         binomial_se=float(np.sqrt(f * (1 - f) / N)),
                         median_ellipse_dof=float(np.median(rep.ellipse_dof)) if rep.ellipse_dof is not None else np.inf,
                         sample_sd_E_kPa=sd[0], mean_std_E_kPa=float(rep.std[:, 0].mean()), sample_sd_K0=sd[1],
                         mean_std_K0=float(rep.std[:, 1].mean()), bias_E_in_sd=bias[0], bias_K0_in_sd=bias[1],
                         not_converged_or_at_bound=int((~rep.converged | rep.at_bound.any(axis=1)).sum()),
                         seconds=sec))
    rf = res["free"]
    counts = dict(res["m_by"])
    for j, name in enumerate(rf.scale_names):
        k, k_true = rf.scales[:, j], TRUE_SCALES[name]
        k2 = k * k
        cover = (rf.scale_low[:, j] <= k_true) & (k_true <= rf.scale_high[:, j])
        c = float(cover.mean())
        se_k2 = float(k2.std(ddof=1) / np.sqrt(N))
        scale_rows.append(dict(layout=res["layout"], instrument=name, true_k=k_true, readings=counts[name],
                               mean_k2=float(k2.mean()), se_mean_k2=se_k2,
                               bias_k2_in_se=float((k2.mean() - k_true ** 2) / se_k2), mean_k=float(k.mean()),
                               se_mean_k=float(k.std(ddof=1) / np.sqrt(N)), median_k=float(np.median(k)),
                               interval_coverage_95=c, binomial_se=float(np.sqrt(c * (1 - c) / N)),
                               mean_dof=float(rf.scale_dof[:, j].mean()),
                               mean_k2_ml=float(np.mean(k2 * rf.scale_dof[:, j] / counts[name]))))
    return rows, scale_rows


def plot(results: list[dict], rows: list[dict], path: Path) -> None:
    plt = C.pyplot()
    fig, axes = plt.subplots(1, 1 + len(results), figsize=(4.2 * (1 + len(results)), 4.0))
    ax = axes[0]
    labels = [f"{r['layout']}\n{r['arm']}" for r in rows]
    frac = [100 * r["fraction_inside_95"] for r in rows]
    err = [200 * r["binomial_se"] for r in rows]
    colours = ["C0" if r["arm"] == "free" else "C7" if r["arm"].startswith("free,") else "C3" for r in rows]
    ax.barh(range(len(rows)), frac, xerr=err, color=colours, alpha=0.8)
    ax.axvspan(93, 97, color="C2", alpha=0.2, label="93-97 %")
    ax.axvline(95, color="k", lw=0.8)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(labels, fontsize=7)
    ax.set_xlabel("truth inside the 95 % ellipse [%]  (± 2 se)")
    ax.set_xlim(0, 100)
    ax.legend(fontsize=7, loc="lower left")
    for ax, res in zip(axes[1:], results):
        rf = res["free"]
        for j, name in enumerate(rf.scale_names):
            k = rf.scales[:, j]
            ax.hist(k, bins=np.linspace(0, max(6.0, float(np.quantile(k, 0.995))), 50), alpha=0.55,
                    color=f"C{j}", label=f"{name}: k̂ (truth {TRUE_SCALES[name]:g})", density=True)
            ax.axvline(TRUE_SCALES[name], color=f"C{j}", ls="--")
        ax.set_xlabel("estimated scale k = σ / stated σ")
        ax.set_title(f"{res['layout']} layout ({' + '.join(f'{n} {m}' for n, m in res['m_by'])} readings)",
                     fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--realisations", type=int, default=None, help="noise realisations (default 1000, small 150)")
    ap.add_argument("--layouts", default=None, help="comma-separated: dense,paper (default both; small: dense)")
    args = ap.parse_args(argv)
    n = args.realisations or (150 if args.small else 1000)
    layouts = (args.layouts or ("dense" if args.small else "dense,paper")).split(",")
    results = [run(layout, n, args.seed + k) for k, layout in enumerate(layouts)]
    rows, scale_rows = [], []
    for res in results:
        a, b = summarise(res)
        rows += a
        scale_rows += b
    out = Path(args.out)
    C.write_csv(out / f"{NAME}.csv", HEADER, [[r[h] for h in HEADER] for r in rows])
    C.write_csv(out / f"{NAME}_scales.csv", SCALE_HEADER, [[r[h] for h in SCALE_HEADER] for r in scale_rows])
    plot(results, rows, out / f"{NAME}.png")
    print(C.format_table(HEADER[:8], [[r[h] for h in HEADER[:8]] for r in rows]))
    print()
    print(C.format_table(SCALE_HEADER, [[r[h] for h in SCALE_HEADER] for r in scale_rows]))
    print(f"-> {out / (NAME + '.csv')}, {out / (NAME + '_scales.csv')}, {out / (NAME + '.png')}")
    return {"rows": rows, "scales": scale_rows}


if __name__ == "__main__":
    main(sys.argv[1:])
