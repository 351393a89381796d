"""Readings of cases/twin-tunnels.yaml: simulated on a mesh twice as fine as the case's (no inverse
crime) at the 'true' values below, once each tunnel has passed (stages west-lined and east-lined),
with noise drawn from each instrument's covariance C_x (independent draws per stage), written to
twin-tunnels-readings.csv (instrument, stage, station, reading in m).

    python cases/generate_twin_tunnels.py [--seed 1]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from geoback.commands.simulate import without_readings, write_readings_csv
from geoback.inference.synthetic import synthetic_readings

HERE = Path(__file__).resolve().parent
CASE = HERE / "twin-tunnels.yaml"
OUT = HERE / "twin-tunnels-readings.csv"
TRUTH = {"E[clay]": 45000.0, "K0": 0.65}  # the gravel, the releases and the rings as in the case
SEED = 1
READ_AT = ("west-lined", "east-lined")  # once each tunnel had passed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    loaded = without_readings(CASE)
    readings = synthetic_readings(loaded, refine=2.0, values=TRUTH, noise_seed=args.seed, by_stage=True)
    readings = {name: {stage: v for stage, v in sets.items() if stage in READ_AT} for name, sets in readings.items()}
    write_readings_csv(loaded, readings, OUT, [f"made by {Path(__file__).name}: the case's model on a mesh twice as "
                                               f"fine at {TRUTH}, noise from each C_x (seed {args.seed})"])
    print(f"{sum(len(v) for sets in readings.values() for v in sets.values())} readings -> {OUT}")


if __name__ == "__main__":
    main()
