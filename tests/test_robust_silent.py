"""Issue 23's last findings: nothing silent, from the library as from the command line.

- a lining modulus given in MPa where GPa was meant (or a bare number read in kPa) loaded without a
  word: now a located warning against a concrete lining's usual range, in validate, run and the
  library's notices and caveats;
- quoted numbers (`!!str 10`): most were used as the number, `order: !!str 2` was refused as "found
  '2'", and `!!str inf` in a reading passed validate and ended `run` in a SuperLU traceback: now every
  quoted number is the number it spells, checked as the number is;
- a surface point inside the ground of 80 layers of 0.5 m was "outside the meshed ground" (no file,
  no line): the long thin elements' centroids were not among the point's nearest; now found, and a
  point still outside is said with its instrument, located;
- stations (points, chord ends) 1e-9 m apart passed silently: refused below 1 mm, located;
- the library's forecast() on a fit that never moved returned numbers at the initial guess: refused in
  words, and `geoback run` says it skipped them with the same words (caveat 'forecast-skipped').

The library is called as a user would (load_case, prepare, identify, forecast), the command line
through a fresh interpreter.
"""
from __future__ import annotations

import copy
import json
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from geoback.case.loading import case_from_data, load_case
from geoback.errors import CaseError, GeobackError
from measure import run_cli

ROOT = Path(__file__).resolve().parents[1]
CASES = ROOT / "cases"
LOCATED = r"error: {file}:\d+:\d+: {field}: "


def _data(name: str) -> dict:
    data = yaml.safe_load((CASES / name).read_text(encoding="utf-8"))
    for ins in data["instruments"]:
        if "readings_file" in ins:
            ins["readings_file"] = str(CASES / ins["readings_file"])
    return data


def _write(tmp_path: Path, data: dict, name: str = "case.yaml") -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return path


def _refused(tmp_path: Path, path: Path, field: str, words: str) -> str:
    """`geoback validate` refuses the case: exit 2, file, line, column and field, the words, no traceback."""
    run = run_cli(["validate", path], tmp_path)
    assert run.returncode == 2, (run.stdout, run.stderr)
    assert re.match(LOCATED.format(file=re.escape(str(path)), field=re.escape(field)), run.stderr), run.stderr
    assert words in run.stderr and "Traceback" not in run.stderr, run.stderr
    return run.stderr


# ---------------------------------------------------------------------------------- a lining's E
@pytest.mark.parametrize("written, read, meant", [(30, "30 kPa", "30 GPa"), (30000, "30 MPa", "30 GPa"),
                                                  ("30 MPa", "30 MPa", "30 GPa")])
def test_lining_modulus_in_mpa_where_gpa_was_meant_is_said(tmp_path, written, read, meant):
    """The staged case's shotcrete written `E: 30` (read as 30 kPa) or `E: 30000` / `30 MPa` (30 MPa, a
    thousand times too soft for concrete) loaded silently, or was called "unusual for ground". Now the
    lining's own usual range (1 to 50 GPa) says so, at the field, in validate and in the library's
    notices (which every result carries as caveats)."""
    from geoback.inference.identification import prepare

    data = _data("staged-tunnel.yaml")
    data["construction"]["lining"]["E"] = written
    path = _write(tmp_path, data)
    run = run_cli(["validate", path], tmp_path)
    assert run.returncode == 0, run.stderr
    expected = (re.escape(f"warning: [implausible-input] {path}:") + r"\d+:\d+: construction\.lining\.E: " +
                re.escape(f"E[shotcrete] = {read} in the case is outside the usual range for a concrete or "
                          f"shotcrete lining (1 GPa to 50 GPa); was {meant} meant? a number without a unit is "
                          f"read in kPa: write the unit, e.g. '{meant}'"))
    assert re.search(expected, run.stdout), run.stdout
    notices = [c for c in prepare(load_case(path)).notices if c.code == "implausible-input"]
    assert [c.parameter for c in notices] == ["E[shotcrete]"]
    assert re.search(expected, f"warning: [implausible-input] {notices[0].message}"), notices[0].message


def test_a_usual_lining_modulus_is_not_warned_and_ground_keeps_its_range(tmp_path):
    """5 GPa shotcrete (the shipped case): no warning; a ground modulus keeps the ground's range and its
    words (E = 40 GPa: written in Pa? 40 MPa meant), now located too."""
    from geoback.inference.identification import prepare

    assert not [c for c in prepare(load_case(CASES / "staged-tunnel.yaml")).notices if c.code == "implausible-input"]
    data = _data("staged-tunnel.yaml")
    data["ground"]["layers"][0]["E"] = 40_000_000
    path = _write(tmp_path, data)
    (notice,) = [c for c in prepare(load_case(path)).notices if c.code == "implausible-input"]
    assert notice.parameter == "E[clay]" and re.match(
        re.escape(str(path)) + r":\d+:\d+: ground\.layers\[0\]\.E: E\[clay\] = 40 GPa in the case is outside the usual "
        r"range for ground \(500 kPa to 20 GPa\); was it written in Pa\? .*'40 MPa'$", notice.message), notice.message


def test_run_writes_the_lining_warning_in_summary_json(tmp_path):
    """The machine-readable warnings of `geoback run` carry it (code, parameter, located message)."""
    data = _data("staged-tunnel.yaml")
    data["construction"]["lining"]["E"] = "30 MPa"
    data["mesh"] = {"size_tunnel": 1.0, "size_far": 6.0}
    path = _write(tmp_path, data)
    env = {**__import__("os").environ, "GEOBACK_CACHE": str(tmp_path / "cache")}
    run = run_cli(["run", path, "-q", "--out", tmp_path / "out"], tmp_path, env=env)
    assert run.returncode in (0, 1), run.stderr
    warnings = json.loads((tmp_path / "out" / "summary.json").read_text())["warnings"]
    (w,) = [w for w in warnings if w["code"] == "implausible-input"]
    assert w["parameter"] == "E[shotcrete]" and "construction.lining.E" in w["message"] and "30 GPa meant" in w["message"]


# ---------------------------------------------------------------------------------- quoted numbers
def _leaves(d, at=()):
    if isinstance(d, dict):
        for k, v in d.items():
            yield from _leaves(v, at + (k,))
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield from _leaves(v, at + (i,))
    else:
        yield at, d


def _set(d, at, v):
    for a in at[:-1]:
        d = d[a]
    d[at[-1]] = v


@pytest.mark.parametrize("name", ["tunnel-paper.yaml", "staged-forecast.yaml", "plastic-tunnel.yaml",
                                  "tunnel-paper-error-scales.yaml"])
def test_every_quoted_number_is_the_number_it_spells(name):
    """Each number of a shipped case written quoted (as `!!str 0.49` gives it) loads to the same case:
    used exactly, wherever it is (a design's `vary` values too, whose candidates keep their names)."""
    from geoback.case.checks import expand_candidates

    data = _data(name)
    base = case_from_data(data)
    count = 0
    for at, v in _leaves(data):
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            quoted = copy.deepcopy(data)
            _set(quoted, at, repr(v))
            case = case_from_data(quoted)
            if "vary" in at:
                assert expand_candidates(case.design) == expand_candidates(base.design), at
            else:
                assert case == base, at
            count += 1
    assert count > 20


def test_quoted_numbers_in_the_file(tmp_path):
    """`order: !!str 2` was refused ("expected one of 1 or 2, found '2'") while `nu: !!str 0.49` was
    used: now both are the numbers they spell. `!!str inf` (or '1e400', 'nan') in a reading passed
    validate and ended `run` in "RuntimeError: Factor is exactly singular": now refused as `.inf` is."""
    text = (CASES / "tunnel-paper.yaml").read_text(encoding="utf-8")
    path = tmp_path / "order.yaml"
    path.write_text(text.replace("  size_far: 4.0\n", "  size_far: 4.0\n  order: !!str 2\n"), encoding="utf-8")
    assert load_case(path).case == load_case(CASES / "tunnel-paper.yaml").case
    for bad in ("!!str inf", "!!str 1e400", "!!str nan", "'-Infinity'"):
        path = tmp_path / "reading.yaml"
        path.write_text(text.replace("readings: [-0.00462415,", f"readings: [{bad},"), encoding="utf-8")
        _refused(tmp_path, path, "instruments[0].readings[0]", "expected a finite number, found '")


@pytest.mark.parametrize("vary, field, words", [
    ({"points": [[[float("-inf"), 0.0]], [[1.5, 0.0]]]}, "design.candidates[1].vary.points[0][0][0]",
     "expected a finite number, found minus infinity"),
    ({"points": [[[1.5, 0.0]], [[1.0]]]}, "design.candidates[1].vary.points[1][0]",
     "expected 2 values [x, y], found a list of 1 item"),
])
def test_a_bad_value_in_a_vary_list_is_located_at_the_value(tmp_path, vary, field, words):
    """The slow API fuzzer's find: a design candidate's `vary: {points: [[[-.inf, 0]], ...]}` was refused as
    "design.candidates: expected every varied candidate to be a valid instrument, found points.0.0: Value
    error, expected a finite number, found minus infinity" (pydantic's words, the value's line lost).
    Now at the value, in the words the case's own fields get."""
    data = _data("staged-forecast.yaml")
    data["design"]["candidates"][1]["vary"] = vary
    path = _write(tmp_path, data)
    message = _refused(tmp_path, path, field, words)
    assert "Value error" not in message and "varied candidate" not in message


# ---------------------------------------------------------------------------------- points in the mesh
def _thin_layers(n: int = 80, thickness: float = 0.5) -> dict:
    """The paper case on `n` layers of `thickness`, meshed coarsely far out (10 m elements over 0.5 m
    layers: long thin elements at the surface), with surface settlement points."""
    data = _data("tunnel-paper.yaml")
    data["geometry"]["depth"] = n * thickness + 5
    data["ground"]["layers"] = [{"name": f"L{i}", "top": i * thickness, "E": "10 MPa", "nu": 0.49} for i in range(n)]
    data["parameters"][0] = {"name": "E[L0]", "initial": "5 MPa", "bounds": [100, 1.0e6]}
    data["mesh"] = {"size_tunnel": 0.4, "size_far": 10.0}
    xs = [0.0, 1.0, 2.0, 5.0, 7.5, 12.5, 20.0, 33.3, 39.9, 40.0]
    data["instruments"].append({"name": "S", "kind": "points", "points": [[x, 0.0] for x in xs], "components": ["uy"],
                                "sigma": 0.0005, "readings": [-0.01] * len(xs)})
    return data


def test_surface_points_in_thin_layers_are_inside_the_mesh(tmp_path):
    """80 layers of 0.5 m: the point (20, 0) was "outside the meshed ground" (exit 2, no file or line).
    Now validate accepts the case, and every point is read in the element that holds it."""
    from geoback.inference.identification import prepare

    path = _write(tmp_path, _thin_layers())
    run = run_cli(["validate", path], tmp_path)
    assert run.returncode == 0 and "S: 10 readings" in run.stdout, run.stderr
    sim = prepare(load_case(path)).simulation
    fe = sim.fe
    points = np.array([[x, 0.0] for x in (0.0, 1.0, 2.0, 5.0, 7.5, 12.5, 20.0, 33.3, 39.9, 40.0)])
    elem, ref = fe.locate(points)
    assert np.all(elem >= 0)
    lam = np.column_stack([1 - ref.sum(axis=1), ref])
    assert np.all(lam >= -1e-9)  # inside its element, not snapped
    corners = fe.nodes[fe.tri[elem][:, :3]]  # the element's straight-sided corners hold the point
    back = np.einsum("nk,nkx->nx", lam, corners)
    np.testing.assert_allclose(back, points, atol=1e-9)
    u = sim.displacements_at(sim.quantities(), points)
    assert np.all(np.isfinite(u)) and np.all(u[:, 1] < 0)  # the surface settles over the tunnel


def test_a_point_on_the_wall_within_the_case_tolerance_is_read_at_the_wall(tmp_path):
    """(2.9999999, -10) is on the tunnel wall within the case's tolerance (1e-6 of the radius) but 1e-7 m
    inside the meshed hole: validate said "point (3, -10) lies outside the meshed ground" without a
    file. Now read at the wall, where the displacement field is continuous."""
    from geoback.inference.identification import prepare

    data = _data("tunnel-paper.yaml")
    data["instruments"].append({"name": "W", "kind": "points", "points": [[2.9999999, -10.0]],
                                "components": ["ux"], "sigma": 0.0005, "readings": [0.01]})
    path = _write(tmp_path, data)
    run = run_cli(["validate", path], tmp_path)
    assert run.returncode == 0, run.stderr
    sim = prepare(load_case(path)).simulation
    u = sim.displacements_at(sim.quantities(), np.array([[2.9999999, -10.0], [3.0, -10.0]]))
    np.testing.assert_allclose(u[0], u[1], rtol=1e-9, atol=0)


def test_a_point_outside_the_mesh_is_said_with_its_instrument():
    """A point the survey cannot place (the case's checks let none through now; the message is the
    survey's last word) names the instrument, located in the case file."""
    from geoback.observation.instruments import case_blocks
    from geoback.physics.factory import make_simulation
    from geoback.physics.simulation import stage_survey

    loaded = load_case(CASES / "tunnel-paper.yaml")
    sim = make_simulation(loaded)
    blocks = [b.at("excavation") for b in case_blocks(loaded)]
    blocks[1] = replace(blocks[1], points=blocks[1].points + np.array([100.0, 0.0]))
    with pytest.raises(CaseError) as info:
        stage_survey(loaded, blocks, ["excavation"], sim.fe)
    assert re.match(re.escape(str(CASES / "tunnel-paper.yaml")) + r":\d+:\d+: instruments\[1\]: expected every point "
                    r"instrument 'X1' reads inside the meshed ground, found \(100, -1\.25\) outside it",
                    str(info.value)), str(info.value)


# ---------------------------------------------------------------------------------- stations apart
@pytest.mark.parametrize("change, field, words", [
    (lambda d: d["instruments"][0].update(spacing=1e-9, stations=7), "instruments[0].spacing",
     "expected stations at least 0.001 m apart, found spacing 1e-09 m: no instrument reads closer"),
    (lambda d: d["instruments"][1].update(spacing=None, stations=None, lengths=[1.25, 1e-9, 1.25]),
     "instruments[1].lengths[1]", "expected stations at least 0.001 m apart, found 1e-09 m"),
    (lambda d: d["instruments"].append({"name": "S", "kind": "points", "points": [[5.0, 0.0], [5.000000001, 0.0]],
                                        "components": ["uy"], "sigma": 5e-4, "readings": [-0.01, -0.01]}),
     "instruments[2].points[1]", "expected points at least 0.001 m apart, found (5, 0) 1e-09 m from points[0] (5, 0)"),
    (lambda d: d["instruments"].append({"name": "S", "kind": "points", "points": [[5.0, 0.0], [9.0, 0.0], [5.0, 0.0]],
                                        "components": ["uy"], "sigma": 5e-4, "readings": [-0.01] * 3}),
     "instruments[2].points[2]", "found (5, 0) at the same place as points[0]"),
    (lambda d: d["instruments"].append({"name": "C", "kind": "convergence", "points": [[0.0, -7.0], [1e-9, -7.0]],
                                        "sigma": 5e-4, "readings": [-0.001]}),
     "instruments[2].points[1]", "expected chord ends at least 0.001 m apart, found (1e-09, -7) 1e-09 m from points[0]"),
], ids=["spacing", "lengths", "points", "same-point", "chord"])
def test_stations_closer_than_a_millimetre_are_refused(tmp_path, change, field, words):
    """Stations 1e-9 m apart passed validate and run silently (a fit to one place counted twice, or to a
    nanometre's slope): refused below 1 mm, located, by validate and by the library's load_case."""
    data = _data("tunnel-paper.yaml")
    change(data)
    for ins in data["instruments"]:
        for key in [k for k, v in ins.items() if v is None]:
            del ins[key]
    path = _write(tmp_path, data)
    _refused(tmp_path, path, field, words)
    with pytest.raises(CaseError) as info:
        load_case(path)
    assert info.value.field == field and words in info.value.reason


# ---------------------------------------------------------------------------------- forecasts
def _unmoved(tmp_path: Path) -> Path:
    """The staged forecast case by Gauss-Newton from E = 1000 GPa: no step decreases J."""
    data = _data("staged-forecast.yaml")
    data["parameters"][0] = {"name": "E", "initial": 1.0e9}
    data["fit"]["method"] = "gn"
    return _write(tmp_path, data)


UNMOVED = ("the identification stopped without moving from the initial values (no step decreased J), so there is "
           "no estimate to forecast from, only the initial guess; fix the case (initial values, bounds, or fit "
           "method lm) and identify again")


def test_forecast_of_a_fit_that_never_moved_is_refused(tmp_path):
    """The library's forecast() returned numbers at the initial guess (settlements of 0.6 um with a
    band) where `geoback run` silently wrote none: refused now, in the words run now writes."""
    import geoback

    analysis = geoback.prepare(geoback.load_case(_unmoved(tmp_path)))
    res = geoback.identify(analysis, profile="none")
    assert not res.fit.moved
    with pytest.raises(GeobackError) as info:
        geoback.forecast(analysis, res)
    assert str(info.value) == "forecast: " + UNMOVED


def test_run_says_it_skipped_the_forecasts(tmp_path):
    """`geoback run` on the same case: exit 1 (did not move), no forecast.csv, and a 'forecast-skipped'
    warning with the same words in summary.json and on the terminal."""
    path = _unmoved(tmp_path)
    env = {**__import__("os").environ, "GEOBACK_CACHE": str(tmp_path / "cache")}
    run = run_cli(["run", path, "--out", tmp_path / "out"], tmp_path, env=env)
    assert run.returncode == 1 and "Traceback" not in run.stderr, run.stderr
    assert f"forecasts: trough, X1-lined, shotcrete not computed: {UNMOVED}" in run.stderr, run.stderr
    assert not (tmp_path / "out" / "forecast.csv").exists()
    warnings = json.loads((tmp_path / "out" / "summary.json").read_text())["warnings"]
    (w,) = [w for w in warnings if w["code"] == "forecast-skipped"]
    assert w["message"] == f"forecasts trough, X1-lined, shotcrete not computed: {UNMOVED}"
