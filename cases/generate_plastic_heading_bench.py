"""Readings of cases/plastic-heading-bench.yaml: simulated on a mesh twice as fine as the case's (no inverse
crime) at the 'true' values below, after each construction stage, with noise drawn from each
instrument's covariance C_x (independent draws per stage), written to plastic-heading-bench-readings.csv
(instrument, stage, station, reading in m). Prints the plastic zone of the truth on the fine mesh
(radii from the opening's centroid, against its equivalent radius sqrt(area / pi)).

    python cases/generate_plastic_heading_bench.py [--seed 3]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from geoback.inference.identification import prepare
from geoback.inference.parameters import resolve_values
from geoback.case.meshsize import refined_case
from geoback.commands.simulate import without_readings, write_readings_csv
from geoback.inference.synthetic import synthetic_readings

HERE = Path(__file__).resolve().parent
CASE = HERE / "plastic-heading-bench.yaml"
OUT = HERE / "plastic-heading-bench-readings.csv"
TRUTH = {"E[marl]": 40000.0, "K0": 0.9, "c[marl]": 40.0, "phi[marl]": 30.0}  # psi = 5 as in the case
SEED = 3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=SEED)
    args = parser.parse_args()
    loaded = without_readings(CASE)
    readings = synthetic_readings(loaded, refine=2.0, values=TRUTH, noise_seed=args.seed, by_stage=True)
    write_readings_csv(loaded, readings, OUT, [f"made by {Path(__file__).name}: the case's model on a mesh twice as "
                                               f"fine at {TRUTH}, psi = 5 deg, noise from each C_x (seed {args.seed})"])
    print(f"{sum(len(v) for sets in readings.values() for v in sets.values())} readings -> {OUT}")
    fine = prepare(loaded.with_case(refined_case(loaded.case, 2.0)), parameters=[], with_readings=False)
    values = {**fine.values, **resolve_values(fine.simulation, TRUTH)}
    zone = fine.simulation.plastic_zone(values)
    for s in zone.stages:
        reach = f"{s.max_radius / zone.radius:.2f} R, {s.area:.3g} m2" if s.yielded_points else "elastic"
        print(f"truth, stage {s.stage} (release {s.release:g}): plastic zone to {reach}")


if __name__ == "__main__":
    main()
