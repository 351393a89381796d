"""Staged identification cost: (E, K0, beta) from readings at two stages, against one staged forward
run and against a finite-difference loop on the same model.

The shipped case cases/staged-tunnel.yaml (release 50 % assumed, shotcrete lining, release the rest;
inclinometer, extensometer and settlement points read after both stages) with its element sizes
divided by --scale (default 4: ~26 k DOFs, the lining's ring on ~500 wall dofs). Timed warm (the
mesh cached, one untimed warm-up of everything), each on a fresh simulation (FE model assembled,
nothing factorised):

  forward      one staged forward run: x at the case's values, both configurations (the ground; the
               ground with the lining) factorised as geoback does (the ground's factor, and its Schur
               complement on the wall with the lining condensed there), and the same run with the
               lined configuration assembled and factorised directly; the floor is measured against
               the cheaper of the two;
  geoback      identify(): Levenberg-Marquardt with exact sensitivities through the stages;
  scipy        scipy.optimize.least_squares(jac='2-point', method='trf') on the same whitened
               residuals in the same scaled variables, every call on a freshly factorised model (what
               an external finite-difference loop around a forward code does).

Floors (issue 11): identification <= 3x one staged forward run; factorisations = the number of
distinct stiffness configurations (2).

    python benchmarks/staged.py [--scale 4] [--backend pardiso|scipy] [--csv out.csv]
"""
from __future__ import annotations

import argparse
import copy
import os
import time
from pathlib import Path

import numpy as np
import yaml

from fd_loop import fd_least_squares  # noqa: E402
from table import print_table

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "staged-tunnel.yaml"
FLOOR_RATIO = 3.0


def loaded_case(scale: float):
    from geoback.case.loading import LoadedCase, case_from_data

    data = copy.deepcopy(yaml.safe_load(CASE.read_text(encoding="utf-8")))
    data["name"] = f"staged-tunnel-x{scale:g}"
    data["mesh"]["size_tunnel"] /= scale
    data["mesh"]["size_far"] /= scale
    return LoadedCase(case_from_data(data), CASE, {})


def fresh(loaded):
    from geoback.inference.identification import prepare

    t0 = time.perf_counter()
    a = prepare(loaded)
    return a, time.perf_counter() - t0


def forward(loaded, direct: bool = False) -> dict:
    """One staged forward run on a fresh simulation (nothing factorised yet)."""
    a, setup = fresh(loaded)
    sim = a.simulation
    if direct:  # make the lined configuration take its assembled factorisation
        sim.lined_system.condense = False
    t0 = time.perf_counter()
    x = sim.predict(a.values).x
    seconds = time.perf_counter() - t0
    c = sim.counters
    out = dict(seconds=seconds, setup=setup, factorisations=c.factorisations, solves=c.solves, x=x, dofs=sim.dofs,
               wall_dofs=sim.ring.n_wall_dofs, backend=sim.solver, factor_seconds=c.seconds_factorising)
    sim.release()
    return out


def run_geoback(loaded) -> dict:
    from geoback.inference.identification import identify

    a, setup = fresh(loaded)
    t0 = time.perf_counter()
    res = identify(a)
    seconds = time.perf_counter() - t0
    return dict(seconds=seconds, fit=res.seconds["fit"], setup=setup, p=res.fit.p, std=res.reliability.std,
                status=res.fit.status, iterations=res.fit.iterations, names=res.parameters.names,
                covariance=res.reliability.covariance, **res.counts)


def run_scipy(loaded) -> dict:
    a, setup = fresh(loaded)
    sim = a.simulation
    fd = fd_least_squares(a.misfit, a.parameters)  # every call factorises, as an external code does
    ls, J = fd["ls"], fd["jacobian"]
    return dict(seconds=fd["seconds"], setup=setup, p=fd["p"], calls=fd["calls"], nfev=ls.nfev, njev=ls.njev,
                factorisations=sim.counters.factorisations, solves=sim.counters.solves, success=ls.success,
                covariance=np.linalg.inv(J.T @ J))


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=4.0, help="divide the case's element sizes by this")
    ap.add_argument("--backend", choices=("pardiso", "scipy"), default=None,
                    help="sparse solver (sets GEOBACK_SOLVER; default: geoback's choice by size)")
    ap.add_argument("--csv", type=Path, default=None, help="also write the table as CSV")
    args = ap.parse_args(argv)
    if args.backend:
        os.environ["GEOBACK_SOLVER"] = args.backend
    from geoback.physics.mesh import build_mesh

    loaded = loaded_case(args.scale)
    t0 = time.perf_counter()
    build_mesh(loaded.case)
    mesh_seconds = time.perf_counter() - t0
    forward(loaded), run_geoback(loaded)  # warm-up, not timed
    f = forward(loaded)
    fd = forward(loaded, direct=True)
    g = run_geoback(loaded)
    s = run_scipy(loaded)
    cheapest = min(f["seconds"], fd["seconds"])  # the floor is against the cheaper way to run forward once
    ratio = g["seconds"] / cheapest
    d = np.sqrt(np.diag(g["covariance"]))
    cov_diff = float(np.linalg.norm((s["covariance"] - g["covariance"]) / np.outer(d, d))
                     / np.linalg.norm(g["covariance"] / np.outer(d, d)))
    est = lambda r: ", ".join(f"{n} = {v:.5g}" for n, v in zip(g["names"], r["p"]))  # noqa: E731
    rows = [
        ("DOFs (ground) / wall dofs of the lining", f"{f['dofs']} / {f['wall_dofs']}"),
        ("solver backend", f["backend"]),
        ("mesh (gmsh, once, not counted) [s]", round(mesh_seconds, 2)),
        ("preparing a simulation (FE model, lining ring, instruments) [s]", round(f["setup"], 2)),
        ("one staged forward run [s]", round(f["seconds"], 3)),
        ("  its factorisations / solves", f"{f['factorisations']} / {f['solves']}"),
        ("  of which factorising (ground factor; wall Schur complement + readings' back-substitutions) [s]",
         round(f["factor_seconds"], 3)),
        ("one staged forward run, lined configuration factorised directly [s]", round(fd["seconds"], 3)),
        ("  its factorisations / solves", f"{fd['factorisations']} / {fd['solves']}"),
        ("  readings equal to the condensed run (max relative difference)",
         f"{np.abs(fd['x'] - f['x']).max() / np.abs(f['x']).max():.1e}"),
        ("geoback identify (E, K0, beta) [s]", round(g["seconds"], 3)),
        ("  factorisations / solves / forward runs / iterations",
         f"{g['factorisations']} / {g['solves']} / {g['forward_runs']} / {g['iterations']}"),
        ("  estimate", f"{est(g)} ({g['status']})"),
        ("least_squares(trf, 2-point) [s]", round(s["seconds"], 3)),
        ("  factorisations / solves / fun calls / nfev / njev",
         f"{s['factorisations']} / {s['solves']} / {s['calls']} / {s['nfev']} / {s['njev']}"),
        ("  estimate", f"{est(s)} (success={s['success']})"),
        ("ratio identification / one staged forward run (the cheaper of the two)", round(ratio, 2)),
        ("ratio identification / one staged forward run as geoback does it", round(g["seconds"] / f["seconds"], 2)),
        ("ratio least_squares / identification (time)", round(s["seconds"] / g["seconds"], 1)),
        ("ratio least_squares / identification (factorisations)", round(s["factorisations"] / g["factorisations"], 1)),
        ("C_p vs least_squares inv(J^t J): standardised relative Frobenius", f"{cov_diff:.1e}"),
        ("load average (1 min) at the end", round(os.getloadavg()[0], 2)),
        (f"floor identification <= {FLOOR_RATIO:g}x one forward run", "PASS" if ratio <= FLOOR_RATIO else "FAIL"),
        ("floor factorisations = distinct configurations (2)", "PASS" if g["factorisations"] == 2 else "FAIL"),
    ]
    return print_table(rows, args.csv)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
