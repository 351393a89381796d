"""Forward runs: predicted readings at every instrument and the displacement/stress field; study
data (readings from a finer mesh with noise drawn from each instrument's C_x)."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from geoback.case.loading import LoadedCase
from geoback.errors import GeobackError
from geoback.inference.identification import Analysis
from geoback.outputs import write_csv, write_json
from geoback.reports.resultsets import result_set
from geoback.observation.readings import measured_values

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


def simulate(analysis: Analysis, out: Path, values: Mapping | None = None, vtu: bool = True,
             plots: bool | None = None, values_text: str = "") -> dict:
    """Predicted readings (CSV, JSON) and optionally the field (VTU) for the case's values; the lining's,
    the walls' and the plastic zone's figures unless `plots` is False, and with `plots` True also the
    predicted readings along every instrument (predicted.png/.svg; `values_text`: the values set, in words)."""
    figures = plots is not False
    from geoback.reports.report import write_field

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
    from geoback.worth.walls import walls_and_supports

    from geoback.worth.walls import WallsUnavailable

    try:
        walls = walls_and_supports(sim, analysis.case, values)  # None without walls (no band: nothing identified)
    except WallsUnavailable as exc:  # refused rather than written wrong
        import sys

        print(f"walls.csv, supports.csv not written: {exc}", file=sys.stderr)
        walls = None
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
            write_field(sim.field(values), staging / "field.vtu", analysis.case)
        if forces is not None:  # thrust and moments around the lining: CSV, VTU, figure
            from geoback.reports.fields import write_lining

            write_lining(forces, staging, vtu=vtu)
            if figures:
                from geoback.reports.plots import save_figures
                from geoback.reports.plots.lining import lining_figure

                fig = lining_figure(forces)
                try:
                    save_figures({"lining": fig}, staging)
                finally:
                    fig.clear()
        if plots:  # the readings predicted along every instrument
            import matplotlib

            from geoback.inference.explore import profiles
            from geoback.reports.plots import save_figures
            from geoback.reports.plots.common import RC
            from geoback.reports.plots.instruments import full_model_axes, predicted_figure

            with matplotlib.rc_context(RC):
                fig = predicted_figure(sim.survey.blocks, x, profiles(sim, values), analysis.case.name, values_text)
                full_model_axes(fig, analysis.case)
            try:
                save_figures({"predicted": fig}, staging)
            finally:
                fig.clear()
        if walls is not None:  # walls.csv, supports.csv
            from geoback.reports.walls import write_walls

            write_walls(walls, staging)
        if walls is not None and figures:  # and their figures
            import matplotlib

            from geoback.reports.plots import save_figures
            from geoback.reports.plots.common import RC
            from geoback.reports.plots.walls import supports_figure, walls_figure

            with matplotlib.rc_context(RC):
                figs = {k: f for k, f in (("walls", walls_figure(walls)), ("supports", supports_figure(walls)))
                        if f is not None}
            try:
                save_figures(figs, staging)
            finally:
                for f in figs.values():
                    f.clear()
        if zone is not None:  # the yielded ground: CSV and figure
            from geoback.reports.fields import write_plastic_zone

            write_plastic_zone(zone, staging)
            if figures:
                from geoback.reports.plots import save_figures
                from geoback.reports.plots.plastic import plastic_zone_figure

                fig = plastic_zone_figure(zone, name=analysis.case.name, case=analysis.case)
                try:
                    save_figures({"plastic_zone": fig}, staging)
                finally:
                    fig.clear()
    return {"readings": x, "dofs": sim.dofs, "lining": forces, "plastic_zone": zone, "walls": walls}


def without_readings(path: Path) -> LoadedCase:
    """A case file loaded without its instruments' readings (a readings generator's starting point)."""
    from geoback.case.loading import case_from_data
    from geoback.case.yamlmarks import load_yaml_with_marks

    data, _ = load_yaml_with_marks(path)  # as case files are read (a lining's `on:` is a key, not true)
    for ins in data.get("instruments", []):  # what the readings say (dated surveys, a baseline) goes with them
        for key in ("readings_file", "readings", "baseline", "installed_after", "columns", "ignore_columns"):
            ins.pop(key, None)
    return LoadedCase(case_from_data(data), Path(path), {})


def write_readings_csv(loaded, readings: dict, path: Path, notes: list[str] = ()) -> None:
    """Readings in the CSV layout `readings_file` accepts (instrument, station, reading; and stage
    when `readings` is {instrument: {stage: values}}), exact to the last digit, after `notes` as
    comment lines (how the data were made)."""
    from geoback.outputs import csv_text, write_atomic

    head = "".join(f"# {line}\n" for line in notes)
    staged = any(isinstance(v, dict) for v in readings.values())
    if staged:
        rows = [[name, stage, i + 1, v] for name, sets in readings.items() for stage, values in sets.items()
                for i, v in enumerate(values)]
        write_atomic(Path(path), head + csv_text(["instrument", "stage", "station", "reading"], rows))
        return
    rows = [[name, i + 1, v] for name, values in readings.items() for i, v in enumerate(values)]
    write_atomic(Path(path), head + csv_text(["instrument", "station", "reading"], rows))
