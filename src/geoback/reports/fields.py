"""Field files: the mesh (.msh, .vtu), the lining's forces (lining.csv, lining.vtu) and the plastic zone
(plastic_zone.csv), written atomically (readers only: they take what the physics computed)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from geoback.outputs import write_atomic, write_csv
from geoback.physics.lining import LiningForces
from geoback.physics.mesh import Mesh
from geoback.physics.plastic_zone import HEADER as PLASTIC_ZONE_HEADER, PlasticZone
from geoback.reports.vtu import vtu_text


def write_mesh(mesh: Mesh, path: Path, point_data: dict | None = None, cell_data: dict | None = None) -> None:
    """Write the mesh (and optional fields); format from the suffix: .vtu (geoback.reports.vtu) or .msh
    (gmsh 2.2 through meshio, with one physical group per layer and 100 for the tunnel wall)."""
    path = Path(path)
    if path.suffix == ".vtu":
        cdata = {"region": mesh.region.astype(np.int32)}
        if getattr(mesh, "part", None) is not None:  # a section with openings: its parts and linings' bands
            cdata.update({"part": mesh.part.astype(np.int32), "band": mesh.band.astype(np.int32)})
        cdata.update(cell_data or {})
        write_atomic(path, vtu_text(mesh.nodes, mesh.triangles, point_data, cdata))
        return
    import meshio

    cell_type = "triangle6" if mesh.order == 2 else "triangle"
    points = np.column_stack([mesh.nodes, np.zeros(len(mesh.nodes))])
    if Path(path).suffix == ".msh":  # gmsh's own tags: one physical group per layer, 100 = tunnel wall
        edge_type = "line3" if mesh.order == 2 else "line"
        blocks = [(cell_type, mesh.triangles)]
        tags = [mesh.region.astype(np.int32) + 1]
        fields = {name: np.array([i + 1, 2]) for i, name in enumerate(mesh.region_names)}
        if len(mesh.tunnel_edges):  # (a section with openings has no tunnel wall: its openings are meshed)
            blocks.append((edge_type, mesh.tunnel_edges))
            tags.append(np.full(len(mesh.tunnel_edges), 100, np.int32))
            fields["tunnel"] = np.array([100, 1])
        m = meshio.Mesh(points, blocks, cell_data={"gmsh:physical": tags, "gmsh:geometrical": tags},
                        field_data=fields)
    else:
        cdata = {"region": [mesh.region.astype(np.int32)]}
        for k, v in (cell_data or {}).items():
            cdata[k] = [v]
        m = meshio.Mesh(points, [(cell_type, mesh.triangles)], point_data=point_data or {}, cell_data=cdata)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp" + path.suffix)
    os.close(fd)
    try:
        if path.suffix == ".msh":
            meshio.write(tmp, m, file_format="gmsh22", binary=False)
        else:
            meshio.write(tmp, m)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


LINING_HEADER = ["stage", "section", "angle_from_crown_deg", "arc_length_m", "x_m", "y_m", "N_kN_per_m",
                 "M_kNm_per_m", "V_kN_per_m", "ux_since_installation_m", "uy_since_installation_m"]


def lining_rows(forces: LiningForces) -> list[list]:
    rows = []
    for k, stage in enumerate(forces.stages):
        for i in range(len(forces.angle)):
            rows.append([stage, i + 1, forces.angle[i], forces.arc[i], forces.points[i, 0], forces.points[i, 1],
                         forces.N[k, i], forces.M[k, i], forces.V[k, i], forces.displacement[k, i, 0],
                         forces.displacement[k, i, 1]])
    return rows


def write_lining(forces: LiningForces, out: Path, vtu: bool = True) -> list[Path]:
    """lining.csv (N, M, V and the centreline's movement at every section and stage; N compression
    positive, M positive with the intrados in tension) and lining.vtu (the centreline as a polyline
    with those fields per stage, for ParaView)."""
    out = Path(out)
    paths = [out / "lining.csv"]
    write_csv(paths[0], LINING_HEADER, lining_rows(forces))
    if vtu:
        paths.append(out / "lining.vtu")
        write_lining_vtu(forces, paths[1])
    return paths


def write_lining_vtu(forces: LiningForces, path: Path) -> None:
    import os
    import tempfile

    import meshio

    pts = np.column_stack([forces.points, np.zeros(len(forces.points))])
    lines = np.column_stack([np.arange(len(pts) - 1), np.arange(1, len(pts))])
    data = {"angle_from_crown_deg": forces.angle, "arc_length_m": forces.arc}
    for k, stage in enumerate(forces.stages):
        data[f"N_kN_per_m[{stage}]"] = forces.N[k]
        data[f"M_kNm_per_m[{stage}]"] = forces.M[k]
        data[f"V_kN_per_m[{stage}]"] = forces.V[k]
        data[f"displacement[{stage}]"] = np.column_stack([forces.displacement[k], np.zeros(len(pts))])
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp.vtu")
    os.close(fd)
    try:
        meshio.write(tmp, meshio.Mesh(pts, [("line", lines)], point_data=data))
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def write_plastic_zone(zone: PlasticZone, out: Path) -> Path:
    """plastic_zone.csv (see the module docstring and ``PlasticZone.rows``)."""
    path = Path(out) / "plastic_zone.csv"
    write_csv(path, PLASTIC_ZONE_HEADER, zone.rows())
    return path
