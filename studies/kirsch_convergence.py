"""Mesh convergence of the wall displacement of a deep unlined tunnel against Kirsch's solution.

Deep tunnel: radius R = 1, axis depth L = 1e4 R, half-width L, depth 2L, uniform initial stress
sigma_v = -p0, sigma_h = K0 sigma_v (K0 = 0.5, nu = 0.25, E = 1000, p0 = 1), released in one step.
Closed form (DESIGN.md): u_r = -p0 R / (4G) [(1 + K0) - (1 - K0)(3 - 4 nu) cos 2theta].

Two refinement series, each five meshes (four halvings):

  A "size_tunnel"  size_tunnel = R/4 ... R/64, size_far = L/10 fixed, the library's grading
                   (element size h(d) = size_tunnel + growth d, mesh.growth = 0.25 by default).
                   Only the elements within a few size_tunnel of the wall get finer: the error
                   soon stalls at the discretisation error of the graded zone (~1e-4), which
                   this series never refines.
  B "uniform"      size_tunnel = R/2 ... R/32 and mesh.growth = 0.5 ... 1/32 halved together, so
                   the element size halves everywhere (up to size_far = L/10, where the Kirsch
                   field is ~(R/r)^2 < 1e-4 of its wall value): a true h-refinement.

Expected rate. P2 isoparametric triangles (curved along the wall, exact quadrature of the
load): the energy-norm error is O(h^2) and the L2 displacement error O(h^3); a point value on
the boundary converges at about h^3 on unstructured meshes (h^4 superconvergence at vertices
needs locally symmetric meshes). Series B should show a slope of about 3 in h, i.e. about
1.5 in DOFs (DOFs ~ h^-2 for uniform refinement), until the floors below.

Floors. The finite domain changes the wall displacement by O(R/L): the free surface and the
fixed bottom mostly translate the tunnel region rigidly (vertically, ~1.4e-4 of the crown
displacement for L = 1e4 R; ~1.4e-3 for L = 1e3 R) - that is the whole of the crown's "raw"
error floor. The springline's u_x is untouched by a vertical translation (and the symmetry axis
forbids a horizontal one). The "translation removed" errors subtract
t = (u_y(crown) + u_y(invert)) / 2 (zero for the exact, top-bottom symmetric solution) from u_y;
what is left of the truncation is a smooth strain of order (R/L)^2 = 1e-8, far below the errors
measured. (Larger L is not possible: gmsh fails to place the curved mid-side nodes at
L = 1e6 R, "Cannot reparametrize a mesh node in high order meshing".)

    python studies/kirsch_convergence.py          # writes studies/out/kirsch_convergence.{csv,png}
"""
from __future__ import annotations

import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

import geoback.physics.mesh as gmesh
from geoback.case.loading import case_from_data
from geoback.physics.fem import FEModel
from geoback.physics.ground import plane_strain_isotropic
from geoback.physics.solver import Factorisation

OUT = Path(__file__).resolve().parent / "out"
R, L = 1.0, 1.0e4
E, NU, K0, P0 = 1000.0, 0.25, 0.5, 1.0
SIZE_FAR = L / 10
LEVELS = 5

SERIES = {
    # name: [(size_tunnel, growth or None = library default)]
    "size_tunnel": [(R / 4 / 2 ** k, None) for k in range(LEVELS)],
    "uniform": [(R / 2 / 2 ** k, 0.5 / 2 ** k) for k in range(LEVELS)],
}


def exact_ur(theta):
    G = E / (2 * (1 + NU))
    return -P0 * R / (4 * G) * ((1 + K0) - (1 - K0) * (3 - 4 * NU) * np.cos(2 * theta))


def run(size_tunnel: float, growth) -> dict:
    case = case_from_data(dict(
        name="kirsch-convergence",
        geometry=dict(radius=R, axis_depth=L, width=L, depth=2 * L),
        ground=dict(unit_weight=1.0, K0=K0, layers=[dict(name="rock", top=0.0, E=E, nu=NU)]),
        mesh=dict(size_tunnel=size_tunnel, size_far=SIZE_FAR, **({"growth": growth} if growth else {})),
    ), allow_large=True)  # the finest levels are large on purpose
    t0 = time.perf_counter()
    mesh = gmesh.build_mesh(case, use_cache=False, allow_large=True)
    fe = FEModel(mesh, L, 2 * L, (0.0, -L), R)
    fact = Factorisation(fe.matrix(np.tile(plane_strain_isotropic(E, NU), (fe.ne, 1))))
    sv = np.full(len(fe.wall_points), -P0)
    u = fe.expand(fact.solve(fe.load(sv, K0 * sv))).reshape(-1, 2)
    seconds = time.perf_counter() - t0

    wall = np.unique(mesh.tunnel_edges)
    d = fe.nodes[wall] - np.array([0.0, -L])
    r = np.hypot(d[:, 0], d[:, 1])
    theta = np.arctan2(d[:, 1], d[:, 0])
    crown, invert, spring = wall[np.argmax(d[:, 1])], wall[np.argmin(d[:, 1])], wall[np.argmax(d[:, 0])]
    exact = exact_ur(theta)
    scale = np.abs(exact).max()
    shift = 0.5 * (u[crown, 1] + u[invert, 1])  # rigid vertical translation (domain truncation)
    ur_raw = np.einsum("nx,nx->n", u[wall], d) / r
    ur_t = ur_raw - shift * d[:, 1] / r
    return dict(
        size_tunnel=size_tunnel, growth=case.mesh.growth,
        dofs=fe.nfree, elements=fe.ne,
        err_crown=abs(u[crown, 1] / exact_ur(np.pi / 2) - 1),
        err_crown_t=abs((u[crown, 1] - shift) / exact_ur(np.pi / 2) - 1),
        err_springline=abs(u[spring, 0] / exact_ur(0.0) - 1),
        err_wall=np.abs(ur_raw - exact).max() / scale,
        err_wall_t=np.abs(ur_t - exact).max() / scale,
        translation=shift / exact_ur(np.pi / 2),
        seconds=seconds,
    )


ERRORS = ("err_crown", "err_crown_t", "err_springline", "err_wall", "err_wall_t")
RATED = ("err_crown_t", "err_springline", "err_wall_t")


FIT_LEVELS = 3  # the slope is fitted over the finest meshes (the coarsest are pre-asymptotic)


def add_rates(rows: list[dict]) -> dict:
    """Successive observed rates in h, and least-squares slopes (in h and in DOFs) per error
    over the FIT_LEVELS finest meshes."""
    for a, b in zip(rows, rows[1:]):
        for e in RATED:
            b["rate_" + e] = math.log(a[e] / b[e]) / math.log(a["size_tunnel"] / b["size_tunnel"])
    fits = {}
    fine = rows[-FIT_LEVELS:]
    h = np.log([row["size_tunnel"] for row in fine])
    n = np.log([row["dofs"] for row in fine])
    for e in RATED:
        y = np.log([row[e] for row in fine])
        fits[e] = (np.polyfit(h, y, 1)[0], np.polyfit(n, y, 1)[0])
    return fits


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    styles = {"size_tunnel": "--", "uniform": "-"}
    labels = {"err_crown_t": "crown", "err_springline": "springline", "err_wall_t": "max over wall"}
    colours = {"err_crown_t": "C0", "err_springline": "C1", "err_wall_t": "C2"}
    for name, rows in results.items():
        hs = np.array([row["size_tunnel"] for row in rows])
        ns = np.array([row["dofs"] for row in rows])
        for e in RATED:
            ys = np.array([row[e] for row in rows])
            lab = f"{labels[e]} ({name})"
            axes[0].loglog(hs, ys, styles[name], marker="o", color=colours[e], label=lab)
            axes[1].loglog(ns, ys, styles[name], marker="o", color=colours[e], label=lab)
    rows = results["uniform"]
    h0, e0 = rows[0]["size_tunnel"], rows[0]["err_wall_t"]
    hs = np.array([row["size_tunnel"] for row in rows])
    axes[0].loglog(hs, e0 * (hs / h0) ** 3, ":", color="k", label="slope 3 (h^3)")
    ns = np.array([row["dofs"] for row in rows])
    axes[1].loglog(ns, e0 * (ns / ns[0]) ** -1.5, ":", color="k", label="slope -1.5 (DOFs^-3/2)")
    axes[0].set_xlabel("element size at the wall h / R")
    axes[1].set_xlabel("free DOFs")
    for ax in axes:
        ax.set_ylabel("relative error (rigid translation removed)")
        ax.grid(True, which="both", alpha=0.3)
    ticks = sorted({row["size_tunnel"] for rows_ in results.values() for row in rows_})
    axes[0].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    axes[0].set_xticks(ticks, [f"1/{R / t:g}" for t in ticks])
    axes[0].invert_xaxis()
    axes[0].legend(fontsize=7, loc="lower left")
    axes[1].legend(handles=[axes[1].lines[-1]], fontsize=7, loc="upper right")
    fig.suptitle(f"Kirsch, P2 isoparametric: K0 = {K0}, nu = {NU}, L = {L:g} R "
                 "(dashed: size_tunnel only; solid: uniform refinement)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    results, fits = {}, {}
    for name, levels in SERIES.items():
        rows = []
        for size_tunnel, growth in levels:
            row = run(size_tunnel, growth)
            row["series"] = name
            rows.append(row)
            print(f"  {name:12s} h = R/{R / size_tunnel:<4g} growth {row['growth']:<8g} {row['dofs']:>8} DOFs "
                  f"{row['seconds']:6.1f} s", file=sys.stderr, flush=True)
        fits[name] = add_rates(rows)
        results[name] = rows

    columns = ["series", "size_tunnel", "growth", "dofs", "elements", *ERRORS, "translation",
               *("rate_" + e for e in RATED), "seconds"]
    with open(OUT / "kirsch_convergence.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
        w.writeheader()
        for rows in results.values():
            for row in rows:
                w.writerow({k: (f"{v:.6e}" if isinstance(v, float) else v) for k, v in row.items()})
    plot(results, OUT / "kirsch_convergence.png")

    print(f"Kirsch convergence, K0 = {K0}, nu = {NU}, R = {R:g}, L = {L:g}, size_far = {SIZE_FAR:g}")
    print("relative errors; '(t)': rigid vertical translation removed; rates: observed order in h\n")
    print("| series | h/R | growth | DOFs | crown | crown (t) | springline | wall max | wall max (t) "
          "| rate crown (t) | rate springline | rate wall (t) |")
    print("|" + "|".join(["---"] * 12) + "|")
    for name, rows in results.items():
        for row in rows:
            rates = " | ".join(f"{row['rate_' + e]:.2f}" if "rate_" + e in row else "" for e in RATED)
            print(f"| {name} | 1/{R / row['size_tunnel']:g} | {row['growth']:g} | {row['dofs']:,} | "
                  f"{row['err_crown']:.2e} | {row['err_crown_t']:.2e} | {row['err_springline']:.2e} | "
                  f"{row['err_wall']:.2e} | {row['err_wall_t']:.2e} | {rates} |")
    print()
    for name, f in fits.items():
        print(f"least-squares slope over the {FIT_LEVELS} finest meshes, series {name}: " + ", ".join(
            f"{e.removeprefix('err_')} ~ h^{f[e][0]:.2f} ~ DOFs^{f[e][1]:.2f}" for e in RATED))
    print(f"\nwrote {OUT / 'kirsch_convergence.csv'} and {OUT / 'kirsch_convergence.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
