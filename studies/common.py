"""Shared helpers for the studies of Ledesma, Gens & Alonso (1996), Part I.

The studies start from the paper case (``cases/tunnel-paper.yaml``: R = 3 m, axis depth 10 m,
nu = 0.49, gamma = 20 kN/m3, truth E = 10 MPa, K0 = 1, start E = 5 MPa, K0 = 0.5) and change
only the instrument layout, the measurement errors and the mesh size.  Every helper works on
plain case dicts (validated by ``geoback.case.loading.case_from_data``), so a study states in a few
lines which instruments it uses.

Conventions of the studies
--------------------------
* Truth: the ground values of the paper case (E = 10 MPa, K0 = 1).
* Readings without the inverse crime: noise-free readings come from the same case meshed
  ``refine`` times finer (``geoback.commands.simulate.synthetic_readings``), noise is added by the study.
* One prepared case per layout and mesh: the noise realisations only change its readings
  (``Analysis.with_readings``); the factorisation of k (K = E k) is reused by every fit.
"""
from __future__ import annotations

import argparse
import copy
import csv
import math
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
PAPER_CASE = ROOT / "cases" / "tunnel-paper.yaml"
OUT = Path(__file__).resolve().parent / "out"

E_TRUE = 10_000.0  # kPa
K0_TRUE = 1.0
P_TRUE = np.array([E_TRUE, K0_TRUE])


# ---------------------------------------------------------------------------- cases
def script(relative: str):
    """A script of the repository (e.g. 'benchmarks/diagnosis_accuracy.py', the one source of concealed cases)
    as a module, loaded once per process under its file's stem."""
    import importlib.util
    import sys

    name = Path(relative).stem
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, ROOT / relative)
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def paper_case_dict() -> dict:
    """The paper case as a plain dict (a fresh copy each call)."""
    with open(PAPER_CASE, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


def case_dict(instruments: list[dict] | None = None, mesh_scale: float = 1.0, name: str | None = None,
              parameters: list[dict] | None = None, weighting: str | None = None, **mesh_overrides) -> dict:
    """The paper case with other instruments and/or a mesh `mesh_scale` times finer.

    `instruments` replace the paper's I1 and X1 (readings are dropped unless given);
    `mesh_scale` > 1 divides both element sizes; `mesh_overrides` set mesh fields directly.
    """
    data = paper_case_dict()
    if instruments is not None:
        data["instruments"] = copy.deepcopy(instruments)
    mesh = dict(data.get("mesh", {}))
    mesh["size_tunnel"] = mesh.get("size_tunnel", 0.4) / mesh_scale
    mesh["size_far"] = mesh.get("size_far", 4.0) / mesh_scale
    mesh.update(mesh_overrides)
    data["mesh"] = mesh
    if name:
        data["name"] = name
    if parameters is not None:
        data["parameters"] = copy.deepcopy(parameters)
    if weighting is not None:
        data.setdefault("fit", {})["weighting"] = weighting
    return data


def loaded_case(data: dict):
    """Validate a case dict and wrap it as a LoadedCase (no file behind it)."""
    from geoback.case.loading import LoadedCase, case_from_data

    return LoadedCase(case_from_data(data), None, {})


def without_readings(data: dict) -> dict:
    data = copy.deepcopy(data)
    for ins in data["instruments"]:
        ins.pop("readings", None)
        ins.pop("readings_file", None)
    return data


def with_readings(data: dict, readings: dict[str, np.ndarray]) -> dict:
    """Copy of a case dict whose instruments carry the given readings."""
    data = copy.deepcopy(data)
    for ins in data["instruments"]:
        ins.pop("readings_file", None)
        ins["readings"] = [float(v) for v in readings[ins["name"]]]
    return data


# ---------------------------------------------------------------------------- instruments
def points(name: str, pts, components, sigma: float) -> dict:
    return {"name": name, "kind": "points", "points": [[float(x), float(y)] for x, y in pts],
            "components": list(components), "sigma": float(sigma)}


def inclinometer(name: str, x: float, toe_depth: float, spacing: float, stations: int, sigma: float,
                 var_b: float = 0.0) -> dict:
    return {"name": name, "kind": "inclinometer", "x": float(x), "toe_depth": float(toe_depth),
            "reference": "toe", "spacing": float(spacing), "stations": int(stations),
            "sigma": float(sigma), "var_b": float(var_b)}


def wall_points(n: int, radius: float = 3.0, axis_depth: float = 10.0, offset: float = 0.0) -> np.ndarray:
    """n points on the tunnel wall strictly between crown and invert (angles from the crown)."""
    theta = np.pi * np.arange(1, n + 1) / (n + 1)
    r = radius + offset
    return np.column_stack([r * np.sin(theta), -axis_depth + r * np.cos(theta)])


# ---------------------------------------------------------------------------- readings
def block_order(analysis) -> list[str]:
    return [b.name for b in analysis.simulation.survey.blocks]


def stack(analysis, readings: dict[str, np.ndarray]) -> np.ndarray:
    """Readings by instrument name -> one vector in the case's reading order."""
    return np.concatenate([np.asarray(readings[n], float) for n in block_order(analysis)])


def fine_readings(loaded, refine: float = 2.0) -> dict[str, np.ndarray]:
    """Noise-free readings at the truth, computed on a mesh `refine` times finer."""
    from geoback.inference.synthetic import synthetic_readings

    return synthetic_readings(loaded, refine=refine)


def problem_with(loaded, measured: np.ndarray | None = None, weighting: str | None = None):
    """The case prepared (geoback.inference.identification.prepare) with the readings `measured` (survey order);
    the truth's own noise-free predictions if none are given."""
    from geoback.inference.identification import prepare

    analysis = prepare(loaded, with_readings=False)
    if measured is None:
        measured = analysis.predict(P_TRUE).x
    return analysis.with_readings(measured, weighting)


def noise_from_cx(analysis, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """A draw from N(0, C_x) of the case's instruments (eqn 9)."""
    return analysis.misfit.data.noise(rng, scale)


def identify_p(analysis, weighting: str, p0=None):
    """Fit and assess on the analysis' readings; returns (Fit, Reliability)."""
    from geoback.inference.identification import identify

    res = identify(analysis, weighting=weighting, p0=p0, require_dof=False)
    return res.fit, res.reliability


# ---------------------------------------------------------------------------- output
def parser(description: str) -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--small", action="store_true", help="few realisations, coarse mesh (for the test suite)")
    ap.add_argument("--out", type=Path, default=OUT, help=f"output folder (default {OUT})")
    ap.add_argument("--seed", type=int, default=20240601, help="seed of the noise generator")
    return ap


def write_csv(path: Path, header: list[str], rows: list[list]) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(header)
        for r in rows:
            w.writerow([repr(float(v)) if isinstance(v, (float, np.floating)) else v for v in r])


def format_table(header: list[str], rows: list[list], floatfmt: str = ".4g") -> str:
    def cell(v):
        if isinstance(v, (float, np.floating)):
            return "nan" if not math.isfinite(v) else format(float(v), floatfmt)
        return str(v)

    cells = [[cell(v) for v in r] for r in rows]
    widths = [max(len(h), *(len(r[i]) for r in cells)) if cells else len(h) for i, h in enumerate(header)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(header, widths)),
             "  ".join("-" * w for w in widths)]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in cells]
    return "\n".join(lines)


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt
