"""Study (c): are geoback's 95 % confidence ellipses from C_p calibrated?

The paper case's instruments with realistic errors: inclinometer I1 (7 stations, slope
sigma = 0.001 rad, toe fixed) and extensometer X1 (5 stations, sigma = 0.5 mm, head survey
variance var A = 1e-6 m2). Each realisation adds a draw from N(0, C_x) (C_x = L L^t, the
instruments' full covariance, eqn 9) to noise-free readings computed at the truth
(E = 10 MPa, K0 = 1), identifies E and K0 with the full C_x from the paper's start
(E = 5 MPa, K0 = 0.5), and checks whether the truth lies inside the 95 % ellipse of that fit:

    d^2 = (p_hat - p_true)^t C_p^-1 (p_hat - p_true) < chi2.ppf(0.95, 2) = 5.99

with C_p = (A'^t A')^-1 evaluated by geoback at p_hat. The fraction inside is reported with
its binomial standard error sqrt(f (1 - f) / N).

No inverse crime, and an honest test: the noise-free readings come from a mesh twice as fine
as the fitting mesh (``--data-mesh fine``, the default), so the estimate carries the fitting
mesh's discretisation bias. The study measures that bias first (fit of the noise-free readings)
and prints it in units of the parameters' std and as the coverage it implies (non-central
chi-square); it must stay below 0.1 std, otherwise the ellipse test would measure the mesh and
not C_p. ``--data-mesh same`` generates the readings on the fitting mesh itself (zero bias).

    python studies/calibration.py [--small] [--realisations N] [--data-mesh fine|same] [--out DIR]
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

NAME = "calibration"
LEVEL = 0.95
BIAS_LIMIT = 0.1  # discretisation bias allowed, in std of the estimate


def case_data(mesh_scale: float) -> dict:
    """The paper case (I1 + X1, their sigma and var A), readings dropped, full C_x."""
    return C.without_readings(C.case_dict(mesh_scale=mesh_scale, weighting="full", name="calibration"))


def chi2_ppf(q: float, dof: int) -> float:
    from scipy import stats

    return float(stats.chi2.ppf(q, dof))


def run(realisations: int, small: bool = False, seed: int = 0, data_mesh: str = "fine") -> dict:
    # the paper's mesh in both sizes: its discretisation bias is ~0.01 std (a coarser one reaches 0.15)
    loaded = C.loaded_case(case_data(1.0))
    problem = C.problem_with(loaded)
    if data_mesh == "fine":
        clean = C.stack(problem, C.fine_readings(loaded, refine=2.0))
    else:
        clean = problem.predict(C.P_TRUE).x

    # discretisation bias of the fitting mesh, in std of the estimate and as implied coverage
    from scipy import stats

    from geoback.inference.identification import identify_replicates

    problem = problem.with_readings(clean)
    f0, rel0 = C.identify_p(problem, "full")
    bias = f0.p - C.P_TRUE
    d2_bias = float(bias @ np.linalg.solve(rel0.covariance, bias))
    limit = chi2_ppf(LEVEL, 2)
    expected = float(stats.ncx2.cdf(limit, 2, d2_bias)) if d2_bias > 0 else LEVEL

    rng = np.random.default_rng(seed)
    data = problem.misfit.data
    noisy = np.array([clean + data.noise(rng) for _ in range(realisations)])
    t0 = time.perf_counter()
    rep = identify_replicates(problem, noisy)  # one supported call: every fit reuses one factorisation
    seconds = time.perf_counter() - t0
    est, cp = rep.p, rep.covariance
    e = est - C.P_TRUE
    d2 = np.einsum("ki,ki->k", e, np.linalg.solve(cp, e[..., None])[..., 0])
    status_ok = rep.converged & ~rep.at_bound.any(axis=1)
    inside = d2 < limit
    frac = float(inside.mean())
    return dict(est=est, d2=d2, cp=cp, inside=inside, fraction=frac,
                se=float(np.sqrt(frac * (1 - frac) / realisations)), limit=limit,
                bias=bias, bias_std=bias / rel0.std, d2_bias=d2_bias, expected=expected, std0=rel0.std,
                cp0=rel0.covariance, ok=status_ok, seconds=seconds, dofs=problem.simulation.dofs,
                factorisations=problem.simulation.counters.factorisations, realisations=realisations,
                data_mesh=data_mesh)


HEADER = ["realisations", "data_mesh", "dofs", "fraction_inside_95", "binomial_se", "expected_with_bias",
          "bias_E_kPa", "bias_K0", "bias_E_in_std", "bias_K0_in_std", "Cp_std_E_kPa", "Cp_std_K0",
          "sample_sd_E_kPa", "sample_sd_K0", "sample_corr", "Cp_corr", "mean_d2", "not_converged_or_at_bound"]


def summarise(res: dict) -> dict:
    sample = np.cov(res["est"].T)
    cp0 = res["cp0"]
    return dict(realisations=res["realisations"], data_mesh=res["data_mesh"], dofs=res["dofs"],
                fraction_inside_95=res["fraction"], binomial_se=res["se"], expected_with_bias=res["expected"],
                bias_E_kPa=res["bias"][0], bias_K0=res["bias"][1], bias_E_in_std=res["bias_std"][0],
                bias_K0_in_std=res["bias_std"][1], Cp_std_E_kPa=res["std0"][0], Cp_std_K0=res["std0"][1],
                sample_sd_E_kPa=float(np.sqrt(sample[0, 0])), sample_sd_K0=float(np.sqrt(sample[1, 1])),
                sample_corr=float(sample[0, 1] / np.sqrt(sample[0, 0] * sample[1, 1])),
                Cp_corr=float(cp0[0, 1] / np.sqrt(cp0[0, 0] * cp0[1, 1])), mean_d2=float(res["d2"].mean()),
                not_converged_or_at_bound=int((~res["ok"]).sum()))


def plot(res: dict, row: dict, path: Path) -> None:
    from scipy import stats

    plt = C.pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4.2))
    e = res["est"]
    ax1.scatter(e[res["inside"], 0] / 1000, e[res["inside"], 1], s=6, alpha=0.5, color="C0", label="truth inside")
    ax1.scatter(e[~res["inside"], 0] / 1000, e[~res["inside"], 1], s=10, color="C3", label="truth outside")
    # the 95 % ellipse of C_p (at the noise-free fit) centred on the truth: where the estimates should fall
    w, V = np.linalg.eigh(res["cp0"])
    t = np.linspace(0, 2 * np.pi, 200)
    circle = np.sqrt(res["limit"]) * np.vstack([np.cos(t), np.sin(t)])
    ell = (V @ (np.sqrt(w)[:, None] * circle)) + C.P_TRUE[:, None]
    ax1.plot(ell[0] / 1000, ell[1], "k-", lw=1.2, label="95 % ellipse of C$_p$")
    ax1.plot([C.E_TRUE / 1000], [C.K0_TRUE], "k*", ms=12, label="truth")
    ax1.set_xlabel("E identified [MPa]")
    ax1.set_ylabel("K$_0$ identified [-]")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    hi = max(15.0, float(np.quantile(res["d2"], 0.995)))
    ax2.hist(res["d2"], bins=np.linspace(0, hi, 40), density=True, alpha=0.6, label="d$^2$ of the truth")
    x = np.linspace(0, hi, 300)
    ax2.plot(x, stats.chi2.pdf(x, 2), "k-", label="$\\chi^2_2$")
    ax2.axvline(res["limit"], color="C3", ls="--", label=f"$\\chi^2_{{2,0.95}}$ = {res['limit']:.2f}")
    ax2.set_xlabel("$d^2 = (\\hat{p} - p_{true})^t C_p^{-1} (\\hat{p} - p_{true})$")
    ax2.set_title(f"inside: {100 * row['fraction_inside_95']:.1f} % $\\pm$ {100 * row['binomial_se']:.1f} % "
                  f"({row['realisations']} realisations)", fontsize=10)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--realisations", type=int, default=None, help="noise realisations (default 1000, small 100)")
    ap.add_argument("--data-mesh", choices=("fine", "same"), default="fine",
                    help="noise-free readings from a 2x finer mesh (default) or from the fitting mesh")
    args = ap.parse_args(argv)
    n = args.realisations or (100 if args.small else 1000)
    res = run(n, small=args.small, seed=args.seed, data_mesh=args.data_mesh)
    row = summarise(res)
    out = Path(args.out)
    C.write_csv(out / f"{NAME}.csv", HEADER, [[row[h] for h in HEADER]])
    plot(res, row, out / f"{NAME}.png")
    print(C.format_table(["quantity", "value"], [[h, row[h]] for h in HEADER]))
    if max(abs(res["bias_std"])) > BIAS_LIMIT:
        print(f"WARNING: the discretisation bias exceeds {BIAS_LIMIT} std "
              f"({res['bias_std'][0]:.3f}, {res['bias_std'][1]:.3f}): refine the fitting mesh or use --data-mesh same")
    print(f"{res['dofs']} dofs, {res['factorisations']} factorisation(s), {n} fits in {res['seconds']:.1f} s")
    print(f"-> {out / (NAME + '.csv')}, {out / (NAME + '.png')}")
    return row


if __name__ == "__main__":
    main(sys.argv[1:])
