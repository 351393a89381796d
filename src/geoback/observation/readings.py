"""Measured readings, inline in the case or from files, matched to the instruments' stations.

Readings are matched, never assumed to be in order: a file row names its instrument (or the file
serves one instrument), its position (station number from the reference end, depth below the
surface, or distance from the reference end) and, for settlement points, its component; rows may
come in any order, head-first inclinometer exports included. Duplicates, gaps, unknown or
out-of-range positions, unknown instruments and rows no instrument takes are errors that name
the file, line and station. Headers are case-insensitive and may carry the unit ('reading [mm]');
the delimiter is sniffed (comma, semicolon, tab, bar, spaces; a decimal comma with ';' or tabs);
UTF-8 with or without a byte-order mark, UTF-16 with one, and Windows-1252 are read.

Inline readings are a list in station order from the reference end (the last construction stage)
or a mapping stage: [values]. Primary readings of linewise instruments (slopes, length changes,
curvatures) are integrated into displacements with the constants taken as zero (eqns 11, 15, 18);
both forms then give the same objective (eqns 21-26).
"""
from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from geoback.case.loading import LoadedCase
from geoback.case.schema import READING_UNITS
from geoback.errors import CaseError
from geoback.observation.instruments import LINEWISE_KINDS, InstrumentBlock

COLUMNS = {  # header (lower case, unit removed) -> role
    "instrument": "instrument", "name": "instrument",
    "station": "station", "point": "station",
    "depth": "depth", "distance": "distance",
    "component": "component",
    "reading": "value", "value": "value", "measured": "value", "displacement": "value",
    "stage": "stage",
}
DELIMITERS = ",;\t|"
POSITION_TOLERANCE = 0.02  # a depth or distance within this fraction of the local spacing (at most 5 cm)
MAX_FILE_BYTES = 50_000_000


@dataclass
class Table:
    """A readings file parsed: header roles, rows with their line numbers, units per role."""

    path: Path
    roles: dict[str, int]  # role -> column index
    units: dict[str, str]
    rows: list[tuple[int, list[str]]]
    decimal_comma: bool
    taken: set = field(default_factory=set)  # line numbers some instrument used

    def where(self, line: int | None = None) -> str:
        return f"{self.path.name}" + (f", line {line}" if line else "")


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
    return name.strip().lower().replace("_", " ").replace("  ", " "), (unit or None)


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
    sample = "\n".join(ln for _, ln in lines[:20])
    counts = {d: min(ln.count(d) for _, ln in lines[:20]) for d in DELIMITERS}
    delim = max(DELIMITERS, key=lambda d: counts[d]) if max(counts.values()) > 0 else None
    header_line, header = lines[0]
    if delim is None:
        split = (lambda ln: ln.split())
    else:
        split = (lambda ln: next(csv.reader(io.StringIO(ln), delimiter=delim, skipinitialspace=True)))
    del sample
    names = split(header)
    roles, units = {}, {}
    for j, h in enumerate(names):
        name, unit = _split_unit(h)
        role = COLUMNS.get(name)
        if role is None:
            continue
        if role in roles:
            raise fail(f"{path.name}, line {header_line}: two columns mean the {role} "
                       f"('{names[roles[role]]}' and '{h}'); expected one")
        roles[role] = j
        if unit:
            units[role] = unit
    if "value" not in roles:
        raise fail(f"{path.name}, line {header_line}: expected a header with a column named reading, value, measured "
                   f"or displacement, found {', '.join(repr(n) for n in names)}")
    rows = []
    for line, text_line in lines[1:]:
        fields = [f.strip() for f in split(text_line)]
        if len(fields) != len(names):
            raise fail(f"{path.name}, line {line}: expected {len(names)} fields as in the header, found {len(fields)}")
        rows.append((line, fields))
    if not rows:
        raise fail(f"readings file {path.name} has a header but no readings")
    decimal_comma = delim in (";", "\t", "|", None) and any(
        re.fullmatch(r"[-+]?\d+,\d+(?:[eE][-+]?\d+)?", r[1][roles["value"]]) for r in rows)
    return Table(path, roles, units, rows, decimal_comma)


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


# ---------------------------------------------------------------------------------------- matching
def _default_unit(block: InstrumentBlock) -> str:
    if block.reading_type == "primary":
        return LINEWISE_KINDS[block.kind].primary_unit
    return "m"


def _unit_factor(unit: str, block: InstrumentBlock, fail, where: str) -> float:
    u = {k.lower(): k for k in READING_UNITS}.get(unit.strip().lower(), unit.strip())  # 'MM' is mm here
    if u not in READING_UNITS:
        raise fail(f"{where}: expected a reading unit {', '.join(READING_UNITS)}, found '{unit}'")
    kind = {"m": "length", "mm": "length", "cm": "length", "rad": "angle", "mrad": "angle", "1/m": "curvature"}
    if kind[u] != kind[_default_unit(block)]:
        raise fail(f"{where}: expected readings in a unit of {kind[_default_unit(block)]} for "
                   f"{block.kind} '{block.name}' ({block.reading_type} readings), found '{unit}'")
    return READING_UNITS[u]


def _station_positions(block: InstrumentBlock) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depth below the surface and distance from the reference end of each station, and the local
    spacing (for the matching tolerance)."""
    pts = block.stations
    depth = -pts[:, 1]
    if block.lengths is None:
        return depth, np.arange(1, len(pts) + 1, dtype=float), np.ones(len(pts))
    dist = np.cumsum(block.lengths)
    return depth, dist, block.lengths


def _match_row(table: Table, line: int, fields: list[str], block: InstrumentBlock, fail) -> int:
    """Row index in the block (0-based) that a file row gives."""
    roles, m = table.roles, block.m
    comps = sorted({lab.component for lab in block.labels}, key=[lab.component for lab in block.labels].index)
    if "station" in roles:
        text = fields[roles["station"]]
        try:
            st = int(float(text))
            if float(text) != st:
                raise ValueError
        except ValueError:
            raise fail(f"{table.where(line)}: expected a whole station number, found '{text}'") from None
        n_st = m // len(comps)
        if not 1 <= st <= n_st:
            raise fail(f"{table.where(line)}: station {st} of {block.kind} '{block.name}' does not exist "
                       f"(stations 1-{n_st} from the reference end)")
        k = st - 1
    elif "depth" in roles or "distance" in roles:
        role = "depth" if "depth" in roles else "distance"
        v = _number(table, line, fields[roles[role]], role, fail)
        if role in table.units and table.units[role].strip() != "m":
            v *= {"mm": 1e-3, "cm": 1e-2}.get(table.units[role].strip(), np.nan)
            if not np.isfinite(v):
                raise fail(f"{table.where(line)}: expected the {role} in m, cm or mm, found '{table.units[role]}'")
        depth, dist, spacing = _station_positions(block)
        if block.lengths is None:
            raise fail(f"{table.where(line)}: {block.kind} '{block.name}' has no depths or distances: "
                       f"give a station (point) column")
        target = depth if role == "depth" else dist
        k = int(np.argmin(np.abs(target - v)))
        tol = min(0.05, POSITION_TOLERANCE * float(spacing[min(k, len(spacing) - 1)]))
        if abs(target[k] - v) > tol:
            near = ", ".join(f"{t:g}" for t in target[:6]) + (", ..." if len(target) > 6 else "")
            raise fail(f"{table.where(line)}: {role} {v:g} m matches no station of {block.kind} '{block.name}' "
                       f"(stations at {role}s {near} m; tolerance {tol:g} m)")
    elif m == 1:
        k = 0
    else:
        raise fail(f"{table.where()}: expected a station, depth or distance column to place the readings of "
                   f"{block.kind} '{block.name}' ({m} readings)")
    if len(comps) > 1:
        if "component" not in roles:
            raise fail(f"{table.where()}: {block.kind} '{block.name}' reads {' and '.join(comps)}: expected a "
                       f"component column")
        c = fields[roles["component"]].strip().lower()
        if c not in comps:
            raise fail(f"{table.where(line)}: expected a component {' or '.join(comps)} for '{block.name}', found '{c}'")
        return k * len(comps) + comps.index(c)
    if "component" in roles:
        c = fields[roles["component"]].strip().lower()
        if c and c not in comps:
            raise fail(f"{table.where(line)}: expected the component {comps[0]} for '{block.name}', found '{c}'")
    return k


def file_readings(table: Table, block: InstrumentBlock, stages: list[str], single: bool, fail) -> dict[str, np.ndarray]:
    """The block's readings per stage from a parsed file. single: the file serves this instrument
    only (then the instrument column is optional)."""
    roles = table.roles
    if "instrument" in roles:
        mine = [(ln, f) for ln, f in table.rows if f[roles["instrument"]] == block.name]
    elif single:
        mine = table.rows
    else:
        raise fail(f"{table.where()}: serves several instruments: expected an instrument column")
    if not mine:
        raise fail(f"{table.where()}: no readings of instrument '{block.name}'")
    factor = 1.0
    unit = table.units.get("value")
    if unit:
        factor = _unit_factor(unit, block, fail, table.where())
    by_stage: dict[str, list] = {}
    for line, fields in mine:
        stage = fields[roles["stage"]] if "stage" in roles else stages[-1]
        if stage not in stages:
            raise fail(f"{table.where(line)}: stage '{stage}' is not a construction stage of the case "
                       f"(stages: {', '.join(stages)})")
        by_stage.setdefault(stage, []).append((line, fields))
    out = {}
    for stage, rows in by_stage.items():
        values = np.full(block.m, np.nan)
        first_line = {}
        if "station" not in roles and "depth" not in roles and "distance" not in roles and block.m > 1:
            if len(rows) != block.m:  # no position column: one instrument, in station order
                raise fail(f"{table.where()}: expected {block.m} readings of '{block.name}' in station order "
                           f"(no station, depth or distance column), found {len(rows)}")
            for k, (line, fields) in enumerate(rows):
                values[k] = _number(table, line, fields[roles["value"]], "reading", fail)
                table.taken.add(line)
        else:
            for line, fields in rows:
                k = _match_row(table, line, fields, block, fail)
                if k in first_line:
                    raise fail(f"{table.where(line)}: {_label(block, k)} of '{block.name}'"
                               f"{'' if len(stages) == 1 else f' at stage {stage}'} is given twice "
                               f"(also on line {first_line[k]})")
                first_line[k] = line
                values[k] = _number(table, line, fields[roles["value"]], "reading", fail)
                table.taken.add(line)
        missing = [_label(block, k) for k in np.flatnonzero(np.isnan(values))]
        if missing:
            raise fail(f"{table.where()}: '{block.name}'{'' if len(stages) == 1 else f' at stage {stage}'} has no "
                       f"reading for {', '.join(missing[:8])}{', ...' if len(missing) > 8 else ''}")
        out[stage] = values * factor
    return out


def _label(block: InstrumentBlock, k: int) -> str:
    lab = block.labels[k]
    comps = {b.component for b in block.labels}
    return f"station {lab.station}" + (f" ({lab.component})" if len(comps) > 1 else "")


# ---------------------------------------------------------------------------------------- the case
def case_readings(loaded: LoadedCase, blocks: list[InstrumentBlock], stages: list[str]) -> dict:
    """Readings of every instrument: {instrument name: {stage: values in station order}} (empty
    for an instrument without readings), in SI units and displacement form."""
    case = loaded.case
    blocks = list({b.index: b for b in blocks}.values())  # one per instrument
    tables: dict[Path, Table] = {}
    users: dict[Path, list[int]] = {}
    for b in blocks:
        ins = case.instruments[b.index]
        if ins.readings_file is not None:
            users.setdefault((loaded.folder / ins.readings_file).resolve(), []).append(b.index)
    out: dict[str, dict[str, np.ndarray]] = {}
    for b in blocks:
        ins = case.instruments[b.index]
        at_file = ("instruments", b.index, "readings_file")
        at = ("instruments", b.index, "readings")

        def fail(message, at=at_file):
            return loaded.error(at, message)

        if ins.readings is not None and ins.readings_file is not None:
            raise fail("give either 'readings' or 'readings_file', not both")
        sets: dict[str, np.ndarray] = {}
        if ins.readings is not None:
            raw = ins.readings if isinstance(ins.readings, dict) else {stages[-1]: ins.readings}
            for stage, values in raw.items():
                if stage not in stages:
                    raise loaded.error(at, f"expected construction stages as keys ({', '.join(stages)}), "
                                           f"found '{stage}'")
                values = np.asarray(values, float)
                if len(values) != b.m:
                    what = "stations" if b.integration is not None else "point components"
                    raise loaded.error(at, f"expected {b.m} readings for instrument '{b.name}' ({what}"
                                           f"{'' if len(raw) == 1 else f', stage {stage}'}), found {len(values)}")
                sets[stage] = values * (_unit_factor(ins.readings_unit, b, lambda m: loaded.error(at, m), "readings")
                                        if ins.readings_unit else 1.0)
        elif ins.readings_file is not None:
            path = (loaded.folder / ins.readings_file).resolve()
            if path not in tables:
                tables[path] = read_table(loaded.folder / ins.readings_file, fail)
            table = tables[path]
            if ins.readings_unit and "value" in table.units and \
                    READING_UNITS.get(table.units["value"].strip().lower()) != READING_UNITS[ins.readings_unit]:
                raise fail(f"readings_unit '{ins.readings_unit}' disagrees with the file's header unit "
                           f"'{table.units['value']}'")
            if ins.readings_unit and "value" not in table.units:
                table.units["value"] = ins.readings_unit
            sets = file_readings(table, b, stages, len(users[path]) == 1, fail)
        for stage, values in sets.items():
            if b.reading_type == "primary":
                sets[stage] = b.integration @ values  # eqns 11, 15, 18 with the constants taken as zero
        out[b.name] = sets
    for path, table in tables.items():
        unused = [ln for ln, _ in table.rows if ln not in table.taken]
        if unused:
            first = unused[0]
            row = dict(table.rows)[first]
            who = row[table.roles["instrument"]] if "instrument" in table.roles else "?"
            names = [ins.name for ins in case.instruments]
            why = (f"names instrument '{who}', which is not in the case (instruments: {', '.join(names)})"
                   if who not in names else f"gives readings of '{who}', which does not read from this file")
            i = users[path][0]
            raise loaded.error(("instruments", i, "readings_file"),
                               f"{table.where(first)}: {why} ({len(unused)} such row{'s' if len(unused) > 1 else ''})")
    return out


def survey_blocks(loaded: LoadedCase, stages: list[str], read: bool = True
                  ) -> tuple[list[InstrumentBlock], np.ndarray | None]:
    """One block per instrument and construction stage it was read at (stages in construction
    order), and their readings stacked in that order; an instrument without readings is predicted
    at the last stage, and then there is no measured vector (None). read=False: every instrument
    at every stage, no readings (forward runs, study data)."""
    from geoback.observation.instruments import case_blocks

    geometry = case_blocks(loaded)
    if not read:
        return [g.at(stage) for g in geometry for stage in stages], None
    readings = case_readings(loaded, geometry, stages)
    blocks, values, complete = [], [], True
    for g in geometry:
        sets = readings[g.name]
        if not sets:
            blocks.append(g.at(stages[-1]))
            complete = False
            continue
        for stage in stages:
            if stage in sets:
                blocks.append(g.at(stage))
                values.append(sets[stage])
    return blocks, (np.concatenate(values) if complete else None)


def measured_values(loaded: LoadedCase, blocks: list[InstrumentBlock]) -> np.ndarray | None:
    """The readings of `blocks` (one per instrument and stage) stacked in their order; None if an
    instrument has none at a block's stage."""
    stages = list(dict.fromkeys(b.stage for b in blocks))
    readings = case_readings(loaded, blocks, stages)
    values = []
    for b in blocks:
        v = readings.get(b.name, {}).get(b.stage)
        if v is None:
            return None
        values.append(v)
    return np.concatenate(values)
