"""The section of a case with openings (``geometry: {model, width, depth, openings}``) as geometry: each
opening's outline as straight lines and circular arcs (exact: gmsh meshes them as they are), its parts
(the pieces its cut lines make), the bands the linings occupy, and the checks of all of it that need no
finite elements (openings inside the ground and apart, parts that tile their opening, cut lines that
cross it, a half-model symmetric about x = 0).

Polygons (``shapely``) are the outlines sampled finely (a chord error below 1e-5 of the opening's size):
they answer the questions of area, containment and tiling; the mesher uses the exact outlines.
shapely is used because its overlay operations (split by cut lines, buffers, symmetric differences)
are robust where hand-written polygon clipping is not.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from geoback.case.schema import Case, HorseshoeOpening, Layout, PolygonOpening, number_text

ARC_PIECE = 2 * math.pi / 3  # an arc longer than this is split (gmsh's arcs are shorter than pi)
SAMPLES = 720  # points per full circle when an outline is sampled into a polygon


@dataclass(frozen=True)
class Line:
    start: tuple[float, float]
    end: tuple[float, float]


@dataclass(frozen=True)
class Arc:
    """A circular arc from `start` to `end` about `centre`, counter-clockwise if `ccw`, of sweep < 2 pi/3."""

    start: tuple[float, float]
    end: tuple[float, float]
    centre: tuple[float, float]
    ccw: bool = True

    @property
    def radius(self) -> float:
        return math.hypot(self.start[0] - self.centre[0], self.start[1] - self.centre[1])


def _arc(start, end, centre, ccw: bool = True) -> list[Arc]:
    """The arc from start to end about centre (ccw or clockwise), split into pieces of at most ARC_PIECE."""
    cx, cy = centre
    r = math.hypot(start[0] - cx, start[1] - cy)
    a0 = math.atan2(start[1] - cy, start[0] - cx)
    a1 = math.atan2(end[1] - cy, end[0] - cx)
    sweep = (a1 - a0) % (2 * math.pi) if ccw else -((a0 - a1) % (2 * math.pi))
    if abs(sweep) < 1e-12:
        sweep = 2 * math.pi if ccw else -2 * math.pi
    n = max(1, math.ceil(abs(sweep) / ARC_PIECE - 1e-9))
    pts = [start] + [(cx + r * math.cos(a0 + sweep * k / n), cy + r * math.sin(a0 + sweep * k / n))
                     for k in range(1, n)] + [end]
    return [Arc(tuple(pts[k]), tuple(pts[k + 1]), (cx, cy), ccw) for k in range(n)]


@dataclass(frozen=True)
class HorseshoeShape:
    """The derived dimensions of a horseshoe: springline centre (cx, cy), radii r1 (crown), r2 (side
    walls), r3 (invert; inf when flat), hs (depth of the invert corners below the springline), xb (half
    the width at the corners) and yc (the invert arc's centre height)."""

    cx: float
    cy: float
    r1: float
    r2: float
    r3: float
    hs: float
    xb: float
    yc: float


def _corner(r1: float, r2: float, hs: float) -> float:
    """Half-width at depth hs below the springline on side walls of radius r2 centred at x = r1 - r2."""
    return r1 - r2 + math.sqrt(max(r2 * r2 - hs * hs, 0.0))


def _sag(r3: float | None, xb: float) -> float:
    return 0.0 if r3 is None else r3 - math.sqrt(max(r3 * r3 - xb * xb, 0.0))


def horseshoe_shape(op: HorseshoeOpening) -> HorseshoeShape:
    """The profile's dimensions: the corners' depth hs solves height = r1 + hs + sag(hs) (bisection:
    the height grows with hs); ValueError (in the case's words) when no profile has that height."""
    cx, cy = op.centre
    r1, r2, r3, H = op.crown_radius, op.side_radius, op.invert_radius, op.height
    if r2 < r1:
        raise ValueError(f"expected side_radius at least crown_radius ({number_text(r1)}), found {number_text(r2)}")
    # the side walls reach the axis at hs_max (the corners close) or stop at depth r2
    hs_max = min(r2, math.sqrt(max(r2 * r2 - (r2 - r1) ** 2, 0.0))) * (1 - 1e-6)
    if r3 is not None and r3 < _corner(r1, r2, 0.0):
        raise ValueError(f"expected an invert radius of at least the half-width {number_text(r1)}, found {number_text(r3)}")

    def height(hs):
        return r1 + hs + _sag(r3, _corner(r1, r2, hs))

    if not height(0.0) < H < height(hs_max):
        raise ValueError(f"expected a height between {number_text(height(0.0))} and {number_text(height(hs_max))} for "
                         f"crown radius {number_text(r1)}, side radius {number_text(r2)}"
                         + (f" and invert radius {number_text(r3)}" if r3 else "") + f", found {number_text(H)}")
    lo, hi = 0.0, hs_max
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if height(mid) < H else (lo, mid)
    hs = (lo + hi) / 2
    xb = _corner(r1, r2, hs)
    yc = cy - hs + (math.sqrt(r3 * r3 - xb * xb) if r3 is not None else 0.0)
    return HorseshoeShape(cx, cy, r1, r2, r3 if r3 is not None else math.inf, hs, xb, yc)


def _tangent(c2, r2, c3, r3):
    """The point where two internally tangent circles touch (None if they are not tangent)."""
    d = math.hypot(c2[0] - c3[0], c2[1] - c3[1])
    if not d > 0 or abs(d - abs(r3 - r2)) > 1e-9 * max(r2, r3):
        return None
    big, rb, small = (c3, r3, c2) if r3 >= r2 else (c2, r2, c3)
    return (big[0] + rb * (small[0] - big[0]) / d, big[1] + rb * (small[1] - big[1]) / d)


def outline(op, inset: float = 0.0) -> list:
    """The opening's outline as Lines and Arcs, counter-clockwise; with `inset`, the outline moved
    inwards by that distance (arcs keep their centres: the intrados of a lining of that thickness).
    Polygon sides are straight lines inset by a sampled buffer (``polygon``)."""
    if op.shape == "circle":
        (cx, cy), r = op.centre, op.radius - inset
        return _arc((cx + r, cy), (cx + r, cy), (cx, cy))
    if op.shape == "horseshoe" and not inset:
        h = horseshoe_shape(op)
        c1, c2r, c2l = (h.cx, h.cy), (h.cx + h.r1 - h.r2, h.cy), (h.cx - h.r1 + h.r2, h.cy)
        pr, pl = (h.cx + h.r1, h.cy), (h.cx - h.r1, h.cy)
        br, bl = (h.cx + h.xb, h.cy - h.hs), (h.cx - h.xb, h.cy - h.hs)
        invert = [Line(bl, br)] if math.isinf(h.r3) else _arc(bl, br, (h.cx, h.yc))
        return _arc(pr, pl, c1) + _arc(pl, bl, c2l) + invert + _arc(br, pr, c2r)
    if inset:
        poly = polygon(op).buffer(-inset, join_style="mitre")
        pts = list(poly.exterior.coords)[:-1]
        return [Line(tuple(pts[k]), tuple(pts[(k + 1) % len(pts)])) for k in range(len(pts))]
    return _polygon_outline(op)


def _polygon_outline(op: PolygonOpening) -> list:
    entries = list(op.boundary)
    out = []
    k, n = 0, len(entries)
    vertices = [i for i, e in enumerate(entries) if not hasattr(e, "through")]
    for j, i in enumerate(vertices):
        nxt = vertices[(j + 1) % len(vertices)]
        a, b = tuple(entries[i]), tuple(entries[nxt])
        between = entries[i + 1:nxt] if nxt > i else entries[i + 1:] + entries[:nxt]
        if between:
            m = tuple(between[0].through)
            centre = _circumcentre(a, m, b)
            # ccw if m lies on the ccw sweep from a to b about the centre
            ang = [math.atan2(p[1] - centre[1], p[0] - centre[0]) for p in (a, m, b)]
            ccw = (ang[1] - ang[0]) % (2 * math.pi) < (ang[2] - ang[0]) % (2 * math.pi)
            out += _arc(a, b, centre, ccw)
        else:
            out.append(Line(a, b))
    return out


def _circumcentre(a, b, c) -> tuple[float, float]:
    ax, ay = a
    bx, by = b
    cx, cy = c
    d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    if abs(d) < 1e-12 * max(1.0, abs(ax) + abs(bx) + abs(cx)) ** 2:
        raise ValueError(f"expected an arc point off the straight line between its neighbours, found "
                         f"({number_text(b[0])}, {number_text(b[1])}) on the line")
    ux = ((ax * ax + ay * ay) * (by - cy) + (bx * bx + by * by) * (cy - ay) + (cx * cx + cy * cy) * (ay - by)) / d
    uy = ((ax * ax + ay * ay) * (cx - bx) + (bx * bx + by * by) * (ax - cx) + (cx * cx + cy * cy) * (bx - ax)) / d
    return (ux, uy)


def sample(pieces: list) -> np.ndarray:
    """Points along an outline (closed implicitly), arcs at SAMPLES per turn."""
    pts = []
    for p in pieces:
        if isinstance(p, Line):
            pts.append(p.start)
            continue
        cx, cy = p.centre
        a0 = math.atan2(p.start[1] - cy, p.start[0] - cx)
        a1 = math.atan2(p.end[1] - cy, p.end[0] - cx)
        sweep = (a1 - a0) % (2 * math.pi) if p.ccw else -((a0 - a1) % (2 * math.pi))
        n = max(2, math.ceil(abs(sweep) / (2 * math.pi) * SAMPLES))
        r = p.radius
        pts += [(cx + r * math.cos(a0 + sweep * k / n), cy + r * math.sin(a0 + sweep * k / n)) for k in range(n)]
    return np.array(pts)


def polygon(op, inset: float = 0.0):
    """The opening as a shapely polygon (sampled outline)."""
    from shapely.geometry import Polygon

    if op.shape != "circle" and inset:
        return polygon(op).buffer(-inset, join_style="mitre")
    return Polygon(sample(outline(op, inset))).buffer(0)


# ---------------------------------------------------------------------------- the model's box
def box(layout: Layout) -> tuple[float, float, float]:
    """x_min, x_max and depth of the model."""
    if layout.model == "half":
        return 0.0, layout.width, layout.depth
    return -layout.width / 2, layout.width / 2, layout.depth


def ground_polygon(layout: Layout):
    from shapely.geometry import box as shapely_box

    x0, x1, d = box(layout)
    return shapely_box(x0, -d, x1, 0.0)


# ---------------------------------------------------------------------------- parts and lining bands
def pieces(op) -> list:
    """The pieces of an opening its cut lines make (shapely polygons), in the model's full plane."""
    from shapely.geometry import LineString
    from shapely.ops import split

    poly = polygon(op)
    out = [poly]
    for a, b in op.cuts:
        line = _extended(a, b, poly)
        nxt = []
        for piece in out:
            nxt += list(split(piece, line).geoms) if line.intersects(piece) else [piece]
        out = nxt
    return [p for p in out if p.area > 1e-9 * poly.area]


def _extended(a, b, poly):
    """The cut line through a and b extended well beyond the opening (a cut is a straight line across it)."""
    from shapely.geometry import LineString

    size = math.hypot(poly.bounds[2] - poly.bounds[0], poly.bounds[3] - poly.bounds[1])
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy)
    dx, dy = dx / n, dy / n
    reach = 2 * size + math.hypot(a[0] - poly.centroid.x, a[1] - poly.centroid.y)
    return LineString([(a[0] - reach * dx, a[1] - reach * dy), (b[0] + reach * dx, b[1] + reach * dy)])


def regions(layout: Layout) -> dict[str, tuple[str, object]]:
    """Every excavatable region by name: a part (its opening's name, polygon) or an opening without parts
    (its own name, polygon). An opening with parts is excavated by its parts (its name stands for all)."""
    from shapely.geometry import Point as P

    out = {}
    for op in layout.openings:
        if not op.parts:
            out[op.name] = (op.name, polygon(op))
            continue
        ps = pieces(op)
        for part in op.parts:
            hit = [p for p in ps if p.buffer(1e-9).contains(P(*part.contains))]
            if len(hit) == 1:
                out[part.name] = (op.name, hit[0])
    return out


def opening_of(layout: Layout, name: str):
    return next((op for op in layout.openings if op.name == name), None)


def lining_band(layout: Layout, lining) -> object:
    """The band (shapely polygon) a lining occupies: within `lining.on` (an opening or a part), the
    `thickness` inside the opening's wall ('wall'), or beside the part's cut lines ('cut')."""
    from shapely.geometry import Polygon

    reg = regions(layout)
    op = opening_of(layout, lining.on)
    if op is None:
        opening_name, where = reg[lining.on]
        op = opening_of(layout, opening_name)
    else:
        where = polygon(op)
    t = lining.thickness
    if lining.side == "wall":
        return where.intersection(polygon(op).difference(polygon(op, inset=t))).buffer(0)
    bands = []
    for a, b in op.cuts:
        line = _extended(a, b, polygon(op))
        (x0, y0), (x1, y1) = line.coords
        n = np.array([-(y1 - y0), x1 - x0]) / math.hypot(x1 - x0, y1 - y0)
        inside = where.representative_point()
        side = 1.0 if np.dot([inside.x - x0, inside.y - y0], n) > 0 else -1.0
        off = side * t * n
        band = Polygon([(x0, y0), (x1, y1), (x1 + off[0], y1 + off[1]), (x0 + off[0], y0 + off[1])])
        if band.intersection(where).area > 0 and line.distance(where) < 1e-9 and _touches_cut(where, line):
            bands.append(band.intersection(where))
    from shapely.ops import unary_union

    return unary_union(bands).buffer(0) if bands else Polygon()


def _touches_cut(where, line) -> bool:
    """Does the part's boundary run along the cut line (not merely cross it at a point)?"""
    return where.exterior.intersection(line.buffer(1e-7)).length > 1e-6


# ---------------------------------------------------------------------------- checks
def layout_problems(case: Case) -> list[tuple[tuple, str]]:
    """Checks of the openings that need no finite elements: (path, message) for each problem."""
    from shapely.geometry import Point as P

    g = case.geometry
    out: list[tuple[tuple, str]] = []
    ground = ground_polygon(g)
    x0, x1, d = box(g)
    names: dict[str, tuple] = {}
    polys = []
    for i, op in enumerate(g.openings):
        at = ("geometry", "openings", i)
        try:
            poly = polygon(op)
        except ValueError as exc:
            out.append((at, str(exc)))
            polys.append(None)
            continue
        polys.append(poly)
        if not poly.is_valid or poly.area <= 0:
            out.append((at, f"expected a closed outline without self-crossings, found one enclosing no area"))
            continue
        minx, miny, maxx, maxy = poly.bounds
        if maxy > 1e-9 * d or miny < -d * (1 - 1e-9):
            out.append((at, f"expected opening '{op.name}' inside the ground (at or below the surface y = 0, above the "
                            f"bottom y = {number_text(-d)}), found it spanning y from {number_text(miny)} to "
                            f"{number_text(maxy)}"))
        if g.model == "half":
            if maxx <= 1e-9 * g.width:
                out.append((at, f"expected opening '{op.name}' on the modelled side of a half-model (x >= 0), "
                                f"found it at x from {number_text(minx)} to {number_text(maxx)}: model: full "
                                f"models both sides"))
            elif minx < -1e-9 * g.width:
                from shapely.affinity import scale

                mirror = scale(poly, xfact=-1, origin=(0, 0))
                if poly.symmetric_difference(mirror).area > 1e-4 * poly.area:
                    out.append((at, f"expected opening '{op.name}' symmetric about x = 0 in a half-model (it crosses "
                                    f"the symmetry axis), found it not symmetric: use model: full"))
            if maxx > g.width * (1 + 1e-9):
                out.append((at, f"expected opening '{op.name}' inside the model (x below the width "
                                f"{number_text(g.width)}), found it reaching x = {number_text(maxx)}"))
        elif minx < x0 - 1e-9 * g.width or maxx > x1 + 1e-9 * g.width:
            out.append((at, f"expected opening '{op.name}' inside the model (x between {number_text(x0)} and "
                            f"{number_text(x1)}), found it spanning x from {number_text(minx)} to {number_text(maxx)}"))
        for n, where in [(op.name, at + ("name",))] + [(p.name, at + ("parts", j, "name")) for j, p in enumerate(op.parts)]:
            if n in names:
                out.append((where, f"expected names of openings and parts different from each other, found '{n}' again"))
            names[n] = where
        out += _part_problems(op, poly, at)
    for i in range(len(polys)):
        for j in range(i):
            if polys[i] is not None and polys[j] is not None and polys[i].intersection(polys[j]).area > 1e-9 * polys[i].area:
                out.append((("geometry", "openings", i), f"expected openings apart from each other, found "
                                                         f"'{g.openings[i].name}' overlapping '{g.openings[j].name}'"))
    layer_names = {layer.name for layer in case.ground.layers}
    for n, where in names.items():
        if n in layer_names:
            out.append((where, f"expected an opening or part name different from the layers' names, found '{n}'"))
    return out


def _part_problems(op, poly, at) -> list[tuple[tuple, str]]:
    from shapely.geometry import Point as P

    out = []
    for k, (a, b) in enumerate(op.cuts):
        if math.hypot(b[0] - a[0], b[1] - a[1]) <= 0:
            out.append((at + ("cuts", k), "expected a cut line between two different points, found one point"))
            return out
        line = _extended(a, b, poly)
        inner = line.intersection(poly)
        if inner.length <= 1e-9 * math.sqrt(poly.area):
            out.append((at + ("cuts", k), f"expected the cut line through ({number_text(a[0])}, {number_text(a[1])}) "
                                          f"and ({number_text(b[0])}, {number_text(b[1])}) to cross opening "
                                          f"'{op.name}', found it missing the opening"))
            return out
    if op.cuts and not op.parts:
        out.append((at + ("parts",), f"expected the parts the cut lines make in '{op.name}' named (parts: [{{name, "
                                     f"contains: [x, y]}}]), found no parts"))
        return out
    if not op.parts:
        return out
    ps = pieces(op)
    owner = [[] for _ in ps]
    for j, part in enumerate(op.parts):
        hit = [i for i, p in enumerate(ps) if p.buffer(1e-9).contains(P(*part.contains))]
        x, y = part.contains
        if not hit:
            out.append((at + ("parts", j, "contains"), f"expected a point inside opening '{op.name}', found "
                                                       f"({number_text(x)}, {number_text(y)}) outside it"))
        elif len(hit) > 1:
            out.append((at + ("parts", j, "contains"), f"expected a point inside one part, found ({number_text(x)}, "
                                                       f"{number_text(y)}) on a cut line"))
        else:
            owner[hit[0]].append(part.name)
    for i, names in enumerate(owner):
        c = ps[i].representative_point()
        if len(names) > 1:
            out.append((at + ("parts",), f"expected one part per piece the cut lines make, found {', '.join(names)} "
                                         f"in the same piece"))
        elif not names and not any(o is not None and False for o in owner):
            out.append((at + ("parts",), f"expected the parts to tile opening '{op.name}', found a piece with no "
                                         f"part (around ({c.x:.3g}, {c.y:.3g}), area {ps[i].area:.3g} m2)"))
    return out


def reference_depth(case: Case) -> float:
    """The depth a gradient with depth is measured from: the tunnel's axis, or with openings the first
    opening's centroid."""
    g = case.geometry
    if hasattr(g, "axis_depth"):
        return g.axis_depth
    return -polygon(g.openings[0]).centroid.y
