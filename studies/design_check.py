"""Study: does `geoback design` predict what an added instrument actually does to the forecast?

cases/staged-forecast.yaml: readings after the advance, forecast of the surface settlement trough
after the lined stage, candidate instruments in its design section. For every candidate (or the
best few), its readings are simulated as the case's were - the model on a mesh twice as fine at
the values that made the case's readings (E = 40 MPa, K0 = 0.7, beta = 0.35), plus noise drawn
from the candidate's C_x - added to the case as a new instrument, and the case identified again.
The root-mean-square std of the trough forecast after that fit is compared with the one `geoback
design` predicted before any reading of the candidate existed (acceptance: within 10 %).

    python studies/design_check.py [--top 3] [--seeds 5]
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

if __name__ == "__main__":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common as C  # noqa: E402

NAME = "design_check"
CASE = C.ROOT / "cases" / "staged-forecast.yaml"
TRUTH = {"E[clay]": 40000.0, "K0": 0.7, "beta[advance]": 0.35}


def _with_candidate(data: dict, candidate: dict, readings: list[float], stage: str) -> dict:
    import copy

    data = copy.deepcopy(data)
    ins = {k: v for k, v in candidate.items() if k not in ("vary", "read_at")}
    ins["readings"] = {stage: [float(v) for v in readings]}
    data["instruments"].append(ins)
    data.pop("design", None)
    return data


def _rms_std(loaded, targets: list[str]) -> float:
    from geoback.worth.forecast import forecast
    from geoback.inference.identification import identify, prepare

    analysis = prepare(loaded)
    res = identify(analysis, profile="none")
    fc = forecast(analysis, res, draws=0)
    rows = [i for i, f in enumerate(fc.forecast) if f in targets]
    return float(np.sqrt(np.mean(fc.std[rows] ** 2)))


def run(top: int | None = 3, seeds: int = 5) -> list[dict]:
    from geoback.case.loading import LoadedCase, case_from_data, load_case
    from geoback.case.checks import expand_candidates
    from geoback.worth.design import design
    from geoback.inference.identification import identify, prepare
    from geoback.observation.instruments import build_block
    from geoback.case.meshsize import refined_case

    loaded = load_case(CASE)
    analysis = prepare(loaded)
    res = identify(analysis, profile="none")
    d = design(analysis, res)
    data = loaded.case.model_dump(exclude_none=True, mode="json")
    for ins in data["instruments"]:  # the readings file resolved to values, so the case can live in memory
        ins.pop("readings_file", None)
    from geoback.observation.readings import survey_blocks

    blocks, measured = survey_blocks(loaded, [s.name for s in loaded.case.construction.stages])
    start = 0
    for b in blocks:
        entry = next(i for i in data["instruments"] if i["name"] == b.name)
        entry.setdefault("readings", {})[b.stage] = [float(v) for v in measured[start:start + b.m]]
        start += b.m
    expanded = {c.name: c for _, c in expand_candidates(loaded.case.design)}
    order = d.ranking if top is None else d.ranking[:top]
    out = []
    for k in order:
        name, stage = d.names[k], d.stages[k]
        cand = expanded[name].model_dump(exclude_none=True, mode="json")
        fine_data = _with_candidate(data, cand, [0.0] * d.readings[k], stage)
        fine_loaded = LoadedCase(case_from_data(fine_data), CASE, {})
        fine = prepare(fine_loaded.with_case(refined_case(fine_loaded.case, 2.0)), with_readings=False)
        x = fine.simulation.predict(dict(fine.values, **TRUTH)).x
        rows = fine.simulation.survey.rows(name)
        clean = x[rows]
        block = build_block(expanded[name], loaded, 0)
        L = np.linalg.cholesky(block.covariance)
        actual = []
        for seed in range(seeds):
            rng = np.random.default_rng(1000 + seed)
            readings = clean + L @ rng.standard_normal(len(clean))
            case = case_from_data(_with_candidate(data, cand, readings, stage))
            actual.append(_rms_std(LoadedCase(case, CASE, {}), d.targets))
        actual = np.array(actual)
        out.append({"candidate": name, "stage": stage, "now": d.before, "predicted": float(d.after[k]),
                    "actual_median": float(np.median(actual)), "actual_min": float(actual.min()),
                    "actual_max": float(actual.max()),
                    "error": float(np.max(np.abs(actual - d.after[k])) / d.after[k])})
    return out


def main() -> None:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=3, help="check the best N candidates (0: all)")
    ap.add_argument("--seeds", type=int, default=5, help="noise draws of each candidate's readings")
    args = ap.parse_args()
    res = run(None if args.top == 0 else args.top, 2 if args.small else args.seeds)
    header = ["candidate", "stage", "rms std now [mm]", "predicted [mm]", "actual median [mm]", "actual min",
              "actual max", "largest error"]
    rows = [[r["candidate"], r["stage"], 1e3 * r["now"], 1e3 * r["predicted"], 1e3 * r["actual_median"],
             1e3 * r["actual_min"], 1e3 * r["actual_max"], r["error"]] for r in res]
    C.write_csv(args.out / f"{NAME}.csv", header, rows)
    print(C.format_table(header, rows))
    worst = max(r["error"] for r in res)
    print(f"\nlargest difference between the predicted and the actual rms std of the forecast: {100 * worst:.1f} % "
          f"(acceptance: 10 %)")


if __name__ == "__main__":
    main()
