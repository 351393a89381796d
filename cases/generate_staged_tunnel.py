"""Readings of cases/staged-tunnel.yaml: simulated on a mesh twice as fine as the case's (no inverse
crime) at the 'true' values below, after each construction stage, with noise drawn from each
instrument's covariance C_x (independent draws per stage), written to staged-tunnel-readings.csv
(instrument, stage, station, reading in mm); the advance stage's rows alone to
staged-forecast-readings.csv (cases/staged-forecast.yaml: forecast the lined stage from them).

    python cases/generate_staged_tunnel.py [--seed 11]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from geoback.outputs import write_csv
from geoback.commands.simulate import without_readings
from geoback.inference.synthetic import synthetic_readings

HERE = Path(__file__).resolve().parent
CASE = HERE / "staged-tunnel.yaml"
OUT = HERE / "staged-tunnel-readings.csv"
FIRST_STAGE_ONLY = HERE / "staged-forecast-readings.csv"
TRUTH = {"E[clay]": 40000.0, "K0": 0.7, "beta[advance]": 0.35}  # the lining as in the case
SEED = 11


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    loaded = without_readings(CASE)
    readings = synthetic_readings(loaded, refine=2.0, values=TRUTH, noise_seed=args.seed, by_stage=True)
    rows = [[name, stage, i + 1, round(v * 1e3, 4)] for name, sets in readings.items()
            for stage, values in sets.items() for i, v in enumerate(values)]
    write_csv(OUT, ["instrument", "stage", "station", "reading [mm]"], rows)
    first = [r for r in rows if r[1] == "advance"]
    write_csv(FIRST_STAGE_ONLY, ["instrument", "stage", "station", "reading [mm]"], first)
    print(f"{len(rows)} readings -> {OUT}; {len(first)} of the advance stage -> {FIRST_STAGE_ONLY}")


if __name__ == "__main__":
    main()
