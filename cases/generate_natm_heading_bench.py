"""Readings of cases/natm-heading-bench.yaml: simulated on a mesh twice as fine as the case's (no
inverse crime) at the 'true' values below, after each construction stage (the bench chord C3 once
the bench is dug), with noise drawn from each instrument's covariance C_x (independent draws per
stage), written to natm-heading-bench-readings.csv (instrument, stage, station, reading in m).

    python cases/generate_natm_heading_bench.py [--seed 19]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from geoback.commands.simulate import without_readings, write_readings_csv
from geoback.inference.synthetic import synthetic_readings

HERE = Path(__file__).resolve().parent
CASE = HERE / "natm-heading-bench.yaml"
OUT = HERE / "natm-heading-bench-readings.csv"
TRUTH = {"E[clay]": 60000.0, "K0": 0.8, "beta[heading]": 0.35}  # the made ground, beta[bench] and linings as in the case
SEED = 19
NOT_YET = {"C3": ("heading", "heading-lined")}  # the bench walls do not exist before the bench is dug


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    loaded = without_readings(CASE)
    readings = synthetic_readings(loaded, refine=2.0, values=TRUTH, noise_seed=args.seed, by_stage=True)
    readings = {name: {stage: v for stage, v in sets.items() if stage not in NOT_YET.get(name, ())}
                for name, sets in readings.items()}
    write_readings_csv(loaded, readings, OUT, [f"made by {Path(__file__).name}: the case's model on a mesh twice as "
                                               f"fine at {TRUTH}, noise from each C_x (seed {args.seed})"])
    print(f"{sum(len(v) for sets in readings.values() for v in sets.values())} readings -> {OUT}")


if __name__ == "__main__":
    main()
