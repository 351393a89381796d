"""Identification cost: `geoback run` against scipy.optimize.least_squares with an FD Jacobian.

The paper case (cases/tunnel-paper.yaml: E, K0 from inclinometer I1 and extensometer X1, its
readings and its weighting) with both element sizes divided by --scale (default 11.6: about
100 k DOFs). Two ways to identify E and K0 from E = 5 MPa, K0 = 0.5:

  geoback    the library path of `geoback run` (geoback.inference.identification.run_case: mesh from the
             cache, assembly, LM fit with exact sensitivities, reliability, and every output file
             of `geoback run`, field.vtu included) into a temporary folder. No subprocess: the
             CLI adds only its start-up (imports) to this.
  scipy      scipy.optimize.least_squares(fun, z0, jac='2-point', method=--ls-method) on the
             same whitened residuals r' = L^-1 (x* - x(p)) in the same scaled variables
             z = p / p_initial, where fun calls geoback's own forward solve after dropping the
             factorisation, so every call assembles and factorises K afresh - what an external
             finite-difference loop around a forward code does. Factorisations = fun calls.

Both start from a warm mesh cache (meshing is reported separately and counted for neither);
both times include preparing the case (FE model, instruments). The covariance of the
estimate from least_squares (inv(J^t J) with its final Jacobian) is compared with geoback's
C_p. Floors (issue): >= 10x fewer factorisations and >= 5x less time for geoback.

    python benchmarks/identification.py [--scale 11.6] [--ls-method trf|lm] [--csv out.csv]
"""
from __future__ import annotations

import argparse
import copy
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from fd_loop import fd_least_squares  # noqa: E402
from table import print_table

ROOT = Path(__file__).resolve().parents[1]
PAPER_CASE = ROOT / "cases" / "tunnel-paper.yaml"
FLOOR_FACTORISATIONS, FLOOR_TIME = 10.0, 5.0


def loaded_case(scale: float):
    from geoback.case.loading import LoadedCase, case_from_data

    with open(PAPER_CASE, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    data = copy.deepcopy(data)
    data["name"] = f"tunnel-paper-x{scale:g}"
    data["mesh"]["size_tunnel"] = data["mesh"]["size_tunnel"] / scale
    data["mesh"]["size_far"] = data["mesh"]["size_far"] / scale
    return LoadedCase(case_from_data(data), PAPER_CASE, {})


def run_geoback(loaded) -> dict:
    from geoback.commands.run import run_case

    with tempfile.TemporaryDirectory() as out:
        c0, t0 = time.process_time(), time.perf_counter()
        res = run_case(loaded, Path(out))
        seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
        summary = __import__("json").loads((Path(out) / "summary.json").read_text())
    parts = res.seconds
    outputs = seconds - parts.get("setup", 0.0) - parts.get("fit", 0.0) - parts.get("assess", 0.0)
    return dict(seconds=seconds, cpu=cpu, setup=parts.get("setup", float("nan")), outputs=outputs,
                fit_seconds=res.seconds.get("fit", float("nan")), p=res.fit.p,
                status=res.fit.status, iterations=res.fit.iterations, factorisations=res.counts["factorisations"],
                solves=res.counts["solves"], forward_runs=res.counts["forward_runs"], dofs=res.dofs,
                covariance=res.reliability.covariance, weighting=res.weighting, backend=res.solver or "?",
                field_work=summary.get("exploration", {}))


def run_scipy(loaded, ls_method: str) -> dict:
    from geoback.inference.identification import prepare

    c0, t0 = time.process_time(), time.perf_counter()
    problem = prepare(loaded)
    sim = problem.simulation  # the same readings and whitening as geoback
    t1 = time.perf_counter()
    fd = fd_least_squares(problem.misfit, problem.parameters, method=ls_method)
    ls = fd["ls"]
    t2, cpu = time.perf_counter(), time.process_time() - c0
    J = fd["jacobian"]
    cov = np.linalg.inv(J.T @ J)
    sim.release()
    return dict(seconds=t2 - t0, cpu=cpu, fit_seconds=t2 - t1, p=fd["p"], status=ls.message, success=ls.success,
                calls=fd["calls"], factorisations=sim.counters.factorisations, solves=sim.counters.solves,
                nfev=ls.nfev, njev=ls.njev, covariance=cov, dofs=sim.dofs)


def rel_frobenius(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    d = np.sqrt(np.diag(b))
    std = np.linalg.norm((a - b) / np.outer(d, d)) / np.linalg.norm(b / np.outer(d, d))
    return float(np.linalg.norm(a - b) / np.linalg.norm(b)), float(std)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=11.6, help="divide the paper case's element sizes by this")
    ap.add_argument("--ls-method", choices=("trf", "lm", "dogbox"), default="trf")
    ap.add_argument("--backend", choices=("pardiso", "scipy"), default=None,
                    help="sparse solver for both methods (sets GEOBACK_SOLVER; default: geoback's choice)")
    ap.add_argument("--csv", type=Path, default=None, help="also write the table as CSV")
    args = ap.parse_args(argv)

    if args.backend:
        os.environ["GEOBACK_SOLVER"] = args.backend
    from geoback.physics.mesh import build_mesh

    loaded = loaded_case(args.scale)
    t0 = time.perf_counter()
    build_mesh(loaded.case)  # warm the cache: meshing is counted for neither method
    mesh_seconds = time.perf_counter() - t0

    # warm-up (not timed): imports, MKL initialisation and first-touch allocations would otherwise
    # be charged to whichever method runs first
    run_geoback(loaded)  # both methods are then timed warm (the second one always was)
    g = run_geoback(loaded)
    s = run_scipy(loaded, args.ls_method)
    frob, frob_std = rel_frobenius(s["covariance"], g["covariance"])
    ratio_f = s["factorisations"] / g["factorisations"]
    ratio_t = s["seconds"] / g["seconds"]
    ratio_fit = s["fit_seconds"] / g["fit_seconds"]
    ratio_cpu = s["cpu"] / g["cpu"]

    rows = [
        ("DOFs", g["dofs"]),
        ("solver backend", g["backend"]),
        ("weighting (case)", g["weighting"]),
        ("mesh (gmsh, once, not counted) [s]", round(mesh_seconds, 2)),
        ("geoback run: wall time (setup + fit + assess + outputs) [s]", round(g["seconds"], 2)),
        ("geoback run: fit only [s]", round(g["fit_seconds"], 2)),
        ("geoback run: CPU time, all threads [s]", round(g["cpu"], 2)),
        ("geoback run: preparing / writing outputs [s]", f"{g['setup']:.2f} / {g['outputs']:.2f}"),
        ("geoback: factorisations", g["factorisations"]),
        ("geoback: solves (right-hand sides)", g["solves"]),
        ("geoback: forward runs / iterations", f"{g['forward_runs']} / {g['iterations']}"),
        ("geoback: field file (exploration) factorisations / solves",
         f"{g['field_work'].get('factorisations', 0)} / {g['field_work'].get('solves', 0)}"),
        ("geoback: E, K0", f"{g['p'][0]:.6g}, {g['p'][1]:.6g} ({g['status']})"),
        (f"least_squares({args.ls_method}, 2-point): wall time (setup + fit) [s]", round(s["seconds"], 2)),
        ("least_squares: fit only [s]", round(s["fit_seconds"], 2)),
        ("least_squares: CPU time, all threads [s]", round(s["cpu"], 2)),
        ("least_squares: factorisations (= fun calls)", s["factorisations"]),
        ("least_squares: fun calls / nfev / njev", f"{s['calls']} / {s['nfev']} / {s['njev']}"),
        ("least_squares: E, K0", f"{s['p'][0]:.6g}, {s['p'][1]:.6g} (success={s['success']})"),
        ("ratio factorisations (scipy / geoback)", round(ratio_f, 1)),
        ("ratio wall time (scipy / geoback)", round(ratio_t, 1)),
        ("ratio fit-only time (scipy / geoback)", round(ratio_fit, 1)),
        ("ratio CPU time (scipy / geoback)", round(ratio_cpu, 1)),
        ("load average (1 min) at the end", round(os.getloadavg()[0], 2)),
        ("C_p vs least_squares inv(J^t J): relative Frobenius", f"{frob:.2e} (standardised {frob_std:.2e})"),
        (f"floor factorisations >= {FLOOR_FACTORISATIONS:g}x", "PASS" if ratio_f >= FLOOR_FACTORISATIONS else "FAIL"),
        (f"floor time >= {FLOOR_TIME:g}x", "PASS" if ratio_t >= FLOOR_TIME else "FAIL"),
        ("C_p within 2 %", "PASS" if max(frob, frob_std) < 0.02 else "FAIL"),
    ]
    return print_table(rows, args.csv)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
