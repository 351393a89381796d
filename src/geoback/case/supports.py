"""Retaining walls, props and ground anchors of an excavation as geometry and data (no finite elements:
``physics/supports.py`` puts them on the mesh).

A wall is a vertical band of its real thickness t centred on x, from depth `top` to `toe`: a continuum
of quadratic elements, as the linings are. A wall given as EA and EI per metre run becomes the band of
the same stiffnesses, t = sqrt(12 EI / EA), E = EA / t; in plane strain its bending stiffness is then
E t^3 / (12 (1 - nu^2)) = EI / (1 - nu^2), the plate stiffness a plane-strain beam of that EI has
(PLAXIS's convention). The continuum is chosen over beam elements because it bends right with two or
more quadratic elements through the thickness, takes the earth pressure on its real faces, needs no
interface between the wall's rotation and the ground's displacement, and is the element the linings
already verify (Kirsch, convergence-confinement); its section forces are integrated from its stresses.

A prop or an anchor is a connector between two *ends*, each the mean displacement along a segment: the
wall's section across its thickness at the support's depth, another wall's section, or for an anchor
the fixed (bonded) length in the ground, through which the anchor force passes evenly into the
ground; a prop to a fixed point (the symmetry plane of a half-model) has one end. With the unit vector
d from the wall end towards the other end, the connector's *shortening* (prop, compression positive)
or *elongation* (anchor, tension positive) is e = c^t u, and its axial force per metre run

    N = P + k (e - e_installed),

k its stiffness per metre run (``stiffness``, or E A / (spacing L), L the spring's length: for a prop
to the symmetry plane half the prop's length), P its preload (lock-off). Named values: ``k[name]`` and
``preload[name]`` of every prop and anchor, ``E[wall]`` and ``nu[wall]`` of every wall (a cracked
section's reduction is a factor on E[wall], so on EI and EA together).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from geoback.case.schema import Case, number_text


@dataclass(frozen=True)
class WallBand:
    """A wall as the band the mesh holds: centreline x, depths top and toe, thickness t, E and nu."""

    name: str
    x: float
    top: float
    toe: float
    thickness: float
    E: float
    nu: float
    layers: int

    @property
    def faces(self) -> tuple[float, float]:
        return (self.x - self.thickness / 2, self.x + self.thickness / 2)

    def polygon(self):
        from shapely.geometry import box

        x0, x1 = self.faces
        return box(x0, -self.toe, x1, -self.top)

    def section(self, depth: float) -> tuple[tuple[float, float], tuple[float, float]]:
        """The segment across the wall at `depth` (face to face)."""
        x0, x1 = self.faces
        return ((x0, -depth), (x1, -depth))


def wall_band(w) -> WallBand:
    """The band of a wall of the case (thickness and E, or EA and EI converted)."""
    if w.thickness is not None:
        t, E = float(w.thickness), float(w.E)
    else:
        t = math.sqrt(12.0 * float(w.EI) / float(w.EA))
        E = float(w.EA) / t
    return WallBand(w.name, float(w.x), float(w.top), float(w.toe), t, E, float(w.nu), int(w.layers))


def walls(case: Case) -> dict[str, WallBand]:
    c = case.construction
    return {w.name: wall_band(w) for w in ((c.walls or []) if c is not None else [])}


@dataclass(frozen=True)
class Connector:
    """A prop or an anchor (module docstring). `ends` are (segment, sign) pairs: the connector's e is
    sum sign * d . mean(u along segment); `far` names what the other end is ('fixed', 'wall <name>',
    'ground')."""

    name: str
    kind: str  # 'prop' or 'anchor'
    wall: str
    head: tuple[float, float]  # the wall's centreline at the support's depth
    direction: tuple[float, float]  # unit vector from the wall end towards the other end
    ends: tuple  # ((segment, sign), ...)
    far: str
    stiffness: float  # k per metre run [kN/m/m]
    preload: float  # P per metre run [kN/m]
    spacing: float | None  # of the props or anchors [m] (None: given per metre run)
    spring_length: float | None

    @property
    def force_word(self) -> str:
        return "compression" if self.kind == "prop" else "tension"

    def per_support(self) -> float:
        """Force of one prop or anchor per force per metre run (its spacing; 1 when given per metre)."""
        return self.spacing if self.spacing is not None else 1.0


def pit_side(case: Case, band: WallBand) -> float:
    """-1 if the excavation lies on the wall's left (x smaller), +1 on its right: the side of the
    openings' area next to the wall (nearest opening in x)."""
    from geoback.case.layout import polygon

    best, side = math.inf, -1.0
    for op in case.geometry.openings:
        p = polygon(op)
        c = p.centroid.x
        d = min(abs(p.bounds[0] - band.x), abs(p.bounds[2] - band.x))
        if d < best:
            best, side = d, (1.0 if c > band.x else -1.0)
    return side


def _spring(s, length: float | None) -> float:
    if s.stiffness is not None:
        return float(s.stiffness)
    return float(s.E) * float(s.area) / (float(s.spacing) * length)


def connectors(case: Case) -> dict[str, Connector]:
    """Every prop and anchor of the case, placed (the checks in ``support_problems`` passed)."""
    c = case.construction
    if c is None:
        return {}
    bands = walls(case)
    out = {p.name: _prop(case, p, bands) for p in c.props or []}
    out.update({a.name: _anchor(case, a, bands) for a in c.anchors or []})
    return out


def _prop(case: Case, p, bands: dict) -> Connector:
    w = bands[p.wall]
    head = (w.x, -p.depth)
    own = (w.section(p.depth), 1.0)
    if p.to is not None:
        other = bands[p.to]
        d = (1.0 if other.x > w.x else -1.0, 0.0)
        length = p.length or abs(other.x - w.x) - (w.thickness + other.thickness) / 2
        ends, far = (own, (other.section(p.depth), -1.0)), f"wall {p.to}"
    else:
        side = pit_side(case, w)
        d = (side, 0.0)
        face = w.x + side * w.thickness / 2
        length = (p.length / 2 if p.length else abs(face)) if case.geometry.model == "half" else p.length
        ends, far = (own,), ("the symmetry plane" if case.geometry.model == "half" else "a fixed point")
    return Connector(p.name, "prop", p.wall, head, d, ends, far, _spring(p, length), float(p.preload), p.spacing,
                     length)


def _anchor(case: Case, a, bands: dict) -> Connector:
    w = bands[a.wall]
    side = -pit_side(case, w)  # into the retained ground
    ang = math.radians(a.angle)
    d = (side * math.cos(ang), -math.sin(ang))
    head = (w.x, -a.depth)
    start = (head[0] + a.free_length * d[0], head[1] + a.free_length * d[1])
    end = (start[0] + a.fixed_length * d[0], start[1] + a.fixed_length * d[1])
    ends = ((w.section(a.depth), -1.0), ((start, end), 1.0))
    return Connector(a.name, "anchor", a.wall, head, d, ends, "ground", _spring(a, a.free_length), float(a.preload),
                     a.spacing, float(a.free_length))


# ---------------------------------------------------------------------------- checks
def support_problems(case: Case, installed: dict[str, int], excavated: dict[str, int]) -> list[tuple[tuple, str]]:
    """Checks of the walls, props and anchors: (path, message) for each problem. `installed` maps what
    stages install to the stage index; `excavated` every excavated region to its stage."""
    from shapely.geometry import LineString, Point

    from geoback.case.layout import box, regions

    c, g = case.construction, case.geometry
    at = ("construction",)
    out: list[tuple[tuple, str]] = []
    x0, x1, depth = box(g)
    regs = regions(g)
    names = [s.name for s in c.stages]
    bands: dict[str, WallBand] = {}
    seen: set[str] = set()
    taken = {ln.name for ln in (c.linings or [])}
    for j, w in enumerate(c.walls or []):
        here = at + ("walls", j)
        if w.name in taken:
            out.append((here + ("name",), f"expected names of linings, walls, props and anchors different from each "
                                          f"other, found '{w.name}' again"))
        taken.add(w.name)
        if (w.thickness is None) == (w.EA is None) or (w.thickness is None) != (w.E is None) or \
                (w.EA is None) != (w.EI is None):
            out.append((here, f"expected wall '{w.name}' given by thickness and E, or by EA and EI per metre run, "
                              f"found {', '.join(k for k in ('thickness', 'E', 'EA', 'EI') if getattr(w, k) is not None) or 'neither'}"))
            continue
        band = wall_band(w)
        if not w.toe > w.top:
            out.append((here + ("toe",), f"expected the toe below the top ({number_text(w.top)} m), found "
                                         f"{number_text(w.toe)} m"))
            continue
        if w.toe >= depth:
            out.append((here + ("toe",), f"expected the toe above the model's bottom ({number_text(depth)} m), found "
                                         f"{number_text(w.toe)} m"))
        fx0, fx1 = band.faces
        if fx0 < x0 - 1e-9 or fx1 > x1 + 1e-9 or (g.model == "half" and fx0 < 0):
            out.append((here + ("x",), f"expected wall '{w.name}' inside the model (x from {number_text(x0)} to "
                                       f"{number_text(x1)}), found it spanning x from {number_text(fx0)} to "
                                       f"{number_text(fx1)}"))
            continue
        poly = band.polygon()
        for name, (_, rp) in regs.items():
            if rp.intersection(poly).area > 1e-9 * poly.area:
                out.append((here, f"expected wall '{w.name}' outside what is excavated, found it overlapping "
                                  f"'{name}'"))
        deepest = max((-regs[r][1].bounds[1] for r in excavated if r in regs and _beside(regs[r][1], band)),
                      default=None)
        if deepest is not None and w.toe < deepest - 1e-9:
            out.append((here + ("toe",), f"expected the toe of wall '{w.name}' below the final dig beside it "
                                         f"({number_text(deepest)} m), found {number_text(w.toe)} m"))
        if w.name in installed and any(excavated.get(r, 99) < installed[w.name] for r in regs if _beside(regs[r][1], band)):
            out.append((here, f"expected wall '{w.name}' installed before the ground beside it is excavated, found it "
                              f"installed at stage '{names[installed[w.name]]}'"))
        bands[w.name] = band
    for kind in ("props", "anchors"):
        for j, s in enumerate(getattr(c, kind) or []):
            here = at + (kind, j)
            if s.name in taken:
                out.append((here + ("name",), f"expected names of linings, walls, props and anchors different from "
                                              f"each other, found '{s.name}' again"))
            taken.add(s.name)
            if s.wall not in bands:
                known = ", ".join(bands) or "none"
                out.append((here + ("wall",), f"expected the name of a wall in construction.walls ({known}), found "
                                              f"'{s.wall}'"))
                continue
            w = bands[s.wall]
            if not (w.top <= s.depth <= w.toe):
                out.append((here + ("depth",), f"expected a depth on wall '{s.wall}' (from {number_text(w.top)} to "
                                               f"{number_text(w.toe)} m), found {number_text(s.depth)} m"))
                continue
            given = s.stiffness is not None
            parts = [s.E is not None, s.area is not None, s.spacing is not None]
            if given == any(parts[:2]) or (not given and not all(parts)):
                out.append((here, f"expected the stiffness per metre run (stiffness) or E, area and spacing, found "
                                  f"{', '.join(k for k in ('stiffness', 'E', 'area', 'spacing') if getattr(s, k) is not None) or 'none of them'}"))
                continue
            if s.name not in installed:
                out.append((here, f"expected {kind[:-1]} '{s.name}' installed by a stage (install: {s.name}), found no "
                                  f"stage installing it"))
                continue
            k = installed[s.name]
            if s.wall in installed and installed[s.wall] > k:
                out.append((here + ("wall",), f"expected {kind[:-1]} '{s.name}' installed on a wall in place, found "
                                              f"wall '{s.wall}' installed later (stage '{names[installed[s.wall]]}')"))
            side = pit_side(case, w)
            face = (w.x + side * w.thickness / 2 + side * 1e-6, -s.depth)
            dug = any(rp.buffer(1e-6).contains(Point(*face)) and excavated.get(r, 99) <= k for r, (_, rp) in regs.items())
            if kind == "props" and not dug:
                out.append((here + ("depth",), f"expected prop '{s.name}' at or above the formation when it is "
                                               f"installed (in ground excavated by stage '{names[k]}'), found "
                                               f"depth {number_text(s.depth)} m not yet excavated"))
            if kind == "props":
                if s.to is not None:
                    if s.to not in bands or s.to == s.wall:
                        out.append((here + ("to",), f"expected the name of another wall ({', '.join(n for n in bands if n != s.wall) or 'none'}), "
                                                    f"found '{s.to}'"))
                    elif s.to in installed and installed[s.to] > k:
                        out.append((here + ("to",), f"expected prop '{s.name}' installed between walls in place, found "
                                                    f"wall '{s.to}' installed later"))
                elif g.model == "full" and s.stiffness is None and s.length is None:
                    out.append((here + ("length",), f"expected the prop's length (a prop to a fixed point in a full "
                                                    f"model), found none"))
            else:
                cn = _anchor(case, s, bands)
                (a, b), _ = cn.ends[1]
                line = LineString([cn.head, b])
                ground = box_polygon(case)
                if not ground.buffer(1e-9).contains(line):
                    out.append((here, f"expected anchor '{s.name}' inside the ground, found its end at "
                                      f"({number_text(round(b[0], 6))}, {number_text(round(b[1], 6))}) leaving the "
                                      f"model"))
                for r, (_, rp) in regs.items():
                    if rp.intersection(LineString([a, b])).length > 1e-9:
                        out.append((here, f"expected the fixed length of anchor '{s.name}' in ground that stays, found "
                                          f"it crossing '{r}'"))
    return out


def box_polygon(case: Case):
    from geoback.case.layout import ground_polygon

    return ground_polygon(case.geometry)


def _beside(region, band: WallBand) -> bool:
    """Does an excavated region touch the wall's face?"""
    return region.distance(band.polygon()) < 1e-6 * max(1.0, band.thickness)
