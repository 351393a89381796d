"""Deep excavations with walls and props (issue 20): identification cost against one forward run and
against a finite-difference loop, on linear-elastic and on Mohr-Coulomb ground.

The propped excavation of cases/propped-excavation.yaml (a 0.8 m diaphragm wall, two prop levels, three
lifts: five stages, three configurations releasing load, the second level's preload jacked on the
second), its element sizes divided by --scale (default ~50 k DOFs), read after every stage by the wall
inclinometer, the settlement points and the two load cells. The readings are the model's at the true
values with noise (a speed benchmark: the estimate's accuracy is the tests' business). Timed warm (the
mesh cached, one untimed warm-up), each on a fresh simulation (nothing factorised):

  forward   one staged forward run;
  geoback   identify() of E[soft], E[stiff], K0, k[P1]: Levenberg-Marquardt with exact sensitivities;
  scipy     least_squares(jac='2-point', method='trf') on the same whitened residuals, every call a
            fresh forward run (what a loop around an external code does).

--plastic: the same with the soft clay Mohr-Coulomb (c' = 10 kPa, phi' = 24 deg), at --plastic-scale.

Floors (issue 20): factorisations of a forward run on linear ground = configurations; least_squares /
geoback >= 10x on linear ground, >= 5x on Mohr-Coulomb ground.

    python benchmarks/walls.py [--scale 3.2] [--plastic] [--plastic-scale 1.0] [--csv out.csv]
"""
from __future__ import annotations

import argparse
import copy
import os
import resource
from pathlib import Path

import yaml

from excavation import forward, run_geoback, run_scipy, with_readings
import excavation
from table import print_table

CASE = Path(__file__).resolve().parents[1] / "cases" / "propped-excavation.yaml"
TRUTH = {"E[soft]": 25000.0, "E[stiff]": 90000.0, "K0": 0.9, "k[P1]": 35000.0}


def propped(scale: float, plastic: bool = False) -> dict:
    """The shipped case's model, its mesh sizes divided by `scale`, readings inline (filled by with_readings)."""
    data = yaml.safe_load(CASE.read_text())
    data["name"] = f"propped-x{scale:g}"
    data["mesh"] = {"size_tunnel": 0.5 / scale, "size_far": 5.0 / scale}
    data["fit"] = {"mesh_error": "ignore"}
    data.pop("forecasts", None)
    stages = [s["name"] for s in data["construction"]["stages"]]
    for ins in data["instruments"]:
        ins.pop("readings_file")
        ins.pop("zero", None)
        first = 1 if ins["name"] == "LC1" else 3 if ins["name"] == "LC2" else 0
        ins["readings"] = {s: [] for s in stages[first:]}
    if plastic:
        data["ground"]["layers"][0].update(model="mohr-coulomb", c=10.0, phi=24.0, psi=0.0)
    return data


def _filled(data: dict) -> dict:
    """Readings at TRUTH with noise: the template's empty lists sized by a first prepare."""
    from geoback.case.loading import LoadedCase, case_from_data
    from geoback.observation.instruments import case_blocks

    sized = copy.deepcopy(data)
    blocks = {b.name: b.m for b in case_blocks(LoadedCase(case_from_data(copy.deepcopy(
        {**data, "instruments": [{**i, "readings": None} for i in data["instruments"]]}), allow_large=True), None, {}))}
    for ins in sized["instruments"]:
        ins["readings"] = {s: [0.0] * blocks[ins["name"]] for s in ins["readings"]}
    excavation.TRUTH = TRUTH
    return with_readings(sized)


def fit_only(data) -> dict:
    """The estimate alone (Levenberg-Marquardt with exact sensitivities), without identify()'s conclusions
    (profile-likelihood intervals, error scales, the reliability report): what least_squares computes."""
    import time

    from excavation import fresh
    from geoback.inference.estimate import fit

    a, _ = fresh(data)
    t0, c0 = time.perf_counter(), time.process_time()
    res = fit(a.misfit, a.settings)
    c = a.simulation.counters
    return dict(seconds=time.perf_counter() - t0, cpu=time.process_time() - c0, factorisations=c.factorisations,
                runs=c.forward_runs, status=res.status)


def measure(data: dict, skip_scipy: bool, label: str) -> list:
    forward(data), run_geoback(data)  # warm-up (mesh cached), not timed
    f = forward(data)
    g = run_geoback(data)
    o = fit_only(data)
    est = lambda r: ", ".join(f"{n} = {v:.5g}" for n, v in zip(g["names"], r["p"]))  # noqa: E731
    rows = [(f"{label}: DOFs", f["dofs"]), (f"{label}: solver backend", f["backend"]),
            (f"{label}: one staged forward run wall / CPU [s]", f"{f['seconds']:.3f} / {f['cpu']:.3f}"),
            (f"{label}:   factorisations / solves", f"{f['factorisations']} / {f['solves']}"),
            (f"{label}: geoback identify (E[soft], E[stiff], K0, k[P1]) wall / CPU [s]",
             f"{g['seconds']:.3f} / {g['cpu']:.3f}"),
            (f"{label}:   factorisations / solves / forward runs / iterations",
             f"{g['factorisations']} / {g['solves']} / {g['forward_runs']} / {g['iterations']}"),
            (f"{label}:   estimate (truth: " + ", ".join(f"{k} = {v:g}" for k, v in TRUTH.items()) + ")",
             f"{est(g)} ({g['status']})"),
            (f"{label}: ratio identification / one forward run (CPU)", round(g["cpu"] / f["cpu"], 2)),
            (f"{label}: geoback fit only (the estimate, no intervals) wall / CPU [s]",
             f"{o['seconds']:.3f} / {o['cpu']:.3f}"),
            (f"{label}:   factorisations / forward runs", f"{o['factorisations']} / {o['runs']}")]
    if not skip_scipy:
        s = run_scipy(data)
        rows += [(f"{label}: least_squares(trf, 2-point) wall / CPU [s]", f"{s['seconds']:.2f} / {s['cpu']:.2f}"),
                 (f"{label}:   factorisations / fun calls", f"{s['factorisations']} / {s['calls']}"),
                 (f"{label}:   estimate", f"{est(s)} (success={s['success']})"),
                 (f"{label}: ratio least_squares / geoback identify (CPU)", round(s["cpu"] / g["cpu"], 1)),
                 (f"{label}: ratio least_squares / geoback fit only (CPU)", round(s["cpu"] / o["cpu"], 1)),
                 (f"{label}: ratio least_squares / geoback (factorisations)",
                  round(s["factorisations"] / max(g["factorisations"], 1), 1))]
    return rows, f, g


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=3.2, help="divide the case's element sizes by this")
    ap.add_argument("--plastic", action="store_true", help="also on Mohr-Coulomb ground")
    ap.add_argument("--plastic-scale", type=float, default=1.0)
    ap.add_argument("--skip-scipy", action="store_true")
    ap.add_argument("--csv", type=Path, default=None)
    args = ap.parse_args(argv)
    rows, f, g = measure(_filled(propped(args.scale)), args.skip_scipy, "elastic")
    rows.append(("floor factorisations of a forward run = configurations (3)",
                 "PASS" if f["factorisations"] == 3 else "FAIL"))
    if args.plastic:
        prow, _, _ = measure(_filled(propped(args.plastic_scale, plastic=True)), args.skip_scipy, "mohr-coulomb")
        rows += prow
    rows.append(("peak memory of the process [MiB]", round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)))
    rows.append(("load average (1 min) at the end", round(os.getloadavg()[0], 2)))
    return print_table(rows, args.csv)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
