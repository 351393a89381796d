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


def case_from_data(data: Any, marks: dict | None = None, file: str | None = None,
                   allow_large: bool = False) -> Case:
    """Validate already-parsed data; raise CaseError located in the file, carrying every problem
    found (``CaseError.problems``). A mesh estimated beyond the default size limit is one of the
    problems unless `allow_large`."""
    marks = marks or {}
    if not isinstance(data, dict):
        line, col = marks.get((), (1, 1))
        raise CaseError(f"expected a mapping of case fields (name:, geometry:, ground:, ...), found {_show(data)}",
                        file=file, line=line, column=col, field=format_path(()))
    from .case_checks import physical_problems
    from .case_messages import _clean_loc, _described

    try:
        case = Case.model_validate(data)
    except ValidationError as exc:
        try:
            problems = _described(exc.errors(), data, marks)
        except Exception:  # pragma: no cover - the plain pydantic wording is better than a crash
            problems = [(_clean_loc(tuple(err["loc"]), data), err["msg"].replace("Input should be", "expected"))
                        for err in exc.errors()]
        raise located_problems(problems, marks, file) from None
    problems = physical_problems(case, allow_large=allow_large)
    if problems:
        raise located_problems(problems, marks, file)
    return case


def located_problems(problems: list[tuple[tuple, str]], marks: dict, file: str | None) -> CaseError:
    """One CaseError for a list of (path, message): the first, '(and N more problems)', and all of
    them in ``.problems``."""
    from .case_messages import _more

    located = []
    for at, message in problems:
        line, col = locate(at, marks)
        located.append(CaseError(message, file=file, line=line, column=col, field=format_path(at)))
    first = located[0]
    if len(located) == 1:
        return first
    return CaseError(first.reason + _more(len(located) - 1), file=file, line=first.line, column=first.column,
                     field=first.field, problems=located)


class LoadedCase:
    """A validated case together with where it came from (for readings files and messages)."""

    def __init__(self, case: Case, path: Path | None, marks: dict, allow_large: bool = False):
        self.case, self.path, self.marks = case, path, marks
        self.allow_large = allow_large  # meshes beyond the default size limit allowed (--allow-large)

    def with_case(self, case: Case) -> "LoadedCase":
        """The same origin (file, marks, allow_large) for a changed case (a finer mesh, a split layer)."""
        return LoadedCase(case, self.path, self.marks, allow_large=self.allow_large)

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


def load_case(path: str | Path, allow_large: bool = False) -> LoadedCase:
    """Read and validate a case file (YAML). A case whose mesh is estimated beyond the default size
    limit (geoback.meshsize.max_dofs()) is refused unless `allow_large`, which the loaded case then
    carries to wherever it is meshed."""
    data, marks = load_yaml_with_marks(path)
    case = case_from_data(data, marks, file=str(path), allow_large=allow_large)
    return LoadedCase(case, Path(path), marks, allow_large=allow_large)


def case_schema() -> dict:
    """JSON Schema of the case file, for editors."""
    schema = Case.model_json_schema()
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "geoback case"
    return schema
