"""Peak memory and time of each physics against the estimate `validate` announces (case/meshsize.py).

For each shipped case of a physics (elastic: the paper case; staged: staged-tunnel; Mohr-Coulomb:
plastic-tunnel) at a few mesh sizes, in a fresh interpreter each (tests/measure.py's peak, VmHWM):

- `forward`: one forward run with the sensitivities of the case's parameters (what a fit iterates),
  against ``Work.forward_bytes`` (the per-DOF constants ``meshsize.BYTES_PER_DOF`` are fitted to it);
- `run` (with --run): the whole `geoback run` (the fit, the discretisation-error check on the mesh twice
  as fine, the outputs), against ``MeshEstimate.run_bytes``.

Measured on the 2-core reference machine under load (forward with the sensitivities of 4 parameters;
Mohr-Coulomb three stages 0.5, 0.8, 1.0):

| physics | DOFs | peak | estimate |
|---|---|---|---|
| Mohr-Coulomb | 5,182 | 164 MB | 213 MB |
| Mohr-Coulomb | 10,298 | 223 MB | 275 MB |
| Mohr-Coulomb | 16,070 | 316 MB | 344 MB |
| Mohr-Coulomb | 30,022 | 457 MB | 513 MB |
| Mohr-Coulomb | 54,982 | 793 MB | 815 MB |
| Mohr-Coulomb | 99,870 | 1.31 GB | 1.36 GB |
| staged | 8,382 | 166 MB | 237 MB |
| staged | 29,896 | 372 MB | 461 MB |
| staged | 82,572 | 969 MB | 1.01 GB |
| elastic | 15,634 | 158 MB | 202 MB |
| elastic | 52,418 | 275 MB | 323 MB |

Whole runs (`geoback run`, the check included): Mohr-Coulomb 2,394 DOFs 189 MB (estimate 213 MB),
5,182 DOFs 265 MB (321 MB), 10,298 DOFs 453 MB (510 MB; the check's run on the finer mesh did not
converge); staged 3,250 DOFs 183 MB (237 MB).

    python benchmarks/physics_costs.py            # forward runs
    python benchmarks/physics_costs.py --run      # whole `geoback run`s (minutes)
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

CASES = {"elastic": ("tunnel-paper.yaml", [(0.1, 1.0), (0.05, 0.5)]),
         "staged": ("staged-tunnel.yaml", [(0.15, 1.5), (0.07, 0.7), (0.04, 0.4)]),
         "mohr-coulomb": ("plastic-tunnel.yaml", [(0.2, 3.0), (0.1, 2.0), (0.07, 1.5), (0.05, 1.0), (0.035, 0.7),
                                                  (0.025, 0.5)])}

PROBE = r"""
import json, sys, time
def hwm():
    with open('/proc/self/status') as fh:
        return next(int(l.split()[1]) for l in fh if l.startswith('VmHWM:')) * 1024
import geoback
from geoback.inference.identification import prepare
a = prepare(geoback.load_case(sys.argv[1], allow_large=True))
t0 = time.perf_counter()
a.predict(a.parameters.initial, sensitivities=True)
print(json.dumps({'dofs': a.simulation.dofs, 'peak': hwm(), 'seconds': time.perf_counter() - t0,
                  'factorisations': a.simulation.counters.factorisations}))
"""


def variant(folder: Path, name: str, size_tunnel: float, size_far: float) -> Path:
    data = yaml.safe_load((ROOT / "cases" / name).read_text())
    for ins in data["instruments"]:
        if "readings_file" in ins:
            ins["readings_file"] = str(ROOT / "cases" / ins["readings_file"])
    data["mesh"] = dict(data.get("mesh") or {}, size_tunnel=size_tunnel, size_far=size_far)
    path = folder / f"{Path(name).stem}-{size_tunnel:g}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--run", action="store_true", help="measure whole `geoback run`s instead of forward runs")
    args = ap.parse_args(argv)
    from geoback.case.loading import load_case
    from geoback.case.meshsize import Work, estimate, mesh_inputs
    from measure import run_cli

    folder = Path(tempfile.mkdtemp(prefix="physics-costs-"))
    env = dict(os.environ, GEOBACK_CACHE=str(folder / "cache"))
    print("| physics | DOFs | peak | estimate | ratio | seconds |\n|---|---|---|---|---|---|")
    for physics, (name, sizes) in CASES.items():
        for st, sf in sizes:
            path = variant(folder, name, st, sf)
            case = load_case(path, allow_large=True).case
            work = Work.of(case)
            est = estimate(mesh_inputs(case), work)
            if args.run:
                m = run_cli(["run", path, "-q", "--out", folder / "out", "--allow-large"], folder, env=env)
                peak, dofs, seconds, guess = m.peak_bytes, est.dofs, m.seconds, est.run_bytes
            else:
                out = subprocess.run([sys.executable, "-c", PROBE, str(path)], capture_output=True, text=True, env=env)
                got = json.loads(out.stdout.strip().splitlines()[-1])
                peak, dofs, seconds = got["peak"], got["dofs"], got["seconds"]
                guess = work.forward_bytes(dofs, case.mesh.order)
            print(f"| {physics} | {dofs:,.0f} | {peak / 1e6:.0f} MB | {guess / 1e6:.0f} MB | {guess / peak:.2f} | "
                  f"{seconds:.1f} |", flush=True)


if __name__ == "__main__":
    main()
