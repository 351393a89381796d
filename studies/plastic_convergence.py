"""Mesh convergence of the elastoplastic deep tunnel against the closed form (Salencon 1969;
Carranza-Torres & Fairhurst 2000).

Deep circular tunnel (R = 1, axis depth L, half-width L, depth 2L), hydrostatic initial stress
p0 = 1000 kPa, Mohr-Coulomb ground E = 100 MPa, nu = 0.4, c = 110 kPa, phi = 30 deg, psi = 0 and
10 deg (non-associated) and psi = 30 deg (associated), full release in adaptive increments, results
also at lambda = 0.9. Closed form: R_p = 1.768 R at full release; with nu = 0.4 the out-of-plane stress
stays intermediate in the plastic zone (the closed form's assumption; with nu = 0.3 it would become
the major stress at the wall and the comparison would not be like for like).

Measured (geoback.physics.plasticity.deep_tunnel.measure): plastic radius from the crossing of the FE
radial stress with -p_cr, and the mean radial wall displacement.

Refinement series: element size at the wall ``size_tunnel`` and growth rate halved together
(so the element size halves everywhere up to size_far = L/10). Domain-size check at the middle mesh:
L = 20, 50, 100.

Non-associated perfect plasticity can lose uniqueness of the incremental problem (Hill 1958; shear
bands, Rudnicki & Rice 1975): on the finest mesh with psi = 0 the tangent's eigenvalues of least
real part approach zero near lambda = 0.8-0.9 and Newton cycles between loading/unloading patterns
of spiral bands; the run stops with NonConvergence and the table says so.

    python studies/plastic_convergence.py            # writes studies/out/plastic_convergence.csv
    python studies/plastic_convergence.py --small    # two coarse meshes, quick
"""
from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from geoback.physics.plasticity import DeepTunnelMC, Material, solve
from geoback.physics.plasticity.deep_tunnel import deep_tunnel_model, hydrostatic_load, measure
from geoback.physics.plasticity.incremental import NonConvergence
from geoback.physics.plasticity.operators import PointOperators

OUT = Path(__file__).resolve().parent / "out"
P0, E, NU, C, PHI = 1000.0, 1.0e5, 0.4, 110.0, 30.0
STAGES = (0.9, 1.0)
MESHES = [(0.2, 0.4), (0.1, 0.2), (0.05, 0.1)]  # (size_tunnel, growth) at L = 50
SMALL = [(0.2, 0.4), (0.1, 0.2)]
EXTRA = {0.0: [(0.1, 0.1)]}  # psi = 0: the finest mesh tried on which Newton still converges (12.8 k DOFs)


def run(psi_deg: float, size_tunnel: float, growth: float, L: float = 50.0) -> list[dict]:
    fe = deep_tunnel_model(L=L, size_tunnel=size_tunnel, growth=growth)
    ops = PointOperators(fe)
    sigma0, f = hydrostatic_load(fe, P0)
    mat = Material.from_degrees(E, NU, C, PHI, psi_deg)
    row = dict(psi=psi_deg, L=L, size_tunnel=size_tunnel, growth=growth, dofs=fe.nfree)
    t0 = time.perf_counter()
    try:
        res = solve(fe, mat, sigma0, f, STAGES, operators=ops)
    except NonConvergence as exc:
        return [dict(row, lam=STAGES[-1], status=f"failed: {exc}")]
    seconds = time.perf_counter() - t0
    xy = ops.point_coordinates()
    rows = []
    for k, lam in enumerate(STAGES):
        cf = DeepTunnelMC.released(P0, fe.radius, E, NU, C, np.radians(PHI), np.radians(psi_deg), lam)
        assert cf.out_of_plane_is_intermediate()
        m = measure(fe, xy, res.sigma[k].reshape(-1, 4), res.plastic[k], res.u[k], cf.critical_pressure)
        rows.append(dict(row, lam=lam, status="ok", Rp_closed=cf.plastic_radius, Rp_fe=m.plastic_radius,
                         Rp_err=m.plastic_radius / cf.plastic_radius - 1, outermost_yielded=m.outermost_yielded,
                         uR_closed=cf.wall_displacement, uR_fe=m.wall_displacement,
                         uR_err=m.wall_displacement / cf.wall_displacement - 1, wall_spread=m.wall_spread,
                         increments=res.counters.increments, newton=res.counters.newton_iterations,
                         max_residual=float(res.converged_residuals().max()), seconds=round(seconds, 2)))
    return rows


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    meshes = SMALL if args.small else MESHES
    rows = []
    for psi in (0.0, 10.0, PHI):
        for st, g in meshes + ([] if args.small else EXTRA.get(psi, [])):
            rows += run(psi, st, g)
        if not args.small and psi != 10.0:
            st, g = meshes[1]
            for L in (20.0, 100.0):
                rows += run(psi, st, g, L)
    args.out.mkdir(parents=True, exist_ok=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(args.out / "plastic_convergence.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, keys)
        w.writeheader()
        w.writerows(rows)
    print(f"{'psi':>4} {'L':>5} {'h_wall':>6} {'growth':>6} {'DOFs':>7} {'lam':>4} {'R_p err':>8} {'u_R err':>8} "
          f"{'outermost':>9} {'incr':>4} {'Newton':>6} {'max res':>8} {'s':>6}")
    for r in rows:
        if r["status"] != "ok":
            print(f"{r['psi']:4.0f} {r['L']:5.0f} {r['size_tunnel']:6.3f} {r['growth']:6.3f} {r['dofs']:7d} "
                  f"{r['lam']:4.2f} {r['status']}")
            continue
        print(f"{r['psi']:4.0f} {r['L']:5.0f} {r['size_tunnel']:6.3f} {r['growth']:6.3f} {r['dofs']:7d} "
              f"{r['lam']:4.2f} "
              f"{r['Rp_err']:+8.3%} {r['uR_err']:+8.3%} {r['outermost_yielded']:9.3f} {r['increments']:4d} "
              f"{r['newton']:6d} {r['max_residual']:8.1e} {r['seconds']:6.1f}")
    return rows


if __name__ == "__main__":
    main()
