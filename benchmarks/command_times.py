"""Wall times of whole commands on shipped cases, alternating, N times each (medians):

- `geoback run` against `geoback simulate` on cases/tunnel-paper.yaml (floor: run <= 1.5 x simulate);
- `geoback diagnose` against `geoback run` on a concealed case (floor: diagnose <= 20 x run).

    python benchmarks/command_times.py [--repeat 5] [--concealed cases/concealed/layer-boundary.yaml]
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def timed(args: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "geoback.commands.cli", *args], check=False, capture_output=True)
    return time.perf_counter() - t0


def ratio(case: str, a: list[str], b: list[str], repeat: int, floor: float) -> float:
    with tempfile.TemporaryDirectory() as out:
        timed([b[0], case, *b[1:], "--out", out])  # mesh into the cache, warm the file system
        ta, tb = [], []
        for _ in range(repeat):
            ta.append(timed([a[0], case, *a[1:], "--out", out]))
            tb.append(timed([b[0], case, *b[1:], "--out", out]))
    ma, mb = statistics.median(ta), statistics.median(tb)
    print(f"{Path(case).name}: median of {repeat}")
    print(f"  geoback {a[0]:9s} {ma:6.2f} s   (min {min(ta):.2f}, max {max(ta):.2f})")
    print(f"  geoback {b[0]:9s} {mb:6.2f} s   (min {min(tb):.2f}, max {max(tb):.2f})")
    print(f"  ratio {a[0]} / {b[0]} = {ma / mb:.2f} (floor <= {floor:g}: {'PASS' if ma / mb <= floor else 'FAIL'})")
    return ma / mb


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--paper", default=str(ROOT / "cases" / "tunnel-paper.yaml"))
    ap.add_argument("--concealed", default=str(ROOT / "cases" / "concealed" / "layer-boundary.yaml"))
    args = ap.parse_args(argv)
    ratio(args.paper, ["run", "--quiet"], ["simulate"], args.repeat, 1.5)
    ratio(args.concealed, ["diagnose", "--quiet"], ["run", "--quiet"], args.repeat, 20.0)


if __name__ == "__main__":
    main()
