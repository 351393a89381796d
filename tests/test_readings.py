"""Readings matched by instrument and station, depth or distance, in any row order and in the
formats instrument software and spreadsheets export (geoback.observation.readings); every mistake refused with
the file, line and station."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import CASES
from geoback.case.loading import load_case
from geoback.errors import CaseError
from geoback.inference.identification import identify, prepare

PAPER = CASES / "tunnel-paper.yaml"


def paper_with_file(folder: Path, text: str | bytes, name: str = "r.csv", **instrument_fields) -> Path:
    """The paper case with both instruments reading from one file (`text`)."""
    data = yaml.safe_load(PAPER.read_text())
    for ins in data["instruments"]:
        ins.pop("readings")
        ins["readings_file"] = name
        ins.update(instrument_fields)
    (folder / name).write_bytes(text if isinstance(text, bytes) else text.encode())
    path = folder / "case.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def reference():
    """The paper case's readings (inline, station order) and their identification."""
    analysis = prepare(load_case(PAPER))
    data = yaml.safe_load(PAPER.read_text())
    rows = []  # (instrument, station, depth, distance, value)
    for block, ins in zip(analysis.simulation.survey.blocks, data["instruments"]):
        dist = np.cumsum(block.lengths)
        for k, v in enumerate(ins["readings"]):
            rows.append((ins["name"], k + 1, -block.points[k, 1], dist[k], repr(float(v))))
    return analysis.misfit.data.measured.copy(), identify(analysis).fit.p, rows


def csv_text(rows, header=("instrument", "station", "reading"), cols=(0, 1, 4), delim=",") -> str:
    lines = [delim.join(header)] + [delim.join(str(r[c]) for c in cols) for r in rows]
    return "\n".join(lines) + "\n"


def measured(path: Path) -> np.ndarray:
    return prepare(load_case(path)).misfit.data.measured


# ----------------------------------------------------------------------------------- any order
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(order=st.permutations(range(12)), position=st.sampled_from(["station", "depth", "distance"]),
       header_case=st.sampled_from(["lower", "upper", "title"]))
def test_any_row_order_and_position_column_gives_identical_readings(tmp_path_factory, reference, order, position,
                                                                    header_case):
    x0, _, rows = reference
    col = {"station": 1, "depth": 2, "distance": 3}[position]
    if position == "depth":  # the extensometer is vertical from the surface: depth = distance
        pass
    header = [getattr(h, header_case)() for h in ("instrument", position, "reading")]
    text = csv_text([rows[i] for i in order], header, (0, col, 4))
    folder = tmp_path_factory.mktemp("order")
    np.testing.assert_array_equal(measured(paper_with_file(folder, text)), x0)


def test_head_first_export_and_identical_estimate(tmp_path, reference):
    """Inclinometer software lists depths top-down (head first): same readings, same estimate, bit for bit."""
    x0, p0, rows = reference
    head_first = sorted(rows, key=lambda r: (r[0], r[2]))  # by instrument, then depth downwards
    path = paper_with_file(tmp_path, csv_text(head_first, ("Instrument", "Depth [m]", "Reading [m]"), (0, 2, 4)))
    np.testing.assert_array_equal(measured(path), x0)
    np.testing.assert_array_equal(identify(load_case(path)).fit.p, p0)


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16", "cp1252"])
def test_encodings_and_byte_order_marks(tmp_path, reference, encoding):
    x0, _, rows = reference
    text = "# exported by a spreadsheet: é\n" + csv_text(rows)
    np.testing.assert_array_equal(measured(paper_with_file(tmp_path, text.encode(encoding))), x0)


def test_semicolons_decimal_commas_and_millimetres(tmp_path, reference):
    x0, _, rows = reference
    lines = ["Instrument;Station;Reading (mm)"]
    for r in rows:
        mm = f"{float(r[4]) * 1000:.12g}".replace(".", ",")
        lines.append(f"{r[0]};{r[1]};{mm}")
    got = measured(paper_with_file(tmp_path, "\n".join(lines) + "\n"))
    np.testing.assert_allclose(got, x0, rtol=1e-11, atol=1e-15)


def test_tabs_and_spaces(tmp_path, reference):
    x0, _, rows = reference
    np.testing.assert_array_equal(measured(paper_with_file(tmp_path, csv_text(rows, delim="\t"))), x0)
    spaced = "instrument station reading\n" + "\n".join(f"{r[0]}   {r[1]}  {r[4]}" for r in rows) + "\n"
    np.testing.assert_array_equal(measured(paper_with_file(tmp_path, spaced, name="s.txt")), x0)


def test_readings_unit_field(tmp_path, reference):
    x0, _, rows = reference
    text = csv_text([(r[0], r[1], r[2], r[3], repr(float(r[4]) * 1000)) for r in rows])
    got = measured(paper_with_file(tmp_path, text, readings_unit="mm"))
    np.testing.assert_allclose(got, x0, rtol=1e-12)


# ----------------------------------------------------------------------------------- mistakes
def _error(tmp_path, text, **fields) -> str:
    with pytest.raises(CaseError) as exc:
        prepare(load_case(paper_with_file(tmp_path, text, **fields)))
    message = str(exc.value)
    assert "case.yaml:" in message and "readings_file" in message, message  # located in the case file
    return message


def test_duplicate_station_is_named(tmp_path, reference):
    rows = reference[2] + [reference[2][3]]
    m = _error(tmp_path, csv_text(rows))
    assert "station 4 of 'I1' is given twice" in m and "line" in m


def test_missing_station_is_named(tmp_path, reference):
    rows = [r for r in reference[2] if not (r[0] == "I1" and r[1] == 6)]
    assert "'I1' has no reading for station 6" in _error(tmp_path, csv_text(rows))


def test_unknown_station_and_depth(tmp_path, reference):
    rows = list(reference[2])
    rows[0] = ("I1", 9) + rows[0][2:]
    assert "station 9 of inclinometer 'I1' does not exist (stations 1-7" in _error(tmp_path, csv_text(rows))
    rows = list(reference[2])
    rows[2] = rows[2][:2] + (7.5,) + rows[2][3:]
    m = _error(tmp_path, csv_text(rows, ("instrument", "depth", "reading"), (0, 2, 4)))
    assert "depth 7.5 m matches no station of inclinometer 'I1'" in m


def test_unknown_instrument_rows_are_refused(tmp_path, reference):
    rows = reference[2] + [("I9", 1, 0, 0, "0.01")]
    m = _error(tmp_path, csv_text(rows))
    assert "instrument 'I9', which is not in the case" in m


def test_ragged_row_bad_number_and_header(tmp_path, reference):
    text = csv_text(reference[2]).replace("I1,3,", "I1,3,0.1,")
    assert "expected 3 fields as in the header, found 4" in _error(tmp_path, text)
    text = csv_text(reference[2]).replace("I1,3,-0.0242546", "I1,3,abc")
    assert "line 4: expected a number for the reading, found 'abc'" in _error(tmp_path, text)
    text = csv_text(reference[2]).replace("instrument,station,reading", "instrument,station,mm")
    assert "expected a header with a column named reading" in _error(tmp_path, text)


def test_binary_file_and_unit_mismatch(tmp_path, reference):
    assert "binary data" in _error(tmp_path, b"\x00\x01\x02instrument,station,reading\n")
    text = csv_text(reference[2], ("instrument", "station", "reading [mm]"))
    assert "disagrees with the file's header unit" in _error(tmp_path, text, readings_unit="m")
    text = csv_text(reference[2], ("instrument", "station", "reading [kPa]"))
    assert "expected a reading unit" in _error(tmp_path, text)


def test_inline_readings_per_stage_and_unknown_stage(tmp_path):
    data = yaml.safe_load(PAPER.read_text())
    values = data["instruments"][0]["readings"]
    data["instruments"][0]["readings"] = {"excavation": values}
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    np.testing.assert_array_equal(prepare(load_case(path)).misfit.data.measured[:7], values)
    data["instruments"][0]["readings"] = {"heading": values}
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(CaseError, match="expected construction stages as keys \\(excavation\\), found 'heading'"):
        prepare(load_case(path))


# ----------------------------------------------------------------------------------- round trip
def test_readings_out_reads_back_identically(tmp_path):
    case = tmp_path / "paper.yaml"
    shutil.copy(PAPER, case)
    out = tmp_path / "r.csv"
    run = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "simulate", str(case), "--noise", "--seed", "3",
                          "--readings-out", str(out)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    lines = out.read_text().splitlines()
    assert lines[0].startswith("# geoback simulate paper.yaml: the case's values; a mesh 2 times finer")
    written = np.array([float(line.split(",")[-1]) for line in lines[2:]])
    data = yaml.safe_load(PAPER.read_text())
    for ins in data["instruments"]:
        ins.pop("readings")
        ins["readings_file"] = "r.csv"
    case.write_text(yaml.safe_dump(data, sort_keys=False))
    np.testing.assert_array_equal(prepare(load_case(case)).misfit.data.measured, written)
