"""`geoback run` on the shipped yielding case against a finite-difference loop of forward runs, in CPU
seconds of whole commands (issue 22).

The loop is what PEST++ GLM did when it drove `geoback simulate` on cases/plastic-tunnel.yaml (E, K0,
c', phi'; diagonal weights, so that both minimise the same objective): 152 non-linear forward runs
to the same estimates within 0.1 sigma (measured for issue 22; PEST++ is not installed here). Its CPU
is taken as 152 times the median CPU of one `geoback simulate --no-vtu --no-plots` (the cheapest
forward command: no field file, no figure; PEST++'s own work is left out, which favours the loop).
`geoback run` is the whole command as a user runs it (identification, profile-likelihood intervals
where the linearised ones are unreliable, the mesh check on a mesh twice as fine, every table and the
report; no figures). Commands alternate, --repeat times each; CPU is the children's user + system
time, so the shared machine's load inflates it little. Printed: medians, the ratio taken pair by pair
(each `run` against the `simulate` right after it: the machine's speed drifts less within a pair than
over the call; its median is the figure), and the run's counts from its summary.json (the fit's
forward runs and factorisations, the DOFs). For reference, also the loop of `simulate --no-vtu` with
its plastic-zone figure, as PEST++ ran it before `--no-plots` existed (about 0.8 s more a run: the
figure and matplotlib's import).

    python benchmarks/plastic_pest.py [--repeat 5]
"""
from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from table import print_table

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "plastic-tunnel.yaml"
PEST_RUNS = 152  # PEST++ GLM's forward runs on this case (issue 22)
PEST_CPU_THEN = 854.0  # its CPU seconds then, and geoback run's 15.7 s (55x), on a loaded machine
FLOOR = 100.0


def cpu_of(args: list[str]) -> float:
    """CPU seconds (user + system) of one geoback command run as a child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, "-m", "geoback.commands.cli", *args], capture_output=True, text=True)
    if done.returncode not in (0, 3):
        raise SystemExit(f"geoback {' '.join(args)} failed:\n{done.stderr[-2000:]}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--csv", type=Path, default=None)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run = ["run", str(CASE), "--out", f"{tmp}/run", "-q"]
        sim = ["simulate", str(CASE), "--out", f"{tmp}/sim", "--no-vtu", "--no-plots"]
        drawn = ["simulate", str(CASE), "--out", f"{tmp}/drawn", "--no-vtu"]
        cpu_of(sim)  # the mesh into the cache, the file system warm
        t_run, t_sim, t_drawn = [], [], []
        for _ in range(args.repeat):
            t_run.append(cpu_of(run))
            t_sim.append(cpu_of(sim))
            t_drawn.append(cpu_of(drawn))
        summary = json.loads(Path(f"{tmp}/run/summary.json").read_text(encoding="utf-8"))
    m_run, m_sim = statistics.median(t_run), statistics.median(t_sim)
    loop = PEST_RUNS * m_sim
    pairs = [PEST_RUNS * s / r for r, s in zip(t_run, t_sim)]  # each run against the simulate right after it
    ratio = statistics.median(pairs)
    drawn_pairs = [PEST_RUNS * s / r for r, s in zip(t_run, t_drawn)]
    rows = [
        ("geoback run (whole command), CPU s: median (min-max)", f"{m_run:.2f} ({min(t_run):.2f}-{max(t_run):.2f})"),
        ("  its fit: forward runs / factorisations / DOFs",
         f"{summary['forward_runs']} / {summary['factorisations']} / {summary['dofs']}"),
        ("geoback simulate --no-vtu --no-plots (one forward run), CPU s: median (min-max)",
         f"{m_sim:.2f} ({min(t_sim):.2f}-{max(t_sim):.2f})"),
        (f"the loop: {PEST_RUNS} forward runs (PEST++ GLM's count), CPU s", f"{loop:.0f}"),
        ("ratio loop / geoback run (CPU), pair by pair: median (min-max)",
         f"{ratio:.0f} ({min(pairs):.0f}-{max(pairs):.0f})"),
        ("for reference: simulate --no-vtu with its plastic-zone figure, CPU s: median (min-max)",
         f"{statistics.median(t_drawn):.2f} ({min(t_drawn):.2f}-{max(t_drawn):.2f})"),
        ("for reference: ratio of that loop / geoback run (CPU), pair by pair: median (min-max)",
         f"{statistics.median(drawn_pairs):.0f} ({min(drawn_pairs):.0f}-{max(drawn_pairs):.0f})"),
        (f"for reference: PEST++'s {PEST_CPU_THEN:.0f} s measured then / this run", f"{PEST_CPU_THEN / m_run:.0f}"),
        (f"target >= {FLOOR:g}x less CPU than the loop", "PASS" if ratio >= FLOOR else "FAIL"),
    ]
    return print_table(rows, args.csv)


if __name__ == "__main__":
    main(sys.argv[1:])
