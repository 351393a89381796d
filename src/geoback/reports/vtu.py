"""VTK XML unstructured grids (.vtu) for ParaView, written directly: points, P1/P2 triangles, point
and cell data as zlib-compressed, base64-encoded binary arrays. Small and dependency-free, so that writing a run's
field costs no library start-up (meshio, which geoback uses for gmsh's .msh, loads far more)."""
from __future__ import annotations

import base64
import zlib

import numpy as np

VTK_TRIANGLE, VTK_QUADRATIC_TRIANGLE = 5, 22  # node order: vertices, then mid-sides 01, 12, 20 (as gmsh)
_TYPES = {np.dtype("float64"): "Float64", np.dtype("float32"): "Float32", np.dtype("int32"): "Int32",
          np.dtype("int64"): "Int64", np.dtype("uint8"): "UInt8"}


def _array(name: str, values: np.ndarray, components: int = 1) -> str:
    values = np.ascontiguousarray(values)
    if values.dtype not in _TYPES:
        values = values.astype(np.float64)
    raw = values.astype(values.dtype.newbyteorder("<"), copy=False).tobytes()
    packed = zlib.compress(raw, 1)  # fast: a 1 M-DOF field in a fraction of a second  # one block: header [blocks, block size, last block size, compressed size]
    header = np.array([1, len(raw), len(raw), len(packed)], dtype="<u8").tobytes()
    blob = (base64.b64encode(header) + base64.b64encode(packed)).decode("ascii")
    comps = f' NumberOfComponents="{components}"' if components > 1 else ""
    label = f' Name="{name}"' if name else ""
    return f'<DataArray type="{_TYPES[values.dtype]}"{label}{comps} format="binary">{blob}</DataArray>'


def vtu_text(nodes: np.ndarray, cells: np.ndarray, point_data: dict | None = None,
             cell_data: dict | None = None) -> str:
    """The XML of an unstructured grid of triangles (3 or 6 nodes each)."""
    points = np.column_stack([nodes, np.zeros(len(nodes))]) if nodes.shape[1] == 2 else nodes
    n, npc = cells.shape
    kind = VTK_QUADRATIC_TRIANGLE if npc == 6 else VTK_TRIANGLE
    parts = ['<?xml version="1.0"?>',
             '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64" '
             'compressor="vtkZLibDataCompressor">',
             "<UnstructuredGrid>", f'<Piece NumberOfPoints="{len(points)}" NumberOfCells="{n}">',
             "<Points>", _array("", points.astype(np.float64), 3), "</Points>", "<Cells>",
             _array("connectivity", cells.astype(np.int64).ravel()),
             _array("offsets", np.arange(npc, npc * n + 1, npc, dtype=np.int64)),
             _array("types", np.full(n, kind, np.uint8)), "</Cells>"]
    for tag, data in (("PointData", point_data), ("CellData", cell_data)):
        if data:
            parts.append(f"<{tag}>")
            for name, v in data.items():
                v = np.asarray(v)
                parts.append(_array(name, v.reshape(len(v), -1) if v.ndim > 1 else v,
                                    v.shape[1] if v.ndim > 1 else 1))
            parts.append(f"</{tag}>")
    parts += ["</Piece>", "</UnstructuredGrid>", "</VTKFile>"]
    return "\n".join(parts) + "\n"
