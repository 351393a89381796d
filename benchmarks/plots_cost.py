"""What `--plots` costs: CPU time of `geoback run` with and without `--plots` on every shipped case
(cases/*.yaml and cases/concealed/*.yaml), one run each, as a subprocess (its own and its
children's user + system time from the resource usage), the mesh cached beforehand (`geoback
mesh`, not counted) so that both runs start from the same cache. Prints a table: case, DOFs,
seconds without, seconds with, ratio, and the median ratio; the target is `--plots` within 2x.

    python benchmarks/plots_cost.py [--cases cases/tunnel-paper.yaml ...] [--csv out.csv]

CPU time rather than wall time: the machine's other work does not enter it (it still moves by a few
per cent between runs). A run of a few seconds carries a fixed cost of drawing the figures
(matplotlib, PNG and SVG: about half a second each), which a cheap identification cannot hide.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TARGET = 2.0


def cpu_of(args: list[str], env: dict) -> tuple[float, subprocess.CompletedProcess]:
    """CPU seconds (user + system, the command and its children) of one geoback command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run([sys.executable, "-m", "geoback.commands.cli", *args], capture_output=True, text=True,
                          env=env)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), proc


def shipped_cases() -> list[Path]:
    return sorted((ROOT / "cases").glob("*.yaml")) + sorted((ROOT / "cases" / "concealed").glob("*.yaml"))


def measure(case: Path, env: dict) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cpu_of(["mesh", str(case), "--out", str(tmp / "mesh"), "--no-plots"], env)  # into the cache
        without, p0 = cpu_of(["run", str(case), "--quiet", "--out", str(tmp / "without")], env)
        with_, p1 = cpu_of(["run", str(case), "--quiet", "--plots", "--out", str(tmp / "with")], env)
        dofs = ""
        summary = tmp / "with" / "summary.json"
        if summary.exists():
            data = json.loads(summary.read_text())
            dofs = data.get("dofs", "")
            slice_words = ""
            report = tmp / "with" / "report.md"
            if report.exists():
                line = [ln for ln in report.read_text().splitlines() if ln.startswith("Figures: ")]
                slice_words = "linearised" if line and "linearised" in line[0] else "model" if line else ""
        else:
            slice_words = ""
        ok = p0.returncode in (0, 1, 3) and p1.returncode in (0, 1, 3)
    rel = case.relative_to(ROOT) if case.is_relative_to(ROOT) else case
    return {"case": str(rel), "dofs": dofs, "without_s": without, "with_s": with_, "ratio": with_ / without,
            "objective_map": slice_words, "ok": ok}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", type=Path, default=None, help="default: every shipped case")
    ap.add_argument("--csv", type=Path, default=None, help="also write the table here")
    args = ap.parse_args(argv)
    env = dict(os.environ)
    env.setdefault("GEOBACK_CACHE", str(Path(tempfile.gettempdir()) / "geoback-plots-cost-cache"))
    rows = []
    head = f"{'case':42s} {'DOFs':>6s} {'without [s]':>11s} {'with [s]':>9s} {'ratio':>6s}  objective map"
    print(head)
    print("-" * len(head))
    for case in args.cases or shipped_cases():
        r = measure(case.resolve(), env)
        rows.append(r)
        flag = "" if r["ok"] else "  (a run failed)"
        print(f"{r['case']:42s} {r['dofs']!s:>6s} {r['without_s']:11.2f} {r['with_s']:9.2f} {r['ratio']:6.2f}  "
              f"{r['objective_map']}{flag}", flush=True)
    ratios = [r["ratio"] for r in rows]
    print("-" * len(head))
    within = sum(q <= TARGET for q in ratios)
    print(f"median ratio {statistics.median(ratios):.2f}; within {TARGET:g}x: {within} of {len(ratios)} cases")
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with open(args.csv, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
