"""The core's performance figures (issue 10), each measured in a fresh process, printed as a table.

Rows:
  1M factorisations   identification of E, K0 on the paper geometry meshed to ~1 M DOFs: how many
                      factorisations (floor: 1) and where the time goes
  1M run              `geoback run` (no plots) on that case: wall seconds (floor: < 30 s, idle machine)
  ratio 100k / paper  in-process identification time / one forward solve (assemble + factorise +
                      solve) on ~100 k DOFs (floor 1.3) and on the paper mesh (floor 2)
  run CPU             whole `geoback run cases/tunnel-paper.yaml` (start-up included): CPU seconds
                      (floor 0.5), median of --repeat runs
  plots               `geoback run --plots` / `geoback run` on a two-layer case (floor 2), medians
  Monte Carlo         1000 replicate identifications on the paper mesh through
                      geoback.inference.identification.identify_replicates: CPU seconds (floor 3)

The mesh cache is warmed before anything is timed (meshing happens once per case). Peak memory is
each child's maximum resident set.

    python benchmarks/core.py                     # every row (the 1 M rows take a few minutes)
    python benchmarks/core.py --rows paper,run,plots,mc
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
MESH = {"paper": None, "100k": (0.17, 0.335), "1M": (0.05, 0.105)}  # (size_tunnel, size_far) [m]
ROWS = ("1M", "100k", "paper", "run", "plots", "mc")


def case_file(folder: Path, sizes, name: str) -> Path:
    """The paper case, meshed with these element sizes (None: the case's own)."""
    data = yaml.safe_load(PAPER.read_text())
    data["name"] = name
    if sizes:
        data["mesh"]["size_tunnel"], data["mesh"]["size_far"] = sizes
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def two_layer_case(folder: Path) -> Path:
    """The paper geometry with a stiffer marl below 9 m, E of both and K0 identified (readings from a
    mesh twice as fine, no noise)."""
    from geoback.case.loading import load_case
    from geoback.inference.synthetic import synthetic_readings

    data = yaml.safe_load(PAPER.read_text())
    data["name"] = "two-layers"
    data["ground"]["layers"] = [{"name": "clay", "top": 0.0, "E": "10 MPa", "nu": 0.49},
                                {"name": "marl", "top": 9.0, "E": "30 MPa", "nu": 0.45}]
    data["parameters"] = [{"name": "E[clay]", "initial": "6 MPa", "bounds": [100, 1e6]},
                          {"name": "E[marl]", "initial": "20 MPa", "bounds": [100, 1e6]},
                          {"name": "K0", "initial": 0.6, "bounds": [0.05, 5.0]}]
    path = folder / "two-layers.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    readings = synthetic_readings(load_case(path), refine=2.0)
    for ins in data["instruments"]:
        ins["readings"] = [float(v) for v in readings[ins["name"]]]
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def peak_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


def cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


# ---------------------------------------------------------------------------- children
def child_identify(path: str) -> dict:
    """prepare + identify in process; then one forward solve from scratch for the ratio."""
    from geoback.case.loading import load_case
    from geoback.inference.identification import identify, prepare
    from geoback.physics.mesh import build_mesh

    import numpy as np
    import scipy.sparse as sp

    from geoback.physics.solver import Factorisation

    loaded = load_case(path, allow_large=True)
    build_mesh(loaded.case, allow_large=True)  # warm cache
    # warm the sparse solver's libraries (MKL's threads and memory pools) on a tiny system, so that
    # neither the identification nor the forward solve is charged their one-time start-up
    Factorisation(sp.triu(sp.eye(50, format="csr") * 2.0, format="csr")).solve(np.ones(50))
    t0 = time.perf_counter()
    analysis = prepare(loaded)
    t1 = time.perf_counter()
    sim = analysis.simulation
    if sim.dofs < 500_000:  # one full-size forward first, forgotten, so that the identification is
        # not charged the first large factorisation's page faults and pools (the forward timed below
        # runs warm, after the identification); at 1 M DOFs the memory makes this too costly
        sim.predict(analysis.values)
        sim.release()
    # identification and one forward solve (assemble + factorise + solve, as an external code does
    # for each run), alternated and each from scratch; medians over the repeats (a shared machine)
    repeats = 7 if sim.dofs < 20_000 else 3 if sim.dofs < 500_000 else 1
    ids, fwds = [], []
    for _ in range(repeats):
        sim.release()
        before = sim.counters.snapshot()
        t2 = time.perf_counter()
        res = identify(analysis)
        ids.append(time.perf_counter() - t2)
        c = sim.counters.since(before)
        sim.release()
        t4 = time.perf_counter()
        sim.predict(analysis.values_at(res.fit.p))
        fwds.append(time.perf_counter() - t4)
    return dict(dofs=sim.dofs, prepare=t1 - t0, identify=statistics.median(ids),
                forward=statistics.median(fwds), ratios=[a / b for a, b in zip(ids, fwds)],
                factorisations=res.counts["factorisations"], solves=res.counts["solves"],
                forward_runs=res.counts["forward_runs"], iterations=res.fit.iterations,
                factorising=c["seconds_factorising"], solving=c["seconds_solving"], assembling=c["seconds_assembling"],
                model=sim.timings.get("assembly", 0.0), observations=sim.timings.get("observations", 0.0),
                solver=res.solver, peak_gib=peak_gib(), E=float(res.fit.p[0]), status=res.fit.status)


def child_mc(path: str, n: int) -> dict:
    import numpy as np

    from geoback.case.loading import load_case
    from geoback.inference.identification import identify_replicates, prepare

    analysis = prepare(load_case(path))
    data = analysis.misfit.data
    rng = np.random.default_rng(1)
    noisy = np.array([data.measured + data.noise(rng) for _ in range(n)])
    identify_replicates(analysis, noisy[:5])  # warm-up: the factorisation and the first solves
    c0, t0 = cpu(), time.perf_counter()
    rep = identify_replicates(analysis, noisy)
    return dict(replicates=n, cpu=cpu() - c0, wall=time.perf_counter() - t0, converged=int(rep.converged.sum()),
                factorisations=analysis.simulation.counters.factorisations, dofs=analysis.simulation.dofs)


def run_child(*args, timeout=3600) -> dict:
    out = subprocess.run([sys.executable, __file__, "--child", *map(str, args)], capture_output=True, text=True,
                         timeout=timeout, env=dict(os.environ))
    if out.returncode != 0:
        raise RuntimeError(out.stderr[-3000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def command(args: list[str], repeat: int) -> tuple[float, float]:
    """Median wall and CPU (user + system of the child) seconds of a whole command."""
    walls, cpus = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(args, capture_output=True, check=True)
        walls.append(time.perf_counter() - t0)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
    return statistics.median(walls), statistics.median(cpus)


def geoback(*args) -> list[str]:
    exe = Path(sys.executable).with_name("geoback")
    return ([str(exe)] if exe.exists() else [sys.executable, "-m", "geoback.commands.cli"]) + [str(a) for a in args]


# ---------------------------------------------------------------------------- main
def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", default=",".join(ROWS), help=f"comma-separated subset of {', '.join(ROWS)}")
    ap.add_argument("--repeat", type=int, default=5, help="runs of each whole command (medians)")
    ap.add_argument("--replicates", type=int, default=1000)
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        kind, *rest = args.child
        out = child_identify(rest[0]) if kind == "identify" else child_mc(rest[0], int(rest[1]))
        print(json.dumps(out))
        return
    rows = args.rows.split(",")
    table: list[tuple[str, str, str]] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for key in ("paper", "100k", "1M"):
            if key not in rows:
                continue
            path = case_file(tmp, MESH[key], f"bench-{key}")
            r = run_child("identify", path)
            ratio = statistics.median(r["ratios"])  # of identification and forward, alternated
            floor = {"paper": 2.0, "100k": 1.3, "1M": None}[key]
            table.append((f"{key}: DOFs, factorisations / solves / forward runs (iterations)",
                          f"{r['dofs']:,}, {r['factorisations']} / {r['solves']} / {r['forward_runs']} "
                          f"({r['iterations']})", "factorisations 1" if key == "1M" else ""))
            table.append((f"{key}: prepare (FE model {r['model']:.2f} s, instruments {r['observations']:.2f} s) / "
                          f"identify / one forward [s]",
                          f"{r['prepare']:.2f} / {r['identify']:.2f} / {r['forward']:.2f}", ""))
            table.append((f"{key}: identify: assembling / factorising / solving [s], solver, peak memory",
                          f"{r['assembling']:.2f} / {r['factorising']:.2f} / {r['solving']:.2f}, {r['solver']}, "
                          f"{r['peak_gib']:.2f} GiB", ""))
            if floor:
                table.append((f"{key}: identification / one forward solve (median of "
                              f"{', '.join(f'{x:.2f}' for x in r['ratios'])})", f"{ratio:.2f}",
                              f"<= {floor} {'PASS' if ratio <= floor else 'FAIL'}"))
            if key == "1M":
                wall, c = command(geoback("run", path, "--out", tmp / "out-1M", "-q", "--allow-large"), 1)
                table.append(("1M: geoback run (no plots), wall / CPU [s]", f"{wall:.1f} / {c:.1f}",
                              f"< 30 s {'PASS' if wall < 30 else 'FAIL'}"))
        if "run" in rows:
            command(geoback("run", PAPER, "--out", tmp / "warm", "-q"), 1)
            wall, c = command(geoback("run", PAPER, "--out", tmp / "run", "-q"), args.repeat)
            table.append(("geoback run cases/tunnel-paper.yaml: wall / CPU [s] (medians)", f"{wall:.2f} / {c:.2f}",
                          f"CPU <= 0.5 {'PASS' if c <= 0.5 else 'FAIL'}"))
        if "plots" in rows:
            path = two_layer_case(tmp)
            command(geoback("run", path, "--out", tmp / "warm2", "-q"), 1)
            w0, _ = command(geoback("run", path, "--out", tmp / "p0", "-q"), args.repeat)
            w1, _ = command(geoback("run", path, "--out", tmp / "p1", "-q", "--plots"), args.repeat)
            table.append(("two-layer case: run / run --plots wall [s] (medians)", f"{w0:.2f} / {w1:.2f}",
                          f"ratio {w1 / w0:.2f} <= 2 {'PASS' if w1 / w0 <= 2 else 'FAIL'}"))
        if "mc" in rows:
            r = run_child("mc", PAPER, args.replicates)
            table.append((f"Monte Carlo: {r['replicates']} identifications on the paper mesh ({r['dofs']} DOFs), "
                          "CPU / wall [s], factorisations",
                          f"{r['cpu']:.2f} / {r['wall']:.2f}, {r['factorisations']} ({r['converged']} converged)",
                          f"CPU <= 3 {'PASS' if r['cpu'] <= 3 else 'FAIL'}"))
    width = max(len(a) for a, _, _ in table)
    print(f"load average at the end: {os.getloadavg()[0]:.2f} (2-core machine)")
    for a, b, c in table:
        print(f"{a.ljust(width)}  {b}  {c}")


if __name__ == "__main__":
    main()
