"""Readings of cases/propped-excavation.yaml: simulated on a mesh twice as fine as the case's (no inverse
crime) at the 'true' values below, after each stage before the final lift (the load cells from their
props' installation on), with noise drawn from each instrument's covariance C_x (independent draws per
stage); each load cell's reading carries its zero reading (the case's `zero`), as the cell would show it.
Written to propped-excavation-readings.csv (instrument, stage, station, reading in m or kN).

    python cases/generate_propped_excavation.py [--seed 21]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from geoback.commands.simulate import without_readings, write_readings_csv
from geoback.inference.synthetic import synthetic_readings

HERE = Path(__file__).resolve().parent
CASE = HERE / "propped-excavation.yaml"
OUT = HERE / "propped-excavation-readings.csv"
TRUTH = {"E[soft]": 25000.0, "E[stiff]": 90000.0, "K0": 0.9, "k[P1]": 35000.0}
SEED = 21
READ = ("lift1", "level1", "lift2", "level2")  # the final lift is forecast
NOT_YET = {"LC1": ("lift1",), "LC2": ("lift1", "level1", "lift2")}  # a cell reads from its prop's installation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    loaded = without_readings(CASE)
    zero = {ins.name: ins.zero for ins in loaded.case.instruments if ins.kind == "load_cell"}
    readings = synthetic_readings(loaded, refine=2.0, values=TRUTH, noise_seed=args.seed, by_stage=True)
    readings = {name: {stage: v + zero.get(name, 0.0) for stage, v in sets.items()
                       if stage in READ and stage not in NOT_YET.get(name, ())}
                for name, sets in readings.items()}
    write_readings_csv(loaded, readings, OUT, [f"made by {Path(__file__).name}: the case's model on a mesh twice as "
                                               f"fine at {TRUTH}, noise from each C_x (seed {args.seed}); load cells "
                                               f"in kN with their zero readings"])
    print(f"{sum(len(v) for sets in readings.values() for v in sets.values())} readings -> {OUT}")


if __name__ == "__main__":
    main()
