"""Study (b), paper Figs. 9-10: the full inclinometer C_x against C_x = I.

15 inclinometer stations (x = 5 m, toe at 24 m depth assumed fixed, spacing 1.5 m: stations
at depths 22.5, 21, ..., 1.5 m), i.e. the 15 horizontal displacements of the paper's layout
(c). Each realisation draws the slope errors alpha_i ~ N(0, sigma_a^2), sigma_a = 0.005 rad,
and integrates them from the toe as in eqn 15, u_n = sum_{i<=n} alpha_i l_i; the result is
added to noise-free readings computed at the truth (E = 10 MPa, K0 = 1) on a mesh twice as
fine as the fitting mesh. E and K0 are then identified twice from the same readings, from the
paper's start (E = 5 MPa, K0 = 0.5): with the full C_x of eqn 17 and with C_x = I (eqn 8).

RMSE = sqrt(mean((p_hat - p_true)^2)) over the realisations. It also contains the
discretisation bias of the fitting mesh, which is reported separately (the fit of the
noise-free fine-mesh readings); it is tiny against the noise.

    python studies/covariance_structure.py [--small] [--realisations N] [--out DIR]
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

NAME = "covariance_structure"
SIGMA_ALPHA = 0.005  # rad, as in the paper
STATIONS, SPACING, TOE, X = 15, 1.5, 24.0, 5.0
WEIGHTINGS = ("full", "identity")


def case_data(mesh_scale: float) -> dict:
    ins = [C.inclinometer("I15", X, TOE, SPACING, STATIONS, SIGMA_ALPHA)]
    return C.case_dict(ins, mesh_scale=mesh_scale, name="inclinometer-15")


def slope_noise(rng: np.random.Generator, lengths: np.ndarray) -> np.ndarray:
    """Slope errors integrated from the toe, eqn 15 (B exactly known: zero)."""
    from geoback.case.covariance import integration_matrix

    alpha = rng.normal(0.0, SIGMA_ALPHA, len(lengths))
    return integration_matrix("inclinometer", lengths) @ alpha


def run(realisations: int, small: bool = False, seed: int = 0) -> dict:
    loaded = C.loaded_case(case_data(0.5 if small else 1.0))
    problem = C.problem_with(loaded)
    lengths = problem.simulation.survey.blocks[0].lengths
    clean = C.stack(problem, C.fine_readings(loaded, refine=2.0))

    # discretisation bias: noise-free fine-mesh readings, both weightings
    bias = {}
    for w in WEIGHTINGS:
        problem = problem.with_readings(clean)
        f, _ = C.identify_p(problem, w)
        bias[w] = f.p - C.P_TRUE

    rng = np.random.default_rng(seed)
    est = {w: np.empty((realisations, 2)) for w in WEIGHTINGS}
    ok = {w: np.ones(realisations, bool) for w in WEIGHTINGS}
    cp_std = np.empty((realisations, 2))
    t0 = time.perf_counter()
    for k in range(realisations):
        problem = problem.with_readings(clean + slope_noise(rng, lengths))
        for w in WEIGHTINGS:
            f, rel = C.identify_p(problem, w)
            est[w][k] = f.p
            ok[w][k] = f.status == "converged" and not f.at_bound.any()
            if w == "full":
                cp_std[k] = rel.std
    seconds = time.perf_counter() - t0
    return dict(est=est, ok=ok, bias=bias, cp_std=cp_std, seconds=seconds, dofs=problem.simulation.dofs,
                factorisations=problem.simulation.counters.factorisations, realisations=realisations)


def summarise(res: dict) -> list[dict]:
    rows = []
    for w in WEIGHTINGS:
        e = res["est"][w]
        err = e - C.P_TRUE
        rmse = np.sqrt(np.mean(err ** 2, axis=0))
        row = dict(weighting=w, realisations=res["realisations"], rmse_E_kPa=rmse[0], rmse_K0=rmse[1],
                   mae_median_E_kPa=float(np.median(np.abs(err[:, 0]))), mae_median_K0=float(np.median(np.abs(err[:, 1]))),
                   mean_err_E_kPa=err[:, 0].mean(), mean_err_K0=err[:, 1].mean(),
                   sd_E_kPa=e[:, 0].std(ddof=1), sd_K0=e[:, 1].std(ddof=1),
                   bias_E_kPa=res["bias"][w][0], bias_K0=res["bias"][w][1],
                   not_converged_or_at_bound=int((~res["ok"][w]).sum()))
        if w == "full":
            row["mean_Cp_std_E_kPa"] = float(np.mean(res["cp_std"][:, 0]))
            row["mean_Cp_std_K0"] = float(np.mean(res["cp_std"][:, 1]))
        else:
            row["mean_Cp_std_E_kPa"] = row["mean_Cp_std_K0"] = float("nan")
        rows.append(row)
    return rows


HEADER = ["weighting", "realisations", "rmse_E_kPa", "rmse_K0", "mae_median_E_kPa", "mae_median_K0",
          "mean_err_E_kPa", "mean_err_K0", "sd_E_kPa",
          "sd_K0", "bias_E_kPa", "bias_K0", "mean_Cp_std_E_kPa", "mean_Cp_std_K0", "not_converged_or_at_bound"]


def plot(res: dict, rows: list[dict], path: Path) -> None:
    plt = C.pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 5))
    for w, colour in zip(WEIGHTINGS, ("C0", "C3")):
        e = res["est"][w]
        r = next(r for r in rows if r["weighting"] == w)
        label = (f"C$_x$ {'full (eqn 17)' if w == 'full' else '= I'}: RMSE E {r['rmse_E_kPa'] / 1000:.2f} MPa, "
                 f"K$_0$ {r['rmse_K0']:.3f}")
        ax.scatter(e[:, 0] / 1000, e[:, 1], s=8, alpha=0.5, color=colour, label=label)
    ax.plot([C.E_TRUE / 1000], [C.K0_TRUE], "k*", ms=14, label="truth")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("E identified [MPa] (bounds 0.1-1000 MPa)")
    ax.set_ylabel("K$_0$ identified [-] (bounds 0.05-5)")
    ax.set_title(f"15 inclinometer readings, $\\sigma_\\alpha$ = {SIGMA_ALPHA} rad, "
                 f"{res['realisations']} realisations", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> list[dict]:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--realisations", type=int, default=None, help="noise realisations (default 400, small 60)")
    args = ap.parse_args(argv)
    n = args.realisations or (60 if args.small else 400)
    res = run(n, small=args.small, seed=args.seed)
    rows = summarise(res)
    out = Path(args.out)
    C.write_csv(out / f"{NAME}.csv", HEADER, [[r[h] for h in HEADER] for r in rows])
    plot(res, rows, out / f"{NAME}.png")
    print(C.format_table(HEADER, [[r[h] for h in HEADER] for r in rows]))
    full, ident = rows
    print(f"RMSE ratio identity/full: E {ident['rmse_E_kPa'] / full['rmse_E_kPa']:.2f}, "
          f"K0 {ident['rmse_K0'] / full['rmse_K0']:.2f}  ({res['dofs']} dofs, {res['factorisations']} "
          f"factorisation(s), {2 * n} fits in {res['seconds']:.1f} s)")
    print(f"-> {out / (NAME + '.csv')}, {out / (NAME + '.png')}")
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
