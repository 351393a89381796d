"""Openings excavated by element removal (issue 19): identification cost against one forward run and
against a finite-difference loop, and a large elastic staged excavation.

Rows of the NATM section (a horseshoe 10 m wide, top heading with shotcrete and a temporary invert,
then bench and invert with the ring closed: four stages, four configurations), its element sizes
divided by --scale (default: ~50 k DOFs). The readings are the model's at the true values with
noise (a speed benchmark: the estimate's accuracy is the tests' business). Timed warm (the mesh
cached, one untimed warm-up), each on a fresh simulation (nothing factorised):

  forward   one staged forward run (four configurations factorised);
  geoback   identify() of E[clay], K0, beta[heading]: Levenberg-Marquardt with exact sensitivities;
  scipy     least_squares(jac='2-point', method='trf') on the same whitened residuals, every call a
            fresh forward run (what a loop around an external code does).

--large: a heading-and-bench excavation without linings in one clay layer at ~500 k DOFs
(--large-scale) identified (E, K0, beta[heading]): one modulus scales every configuration, so each
is factorised once for the whole identification; wall and CPU seconds, peak memory, factorisations.

Floors (issue 19): factorisations of a forward run = distinct configurations; least_squares / geoback
>= 10x; the large identification < 60 s wall.

    python benchmarks/excavation.py [--scale 4.5] [--large] [--csv out.csv]
"""
from __future__ import annotations

import argparse
import copy
import os
import resource
import time
from pathlib import Path

import numpy as np

from fd_loop import fd_least_squares  # noqa: E402
from table import print_table

TRUTH = {"E[clay]": 60000.0, "K0": 0.7, "beta[heading]": 0.4}
START = {"E[clay]": 30000.0, "K0": 0.5, "beta[heading]": 0.6}
STAGES = ("heading", "heading-lined", "bench", "closed")
WALL = -3.0 + (64.0 - 0.25) ** 0.5  # the side wall (radius 8 about (-3, -15)) 0.5 m below the springline


def section(scale: float, lined: bool = True, layers: int = 2) -> dict:
    """The NATM section of tests/test_excavation.py (two layers, or the clay alone; a horseshoe in three
    parts)."""
    parts = [{"name": "heading", "contains": [0.0, -12.0]}, {"name": "bench", "contains": [0.0, -17.0]},
             {"name": "invert", "contains": [0.0, -18.8]}]
    data = {"name": f"natm-x{scale:g}", "geometry": {"model": "half", "width": 60.0, "depth": 45.0, "openings": [
        {"name": "tunnel", "shape": "horseshoe", "centre": [0.0, -15.0], "crown_radius": 5.0, "side_radius": 8.0,
         "height": 9.5, "invert_radius": 12.0, "cuts": [[[-6.0, -15.5], [6.0, -15.5]], [[-6.0, -18.0], [6.0, -18.0]]],
         "parts": parts}]},
        "ground": {"unit_weight": 20.0, "K0": 0.7, "layers": [
            {"name": "fill", "top": 0.0, "E": 20000.0, "nu": 0.3, "unit_weight": 18.0},
            {"name": "clay", "top": 5.0, "E": 60000.0, "nu": 0.3}]},
        "mesh": {"size_tunnel": 0.5 / scale, "size_far": 5.0 / scale},
        "fit": {"mesh_error": "ignore"}}
    if layers == 1:
        data["ground"]["layers"] = [{"name": "clay", "top": 0.0, "E": 60000.0, "nu": 0.3}]
    if lined:
        data["construction"] = {
            "linings": [{"name": "shotcrete", "on": "heading", "thickness": 0.25, "E": "10 GPa", "nu": 0.2},
                        {"name": "temporary", "on": "heading", "side": "cut", "thickness": 0.3, "E": "8 GPa", "nu": 0.2},
                        {"name": "ring", "on": "bench", "thickness": 0.25, "E": "12 GPa", "nu": 0.2}],
            "stages": [{"name": "heading", "excavate": ["heading"], "release": 0.4},
                       {"name": "heading-lined", "install": ["shotcrete", "temporary"]},
                       {"name": "bench", "excavate": ["bench", "invert"], "remove": ["temporary"], "release": 0.6},
                       {"name": "closed", "install": ["ring"]}]}
        stages = STAGES
    else:
        data["construction"] = {"stages": [{"name": "heading", "excavate": ["heading"], "release": 0.4},
                                           {"name": "heading-rest", "release": 1.0},
                                           {"name": "bench", "excavate": ["bench", "invert"]}]}
        stages = ("heading", "heading-rest", "bench")
    surface = [[x, 0.0] for x in (0.0, 2.0, 4.0, 6.0, 9.0, 12.0, 16.0, 20.0)]
    data["instruments"] = [
        {"name": "S1", "kind": "points", "points": surface, "components": ["uy"], "sigma": 0.0005,
         "readings": {s: [0.0] * len(surface) for s in stages}},
        {"name": "X1", "kind": "extensometer", "start": [0.0, 0.0], "end": [0.0, -9.0], "spacing": 1.5,
         "stations": 5, "sigma": 0.0002, "readings": {s: [0.0] * 5 for s in stages}},
        {"name": "C1", "kind": "convergence", "points": [[-WALL, -15.5], [WALL, -15.5]], "sigma": 0.0005,
         "readings": {s: [0.0] for s in stages[:2]}}]
    data["parameters"] = [{"name": "E[clay]", "initial": START["E[clay]"], "bounds": [5000.0, 500000.0]},
                          {"name": "K0", "initial": START["K0"], "bounds": [0.2, 2.0]},
                          {"name": "beta[heading]", "initial": START["beta[heading]"], "bounds": [0.05, 1.0]}]
    return data


def with_readings(data: dict, seed: int = 19) -> dict:
    """The case with the model's readings at TRUTH plus noise of each instrument's sigma."""
    from geoback.case.loading import LoadedCase, case_from_data
    from geoback.inference.identification import prepare

    a = prepare(LoadedCase(case_from_data(copy.deepcopy(data)), None, {}))
    x = a.simulation.predict(dict(a.values, **TRUTH)).x
    rng = np.random.default_rng(seed)
    out = copy.deepcopy(data)
    r = 0
    for ins, block in _blocks(out, a):
        for stage, n in block:
            sigma = ins["sigma"]
            ins["readings"][stage] = [float(v) for v in x[r:r + n] + rng.normal(0.0, sigma, n)]
            r += n
    return out


def _blocks(data, analysis):
    """(instrument, [(stage, rows)]) in the survey's row order."""
    labels = analysis.simulation.survey.labels
    order = []
    for lab in labels:
        key = (lab.instrument, lab.stage)
        if not order or order[-1][0] != key:
            order.append([key, 0])
        order[-1][1] += 1
    by_name = {ins["name"]: ins for ins in data["instruments"]}
    out = []
    for (name, stage), n in order:
        if not out or out[-1][0]["name"] != name:
            out.append((by_name[name], []))
        out[-1][1].append((stage, n))
    return out


def loaded(data):
    from geoback.case.loading import LoadedCase, case_from_data

    return LoadedCase(case_from_data(copy.deepcopy(data), allow_large=True), None, {})


def fresh(data):
    from geoback.inference.identification import prepare

    t0 = time.perf_counter()
    a = prepare(loaded(data))
    return a, time.perf_counter() - t0


def forward(data) -> dict:
    a, setup = fresh(data)
    sim = a.simulation
    t0, c0 = time.perf_counter(), time.process_time()
    sim.predict(a.values)
    return dict(seconds=time.perf_counter() - t0, cpu=time.process_time() - c0, setup=setup, dofs=sim.dofs,
                factorisations=sim.counters.factorisations, solves=sim.counters.solves, backend=sim.solver,
                factor_seconds=sim.counters.seconds_factorising)


def run_geoback(data) -> dict:
    from geoback.inference.identification import identify

    a, setup = fresh(data)
    t0, c0 = time.perf_counter(), time.process_time()
    res = identify(a)
    return dict(seconds=time.perf_counter() - t0, cpu=time.process_time() - c0, setup=setup, p=res.fit.p,
                std=res.reliability.std, status=res.fit.status, iterations=res.fit.iterations,
                names=res.parameters.names, **res.counts)


def run_scipy(data) -> dict:
    a, setup = fresh(data)
    sim = a.simulation
    c0 = time.process_time()
    fd = fd_least_squares(a.misfit, a.parameters)
    return dict(seconds=fd["seconds"], cpu=time.process_time() - c0, p=fd["p"], calls=fd["calls"],
                factorisations=sim.counters.factorisations, success=fd["ls"].success)


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=4.5, help="divide the section's element sizes by this")
    ap.add_argument("--large", action="store_true", help="also the ~500 k DOF heading-and-bench identification")
    ap.add_argument("--large-scale", type=float, default=7.0)
    ap.add_argument("--skip-scipy", action="store_true")
    ap.add_argument("--csv", type=Path, default=None)
    args = ap.parse_args(argv)
    data = with_readings(section(args.scale))
    forward(data), run_geoback(data)  # warm-up (mesh cached), not timed
    f = forward(data)
    g = run_geoback(data)
    est = lambda r: ", ".join(f"{n} = {v:.5g}" for n, v in zip(g["names"], r["p"]))  # noqa: E731
    rows = [("DOFs", f["dofs"]), ("solver backend", f["backend"]),
            ("preparing a simulation (mesh cached, FE model, instruments) [s]", round(f["setup"], 2)),
            ("one staged forward run: wall / CPU [s]", f"{f['seconds']:.3f} / {f['cpu']:.3f}"),
            ("  factorisations (= configurations releasing load: 4) / solves", f"{f['factorisations']} / {f['solves']}"),
            ("geoback identify (E, K0, beta[heading]): wall / CPU [s]", f"{g['seconds']:.3f} / {g['cpu']:.3f}"),
            ("  factorisations / solves / forward runs / iterations",
             f"{g['factorisations']} / {g['solves']} / {g['forward_runs']} / {g['iterations']}"),
            ("  estimate (truth: " + ", ".join(f"{k} = {v:g}" for k, v in TRUTH.items()) + ")",
             f"{est(g)} ({g['status']})"),
            ("ratio identification / one forward run (CPU)", round(g["cpu"] / f["cpu"], 2))]
    if not args.skip_scipy:
        s = run_scipy(data)
        rows += [("least_squares(trf, 2-point): wall / CPU [s]", f"{s['seconds']:.2f} / {s['cpu']:.2f}"),
                 ("  factorisations / fun calls", f"{s['factorisations']} / {s['calls']}"),
                 ("  estimate", f"{est(s)} (success={s['success']})"),
                 ("ratio least_squares / geoback (CPU)", round(s["cpu"] / g["cpu"], 1)),
                 ("ratio least_squares / geoback (factorisations)", round(s["factorisations"] / g["factorisations"], 1)),
                 ("floor least_squares / geoback >= 10x (CPU)", "PASS" if s["cpu"] / g["cpu"] >= 10 else "FAIL")]
    rows.append(("floor factorisations of a forward run = configurations (4)",
                 "PASS" if f["factorisations"] == 4 else "FAIL"))
    if not args.skip_scipy:  # the same section in one clay layer without linings: every configuration scales
        plain = with_readings(section(args.scale, lined=False, layers=1))
        forward(plain), run_geoback(plain)
        pg, ps = run_geoback(plain), run_scipy(plain)
        rows += [("one layer, no lining: geoback identify wall / CPU [s]", f"{pg['seconds']:.3f} / {pg['cpu']:.3f}"),
                 ("  factorisations / solves / forward runs", f"{pg['factorisations']} / {pg['solves']} / {pg['forward_runs']}"),
                 ("  least_squares wall / CPU [s], factorisations",
                  f"{ps['seconds']:.2f} / {ps['cpu']:.2f}, {ps['factorisations']}"),
                 ("  ratio least_squares / geoback (CPU)", round(ps["cpu"] / pg["cpu"], 1)),
                 ("  floor >= 10x (CPU)", "PASS" if ps["cpu"] / pg["cpu"] >= 10 else "FAIL")]
    if args.large:
        big = with_readings(section(args.large_scale, lined=False, layers=1))
        lf = forward(big)
        lg = run_geoback(big)
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        rows += [("large: DOFs", lf["dofs"]), ("large: one forward run wall / CPU [s]", f"{lf['seconds']:.1f} / {lf['cpu']:.1f}"),
                 ("large: set-up (FE model, instruments) [s]", round(lg["setup"], 1)),
                 ("large: identify wall / CPU [s]", f"{lg['seconds']:.1f} / {lg['cpu']:.1f}"),
                 ("large: set-up + identify wall [s]", round(lg["setup"] + lg["seconds"], 1)),
                 ("large: factorisations / solves / forward runs / iterations",
                  f"{lg['factorisations']} / {lg['solves']} / {lg['forward_runs']} / {lg['iterations']}"),
                 ("large: estimate", f"{est(lg)} ({lg['status']})"),
                 ("large: peak memory of the process [MiB]", round(peak)),
                 ("floor large identification < 60 s wall", "PASS" if lg["seconds"] < 60 else "FAIL")]
    rows.append(("load average (1 min) at the end", round(os.getloadavg()[0], 2)))
    return print_table(rows, args.csv)


if __name__ == "__main__":
    import sys

    main(sys.argv[1:])
