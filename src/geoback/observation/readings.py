"""Measured readings, inline in the case or from files, matched to the instruments' stations.

Readings are matched, never assumed to be in order: a file row names its instrument (or the file
serves one instrument), its position (station number from the reference end, a point's ID, depth
below the surface, distance from the reference end, x, y: any of them, each checked against the
others) and, for settlement points, its component; rows may come in any order, head-first
inclinometer exports included. Every column of a file is used, mapped to what it means by the
case (``columns``) or listed in ``ignore_columns``; an unknown column is refused, never dropped.
Duplicates, gaps, unknown or out-of-range positions, unknown instruments and rows no instrument
takes are errors that name the file, line and station. Headers are case-insensitive, may carry the
unit ('reading [mm]') and are recognised in common spellings (depth, Tiefe, profondeur, z; point,
pt, id; offset for x; settlement, positive down); the delimiter is sniffed (comma, semicolon, tab,
bar, spaces; a decimal comma with ';' or tabs); UTF-8 with or without a byte-order mark, UTF-16 with
one, and Windows-1252 are read. A row at a linewise instrument's reference end (an inclinometer
export's toe row) is checked to read zero and not used. A reading written as an empty cell, '-',
'n/a' or 'NaN' is missing: its row and column of C_x are dropped (``InstrumentBlock.without``).

Inline readings are a list in station order from the reference end or a mapping stage: [values].
Every reading is placed in a construction stage by a stage column, the mapping's keys, the
instrument's ``stage`` or, in a case of one stage, that stage; a case of several stages refuses
readings none of these place. How each instrument's readings were matched is returned with them
(``Matching``; `geoback validate` and `geoback run` print it). Primary readings of linewise
instruments (slopes, length changes, curvatures) are integrated into displacements with the
constants taken as zero (eqns 11, 15, 18); both forms then give the same objective (eqns 21-26).
"""
from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from geoback.case.dates import stage_periods
from geoback.case.loading import LoadedCase
from geoback.case.messages import more_problems
from geoback.case.schema import READING_UNITS
from geoback.errors import CaseError
from geoback.observation.instruments import LINEWISE_KINDS, InstrumentBlock
from geoback.observation.surveys import SetInfo, Sets, Surveys, averaged

ROLE_WORDS = {  # what a column means -> its headers (lower case, unit removed, '_' and '-' as spaces)
    "instrument": ("instrument", "name", "instrument name", "instrument id", "sensor"),
    "station": ("station", "station no", "station number", "stn"),
    "point": ("point", "pt", "id", "point id", "point name", "punkt"),
    "depth": ("depth", "tiefe", "profondeur", "profundidad", "z"),
    "distance": ("distance", "dist", "abstand", "distanz"),
    "x": ("x", "offset"),
    "y": ("y",),
    "component": ("component", "comp"),
    "reading": ("reading", "value", "measured", "displacement", "force", "load"),
    "settlement": ("settlement", "setzung", "tassement"),  # positive down: u_y = -settlement
    "stage": ("stage", "construction stage", "phase"),
    "date": ("date", "survey date", "reading date", "datum", "date time", "datetime", "timestamp"),
    "survey": ("survey", "survey no", "survey number", "survey name", "set", "messung"),
}
COLUMNS = {word: role for role, words in ROLE_WORDS.items() for word in words}
POSITIONS = ("depth", "distance", "x", "y")  # coordinates [m]; station and point are numbers or IDs
MISSING = {"", "-", "n/a", "na", "nan", "\u2013", "\u2014"}  # a reading not taken (compared in lower case)
DELIMITERS = ",;\t|"
POSITION_TOLERANCE = 0.02  # a position within this fraction of the distance to the next station (at most 5 cm)
REFERENCE_TOLERANCE = 1e-6  # a reference-end row reads zero within this, in SI units (1 µm, 1 µrad)
MAX_FILE_BYTES = 50_000_000
REFERENCE = -1  # the row index of a reference-end row


@dataclass
class Table:
    """A readings file parsed: headers (as written, as names without unit, and their units), rows
    with their line numbers; what each column means is decided per instrument (``_columns``)."""

    path: Path
    header_line: int
    names: list[str]  # headers as written
    keys: list[str]  # lower case, unit removed
    units: list[str | None]
    rows: list[tuple[int, list[str]]]
    decimal_comma: bool
    taken: set = field(default_factory=set)  # line numbers some instrument used

    def where(self, line: int | None = None) -> str:
        return f"{self.path.name}" + (f", line {line}" if line else "")


@dataclass(frozen=True)
class Matching:
    """How one instrument's readings were read: from where, how its rows were placed at its
    stations and in construction stages, and what was checked or dropped on the way."""

    instrument: str
    source: str  # 'inline' or the readings file's name
    how: str  # 'by station', 'by depth', ..., 'in station order'
    count: int  # readings taken (missing ones not counted)
    stages: tuple  # ((stage, count), ...) in construction order
    staged_by: str  # the stage column, the mapping's keys, the case's stage:, the only stage
    missing: tuple = ()  # readings marked missing, in words ('station 4 (line 5)')
    details: tuple = ()  # reference rows checked, signs converted, columns ignored or mapped

    def text(self) -> str:
        src = "inline" if self.source == "inline" else f"from {self.source}"
        if len(self.stages) == 1:
            at = f"at stage {self.stages[0][0]} ({self.staged_by})"
        else:
            at = ", ".join(f"{s} {n}" for s, n in self.stages) + f" ({self.staged_by})"
        parts = [f"{self.instrument}: {self.count} reading{'s' if self.count != 1 else ''} {src} {self.how}", at]
        if self.missing:
            parts.append(f"marked missing and dropped (their rows and columns of C_x): "
                         f"{', '.join(self.missing[:8])}{', ...' if len(self.missing) > 8 else ''}")
        return "; ".join(parts + list(self.details))


@dataclass
class CaseReadings:
    """Readings of every instrument: values {instrument: {set: values in station order}} in SI
    units and displacement form, NaN where a reading is marked missing ({} for an instrument
    without readings), a set being a stage or, for dated surveys, 'stage@survey' (``sets`` says
    which: {instrument: Sets}); how each was matched (``notes``); the instruments without readings."""

    values: dict
    notes: list
    unread: list
    sets: dict = field(default_factory=dict)

    def lines(self) -> list[str]:
        """What `geoback validate` and `geoback run` print: how each instrument's readings were
        matched, one line each, and the instruments without readings."""
        return [n.text() for n in self.notes] + ([self.unread_line()] if self.unread else [])

    def unread_line(self) -> str:
        return (f"no readings: {', '.join(self.unread)} - run needs readings of every instrument (a forward "
                f"run, `geoback simulate`, does not)")


class ReadingsError(CaseError):
    pass


# ---------------------------------------------------------------------------------------- files
def _decode(data: bytes) -> str:
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        text = data.decode("utf-16")
    else:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = data.decode("cp1252", errors="strict")
    return text.lstrip("\ufeff")  # byte-order marks, even one written twice


def _split_unit(header: str) -> tuple[str, str | None]:
    m = re.fullmatch(r"\s*(.*?)\s*(?:[\[(]\s*([^\])]*?)\s*[\])])?\s*", header)
    name, unit = m.group(1), m.group(2)
    return " ".join(name.strip().lower().replace("_", " ").replace("-", " ").split()), (unit or None)


def read_table(path: Path, fail) -> Table:
    """Parse a readings file; fail(message) builds the located error."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise fail(f"readings file not found: {path}") from None
    except IsADirectoryError:
        raise fail(f"expected a readings file, found a directory: {path}") from None
    except OSError as exc:
        raise fail(f"cannot read the readings file {path} ({exc.strerror or exc})") from None
    if len(data) > MAX_FILE_BYTES:
        raise fail(f"readings file {path} is {len(data) / 1e6:.0f} MB: expected at most {MAX_FILE_BYTES / 1e6:.0f} MB")
    try:
        text = _decode(data)
    except UnicodeDecodeError as exc:
        raise fail(f"{path.name}: expected text (UTF-8, UTF-16 or Windows-1252), found undecodable bytes at "
                   f"byte {exc.start}") from None
    if "\x00" in text:
        raise fail(f"{path.name}: expected a text file, found binary data (NUL bytes)")
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise fail(f"readings file {path.name} has no rows")
    counts = {d: min(ln.count(d) for _, ln in lines[:20]) for d in DELIMITERS}
    delim = max(DELIMITERS, key=lambda d: counts[d]) if max(counts.values()) > 0 else None
    header_line, header = lines[0]
    if delim is None:
        split = (lambda ln: ln.split())
    else:
        split = (lambda ln: next(csv.reader(io.StringIO(ln), delimiter=delim, skipinitialspace=True)))
    names = [h.strip() for h in split(header)]
    keys, units = zip(*(_split_unit(h) for h in names)) if names else ((), ())
    rows = []
    for line, text_line in lines[1:]:
        fields = [f.strip() for f in split(text_line)]
        if len(fields) != len(names):
            raise fail(f"{path.name}, line {line}: expected {len(names)} fields as in the header, found {len(fields)}")
        rows.append((line, fields))
    if not rows:
        raise fail(f"readings file {path.name} has a header but no readings")
    decimal_comma = delim in (";", "\t", "|", None) and any(
        re.fullmatch(r"[-+]?\d+,\d+(?:[eE][-+]?\d+)?", f) for _, r in rows for f in r)
    return Table(path, header_line, names, list(keys), list(units), rows, decimal_comma)


def _number(table: Table, line: int, text: str, what: str, fail) -> float:
    t = text.replace(",", ".") if table.decimal_comma else text
    try:
        v = float(t)
    except ValueError:
        raise fail(f"{table.where(line)}: expected a number for the {what}, found '{text}'") from None
    if not np.isfinite(v):
        raise fail(f"{table.where(line)}: expected a finite {what}, found '{text}' "
                   f"({'not a number' if np.isnan(v) else 'infinite'})")
    return v


# ---------------------------------------------------------------------------------------- columns
@dataclass
class _Columns:
    """What the columns of a file mean for one instrument: role -> column, the unit of each role
    given in its header, and the columns mapped or ignored by the case."""

    roles: dict
    units: dict
    ignored: list
    mapped: list


def _header_matches(table: Table, text: str) -> list[int]:
    """Columns a header written in the case names: as written, or by name without its unit."""
    t = text.strip().lower()
    exact = [j for j, n in enumerate(table.names) if n.lower() == t]
    return exact or [j for j, k in enumerate(table.keys) if k == _split_unit(text)[0]]


def _columns(table: Table, ins, err) -> _Columns:
    """The meaning of every column of `table` for instrument `ins`: mapped by the case (columns:),
    ignored by it (ignore_columns:) or recognised by its header; any other column is refused."""
    at_file = ("readings_file",)
    listing = ", ".join(repr(n) for n in table.names)
    roles, units, mapped, ignored = {}, {}, [], []
    for role, header in (ins.columns or {}).items():
        found = _header_matches(table, header)
        if len(found) != 1:
            raise err(("columns", role), f"expected one column '{header}' in {table.path.name}, found "
                                         f"{'none' if not found else f'{len(found)}'} (columns: {listing})")
        if found[0] in roles.values():
            raise err(("columns", role), f"expected each column mapped once, found '{header}' mapped again")
        roles[role] = found[0]
        mapped.append(f"{table.names[found[0]]} as {role}")
    skip = set()
    for k, header in enumerate(ins.ignore_columns or []):
        found = _header_matches(table, header)
        if not found:
            raise err(("ignore_columns", k), f"expected a column of {table.path.name} to ignore, found '{header}', "
                                             f"which is none of its columns ({listing})")
        clash = [j for j in found if j in roles.values()]
        if clash:
            raise err(("ignore_columns", k), f"expected a column either mapped or ignored, found "
                                             f"'{table.names[clash[0]]}' both in columns and ignore_columns")
        skip.update(found)
        ignored += [table.names[j] for j in found]
    unknown = []
    for j, key in enumerate(table.keys):
        if j in roles.values() or j in skip:
            continue
        role = COLUMNS.get(key)
        if role is None:
            unknown.append(j)
            continue
        if role in roles:
            raise err(at_file, f"{table.where(table.header_line)}: two columns mean the {role} "
                               f"('{table.names[roles[role]]}' and '{table.names[j]}'); expected one (map the one "
                               f"meant with columns: {{{role}: ...}}, list the other in ignore_columns)")
        roles[role] = j
    if "reading" not in roles and "settlement" not in roles:
        raise err(at_file, f"{table.where(table.header_line)}: expected a header with a column named reading, value, "
                           f"measured, displacement or settlement (or columns: {{reading: ...}}), found {listing}")
    if unknown:
        names = ", ".join(repr(table.names[j]) for j in unknown)
        placed = any(r in roles for r in ("station", "point") + POSITIONS)
        role = "<what it holds>" if placed else {"inclinometer": "depth", "points": "x"}.get(ins.kind, "distance")
        one = len(unknown) == 1
        raise err(at_file, f"{table.where(table.header_line)}: expected columns geoback reads ("
                           f"{', '.join(ROLE_WORDS)}, in their usual spellings), found {names}, which geoback does "
                           f"not know: say what {'it holds' if one else 'each holds'} for '{ins.name}' with columns: "
                           f"{{{role}: {table.names[unknown[0]]!r}}}, or list {'it' if one else 'them'} in "
                           f"ignore_columns if {'it is' if one else 'they are'} not needed")
    for one, other in (("reading", "settlement"), ("station", "point")):
        if one in roles and other in roles:
            raise err(at_file, f"{table.where(table.header_line)}: two columns give the {one} "
                               f"('{table.names[roles[one]]}' and '{table.names[roles[other]]}'); expected one")
    for role, j in roles.items():
        if table.units[j]:
            units[role] = table.units[j]
    return _Columns(roles, units, ignored, mapped)


# ---------------------------------------------------------------------------------------- places
@dataclass
class _Places:
    """Where an instrument's stations are, to match a file's position columns against."""

    n: int
    comps: list
    xy: np.ndarray  # (n, 2)
    distance: np.ndarray | None  # from the reference end (linewise)
    tol: np.ndarray  # (n,) matching tolerance per station [m]
    ref: np.ndarray | None  # the reference end (linewise)
    ref_tol: float

    def coordinate(self, role: str, ref: bool = False) -> np.ndarray:
        xy = self.ref[None] if ref else self.xy
        if role == "depth":
            return -xy[:, 1]
        if role == "x":
            return xy[:, 0]
        if role == "y":
            return xy[:, 1]
        return np.zeros(1) if ref else self.distance


def _places(block: InstrumentBlock) -> _Places:
    comps = list(dict.fromkeys(lab.component for lab in block.labels))
    labels = block.labels[::len(comps)]
    xy = np.array([[lab.x, lab.y] for lab in labels], float)
    n = len(labels)
    if block.lengths is not None:
        ls = np.asarray(block.lengths, float)
        nxt = np.append(ls[1:], np.inf)
        tol = np.minimum(0.05, POSITION_TOLERANCE * np.minimum(ls, nxt))
        return _Places(n, comps, xy, np.cumsum(ls), tol, block.reference, min(0.05, POSITION_TOLERANCE * ls[0]))
    if n > 1:
        from scipy.spatial import cKDTree

        nearest = cKDTree(xy).query(xy, k=2)[0][:, 1]
    else:
        nearest = np.full(n, np.inf)
    return _Places(n, comps, xy, None, np.minimum(0.05, POSITION_TOLERANCE * nearest), None, 0.0)


def _natural(text: str) -> list:
    return [(0, int(t), "") if t.isdigit() else (1, 0, t.lower()) for t in re.split(r"(\d+)", text) if t]


def _whole(text: str) -> int | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return int(v) if np.isfinite(v) and v == int(v) else None


# ---------------------------------------------------------------------------------------- matching
def _default_unit(block: InstrumentBlock) -> str:
    if block.reading_type == "primary":
        return LINEWISE_KINDS[block.kind].primary_unit
    return "kN" if block.kind == "load_cell" else "m"


def _unit_factor(unit: str, block: InstrumentBlock, fail, where: str) -> float:
    u = {k.lower(): k for k in READING_UNITS}.get(unit.strip().lower(), unit.strip())  # 'MM' is mm here
    if u not in READING_UNITS:
        raise fail(f"{where}: expected a reading unit {', '.join(READING_UNITS)}, found '{unit}'")
    kind = {"m": "length", "mm": "length", "cm": "length", "rad": "angle", "mrad": "angle", "1/m": "curvature",
            "kN": "force", "MN": "force"}
    if kind[u] != kind[_default_unit(block)]:
        what = "" if block.kind == "load_cell" else f" ({block.reading_type} readings)"
        raise fail(f"{where}: expected readings in a unit of {kind[_default_unit(block)]} for "
                   f"{block.kind} '{block.name}'{what}, found '{unit}'")
    return READING_UNITS[u]


class _Matcher:
    """Places the rows of one instrument in a file at its stations (``place``)."""

    def __init__(self, table: Table, cols: _Columns, block: InstrumentBlock, ins, fail):
        self.table, self.cols, self.block, self.ins, self.fail = table, cols, block, ins, fail
        self.places = _places(block)
        self.scale = {}
        for role in POSITIONS:
            if role in cols.roles:
                unit = (cols.units.get(role) or "m").strip().lower()
                if unit not in ("m", "cm", "mm"):
                    raise fail(f"{table.where(table.header_line)}: expected the {role} in m, cm or mm, found "
                               f"'{cols.units[role]}'")
                self.scale[role] = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}[unit]
        if "distance" in cols.roles and block.lengths is None:
            raise fail(f"{table.where(table.header_line)}: {block.kind} '{block.name}' has no distances from a "
                       f"reference end: give a station, point, x or y column")
        self.ids: dict[str, int] | None = None
        self.id_note = ""

    @property
    def positioned(self) -> bool:
        return any(r in self.cols.roles for r in ("station", "point") + POSITIONS)

    def how(self) -> str:
        roles = self.cols.roles
        if "point" in roles and self.ids is not None:
            return "matched by point ID" + self.id_note
        given = [r for r in ("station", "point") + POSITIONS if r in roles]
        if not given:
            return "(one reading)" if self.places.n == 1 else \
                "taken in station order from the reference end: the file has no position column"
        first, rest = given[0], given[1:]
        return f"matched by {first}" + (f" ({', '.join(rest)} checked)" if rest else "")

    def point_ids(self, rows) -> None:
        """Point IDs of a points instrument: the case's list, or the file's IDs in natural order."""
        ins, roles = self.ins, self.cols.roles
        if "point" not in roles or self.block.kind != "points" or ins.point_ids is None:
            return
        if isinstance(ins.point_ids, list):
            self.ids = {p: k for k, p in enumerate(ins.point_ids)}
            self.id_note = " (point_ids)"
            return
        found = sorted({f[roles["point"]] for _, f in rows}, key=_natural)
        if len(found) != self.places.n:
            raise self.fail(f"{self.table.where()}: expected {self.places.n} point IDs for '{self.block.name}' (one "
                            f"per point; point_ids: sorted), found {len(found)} ({', '.join(found[:8])}"
                            f"{', ...' if len(found) > 8 else ''})")
        self.ids = {p: k for k, p in enumerate(found)}
        pairs = ", ".join(f"{p} = point {k + 1}" for k, p in enumerate(found[:6])) + (", ..." if len(found) > 6 else "")
        self.id_note = f" in sorted order (point_ids: sorted: {pairs})"

    def _station(self, line: int, fields: list[str]) -> int | None:
        roles, b, n = self.cols.roles, self.block, self.places.n
        if "station" in roles:
            text, what = fields[roles["station"]], "station"
        elif "point" in roles:
            text, what = fields[roles["point"]], "point"
        else:
            return None
        if what == "point" and self.ids is not None:
            if text not in self.ids:
                known = ", ".join(list(self.ids)[:8]) + (", ..." if len(self.ids) > 8 else "")
                raise self.fail(f"{self.table.where(line)}: point '{text}' is not a point of '{b.name}' "
                                f"(point_ids: {known})")
            return self.ids[text]
        st = _whole(text)
        if st is None:
            if what == "point" and text and b.kind == "points":
                raise self.fail(f"{self.table.where(line)}: point '{text}' is an ID, not a point number: expected "
                                f"the case to name the points of '{b.name}' (point_ids: [{text}, ...] in the order "
                                f"of its points, or point_ids: sorted to take the file's IDs in sorted order)")
            raise self.fail(f"{self.table.where(line)}: expected a whole station number, found '{text}'")
        if not 1 <= st <= n:
            raise self.fail(f"{self.table.where(line)}: station {st} of {b.kind} '{b.name}' does not exist "
                            f"(stations 1-{n} from the reference end)")
        return st - 1

    def place(self, line: int, fields: list[str]) -> tuple[int, str]:
        """(station index or REFERENCE, component) of a row."""
        table, roles, pl, b = self.table, self.cols.roles, self.places, self.block
        k = self._station(line, fields)
        given = {r: _number(table, line, fields[roles[r]], r, self.fail) * self.scale[r]
                 for r in POSITIONS if r in roles}
        said = " and ".join(f"{r} {v:g} m" for r, v in given.items())
        if k is not None:
            off = [r for r, v in given.items() if abs(pl.coordinate(r)[k] - v) > pl.tol[k]]
            if off:
                r = off[0]
                raise self.fail(f"{table.where(line)}: {r} {given[r]:g} m disagrees with station {k + 1} of "
                                f"{b.kind} '{b.name}' ({r} {pl.coordinate(r)[k]:g} m; tolerance {pl.tol[k]:g} m)")
        elif given:
            if pl.ref is not None and all(abs(pl.coordinate(r, ref=True)[0] - v) <= pl.ref_tol
                                          for r, v in given.items()):
                k = REFERENCE
            else:
                ok = np.ones(pl.n, bool)
                for r, v in given.items():
                    ok &= np.abs(pl.coordinate(r) - v) <= pl.tol
                hits = np.flatnonzero(ok)
                if len(hits) == 0:
                    r = next(iter(given))
                    target = pl.coordinate(r)
                    near = ", ".join(f"{t:g}" for t in target[:6]) + (", ..." if len(target) > 6 else "")
                    raise self.fail(f"{table.where(line)}: {said} match{'es' if len(given) == 1 else ''} no "
                                    f"station of {b.kind} '{b.name}' "
                                    f"(stations at {r}s {near} m; tolerance {float(pl.tol.max()):g} m)")
                if len(hits) > 1:
                    listed = ", ".join(str(h + 1) for h in hits[:6]) + (", ..." if len(hits) > 6 else "")
                    raise self.fail(f"{table.where(line)}: {said} match{'es' if len(given) == 1 else ''} "
                                    f"{len(hits)} stations of {b.kind} "
                                    f"'{b.name}' ({listed}): expected a position that tells them apart (a station, "
                                    f"point, depth, distance, x or y column)")
                k = int(hits[0])
        elif pl.n == 1:
            k = 0
        else:
            raise self.fail(f"{table.where()}: expected a station, depth or distance column to place the readings "
                            f"of {b.kind} '{b.name}' ({b.m} readings)")
        return k, self.component(line, fields)

    def component(self, line: int, fields: list[str]) -> str:
        roles, comps, name = self.cols.roles, self.places.comps, self.block.name
        where = self.table.where(line)
        c = fields[roles["component"]].strip().lower() if "component" in roles else None
        if "settlement" in roles:
            if "uy" not in comps:
                raise self.fail(f"{self.table.where(self.table.header_line)}: a settlement column gives vertical "
                                f"readings, but '{name}' reads {' and '.join(comps)}")
            if c not in (None, "", "uy"):
                raise self.fail(f"{where}: expected the component uy for a settlement (a vertical reading) of "
                                f"'{name}', found '{c}'")
            return "uy"
        if len(comps) > 1:
            if c is None:
                raise self.fail(f"{self.table.where()}: {self.block.kind} '{name}' reads {' and '.join(comps)}: "
                                f"expected a component column")
            if c not in comps:
                raise self.fail(f"{where}: expected a component {' or '.join(comps)} for '{name}', found '{c}'")
            return c
        if c and c not in comps:
            raise self.fail(f"{where}: expected the component {comps[0]} for '{name}', found '{c}'")
        return comps[0]


def _label(block: InstrumentBlock, k: int) -> str:
    lab = block.labels[k]
    comps = {b.component for b in block.labels}
    word = "point" if block.kind == "points" else "station"
    return f"{word} {lab.station}" + (f" ({lab.component})" if len(comps) > 1 else "")


def _sign(ins, settlement_column: bool, err) -> float:
    """-1 when the instrument's vertical readings are settlements (positive down)."""
    sign = getattr(ins, "sign", None)
    if settlement_column and sign == "uy":
        raise err(("sign",), "expected readings positive up (sign: uy), found a settlement column in the readings "
                             "file (positive down): remove sign: uy, or rename the column")
    return -1.0 if settlement_column or sign == "settlement" else 1.0


def file_readings(table: Table, block: InstrumentBlock, ins, stages: list[str], single: bool, err,
                  periods=None) -> tuple[dict[str, np.ndarray], Matching, "Sets"]:
    """The block's readings per stage from a parsed file (NaN where marked missing) and how they
    were matched. single: the file serves this instrument only (then the instrument column is
    optional). err(path, message): the error located at the instrument's field `path`."""
    def fail(message):
        return err(("readings_file",), message)

    cols = _columns(table, ins, err)
    roles = cols.roles
    if "instrument" in roles:
        mine = [(ln, f) for ln, f in table.rows if f[roles["instrument"]] == block.name]
    elif single:
        mine = table.rows
    else:
        raise fail(f"{table.where()}: serves several instruments: expected an instrument column")
    if not mine:
        raise fail(f"{table.where()}: no readings of instrument '{block.name}'")
    value_role = "settlement" if "settlement" in roles else "reading"
    factor = 1.0
    unit = cols.units.get(value_role)
    if ins.readings_unit and unit and READING_UNITS.get(unit.strip().lower()) != READING_UNITS[ins.readings_unit]:
        raise fail(f"readings_unit '{ins.readings_unit}' disagrees with the file's header unit '{unit}'")
    unit = unit or ins.readings_unit
    if unit:
        factor = _unit_factor(unit, block, fail, table.where())
    sign = _sign(ins, value_role == "settlement", err)
    matcher = _Matcher(table, cols, block, ins, fail)
    matcher.point_ids(mine)
    surveys = Surveys(table, block, ins, stages, periods, roles, fail, err)
    staged_by = surveys.staged_by
    comps = matcher.places.comps
    out, missing, details, ref_rows = {}, [], [], []
    where_stage = (lambda s: s)  # ' at stage X', ' at stage X, survey D' or '' (one stage, no surveys)

    def collect(stage: str, rows: list) -> np.ndarray:
        """One survey's values in station order (NaN where marked missing) from its rows."""
        values = np.full(block.m, np.nan)
        marked = np.zeros(block.m, bool)
        first_line: dict[int, int] = {}
        ref_line = None
        for pos, (line, fields) in enumerate(rows):
            text = fields[roles[value_role]]
            gone = text.strip().lower() in MISSING
            v = np.nan if gone else _number(table, line, text, "reading", fail)
            if matcher.positioned or block.m == 1:
                k, c = matcher.place(line, fields)
            else:  # no position column: one instrument, in station order
                if len(rows) != block.m:
                    raise fail(f"{table.where()}: expected {block.m} readings of '{block.name}' in station order "
                               f"(no station, point, depth, distance, x or y column), found {len(rows)}")
                k, c = pos // len(comps), comps[pos % len(comps)]
                if ("component" in roles or "settlement" in roles) and matcher.component(line, fields) != c:
                    raise fail(f"{table.where(line)}: expected the component {c} here (rows in station order, "
                               f"{' then '.join(comps)} at each point), found {matcher.component(line, fields)}")
            table.taken.add(line)
            if k == REFERENCE:
                _check_reference(table, line, block, matcher, fields, v * factor, ref_line, stage, fail)
                ref_line = line
                ref_rows.append(line)
                continue
            i = k * len(comps) + comps.index(c)
            if i in first_line:
                again = " (a date or survey column tells repeated surveys apart)" if not surveys.dated else ""
                raise fail(f"{table.where(line)}: {_label(block, i)} of '{block.name}'{where_stage(stage)} is given "
                           f"twice (also on line {first_line[i]}){again}")
            first_line[i] = line
            if gone:
                marked[i] = True
                missing.append(f"{_label(block, i)}{where_stage(stage)} (line {line})")
                if block.reading_type == "primary":
                    raise fail(f"{table.where(line)}: the primary reading of {_label(block, i)} of '{block.name}' is "
                               f"marked missing, but the displacements of the stations beyond it are integrated "
                               f"through it (eqns 11, 15, 18): expected a reading there (or displacements, "
                               f"reading_type: displacement, of which a missing one is dropped)")
                continue
            values[i] = v * factor * (sign if c == "uy" else 1.0)
        absent = [_label(block, k) for k in np.flatnonzero(np.isnan(values) & ~marked)]
        if absent:
            raise fail(f"{table.where()}: '{block.name}'{where_stage(stage)} has no reading for "
                       f"{', '.join(absent[:8])}{', ...' if len(absent) > 8 else ''} (a reading not taken is written "
                       f"as an empty cell, -, n/a or NaN)")
        return values

    for line, fields in mine:
        surveys.add(line, fields)
    sets = surveys.finish()
    base = None
    if surveys.baseline is not None:
        b = surveys.baseline
        base = collect(f" in {b.label}", surveys.rows[b.key])
        details.append(f"baseline survey {b.survey} (lines {b.lines}) subtracted from every later survey; the "
                       f"readings are increments since {'before construction' if b.stage is None else 'stage ' + repr(b.stage)}")
    meta = {}
    for info in sets:
        values = collect("" if len(stages) == 1 and info.survey is None else f" at {info.label}",
                         surveys.rows[info.key])
        if base is not None:
            values = values - base
        meta[info.name] = info
        out[info.name] = values
    if ins.surveys == "average":
        out, meta = averaged(out, meta, block, fail, table)
        details.extend(f"{s}: the average of {m.count} surveys ({', '.join(m.survey.split(' + '))}), C_x / {m.count}"
                       for s, m in meta.items() if m.count > 1)
    if surveys.dated:
        details.append(f"{len(sets)} survey{'s' if len(sets) != 1 else ''} besides the baseline"
                       if base is not None else f"{len(sets)} survey{'s' if len(sets) != 1 else ''}")
    if ref_rows:
        end = block.reference_end or "reference end"
        details.append(f"the {end} row{'s' if len(ref_rows) > 1 else ''} (line{'s' if len(ref_rows) > 1 else ''} "
                       f"{', '.join(map(str, ref_rows))}) checked to read 0 and not used")
    if sign < 0:
        why = "settlement column" if value_role == "settlement" else "sign: settlement"
        details.append(f"{why}: u_y = -reading (positive down)")
    if cols.mapped:
        details.append("columns mapped by the case: " + ", ".join(cols.mapped))
    if cols.ignored:
        details.append("columns ignored (ignore_columns): " + ", ".join(cols.ignored))
    if unit and READING_UNITS.get(unit.strip().lower(), 1.0) != 1.0:
        details.append(f"in {unit}")
    count = int(sum(np.count_nonzero(~np.isnan(v)) for v in out.values()))
    lines = [ln for ln, _ in mine]
    how = matcher.how() + f" (lines {min(lines)}-{max(lines)})"
    note = Matching(block.name, table.path.name, how, count,
                    tuple((s, int(np.count_nonzero(~np.isnan(v)))) for s, v in out.items()), staged_by,
                    tuple(missing), tuple(details))
    return out, note, Sets(meta, surveys.since)


def _check_reference(table, line, block, matcher, fields, value, previous, stage, fail) -> None:
    """A row at the reference end: taken only by an instrument read relative to it, where it reads
    zero by definition; refused when it does not, or when given twice."""
    end = block.reference_end or "reference end"
    said = " and ".join(f"{r} {_number(table, line, fields[matcher.cols.roles[r]], r, fail) * matcher.scale[r]:g} m"
                        for r in POSITIONS if r in matcher.cols.roles)
    if not block.relative:
        raise fail(f"{table.where(line)}: {said} is the {end} of {block.kind} '{block.name}', not a station: its "
                   f"readings are absolute (readings_relative: false), so the {end} has no reading of its own; "
                   f"expected no row there")
    if previous is not None:
        raise fail(f"{table.where(line)}: the {end} of '{block.name}'"
                   f"{stage or ''} is given twice (also on line {previous})")
    if np.isfinite(value) and abs(value) > REFERENCE_TOLERANCE:
        raise fail(f"{table.where(line)}: {said} is the {end} of {block.kind} '{block.name}', which its readings are "
                   f"relative to: expected 0 there (within {REFERENCE_TOLERANCE:g} in SI units), found "
                   f"{fields[matcher.cols.roles['settlement' if 'settlement' in matcher.cols.roles else 'reading']]}")


def inline_readings(ins, block: InstrumentBlock, stages: list[str], err
                    ) -> tuple[dict[str, np.ndarray], Matching, Sets]:
    """An instrument's inline readings per stage, and how they were placed."""
    at = ("readings",)
    if isinstance(ins.readings, dict):
        if ins.stage is not None:
            raise err(("stage",), "expected either readings by stage (a mapping) or stage:, found both")
        raw, staged_by = ins.readings, "the readings' stage keys"
    elif ins.stage is not None:
        raw, staged_by = {ins.stage: ins.readings}, f"stage: {ins.stage} in the case"
    elif len(stages) == 1:
        raw, staged_by = {stages[0]: ins.readings}, "the case's only stage"
    else:
        raise err(at, f"expected the stage these readings of '{block.name}' were taken at (stage: {stages[-1]}, say) "
                      f"or readings by stage ({{{stages[0]}: [...], ...}}): the case has construction stages "
                      f"{', '.join(stages)}, found a list")
    sets = {}
    for stage, values in raw.items():
        if stage not in stages:
            raise err(at, f"expected construction stages as keys ({', '.join(stages)}), found '{stage}'")
        values = np.asarray(values, float)
        if len(values) != block.m:
            what = "stations" if block.integration is not None else "point components"
            raise err(at, f"expected {block.m} readings for instrument '{block.name}' ({what}"
                          f"{'' if len(raw) == 1 else f', stage {stage}'}), found {len(values)}")
        factor = _unit_factor(ins.readings_unit, block, lambda m: err(at, m), "readings") if ins.readings_unit else 1.0
        sets[stage] = values * factor
    sign = _sign(ins, False, err)
    details = []
    if sign < 0:
        uy = np.array([lab.component == "uy" for lab in block.labels])
        sets = {s: np.where(uy, -v, v) for s, v in sets.items()}
        details.append("sign: settlement: u_y = -reading (positive down)")
    ordered = [s for s in stages if s in sets]
    since = ins.installed_after
    if since is not None:
        early = [s for s in ordered if stages.index(s) < stages.index(since)]
        if early:
            raise err(at, f"'{block.name}' was read at stage '{early[0]}', before it was installed (after stage "
                          f"'{since}'): expected readings at stage '{since}' or later")
        details.append(f"increments since it was installed after stage '{since}'")
    note = Matching(block.name, "inline", "in station order from the reference end" if block.m > 1 else "(one reading)",
                    sum(block.m for _ in ordered), tuple((s, block.m) for s in ordered), staged_by, (), tuple(details))
    return {s: sets[s] for s in ordered}, note, Sets({s: SetInfo(s, s) for s in ordered}, since)


# ---------------------------------------------------------------------------------------- the case
def _combined(errors: list[CaseError]) -> CaseError:
    """One error for several: the first, '(and N more problems)', all of them in ``problems``."""
    problems = [p for e in errors for p in e.problems]
    if len(problems) == 1:
        return problems[0]
    first = problems[0]
    return CaseError(first.reason + more_problems(len(problems) - 1), file=first.file, line=first.line,
                     column=first.column, field=first.field, problems=problems)


def read_readings(loaded: LoadedCase, blocks: list[InstrumentBlock], stages: list[str]) -> CaseReadings:
    """Readings of every instrument of `blocks` (``CaseReadings``). Every instrument's problems are
    collected and raised together (a CaseError listing them all)."""
    case = loaded.case
    blocks = list({b.index: b for b in blocks}.values())  # one per instrument
    tables: dict[Path, Table] = {}
    users: dict[Path, list[int]] = {}
    for b in blocks:
        ins = case.instruments[b.index]
        if ins.readings_file is not None:
            users.setdefault((loaded.folder / ins.readings_file).resolve(), []).append(b.index)
    values: dict[str, dict[str, np.ndarray]] = {}
    meta: dict[str, Sets] = {}
    periods = stage_periods(case)
    notes, unread, errors, broken = [], [], [], set()
    for b in blocks:
        ins = case.instruments[b.index]

        def err(path, message, i=b.index):
            return loaded.error(("instruments", i) + tuple(path), message)

        path = None
        try:
            if ins.stage is not None and ins.stage not in stages:
                raise err(("stage",), f"expected one of the construction stages ({', '.join(stages)}), "
                                      f"found '{ins.stage}'")
            if ins.readings is not None and ins.readings_file is not None:
                raise err(("readings_file",), "give either 'readings' or 'readings_file', not both")
            sets: dict[str, np.ndarray] = {}
            info = Sets({}, ins.installed_after)
            if ins.readings is not None:
                sets, note, info = inline_readings(ins, b, stages, err)
            elif ins.readings_file is not None:
                path = (loaded.folder / ins.readings_file).resolve()
                if path not in tables:
                    tables[path] = read_table(loaded.folder / ins.readings_file,
                                              lambda m: err(("readings_file",), m))
                sets, note, info = file_readings(tables[path], b, ins, stages, len(users[path]) == 1, err, periods)
            sets, info = _until(loaded, sets, info, stages)
            for stage, v in sets.items():
                if b.reading_type == "primary":
                    sets[stage] = b.integration @ v  # eqns 11, 15, 18 with the constants taken as zero
                if b.kind == "load_cell":
                    sets[stage] = v - ins.zero  # the force since installation: the cell's zero reading subtracted
        except CaseError as exc:
            errors.append(exc)
            if path is not None:
                broken.add(path)
            values[b.name] = {}
            continue
        values[b.name] = sets
        meta[b.name] = info
        if any(np.any(~np.isnan(v)) for v in sets.values()):
            notes.append(note)
        else:
            unread.append(b.name)
    for path, table in tables.items():
        if path in broken:
            continue  # an instrument of this file was refused: its rows are not all taken
        unused = [ln for ln, _ in table.rows if ln not in table.taken]
        if unused:
            first = unused[0]
            row = dict(table.rows)[first]
            col = next((j for j, k in enumerate(table.keys) if COLUMNS.get(k) == "instrument"), None)
            for i in users[path]:
                mapped = (case.instruments[i].columns or {}).get("instrument")
                if mapped is not None:
                    col = _header_matches(table, mapped)[0]
            who = row[col] if col is not None else "?"
            names = [ins.name for ins in case.instruments]
            why = (f"names instrument '{who}', which is not in the case (instruments: {', '.join(names)})"
                   if who not in names else f"gives readings of '{who}', which does not read from this file")
            i = users[path][0]
            errors.append(loaded.error(("instruments", i, "readings_file"),
                                       f"{table.where(first)}: {why} ({len(unused)} such row"
                                       f"{'s' if len(unused) > 1 else ''})"))
    if errors:
        raise _combined(errors)
    return CaseReadings(values, notes, unread, meta)


def _until(loaded: LoadedCase, sets: dict, info: Sets, stages: list[str]) -> tuple[dict, Sets]:
    """Only the sets read up to the case's cut-off (``LoadedCase.until``: a stage, or a date for
    dated surveys), for `geoback update`."""
    until = getattr(loaded, "until", None)
    if until is None:
        return sets, info
    keep = [n for n, m in info.sets.items() if _before(m, until, stages)] if info.sets else \
        [n for n in sets if stages.index(n) <= stages.index(until) if isinstance(until, str)]
    return {n: sets[n] for n in keep}, Sets({n: info.sets[n] for n in keep if n in info.sets}, info.since)


def _before(m: SetInfo, until, stages: list[str]) -> bool:
    if isinstance(until, str):
        return stages.index(m.stage) <= stages.index(until)
    return m.when is not None and m.when <= until


def case_readings(loaded: LoadedCase, blocks: list[InstrumentBlock], stages: list[str]) -> dict:
    """Readings of every instrument: {instrument name: {stage: values in station order}} (empty
    for an instrument without readings; NaN where a reading is marked missing), in SI units and
    displacement form (``read_readings`` also says how they were matched)."""
    return read_readings(loaded, blocks, stages).values


def readings_report(loaded: LoadedCase) -> CaseReadings:
    """How the case's readings are read (``CaseReadings``), for `geoback validate` and `geoback run`."""
    from geoback.case.loading import stage_names
    from geoback.observation.instruments import case_blocks

    return read_readings(loaded, case_blocks(loaded), stage_names(loaded.case))


def require_readings(loaded: LoadedCase, report: CaseReadings | None = None) -> None:
    """Refuse, naming them, instruments without readings (identification needs every one's; up to
    a cut-off, ``LoadedCase.until``, those not read yet are left out instead)."""
    report = report if report is not None else readings_report(loaded)
    if not report.unread or getattr(loaded, "until", None) is not None:
        return
    names = [ins.name for ins in loaded.case.instruments]
    i = names.index(report.unread[0])
    raise loaded.error(("instruments", i), f"expected readings of every instrument to identify parameters, found "
                                           f"none for {', '.join(report.unread)} (give 'readings' or 'readings_file'; "
                                           f"readings marked missing do not count)")


def survey_blocks(loaded: LoadedCase, stages: list[str], read: bool = True
                  ) -> tuple[list[InstrumentBlock], np.ndarray | None]:
    """One block per instrument and set of readings (a stage, or each dated survey: in construction
    order, then by date), without the readings marked missing (``InstrumentBlock.without``), reading
    increments since its installation when it was installed after a stage (``since``), and their
    readings stacked in that order; an instrument without readings is predicted at the last stage,
    and then there is no measured vector (None). read=False: every instrument at every stage, no
    readings (forward runs, study data)."""
    from geoback.observation.instruments import case_blocks

    geometry = case_blocks(loaded)
    if not read:  # every instrument at every stage it reads (after its installation: increments since then)
        since = _installations(loaded, geometry, stages)
        return [g.at(stage, since=since[g.name]) for g in geometry for stage in stages
                if since[g.name] is None or stages.index(stage) > stages.index(since[g.name])], None
    report = read_readings(loaded, geometry, stages)
    blocks, values, complete = [], [], True
    for g in geometry:
        sets = {s: v for s, v in report.values[g.name].items() if np.any(~np.isnan(v))}
        info = report.sets.get(g.name, Sets({}))
        if not sets:
            if getattr(loaded, "until", None) is not None:
                continue  # `geoback update`: not read by the cut-off (installed or read later)
            blocks.append(g.at(stages[-1], since=info.since))
            complete = False
            continue
        for name, v in sets.items():
            m = info.sets.get(name, SetInfo(name, name))
            block = g.at(m.stage, survey=m.survey, since=info.since, averaged=m.count, reading_set=m.name)
            gone = np.flatnonzero(np.isnan(v))
            blocks.append(block.without(gone) if len(gone) else block)
            values.append(v[~np.isnan(v)])
    return blocks, ((np.concatenate(values) if values else np.zeros(0)) if complete else None)


def _installations(loaded: LoadedCase, geometry: list[InstrumentBlock], stages: list[str]) -> dict:
    """The stage after which each instrument was installed: its dated baseline's stage where its readings
    say it (readable readings), else the case's installed_after (None: from the start)."""
    since = {g.name: g.since for g in geometry}
    try:
        report = read_readings(loaded, geometry, stages)
    except CaseError:  # readings that cannot be read are refused where they are used, not here
        return since
    since.update({name: sets.since for name, sets in report.sets.items() if sets.since is not None})
    return since


def measured_values(loaded: LoadedCase, blocks: list[InstrumentBlock]) -> np.ndarray | None:
    """The readings of `blocks` (one per instrument and stage, the rows each keeps) stacked in their
    order; None if an instrument has none at a block's stage, or one of the block's is missing."""
    from geoback.case.loading import stage_names

    readings = case_readings(loaded, blocks, stage_names(loaded.case))  # the case's stages, not only those read
    values = []
    for b in blocks:
        v = readings.get(b.name, {}).get(b.set_name)
        if v is None:
            return None
        v = v[list(b.kept)] if b.kept is not None else v
        if np.any(np.isnan(v)):
            return None
        values.append(v)
    return np.concatenate(values)
