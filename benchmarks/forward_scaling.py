"""Forward-model scaling: mesh, assembly, factorisation and solve time, and peak memory.

The geometry is that of cases/tunnel-paper.yaml (R = 3 m, axis depth 10 m, half-width 40 m,
depth 30 m; one layer, nu = 0.49, gravity initial stress, K0 = 1), meshed ever finer to reach
about 10 k, 100 k and 700 k free DOFs. Every (size, backend) runs in a fresh subprocess so that
the peak resident memory (getrusage RUSAGE_SELF ru_maxrss) belongs to that run alone.

Stages (seconds):
  mesh      gmsh, without the cache (not part of a forward run: meshing happens once per case)
  model     FEModel construction: element matrices, sparsity pattern, wall quadrature
  K         fe.matrix(coeffs): the stiffness for given parameters (repeated in an identification
            whenever the stiffness changes) plus the load vector
  factor    sparse Cholesky/LU of K
  solve     one back-substitution
  forward   model + K + factor + solve (what `geoback run` spends on its first prediction)
  forward CPU  user + system CPU seconds of the forward stages (all threads; less sensitive
            than wall time to other work on the machine); load: 1-min load average at the end

Floors on the 2-core reference machine: 100 k DOFs forward < 5 s; 700 k DOFs forward < 60 s
with peak memory < 8 GiB.

    python benchmarks/forward_scaling.py                 # 10 k and 100 k both backends, 700 k pardiso
    python benchmarks/forward_scaling.py --all-backends  # scipy (SuperLU) at 700 k too (minutes)
    python benchmarks/forward_scaling.py --sizes 10k     # a quick run
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

# mesh size h (size_far; size_tunnel = h/2) of the tunnel-paper geometry for each target
TARGETS = {"10k": 1.08, "100k": 0.335, "700k": 0.125}
FLOORS = {"100k": (5.0, None), "700k": (60.0, 8.0)}  # forward seconds, GiB


def case_data(h: float) -> dict:
    return dict(
        name="forward-scaling",
        geometry=dict(radius=3.0, axis_depth=10.0, width=40.0, depth=30.0),
        ground=dict(unit_weight=20.0, K0=1.0, layers=[dict(name="clay", top=0.0, E=1.0e4, nu=0.49)]),
        mesh=dict(size_tunnel=h / 2, size_far=h),
    )


def cpu_seconds() -> float:
    """User + system CPU time of this process (all threads)."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20  # KiB on Linux


def child(h: float, backend: str) -> dict:
    """One forward run in this (fresh) process; returns the measurements."""
    import numpy as np

    from geoback.case.loading import case_from_data
    from geoback.physics.fem import FEModel
    from geoback.physics.ground import plane_strain_isotropic
    from geoback.physics.mesh import build_mesh
    from geoback.physics.solver import Factorisation

    out: dict = {"h": h, "backend": backend}
    case = case_from_data(case_data(h), allow_large=True)  # up to 700 k DOFs on purpose
    g = case.geometry
    t0 = time.perf_counter()
    mesh = build_mesh(case, use_cache=False, allow_large=True)
    t1 = time.perf_counter()
    out["rss_mesh"] = rss_gib()
    c1 = cpu_seconds()
    fe = FEModel(mesh, g.width, g.depth, (0.0, -g.axis_depth), g.radius)
    t2 = time.perf_counter()
    out["rss_model"] = rss_gib()
    coeffs = np.tile(np.array(plane_strain_isotropic(1.0e4, 0.49)), (fe.ne, 1))
    K = fe.matrix(coeffs)
    sv = -case.ground.unit_weight * (-fe.wall_points[:, 1])
    f = fe.load(sv, sv)
    t3 = time.perf_counter()
    fact = Factorisation(K, backend)
    t4 = time.perf_counter()
    out["rss_factor"] = rss_gib()
    u = fact.solve(f)
    t5 = time.perf_counter()
    out["forward_cpu"] = cpu_seconds() - c1
    out["loadavg"] = os.getloadavg()[0]
    residual = np.linalg.norm(fe.symmetric_product(K, u) - f) / np.linalg.norm(f)
    out.update(ndof=int(fe.nfree), elements=int(fe.ne), nnz_upper=int(K.nnz),
               mesh=t1 - t0, model=t2 - t1, K=t3 - t2, factor=t4 - t3, solve=t5 - t4,
               forward=t5 - t1, peak_gib=rss_gib(), residual=float(residual),
               umax=float(np.abs(u).max()))
    return out


def run_child(h: float, backend: str, timeout: float) -> dict:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, GEOBACK_CACHE=cache)  # nothing is cached anyway (use_cache=False)
        proc = subprocess.run([sys.executable, __file__, "--child", str(h), backend],
                              capture_output=True, text=True, env=env, timeout=timeout)
    if proc.returncode != 0:
        return {"h": h, "backend": backend, "error": (proc.stderr.strip().splitlines() or ["?"])[-1]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def table(rows: list[dict]) -> str:
    head = ("| target | backend | DOFs | elements | mesh [s] | model [s] | K [s] | factor [s] | "
            "solve [s] | forward [s] | forward CPU [s] | peak RSS [GiB] | load | floor |")
    lines = [head, "|" + "|".join(["---"] * 14) + "|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['target']} | {r['backend']} | failed: {r['error']} |" + " |" * 11)
            continue
        floor = FLOORS.get(r["target"])
        verdict = ""
        if floor:
            seconds, gib = floor
            ok = r["forward"] < seconds and (gib is None or r["peak_gib"] < gib)
            verdict = ("ok" if ok else "MISSED") + f" (< {seconds:g} s" + (f", < {gib:g} GiB)" if gib else ")")
        lines.append(f"| {r['target']} | {r['backend']} | {r['ndof']:,} | {r['elements']:,} | {r['mesh']:.2f} | "
                     f"{r['model']:.2f} | {r['K']:.2f} | {r['factor']:.2f} | {r['solve']:.3f} | "
                     f"{r['forward']:.2f} | {r['forward_cpu']:.2f} | {r['peak_gib']:.2f} | {r['loadavg']:.1f} | {verdict} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", nargs=2, metavar=("H", "BACKEND"), help=argparse.SUPPRESS)
    ap.add_argument("--sizes", default=",".join(TARGETS), help="comma-separated targets (10k,100k,700k)")
    ap.add_argument("--all-backends", action="store_true", help="also run scipy (SuperLU) at 700 k DOFs")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per subprocess")
    ap.add_argument("--json", help="also write the measurements to this JSON file")
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(child(float(args.child[0]), args.child[1])))
        return 0

    from geoback.physics.solver import available_backends

    backends = available_backends()
    rows = []
    for target in args.sizes.split(","):
        h = TARGETS[target]
        for backend in backends:
            if target == "700k" and backend == "scipy" and not args.all_backends:
                continue
            r = run_child(h, backend, args.timeout)
            r["target"] = target
            rows.append(r)
            print(f"  {target:>5} {backend:8s} " + (r["error"] if "error" in r else
                  f"{r['ndof']} DOFs, forward {r['forward']:.2f} s, peak {r['peak_gib']:.2f} GiB, "
                  f"residual {r['residual']:.1e}"), file=sys.stderr, flush=True)
    print(f"CPU cores: {os.cpu_count()}, python {sys.version.split()[0]}\n")
    print(table(rows))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    missed = [r for r in rows if "error" not in r and r["target"] in FLOORS and r["backend"] == backends[0]
              and (r["forward"] >= FLOORS[r["target"]][0]
                   or (FLOORS[r["target"]][1] and r["peak_gib"] >= FLOORS[r["target"]][1]))]
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
