"""Physical checks of a case that pydantic cannot express field by field: the tunnel below the
surface and inside the model, layers in order, instruments in the ground and outside the
tunnel, parameters within their bounds, a mesh of sensible size. Each problem is (path, message)."""
from __future__ import annotations

import math

from geoback.case.schema import Case, Geometry, number_text


def _span(g) -> tuple[float, float]:
    """x range of the ground points may lie in (a half-model with openings takes the mirrored side too)."""
    if isinstance(g, Geometry):
        return 0.0, g.width
    return (-g.width, g.width) if g.model == "half" else (-g.width / 2, g.width / 2)


def _inside_ground(g, x: float, y: float) -> bool:
    tol = 1e-9 * max(g.width, g.depth)
    lo, hi = _span(g)
    return lo - tol <= x <= hi + tol and -g.depth - tol <= y <= tol


def _inside_tunnel(g, x: float, y: float) -> bool:
    """Inside the circular tunnel (with openings, what is excavated depends on the stage: the
    simulation refuses readings of excavated ground, located)."""
    if not isinstance(g, Geometry):
        return False
    return math.hypot(x, y + g.axis_depth) < g.radius * (1 - 1e-6)


def _segment_enters_tunnel(g, a: tuple, b: tuple) -> bool:
    """Does the straight segment a-b pass through the excavated tunnel's interior?"""
    if not isinstance(g, Geometry):
        return False
    cx, cy = 0.0, -g.axis_depth
    dx, dy = b[0] - a[0], b[1] - a[1]
    n2 = dx * dx + dy * dy
    t = 0.0 if n2 == 0 else min(1.0, max(0.0, ((cx - a[0]) * dx + (cy - a[1]) * dy) / n2))
    return math.hypot(a[0] + t * dx - cx, a[1] + t * dy - cy) < g.radius * (1 - 1e-6)


def _ground_span(g) -> str:
    lo, hi = _span(g)
    return f"x between {number_text(lo)} and {number_text(hi)}, y between {number_text(-g.depth)} and 0"


def _tunnel_text(g: Geometry) -> str:
    return f"radius {number_text(g.radius)} around (0, {number_text(-g.axis_depth)})"


def _point_problem(g: Geometry, p: tuple, what: str) -> str | None:
    x, y = p
    if not _inside_ground(g, x, y):
        return f"expected {what} inside the ground ({_ground_span(g)}), found ({number_text(x)}, {number_text(y)})"
    if _inside_tunnel(g, x, y):
        return (f"expected {what} outside the excavated tunnel ({_tunnel_text(g)}), found ({number_text(x)}, {number_text(y)}), "
                f"{number_text(math.hypot(x, y + g.axis_depth))} from the tunnel axis")
    return None


MIN_STATION_GAP = 1e-3  # m: no instrument reads two stations (or points) closer than a millimetre


def min_station_gap(g: Geometry) -> float:
    """How close two stations of one instrument may be: 1 mm, or 1e-4 of a smaller model's size (a
    laboratory model). Closer, the finite elements cannot tell them apart (the mesh's smallest elements
    are 1e-4 of the radius, and interpolation within one element gives them one reading to rounding),
    and such a gap is a unit slip (mm written as m) or a point listed twice more often than a design."""
    return min(MIN_STATION_GAP, 1e-4 * max(g.width, g.depth))


def _closest_pair(points, gap: float) -> tuple[int, int, float] | None:
    """The first two points (j < k) closer than `gap`, and their distance; None if there are none
    (buckets of size `gap`: linear in the number of points)."""
    cells: dict[tuple[int, int], list[int]] = {}
    for k, (x, y) in enumerate(points):
        cx, cy = math.floor(x / gap), math.floor(y / gap)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for j in cells.get((cx + dx, cy + dy), ()):
                    d = math.hypot(points[j][0] - x, points[j][1] - y)
                    if d < gap:
                        return j, k, d
        cells.setdefault((cx, cy), []).append(k)
    return None


def _gap_problems(g: Geometry, at: tuple, ins) -> list[tuple[tuple, str]]:
    """Stations, points or chord ends of one instrument closer than ``min_station_gap`` (located at the
    field that places them): they passed silently, 1e-9 m apart, and fitted the model to one place's
    readings counted twice or to a nanometre's slope."""
    gap = min_station_gap(g)
    why = "no instrument reads closer, and the mesh cannot tell them apart; check the unit (lengths are in metres)"
    out = []
    if ins.kind in ("points", "convergence"):
        pts = [tuple(p) for p in ins.points]
        pair = _closest_pair(pts, gap)
        if pair is not None:
            j, k, d = pair
            what = "points" if ins.kind == "points" else "chord ends"
            where = (f"at the same place as points[{j}]" if d == 0 else
                     f"{number_text(d)} m from points[{j}] ({number_text(pts[j][0])}, {number_text(pts[j][1])})")
            out.append((at + ("points", k), f"expected {what} at least {number_text(gap)} m apart, found "
                                            f"({number_text(pts[k][0])}, {number_text(pts[k][1])}) {where}: {why}, "
                                            f"and list a point once"))
    elif getattr(ins, "lengths", None) is not None:
        for j, length in enumerate(ins.lengths):
            if length < gap:
                out.append((at + ("lengths", j), f"expected stations at least {number_text(gap)} m apart, found "
                                                 f"{number_text(length)} m: {why}"))
                break
    elif getattr(ins, "spacing", None) is not None and ins.spacing < gap:
        out.append((at + ("spacing",), f"expected stations at least {number_text(gap)} m apart, found spacing "
                                       f"{number_text(ins.spacing)} m: {why}"))
    return out


def _instrument_problems(g: Geometry, i: int, ins, at: tuple | None = None) -> list[tuple[tuple, str]]:
    at, out = at or ("instruments", i), []
    out.extend(_gap_problems(g, at, ins))
    if ins.kind == "points":
        for j, p in enumerate(ins.points):
            why = _point_problem(g, p, "a point")
            if why:
                out.append((at + ("points", j), why))
    elif ins.kind == "convergence":
        for j, p in enumerate(ins.points):
            why = _point_problem(g, p, "a chord end")
            if why:
                out.append((at + ("points", j), why))
    elif ins.kind == "inclinometer":
        if not _inside_ground(g, ins.x, 0.0):
            out.append((at + ("x",), f"expected the borehole inside the ground ({_ground_span(g)}), "
                                     f"found x {number_text(ins.x)}"))
        elif ins.toe_depth <= ins.head_depth:
            out.append((at + ("toe_depth",), f"expected the toe deeper than the head (head_depth "
                                             f"{number_text(ins.head_depth)}), found toe_depth {number_text(ins.toe_depth)}"))
        elif ins.toe_depth > g.depth * (1 + 1e-9):
            out.append((at + ("toe_depth",), f"expected the toe inside the ground (depth at most the model's "
                                             f"depth {number_text(g.depth)}), found toe_depth {number_text(ins.toe_depth)}"))
        elif _segment_enters_tunnel(g, (ins.x, -ins.head_depth), (ins.x, -ins.toe_depth)):
            out.append((at + ("x",), f"expected the borehole to miss the excavated tunnel ({_tunnel_text(g)}), "
                                     f"found it passing through the tunnel at x {number_text(ins.x)} between depths "
                                     f"{number_text(ins.head_depth)} and {number_text(ins.toe_depth)}"))
    else:  # sliding micrometer, extensometer, deflectometer
        for end in ("start", "end"):
            why = _point_problem(g, getattr(ins, end), f"the line's {end}")
            if why:
                out.append((at + (end,), why))
                return out
        if tuple(ins.start) == tuple(ins.end):
            out.append((at + ("end",), f"expected an end different from the start, found the same point "
                                       f"({number_text(ins.end[0])}, {number_text(ins.end[1])})"))
        elif _segment_enters_tunnel(g, ins.start, ins.end):
            out.append((at + ("end",), f"expected the measuring line to miss the excavated tunnel "
                                       f"({_tunnel_text(g)}), found the line from ({number_text(ins.start[0])}, "
                                       f"{number_text(ins.start[1])}) to ({number_text(ins.end[0])}, {number_text(ins.end[1])}) "
                                       f"passing through it"))
    return out


MAX_RADIUS = 1e3  # m: gmsh's geometry kernel fails on larger tunnels (and none is that large)
MAX_SIZE = 1e5  # m: width and depth of the model
MAX_STATIONS = 2_000  # stations per instrument: its covariance matrix is dense


def _line_length(ins) -> float:
    if ins.kind == "inclinometer":
        return ins.toe_depth - ins.head_depth
    return math.hypot(ins.end[0] - ins.start[0], ins.end[1] - ins.start[1])


def _station_count(ins) -> tuple[int, str]:
    """Number of stations of a linewise instrument and the field that sets it."""
    if ins.lengths is not None:
        return len(ins.lengths), "lengths"
    if ins.stations is not None:
        return ins.stations, "stations"
    return max(int(math.floor(_line_length(ins) / ins.spacing + 1e-9)), 1), "spacing"


def _covariance_problem(ins) -> tuple[str, str] | None:
    """A reading covariance that cannot be factorised (sigma's square underflows, or the
    integration constants' variances swamp it): (field, message)."""
    s2 = ins.sigma * ins.sigma  # (** would raise OverflowError)
    if not (s2 > 0 and math.isfinite(s2) and math.isfinite(1.0 / s2)):
        return "sigma", (f"expected a standard deviation whose square is a usable number (between about "
                         f"1e-150 and 1e150), found {number_text(ins.sigma)}")
    if ins.kind not in ("inclinometer", "sliding_micrometer", "extensometer", "deflectometer"):
        return None
    from geoback.case import covariance as cov  # numpy only; no geoback imports

    kind = cov.normalise_kind(ins.kind)
    variances = {n: getattr(ins, f"var_{n.lower()}") for n in cov.constant_names(kind)}
    try:
        n, _ = _station_count(ins)
        lengths = cov.station_lengths(lengths=ins.lengths) if ins.lengths is not None else \
            cov.station_lengths(stations=n, spacing=ins.spacing)
        C = cov.instrument_covariance(kind, lengths, ins.sigma, variances)
        cov.cholesky_factor(C, ins.name)
    except cov.NotPositiveDefinite as exc:
        big = ", ".join(f"var_{k.lower()} {number_text(v)}" for k, v in variances.items() if v)
        return "sigma", (f"expected sigma {number_text(ins.sigma)}" + (f" and {big}" if big else "")
                         + f" to give a positive-definite reading covariance, found it singular ({exc})")
    except ValueError:
        return None  # reported with its context when the instrument is built
    return None


def mesh_size_problem(case: Case, allow_large: bool = False) -> tuple[tuple, str] | None:
    """(path, message) when the case's mesh is estimated beyond the limit (geoback.case.meshsize)."""
    from geoback.case.meshsize import Work, mesh_inputs, size_problem

    settings = {f: getattr(case.mesh, f) for f in ("size_tunnel", "size_far", "size_instruments")}
    found = size_problem(mesh_inputs(case), allow_large=allow_large, settings=settings, work=Work.of(case))
    return (("mesh", found[0]), found[1]) if found else None


def physical_problems(case: Case, allow_large: bool = False) -> list[tuple[tuple, str]]:
    """Checks pydantic cannot express field by field: (path, message) for each problem. The mesh
    size is estimated (geoback.case.meshsize) and refused beyond the default limit unless `allow_large`."""
    g, problems = case.geometry, []
    if not isinstance(g, Geometry):
        return _section_problems(case, allow_large)
    if g.axis_depth - g.radius <= 0:
        problems.append((("geometry", "axis_depth"),
                         f"expected the tunnel below the surface (axis_depth greater than the radius "
                         f"{number_text(g.radius)}), found axis_depth {number_text(g.axis_depth)}: the tunnel reaches above the surface"))
    if g.radius >= g.width:
        problems.append((("geometry", "width"),
                         f"expected the half-model wider than the tunnel (width greater than the radius "
                         f"{number_text(g.radius)}), found width {number_text(g.width)}: the tunnel is wider than the domain"))
    if g.axis_depth + g.radius >= g.depth:
        problems.append((("geometry", "depth"),
                         f"expected the model's bottom below the tunnel's invert (depth greater than "
                         f"axis_depth + radius = {number_text(g.axis_depth + g.radius)}), found depth {number_text(g.depth)}"))
    for field, value, cap in (("radius", g.radius, MAX_RADIUS), ("width", g.width, MAX_SIZE),
                              ("depth", g.depth, MAX_SIZE)):
        if value > cap:
            problems.append((("geometry", field), f"expected at most {cap:g} m (lengths are in metres), "
                                                  f"found {field} {number_text(value)}"))
    if g.radius < 1e-5 * max(g.width, g.depth) * (1 - 1e-9):
        problems.append((("geometry", "radius"),
                         f"expected a radius of at least 1e-5 times the model's size ({number_text(1e-5 * max(g.width, g.depth))}), "
                         f"found {number_text(g.radius)}: the mesher cannot resolve a tunnel that small"))
    problems.extend(_layer_problems(case))
    for i, layer in enumerate(case.ground.layers):
        if layer.unit_weight is not None and layer.unit_weight != case.ground.unit_weight:
            problems.append((("ground", "layers", i, "unit_weight"),
                             "expected one unit weight (ground.unit_weight) for a circular tunnel's geometry (radius, "
                             "axis_depth): layers with their own unit weight need the geometry with openings, found "
                             f"{number_text(layer.unit_weight)}"))
    problems.extend(_instrument_and_mesh_problems(case, allow_large))
    problems.extend(_rest_problems(case))
    return problems


def _layer_problems(case: Case) -> list[tuple[tuple, str]]:
    g, problems = case.geometry, []
    layers = case.ground.layers
    if layers[0].top != 0:
        problems.append((("ground", "layers", 0, "top"),
                         f"expected the first layer to start at the surface (top: 0), found top {number_text(layers[0].top)}"))
    for i in range(1, len(layers)):
        if layers[i].top <= layers[i - 1].top:
            problems.append((("ground", "layers", i, "top"),
                             f"expected layer tops increasing downwards (greater than the previous top "
                             f"{number_text(layers[i - 1].top)}), found top {number_text(layers[i].top)}"))
        elif layers[i].top >= g.depth:
            problems.append((("ground", "layers", i, "top"),
                             f"expected the layer's top above the model's bottom (less than depth {number_text(g.depth)}), "
                             f"found top {number_text(layers[i].top)}"))
        elif min(layers[i].top - layers[i - 1].top, g.depth - layers[i].top) < 1e-6 * g.depth:
            problems.append((("ground", "layers", i, "top"),
                             f"expected layers at least {number_text(1e-6 * g.depth)} thick (1e-6 of the model's depth), "
                             f"found top {number_text(layers[i].top)} within that of the next boundary"))
    names = [layer.name for layer in layers]
    for i, n in enumerate(names):
        if names.index(n) != i:
            problems.append((("ground", "layers", i, "name"),
                             f"expected unique layer names, found '{n}' again (as in ground.layers[{names.index(n)}])"))
    for i, layer in enumerate(layers):
        if layer.K0 is None and case.ground.K0 is None:
            problems.append((("ground", "layers", i, "K0"),
                             "expected a K0 for this layer (or ground.K0 for all layers), found none"))
    return problems


def _section_problems(case: Case, allow_large: bool) -> list[tuple[tuple, str]]:
    """Checks of a case with openings (``layout.py``, ``sequence.py``) and of what it shares with the
    circular tunnel (layers, instruments' stations, parameters, forecasts)."""
    from geoback.case.layout import layout_problems
    from geoback.case.sequence import sequence_problems

    g, problems = case.geometry, []
    for field, value in (("width", g.width), ("depth", g.depth)):
        if value > MAX_SIZE:
            problems.append((("geometry", field), f"expected at most {MAX_SIZE:g} m (lengths are in metres), "
                                                  f"found {field} {number_text(value)}"))
    problems.extend(_layer_problems(case))
    if problems:
        return problems
    problems.extend(layout_problems(case))
    if problems:
        return problems
    problems.extend(sequence_problems(case))
    problems.extend(_instrument_list_problems(case))
    problems.extend(_rest_problems(case, construction=False))
    if not problems:  # the size of the section's mesh, estimated from its size field before gmsh runs
        big = mesh_size_problem(case, allow_large)
        if big:
            problems.append(big)
    return problems


def _instrument_list_problems(case: Case) -> list[tuple[tuple, str]]:
    """Instruments of any geometry: unique names, points in the ground, stations, covariance."""
    g, problems = case.geometry, []
    inames = [ins.name for ins in case.instruments]
    for i, n in enumerate(inames):
        if inames.index(n) != i:
            problems.append((("instruments", i, "name"),
                             f"expected unique instrument names, found '{n}' again (as in instruments[{inames.index(n)}])"))
    c = case.construction
    supports = [x.name for x in ((c.props or []) + (c.anchors or []) if c is not None and hasattr(c, "props") else [])]
    for i, ins in enumerate(case.instruments):
        if ins.kind == "load_cell":
            if ins.support not in supports:
                problems.append((("instruments", i, "support"),
                                 f"expected the name of a prop or anchor in construction.props or construction.anchors "
                                 f"({', '.join(supports) or 'none in this case'}), found '{ins.support}'"))
            continue
        problems.extend(_instrument_problems(g, i, ins))
        if ins.kind in ("inclinometer", "sliding_micrometer", "extensometer", "deflectometer"):
            n, field = _station_count(ins)
            if n > MAX_STATIONS:
                problems.append((("instruments", i, field),
                                 f"expected at most {MAX_STATIONS} stations, found {n}"))
                continue
            length = _line_length(ins)
            reach = sum(ins.lengths) if ins.lengths is not None else n * ins.spacing
            if reach > length * (1 + 1e-9):
                problems.append((("instruments", i, field),
                                 f"expected the stations within the instrument's length {number_text(length)} m, found "
                                 f"them reaching {number_text(reach)} m from the reference end"))
                continue
        bad = _covariance_problem(ins)
        if bad:
            problems.append((("instruments", i, bad[0]), bad[1]))
    return problems


def _instrument_and_mesh_problems(case: Case, allow_large: bool) -> list[tuple[tuple, str]]:
    g = case.geometry
    problems = _instrument_list_problems(case)
    for field in ("size_tunnel", "size_far", "size_instruments"):
        size = getattr(case.mesh, field)
        if size is not None and size < 1e-4 * g.radius:
            problems.append((("mesh", field), f"expected an element size of at least 1e-4 times the radius "
                                              f"({number_text(1e-4 * g.radius)}), found {number_text(size)}"))
    if case.mesh.size_tunnel is not None and case.mesh.size_tunnel > g.radius:
        problems.append((("mesh", "size_tunnel"),
                         f"expected an element size at the wall of at most the radius {number_text(g.radius)} "
                         f"(else the tunnel is not round), found {number_text(case.mesh.size_tunnel)}"))
    big = mesh_size_problem(case, allow_large)
    if big:
        problems.append(big)
    return problems


def _rest_problems(case: Case, construction: bool = True) -> list[tuple[tuple, str]]:
    """Parameters, strength, construction (circular), error scales, forecasts and the design."""
    problems = []
    for i, p in enumerate(case.parameters):
        if p.bounds is not None:
            lo, hi = p.bounds
            if not lo < hi:
                problems.append((("parameters", i, "bounds"),
                                 f"expected a lower bound below the upper bound, found [{number_text(lo)}, {number_text(hi)}]"))
            elif not lo <= p.initial <= hi:
                problems.append((("parameters", i, "initial"),
                                 f"expected an initial value within the bounds [{number_text(lo)}, {number_text(hi)}], "
                                 f"found {number_text(p.initial)} (outside the bounds)"))
            if p.log and lo <= 0:
                problems.append((("parameters", i, "bounds"),
                                 f"expected positive bounds for a log-transformed parameter, found lower bound {number_text(lo)}"))
        if p.log and p.initial <= 0:
            problems.append((("parameters", i, "initial"),
                             f"expected a positive initial value for a log-transformed parameter, found {number_text(p.initial)}"))
    from geoback.case.construction import construction_problems
    from geoback.case.strength import strength_problems

    problems.extend(strength_problems(case))
    if construction:
        problems.extend(construction_problems(case))
    pnames = [p.name for p in case.parameters]
    for i, n in enumerate(pnames):
        if pnames.index(n) != i:
            problems.append((("parameters", i, "name"),
                             f"expected each parameter once, found '{n}' again (as in parameters[{pnames.index(n)}])"))
    problems.extend(_error_scale_problems(case))
    from geoback.case.timeline import timeline_problems

    problems.extend(timeline_problems(case))
    problems.extend(forecast_problems(case))
    problems.extend(design_problems(case))
    problems.extend(trough_problems(case))
    problems.extend(building_problems(case))
    return problems


def _model_span(g) -> tuple[float, float, str]:
    """x range a building or a trough's axis may lie in: a half-model mirrored about its symmetry axis."""
    if isinstance(g, Geometry) or g.model == "half":
        return -g.width, g.width, "the half-model mirrored about its symmetry axis"
    return -g.width / 2, g.width / 2, "the full model's width"


def building_problems(case: Case) -> list[tuple[tuple, str]]:
    """Buildings (``worth.damage``) lie on the model: within its width, their foundation above its
    bottom and outside the tunnel, assessed at a stage of the case; names unique."""
    from geoback.case.construction import stage_names

    g, out = case.geometry, []
    lo, hi, words = _model_span(g)
    tol = 1e-9 * max(g.width, g.depth)
    stages = stage_names(case)
    names = [b.name for b in case.buildings]
    for i, b in enumerate(case.buildings):
        at = ("buildings", i)
        if names.index(b.name) != i:
            out.append((at + ("name",), f"expected unique building names, found '{b.name}' again "
                                        f"(as in buildings[{names.index(b.name)}])"))
        end = b.x_start + b.length
        if not lo - tol <= b.x_start <= hi + tol:
            out.append((at + ("x_start",), f"expected the building's start within the model (x between "
                                           f"{number_text(lo)} and {number_text(hi)} m, {words}), found x_start "
                                           f"{number_text(b.x_start)}: the building lies outside the model"))
        elif end > hi + tol:
            out.append((at + ("length",), f"expected the building within the model (x_start + length at most "
                                          f"{number_text(hi)} m, {words}), found length {number_text(b.length)}: its "
                                          f"end at x = {number_text(end)} m is beyond the model"))
        if b.foundation_depth >= g.depth - tol:
            out.append((at + ("foundation_depth",), f"expected a foundation above the model's bottom (depth less "
                                                    f"than {number_text(g.depth)} m), found foundation_depth "
                                                    f"{number_text(b.foundation_depth)}: deeper than the model"))
        elif isinstance(g, Geometry) and abs(b.foundation_depth - g.axis_depth) < g.radius:
            half = math.sqrt(g.radius ** 2 - (b.foundation_depth - g.axis_depth) ** 2)
            if b.x_start < half and end > -half:
                out.append((at + ("foundation_depth",), f"expected the foundation outside the excavated tunnel "
                                                        f"({_tunnel_text(g)}), found foundation_depth "
                                                        f"{number_text(b.foundation_depth)} across it"))
        if b.stage is not None and b.stage not in stages:
            out.append((at + ("stage",), f"expected one of the construction stages ({', '.join(stages)}), "
                                         f"found '{b.stage}'"))
    return out


def trough_problems(case: Case) -> list[tuple[tuple, str]]:
    """`trough:` names settlement-point instruments reading u_y at the surface, stages of the case and
    an axis within the model."""
    from geoback.case.construction import stage_names

    t = case.trough
    if t is None:
        return []
    g, out = case.geometry, []
    by_name = {ins.name: ins for ins in case.instruments}
    for j, n in enumerate(t.instruments or []):
        ins = by_name.get(n)
        if ins is None:
            out.append((("trough", "instruments", j), f"expected the name of an instrument of the case "
                                                      f"({', '.join(by_name) or 'none'}), found '{n}'"))
        elif ins.kind != "points" or "uy" not in ins.components or not any(abs(p[1]) <= 1e-6 for p in ins.points):
            out.append((("trough", "instruments", j), f"expected settlement points (kind points, reading uy, at "
                                                      f"the ground surface y = 0), found {ins.kind} '{n}'"
                                                      + (" without surface points reading uy"
                                                         if ins.kind == "points" else "")))
    stages = stage_names(case)
    for j, st in enumerate(t.stages or []):
        if st not in stages:
            out.append((("trough", "stages", j), f"expected one of the construction stages ({', '.join(stages)}), "
                                                 f"found '{st}'"))
    if t.axis_x is not None:
        lo, hi, words = _model_span(g)
        if not lo <= t.axis_x <= hi:
            out.append((("trough", "axis_x"), f"expected the axis within the model (x between {number_text(lo)} and "
                                              f"{number_text(hi)} m), found {number_text(t.axis_x)}"))
    return out


def expand_candidates(design) -> list[tuple[int, object]]:
    """(index in design.candidates, instrument) for every candidate, one per value of its `vary`
    field (named e.g. 'I2-x6', or 'S2-3' for the third of other values); a variant that does not validate raises ValueError."""
    out = []
    for i, c in enumerate(design.candidates):
        if not c.vary:
            out.append((i, c))
            continue
        (field, values), = c.vary.items()
        base = c.model_dump(exclude={"vary"})
        for k, v in enumerate(values):
            variant = type(c).model_validate({**base, field: v})
            value = getattr(variant, field)  # as validated: a quoted '4.5' is named as 4.5 is
            number = isinstance(value, (int, float)) and not isinstance(value, bool)
            name = f"{c.name}-{field}{number_text(value)}" if number else f"{c.name}-{k + 1}"
            out.append((i, type(c).model_validate({**base, field: value, "name": name})))
    return out


READINGS_OPTIONS = ("stage", "columns", "ignore_columns", "point_ids", "sign")  # how readings are read


def _variant_problems(case: Case) -> list[tuple[tuple, str]]:
    """A `vary` value that makes no valid candidate, located at the value (design.candidates[i].vary.x[k],
    and within it) in the words the case's own fields get: it was "design.candidates: ... points.0.0:
    Value error, expected a finite number ..." (pydantic's wording, the value's place lost). The first
    bad value of each candidate."""
    from pydantic import ValidationError

    from geoback.case.messages import described_problems

    out, full = [], None
    for i, c in enumerate(case.design.candidates):
        if not c.vary:
            continue
        (field, values), = c.vary.items()
        base = c.model_dump(exclude={"vary"})
        for k, v in enumerate(values):
            variant = {**base, field: v}
            try:
                type(c).model_validate(variant)
            except ValidationError as exc:
                if full is None:
                    full = case.model_dump()
                data = {**full, "design": {**full["design"], "candidates": [
                    variant if j == i else cand for j, cand in enumerate(full["design"]["candidates"])]}}
                at = ("design", "candidates", i)
                errors = [{**e, "loc": at + (c.kind,) + tuple(e["loc"])} for e in exc.errors()]  # as in the case
                where, message = described_problems(errors, data, {})[0]
                if where[:4] == at + (field,):
                    where = at + ("vary", field, k) + where[4:]
                out.append((where, message))
                break
    return out


def design_problems(case: Case) -> list[tuple[tuple, str]]:
    """Candidates without readings, at known stages, in the ground; `vary` one field of theirs;
    targets that are forecasts of the case."""
    from geoback.case.construction import stage_names

    d = case.design
    if d is None:
        return []
    out, g, stages = [], case.geometry, stage_names(case)
    forecasts = [f.name for f in case.forecasts]
    for j, name in enumerate(d.forecasts or []):
        if name not in forecasts:
            out.append((("design", "forecasts", j), f"expected the name of a forecast of the case "
                                                    f"({', '.join(forecasts) or 'none'}), found '{name}'"))
    if d.objective == "forecasts" and not forecasts:
        out.append((("design", "objective"), "expected forecasts in the case for objective 'forecasts' (or "
                                             "objective: parameters), found none"))
    for i, c in enumerate(d.candidates):
        at = ("design", "candidates", i)
        if c.readings is not None or c.readings_file is not None:
            out.append((at + ("readings" if c.readings is not None else "readings_file",),
                        "expected no readings for a candidate instrument (not installed yet), found some"))
        for name in READINGS_OPTIONS:
            if getattr(c, name, None) is not None:
                out.append((at + (name,), f"expected no readings options for a candidate instrument (not "
                                          f"installed yet), found {name}"))
        if c.read_at is not None and c.read_at not in stages:
            out.append((at + ("read_at",), f"expected one of the construction stages ({', '.join(stages)}), "
                                           f"found '{c.read_at}'"))
        if c.vary is not None:
            fields = set(type(c).model_fields) - {"name", "kind", "vary", "read_at", "readings", "readings_file",
                                                  *READINGS_OPTIONS}
            if len(c.vary) != 1:
                out.append((at + ("vary",), f"expected one field to vary, found {len(c.vary)}"))
                continue
            (field, values), = c.vary.items()
            if field not in fields:
                out.append((at + ("vary",), f"expected one of the {c.kind}'s fields ({', '.join(sorted(fields))}), "
                                            f"found '{field}'"))
                continue
            if not values:
                out.append((at + ("vary", field), "expected at least one value, found an empty list []"))
                continue
    if out:
        return out
    out = _variant_problems(case)
    if out:
        return out
    expanded = expand_candidates(d)
    names = [c.name for _, c in expanded] + [ins.name for ins in case.instruments]
    for i, c in expanded:
        if names.count(c.name) > 1:
            out.append((("design", "candidates", i, "name"), f"expected candidate names different from each other "
                                                             f"and from the instruments', found '{c.name}' twice"))
        for path, why in _instrument_problems(g, i, c, ("design", "candidates", i)):
            out.append((path, f"{c.name}: {why}"))
    return out


def line_points(start, end, count: int) -> list[tuple[float, float]]:
    """`count` evenly spaced points from `start` to `end` (a line forecast's points)."""
    return [(start[0] + (end[0] - start[0]) * k / (count - 1), start[1] + (end[1] - start[1]) * k / (count - 1))
            for k in range(count)]


def forecast_problems(case: Case) -> list[tuple[tuple, str]]:
    """Forecasts name known stages and instruments, lie in the ground and outside the tunnel, and
    ask for the lining only where there is one."""
    from geoback.case.construction import stage_names

    g, out = case.geometry, []
    stages = stage_names(case)
    names = [f.name for f in case.forecasts]
    instruments = [ins.name for ins in case.instruments]
    lining = case.construction.lining if case.construction is not None else None
    installed = next((k for k, s in enumerate(case.construction.stages) if s.install is not None), None) \
        if case.construction is not None else None
    for i, f in enumerate(case.forecasts):
        at = ("forecasts", i)
        if names.index(f.name) != i:
            out.append((at + ("name",), f"expected unique forecast names, found '{f.name}' again "
                                        f"(as in forecasts[{names.index(f.name)}])"))
        if f.stage is not None and f.stage not in stages:
            out.append((at + ("stage",), f"expected one of the construction stages ({', '.join(stages)}), "
                                         f"found '{f.stage}'"))
            continue
        stage = stages.index(f.stage) if f.stage is not None else len(stages) - 1
        if f.kind in ("points", "convergence"):
            for j, p in enumerate(f.points):
                why = _point_problem(g, p, "a point" if f.kind == "points" else "a chord end")
                if why:
                    out.append((at + ("points", j), why))
            if f.kind == "convergence" and len(f.points) == 2 and tuple(f.points[0]) == tuple(f.points[1]):
                out.append((at + ("points",), f"expected a chord between two distinct points, found both at "
                                              f"({number_text(f.points[0][0])}, {number_text(f.points[0][1])})"))
            elif f.kind == "convergence":
                out.extend(_gap_problems(g, at, f))
        elif f.kind == "line":
            for key, p in (("start", f.start), ("end", f.end)):
                why = _point_problem(g, p, f"the line's {key}")
                if why:
                    out.append((at + (key,), why))
            if all(_point_problem(g, p, "") is None for p in (f.start, f.end)):
                inside = [p for p in line_points(f.start, f.end, f.points) if _point_problem(g, p, "") is not None]
                if inside:
                    out.append((at + ("points",), f"expected the line's points outside the excavated tunnel "
                                                  f"({_tunnel_text(g)}), found {len(inside)} of {f.points} inside it, "
                                                  f"e.g. ({number_text(inside[0][0])}, {number_text(inside[0][1])})"))
        elif f.kind == "instrument" and f.instrument not in instruments:
            out.append((at + ("instrument",), f"expected the name of an instrument of the case "
                                              f"({', '.join(instruments) or 'none'}), found '{f.instrument}'"))
        elif f.kind in ("support", "wall"):
            out.extend(_structure_forecast_problem(case, at, f, stages, stage))
        elif f.kind == "lining":
            if lining is None:
                out.append((at + ("kind",), "expected a case with a lining (construction.lining) for a lining "
                                            "forecast, found none"))
            elif installed is None or stage < installed:
                out.append((at + ("stage",), f"expected a stage at or after the lining's installation "
                                             f"({stages[installed] if installed is not None else 'never installed'}), "
                                             f"found '{stages[stage]}'"))
    return out


def _structure_forecast_problem(case: Case, at: tuple, f, stages: list[str], stage: int) -> list[tuple[tuple, str]]:
    """A support or wall forecast names a prop, anchor or wall of the case, at or after its installation."""
    c = case.construction
    walls = [w.name for w in (getattr(c, "walls", None) or [])] if c is not None else []
    if not walls:
        return [(at + ("kind",), f"expected a case with retaining walls (construction.walls) for a {f.kind} forecast, "
                                 "found none")]
    if f.kind == "support":
        known = [s.name for s in (c.props or []) + (c.anchors or [])]
        name, field, what = f.support, "support", "a prop or anchor (construction.props, construction.anchors)"
    else:
        known, name, field, what = walls, f.wall, "wall", "a wall (construction.walls)"
    if name not in known:
        return [(at + (field,), f"expected the name of {what}: {', '.join(known) or 'none'}; found '{name}'")]
    installs = [k for k, s in enumerate(c.stages)
                if name in ([s.install] if isinstance(s.install, str) else (s.install or []))]
    if installs and stage < installs[0]:
        return [(at + ("stage",), f"expected a stage at or after {field} '{name}' is installed "
                                  f"('{stages[installs[0]]}'), found '{stages[stage]}'")]
    return []


def _reading_count(ins) -> int:
    """Number of readings an instrument gives (stations, point components, one chord)."""
    if ins.kind == "points":
        return len(ins.points) * len(ins.components)
    if ins.kind == "convergence":
        return 1
    return _station_count(ins)[0]


def _error_scale_problems(case: Case) -> list[tuple[tuple, str]]:
    """error_scales: known instruments with readings, each in one group, group names unique, and
    enough readings to estimate a scale that has no prior."""
    out: list[tuple[tuple, str]] = []
    by_name = {ins.name: ins for ins in case.instruments}
    known = ", ".join(by_name) or "none"
    seen: dict[str, int] = {}
    names: dict[str, int] = {}
    for i, entry in enumerate(case.error_scales):
        at = ("error_scales", i)
        for j, name in enumerate(entry.instruments):
            ins = by_name.get(name)
            if ins is None:
                out.append((at + ("instruments", j), f"expected the name of an instrument of the case ({known}), "
                                                     f"found '{name}'"))
            elif name in seen:
                out.append((at + ("instruments", j), f"expected each instrument in one error_scales entry, found "
                                                     f"'{name}' again (as in error_scales[{seen[name]}])"))
            elif ins.readings is None and ins.readings_file is None:
                out.append((at + ("instruments", j), f"expected an instrument with readings (a scale is estimated "
                                                     f"from them), found '{name}' without readings or readings_file"))
            seen.setdefault(name, i)
        group = entry.name or "+".join(entry.instruments)
        clash = group in by_name and group not in entry.instruments
        if group in names or clash:
            out.append((at + ("name",) if entry.name else at + ("instruments",),
                        f"expected a group name used once and not naming another instrument, found '{group}' "
                        + (f"again (as in error_scales[{names[group]}])" if group in names else
                           "(the name of an instrument outside the group)")))
        names.setdefault(group, i)
        if entry.scale == "estimate" and entry.prior is None:
            count = sum(_reading_count(by_name[n]) for n in set(entry.instruments) if n in by_name)
            if 0 < count < 2:
                out.append((at + ("scale",), f"expected at least 2 readings to estimate a scale without a prior, "
                                             f"found {count} (give it a prior, or scale: known)"))
    return out
