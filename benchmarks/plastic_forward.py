"""One elastoplastic forward run at about 50 k DOFs, and the cost of its DDM sensitivities.

Deep circular tunnel (R = 1 m, L = 50 R, wall elements R/33 growing by 0.06 per unit distance:
48.6 k free DOFs), hydrostatic p0 = 1000 kPa, Mohr-Coulomb E = 100 MPa, nu = 0.4, c = 110 kPa,
phi = 30 deg, psi = 20 deg (non-associated: unsymmetric tangent), released to lambda = 0.9 and 1
(plastic radius 1.77 R at full release), Newton tolerance 1e-10.

Printed: DOFs, quadrature points, increments, Newton iterations, factorisations, back-substitutions,
wall time by part (mesh and model set-up apart from the forward solve), peak resident memory, and
the same run with the DDM sensitivities of 4 parameters (E, c, phi, beta): their extra time,
which is back-substitutions plus one complex-step evaluation of the return mapping per parameter
and increment (the converged tangent is factorised anyway: it starts the next increment).

Goal on the 2-core reference machine: forward under 20 s; sensitivities a small fraction of it.

    python benchmarks/plastic_forward.py
    python benchmarks/plastic_forward.py --psi 30 --size 0.05 --growth 0.1   # other settings
"""
from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=float, default=0.03, help="element size at the wall [R]")
    ap.add_argument("--growth", type=float, default=0.06)
    ap.add_argument("--psi", type=float, default=20.0, help="dilation angle [deg]")
    ap.add_argument("--backend", default=None, help="pardiso | scipy (default: pardiso if installed)")
    args = ap.parse_args(argv)

    from geoback.physics.plasticity import Material, Options, ParameterDerivative, solve
    from geoback.physics.plasticity.deep_tunnel import deep_tunnel_model, hydrostatic_load
    from geoback.physics.plasticity.operators import PointOperators

    t0 = time.perf_counter()
    fe = deep_tunnel_model(L=50.0, size_tunnel=args.size, growth=args.growth)
    t_model = time.perf_counter() - t0
    t0 = time.perf_counter()
    ops = PointOperators(fe)
    t_ops = time.perf_counter() - t0
    sigma0, f = hydrostatic_load(fe, 1000.0)
    mat = Material.from_degrees(1.0e5, 0.4, 110.0, 30.0, args.psi)
    stages = np.array([0.9, 1.0])
    opts = Options(backend=args.backend)

    t0 = time.perf_counter()
    res = solve(fe, mat, sigma0, f, stages, options=opts, operators=ops)
    t_fwd = time.perf_counter() - t0
    c = res.counters

    derivs = [ParameterDerivative("E", E=1.0), ParameterDerivative("c", c=1.0),
              ParameterDerivative("phi", phi=1.0), ParameterDerivative("beta", stages=stages)]
    t0 = time.perf_counter()
    res_d = solve(fe, mat, sigma0, f, stages, derivatives=derivs, options=Options(backend=args.backend,
                                                                                  schedule=res.schedule),
                  operators=ops)
    t_ddm = time.perf_counter() - t0
    cd = res_d.counters
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # MiB (Linux: KiB)

    from geoback.physics.plasticity.linear import default_backend

    print(f"DOFs {fe.nfree}   quadrature points {ops.npts}   psi {args.psi:g} deg   "
          f"backend {opts.backend or default_backend(fe.nfree)}   "
          f"MKL threads {os.environ.get('MKL_NUM_THREADS', 'default')}")
    print(f"set-up: mesh + FEModel {t_model:.2f} s, point operators {t_ops:.2f} s")
    print(f"forward: {t_fwd:.2f} s wall   increments {c.increments}   Newton iterations {c.newton_iterations}   "
          f"factorisations {c.factorisations}   back-substitutions {c.backsubstitutions}   cutbacks {c.cutbacks}")
    print("  by part [s]: " + ", ".join(f"{k} {v:.2f}" for k, v in sorted(c.seconds.items(), key=lambda kv: -kv[1])))
    print(f"  max converged relative residual {res.converged_residuals().max():.1e} (tolerance {res.tol:g})")
    print(f"forward + DDM of {len(derivs)} parameters: {t_ddm:.2f} s wall   factorisations {cd.factorisations}   "
          f"back-substitutions {cd.backsubstitutions} (+{cd.backsubstitutions - c.backsubstitutions})")
    sens = cd.seconds["sensitivities"]
    local = cd.seconds["sensitivities: local derivatives and right-hand sides"]
    hist = cd.seconds["sensitivities: stress history"]
    print(f"  sensitivities {sens:.2f} s = {sens / t_fwd:.1%} of the forward ({sens / t_fwd / len(derivs):.1%} per "
          f"parameter): local derivatives and right-hand sides {local:.2f} s, back-substitutions "
          f"{sens - local - hist:.2f} s, stress history {hist:.2f} s; wall-time difference {t_ddm - t_fwd:+.2f} s")
    print(f"peak resident memory {peak:.0f} MiB")


if __name__ == "__main__":
    main()
