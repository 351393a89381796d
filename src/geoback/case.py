"""The case file: YAML -> validated pydantic models, with file:line:column on every error.

Units are SI throughout: lengths in m, stresses and moduli in kPa (a string such as
``"10 MPa"`` is also accepted for a modulus), unit weight in kN/m³, angles in rad.
Coordinates are those of the half-model: symmetry axis x = 0, ground surface y = 0, y up
(depth = -y).
"""
from __future__ import annotations

import difflib
import hashlib
import json
import math
import re
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import (BaseModel, BeforeValidator, ConfigDict, Field, ValidationError,
                      model_validator)

from .errors import CaseError
from .yamlmarks import format_path, load_yaml_with_marks, locate, printable

_UNITS = {"pa": 1e-3, "kpa": 1.0, "mpa": 1e3, "gpa": 1e6}


def _show(value: Any) -> str:
    """A found value, shown as it would read in the file."""
    if value is None:
        return "nothing (an empty value)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return ".nan (not a number)"
        if math.isinf(value):
            return "infinity" if value > 0 else "minus infinity"
        return f"{value:g}"
    if isinstance(value, int):
        text = str(value)
        return text if len(text) <= 20 else f"a {len(text)}-digit number"
    if isinstance(value, str):
        text = value if len(value) <= 50 else value[:47] + "..."
        return "an empty string" if not value else repr(text)
    if isinstance(value, dict):
        keys = ", ".join(printable(k) for k in list(value)[:6]) + (", ..." if len(value) > 6 else "")
        return f"a mapping ({keys})" if value else "an empty mapping {}"
    if isinstance(value, (list, tuple)):
        if not value:
            return "an empty list []"
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    return type(value).__name__


def _number(value: Any) -> Any:
    """Numbers only: reject true/false (YAML's yes/no), NaN, infinities and overflowing integers."""
    if isinstance(value, bool):
        raise ValueError(f"expected a number, found {_show(value)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"expected a finite number, found {_show(value)}")
    if isinstance(value, int) and abs(value) > 1e300:
        raise ValueError(f"expected a finite number, found {_show(value)}")
    return value


def _flag(value: Any) -> Any:
    if not isinstance(value, bool):
        raise ValueError(f"expected true or false, found {_show(value)}")
    return value


def _whole(value: Any) -> Any:
    if isinstance(value, bool):
        raise ValueError(f"expected a whole number, found {_show(value)}")
    return value


def _stress(value: Any) -> Any:
    """Accept numbers (kPa) or strings with an explicit unit: '10 MPa', '2e4 kPa'."""
    if isinstance(value, str):
        m = re.fullmatch(r"\s*([-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?)\s*([A-Za-z/]+)?\s*", value)
        if not m:
            raise ValueError(f"expected a stress: a number in kPa or a number with a unit like '10 MPa', "
                             f"found {_show(value)}")
        if m.group(2) and m.group(2).lower() not in _UNITS:
            raise ValueError(f"expected a unit Pa, kPa, MPa or GPa after the number, found '{m.group(2)}' "
                             f"in {_show(value)}")
        number = float(m.group(1)) * _UNITS[(m.group(2) or "kpa").lower()]
        if not math.isfinite(number):
            raise ValueError(f"expected a finite stress, found {_show(value)}")
        return number
    return _number(value)


Stress = Annotated[float, BeforeValidator(_stress)]
Num = Annotated[float, BeforeValidator(_number)]
Positive = Annotated[float, BeforeValidator(_number), Field(gt=0)]
NonNegative = Annotated[float, BeforeValidator(_number), Field(ge=0)]
Count = Annotated[int, BeforeValidator(_whole)]
Point = tuple[Num, Num]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Geometry(Strict):
    """Half-model of a circular tunnel: x from 0 (symmetry axis) to `width`, y from -`depth` to 0."""

    radius: Positive = Field(description="tunnel radius R [m]")
    axis_depth: Positive = Field(description="depth of the tunnel axis below the surface [m]")
    width: Positive = Field(description="width of the half-model (symmetry axis to far side) [m]")
    depth: Positive = Field(description="depth of the model's bottom boundary below the surface [m]")


class Layer(Strict):
    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$", description="layer name (letters, digits, _ -)")
    top: NonNegative = Field(description="depth of the layer's top [m]; the first layer starts at 0")
    E: Stress = Field(gt=0, description="Young's modulus [kPa] (or '10 MPa')")
    nu: Num = Field(ge=0.0, lt=0.5, description="Poisson's ratio, 0 <= nu < 0.5")
    K0: Optional[Positive] = Field(None, description="coefficient of earth pressure at rest of this layer")


class Ground(Strict):
    unit_weight: Positive = Field(description="unit weight gamma [kN/m3]; sigma_v = -gamma*depth")
    K0: Optional[Positive] = Field(None, description="K0 of all layers (unless a layer gives its own)")
    layers: list[Layer] = Field(min_length=1)


class MeshSettings(Strict):
    size_tunnel: Optional[Positive] = Field(None, description="element size at the tunnel wall [m] (default R/8)")
    size_far: Optional[Positive] = Field(None, description="element size far from the tunnel [m] (default domain/12)")
    size_instruments: Optional[Positive] = Field(None, description="element size along instruments [m] (default: no refinement)")
    order: Annotated[Literal[1, 2], BeforeValidator(_whole)] = Field(2, description="element order: 2 = quadratic triangles")
    growth: Annotated[float, BeforeValidator(_number), Field(gt=0.01, le=2.0)] = Field(
        0.25, description="element size grows by this fraction of the distance from the tunnel (and instruments)")


class _Instrument(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_\-.]+$", description="unique instrument name")
    readings: Optional[list[Num]] = Field(None, description="measured values in station order")
    readings_file: Optional[str] = Field(None, description="CSV file with the readings (relative to the case file)")


class PointsInstrument(_Instrument):
    """Settlement points, prisms: chosen displacement components at listed points."""

    kind: Literal["points"]
    points: list[Point] = Field(min_length=1, description="[x, y] of each point [m]")
    components: list[Literal["ux", "uy"]] = Field(["ux", "uy"], min_length=1)
    sigma: Positive = Field(description="standard deviation of each reading [m]")


class _Linewise(_Instrument):
    spacing: Optional[Positive] = Field(None, description="equal distance between stations [m]")
    stations: Optional[Count] = Field(None, gt=0, description="number of stations (with spacing)")
    lengths: Optional[list[Positive]] = Field(None, min_length=1,
                                              description="distances l_1..l_n between stations from the reference end [m]")
    reading_type: Literal["displacement", "primary"] = Field(
        "displacement", description="readings given as integrated displacements or as primary readings")

    @model_validator(mode="after")
    def _stations(self):
        if self.lengths is None and self.spacing is None:
            raise ValueError("expected the stations as 'lengths' or as 'spacing' (with 'stations'), "
                             "found neither")
        if self.lengths is not None and (self.spacing is not None or self.stations is not None):
            raise ValueError("expected the stations as 'lengths' or as 'spacing'/'stations', found both")
        return self


class Inclinometer(_Linewise):
    """Vertical borehole at x; slopes integrated from the reference end (eqns 15-17)."""

    kind: Literal["inclinometer"]
    x: NonNegative = Field(description="horizontal position of the borehole [m]")
    toe_depth: Positive = Field(description="depth of the borehole's toe [m]")
    head_depth: NonNegative = Field(0.0, description="depth of the borehole's head [m]")
    reference: Literal["toe", "head"] = Field("toe", description="end the readings are integrated from")
    sigma: Positive = Field(description="standard deviation of one slope reading [rad]")
    var_b: NonNegative = Field(0.0, description="variance of the integration constant B [m2]")


class SlidingMicrometer(_Linewise):
    """Straight measuring line from `start` (reference end) towards `end` (eqns 11-14)."""

    kind: Literal["sliding_micrometer", "extensometer"]
    start: Point = Field(description="reference end [x, y] [m]")
    end: Point = Field(description="other end [x, y] [m]; displacement is positive from start to end")
    sigma: Positive = Field(description="standard deviation of one length-change reading [m]")
    var_a: NonNegative = Field(0.0, description="variance of the integration constant A [m2]")


class Deflectometer(_Linewise):
    """Straight line measuring curvatures; displacement normal to the line (eqns 18-20)."""

    kind: Literal["deflectometer"]
    start: Point
    end: Point
    sigma: Positive = Field(description="standard deviation of one curvature reading [1/m]")
    var_c: NonNegative = Field(0.0, description="variance of the integration constant C [rad2]")
    var_d: NonNegative = Field(0.0, description="variance of the integration constant D [m2]")


class Convergence(_Instrument):
    """A chord between two points on the tunnel wall; reads the change of its length [m]."""

    kind: Literal["convergence"]
    points: tuple[Point, Point]
    sigma: Positive = Field(description="standard deviation of the reading [m]")


Instrument = Annotated[Union[PointsInstrument, Inclinometer, SlidingMicrometer, Deflectometer,
                             Convergence], Field(discriminator="kind")]


class Prior(Strict):
    mean: Num
    std: Positive


class Parameter(Strict):
    """A quantity to identify: 'E[layer]', 'nu[layer]', 'K0', 'K0[layer]', 'B[instrument]', ..."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_]*(\[[A-Za-z0-9_\-.]+\])?$")
    initial: Stress
    bounds: Optional[tuple[Stress, Stress]] = None
    log: Annotated[bool, BeforeValidator(_flag)] = Field(False, description="iterate on log(p) (positive parameters)")
    prior: Optional[Prior] = None


class FitSettings(Strict):
    method: Literal["lm", "gn", "lm-scaled"] = "lm"
    max_iterations: Count = Field(30, gt=0)
    mu0: Positive = 10.0
    step_tol: Positive = 1e-6
    objective_tol: Positive = 1e-10
    weighting: Literal["full", "diagonal", "identity"] = Field(
        "full", description="C_x used in J: the instruments' full covariance (eqn 9), its diagonal, or I (eqn 8)")


class Output(Strict):
    dir: Optional[str] = Field(None, description="results directory (default results/<name>)")
    vtu: Annotated[bool, BeforeValidator(_flag)] = True


class Case(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_\-.]+$")
    description: str = ""
    geometry: Geometry
    ground: Ground
    mesh: MeshSettings = MeshSettings()
    instruments: list[Instrument] = Field(default_factory=list)
    parameters: list[Parameter] = Field(default_factory=list)
    fit: FitSettings = FitSettings()
    output: Output = Output()


def _g(x: float) -> str:
    return f"{x:g}"


def _inside_ground(g: Geometry, x: float, y: float) -> bool:
    tol = 1e-9 * max(g.width, g.depth)
    return -tol <= x <= g.width + tol and -g.depth - tol <= y <= tol


def _inside_tunnel(g: Geometry, x: float, y: float) -> bool:
    return math.hypot(x, y + g.axis_depth) < g.radius * (1 - 1e-6)


def _segment_enters_tunnel(g: Geometry, a: tuple, b: tuple) -> bool:
    """Does the straight segment a-b pass through the excavated tunnel's interior?"""
    cx, cy = 0.0, -g.axis_depth
    dx, dy = b[0] - a[0], b[1] - a[1]
    n2 = dx * dx + dy * dy
    t = 0.0 if n2 == 0 else min(1.0, max(0.0, ((cx - a[0]) * dx + (cy - a[1]) * dy) / n2))
    return math.hypot(a[0] + t * dx - cx, a[1] + t * dy - cy) < g.radius * (1 - 1e-6)


def _ground_span(g: Geometry) -> str:
    return f"x between 0 and {_g(g.width)}, y between {_g(-g.depth)} and 0"


def _tunnel_text(g: Geometry) -> str:
    return f"radius {_g(g.radius)} around (0, {_g(-g.axis_depth)})"


def _point_problem(g: Geometry, p: tuple, what: str) -> str | None:
    x, y = p
    if not _inside_ground(g, x, y):
        return f"expected {what} inside the ground ({_ground_span(g)}), found ({_g(x)}, {_g(y)})"
    if _inside_tunnel(g, x, y):
        return (f"expected {what} outside the excavated tunnel ({_tunnel_text(g)}), found ({_g(x)}, {_g(y)}), "
                f"{_g(math.hypot(x, y + g.axis_depth))} from the tunnel axis")
    return None


def _instrument_problems(g: Geometry, i: int, ins) -> list[tuple[tuple, str]]:
    at, out = ("instruments", i), []
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
        if not -1e-9 * g.width <= ins.x <= g.width * (1 + 1e-9):
            out.append((at + ("x",), f"expected the borehole inside the ground (x between 0 and {_g(g.width)}), "
                                     f"found x {_g(ins.x)}"))
        elif ins.toe_depth <= ins.head_depth:
            out.append((at + ("toe_depth",), f"expected the toe deeper than the head (head_depth "
                                             f"{_g(ins.head_depth)}), found toe_depth {_g(ins.toe_depth)}"))
        elif ins.toe_depth > g.depth * (1 + 1e-9):
            out.append((at + ("toe_depth",), f"expected the toe inside the ground (depth at most the model's "
                                             f"depth {_g(g.depth)}), found toe_depth {_g(ins.toe_depth)}"))
        elif _segment_enters_tunnel(g, (ins.x, -ins.head_depth), (ins.x, -ins.toe_depth)):
            out.append((at + ("x",), f"expected the borehole to miss the excavated tunnel ({_tunnel_text(g)}), "
                                     f"found it passing through the tunnel at x {_g(ins.x)} between depths "
                                     f"{_g(ins.head_depth)} and {_g(ins.toe_depth)}"))
    else:  # sliding micrometer, extensometer, deflectometer
        for end in ("start", "end"):
            why = _point_problem(g, getattr(ins, end), f"the line's {end}")
            if why:
                out.append((at + (end,), why))
                return out
        if tuple(ins.start) == tuple(ins.end):
            out.append((at + ("end",), f"expected an end different from the start, found the same point "
                                       f"({_g(ins.end[0])}, {_g(ins.end[1])})"))
        elif _segment_enters_tunnel(g, ins.start, ins.end):
            out.append((at + ("end",), f"expected the measuring line to miss the excavated tunnel "
                                       f"({_tunnel_text(g)}), found the line from ({_g(ins.start[0])}, "
                                       f"{_g(ins.start[1])}) to ({_g(ins.end[0])}, {_g(ins.end[1])}) "
                                       f"passing through it"))
    return out


MAX_RADIUS = 1e3  # m: gmsh's geometry kernel fails on larger tunnels (and none is that large)
MAX_SIZE = 1e5  # m: width and depth of the model
MAX_STATIONS = 2_000  # stations per instrument: its covariance matrix is dense
MAX_ELEMENTS = 1_000_000  # estimated triangles of the mesh: beyond this gmsh and the solver take far too long


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
                         f"1e-150 and 1e150), found {_g(ins.sigma)}")
    if ins.kind not in ("inclinometer", "sliding_micrometer", "extensometer", "deflectometer"):
        return None
    from . import covariance as cov  # numpy only; no geoback imports

    kind = cov.normalise_kind(ins.kind)
    variances = {n: getattr(ins, f"var_{n.lower()}") for n in cov.constant_names(kind)}
    try:
        n, _ = _station_count(ins)
        lengths = cov.station_lengths(lengths=ins.lengths) if ins.lengths is not None else \
            cov.station_lengths(stations=n, spacing=ins.spacing)
        C = cov.instrument_covariance(kind, lengths, ins.sigma, variances)
        cov.cholesky_factor(C, ins.name)
    except cov.NotPositiveDefinite as exc:
        big = ", ".join(f"var_{k.lower()} {_g(v)}" for k, v in variances.items() if v)
        return "sigma", (f"expected sigma {_g(ins.sigma)}" + (f" and {big}" if big else "")
                         + f" to give a positive-definite reading covariance, found it singular ({exc})")
    except ValueError:
        return None  # reported with its context when the instrument is built
    return None


def _mesh_estimate(case: Case) -> dict[str, float]:
    """Rough number of triangles gmsh will make, split by the mesh size responsible."""
    try:
        return _mesh_estimate_(case)
    except (ZeroDivisionError, OverflowError, ValueError):
        return {"size_far": math.inf}


def _mesh_estimate_(case: Case) -> dict[str, float]:
    g, m = case.geometry, case.mesh
    t = m.size_tunnel or g.radius / 8
    far = m.size_far or max(g.width, g.depth) / 12
    k = 2.31  # triangles per h^2 of area (equilateral)
    growth = m.growth
    out = {"size_far": k * g.width * g.depth / (far * far), "size_tunnel": 0.0, "size_instruments": 0.0}
    if far > t:  # graded ring around the wall: integral of 1/h^2 over the half annulus
        out["size_tunnel"] = k * math.pi / growth * ((g.radius - t / growth) * (1 / t - 1 / far)
                                                      + math.log(far / t) / growth)
    si = m.size_instruments
    if si and far > si:
        points = sum(len(ins.points) if ins.kind in ("points", "convergence") else 25 for ins in case.instruments)
        out["size_instruments"] = points * k * 2 * math.pi * (0.5 + math.log(far / si) / growth ** 2)
    return out


def physical_problems(case: Case) -> list[tuple[tuple, str]]:
    """Checks pydantic cannot express field by field: (path, message) for each problem."""
    g, problems = case.geometry, []
    if g.axis_depth - g.radius <= 0:
        problems.append((("geometry", "axis_depth"),
                         f"expected the tunnel below the surface (axis_depth greater than the radius "
                         f"{_g(g.radius)}), found axis_depth {_g(g.axis_depth)}: the tunnel reaches above the surface"))
    if g.radius >= g.width:
        problems.append((("geometry", "width"),
                         f"expected the half-model wider than the tunnel (width greater than the radius "
                         f"{_g(g.radius)}), found width {_g(g.width)}: the tunnel is wider than the domain"))
    if g.axis_depth + g.radius >= g.depth:
        problems.append((("geometry", "depth"),
                         f"expected the model's bottom below the tunnel's invert (depth greater than "
                         f"axis_depth + radius = {_g(g.axis_depth + g.radius)}), found depth {_g(g.depth)}"))
    for field, value, cap in (("radius", g.radius, MAX_RADIUS), ("width", g.width, MAX_SIZE),
                              ("depth", g.depth, MAX_SIZE)):
        if value > cap:
            problems.append((("geometry", field), f"expected at most {cap:g} m (lengths are in metres), "
                                                  f"found {field} {_g(value)}"))
    if g.radius < 1e-5 * max(g.width, g.depth) * (1 - 1e-9):
        problems.append((("geometry", "radius"),
                         f"expected a radius of at least 1e-5 times the model's size ({_g(1e-5 * max(g.width, g.depth))}), "
                         f"found {_g(g.radius)}: the mesher cannot resolve a tunnel that small"))
    layers = case.ground.layers
    if layers[0].top != 0:
        problems.append((("ground", "layers", 0, "top"),
                         f"expected the first layer to start at the surface (top: 0), found top {_g(layers[0].top)}"))
    for i in range(1, len(layers)):
        if layers[i].top <= layers[i - 1].top:
            problems.append((("ground", "layers", i, "top"),
                             f"expected layer tops increasing downwards (greater than the previous top "
                             f"{_g(layers[i - 1].top)}), found top {_g(layers[i].top)}"))
        elif layers[i].top >= g.depth:
            problems.append((("ground", "layers", i, "top"),
                             f"expected the layer's top above the model's bottom (less than depth {_g(g.depth)}), "
                             f"found top {_g(layers[i].top)}"))
        elif min(layers[i].top - layers[i - 1].top, g.depth - layers[i].top) < 1e-6 * g.depth:
            problems.append((("ground", "layers", i, "top"),
                             f"expected layers at least {_g(1e-6 * g.depth)} thick (1e-6 of the model's depth), "
                             f"found top {_g(layers[i].top)} within that of the next boundary"))
    names = [layer.name for layer in layers]
    for i, n in enumerate(names):
        if names.index(n) != i:
            problems.append((("ground", "layers", i, "name"),
                             f"expected unique layer names, found '{n}' again (as in ground.layers[{names.index(n)}])"))
    for i, layer in enumerate(layers):
        if layer.K0 is None and case.ground.K0 is None:
            problems.append((("ground", "layers", i, "K0"),
                             "expected a K0 for this layer (or ground.K0 for all layers), found none"))
    inames = [ins.name for ins in case.instruments]
    for i, n in enumerate(inames):
        if inames.index(n) != i:
            problems.append((("instruments", i, "name"),
                             f"expected unique instrument names, found '{n}' again (as in instruments[{inames.index(n)}])"))
    for i, ins in enumerate(case.instruments):
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
                                 f"expected the stations within the instrument's length {_g(length)} m, found "
                                 f"them reaching {_g(reach)} m from the reference end"))
                continue
        bad = _covariance_problem(ins)
        if bad:
            problems.append((("instruments", i, bad[0]), bad[1]))
    for field in ("size_tunnel", "size_far", "size_instruments"):
        size = getattr(case.mesh, field)
        if size is not None and size < 1e-4 * g.radius:
            problems.append((("mesh", field), f"expected an element size of at least 1e-4 times the radius "
                                              f"({_g(1e-4 * g.radius)}), found {_g(size)}"))
    if case.mesh.size_tunnel is not None and case.mesh.size_tunnel > g.radius:
        problems.append((("mesh", "size_tunnel"),
                         f"expected an element size at the wall of at most the radius {_g(g.radius)} "
                         f"(else the tunnel is not round), found {_g(case.mesh.size_tunnel)}"))
    estimate = _mesh_estimate(case)
    if sum(estimate.values()) > MAX_ELEMENTS:
        worst = max(estimate, key=estimate.get)
        problems.append((("mesh", worst),
                         f"expected mesh sizes giving at most about {MAX_ELEMENTS:,} elements, found sizes "
                         f"giving about {sum(estimate.values()):,.0f} (mostly from {worst} "
                         f"{_g(getattr(case.mesh, worst) or 0) if getattr(case.mesh, worst) else '(default)'})"))
    for i, p in enumerate(case.parameters):
        if p.bounds is not None:
            lo, hi = p.bounds
            if not lo < hi:
                problems.append((("parameters", i, "bounds"),
                                 f"expected a lower bound below the upper bound, found [{_g(lo)}, {_g(hi)}]"))
            elif not lo <= p.initial <= hi:
                problems.append((("parameters", i, "initial"),
                                 f"expected an initial value within the bounds [{_g(lo)}, {_g(hi)}], "
                                 f"found {_g(p.initial)} (outside the bounds)"))
            if p.log and lo <= 0:
                problems.append((("parameters", i, "bounds"),
                                 f"expected positive bounds for a log-transformed parameter, found lower bound {_g(lo)}"))
        if p.log and p.initial <= 0:
            problems.append((("parameters", i, "initial"),
                             f"expected a positive initial value for a log-transformed parameter, found {_g(p.initial)}"))
    pnames = [p.name for p in case.parameters]
    for i, n in enumerate(pnames):
        if pnames.index(n) != i:
            problems.append((("parameters", i, "name"),
                             f"expected each parameter once, found '{n}' again (as in parameters[{pnames.index(n)}])"))
    return problems


# ---------------------------------------------------------------------------- schema errors
_KINDS = {"points": PointsInstrument, "inclinometer": Inclinometer, "sliding_micrometer": SlidingMicrometer,
          "extensometer": SlidingMicrometer, "deflectometer": Deflectometer, "convergence": Convergence}
_CHILDREN: dict = {Case: {"geometry": Geometry, "ground": Ground, "mesh": MeshSettings, "instruments": "instrument",
                          "parameters": Parameter, "fit": FitSettings, "output": Output},
                   Ground: {"layers": Layer}, Parameter: {"prior": Prior}}
_PATTERNS = {r"^[A-Za-z0-9_\-.]+$": "a name of letters, digits, '_', '-' or '.' (no spaces)",
             r"^[A-Za-z_][A-Za-z0-9_\-]*$": "a name starting with a letter or '_', then letters, digits, '_' or '-'",
             r"^[A-Za-z_][A-Za-z0-9_]*(\[[A-Za-z0-9_\-.]+\])?$":
                 "a parameter name such as E, K0, E[layer] or B[instrument]"}
_PAIRS = {"start": "[x, y]", "end": "[x, y]", "bounds": "[lower, upper]"}


def _model_at(at: tuple, data: Any):
    """The model class describing the mapping at path `at` of the data (None if unknown)."""
    model, node = Case, data
    for part in at:
        if isinstance(part, int):
            node = node[part] if isinstance(node, list) and 0 <= part < len(node) else None
            continue
        if model == "instrument":
            model = _instrument_model(node)
        model = _CHILDREN.get(model, {}).get(part)
        if model is None:
            return None
        node = node.get(part) if isinstance(node, dict) else None
    if model == "instrument":
        model = _instrument_model(node)
    return model


def _instrument_model(node: Any):
    kind = node.get("kind") if isinstance(node, dict) else None
    return _KINDS.get(kind) if isinstance(kind, str) else None


def _clean_loc(loc: tuple, data: Any) -> tuple:
    """Drop the union tags pydantic inserts (e.g. 'inclinometer') so the path follows the file."""
    out: list = []
    for k, part in enumerate(loc):
        if k == 2 and loc[0] == "instruments" and part in _KINDS:
            continue  # the discriminated union's tag
        if isinstance(part, str) and ("[" in part or part.startswith(("function-", "tagged-union"))):
            continue  # a validator's tag such as 'function-after[...]'
        out.append(part)
    return tuple(out)


def _fields_text(model) -> str:
    names = list(model.model_fields)
    if model in _KINDS.values():
        names.remove("kind")
        names.insert(0, "kind")
    return ", ".join(names)


def _bound(v: Any) -> str:
    return _g(v) if isinstance(v, (int, float)) else str(v)


def _expected(err: dict, at: tuple, data: Any) -> str:
    """The 'expected ...' phrase of a pydantic error, in plain words."""
    t, ctx = err["type"], err.get("ctx") or {}
    simple = {"float_type": "a number", "float_parsing": "a number", "int_type": "a whole number",
              "int_parsing": "a whole number", "int_from_float": "a whole number", "string_type": "text",
              "bool_type": "true or false", "bool_parsing": "true or false", "list_type": "a list",
              "finite_number": "a finite number", "dict_type": "a mapping of fields"}
    if t in simple:
        return simple[t]
    if t == "greater_than":
        return f"a number greater than {_bound(ctx['gt'])}"
    if t == "greater_than_equal":
        return f"a number of at least {_bound(ctx['ge'])}"
    if t == "less_than":
        return f"a number less than {_bound(ctx['lt'])}"
    if t == "less_than_equal":
        return f"a number of at most {_bound(ctx['le'])}"
    if t == "literal_error":
        return f"one of {ctx.get('expected', '?')}"
    if t in ("model_type", "model_attributes_type"):
        model = _model_at(at, data)
        return f"a mapping of fields ({_fields_text(model)})" if model else "a mapping of fields"
    if t == "string_pattern_mismatch":
        return _PATTERNS.get(ctx.get("pattern"), f"text matching {ctx.get('pattern')}")
    if t in ("tuple_type", "too_long", "too_short") and at and at[-1] in _PAIRS:
        return f"2 values {_PAIRS[at[-1]]}"
    if t == "too_short":
        n = ctx.get("min_length", 1)
        return f"at least {n} item{'s' if n != 1 else ''}"
    if t == "too_long":
        n = ctx.get("max_length", 1)
        return f"at most {n} item{'s' if n != 1 else ''}"
    if t == "tuple_type":
        return "a list"
    msg = err["msg"]
    for prefix in ("Input should be ", "Value should be "):
        if msg.startswith(prefix):
            return msg[len(prefix):]
    return msg[0].lower() + msg[1:]


def _field_info(at: tuple, data: Any):
    if not at or not isinstance(at[-1], str):
        return None
    model = _model_at(at[:-1], data)
    return model.model_fields.get(at[-1]) if model else None


def _is_pair(at: tuple, data: Any) -> bool:
    """Is the value at `at` one of the schema's 2-tuples ([x, y], [lower, upper], convergence points)?"""
    if not at:
        return False
    if at[-1] in _PAIRS:
        return True
    if len(at) >= 2 and at[-2] == "points" and isinstance(at[-1], int):
        return True  # a point [x, y] of a points list
    if at[-1] == "points" and _model_at(at[:-1], data) is Convergence:
        return True
    return False


def _describe(err: dict, data: Any) -> tuple[tuple, str]:
    """(path, message) for one pydantic error: what was expected and what was found."""
    t, ctx = err["type"], err.get("ctx") or {}
    at = _clean_loc(tuple(err["loc"]), data)
    found = err.get("input")
    if t == "missing" and at and isinstance(at[-1], int):  # a pair given too few values
        pair = at[:-1]
        what = _PAIRS.get(pair[-1], "[x, y]") if pair else "[x, y]"
        if pair and pair[-1] == "points" and _model_at(pair[:-1], data) is Convergence:
            what = "points [[x1, y1], [x2, y2]]"
        return pair, f"expected 2 {what if what.startswith('points') else 'values ' + what}, found {_show(found)}"
    if t == "missing":
        field = _field_info(at, data)
        what = f" ({field.description})" if field is not None and field.description else ""
        have = ", ".join(printable(k) for k in found) if isinstance(found, dict) and found else "no fields"
        return at, f"expected the required field '{at[-1]}'{what}, found it missing (given: {have})"
    if t == "extra_forbidden":
        key = printable(at[-1])
        model = _model_at(at[:-1], data)
        allowed = _fields_text(model) if model else ""
        close = difflib.get_close_matches(key, list(model.model_fields) if model else [], n=1, cutoff=0.6)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        return at, (f"unknown field '{key}'{hint}: expected one of {allowed}" if allowed
                    else f"unknown field '{key}'{hint}")
    if t == "union_tag_invalid":
        kinds = ", ".join(_KINDS)
        return at + ("kind",), f"unknown instrument kind {_show(ctx.get('tag'))}: expected one of {kinds}"
    if t == "union_tag_not_found":
        kinds = ", ".join(_KINDS)
        if isinstance(found, dict):
            return at + ("kind",), f"expected the required field 'kind' (one of {kinds}), found it missing"
        return at, f"expected a mapping describing an instrument (kind: one of {kinds}), found {_show(found)}"
    if t in ("value_error", "assertion_error"):
        msg = err["msg"].removeprefix("Value error, ").removeprefix("Assertion failed, ")
        if "found" not in msg and not isinstance(found, dict):
            msg += f", found {_show(found)}"
        return at, msg
    if t in ("too_short", "too_long") or (t == "tuple_type" and _is_pair(at, data)):
        if _is_pair(at, data) and t != "too_short":
            what = "2 points [[x1, y1], [x2, y2]]" if at[-1] == "points" else \
                f"2 values {_PAIRS.get(at[-1], '[x, y]')}"
            n = ctx.get("actual_length")
            got = f"{n} value{'s' if n != 1 else ''}" if n is not None else _show(found)
            return at, f"expected {what}, found {got}"
        n = ctx.get("actual_length")
        got = f"{n} item{'s' if n != 1 else ''}" if n is not None else _show(found)
        return at, f"expected {_expected(err, at, data)}, found {got}"
    if t == "string_type" and isinstance(found, (int, float)) and not isinstance(found, bool):
        return at, f"expected text, found the number {_show(found)} (put it in quotes)"
    return at, f"expected {_expected(err, at, data)}, found {_show(found)}"


def _pick(errors: list[dict], data: Any, marks: dict) -> tuple[tuple, str, int]:
    """The error to report (first in the file; a misspelt key before the field it misses) and how many
    other problems there are."""
    described = [_describe(e, data) + (e,) for e in errors]
    # a misspelt key shows up twice: unknown 'radus' and missing 'radius'. Report it once.
    typos = set()
    for at, msg, e in described:
        if e["type"] == "extra_forbidden" and "did you mean '" in msg:
            typos.add(at[:-1] + (msg.split("did you mean '")[1].split("'")[0],))
    described = [d for d in described if not (d[2]["type"] == "missing" and d[0] in typos)]

    def order(d):
        at, _, e = d
        line, col = locate(at, marks)
        return (line if line is not None else 0, col if col is not None else 0)

    described.sort(key=order)
    at, msg, _ = described[0]
    return at, msg, len(described) - 1


def _more(n: int) -> str:
    return f" (and {n} more problem{'s' if n > 1 else ''})" if n else ""


def case_from_data(data: Any, marks: dict | None = None, file: str | None = None) -> Case:
    """Validate already-parsed data; raise CaseError located in the file."""
    marks = marks or {}
    if not isinstance(data, dict):
        line, col = marks.get((), (1, 1))
        raise CaseError(f"expected a mapping of case fields (name:, geometry:, ground:, ...), found {_show(data)}",
                        file=file, line=line, column=col, field=format_path(()))
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        try:
            at, message, more = _pick(exc.errors(), data, marks)
        except Exception:  # pragma: no cover - the plain pydantic wording is better than a crash
            err = exc.errors()[0]
            at = _clean_loc(tuple(err["loc"]), data)
            message, more = err["msg"].replace("Input should be", "expected"), len(exc.errors()) - 1
        line, col = locate(at, marks)
        raise CaseError(message + _more(more), file=file, line=line, column=col,
                        field=format_path(at)) from None
    problems = physical_problems(case)
    if problems:
        at, message = problems[0]
        line, col = locate(at, marks)
        raise CaseError(message + _more(len(problems) - 1), file=file, line=line, column=col,
                        field=format_path(at))
    return case


class LoadedCase:
    """A validated case together with where it came from (for readings files and messages)."""

    def __init__(self, case: Case, path: Path | None, marks: dict):
        self.case, self.path, self.marks = case, path, marks

    @property
    def folder(self) -> Path:
        return self.path.parent if self.path else Path.cwd()

    def error(self, at: tuple, message: str) -> CaseError:
        line, col = locate(at, self.marks)
        return CaseError(message, file=str(self.path) if self.path else None, line=line, column=col,
                         field=format_path(at))

    def digest(self) -> str:
        text = json.dumps(self.case.model_dump(mode="json"), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def load_case(path: str | Path) -> LoadedCase:
    """Read and validate a case file (YAML)."""
    data, marks = load_yaml_with_marks(path)
    case = case_from_data(data, marks, file=str(path))
    return LoadedCase(case, Path(path), marks)


def case_schema() -> dict:
    """JSON Schema of the case file, for editors."""
    schema = Case.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "geoback case"
    return schema
