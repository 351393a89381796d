"""The case file's schema: pydantic models of every section, and the value parsers they use
(numbers, flags, stresses with units). Units are SI throughout: lengths in m, stresses and moduli
in kPa (a string such as ``"10 MPa"`` is also accepted for a stress), unit weight in kN/m³, angles in
rad, except the friction and dilation angles of a mohr-coulomb layer, in degrees as engineers
write them. Coordinates are those of the half-model: symmetry axis x = 0, ground surface y = 0,
y up (depth = -y). Imports nothing else of geoback's case modules (case.py loads and validates)."""
from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal, Optional, Union

from pydantic import (BaseModel, BeforeValidator, ConfigDict, Discriminator, Field, Tag,
                      field_validator, model_validator)

from geoback.case.yamlmarks import printable

_UNITS = {"pa": 1e-3, "kpa": 1.0, "mpa": 1e3, "gpa": 1e6}


def number_text(x: float) -> str:
    """A number as a person writes it (general format)."""
    return f"{x:g}"


def shown(value: Any) -> str:
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


def _spelled(value: str) -> Any:
    """A quoted number (YAML `!!str 10`, `'0.3'`) read as the number it spells, so that it is used
    exactly as the same number unquoted is, and checked the same way (`'nan'` and `'1e400'` are not
    finite, as `.nan` is not); text that spells no number is left for the field's own message."""
    try:
        number = float(value)
    except ValueError:
        return value
    if not math.isfinite(number):
        raise ValueError(f"expected a finite number, found {shown(value)}")
    return number


def _number(value: Any) -> Any:
    """Numbers only: reject true/false (YAML's yes/no), NaN, infinities and overflowing integers."""
    if isinstance(value, str):
        return _spelled(value)
    if isinstance(value, bool):
        raise ValueError(f"expected a number, found {shown(value)}")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"expected a finite number, found {shown(value)}")
    if isinstance(value, int) and abs(value) > 1e300:
        raise ValueError(f"expected a finite number, found {shown(value)}")
    return value


def _flag(value: Any) -> Any:
    if not isinstance(value, bool):
        raise ValueError(f"expected true or false, found {shown(value)}")
    return value


def _whole(value: Any) -> Any:
    if isinstance(value, str):  # '2' as 2 (an element order among 1 and 2 too), '7.5' left to be refused
        value = _spelled(value)
        return int(value) if isinstance(value, float) and value.is_integer() else value
    if isinstance(value, bool):
        raise ValueError(f"expected a whole number, found {shown(value)}")
    return value


_NUMBER_AND_UNIT = re.compile(r"\s*([-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?)\s*([A-Za-z/]+)?\s*")


def _with_unit(value: Any, units: dict, default: str, what: str, unit_words: str, shape_error: str) -> Any:
    """A number in the default unit, or a string '<number> <unit>' converted by `units` (keys lower
    case, listed for people as `unit_words`); `shape_error` is the message for a string that is no
    number with a unit."""
    if isinstance(value, str):
        m = _NUMBER_AND_UNIT.fullmatch(value)
        if not m:
            raise ValueError(shape_error)
        if m.group(2) and m.group(2).lower() not in units:
            raise ValueError(f"expected a unit {unit_words} after the number, found '{m.group(2)}' in {shown(value)}")
        number = float(m.group(1)) * units[(m.group(2) or default).lower()]
        if not math.isfinite(number):
            raise ValueError(f"expected a finite {what}, found {shown(value)}")
        return number
    return _number(value)


def _stress(value: Any) -> Any:
    """Accept numbers (kPa) or strings with an explicit unit: '10 MPa', '2e4 kPa'."""
    return _with_unit(value, _UNITS, "kpa", "stress", "Pa, kPa, MPa or GPa",
                      f"expected a stress: a number in kPa or a number with a unit like '10 MPa', found {shown(value)}")


Stress = Annotated[float, BeforeValidator(_stress)]

_LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "km": 1e3}


def _length(value: Any) -> Any:
    """Accept numbers (m) or strings with an explicit unit: '0.5 m', '50 cm', '500mm' (as stresses
    accept '10 MPa')."""
    return _with_unit(value, _LENGTH_UNITS, "m", "length", "m, cm, mm or km",
                      f"expected a number, found {shown(value)} (a length in m, or with a unit like '50 cm')")


Length = Annotated[float, BeforeValidator(_length)]
PositiveLength = Annotated[float, BeforeValidator(_length), Field(gt=0)]
NonNegativeLength = Annotated[float, BeforeValidator(_length), Field(ge=0)]
Num = Annotated[float, BeforeValidator(_number)]
Positive = Annotated[float, BeforeValidator(_number), Field(gt=0)]
NonNegative = Annotated[float, BeforeValidator(_number), Field(ge=0)]
Count = Annotated[int, BeforeValidator(_whole)]
Point = tuple[Length, Length]


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Geometry(Strict):
    """Half-model of a circular tunnel: x from 0 (symmetry axis) to `width`, y from -`depth` to 0."""

    radius: PositiveLength = Field(description="tunnel radius R [m]")
    axis_depth: PositiveLength = Field(description="depth of the tunnel axis below the surface [m]")
    width: PositiveLength = Field(description="width of the half-model (symmetry axis to far side) [m]")
    depth: PositiveLength = Field(description="depth of the model's bottom boundary below the surface [m]")


class _Opening(Strict):
    """An opening: a named region of the ground that construction excavates, whole or in parts."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$", description="opening name (stages excavate it by name)")
    cuts: list[tuple[Point, Point]] = Field(
        default_factory=list, description="straight cut lines [[x1, y1], [x2, y2]] dividing the opening into parts "
                                          "(each line crosses the opening from side to side)")
    parts: list["Part"] = Field(default_factory=list, description="the pieces the cuts make, each named by a point "
                                                                  "inside it (none: the opening is excavated whole)")


class Part(Strict):
    """A named piece of an opening (top heading, bench, invert, side drift), found by a point inside it."""

    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$", description="part name (stages excavate it by name)")
    contains: Point = Field(description="a point [x, y] inside the part [m]")


class CircleOpening(_Opening):
    shape: Literal["circle"]
    centre: Point = Field(description="centre [x, y] [m]")
    radius: PositiveLength = Field(description="radius [m]")


class HorseshoeOpening(_Opening):
    """The horseshoe (NATM) profile: a crown semicircle (radius `crown_radius`, centre `centre` on the
    springline), side walls curving in below it (arcs of radius `side_radius` >= crown_radius, tangent to
    the crown at the springline, their centres on the springline) down to the invert corners, and an
    invert arc of radius `invert_radius` between the corners (flat without it). `height` is from the
    invert's lowest point to the crown. The width is 2 x crown_radius, at the springline."""

    shape: Literal["horseshoe"]
    centre: Point = Field(description="centre of the crown arc [x, y] [m], on the springline")
    crown_radius: PositiveLength = Field(description="radius of the crown arc [m] (half the width)")
    side_radius: PositiveLength = Field(description="radius of the side walls [m], at least the crown radius")
    height: PositiveLength = Field(description="height from the invert's lowest point to the crown [m]")
    invert_radius: Optional[PositiveLength] = Field(None, description="radius of the invert arc [m] (default: a "
                                                                      "flat invert)")


class ArcThrough(Strict):
    through: Point = Field(description="a point [x, y] the circular arc between the neighbouring vertices passes through")


class PolygonOpening(_Opening):
    shape: Literal["polygon"]
    boundary: list[Union[Point, ArcThrough]] = Field(
        min_length=3, description="vertices [x, y] in order around the opening; between two vertices an entry "
                                  "{through: [x, y]} makes the side a circular arc through that point")


Opening = Annotated[Union[CircleOpening, HorseshoeOpening, PolygonOpening], Field(discriminator="shape")]


class Layout(Strict):
    """The general section: a full model (x from -width/2 to width/2) or a half-model with symmetry at
    x = 0 (x from 0 to width), ground surface y = 0, bottom y = -depth, and openings of any shape."""

    model: Literal["full", "half"] = Field(description="'full': the whole section; 'half': symmetric about x = 0")
    width: PositiveLength = Field(description="full model: total width; half-model: symmetry axis to far side [m]")
    depth: PositiveLength = Field(description="depth of the model's bottom boundary below the surface [m]")
    openings: list[Opening] = Field(min_length=1, description="the openings (tunnels, shafts, galleries)")


def _geometry_shape(value: Any) -> str:
    """Which geometry a value is (a mapping when validating, a model when serialising)."""
    openings = "openings" in value if isinstance(value, dict) else hasattr(value, "openings")
    return "layout" if openings else "circular"


GROUND_MODELS = ("linear-elastic", "mohr-coulomb")
MC_FIELDS = ("c", "phi", "psi", "tension")  # the strength of a mohr-coulomb layer
Angle = Annotated[float, BeforeValidator(_number)]


class Layer(Strict):
    name: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$", description="layer name (letters, digits, _ -)")
    top: NonNegativeLength = Field(description="depth of the layer's top [m]; the first layer starts at 0")
    E: Stress = Field(gt=0, description="Young's modulus [kPa] (or '10 MPa')")
    nu: Num = Field(ge=0.0, lt=0.5, description="Poisson's ratio, 0 <= nu < 0.5")
    K0: Optional[Positive] = Field(None, description="coefficient of earth pressure at rest of this layer")
    unit_weight: Optional[Positive] = Field(None, description="unit weight of this layer [kN/m3] (default: the "
                                                              "ground's); with openings: geometry only")
    model: Literal["linear-elastic", "mohr-coulomb"] = Field(
        "linear-elastic", description="'linear-elastic', or 'mohr-coulomb': elastic-perfectly plastic with the strength "
                                      "c, phi, dilation psi and an optional tension cut-off")
    c: Optional[Stress] = Field(None, ge=0, description="mohr-coulomb: cohesion c' [kPa] (or '20 kPa'), at least 0")
    phi: Optional[Angle] = Field(None, gt=0, lt=70, description="mohr-coulomb: friction angle phi' [degrees], "
                                                                "0 < phi < 70")
    psi: Optional[Angle] = Field(None, ge=0, lt=70, description="mohr-coulomb: dilation angle psi [degrees], "
                                                                "0 <= psi <= phi (psi < phi: non-associated flow)")
    tension: Optional[Stress] = Field(None, ge=0, description="mohr-coulomb, optional: tension cut-off [kPa], the "
                                                              "largest tensile principal stress (at most c / tan phi)")


class Ground(Strict):
    unit_weight: Positive = Field(description="unit weight gamma [kN/m3]; sigma_v = -gamma*depth")
    K0: Optional[Positive] = Field(None, description="K0 of all layers (unless a layer gives its own)")
    layers: list[Layer] = Field(min_length=1)
    logged_to: Optional[NonNegativeLength] = Field(
        None, description="depth the boreholes log the strata to [m] (or '25 m'): the layers above it are as "
                          "logged, so `geoback diagnose` proposes no unmodelled stratum boundary above it "
                          "(below it, and without it, it does)")


class MeshSettings(Strict):
    size_tunnel: Optional[PositiveLength] = Field(None, description="element size at the tunnel wall [m] (default R/8)")
    size_far: Optional[PositiveLength] = Field(None, description="element size far from the tunnel [m] (default domain/12)")
    size_instruments: Optional[PositiveLength] = Field(None, description="element size along instruments [m] (default: no refinement)")
    order: Annotated[Literal[1, 2], BeforeValidator(_whole)] = Field(2, description="element order: 2 = quadratic triangles")
    growth: Annotated[float, BeforeValidator(_number), Field(gt=0.01, le=2.0)] = Field(
        0.25, description="element size grows by this fraction of the distance from the tunnel (and instruments)")


NAME = r"^[A-Za-z0-9_\-.]+$"
READING_UNITS = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "rad": 1.0, "mrad": 1e-3, "1/m": 1.0, "kN": 1.0, "MN": 1e3}


def _readings_shape(value: Any) -> str:
    return "by-stage" if isinstance(value, dict) else "in-order"


StageName = Annotated[str, Field(pattern=NAME)]


def _date(value: Any) -> Any:
    """A date as YAML reads it (2026-03-05) or a text in one of ``case.dates.FORMS``, as a datetime."""
    from geoback.case.dates import parse_date

    return parse_date(value)


Date = Annotated[Any, BeforeValidator(_date)]


def _period(value: Any) -> Any:
    """A stage's date: its start, or [start, end]."""
    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise ValueError(f"expected a date or [start, end], found a list of {len(value)}")
        start, end = (_date(v) for v in value)
        if end < start:
            raise ValueError(f"expected an end on or after the start, found [{value[0]}, {value[1]}]")
        return (start, end)
    return _date(value)


StagePeriod = Annotated[Any, BeforeValidator(_period)]


def _baseline(value: Any) -> Any:
    """A baseline survey: its date (as a datetime) when it reads as one, else its name in a survey column."""
    from geoback.case.dates import parse_date

    value = _header_text(value) if not hasattr(value, "year") else value
    try:
        return parse_date(value)
    except ValueError:
        if not value.strip():
            raise ValueError("expected a survey date or name, found an empty text") from None
        return value


Baseline = Annotated[Any, BeforeValidator(_baseline)]
# a list in station order, or a mapping stage -> list; the tags name the two shapes (dropped from
# error locations, which then follow the file: instruments[0].readings[3])
Readings = Annotated[Union[Annotated[list[Num], Tag("in-order")],
                           Annotated[dict[StageName, list[Num]], Tag("by-stage")]], Discriminator(_readings_shape)]


# what a readings file's column can mean (`columns:` maps a role to a header the file uses)
COLUMN_ROLES = ("instrument", "station", "point", "depth", "distance", "x", "y", "component", "reading",
                "settlement", "stage", "date", "survey")


def _header_text(value: Any) -> Any:
    """A column header or point ID as written; a number YAML read (101) is taken as its text."""
    if isinstance(value, bool) or isinstance(value, float):
        raise ValueError(f"expected a text, found {shown(value)}")
    return str(value) if isinstance(value, int) else value


HeaderText = Annotated[str, BeforeValidator(_header_text), Field(min_length=1)]


def _level(value: Any) -> Any:
    """A trigger level: a number (SI: m, rad, kN) or a number with its unit ('15 mm', '250 kN')."""
    if isinstance(value, str):
        m = re.match(r"^\s*([-+0-9.eE]+)\s*([A-Za-z/]+)?\s*$", value)
        if not m:
            raise ValueError(f"expected a level: a number or a number with its unit ('15 mm'), found {shown(value)}")
        unit = m.group(2)
        return (_number(m.group(1)), unit) if unit else _number(m.group(1))
    return _number(value)


Level = Annotated[Any, BeforeValidator(_level)]


class Triggers(Strict):
    """Trigger levels of a TARP: amber (review) and red (act) on a quantity's magnitude."""

    amber: Optional[Level] = Field(None, description="amber level (a number in SI units, or with its unit: '15 mm')")
    red: Optional[Level] = Field(None, description="red level (above amber)")


class _Instrument(Strict):
    name: str = Field(pattern=NAME, description="unique instrument name")
    readings: Optional[Readings] = Field(
        None, description="measured values in station order from the reference end, or a mapping stage: [values] "
                          "for readings taken at several stages (a list in a case with several construction stages "
                          "needs `stage`)")
    readings_file: Optional[str] = Field(
        None, description="CSV or text file with the readings (relative to the case file): a header row with a "
                          "reading column (reading, value, measured, displacement; settlement: positive down), a "
                          "position column (station, point, depth, distance from the reference end, x, y) unless "
                          "the file lists one instrument in station order, and optionally instrument, component, "
                          "stage, date and survey columns (several dated surveys: see baseline); a unit in the header such as 'reading [mm]'. Every column is used, mapped "
                          "(`columns`) or listed in `ignore_columns`; a reading written '', -, n/a or NaN is missing "
                          "and dropped with its row and column of C_x")
    readings_unit: Optional[Literal["m", "mm", "cm", "rad", "mrad", "1/m", "kN", "MN"]] = Field(
        None, description="unit of the readings (default SI: m for displacements and length changes, rad for slopes, "
                          "1/m for curvatures, kN for load cells)")
    stage: Optional[StageName] = Field(
        None, description="construction stage the readings were taken at, for a readings file without a stage column "
                          "or a list of inline readings (needed when the case has several construction stages)")
    columns: Optional[dict[Literal[COLUMN_ROLES], HeaderText]] = Field(
        None, description="the readings file's headers for what geoback reads, where the file names them otherwise: "
                          "{depth: 'Tiefe [m]', reading: 'Verschiebung [mm]'} (roles: " + ", ".join(COLUMN_ROLES) + ")")
    ignore_columns: Optional[list[HeaderText]] = Field(
        None, description="headers of readings-file columns geoback is to leave unread (a remark), by name "
                          "with or without the unit")
    baseline: Optional[Baseline] = Field(
        None, description="the zero survey in the readings file (its date, or its name in a survey column): "
                          "subtracted from every later survey; the stage in force on its date is the state the "
                          "instrument reads increments from (before the first stage: the ground before construction)")
    installed_after: Optional[StageName] = Field(
        None, description="the stage after which the instrument was installed and zeroed: its readings are increments "
                          "since then, x = P(u_k - u_installed) (implied by a dated baseline)")
    surveys: Literal["separate", "average"] = Field(
        "separate", description="several surveys within one stage: separate reading sets, each with its own C_x "
                                "(default), or their average with C_x / n")
    triggers: Optional[Triggers] = Field(
        None, description="trigger levels (TARP) on the magnitude of every reading, in the readings' unit: "
                          "{amber: 15 mm, red: 25 mm}")


class PointsInstrument(_Instrument):
    """Settlement points, prisms: chosen displacement components at listed points."""

    kind: Literal["points"]
    points: list[Point] = Field(min_length=1, description="[x, y] of each point [m]")
    components: list[Literal["ux", "uy"]] = Field(["ux", "uy"], min_length=1)
    sigma: PositiveLength = Field(description="standard deviation of each reading [m]")
    point_ids: Optional[Union[list[HeaderText], Literal["sorted"]]] = Field(
        None, description="the points' IDs in a readings file's point column, in the order of `points` ([SP-01, "
                          "SP-02, ...]); or 'sorted': the file's IDs in natural order (SP-2 before SP-10) are the "
                          "points in the order of `points`")
    sign: Optional[Literal["uy", "settlement"]] = Field(
        None, description="vertical readings as 'uy' (up positive, the default) or as 'settlement' (down positive, "
                          "as surveyors report them: u_y = -reading); a file's settlement column is taken as "
                          "settlement")

    @model_validator(mode="after")
    def _ids(self):
        if isinstance(self.point_ids, list):
            if len(self.point_ids) != len(self.points):
                raise ValueError(f"expected one point ID per point ({len(self.points)}), found "
                                 f"{len(self.point_ids)} in point_ids")
            twice = sorted({i for i in self.point_ids if self.point_ids.count(i) > 1})
            if twice:
                raise ValueError(f"expected point IDs different from each other, found {', '.join(twice)} more "
                                 f"than once in point_ids")
        if self.sign == "settlement" and "uy" not in self.components:
            raise ValueError("expected sign: settlement for an instrument reading uy (settlements are vertical), "
                             "found components " + ", ".join(self.components))
        return self


class _Linewise(_Instrument):
    spacing: Optional[PositiveLength] = Field(None, description="equal distance between stations [m]")
    stations: Optional[Count] = Field(None, gt=0, description="number of stations (with spacing)")
    lengths: Optional[list[PositiveLength]] = Field(None, min_length=1,
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
    x: Length = Field(description="horizontal position of the borehole [m] (x < 0: a full model's other side)")
    toe_depth: PositiveLength = Field(description="depth of the borehole's toe [m]")
    head_depth: NonNegativeLength = Field(0.0, description="depth of the borehole's head [m]")
    reference: Literal["toe", "head"] = Field("toe", description="end the readings are integrated from")
    readings_relative: Annotated[bool, BeforeValidator(_flag)] = Field(
        True, description="true (field practice): the readings are movements relative to the reference end, as "
                          "integrated from an end assumed fixed, and the model is compared as u(z) - u(reference end); "
                          "false: absolute displacements (the reference end surveyed)")
    sigma: Positive = Field(description="standard deviation of one slope reading [rad]")
    var_b: NonNegative = Field(0.0, description="variance of the integration constant B [m2]: the reference end's "
                                                "movement beyond what the model computes for it")


class SlidingMicrometer(_Linewise):
    """Straight measuring line from `start` (reference end) towards `end` (eqns 11-14)."""

    kind: Literal["sliding_micrometer", "extensometer"]
    start: Point = Field(description="reference end [x, y] [m]")
    end: Point = Field(description="other end [x, y] [m]; displacement is positive from start to end")
    readings_relative: Annotated[bool, BeforeValidator(_flag)] = Field(
        False, description="true: the readings are movements relative to the reference end (start), compared with "
                           "u - u(start); false (default): absolute displacements (the head surveyed)")
    sigma: PositiveLength = Field(description="standard deviation of one length-change reading [m]")
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
    sigma: PositiveLength = Field(description="standard deviation of the reading [m]")


class LoadCell(_Instrument):
    """A load cell on a prop or an anchor: reads the axial force of one prop or anchor [kN] (a prop's
    compression, an anchor's tension; per metre run when the support gives no spacing), less the cell's
    own reading at installation (`zero`)."""

    kind: Literal["load_cell"]
    support: str = Field(pattern=NAME, description="the prop or anchor it reads (construction.props / anchors)")
    sigma: Positive = Field(description="standard deviation of one reading [kN]")
    zero: Num = Field(0.0, description="the cell's reading at installation [kN], subtracted from every reading")


Instrument = Annotated[Union[PointsInstrument, Inclinometer, SlidingMicrometer, Deflectometer,
                             Convergence, LoadCell], Field(discriminator="kind")]


class Prior(Strict):
    mean: Num
    std: Positive


_NAME = r"^[A-Za-z0-9_\-.]+$"


MAX_PRIOR_DOF = 1e6  # an inverse-chi2 prior worth more readings than this is a known scale


class ScalePrior(Strict):
    """What is known of the factor k = true sigma / stated sigma before the readings: the stated
    sigma is right within a factor `within` with probability `level` (1/within <= k <= within)."""

    shape: Literal["lognormal", "inverse-chi2"] = Field(
        "lognormal", description="prior of k: 'lognormal' (ln k normal) or 'inverse-chi2' (k^2 scaled "
                                 "inverse-chi-square, centred on 1; conjugate: the prior counts as `dof` readings)")
    within: Optional[Annotated[float, BeforeValidator(_number)]] = Field(
        None, description="the true sigma is within this factor of the stated one (a number above 1, e.g. 2)")
    level: Annotated[float, BeforeValidator(_number), Field(gt=0, lt=1)] = Field(
        0.95, description="prior probability of 1/within <= k <= within")
    dof: Optional[Positive] = Field(None, description="inverse-chi2 only, instead of `within`: the stated sigma "
                                                      "is worth this many readings")

    @field_validator("within")
    @classmethod
    def _above_one(cls, v):
        if v is not None and not v > 1:
            raise ValueError(f"expected a factor greater than 1 (within: 1 would say the stated sigma is exact: "
                             f"give the instruments scale: known), found {number_text(v)}")
        return v

    @field_validator("dof")
    @classmethod
    def _finite_information(cls, v):
        if v is not None and v > MAX_PRIOR_DOF:
            raise ValueError(f"expected at most {MAX_PRIOR_DOF:g} degrees of freedom (a stated sigma worth more readings "
                             f"than that is exact: give the instruments scale: known), found {number_text(v)}")
        return v

    @model_validator(mode="after")
    def _one_width(self):
        if self.dof is not None and self.shape != "inverse-chi2":
            raise ValueError("expected 'within' for a lognormal prior ('dof' is for shape: inverse-chi2), found dof")
        if (self.within is None) == (self.dof is None):
            raise ValueError("expected the prior's width as 'within' (a factor above 1)"
                             + (" or 'dof'" if self.shape == "inverse-chi2" else "")
                             + (", found both" if self.within is not None else ", found neither"))
        return self


class ErrorScale(Strict):
    """How well the stated sigma of some instruments is known (eqn 10: C_x,i = k^2 x the stated
    C_x,i). The listed instruments share one factor k; instruments not listed keep their stated sigma
    (k = 1). 'estimate' identifies k with the parameters (maximum likelihood of the full support
    function, eqn 5, with the restricted correction for the parameters' degrees of freedom);
    with a `prior`, k is estimated with that prior."""

    name: Optional[str] = Field(None, pattern=_NAME,
                                description="name of the group in reports (default: its instruments' names)")
    instruments: list[Annotated[str, Field(pattern=_NAME)]] = Field(
        min_length=1, description="names of the instruments sharing the factor k")
    scale: Literal["known", "estimate"] = Field(
        "estimate", description="'estimate': the stated sigma is right up to a factor k, estimated with the "
                                "parameters; 'known': k = 1 (the default for instruments not listed)")
    prior: Optional[ScalePrior] = Field(None, description="prior on k (scale: estimate only)")

    @model_validator(mode="after")
    def _prior_needs_estimate(self):
        if self.prior is not None and self.scale == "known":
            raise ValueError("expected no prior for a known scale (scale: estimate to give k a prior), found a prior")
        return self


PARAMETER_NAME = r"^[A-Za-z_][A-Za-z0-9_]*(\[[^\[\]\n]+\])?$"  # E, K0, E[layer], B[instrument]; an integration
# constant of one survey carries its reading set, e.g. B[I1.advance@2026-03-05 08:30] (observation/instruments.py)


class Parameter(Strict):
    """A quantity to identify: 'E[layer]', 'nu[layer]', 'K0', 'K0[layer]', 'B[instrument]', ..."""

    name: str = Field(pattern=PARAMETER_NAME)
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
    mesh_error: Literal["check", "include", "ignore"] = Field(
        "check", description="discretisation error of the readings, from one run at the estimate on a mesh twice as "
                             "fine: 'check' reports it against each reading's sigma (a warning above 0.3 sigma); "
                             "'include' adds it to C_x and fits again; 'ignore' skips the check")


class Lining(Strict):
    """An elastic lining: a ring of its real thickness inside the excavated boundary (meshed with
    `layers` quadratic elements through the thickness), installed stress-free at a stage."""

    name: str = Field("lining", pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$",
                      description="name of the lining (its parameters are E[name] and nu[name])")
    thickness: PositiveLength = Field(description="thickness of the lining [m]; its outer face is the excavated wall")
    E: Stress = Field(gt=0, description="Young's modulus of the lining [kPa] (or '30 GPa')")
    nu: Num = Field(ge=0.0, lt=0.5, description="Poisson's ratio of the lining, 0 <= nu < 0.5")
    layers: Annotated[int, BeforeValidator(_whole), Field(ge=1, le=8)] = Field(
        2, description="quadratic elements through the lining's thickness (bending needs at least 2)")


class PlacedLining(Lining):
    """A lining of an opening of any shape (geometry with openings): a band of its real thickness inside
    the wall of an opening or of a part (`on`), or along a part's cut lines (`side: cut`, a temporary
    invert), meshed with the ground and activated stress-free by the stage that installs it."""

    on: str = Field(pattern=r"^[A-Za-z_][A-Za-z0-9_\-]*$", description="the opening or part whose wall it lines")
    side: Literal["wall", "cut"] = Field("wall", description="'wall': along the opening's wall within `on`; 'cut': "
                                                            "along the cut lines of the part `on` (a temporary invert)")


_LINE_FORCE_UNITS = {"kn/m": 1.0, "mn/m": 1e3}
_SPRING_UNITS = {"kn/m/m": 1.0, "mn/m/m": 1e3, "kn/m2": 1.0, "mn/m2": 1e3, "kpa": 1.0, "mpa": 1e3}


def _line_force(value: Any) -> Any:
    """A force per metre run [kN/m]: a number, or '450 kN/m', '0.5 MN/m' (a force per prop is divided by
    the spacing first: 'kN' alone is refused)."""
    return _with_unit(value, _LINE_FORCE_UNITS, "kn/m", "force per metre run", "kN/m or MN/m (per metre run)",
                      f"expected a force per metre run: a number in kN/m or with a unit like '300 kN/m', found "
                      f"{shown(value)}")


def _spring(value: Any) -> Any:
    """A stiffness per metre run [kN/m per m]: a number, or '5e4 kN/m/m', '50 MN/m/m'."""
    return _with_unit(value, _SPRING_UNITS, "kn/m/m", "stiffness per metre run", "kN/m/m or MN/m/m",
                      f"expected a stiffness per metre run: a number in kN/m/m or with a unit like '50 MN/m/m', "
                      f"found {shown(value)}")


LineForce = Annotated[float, BeforeValidator(_line_force)]
Spring = Annotated[float, BeforeValidator(_spring)]
_SUPPORT_NAME = r"^[A-Za-z_][A-Za-z0-9_\-]*$"


class Wall(Strict):
    """An embedded retaining wall (diaphragm, secant-pile, sheet-pile): a vertical band of its real
    thickness centred on `x`, from depth `top` to `toe`, meshed with the ground in quadratic elements
    (`layers` through its thickness) and switched to the wall's material when installed (in place from
    the start unless a stage installs it). Give `thickness` and `E`, or the section's `EA` and `EI` per
    metre run (the band then has t = sqrt(12 EI / EA) and E = EA / t)."""

    name: str = Field(pattern=_SUPPORT_NAME, description="wall name (its values are E[name] and nu[name])")
    x: Length = Field(description="x of the wall's centreline [m]")
    top: NonNegativeLength = Field(0.0, description="depth of the wall's top [m] (0: the ground surface)")
    toe: PositiveLength = Field(description="depth of the wall's toe [m]")
    thickness: Optional[PositiveLength] = Field(None, description="thickness [m] (with E)")
    E: Optional[Stress] = Field(None, gt=0, description="Young's modulus [kPa] (or '30 GPa'), with thickness")
    EA: Optional[Positive] = Field(None, description="axial stiffness per metre run [kN/m] (with EI)")
    EI: Optional[Positive] = Field(None, description="bending stiffness per metre run [kNm2/m] (with EA)")
    nu: Num = Field(ge=0.0, lt=0.5, description="Poisson's ratio of the wall, 0 <= nu < 0.5")
    layers: Annotated[int, BeforeValidator(_whole), Field(ge=2, le=8)] = Field(
        3, description="quadratic elements through the wall's thickness (bending needs at least 2)")


class Prop(Strict):
    """A prop (strut, slab) at a depth on a wall, installed by a stage: a spring of axial stiffness per
    metre run `stiffness`, or E * area / (spacing * length); to a fixed point (the symmetry plane of a
    half-model: the spring has half the prop's length) or to another wall (`to`). Stress-free when
    installed, or carrying `preload` from then on."""

    name: str = Field(pattern=_SUPPORT_NAME, description="prop name (its values are k[name] and preload[name])")
    wall: str = Field(pattern=_SUPPORT_NAME, description="the wall it props")
    depth: NonNegativeLength = Field(description="depth of the prop's axis [m]")
    to: Optional[str] = Field(None, pattern=_SUPPORT_NAME, description="the wall at its other end (default: a "
                                                                        "fixed point, the symmetry plane of a half-model)")
    stiffness: Optional[Spring] = Field(None, gt=0, description="axial stiffness per metre run [kN/m/m]")
    E: Optional[Stress] = Field(None, gt=0, description="Young's modulus of the prop [kPa] (with area, spacing)")
    area: Optional[Annotated[float, BeforeValidator(_number), Field(gt=0)]] = Field(
        None, description="cross-section area of one prop [m2]")
    spacing: Optional[PositiveLength] = Field(None, description="horizontal spacing of the props along the wall [m] "
                                                                 "(1: a slab, or per metre run)")
    length: Optional[PositiveLength] = Field(None, description="prop length [m] (default: from wall to wall, or "
                                                                "twice the distance to the symmetry plane)")
    preload: LineForce = Field(0.0, ge=0, description="preload per metre run [kN/m] applied at installation")


class Anchor(Strict):
    """A ground anchor from a wall point at `depth`, inclined `angle` degrees below the horizontal into
    the retained ground: a free length acting as a spring (`stiffness`, or E * area / (spacing *
    free_length)), and a fixed length bonded to the ground (the anchor force passes into the ground
    evenly along it). Locked off at `preload` when installed."""

    name: str = Field(pattern=_SUPPORT_NAME, description="anchor name (its values are k[name] and preload[name])")
    wall: str = Field(pattern=_SUPPORT_NAME, description="the wall it holds")
    depth: NonNegativeLength = Field(description="depth of the anchor head on the wall [m]")
    angle: Annotated[float, BeforeValidator(_number), Field(ge=0, lt=90)] = Field(
        description="inclination below the horizontal [degrees]")
    free_length: PositiveLength = Field(description="free (tendon) length [m]")
    fixed_length: PositiveLength = Field(description="fixed (grouted, bonded) length [m]")
    stiffness: Optional[Spring] = Field(None, gt=0, description="axial stiffness of the free length per metre run "
                                                                "[kN/m/m]")
    E: Optional[Stress] = Field(None, gt=0, description="Young's modulus of the tendon [kPa] (with area, spacing)")
    area: Optional[Annotated[float, BeforeValidator(_number), Field(gt=0)]] = Field(
        None, description="cross-section area of one tendon [m2]")
    spacing: Optional[PositiveLength] = Field(None, description="horizontal spacing of the anchors [m]")
    preload: LineForce = Field(0.0, ge=0, description="lock-off load per metre run [kN/m]")


class Stage(Strict):
    """One construction step. In a stage the lining named by `install` is placed first (stress-free,
    on the wall as it has moved so far), then the in-situ stress on the tunnel wall is released up to
    the cumulative fraction `release`. With openings (geometry with `openings`): the parts or openings
    in `excavate` and the linings in `remove` are removed first, the linings in `install` placed, then
    `release` (default 1) is the cumulative fraction of the removed elements' load released."""

    name: StageName = Field(description="stage name (readings are tagged with it)")
    release: Optional[Annotated[float, BeforeValidator(_number), Field(gt=0.0, le=1.0)]] = Field(
        None, description="cumulative fraction of the in-situ stress on the tunnel wall released by the end of "
                          "this stage (beta_k, 0 < beta <= 1, increasing from stage to stage)")
    install: Optional[Union[str, list[str]]] = Field(None, description="name(s) of the lining(s) installed at the "
                                                                      "start of this stage (with openings: "
                                                                      "linings, walls, props or anchors)")
    excavate: Optional[list[str]] = Field(None, description="with openings: parts or openings excavated (their "
                                                            "elements removed) in this stage")
    remove: Optional[list[str]] = Field(None, description="with openings: linings removed in this stage (a "
                                                          "temporary invert)")
    date: Optional[StagePeriod] = Field(
        None, description="when the stage began (2026-03-05), or [start, end]: dated surveys are placed in the stage "
                          "in force on their date (give every stage a date, or none)")


class Construction(Strict):
    """Staged construction (convergence-confinement): stress released in steps, a lining between them."""

    lining: Optional[Lining] = Field(None, description="the lining (installed by a stage's 'install')")
    linings: Optional[list[PlacedLining]] = Field(None, description="with openings: the linings, each placed on an "
                                                                    "opening's or a part's wall")
    walls: Optional[list[Wall]] = Field(None, description="with openings: embedded retaining walls")
    props: Optional[list[Prop]] = Field(None, description="with openings: props (struts, slabs) on the walls")
    anchors: Optional[list[Anchor]] = Field(None, description="with openings: ground anchors on the walls")
    stages: list[Stage] = Field(min_length=1, description="construction stages in order")


class _Forecast(Strict):
    name: str = Field(pattern=NAME, description="unique forecast name (files and figures use it)")
    stage: Optional[StageName] = Field(None, description="construction stage the forecast is for (default: the last)")
    alert: Optional[Positive] = Field(
        None, description="alert level of the forecast quantity's magnitude, in its unit (m, kN/m, kNm/m; kN per prop or anchor): the "
                          "probability that it is exceeded is reported")
    triggers: Optional[Triggers] = Field(
        None, description="trigger levels (TARP) on the forecast quantity's magnitude: {amber: 20 mm, red: 30 mm}")


class PointsForecast(_Forecast):
    """Displacement components at listed points (a building, a utility)."""

    kind: Literal["points"]
    points: list[Point] = Field(min_length=1, description="[x, y] of each point [m]")
    components: list[Literal["ux", "uy"]] = Field(["uy"], min_length=1)


class LineForecast(_Forecast):
    """A displacement component at evenly spaced points of a straight line (a settlement trough)."""

    kind: Literal["line"]
    start: Point = Field(description="first point [x, y] [m]")
    end: Point = Field(description="last point [x, y] [m]")
    points: Annotated[int, BeforeValidator(_whole), Field(ge=2, le=2000)] = Field(
        41, description="number of evenly spaced points from start to end")
    component: Literal["ux", "uy"] = Field("uy", description="displacement component (uy: up positive)")


class ChordForecast(_Forecast):
    """Change of length of a chord between two points (convergence; shortening negative)."""

    kind: Literal["convergence"]
    points: tuple[Point, Point]


class InstrumentForecast(_Forecast):
    """What an instrument of the case will read at `stage` (its readings convention; integration
    constants of a future survey not included)."""

    kind: Literal["instrument"]
    instrument: str = Field(pattern=NAME, description="name of an instrument of the case")


class LiningForecast(_Forecast):
    """Section forces around the lining (thrust N [kN/m], bending moment M [kNm/m], shear V [kN/m])."""

    kind: Literal["lining"]
    quantities: list[Literal["N", "M", "V"]] = Field(["N", "M"], min_length=1)


class SupportForecast(_Forecast):
    """The axial force of a prop (compression +) or a ground anchor (tension +) at `stage`: per prop or
    anchor [kN] when the support gives a spacing, else per metre run of wall [kN/m]."""

    kind: Literal["support"]
    support: str = Field(pattern=NAME, description="the prop or anchor (construction.props / anchors)")


class WallForecast(_Forecast):
    """A retaining wall's bending moment M [kNm/m], shear V [kN/m] or deflection ux [m] (+ towards larger
    x) against depth at `stage`, per metre run."""

    kind: Literal["wall"]
    wall: str = Field(pattern=NAME, description="the wall (construction.walls)")
    quantities: list[Literal["M", "V", "ux"]] = Field(["M"], min_length=1)


Forecast = Annotated[Union[PointsForecast, LineForecast, ChordForecast, InstrumentForecast, LiningForecast,
                           SupportForecast, WallForecast], Field(discriminator="kind")]


class _Candidate(Strict):
    """An instrument that could be installed: defined as in `instruments` (without readings), read at
    `read_at`; `vary` makes one candidate per value of one of its fields (e.g. {x: [3, 6, 9]})."""

    read_at: Optional[StageName] = Field(None, description="stage the candidate would be read at (default: the "
                                                           "last stage with readings)")
    vary: Optional[dict[str, list[Any]]] = Field(
        None, description="one field and its values, one candidate per value (e.g. {x: [3, 6, 9, 12]})")


class PointsCandidate(PointsInstrument, _Candidate):
    pass


class InclinometerCandidate(Inclinometer, _Candidate):
    pass


class SlidingMicrometerCandidate(SlidingMicrometer, _Candidate):
    pass


class DeflectometerCandidate(Deflectometer, _Candidate):
    pass


class ConvergenceCandidate(Convergence, _Candidate):
    pass


Candidate = Annotated[Union[PointsCandidate, InclinometerCandidate, SlidingMicrometerCandidate,
                            DeflectometerCandidate, ConvergenceCandidate], Field(discriminator="kind")]


class Design(Strict):
    """`geoback design`: which candidate instrument would narrow the forecasts (or C_p) most."""

    objective: Optional[Literal["forecasts", "parameters"]] = Field(
        None, description="'forecasts': the variance of the target forecasts; 'parameters': ln det C_p (default: "
                          "forecasts if the case has any)")
    forecasts: Optional[list[Annotated[str, Field(pattern=NAME)]]] = Field(
        None, description="names of the forecasts to narrow (default: all)")
    candidates: list[Candidate] = Field(min_length=1, description="candidate instruments")


class TroughSettings(Strict):
    """`trough:`: what the settlement trough (``worth.trough``) is fitted to and read against; every
    field optional (default: every settlement-point instrument reading u_y at the surface, every stage,
    x0 at the symmetry axis or fitted, z0 the tunnel axis' depth or the excavated centroid's)."""

    instruments: Optional[list[Annotated[str, Field(pattern=NAME)]]] = Field(
        None, description="settlement-point instruments (kind points, u_y at the surface) whose readings are fitted")
    stages: Optional[list[StageName]] = Field(None, description="stages to fit the trough of (default: every stage)")
    axis_x: Optional[Length] = Field(None, description="full model: x of the trough's centre x0 [m], fixed "
                                                       "(default: fitted, or the excavated opening's centre)")
    z0: Optional[PositiveLength] = Field(None, description="depth z0 for K = i / z0 [m] (default: the tunnel "
                                                           "axis' depth, or the excavated ground's centroid)")
    extent: Optional[PositiveLength] = Field(None, description="the model's profile is fitted from the axis out "
                                                               "to this distance [m] (default: the farthest "
                                                               "settlement point read, else 2.5 z0)")


class Building(Strict):
    """A building as a line at its foundation level, assessed for damage on the greenfield movement
    (``worth.damage``: Burland & Wroth 1974, Burland 1995)."""

    name: str = Field(pattern=NAME, description="building name")
    x_start: Length = Field(description="x of the building's end nearer to smaller x [m]")
    length: PositiveLength = Field(description="length of the building across the tunnel [m]")
    height: PositiveLength = Field(description="height of the building's facade above the foundation [m]")
    foundation_depth: NonNegativeLength = Field(0.0, description="depth of the foundation below the surface [m]")
    E_over_G: Positive = Field(2.6, description="E/G of the deep beam (2.6: isotropic masonry; 12.5: frames)")
    nu: Num = Field(0.3, ge=0.0, lt=0.5, description="Poisson's ratio in the combined diagonal strain")
    stage: Optional[StageName] = Field(None, description="the stage to assess (default: every stage)")


class Output(Strict):
    dir: Optional[str] = Field(None, description="results directory (default results/<name>)")
    vtu: Annotated[bool, BeforeValidator(_flag)] = True


class Case(Strict):
    name: str = Field(pattern=r"^[A-Za-z0-9_\-.]+$")
    description: str = ""
    geometry: Annotated[Union[Annotated[Geometry, Tag("circular")], Annotated[Layout, Tag("layout")]],
                        Discriminator(_geometry_shape)]
    ground: Ground
    mesh: MeshSettings = MeshSettings()
    instruments: list[Instrument] = Field(default_factory=list)
    construction: Optional[Construction] = Field(
        None, description="construction stages (release fractions, a lining); default: one excavation step")
    error_scales: list[ErrorScale] = Field(
        default_factory=list, description="instruments whose stated sigma is known only up to a factor "
                                          "(estimated with the parameters); the others' sigma is taken as exact")
    parameters: list[Parameter] = Field(default_factory=list)
    fit: FitSettings = FitSettings()
    forecasts: list[Forecast] = Field(
        default_factory=list, description="quantities to forecast at the estimate with their 95 % band (points, "
                                          "lines, chords, an instrument's next readings, the lining's forces)")
    design: Optional[Design] = Field(None, description="candidate instruments for `geoback design`")
    trough: Optional[TroughSettings] = Field(
        None, description="the settlement trough's fit (optional: tunnels with surface settlement readings get one)")
    buildings: list[Building] = Field(
        default_factory=list, description="buildings assessed for damage on the greenfield movement (a line each)")
    output: Output = Output()
