"""The case file: YAML -> validated pydantic models, with file:line:column on every error.

Units are SI throughout: lengths in m, stresses and moduli in kPa (a string such as
``"10 MPa"`` is also accepted for a modulus), unit weight in kN/m³, angles in rad.
Coordinates are those of the half-model: symmetry axis x = 0, ground surface y = 0, y up
(depth = -y).
"""
from __future__ import annotations

import hashlib
import json
import math
import re
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import (BaseModel, BeforeValidator, ConfigDict, Field, ValidationError,
                      model_validator)

from .errors import CaseError
from .yamlmarks import format_path, load_yaml_with_marks, locate

_UNITS = {"pa": 1e-3, "kpa": 1.0, "mpa": 1e3, "gpa": 1e6}


def _stress(value: Any) -> Any:
    """Accept numbers (kPa) or strings with an explicit unit: '10 MPa', '2e4 kPa'."""
    if isinstance(value, str):
        m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*([A-Za-z]+)?\s*", value)
        if not m or (m.group(2) and m.group(2).lower() not in _UNITS):
            raise ValueError("expected a stress in kPa or a string like '10 MPa' "
                             "(units Pa, kPa, MPa, GPa)")
        try:
            number = float(m.group(1))
        except ValueError:
            raise ValueError("expected a number with an optional unit, like '10 MPa'") from None
        return number * _UNITS[(m.group(2) or "kpa").lower()]
    return value


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError("expected a finite number, found NaN or infinity")
    return value


Stress = Annotated[float, BeforeValidator(_stress), BeforeValidator(_finite)]
Num = Annotated[float, BeforeValidator(_finite)]
Positive = Annotated[float, BeforeValidator(_finite), Field(gt=0)]
NonNegative = Annotated[float, BeforeValidator(_finite), Field(ge=0)]
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
    order: Literal[1, 2] = Field(2, description="element order: 2 = quadratic triangles")


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
    stations: Optional[int] = Field(None, gt=0, description="number of stations (with spacing)")
    lengths: Optional[list[Positive]] = Field(None, min_length=1,
                                              description="distances l_1..l_n between stations from the reference end [m]")
    reading_type: Literal["displacement", "primary"] = Field(
        "displacement", description="readings given as integrated displacements or as primary readings")

    @model_validator(mode="after")
    def _stations(self):
        if self.lengths is None and self.spacing is None:
            raise ValueError("give either 'lengths' or 'spacing' (with 'stations')")
        if self.lengths is not None and (self.spacing is not None or self.stations is not None):
            raise ValueError("give either 'lengths' or 'spacing'/'stations', not both")
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
    log: bool = Field(False, description="iterate on log(p) (positive parameters)")
    prior: Optional[Prior] = None


class FitSettings(Strict):
    method: Literal["lm", "gn", "lm-scaled"] = "lm"
    max_iterations: int = Field(30, gt=0)
    mu0: Positive = 10.0
    step_tol: Positive = 1e-6
    objective_tol: Positive = 1e-10
    weighting: Literal["full", "diagonal", "identity"] = Field(
        "full", description="C_x used in J: the instruments' full covariance (eqn 9), its diagonal, or I (eqn 8)")


class Output(Strict):
    dir: Optional[str] = Field(None, description="results directory (default results/<name>)")
    vtu: bool = True


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

    def layer_of_depth(self, depth: float) -> int:
        tops = [layer.top for layer in self.ground.layers]
        return max(i for i, t in enumerate(tops) if t <= depth + 1e-12)

    def k0(self, layer: int) -> float:
        value = self.ground.layers[layer].K0
        return value if value is not None else self.ground.K0  # type: ignore[return-value]


def physical_problems(case: Case) -> list[tuple[tuple, str]]:
    """Checks pydantic cannot express field by field: (path, message) for each problem."""
    g, problems = case.geometry, []
    if g.axis_depth - g.radius <= 0:
        problems.append((("geometry", "axis_depth"),
                         f"the tunnel reaches above the surface: axis_depth {g.axis_depth} must exceed "
                         f"the radius {g.radius}"))
    if g.radius >= g.width:
        problems.append((("geometry", "width"),
                         f"the tunnel (radius {g.radius}) is wider than the half-model (width {g.width})"))
    if g.axis_depth + g.radius >= g.depth:
        problems.append((("geometry", "depth"),
                         f"the tunnel's invert (depth {g.axis_depth + g.radius}) is not above the model's "
                         f"bottom (depth {g.depth})"))
    layers = case.ground.layers
    if layers[0].top != 0:
        problems.append((("ground", "layers", 0, "top"),
                         f"the first layer must start at the surface (top: 0), found {layers[0].top}"))
    for i in range(1, len(layers)):
        if layers[i].top <= layers[i - 1].top:
            problems.append((("ground", "layers", i, "top"),
                             f"layer tops must increase downwards: {layers[i].top} follows {layers[i - 1].top}"))
        if layers[i].top >= g.depth:
            problems.append((("ground", "layers", i, "top"),
                             f"layer top {layers[i].top} is below the model's bottom (depth {g.depth})"))
    names = [layer.name for layer in layers]
    for i, n in enumerate(names):
        if names.index(n) != i:
            problems.append((("ground", "layers", i, "name"), f"duplicate layer name '{n}'"))
    for i, layer in enumerate(layers):
        if layer.K0 is None and case.ground.K0 is None:
            problems.append((("ground", "layers", i, "K0"),
                             "no K0: give ground.K0 or a K0 for every layer"))
    inames = [ins.name for ins in case.instruments]
    for i, n in enumerate(inames):
        if inames.index(n) != i:
            problems.append((("instruments", i, "name"), f"duplicate instrument name '{n}'"))
    for i, p in enumerate(case.parameters):
        if p.bounds is not None:
            lo, hi = p.bounds
            if not lo < hi:
                problems.append((("parameters", i, "bounds"), f"lower bound {lo} is not below upper bound {hi}"))
            elif not lo <= p.initial <= hi:
                problems.append((("parameters", i, "initial"),
                                 f"initial value {p.initial} lies outside the bounds [{lo}, {hi}]"))
            if p.log and lo <= 0:
                problems.append((("parameters", i, "bounds"), "a log-transformed parameter needs positive bounds"))
        if p.log and p.initial <= 0:
            problems.append((("parameters", i, "initial"), "a log-transformed parameter needs a positive initial value"))
    pnames = [p.name for p in case.parameters]
    for i, n in enumerate(pnames):
        if pnames.index(n) != i:
            problems.append((("parameters", i, "name"), f"parameter '{n}' is listed twice"))
    return problems


def _pydantic_message(err: dict) -> str:
    msg = err["msg"]
    if err["type"] == "missing":
        return "required field is missing"
    if err["type"] == "extra_forbidden":
        return "unknown field (not part of the case schema; see `geoback schema`)"
    msg = msg.removeprefix("Value error, ")
    if "input" in err and err["type"] not in ("missing",):
        found = err["input"]
        text = repr(found) if not isinstance(found, (dict, list)) else type(found).__name__
        if len(text) > 60:
            text = text[:57] + "..."
        return f"{msg[0].lower()}{msg[1:]}; found {text}"
    return msg


def _clean_loc(loc: tuple, data: Any) -> tuple:
    """Drop the union tags pydantic inserts (e.g. 'inclinometer') so the path follows the file."""
    out, node = [], data
    for part in loc:
        if isinstance(node, dict) and part in node:
            out.append(part)
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and part < len(node):
            out.append(part)
            node = node[part]
        elif isinstance(node, dict) and isinstance(part, str) and part in Case.model_fields | _all_fields():
            out.append(part)  # a missing or unknown key: keep it, the parent locates it
            node = None
        # else: a tag such as 'inclinometer' or 'function-after[...]': skip
    return tuple(out)


def _all_fields() -> dict:
    fields = {}
    for model in (Geometry, Layer, Ground, MeshSettings, PointsInstrument, Inclinometer,
                  SlidingMicrometer, Deflectometer, Convergence, Prior, Parameter, FitSettings, Output):
        fields.update(model.model_fields)
    return fields


def case_from_data(data: Any, marks: dict | None = None, file: str | None = None) -> Case:
    """Validate already-parsed data; raise CaseError located in the file."""
    marks = marks or {}
    if not isinstance(data, dict):
        raise CaseError(f"expected a mapping of case fields, found {type(data).__name__}", file=file, line=1)
    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = tuple(err["loc"])
        at = _clean_loc(loc, data)
        line, col = locate(at, marks)
        more = len(exc.errors()) - 1
        suffix = f" (and {more} more problem{'s' if more > 1 else ''})" if more else ""
        raise CaseError(_pydantic_message(err) + suffix, file=file, line=line, column=col,
                        field=format_path(at)) from None
    problems = physical_problems(case)
    if problems:
        at, message = problems[0]
        line, col = locate(at, marks)
        more = len(problems) - 1
        suffix = f" (and {more} more problem{'s' if more > 1 else ''})" if more else ""
        raise CaseError(message + suffix, file=file, line=line, column=col, field=format_path(at))
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
