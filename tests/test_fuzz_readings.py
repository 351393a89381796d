"""Fuzz test of readings files: mutated exports of the paper case's readings are either read exactly
as meant or refused with the case file, line and field and the readings file's own line; never a
traceback, never a silent change (200 examples by default, 2 000 in the slow suite). A reading
written as an empty cell or NaN is read as missing (NaN in the readings, dropped later), exactly
where it was written. Columns renamed to other spellings, reordered, mapped, ignored or added give
the same readings exactly, or a located refusal (``test_columns_renamed_reordered_and_added``)."""
from __future__ import annotations

import random
import re
import time

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import CASES
from measure import HANG_SECONDS
from geoback.case.loading import LoadedCase, case_from_data, stage_names
from geoback.errors import CaseError
from geoback.observation.instruments import case_blocks
from geoback.observation.readings import case_readings

PAPER = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())
ROWS = [(ins["name"], k + 1, v) for ins in PAPER["instruments"] for k, v in enumerate(ins["readings"])]
EXPECTED = {ins["name"]: np.array(ins["readings"]) for ins in PAPER["instruments"]}

MUTATIONS = ["shuffle", "reverse", "drop_row", "duplicate_row", "bad_number", "empty_cell", "extra_field",
             "unknown_instrument", "bad_station", "header_case", "header_unit_mm", "bad_unit", "semicolon",
             "tab", "bom", "utf16", "garbage_bytes", "truncate", "blank_lines", "comment", "no_header",
             "nan", "huge", "stage_column", "crlf"]


def render(rows, header=("instrument", "station", "reading"), delim=","):
    return "\n".join([delim.join(header)] + [delim.join(map(str, r)) for r in rows]) + "\n"


def _finite(text: str) -> bool:
    try:
        return bool(np.isfinite(float(text)))
    except ValueError:
        return False


def mutate(kinds: list[str], rnd: random.Random) -> tuple[bytes, bool, float]:
    """A readings file after the mutations; whether it should still read exactly; value factor.
    (Readings marked missing, an empty cell or NaN, read exactly as missing: ``expected``.)"""
    rows = [list(r) for r in ROWS]
    header = ["instrument", "station", "reading"]
    delim, exact, factor, prefix, enc, eol = ",", True, 1.0, "", "utf-8", "\n"

    def pick():  # a data row (not a blank or comment line)
        return rnd.choice([r for r in rows if len(r) >= 3])

    for kind in kinds:
        if kind == "shuffle":
            rnd.shuffle(rows)
        elif kind == "reverse":
            rows.reverse()
        elif kind == "drop_row":
            rows.pop(rnd.randrange(len(rows)))
        elif kind == "duplicate_row":
            rows.insert(rnd.randrange(len(rows)), list(pick()))
        elif kind == "bad_number":
            pick()[2] = rnd.choice(["abc", "1..2", "--3", "0x1p3", "1e", "∞"])  # judged below
        elif kind == "empty_cell":  # an empty reading is a reading marked missing (issue 18)
            col = rnd.randrange(3)
            pick()[col] = ""
            exact = exact if col == 2 else False
        elif kind == "extra_field":
            pick().append("9")
            exact = False
        elif kind == "unknown_instrument":
            pick()[0] = rnd.choice(["I2", "i1", "I1;", "X9"])
            exact = False
        elif kind == "bad_station":
            pick()[1] = rnd.choice([0, -1, 99, 2.5, "two"])
            exact = False
        elif kind == "header_case":
            header = [h.upper() if rnd.random() < 0.5 else h.title() for h in header]
        elif kind == "header_unit_mm":
            if "[" not in header[2] and "(" not in header[2]:  # a unit already written stays
                header[2] = header[2] + " [mm]"
                factor = 1e-3
        elif kind == "bad_unit":
            header[2] = rnd.choice(["reading [kPa]", "reading (furlong)", "reading [rad]"])
            exact, factor = False, 1.0
        elif kind == "semicolon":
            delim = ";"
        elif kind == "tab":
            delim = "\t"
        elif kind == "bom":
            prefix = "\ufeff"
        elif kind == "utf16":
            enc = "utf-16"
        elif kind == "blank_lines":
            rows.insert(rnd.randrange(len(rows)), [])
        elif kind == "comment":
            rows.insert(0, ["# a comment"])
        elif kind == "nan":  # NaN marks a reading missing (issue 18); infinities are refused (below)
            pick()[2] = rnd.choice(["nan", "inf", "-inf"])
        elif kind == "huge":
            pick()[2] = "1e400"  # judged below
        elif kind == "stage_column":
            twice = any(h.lower() == "stage" for h in header)  # two stage columns are ambiguous: refused
            header.append("stage")
            for r in rows:
                if len(r) == 3:
                    r.append(rnd.choice(["excavation", "excavation", "heading"]))
            exact = False if twice else exact and all(r[3] == "excavation" for r in rows if len(r) == 4)
        elif kind == "crlf":
            eol = "\r\n"
    for r in rows:  # a reading is a finite number or marked missing (a later mutation may have replaced it)
        if len(r) >= 3 and str(r[2]).strip().lower() not in ("", "nan") and not _finite(str(r[2])):
            exact = False
    keys = sorted((str(r[0]), str(r[1])) for r in rows if len(r) >= 3)
    if keys != sorted((str(r[0]), str(r[1])) for r in ROWS):  # a station missing or given twice
        exact = False
    lines = [delim.join(header)] + [delim.join(map(str, r)) if r and r != ["# a comment"] else
                                    ("# a comment" if r else "") for r in rows]
    text = prefix + eol.join(lines) + eol
    data = text.encode(enc)
    for kind in kinds:
        if kind == "garbage_bytes" and data:
            i = rnd.randrange(len(data))
            data = data[:i] + bytes([rnd.randrange(256)]) + data[i + 1:]
            exact = None  # may or may not still read; it must not crash
        elif kind == "truncate" and data:
            data = data[:rnd.randrange(len(data))]
            exact = None
        elif kind == "no_header":
            data = data.split(b"\n", 1)[-1]
            exact = False
    return data, exact, factor


def expected_readings(data: bytes) -> dict:
    """The paper's readings with NaN where the file marks one missing (an empty cell or NaN)."""
    out = {name: v.astype(float).copy() for name, v in EXPECTED.items()}
    text = data.decode("utf-16" if data.startswith((b"\xff\xfe", b"\xfe\xff")) else "utf-8-sig")
    for line in text.splitlines():
        fields = [f.strip() for f in re.split(r"[,;\t]", line)]
        if len(fields) >= 3 and fields[0] in out and fields[2].lower() in ("", "nan"):
            out[fields[0]][int(fields[1]) - 1] = np.nan
    return out


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzz")
    data = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())
    for ins in data["instruments"]:
        ins.pop("readings")
        ins["readings_file"] = "r.csv"
    loaded = LoadedCase(case_from_data(data), folder / "case.yaml", {("instruments", 0, "readings_file"): (30, 5),
                                                                      ("instruments", 1, "readings_file"): (40, 5)})
    return folder, loaded, case_blocks(loaded)


def check(setup, kinds, seed):
    folder, loaded, blocks = setup
    data, exact, factor = mutate(kinds, random.Random(seed))
    (folder / "r.csv").write_bytes(data)
    t0 = time.perf_counter()
    try:
        got = case_readings(loaded, blocks, stage_names(loaded.case))
    except CaseError as exc:
        message = str(exc)
        assert "case.yaml:" in message and "readings_file" in message, message
        assert exact is not True, f"refused a benign file ({kinds}): {message}"
    else:
        assert exact is not False, f"accepted a faulty file silently ({kinds})"
        if exact is None:  # a flipped digit or a cut in the last number cannot be told from data
            return
        for name, expected in expected_readings(data).items():
            np.testing.assert_allclose(got[name]["excavation"], expected * factor, rtol=1e-12)
    assert time.perf_counter() - t0 < HANG_SECONDS, "hung"


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kinds=st.lists(st.sampled_from(MUTATIONS), min_size=1, max_size=3), seed=st.integers(0, 2 ** 16))
def test_mutated_readings_files(setup, kinds, seed):
    check(setup, kinds, seed)


@pytest.mark.slow
@settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kinds=st.lists(st.sampled_from(MUTATIONS), min_size=1, max_size=4), seed=st.integers(0, 2 ** 31))
def test_mutated_readings_files_many(setup, kinds, seed):
    check(setup, kinds, seed)


# ------------------------------------------------------------------- columns renamed, reordered, added
STATIONS = {ins["name"]: (ins["toe_depth"] if ins["kind"] == "inclinometer" else 0.0, ins["spacing"],
                          ins["kind"] == "inclinometer") for ins in PAPER["instruments"]}
SPELLINGS = {  # other headers geoback knows for each column, with and without a unit
    "instrument": ["instrument", "Instrument", "NAME", "instrument_name", "Sensor"],
    "station": ["station", "Station No", "STN", "point", "Pt", "ID"],
    "depth": ["depth [m]", "Tiefe [m]", "profondeur (m)", "Z", "depth (cm)"],
    "distance": ["distance [m]", "Abstand [m]", "dist", "distance (mm)"],
    "reading": ["reading", "Value", "measured [m]", "displacement (mm)", "Reading [cm]"],
}
UNKNOWN = ["Datum", "remark", "Messung Nr", "temperature [C]", "Teufe [m]"]


def position(name: str, station: int, role: str) -> float:
    top, spacing, from_toe = STATIONS[name]
    if role == "distance":
        return spacing * station
    return top - spacing * station if from_toe else spacing * station  # depth below the surface


def unit_of(header: str) -> float:
    unit = re.search(r"[\[(](\w+)[\])]", header)
    return {"mm": 1e3, "cm": 1e2}.get(unit.group(1), 1.0) if unit else 1.0


@st.composite
def layouts(draw):
    """A readings file of the paper's readings with its columns spelt, ordered, mapped, ignored or
    added at random; whether it must read exactly; the instrument fields the case adds."""
    roles = ["instrument", draw(st.sampled_from(["station", "depth", "distance"])), "reading"]
    if draw(st.booleans()):  # a second position column, checked against the first
        roles.append(draw(st.sampled_from([r for r in ("station", "depth", "distance") if r not in roles])))
    headers = {r: draw(st.sampled_from(SPELLINGS[r])) for r in roles}
    fields, exact, extra = {}, True, []
    for k in range(draw(st.integers(0, 2))):  # unknown columns: ignored, mapped, or refused
        header = draw(st.sampled_from([u for u in UNKNOWN if u not in extra]))
        extra.append(header)
        fate = draw(st.sampled_from(["ignore", "ignore_by_name", "refuse", "map_depth"]))
        if fate == "ignore":
            fields.setdefault("ignore_columns", []).append(header)
        elif fate == "ignore_by_name":  # the name without its unit
            fields.setdefault("ignore_columns", []).append(re.sub(r"\s*[\[(].*", "", header))
        elif fate == "map_depth" and "depth" not in roles and "depth" not in fields.get("columns", {}):
            fields.setdefault("columns", {})["depth"] = header  # the unknown header holds the depth
            roles.append(f"mapped:{header}")
            continue
        else:
            exact = False
        roles.append(f"extra:{header}")
    shifted = "depth" in headers and len(roles) > 3 and draw(st.integers(0, 9)) == 0
    if shifted:  # a depth 0.5 m off a station's: refused, never matched elsewhere
        exact = False
    order = draw(st.permutations(roles))
    delim = draw(st.sampled_from([",", ";", "\t"]))
    rows = draw(st.permutations(ROWS))
    names = [headers.get(r, r.split(":", 1)[-1]) for r in order]
    lines = [delim.join(names)]
    for name, station, value in rows:
        out = []
        for r in order:
            if r == "instrument":
                out.append(name)
            elif r == "station":
                out.append(str(station))
            elif r in ("depth", "distance") or r.startswith("mapped:"):
                role = "depth" if r.startswith("mapped:") else r
                v = position(name, station, role) + (0.5 if shifted and r == "depth" else 0.0)
                out.append(repr(v * (unit_of(headers[r]) if r in headers else 1.0)))
            elif r == "reading":
                out.append(repr(value * unit_of(headers[r])))
            else:
                out.append("x")
        lines.append(delim.join(out))
    factor = 1.0 / unit_of(headers["reading"])
    return ("\n".join(lines) + "\n").encode(), exact, fields, factor


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(layout=layouts())
def test_columns_renamed_reordered_and_added(tmp_path_factory, layout):
    """Every column used, mapped (columns:), ignored (ignore_columns:) or refused, located: renamed,
    reordered and added columns give the paper's readings exactly (so the same estimate, a
    function of them) or a refusal naming the case file, the field and the readings file."""
    data, exact, fields, factor = layout
    folder = tmp_path_factory.mktemp("columns")
    (folder / "r.csv").write_bytes(data)
    case = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())
    for ins in case["instruments"]:
        ins.pop("readings")
        ins.update(readings_file="r.csv", **fields)
    loaded = LoadedCase(case_from_data(case), folder / "case.yaml", {})
    try:
        got = case_readings(loaded, case_blocks(loaded), stage_names(loaded.case))
    except CaseError as exc:
        message = str(exc)
        assert "case.yaml" in message and "instruments[" in message and "r.csv" in message, message
        assert exact is not True, f"refused a benign file: {message}\n{data.decode()}"
    else:
        assert exact is not False, f"accepted a faulty file silently:\n{data.decode()}"
        for name, expected in EXPECTED.items():
            got_v = got[name]["excavation"]
            if factor == 1.0:
                np.testing.assert_array_equal(got_v, expected)  # exactly: the same estimate, bit for bit
            else:  # a unit converted back and forth: to the last bits
                np.testing.assert_allclose(got_v, expected, rtol=1e-14, atol=0)
