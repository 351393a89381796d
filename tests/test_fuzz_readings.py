"""Fuzz test of readings files: mutated exports of the paper case's readings are either read exactly
as meant or refused with the case file, line and field and the readings file's own line; never a
traceback, never a silent change (200 examples by default, 2 000 in the slow suite)."""
from __future__ import annotations

import random
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


def mutate(kinds: list[str], rnd: random.Random) -> tuple[bytes, bool, float]:
    """A readings file after the mutations; whether it should still read exactly; value factor."""
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
            pick()[2] = rnd.choice(["abc", "1..2", "--3", "0x1p3", "1e", "∞"])
            exact = False
        elif kind == "empty_cell":
            pick()[rnd.randrange(3)] = ""
            exact = False
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
        elif kind == "nan":
            pick()[2] = rnd.choice(["nan", "inf", "-inf"])
            exact = False
        elif kind == "huge":
            pick()[2] = "1e400"
            exact = False
        elif kind == "stage_column":
            twice = any(h.lower() == "stage" for h in header)  # two stage columns are ambiguous: refused
            header.append("stage")
            for r in rows:
                if len(r) == 3:
                    r.append(rnd.choice(["excavation", "excavation", "heading"]))
            exact = False if twice else exact and all(r[3] == "excavation" for r in rows if len(r) == 4)
        elif kind == "crlf":
            eol = "\r\n"
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
        for name, expected in EXPECTED.items():
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
