"""Forward runs: predicted readings at every instrument and the displacement/stress field; study
data (readings from a finer mesh with noise drawn from each instrument's C_x)."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from .case import LoadedCase
from .errors import GeobackError
from .identification import Analysis, prepare
from .outputs import write_csv, write_json
from .resultsets import result_set
from .parameters import resolve_values
from .readings import measured_values

READING_HEADER = ["instrument", "kind", "station", "component", "stage", "x", "y", "computed"]


def reading_rows(labels, computed: np.ndarray, measured: np.ndarray | None = None) -> list[list]:
    rows = []
    for i, lab in enumerate(labels):
        row = [lab.instrument, lab.kind, lab.station, lab.component, lab.stage, lab.x, lab.y, computed[i]]
        if measured is not None:
            row.append(measured[i])
        rows.append(row)
    return rows


def forward(analysis: Analysis, values: Mapping | None = None) -> np.ndarray:
    """Computed readings at the case's values (or `values`)."""
    return analysis.simulation.predict(values if values is not None else analysis.values).x


def simulate(analysis: Analysis, out: Path, values: Mapping | None = None, vtu: bool = True) -> dict:
    """Predicted readings (CSV, JSON) and optionally the field (VTU) for the case's values."""
    from .report import write_field

    sim = analysis.simulation
    values = dict(values if values is not None else analysis.values)
    x = sim.predict(values).x
    try:
        measured = measured_values(analysis.loaded, sim.survey.blocks)
    except GeobackError:  # readings not at every stage: list the predictions alone
        measured = None
    header = READING_HEADER + (["measured"] if measured is not None else [])
    rows = reading_rows(sim.survey.labels, x, measured)
    forces = sim.lining_forces(values)
    zone = sim.plastic_zone(values)
    with result_set(out, "simulate") as staging:  # the previous set replaced as a whole
        write_csv(staging / "predicted.csv", header, rows)
        write_json(staging / "predicted.json", {
            "case": analysis.case.name,
            "values": values,
            "dofs": sim.dofs,
            "readings": [dict(zip(header, r)) for r in rows],
            **({"plastic_zone": zone.as_dict()} if zone is not None else {}),
        })
        if vtu:
            write_field(sim.field(values), staging / "field.vtu")
        if forces is not None:  # thrust and moments around the lining: CSV, VTU, figure
            from .lining import write_lining
            from .plots import save_figures
            from .plots.lining import lining_figure

            write_lining(forces, staging, vtu=vtu)
            fig = lining_figure(forces)
            try:
                save_figures({"lining": fig}, staging)
            finally:
                fig.clear()
        if zone is not None:  # the yielded ground: CSV and figure
            from .plastic_zone import write_plastic_zone
            from .plots import save_figures
            from .plots.plastic import plastic_zone_figure

            write_plastic_zone(zone, staging)
            fig = plastic_zone_figure(zone, name=analysis.case.name)
            try:
                save_figures({"plastic_zone": fig}, staging)
            finally:
                fig.clear()
    return {"readings": x, "dofs": sim.dofs, "lining": forces, "plastic_zone": zone}


def without_readings(path: Path) -> LoadedCase:
    """A case file loaded without its instruments' readings (a readings generator's starting point)."""
    import yaml

    from .case import case_from_data

    data = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    for ins in data.get("instruments", []):
        ins.pop("readings_file", None)
        ins.pop("readings", None)
    return LoadedCase(case_from_data(data), Path(path), {})


def refined_case(case, factor: float):
    """The same case meshed `factor` times finer (for data that avoids the inverse crime)."""
    from .mesh import mesh_inputs

    sizes = mesh_inputs(case)
    mesh = case.mesh.model_copy(update={
        "size_tunnel": sizes["size_tunnel"] / factor,
        "size_far": sizes["size_far"] / factor,
        "size_instruments": (sizes["size_instruments"] / factor) if sizes["size_instruments"] else None,
    })
    return case.model_copy(update={"mesh": mesh})


def synthetic_readings(loaded: LoadedCase, refine: float = 2.0, values: Mapping | None = None,
                       noise_seed: int | None = None, noise_scale: float = 1.0, by_stage: bool = False) -> dict:
    """Readings of every instrument from a finer mesh, optionally with noise drawn from C_x.

    `values` overrides named quantities, by name as in a case file, with units if wished (e.g.
    {'Egrad[clay]': 500, 'E': '12 MPa', 'B[I1]': 0.002}); unknown names are refused. An
    inclinometer's bias shift ('bias[I1]': 2e-4 rad) adds bias * L_n to its readings; its depth
    offset ('zoff[I1]': '300 mm') reads its stations and reference end that much deeper (the
    observation operator at the shifted points). Noise is L z with C_x = L L^t per instrument
    (eqn 10), seeded, independent from stage to stage. Returns {instrument: readings} at the last
    construction stage, or with `by_stage` {instrument: {stage: readings}} at every stage."""
    fine = loaded.with_case(refined_case(loaded.case, refine))
    analysis = prepare(fine, parameters=[], with_readings=False)
    sim = analysis.simulation
    named = dict(analysis.values)
    named.update(resolve_values(sim, values or {}))
    x = sim.predict(named).x  # a reference end that moved: readings = P u - G c (eqns 11, 15, 18)
    rng = np.random.default_rng(noise_seed) if noise_seed is not None else None
    out, offset = {}, 0
    for block in sim.survey.blocks:
        xi = x[offset:offset + block.m].copy()
        if rng is not None:
            xi += noise_scale * (np.linalg.cholesky(block.covariance) @ rng.standard_normal(block.m))
        out.setdefault(block.name, {})[block.stage] = xi
        offset += block.m
    if by_stage:
        return out
    last = sim.stages[-1]
    return {name: sets[last] for name, sets in out.items()}


def write_readings_csv(loaded, readings: dict, path: Path, notes: list[str] = ()) -> None:
    """Readings in the CSV layout `readings_file` accepts (instrument, station, reading; and stage
    when `readings` is {instrument: {stage: values}}), exact to the last digit, after `notes` as
    comment lines (how the data were made)."""
    from .outputs import csv_text, write_atomic

    head = "".join(f"# {line}\n" for line in notes)
    staged = any(isinstance(v, dict) for v in readings.values())
    if staged:
        rows = [[name, stage, i + 1, v] for name, sets in readings.items() for stage, values in sets.items()
                for i, v in enumerate(values)]
        write_atomic(Path(path), head + csv_text(["instrument", "stage", "station", "reading"], rows))
        return
    rows = [[name, i + 1, v] for name, values in readings.items() for i, v in enumerate(values)]
    write_atomic(Path(path), head + csv_text(["instrument", "station", "reading"], rows))
