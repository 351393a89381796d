"""Meshing the half-model with gmsh (headless, deterministic, cached by a hash of its inputs).

The size of the mesh is estimated before gmsh runs (geoback.case.meshsize) and refused beyond the
default limit unless ``allow_large``. Cache entries (``$GEOBACK_CACHE/meshes/<key>.npz``, default
``~/.cache/geoback``) carry a checksum of their arrays; an entry that is truncated, empty, corrupt
or inconsistent (wrong shapes, indices out of range) is rebuilt with a one-line notice on stderr,
and a cache that cannot be written is skipped with a notice.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from geoback.case.meshsize import mesh_inputs
from geoback.case.schema import Case


@dataclass(frozen=True)
class Mesh:
    """Triangles of the ground around the excavated tunnel.

    nodes: (N, 2) coordinates; triangles: (ne, 3|6) node indices (gmsh order: vertices, then
    mid-side nodes of edges 01, 12, 20); region: (ne,) layer index of each element;
    tunnel_edges: (nf, 2|3) node indices of the excavated boundary (vertices, then mid-node).
    """

    nodes: np.ndarray
    triangles: np.ndarray
    region: np.ndarray
    region_names: tuple[str, ...]
    tunnel_edges: np.ndarray
    key: str

    @property
    def order(self) -> int:
        return 2 if self.triangles.shape[1] == 6 else 1


def cache_dir() -> Path:
    root = os.environ.get("GEOBACK_CACHE")
    return Path(root) if root else Path.home() / ".cache" / "geoback"


def gmsh_version() -> str:
    """gmsh's version, read from its Python module without loading the library (a cached mesh then
    costs no gmsh start-up)."""
    import importlib.util
    import re

    spec = importlib.util.find_spec("gmsh")
    if spec is None or not spec.origin:
        return "none"
    try:
        with open(spec.origin, encoding="utf-8") as fh:
            head = fh.read(20000)
    except OSError:
        head = ""
    m = re.search(r'^GMSH_API_VERSION\s*=\s*"([^"]+)"', head, re.M) or re.search(r'^__version__\s*=\s*"([^"]+)"', head, re.M)
    if m:
        return m.group(1)
    import gmsh

    return gmsh.__version__


def mesh_key(inputs: dict) -> str:
    text = json.dumps(inputs, sort_keys=True) + gmsh_version()
    return hashlib.sha256(text.encode()).hexdigest()[:20]


GMSH_CALLS = 0  # counts real gmsh runs (tests check that the cache avoids them)
_ARRAYS = ("nodes", "triangles", "region", "region_names", "tunnel_edges")
_STALE_TMP_SECONDS = 3600  # temporary files of a writer killed midway are removed after this


def notice(message: str) -> None:
    """One line on stderr about something geoback repaired on its own."""
    print(f"notice: {message}", file=sys.stderr, flush=True)


def build_mesh(case: Case, use_cache: bool = True, allow_large: bool = False) -> Mesh:
    """Mesh of the case, from the on-disk cache when the same inputs were meshed before.

    Raises GeobackError, before gmsh runs, when the mesh is estimated beyond
    the default size limit (geoback.case.meshsize.max_dofs()), unless `allow_large`.
    """
    from geoback.errors import GeobackError
    from geoback.case.meshsize import Work, size_problem

    inputs = mesh_inputs(case)
    too_big = size_problem(inputs, allow_large=allow_large, work=Work.of(case))
    if too_big:
        raise GeobackError(f"mesh of case '{case.name}': {too_big[1]}")
    key = mesh_key(inputs)
    path = cache_dir() / "meshes" / f"{key}.npz"
    if use_cache:
        mesh = _read_cached(path, inputs, key)
        if mesh is not None:
            return mesh
    try:
        mesh = _run_gmsh(inputs, key)
    except Exception as exc:  # gmsh and OpenCASCADE raise plain exceptions
        raise GeobackError(f"gmsh could not mesh this geometry ({exc}); check the geometry and mesh sizes") from None
    if use_cache:
        _write_cached(path, mesh)
    return mesh


def _checksum(arrays: dict) -> str:
    h = hashlib.sha256()
    for name in _ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape};".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _read_cached(path: Path, inputs: dict, key: str) -> Mesh | None:
    """The cached mesh, or None when there is none or it is damaged (then a notice says so)."""
    try:
        if not path.exists():
            return None
    except OSError:
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {name: z[name] for name in _ARRAYS}
            stored = str(z["checksum"])
        problem = _inconsistency(arrays, stored, inputs)
    except Exception as exc:  # noqa: BLE001 - BadZipFile, EOFError, zlib errors, KeyError, ...: all mean damaged
        text = str(exc).split(". ")[0]
        problem = f"unreadable: {type(exc).__name__}{': ' + text if text else ''}"
    if problem is None:
        return Mesh(arrays["nodes"], arrays["triangles"], arrays["region"],
                    tuple(arrays["region_names"].tolist()), arrays["tunnel_edges"], key)
    notice(f"cached mesh {path} is damaged ({' '.join(problem.split())[:200]}); meshing again")
    return None


def _inconsistency(arrays: dict, stored: str, inputs: dict) -> str | None:
    """What is wrong with a cache entry's arrays (None if nothing)."""
    nodes, tri, region, names, edges = (arrays[n] for n in _ARRAYS)
    npe = 6 if inputs["order"] == 2 else 3
    if nodes.dtype != np.float64 or nodes.ndim != 2 or nodes.shape[1] != 2 or len(nodes) < 3:
        return f"nodes of shape {nodes.shape} and type {nodes.dtype}"
    if tri.dtype.kind not in "iu" or tri.ndim != 2 or tri.shape[1] != npe or len(tri) == 0:
        return f"triangles of shape {tri.shape} and type {tri.dtype}, expected (n, {npe}) integers"
    if region.dtype.kind not in "iu" or region.shape != (len(tri),):
        return f"{region.shape} region indices for {len(tri)} triangles"
    if names.dtype.kind != "U" or tuple(names.tolist()) != tuple(inputs["names"]):
        return "layer names differ from the case's"
    if edges.dtype.kind not in "iu" or edges.ndim != 2 or edges.shape[1] != (3 if npe == 6 else 2) or len(edges) == 0:
        return f"tunnel edges of shape {edges.shape}"
    if stored != _checksum(arrays):
        return "checksum mismatch"
    if tri.min() < 0 or tri.max() >= len(nodes):
        return "triangles refer to nodes that do not exist"
    if region.min() < 0 or region.max() >= len(names):
        return "region indices out of range"
    if edges.min() < 0 or edges.max() >= len(nodes):
        return "tunnel edges refer to nodes that do not exist"
    if not np.isfinite(nodes).all():
        return "non-finite node coordinates"
    return None


def _write_cached(path: Path, mesh: Mesh) -> None:
    """Store the mesh atomically (temporary file, then rename); a cache that cannot be written is
    skipped with a notice."""
    arrays = {"nodes": mesh.nodes, "triangles": mesh.triangles, "region": mesh.region,
              "region_names": np.array(mesh.region_names, dtype=str), "tunnel_edges": mesh.tunnel_edges}
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _remove_stale_temporaries(path.parent)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".tmp.npz")
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, checksum=np.array(_checksum(arrays)), **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; a shared cache keeps the usual mode
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        notice(f"could not write the mesh cache in {path.parent} ({exc.strerror or exc}); continuing without it")
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.remove(tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _remove_stale_temporaries(folder: Path) -> None:
    now = time.time()
    for leftover in folder.glob(".*.tmp.npz"):
        try:
            if now - leftover.stat().st_mtime > _STALE_TMP_SECONDS:
                leftover.unlink()
        except OSError:
            pass


def graded_fields(gmsh, curves: list[int], size_wall: float, size_far: float, growth: float, points=(),
                  size_points: float | None = None) -> list[int]:
    """Size fields: `size_wall` on `curves` growing linearly by `growth` of the distance up to `size_far`
    (a graded mesh, ~log(domain / R) elements), and with `points` and `size_points` the same around
    those points (instruments); returns the fields' ids for ``generate``."""
    fields = gmsh.model.mesh.field
    fields.add("Distance", 1)
    fields.setNumbers(1, "CurvesList", curves)
    fields.setNumber(1, "Sampling", 200)
    fields.add("Threshold", 2)
    fields.setNumber(2, "InField", 1)
    fields.setNumber(2, "SizeMin", size_wall)
    fields.setNumber(2, "SizeMax", size_far)
    fields.setNumber(2, "DistMin", 0.0)
    fields.setNumber(2, "DistMax", (size_far - size_wall) / growth)
    background = [2]
    if len(points) and size_points:
        occ = gmsh.model.occ
        pts = [occ.addPoint(x, y, 0) for x, y in points]
        occ.synchronize()
        fields.add("Distance", 3)
        fields.setNumbers(3, "PointsList", pts)
        fields.add("Threshold", 4)
        fields.setNumber(4, "InField", 3)
        fields.setNumber(4, "SizeMin", size_points)
        fields.setNumber(4, "SizeMax", size_far)
        fields.setNumber(4, "DistMin", size_points)
        fields.setNumber(4, "DistMax", size_points + (size_far - size_points) / growth)
        background.append(4)
    return background


def generate(gmsh, background: list[int], order: int) -> tuple[np.ndarray, np.ndarray]:
    """Mesh with the minimum of the size fields `background` (nothing else sets sizes), quadratic
    elements straight-sided where the geometry is (no high-order optimisation); returns the map from
    gmsh's node tags to indices and the nodes' (x, y)."""
    fields = gmsh.model.mesh.field
    fields.add("Min", 10)
    fields.setNumbers(10, "FieldsList", background)
    fields.setAsBackgroundMesh(10)
    for opt, val in (("Mesh.MeshSizeExtendFromBoundary", 0), ("Mesh.MeshSizeFromPoints", 0),
                     ("Mesh.MeshSizeFromCurvature", 0), ("Mesh.Algorithm", 6),
                     ("Mesh.ElementOrder", order), ("Mesh.SecondOrderLinear", 0),
                     ("Mesh.HighOrderOptimize", 0)):
        gmsh.option.setNumber(opt, val)
    gmsh.model.mesh.generate(2)
    node_tags, coords, _ = gmsh.model.mesh.getNodes()
    index = np.empty(int(node_tags.max()) + 1, dtype=np.int64)
    index[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    return index, coords.reshape(-1, 3)[:, :2].copy()


def compact(nodes: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nodes that elements use, renumbered compactly (gmsh keeps geometry points no element uses), and
    every triangle counter-clockwise; returns nodes, triangles and the renumbering (old -> new)."""
    used = np.zeros(len(nodes), bool)
    used[triangles.ravel()] = True
    renum = np.cumsum(used) - 1
    nodes = nodes[used]
    triangles = renum[triangles]
    p = nodes[triangles[:, :3]]
    area2 = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1])
    flip = area2 < 0
    if flip.any():
        t = triangles[flip]
        triangles[flip] = t[:, [0, 2, 1, 5, 4, 3]] if triangles.shape[1] == 6 else t[:, [0, 2, 1]]
    return nodes, triangles.astype(np.int64), renum


def _run_gmsh(inputs: dict, key: str) -> Mesh:
    import gmsh

    global GMSH_CALLS
    GMSH_CALLS += 1
    g = inputs["geometry"]
    W, H, R, d = g["width"], g["depth"], g["radius"], g["axis_depth"]
    tops = list(inputs["tops"]) + [H]
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.add(key)
        occ = gmsh.model.occ
        rects = [occ.addRectangle(0, -tops[i + 1], 0, W, tops[i + 1] - tops[i]) for i in range(len(tops) - 1)]
        disk = occ.addDisk(0, -d, 0, R, R)
        pieces, _ = occ.cut([(2, r) for r in rects], [(2, disk)])
        occ.fragment(pieces, [])
        occ.synchronize()

        # which layer each surface belongs to: its centre of mass depth
        surfaces = sorted(tag for _, tag in gmsh.model.getEntities(2))
        layer_of = {}
        for tag in surfaces:
            cy = occ.getCenterOfMass(2, tag)[1]
            layer_of[tag] = max(i for i in range(len(tops) - 1) if tops[i] <= -cy)
        tunnel = [tag for _, tag in gmsh.model.getEntities(1) if gmsh.model.getType(1, tag) != "Line"]
        for i in range(len(tops) - 1):
            tags = [t for t in surfaces if layer_of[t] == i]
            if tags:
                gmsh.model.addPhysicalGroup(2, tags, tag=i + 1, name=inputs["names"][i])
        gmsh.model.addPhysicalGroup(1, tunnel, tag=100, name="tunnel")

        background = graded_fields(gmsh, tunnel, inputs["size_tunnel"], inputs["size_far"], inputs["growth"],
                                   inputs["instrument_points"], inputs["size_instruments"])
        index, nodes = generate(gmsh, background, inputs["order"])
        tri_type = 9 if inputs["order"] == 2 else 2
        line_type = 8 if inputs["order"] == 2 else 1
        npe = 6 if inputs["order"] == 2 else 3
        tris, region = [], []
        for i in range(len(tops) - 1):
            tags = [t for t in surfaces if layer_of[t] == i]
            for t in tags:
                _, enodes = gmsh.model.mesh.getElementsByType(tri_type, t)
                tris.append(index[enodes.astype(np.int64)].reshape(-1, npe))
                region.append(np.full(len(tris[-1]), i, dtype=np.int32))
        edges = []
        for t in tunnel:
            _, enodes = gmsh.model.mesh.getElementsByType(line_type, t)
            edges.append(index[enodes.astype(np.int64)].reshape(-1, 3 if npe == 6 else 2))
    finally:
        gmsh.finalize()
    triangles = np.vstack(tris)
    region_arr = np.concatenate(region)
    nodes, triangles, renum = compact(nodes, triangles)
    tunnel_edges = renum[np.vstack(edges)]
    return Mesh(nodes, triangles.astype(np.int64), region_arr, tuple(inputs["names"]),
                tunnel_edges.astype(np.int64), key)
