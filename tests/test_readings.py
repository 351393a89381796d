"""Readings matched by instrument and station, depth or distance, in any row order and in the
formats instrument software and spreadsheets export (geoback.observation.readings); every mistake refused with
the file, line and station. Every column used, mapped or named in a refusal, point IDs, settlements,
the reference-end row and readings marked missing; readings placed in construction stages only as the
case or the file says; how they were matched said by `validate` and `run` (issues 18 and 23)."""
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
from geoback.commands.template import TEMPLATE
from geoback.commands.validation import check_case
from geoback.errors import CaseError
from geoback.inference.identification import identify, prepare
from geoback.observation.instruments import case_blocks
from geoback.observation.readings import read_readings, readings_report
from measure import run_cli

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


# ----------------------------------------------------------------------------------- issue 18, 23
# Every column used, mapped or named in a refusal; how rows were matched said; point IDs, settlements,
# the reference-end row, readings marked missing; readings placed in construction stages explicitly.
STAGED = CASES / "staged-tunnel.yaml"
I1_DEPTHS = [21.0, 18.0, 15.0, 12.0, 9.0, 6.0, 3.0]


def write_case(folder: Path, data: dict, files: dict | None = None, name: str = "case.yaml") -> Path:
    for fname, text in (files or {}).items():
        (folder / fname).write_bytes(text if isinstance(text, bytes) else text.encode())
    path = folder / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def paper_i1_file(folder: Path, text: str, **fields) -> Path:
    """The paper case with I1 reading from its own file `text` (X1 inline)."""
    data = yaml.safe_load(PAPER.read_text())
    data["instruments"][0].pop("readings")
    data["instruments"][0].update(readings_file="i1.csv", **fields)
    return write_case(folder, data, {"i1.csv": text})


def head_first(header: str, values=None) -> str:
    """I1's readings as inclinometer software exports them: head first, by depth."""
    values = yaml.safe_load(PAPER.read_text())["instruments"][0]["readings"] if values is None else values
    return header + "\n" + "".join(f"{z:g},{v!r}\n" for z, v in sorted(zip(I1_DEPTHS, values)))


def refusal(path: Path) -> str:
    with pytest.raises(CaseError) as exc:
        prepare(load_case(path))
    message = str(exc.value)
    assert message.startswith(str(path)) and "instruments[" in message, message  # located in the case file
    return message


def test_metro_export_unknown_depth_header_refused_or_mapped(tmp_path, reference):
    """The metro reproducer: a head-first export whose depth column geoback does not know was taken in
    file order (a wrong estimate, exit 0); now it is refused, naming the column, or matched by depth
    when the case maps it, giving the paper's readings and estimate bit for bit."""
    x0, p0, _ = reference
    path = paper_i1_file(tmp_path, head_first("Teufe [m],reading [m]"))
    proc = run_cli(["validate", path], tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f"{path}:" in proc.stderr and "instruments[0].readings_file: i1.csv, line 1" in proc.stderr
    assert "'Teufe [m]', which geoback does not know" in proc.stderr
    assert "columns: {depth: 'Teufe [m]'}" in proc.stderr
    mapped = paper_i1_file(tmp_path, head_first("Teufe [m],reading [m]"), columns={"depth": "Teufe [m]"})
    np.testing.assert_array_equal(measured(mapped), x0)
    np.testing.assert_array_equal(identify(load_case(mapped)).fit.p, p0)
    verdict = check_case(load_case(mapped))
    assert "I1: 7 readings from i1.csv matched by depth (lines 2-8)" in verdict, verdict
    assert "columns mapped by the case: Teufe [m] as depth" in verdict


@pytest.mark.parametrize("header", ["Tiefe [m]", "profondeur (m)", "z", "DEPTH", "Depth (cm)"])
def test_depth_in_common_spellings(tmp_path, reference, header):
    x0 = reference[0]
    scale = 100.0 if "cm" in header else 1.0
    text = f"{header},reading\n" + "".join(f"{z * scale:g},{float(v)!r}\n" for z, v in sorted(zip(I1_DEPTHS, x0[:7])))
    np.testing.assert_array_equal(measured(paper_i1_file(tmp_path, text)), x0)


def test_unknown_columns_named_ignored_or_mapped(tmp_path, reference):
    x0, _, rows = reference
    text = csv_text([r + ("2024-03-01",) for r in rows], ("instrument", "station", "reading", "Bemerkung"), (0, 1, 4, 5))
    m = _error(tmp_path, text)
    assert "r.csv, line 1" in m and "found 'Bemerkung', which geoback does not know" in m
    np.testing.assert_array_equal(measured(paper_with_file(tmp_path, text, ignore_columns=["Bemerkung"])), x0)
    m = refusal(paper_with_file(tmp_path, text, ignore_columns=["Date"]))
    assert "ignore_columns[0]" in m and "'Date', which is none of its columns" in m
    m = refusal(paper_with_file(tmp_path, text, columns={"depth": "Tiefe"}))
    assert "columns.depth" in m and "expected one column 'Tiefe' in r.csv, found none" in m
    two = csv_text(rows, ("instrument", "station", "depth", "reading"), (0, 1, 2, 4)).replace("depth", "z")
    text2 = two.replace("instrument,station,z,reading", "instrument,station,z,reading,Tiefe")
    text2 = "\n".join(ln + (",0" if i else "") for i, ln in enumerate(text2.splitlines())) + "\n"
    assert "two columns mean the depth ('z' and 'Tiefe')" in _error(tmp_path, text2)


def test_a_second_position_column_is_checked(tmp_path, reference):
    x0, _, rows = reference
    text = csv_text(rows, ("instrument", "station", "depth [m]", "reading"), (0, 1, 2, 4))
    np.testing.assert_array_equal(measured(paper_with_file(tmp_path, text)), x0)
    bad = text.replace("I1,4,12.0,", "I1,4,13.0,")
    assert "line 5: depth 13 m disagrees with station 4 of inclinometer 'I1' (depth 12 m" in _error(tmp_path, bad)


# settlement points: by offset, by ID, as settlements
def template_case() -> dict:
    """`geoback init`'s case: the paper's instruments and surface settlement points S1 (uy)."""
    data = yaml.safe_load(TEMPLATE)
    data.pop("forecasts")
    return data


def s1(data: dict) -> dict:
    return next(ins for ins in data["instruments"] if ins["name"] == "S1")


@pytest.fixture(scope="module")
def template_reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("template")
    path = write_case(folder, template_case())
    analysis = prepare(load_case(path))
    return analysis.misfit.data.measured.copy(), identify(analysis).fit.p


def test_settlement_points_by_offset_in_any_order(tmp_path, template_reference):
    x0, p0 = template_reference
    data = template_case()
    pts, values = s1(data)["points"], s1(data).pop("readings")
    rows = list(zip([p[0] for p in pts], values))[::-1]
    s1(data)["readings_file"] = "s1.csv"
    path = write_case(tmp_path, data, {"s1.csv": "offset [m];reading [m]\n" + "".join(
        f"{x:g};{v!r}\n" for x, v in rows)})
    np.testing.assert_array_equal(measured(path), x0)
    assert "S1: 7 readings from s1.csv matched by x" in check_case(load_case(path))
    both = "x,y,reading\n" + "".join(f"{x:g},0,{v!r}\n" for x, v in rows)  # x and y: y checked
    np.testing.assert_array_equal(measured(write_case(tmp_path, data, {"s1.csv": both})), x0)
    off = both.replace("\n10,0,", "\n10.5,0,")
    assert "x 10.5 m and y 0 m match no station of points 'S1'" in refusal(write_case(tmp_path, data, {"s1.csv": off}))


def test_two_points_at_one_offset_are_refused_not_guessed(tmp_path):
    data = template_case()
    s1(data)["points"][1] = [0.0, -2.0]  # below the first point: the same x
    s1(data).pop("readings")
    s1(data)["readings_file"] = "s1.csv"
    text = "x [m],reading\n0,-0.03\n0,-0.029\n" + "".join(f"{p[0]:g},-0.02\n" for p in s1(data)["points"][2:])
    m = refusal(write_case(tmp_path, data, {"s1.csv": text}))
    assert "line 2: x 0 m matches 2 stations of points 'S1' (1, 2): expected a position that tells them apart" in m


def test_point_ids_listed_sorted_or_refused(tmp_path, template_reference):
    x0, _ = template_reference
    data = template_case()
    values = s1(data).pop("readings")
    ids = [f"SP-{k + 1:02d}" for k in range(len(values))]
    text = "point,reading [mm]\n" + "".join(f"{i},{v * 1000!r}\n" for i, v in reversed(list(zip(ids, values))))
    s1(data)["readings_file"] = "s1.csv"
    m = refusal(write_case(tmp_path, data, {"s1.csv": text}))
    assert "point 'SP-07' is an ID, not a point number" in m and "point_ids" in m
    s1(data)["point_ids"] = ids
    got = measured(write_case(tmp_path, data, {"s1.csv": text}))
    np.testing.assert_allclose(got, x0, rtol=1e-12, atol=0)
    s1(data)["point_ids"] = ids[::-1]  # a different list: a different (wrong, but stated) matching
    assert not np.allclose(measured(write_case(tmp_path, data, {"s1.csv": text})), x0)
    s1(data)["point_ids"] = "sorted"
    path = write_case(tmp_path, data, {"s1.csv": text})
    np.testing.assert_allclose(measured(path), x0, rtol=1e-12, atol=0)
    assert "matched by point ID in sorted order (point_ids: sorted: SP-01 = point 1" in check_case(load_case(path))
    s1(data)["point_ids"] = ids
    unknown = text.replace("SP-03,", "SP-3,")
    assert "point 'SP-3' is not a point of 'S1' (point_ids: SP-01" in refusal(
        write_case(tmp_path, data, {"s1.csv": unknown}))
    s1(data)["point_ids"] = ids[:3]
    with pytest.raises(CaseError, match="expected one point ID per point \\(7\\), found 3"):
        load_case(write_case(tmp_path, data))


def test_settlement_column_and_sign(tmp_path, template_reference):
    x0, _ = template_reference
    data = template_case()
    values = s1(data).pop("readings")
    s1(data)["readings_file"] = "s1.csv"
    text = "point,settlement [mm]\n" + "".join(f"{k + 1},{-v * 1000!r}\n" for k, v in enumerate(values))
    path = write_case(tmp_path, data, {"s1.csv": text})
    np.testing.assert_allclose(measured(path), x0, rtol=1e-12, atol=0)
    assert "settlement column: u_y = -reading (positive down)" in check_case(load_case(path))
    inline = template_case()
    s1(inline).update(readings=[-v for v in values], sign="settlement")
    np.testing.assert_array_equal(measured(write_case(tmp_path, inline)), x0)
    s1(data)["sign"] = "uy"
    assert "instruments[2].sign: expected readings positive up (sign: uy), found a settlement column" in refusal(
        write_case(tmp_path, data, {"s1.csv": text}))
    s1(data).pop("sign")
    s1(data)["components"] = ["ux"]
    assert "a settlement column gives vertical readings, but 'S1' reads ux" in refusal(
        write_case(tmp_path, data, {"s1.csv": text}))


# the reference end's row
def test_toe_row_checked_and_not_used(tmp_path, reference):
    x0, p0, _ = reference
    text = head_first("depth [m],reading [m]").replace("\n", "\n24,0\n", 1)  # the toe row first, as exported
    path = paper_i1_file(tmp_path, text)
    np.testing.assert_array_equal(measured(path), x0)
    assert "the toe row (line 2) checked to read 0 and not used" in check_case(load_case(path))
    m = refusal(paper_i1_file(tmp_path, text.replace("\n24,0\n", "\n24,0.0012\n")))
    assert "i1.csv, line 2: depth 24 m is the toe of inclinometer 'I1', which its readings are relative to: " \
           "expected 0 there" in m and "found 0.0012" in m
    absolute = paper_i1_file(tmp_path, text, readings_relative=False)
    assert "depth 24 m is the toe of inclinometer 'I1', not a station: its readings are absolute" in refusal(absolute)


# readings marked missing
@pytest.mark.parametrize("mark", ["", "-", "n/a", "NaN"])
def test_missing_reading_dropped_with_its_row_and_column(tmp_path, reference, mark):
    x0, _, _ = reference
    values = [float(v) for v in x0[:7]]
    values[3] = mark
    text = "depth [m],reading [m]\n" + "".join(f"{z:g},{v if isinstance(v, str) else repr(v)}\n"
                                                for z, v in zip(I1_DEPTHS, values))
    path = paper_i1_file(tmp_path, text)
    full = prepare(load_case(PAPER))
    analysis = prepare(load_case(path))
    keep = [i for i in range(12) if i != 3]
    data = analysis.misfit.data
    np.testing.assert_array_equal(data.measured, x0[keep])
    np.testing.assert_array_equal(data.covariance, full.misfit.data.covariance[np.ix_(keep, keep)])
    assert [lab.station for lab in data.labels[:6]] == [1, 2, 3, 5, 6, 7]
    i1 = analysis.simulation.survey.blocks[0]
    assert i1.kept == (0, 1, 2, 4, 5, 6) and i1.stations.shape == (6, 2)
    assert "marked missing and dropped (their rows and columns of C_x): station 4 (line 5)" in check_case(
        load_case(path))
    assert identify(analysis).fit.status == "converged"


def test_without_keeps_the_block_consistent():
    loaded = load_case(PAPER)
    b = case_blocks(loaded)[0]  # I1: relative to its toe, B's variance, W
    b = b.__class__(**{**b.__dict__, "constant_variances": {"B": 4e-6}})
    b = b.__class__(**{**b.__dict__, "covariance": b.covariance + 4e-6 * np.outer(b.constants[:, 0], b.constants[:, 0])})
    r = b.without([1, 4])
    keep = [0, 2, 3, 5, 6]
    assert [lab.station for lab in r.labels] == [1, 3, 4, 6, 7] and r.kept == tuple(keep)
    np.testing.assert_array_equal(r.weights, b.weights[keep])
    np.testing.assert_array_equal(r.covariance, b.covariance[np.ix_(keep, keep)])
    np.testing.assert_array_equal(r.constants, b.constants[keep])
    np.testing.assert_array_equal(r.integration, b.integration[keep])
    np.testing.assert_array_equal(r.stations, b.stations[keep])
    np.testing.assert_array_equal(r.points, b.points)  # the reference end still sampled (relative readings)
    identified = {b.constant_names[0]}
    np.testing.assert_allclose(r.covariance_given(identified), b.covariance_given(identified)[np.ix_(keep, keep)])
    twice = r.without([0])
    assert twice.kept == (2, 3, 5, 6) and twice.at("excavation").kept == twice.kept
    with pytest.raises(IndexError):
        r.without([5])


def test_missing_point_gives_the_estimate_of_the_case_without_it(tmp_path):
    """A settlement point marked missing in the file = the point deleted from the case: the same
    estimate, bit for bit (the mesh does not depend on the instruments without size_instruments)."""
    data = template_case()
    values = s1(data).pop("readings")
    s1(data)["readings_file"] = "s1.csv"
    text = "point,reading\n" + "".join(f"{k + 1},{'n/a' if k == 2 else repr(v)}\n" for k, v in enumerate(values))
    marked = identify(load_case(write_case(tmp_path, data, {"s1.csv": text}, "marked.yaml")))
    deleted = template_case()
    del s1(deleted)["points"][2], s1(deleted)["readings"][2]
    gone = identify(load_case(write_case(tmp_path, deleted, name="deleted.yaml")))
    np.testing.assert_array_equal(marked.data.measured, gone.data.measured)
    np.testing.assert_array_equal(marked.fit.p, gone.fit.p)
    np.testing.assert_array_equal(marked.reliability.std, gone.reliability.std)


def test_missing_primary_reading_is_refused(tmp_path):
    text = "station,reading [mrad]\n1,-1.5\n2,-\n3,-4.2\n4,-5.8\n5,0.5\n6,7.3\n7,4.2\n"
    m = refusal(paper_i1_file(tmp_path, text, reading_type="primary"))
    assert "line 3: the primary reading of station 2 of 'I1' is marked missing" in m
    assert "integrated through it" in m


def test_missing_linewise_station_runs_plots_and_locates(tmp_path, reference):
    """The figures and the diagnosis's mismatch location take an inclinometer with a station dropped."""
    from geoback.commands.run import run_case
    from geoback.diagnosis.procedure import locate

    x0 = reference[0]
    text = "station,reading\n" + "".join(f"{k + 1},{'-' if k == 2 else repr(float(v))}\n" for k, v in enumerate(x0[:7]))
    loaded = load_case(paper_i1_file(tmp_path, text))
    res = run_case(loaded, tmp_path / "out", plots=True)
    assert (tmp_path / "out" / "instruments.png").exists() and res.fit.status == "converged"
    report = (tmp_path / "out" / "report.md").read_text()
    assert "I1: 6 readings from i1.csv matched by station" in report
    assert "station 3 (line 4)" in report
    found = locate(prepare(loaded).misfit, res.fit, res.reliability)
    assert {mm.instrument for mm in found} == {"I1", "X1"}


# validate: instruments without readings, every problem at once; run names them
def test_validate_names_instruments_without_readings_and_run_refuses_naming_them(tmp_path):
    data = template_case()
    for ins in data["instruments"][1:]:
        ins.pop("readings")
    path = write_case(tmp_path, data)
    proc = run_cli(["validate", path], tmp_path)
    # issue 23: what run refuses before fitting, validate refuses too (the same located line)
    assert proc.returncode == 2, proc.stdout
    assert "found none for X1, S1" in proc.stderr and "Traceback" not in proc.stderr
    run = run_cli(["run", path, "--out", tmp_path / "out"], tmp_path)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    (line,) = run.stderr.strip().splitlines()
    assert f"{path}:" in line and "instruments[1]: expected readings of every instrument to identify parameters, " \
                                  "found none for X1, S1" in line
    assert proc.stderr.strip() == run.stderr.strip()


def test_validate_lists_every_readings_problem(tmp_path, reference):
    data = yaml.safe_load(PAPER.read_text())
    for ins, text in zip(data["instruments"], ["station,reading\n1,0.1\n", "station,reading,Bemerkung\n1,0.1,x\n"]):
        ins.pop("readings")
        ins["readings_file"] = f"{ins['name']}.csv"
        (tmp_path / ins["readings_file"]).write_text(text)
    path = write_case(tmp_path, data)
    proc = run_cli(["validate", path], tmp_path)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 2, proc.stderr
    assert "instruments[0].readings_file: I1.csv: 'I1' has no reading for station 2" in lines[0]
    assert "instruments[1].readings_file: X1.csv, line 1" in lines[1] and "'Bemerkung'" in lines[1]
    run = run_cli(["run", path, "--out", tmp_path / "out"], tmp_path)
    assert run.returncode == 2 and run.stderr.strip() == lines[0] + " (and 1 more problem)"


def test_run_echoes_how_readings_were_matched(tmp_path, reference):
    path = paper_i1_file(tmp_path, head_first("Tiefe [m],reading [m]"))
    proc = run_cli(["run", path, "--out", tmp_path / "out"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "readings: I1: 7 readings from i1.csv matched by depth (lines 2-8)" in proc.stderr
    assert "readings: X1: 5 readings inline in station order" in proc.stderr
    summary = yaml.safe_load((tmp_path / "out" / "summary.json").read_text())
    assert summary["readings_matched"][0].startswith("I1: 7 readings from i1.csv matched by depth")


def test_station_order_is_said(tmp_path, reference):
    path = paper_i1_file(tmp_path, "reading\n" + "".join(f"{float(v)!r}\n" for v in reference[0][:7]))
    assert "I1: 7 readings from i1.csv taken in station order from the reference end: the file has no position " \
           "column" in check_case(load_case(path))


# issue 23: construction stages
def staged_case(folder: Path, text: str, **fields) -> Path:
    data = yaml.safe_load(STAGED.read_text())
    for ins in data["instruments"]:
        ins.update(readings_file="r.csv", **fields)
    return write_case(folder, data, {"r.csv": text})


def staged_rows(stage: str | None = None, with_stage: bool = True) -> str:
    lines = (CASES / "staged-tunnel-readings.csv").read_text().splitlines()
    rows = [ln.split(",") for ln in lines[1:] if stage is None or ln.split(",")[1] == stage]
    if with_stage:
        return "\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n"
    return "\n".join(["instrument,station,reading [mm]"] + [",".join([r[0], r[2], r[3]]) for r in rows]) + "\n"


def test_staged_file_without_stage_column_refused_unless_the_case_says(tmp_path):
    path = staged_case(tmp_path, staged_rows("advance", with_stage=False))
    proc = run_cli(["validate", path], tmp_path)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 3, proc.stderr  # every instrument named, none silently placed
    for line, name in zip(lines, ("I1", "X1", "S1")):
        assert "readings_file: r.csv has no stage column and the case has construction stages advance, lined" in line
        assert f"the readings of '{name}' were taken at" in line
    tagged = prepare(load_case(staged_case(tmp_path, staged_rows("advance"))))
    stated = prepare(load_case(staged_case(tmp_path, staged_rows("advance", with_stage=False), stage="advance")))
    np.testing.assert_array_equal(stated.misfit.data.measured, tagged.misfit.data.measured)
    assert {b.stage for b in stated.simulation.survey.blocks} == {"advance"}
    verdict = check_case(load_case(staged_case(tmp_path, staged_rows("advance", with_stage=False), stage="advance")))
    assert "I1: 11 readings from r.csv matched by station (lines 2-12); at stage advance (stage: advance in the " \
           "case)" in verdict
    assert "advance 11, lined 11 (stage column)" in check_case(load_case(staged_case(tmp_path, staged_rows())))
    m = refusal(staged_case(tmp_path, staged_rows("advance"), stage="advance"))
    assert "instruments[0].stage: expected either a stage column in r.csv or stage: in the case, found both" in m
    m = refusal(staged_case(tmp_path, staged_rows("advance", with_stage=False), stage="final"))
    assert "instruments[0].stage: expected one of the construction stages (advance, lined), found 'final'" in m


def test_staged_inline_list_needs_its_stage(tmp_path):
    data = yaml.safe_load(STAGED.read_text())
    tagged = prepare(load_case(STAGED))
    lined = {b.name: tagged.misfit.data.measured[rows] for b, rows in tagged.misfit.data.block_rows()
             if b.stage == "lined"}
    for ins in data["instruments"]:
        ins.pop("readings_file")
        ins["readings"] = [float(v) for v in lined[ins["name"]]]
    m = refusal(write_case(tmp_path, data))
    assert "instruments[0].readings: expected the stage these readings of 'I1' were taken at" in m
    assert "the case has construction stages advance, lined, found a list" in m
    for ins in data["instruments"]:
        ins["stage"] = "lined"
    analysis = prepare(load_case(write_case(tmp_path, data)))
    assert {b.stage for b in analysis.simulation.survey.blocks} == {"lined"}
    np.testing.assert_array_equal(analysis.misfit.data.measured, np.concatenate(list(lined.values())))
    data["instruments"][0]["readings"] = {"lined": data["instruments"][0]["readings"]}
    m = refusal(write_case(tmp_path, data))
    assert "instruments[0].stage: expected either readings by stage (a mapping) or stage:, found both" in m


def test_read_readings_returns_values_and_notes(tmp_path, reference):
    loaded = load_case(paper_i1_file(tmp_path, head_first("depth [m],reading [m]")))
    got = read_readings(loaded, case_blocks(loaded), ["excavation"])
    assert [n.instrument for n in got.notes] == ["I1", "X1"] and got.unread == []
    note = got.notes[0]
    assert (note.source, note.count, note.stages, note.staged_by) == ("i1.csv", 7, (("excavation", 7),),
                                                                      "the case's only stage")
    assert note.how.startswith("matched by depth")
    np.testing.assert_array_equal(got.values["I1"]["excavation"], reference[0][:7])
    assert readings_report(loaded).lines() == [n.text() for n in got.notes]
