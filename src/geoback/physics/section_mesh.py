"""Meshing a section with openings (``geometry: {model, width, depth, openings}``) with gmsh: the ground in
horizontal layers, every opening meshed inside (its parts conforming to the cut lines, the linings' bands
conforming to their thickness), so that construction removes and adds elements.

The outlines are exact (gmsh's circular arcs); parts are the opening cut by half-planes and bands the
opening less its inset outline (or a strip beside a cut line), intersected with their part, all with
OpenCASCADE booleans. Elements are then told apart by their centroids against the layout's polygons
(``case/layout.py``), each gmsh surface taking the majority of its elements (a surface never straddles
a layer, a part or a band after the fragment). Cached like the circular mesh (``mesh.py``).
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass

import numpy as np

from geoback.case import layout as lay
from geoback.case.schema import Case
from geoback.physics.mesh import Mesh, cache_dir, compact, generate, gmsh_version, graded_fields, notice

GMSH_CALLS = 0
MESHER_VERSION = 6  # part of the cache key: raised when the meshing changes


@dataclass(frozen=True)
class SectionMesh(Mesh):
    """A ``Mesh`` with what construction needs: part[e] (index into part_names, -1: ground never excavated),
    band[e] (index into band_names, the lining whose band holds the element, -1: none)."""

    part: np.ndarray = None
    part_names: tuple[str, ...] = ()
    band: np.ndarray = None
    band_names: tuple[str, ...] = ()


def default_sizes(case: Case) -> tuple[float, float]:
    """Element size at the openings' walls (the smallest opening's equivalent radius / 8) and far away
    (the model's larger side / 12), unless the case's mesh section gives them."""
    g, m = case.geometry, case.mesh
    radii = [math.sqrt(lay.polygon(op).area / math.pi) for op in g.openings]
    return (m.size_tunnel or min(radii) / 8, m.size_far or max(g.width, g.depth) / 12)


def section_inputs(case: Case, instrument_points=()) -> dict:
    """Everything the mesh depends on, as plain data (its cache key is their hash)."""
    from geoback.case.sequence import Sequence

    g, m = case.geometry, case.mesh
    wall, far = default_sizes(case)
    linings = Sequence.of(case).linings if case.construction is not None else {}
    from geoback.case.supports import walls

    return {"kind": "section", "walls": [[w.name, w.x, w.top, w.toe, w.thickness, w.layers] for w in walls(case).values()], "mesher": MESHER_VERSION, "model": g.model, "box": list(lay.box(g)),
            "tops": [layer.top for layer in case.ground.layers], "names": [layer.name for layer in case.ground.layers],
            "openings": [op.model_dump(mode="json") for op in g.openings],
            "linings": [ln.model_dump(mode="json") for ln in linings.values()],
            "size_wall": wall, "size_far": far, "size_instruments": m.size_instruments,
            "growth": m.growth, "order": m.order, "points": [list(map(float, p)) for p in instrument_points]}


def build_section_mesh(case: Case, instrument_points=(), use_cache: bool = True) -> SectionMesh:
    inputs = section_inputs(case, instrument_points)
    key = hashlib.sha256((json.dumps(inputs, sort_keys=True) + gmsh_version()).encode()).hexdigest()[:20]
    path = cache_dir() / "meshes" / f"section-{key}.npz"
    if use_cache and path.exists():
        try:
            with np.load(path, allow_pickle=False) as z:
                return SectionMesh(z["nodes"], z["triangles"], z["region"], tuple(z["region_names"].tolist()),
                                   z["tunnel_edges"], key, z["part"], tuple(z["part_names"].tolist()), z["band"],
                                   tuple(z["band_names"].tolist()))
        except Exception as exc:  # noqa: BLE001 - a damaged entry is meshed again
            notice(f"cached mesh {path} is damaged ({type(exc).__name__}); meshing again")
    from geoback.errors import GeobackError

    try:
        mesh = _run_gmsh(case, inputs, key)
    except GeobackError:
        raise
    except Exception as exc:  # noqa: BLE001 - gmsh and OpenCASCADE raise plain exceptions
        raise GeobackError(f"gmsh could not mesh this section ({exc}); check the openings and mesh sizes") from None
    if use_cache:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, nodes=mesh.nodes, triangles=mesh.triangles, region=mesh.region,
                     region_names=np.array(mesh.region_names, str), tunnel_edges=mesh.tunnel_edges, part=mesh.part,
                     part_names=np.array(mesh.part_names, str), band=mesh.band, band_names=np.array(mesh.band_names, str))
            tmp.replace(path)
        except OSError as exc:
            notice(f"could not write the mesh cache in {path.parent} ({exc}); continuing without it")
    return mesh


def _curve_loop(occ, pieces) -> int:
    tags, first = [], None
    pts = {}

    def point(p):
        key = (round(p[0], 12), round(p[1], 12))
        if key not in pts:
            pts[key] = occ.addPoint(p[0], p[1], 0)
        return pts[key]

    for p in pieces:
        if isinstance(p, lay.Line):
            tags.append(occ.addLine(point(p.start), point(p.end)))
        else:
            tags.append(occ.addCircleArc(point(p.start), occ.addPoint(*p.centre, 0), point(p.end)))
    return occ.addCurveLoop(tags)


def _surface(occ, pieces) -> int:
    return occ.addPlaneSurface([_curve_loop(occ, pieces)])


def _polygon_surface(occ, coords) -> int:
    pts = [occ.addPoint(x, y, 0) for x, y in coords]
    lines = [occ.addLine(pts[k], pts[(k + 1) % len(pts)]) for k in range(len(pts))]
    return occ.addPlaneSurface([occ.addCurveLoop(lines)])


def _run_gmsh(case: Case, inputs: dict, key: str) -> SectionMesh:
    import gmsh
    from shapely import contains_xy

    global GMSH_CALLS
    GMSH_CALLS += 1
    g = case.geometry
    x0, x1, depth = lay.box(g)
    tops = list(inputs["tops"]) + [depth]
    regions = lay.regions(g)
    part_names = tuple(regions)
    linings = inputs["linings"]
    from geoback.case.sequence import Sequence

    from geoback.case.supports import walls

    placed = list(Sequence.of(case).linings.values()) if case.construction is not None else []
    wall_bands = list(walls(case).values())
    bands = [lay.lining_band(g, ln) for ln in placed] + [w.polygon() for w in wall_bands]
    band_names = tuple(ln.name for ln in placed) + tuple(w.name for w in wall_bands)
    gmsh.initialize(readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        gmsh.model.add(key)
        occ = gmsh.model.occ
        surfaces = [(2, occ.addRectangle(x0, -tops[i + 1], 0, x1 - x0, tops[i + 1] - tops[i])) for i in range(len(tops) - 1)]
        for op in g.openings:
            whole = _surface(occ, lay.outline(op))
            pieces = [(2, whole)]
            poly = lay.polygon(op)
            for a, b in op.cuts:
                half = _half_plane(occ, a, b, poly)
                nxt = []
                for piece in pieces:  # (OCC may return a piece the line misses as itself: keep it then)
                    inside, _ = occ.intersect([piece], [(2, half)], removeObject=False, removeTool=False)
                    outside, _ = occ.cut([piece], [(2, half)], removeObject=False, removeTool=False)
                    made = [s for s in inside + outside if s[0] == 2 and s != piece]
                    area = occ.getMass(*piece)
                    if made and abs(sum(occ.getMass(*s) for s in made) - area) <= 1e-9 * area:
                        occ.remove([piece], recursive=True)
                        nxt += made
                    else:  # wholly on one side of the cut (OpenCASCADE may then return nothing): kept as it is
                        occ.remove(made, recursive=True)
                        nxt.append(piece)
                occ.remove([(2, half)], recursive=True)
                pieces = nxt
            surfaces += pieces
        band_inputs = []
        for ln in placed:
            op = lay.opening_of(g, ln.on) or lay.opening_of(g, regions[ln.on][0])
            t = ln.thickness
            if ln.side == "wall":
                outer = _surface(occ, lay.outline(op))
                inner = _surface(occ, lay.outline(op, inset=t)) if op.shape == "circle" else \
                    _polygon_surface(occ, list(lay.polygon(op, inset=t).exterior.coords)[:-1])
                band, _ = occ.cut([(2, outer)], [(2, inner)])
            else:
                band_poly = lay.lining_band(g, ln).buffer(t * 1e-3)  # a strip beyond the part, cut back below
                band = [(2, _polygon_surface(occ, list(band_poly.minimum_rotated_rectangle.exterior.coords)[:-1]))]
            if ln.on in regions and lay.opening_of(g, ln.on) is None:  # a part: keep the band within it
                holder = _surface(occ, lay.outline(op))
                for a, b in op.cuts:
                    half = _half_plane(occ, a, b, lay.polygon(op), side_of=regions[ln.on][1].representative_point())
                    holder_l, _ = occ.intersect([(2, holder)] if isinstance(holder, int) else holder, [(2, half)])
                    holder = holder_l
                band, _ = occ.intersect(band, holder if isinstance(holder, list) else [(2, holder)])
            band_inputs.append([len(surfaces) + j for j, s in enumerate(band) if s[0] == 2])
            surfaces += [s for s in band if s[0] == 2]
        for w in wall_bands:  # a wall: its band, fragmented with the ground below
            fx0, fx1 = w.faces
            band_inputs.append([len(surfaces)])
            surfaces.append((2, occ.addRectangle(fx0, -w.toe, 0, fx1 - fx0, w.toe - w.top)))
        _, fragments = occ.fragment(surfaces, [])
        occ.synchronize()
        outside = []
        for dim, tag in gmsh.model.getEntities(2):
            cx, cy, _ = occ.getCenterOfMass(dim, tag)  # a piece outside the box (a half-plane) has its centre there
            if cx < x0 or cx > x1 or cy > 0 or cy < -depth:
                outside.append((dim, tag))
        if outside:
            occ.remove(outside, recursive=True)
            occ.synchronize()
        f = gmsh.model.mesh.field
        background = graded_fields(gmsh, _wall_curves(g, gmsh, [w.polygon() for w in wall_bands]), inputs["size_wall"], inputs["size_far"],
                                   inputs["growth"], inputs["points"], inputs["size_instruments"])
        surf_tags = [t for _, t in gmsh.model.getEntities(2)]
        alive = set(surf_tags)
        band_surfaces = [sorted({t for i in idx for d, t in fragments[i] if d == 2 and t in alive}) for idx in band_inputs]
        through = [ln.thickness / 2 for ln in placed] + [w.thickness / w.layers for w in wall_bands]
        for n, (size, tags) in enumerate(zip(through, band_surfaces)):
            if tags:
                fid = 20 + n
                f.add("Constant", fid)
                f.setNumber(fid, "VIn", min(inputs["size_wall"], size))
                f.setNumber(fid, "VOut", 1e22)
                f.setNumbers(fid, "SurfacesList", tags)
                background.append(fid)
        index, nodes = generate(gmsh, background, inputs["order"])
        npe = 6 if inputs["order"] == 2 else 3
        tri_type = 9 if npe == 6 else 2
        tris, surface_of = [], []
        for tag in surf_tags:
            _, enodes = gmsh.model.mesh.getElementsByType(tri_type, tag)
            t = index[enodes.astype(np.int64)].reshape(-1, npe)
            tris.append(t)
            surface_of.append(np.full(len(t), tag))
    finally:
        gmsh.finalize()
    triangles = np.vstack(tris)
    surface_of = np.concatenate(surface_of)
    nodes, triangles, _ = compact(nodes, triangles)
    p = nodes[triangles[:, :3]]
    c = p.mean(axis=1)
    layer = np.clip(np.searchsorted(np.asarray(inputs["tops"]), -c[:, 1], side="right") - 1, 0, len(inputs["tops"]) - 1)
    part = -np.ones(len(triangles), np.int64)
    for k, name in enumerate(part_names):
        part[contains_xy(regions[name][1], c[:, 0], c[:, 1])] = k
    band = -np.ones(len(triangles), np.int64)
    for k, b in enumerate(bands):
        band[contains_xy(b, c[:, 0], c[:, 1])] = k
    for tag in np.unique(surface_of):  # one class per gmsh surface: the majority of its elements
        sel = surface_of == tag
        for arr in (layer, part, band):
            vals, counts = np.unique(arr[sel], return_counts=True)
            arr[sel] = vals[np.argmax(counts)]
    return SectionMesh(nodes, triangles.astype(np.int64), layer.astype(np.int32), tuple(inputs["names"]),
                       np.zeros((0, 3 if npe == 6 else 2), np.int64), key, part, part_names, band, band_names)


def _half_plane(occ, a, b, poly, side_of=None) -> int:
    """A large polygon on the left of the directed line a -> b (or on the side of point `side_of`)."""
    size = 4 * math.hypot(poly.bounds[2] - poly.bounds[0], poly.bounds[3] - poly.bounds[1]) + 4 * max(
        abs(v) for v in poly.bounds)
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy)
    dx, dy = dx / n, dy / n
    nx, ny = -dy, dx
    if side_of is not None and (side_of.x - a[0]) * nx + (side_of.y - a[1]) * ny < 0:
        nx, ny = -nx, -ny
    p0 = (a[0] - size * dx, a[1] - size * dy)
    p1 = (a[0] + size * dx, a[1] + size * dy)
    return _polygon_surface(occ, [p0, p1, (p1[0] + size * nx, p1[1] + size * ny), (p0[0] + size * nx, p0[1] + size * ny)])


def _wall_curves(g, gmsh, retaining=()) -> list[int]:
    """Curves on the openings' walls and cut lines and on the retaining walls (where the mesh is refined):
    curves whose midpoint lies within the openings' closed outlines or on a retaining wall."""
    from shapely.geometry import Point

    polys = [p.buffer(1e-6 * max(g.width, g.depth)) for p in [lay.polygon(op) for op in g.openings] + list(retaining)]
    out = []
    for _, tag in gmsh.model.getEntities(1):
        lo, hi = gmsh.model.getParametrizationBounds(1, tag)
        x, y, _ = gmsh.model.getValue(1, tag, [(lo[0] + hi[0]) / 2])
        if any(p.contains(Point(x, y)) for p in polys):
            out.append(tag)
    return out
