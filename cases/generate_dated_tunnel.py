"""Readings of cases/dated-tunnel.yaml as instrument software exports them: simulated on a mesh
twice as fine as the case's (no inverse crime) at the 'true' values below, after each construction
stage, with independent noise per survey drawn from each instrument's C_x; each survey dated, a
baseline survey per instrument (taken as exact: the case's sigma is that of a reading relative to
it), two surveys in each stage.

- dated-tunnel-I1.csv: the inclinometer's position relative to its toe [mm] by date and depth (an
  'absolute position' export: the casing's own deviation from vertical plus its movement);
- dated-tunnel-X1.csv: the extensometer's gauge readings [mm] (an arbitrary zero plus the movement
  since its installation on 10 Mar 2026, during the advance);
- dated-tunnel-S1.csv: reduced levels [m] of the surface points.

    python cases/generate_dated_tunnel.py [--seed 31]
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from geoback.commands.simulate import without_readings
from geoback.inference.misfit import block_noise
from geoback.inference.synthetic import synthetic_readings
from geoback.observation.instruments import case_blocks
from geoback.outputs import write_csv

HERE = Path(__file__).resolve().parent
CASE = HERE / "dated-tunnel.yaml"
TRUTH = {"E[clay]": 40000.0, "K0": 0.7, "beta[advance]": 0.35}
SEED = 31
BASELINE = "2026-02-25"
SURVEYS = {"advance": ["2026-03-05", "2026-03-12"], "lined": ["2026-03-18", "2026-03-25"]}
X1_BASELINE, X1_SURVEYS = "2026-03-10", {"lined": ["2026-03-18", "2026-03-25"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    loaded = without_readings(CASE)
    exact = synthetic_readings(loaded, refine=2.0, values=TRUTH, by_stage=True)  # {instrument: {stage: x}}
    blocks = {b.name: b for b in case_blocks(loaded)}
    rng = np.random.default_rng(args.seed)

    i1 = blocks["I1"]
    depths = -i1.stations[:, 1]
    casing = 1e-3 * np.cumsum(rng.normal(0.0, 1.5, i1.m))  # the casing's own deviation [m], read at the baseline
    rows = [[BASELINE, d, round(1e3 * c, 3)] for d, c in zip(depths, casing)]
    for stage, dates in SURVEYS.items():
        for date in dates:
            x = casing + exact["I1"][stage] + block_noise(i1, rng)
            rows += [[date, d, round(1e3 * v, 3)] for d, v in zip(depths, x)]
    write_csv(HERE / "dated-tunnel-I1.csv", ["Date", "Depth [m]", "A0 position [mm]"], rows)

    x1 = blocks["X1"]
    zero = 1e-3 * rng.uniform(20.0, 40.0, x1.m)  # the gauges' arbitrary zero [m]
    rows = [[X1_BASELINE, k + 1, round(1e3 * z, 3)] for k, z in enumerate(zero)]
    for stage, dates in X1_SURVEYS.items():
        for date in dates:
            x = zero + exact["X1"][stage] - exact["X1"]["advance"] + block_noise(x1, rng)
            rows += [[date, k + 1, round(1e3 * v, 3)] for k, v in enumerate(x)]
    write_csv(HERE / "dated-tunnel-X1.csv", ["date", "station", "reading [mm]"], rows)

    s1 = blocks["S1"]
    level = 100.0 + rng.uniform(-0.3, 0.3, s1.m)  # reduced levels of the points before construction [m]
    rows = [[BASELINE, f"S1-{k + 1}", round(v, 5)] for k, v in enumerate(level)]
    for stage, dates in SURVEYS.items():
        for date in dates:
            x = level + exact["S1"][stage] + block_noise(s1, rng)
            rows += [[date, f"S1-{k + 1}", round(v, 5)] for k, v in enumerate(x)]
    write_csv(HERE / "dated-tunnel-S1.csv", ["date", "point", "level [m]"], rows)
    print("dated-tunnel-I1.csv, dated-tunnel-X1.csv, dated-tunnel-S1.csv written")


if __name__ == "__main__":
    main()
