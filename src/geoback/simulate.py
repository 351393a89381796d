"""Forward runs: predicted readings at every instrument and the displacement/stress field."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .mesh import write_mesh
from .outputs import result_set, write_csv, write_json
from .problem import Problem


def reading_rows(problem: Problem, computed: np.ndarray, measured: np.ndarray | None = None) -> list[list]:
    rows = []
    for i, lab in enumerate(problem.obs.labels):
        row = [lab.instrument, lab.kind, lab.station, lab.component, lab.x, lab.y, computed[i]]
        if measured is not None:
            row.append(measured[i])
        rows.append(row)
    return rows


READING_HEADER = ["instrument", "kind", "station", "component", "x", "y", "computed"]


def element_stress(problem: Problem, values: dict, u_full: np.ndarray) -> np.ndarray:
    """Total stress (sxx, syy, sxy) per element: initial geostatic + excavation increment."""
    st = problem.ground.state(values)
    eps = problem.fe.element_strain(u_full)
    d11, d22, d12, d33 = st.coeffs.T.real
    ds = np.column_stack([d11 * eps[:, 0] + d12 * eps[:, 1], d12 * eps[:, 0] + d22 * eps[:, 1], d33 * eps[:, 2]])
    depth = -problem.fe.centroid[:, 1]
    sv = -problem.case.ground.unit_weight * depth
    k0 = np.array([problem.ground._layer_k0(values, r) for r in range(len(problem.ground.layers))])[problem.fe.region]
    k0 = k0 + values.get("K0grad", 0.0) * (depth - problem.case.geometry.axis_depth)
    s0 = np.column_stack([k0 * sv, sv, np.zeros_like(sv)])
    return s0 + ds


def write_field(problem: Problem, values: dict, path: Path) -> None:
    """Displacement (point data) and stress (cell data) as VTU for ParaView."""
    u = problem.fe.expand(problem.displacement(values))
    disp = u.reshape(-1, 2)
    stress = element_stress(problem, values, u)
    write_mesh(problem.mesh, path,
               point_data={"displacement": np.column_stack([disp, np.zeros(len(disp))])},
               cell_data={"stress_xx": stress[:, 0], "stress_yy": stress[:, 1], "stress_xy": stress[:, 2]})


def simulate(problem: Problem, out: Path, values: dict | None = None, vtu: bool = True) -> dict:
    """Predicted readings (CSV, JSON) and optionally the field (VTU) for the case's values."""
    values = values if values is not None else problem.values
    u = problem.displacement(values)
    x = problem.obs.P @ u
    measured = problem.obs.measured
    header = READING_HEADER + (["measured"] if measured is not None else [])
    rows = reading_rows(problem, x, measured)
    with result_set(out, "simulate") as staging:  # the previous set replaced as a whole
        write_csv(staging / "predicted.csv", header, rows)
        write_json(staging / "predicted.json", {
            "case": problem.case.name,
            "values": values,
            "dofs": problem.fe.ndof,
            "readings": [dict(zip(header, r)) for r in rows],
        })
        if vtu:
            write_field(problem, values, staging / "field.vtu")
    return {"readings": x, "dofs": problem.fe.ndof}


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


def synthetic_readings(loaded, refine: float = 2.0, values: dict | None = None,
                       noise_seed: int | None = None, noise_scale: float = 1.0) -> dict[str, np.ndarray]:
    """Readings of every instrument from a finer mesh, optionally with noise drawn from C_x.

    `values` overrides named quantities (e.g. {'Egrad[clay]': 500}); noise is L z with
    C_x = L L^t per instrument (eqn 10), seeded.
    """
    fine = loaded.with_case(refined_case(loaded.case, refine))
    values = dict(values or {})
    constants = {k: values.pop(k) for k in list(values) if k.split("[")[0] in ("A", "B", "C", "D")}
    problem = Problem(fine, parameters=[], extra_values=values, with_readings=False)
    x = problem.obs.P @ problem.displacement(problem.values)
    for name, c in constants.items():  # a reference end that moved: readings = P u - G c (eqns 11, 15, 18)
        if name not in problem.obs.constant_names:
            raise ValueError(f"no linewise instrument has the integration constant '{name}'")
        x = x - problem.obs.G[:, problem.obs.constant_names.index(name)] * c
    rng = np.random.default_rng(noise_seed) if noise_seed is not None else None
    out, offset = {}, 0
    for block in problem.obs.blocks:
        m = len(block.labels)
        xi = x[offset:offset + m].copy()
        if rng is not None:
            xi += noise_scale * (np.linalg.cholesky(block.covariance) @ rng.standard_normal(m))
        out[block.name] = xi
        offset += m
    return out


def write_readings_csv(loaded, readings: dict[str, np.ndarray], path: Path) -> None:
    """Readings in the CSV layout `readings_file` accepts (instrument, station, reading)."""
    rows = [[name, i + 1, v] for name, values in readings.items() for i, v in enumerate(values)]
    write_csv(Path(path), ["instrument", "station", "reading"], rows)
