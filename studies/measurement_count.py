"""Study (a), paper Fig. 7: reliability of E and K0 against the number of readings.

Four layouts of displacement readings (independent, equal sigma: diagonal C_x, as in the
paper's section on the number of measurements):

  2   uy at the crown-line point nearest the crown (paper point 12, depth 6.25 m) and ux at
      the springline wall (paper point A): the problem is exactly determined;
  12  the paper case: ux at points 1-7 (x = 5 m, depths 21, 18, ..., 3 m), uy at points 8-12
      (x = 0, depths 1.25 ... 6.25 m);
  24  15 ux (x = 5 m, depths 22.5, 21, ..., 1.5 m) and 9 uy (x = 0, depths 0.7 ... 6.3 m);
  55  the 24 plus uy at the crown and ux, uy at 15 wall points between crown and invert.

std(E), std(K0) are the square roots of the diagonal of C_p = (A^t C_x^-1 A)^-1 (eqn 55)
evaluated at the truth (E = 10 MPa, K0 = 1) by geoback's reliability module. Running two
sigma values shows that they are proportional to sigma. As a check that each layout
identifies the truth, E and K0 are also fitted to noise-free readings from a 2x finer mesh.

    python studies/measurement_count.py [--small] [--out DIR]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common as C  # noqa: E402

SIGMAS = (0.001, 0.002)  # m: two measurement errors to show std proportional to sigma
NAME = "measurement_count"


def layouts(sigma: float) -> dict[int, list[dict]]:
    """Instrument lists of the four layouts (all `points`, diagonal C_x)."""
    ux12 = [(5.0, -d) for d in np.arange(21.0, 2.0, -3.0)]  # paper points 1-7
    uy12 = [(0.0, -d) for d in np.arange(1.25, 6.3, 1.25)]  # paper points 8-12
    ux24 = [(5.0, -d) for d in np.arange(22.5, 1.0, -1.5)]  # 15 points
    uy24 = [(0.0, -d) for d in np.linspace(0.7, 6.3, 9)]  # 9 points
    wall = C.wall_points(15)
    out = {
        2: [C.points("crown_line", [(0.0, -6.25)], ["uy"], sigma),
            C.points("springline", [(3.0, -10.0)], ["ux"], sigma)],
        12: [C.points("P1_7", ux12, ["ux"], sigma), C.points("P8_12", uy12, ["uy"], sigma)],
        24: [C.points("P1_15", ux24, ["ux"], sigma), C.points("P16_24", uy24, ["uy"], sigma)],
    }
    out[55] = out[24] + [C.points("crown", [(0.0, -7.0)], ["uy"], sigma),
                         C.points("wall", wall, ["ux", "uy"], sigma)]
    return out


def std_at_truth(problem) -> tuple[np.ndarray, object]:
    """std of the parameters from C_p at the truth (reliability module, full C_x = sigma^2 I)."""
    from geoback.inference.reliability import assess

    at_truth = problem.with_readings(problem.predict(C.P_TRUE).x, "full").misfit
    rel = assess(at_truth.evaluate(C.P_TRUE, jacobian=True), at_truth.parameters, at_truth.logdet)
    return rel.std, rel


def run(small: bool = False) -> list[dict]:
    scale = 0.5 if small else 1.0
    rows = []
    for sigma in SIGMAS:
        for m, instruments in layouts(sigma).items():
            data = C.case_dict(instruments, mesh_scale=scale, name=f"count-{m}")
            loaded = C.loaded_case(data)
            problem = C.problem_with(loaded)
            assert problem.misfit.m == m, (m, problem.misfit.m)
            std, rel = std_at_truth(problem)
            # identification from noise-free readings of a 2x finer mesh (discretisation bias only)
            problem = problem.with_readings(C.stack(problem, C.fine_readings(loaded, refine=2.0)))
            fit, _ = C.identify_p(problem, "full")
            rows.append(dict(readings=m, sigma_m=sigma, std_E_kPa=std[0], std_K0=std[1],
                             std_E_per_sigma=std[0] / sigma, std_K0_per_sigma=std[1] / sigma,
                             corr_E_K0=rel.correlation[0, 1], E_hat_kPa=fit.p[0], K0_hat=fit.p[1],
                             iterations=fit.iterations, status=fit.status, dofs=problem.simulation.dofs))
    return rows


def plot(rows: list[dict], path: Path) -> None:
    plt = C.pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.8))
    for ax, key, label in ((axes[0], "std_E_kPa", "std(E) [MPa]"), (axes[1], "std_K0", "std(K$_0$) [-]")):
        for sigma, marker in zip(SIGMAS, ("o", "s")):
            sel = [r for r in rows if r["sigma_m"] == sigma]
            ms = [r["readings"] for r in sel]
            vals = [r[key] / (1000.0 if key == "std_E_kPa" else 1.0) for r in sel]
            ax.plot(ms, vals, marker=marker, label=f"$\\sigma$ = {1000 * sigma:g} mm")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks([2, 12, 24, 55])
        ax.set_xticklabels(["2", "12", "24", "55"])
        ax.xaxis.set_minor_formatter(plt.NullFormatter())
        ax.set_xlabel("number of readings")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle("Reliability against number of readings (cf. paper Fig. 7); C$_p$ at the truth")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


HEADER = ["readings", "sigma_m", "std_E_kPa", "std_K0", "std_E_per_sigma", "std_K0_per_sigma", "corr_E_K0",
          "E_hat_kPa", "K0_hat", "iterations", "status", "dofs"]


def main(argv: list[str] | None = None) -> list[dict]:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    rows = run(small=args.small)
    out = Path(args.out)
    C.write_csv(out / f"{NAME}.csv", HEADER, [[r[h] for h in HEADER] for r in rows])
    plot(rows, out / f"{NAME}.png")
    print(C.format_table(HEADER, [[r[h] for h in HEADER] for r in rows]))
    print(f"-> {out / (NAME + '.csv')}, {out / (NAME + '.png')}")
    return rows


if __name__ == "__main__":
    main(sys.argv[1:])
