"""The Python API as a user calls it (issue 18, item 8, against lmfit's; issue 23, item 3: the
library refuses what the command line refuses, with one set of checks). docs/examples style:
only the public names and the results' own methods."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

import geoback
from geoback.errors import GeobackError

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
STAGED = ROOT / "cases" / "staged-tunnel.yaml"
FORECAST = ROOT / "cases" / "staged-forecast.yaml"


@pytest.fixture(scope="module")
def paper():
    analysis = geoback.prepare(geoback.load_case(PAPER))
    return analysis, geoback.identify(analysis)


@pytest.fixture(scope="module")
def staged_forecasts():
    analysis = geoback.prepare(FORECAST)
    result = geoback.identify(analysis)
    return analysis, result, geoback.forecast(analysis, result, draws=0)


# ---------------------------------------------------------------------------- issue 18.8
@pytest.mark.parametrize("as_given", [str, Path])
def test_identify_takes_a_case_files_path(as_given, paper):
    """identify("case.yaml") ended in AttributeError: 'str' object has no attribute 'case'."""
    result = geoback.identify(as_given(PAPER))
    assert result.status == "converged"
    assert result["E[clay]"].value == pytest.approx(paper[1]["E[clay]"].value, rel=1e-9)


def test_identify_refuses_what_is_not_a_case():
    with pytest.raises(GeobackError, match="expected a case: a case file's path"):
        geoback.identify(42)


def test_a_result_iterates_over_its_estimates_and_is_a_dict(paper):
    """Like lmfit's Parameters: iterate, take by name, turn into plain JSON-ready data."""
    _, result = paper
    names = [e.name for e in result]
    assert names == ["E[clay]", "K0"] == result.keys() and len(result) == 2 and "K0" in result
    by_name = dict(zip(result.keys(), result))
    assert by_name["K0"] == result["K0"]
    data = result.to_dict()
    json.dumps(data, allow_nan=False)  # JSON as it is: no nan, no numpy types
    E = data["estimates"]["E[clay]"]
    assert E["value"] == pytest.approx(result["E[clay]"].value) and E["unit"] == "kPa"
    assert E["std"] == pytest.approx(result["E[clay]"].std)
    assert E["interval"] == pytest.approx(list(result["E[clay]"].interval))
    assert data["status"] == "converged" and data["chi2"] == pytest.approx(result.reliability.chi2)
    assert data["caveats"] == [c.as_dict() for c in result.caveats]


def test_correlations_by_name(paper):
    _, result = paper
    c = result.correlation("E[clay]", "K0")
    assert c == result.reliability.correlation[0, 1] == result.correlation("K0", "E[clay]")
    assert result.correlations == {("E[clay]", "K0"): c}
    assert result.to_dict()["correlations"] == {"E[clay], K0": c}
    with pytest.raises(KeyError, match="not an identified parameter"):
        result.correlation("E[clay]", "nu[clay]")


def test_forecasts_are_addressed_by_name(staged_forecasts):
    """fc["trough"] was a TypeError; it is the trough's frozen view, point by point."""
    _, _, fc = staged_forecasts
    trough = fc["trough"]
    rows = fc.rows("trough")
    assert trough.name == "trough" and trough.unit == "m" and trough.stage == "lined" and len(trough) == 31
    np.testing.assert_array_equal(trough.values, fc.value[rows])
    np.testing.assert_array_equal(trough.std, fc.std[rows])
    low, high = trough.band
    assert np.all(low <= trough.values) and np.all(trough.values <= high)
    assert trough.alert == pytest.approx(0.006)
    assert fc["shotcrete"].unit in ("kN/m, kNm/m", "kNm/m, kN/m") and set(fc["shotcrete"].quantity) == {"N", "M"}
    assert [f.name for f in fc] == fc.names == fc.keys() and "X1-lined" in fc
    json.dumps(trough.as_dict(), allow_nan=False)
    with pytest.raises(dataclasses.FrozenInstanceError):
        trough.values = None
    with pytest.raises(ValueError):
        trough.values[0] = 1.0
    with pytest.raises(KeyError, match="trough, X1-lined, shotcrete"):
        fc["settlement"]


def test_the_public_names_are_listed():
    assert {"load_case", "prepare", "identify", "diagnose", "forecast", "design", "fit_report",
            "run_case"} <= set(dir(geoback))


# ---------------------------------------------------------------------------- issue 23.3
def test_a_forecast_with_another_cases_identification_is_refused(paper, staged_forecasts):
    """The staged case's forecasts computed at the paper case's estimate returned numbers."""
    analysis, _, _ = staged_forecasts
    with pytest.raises(GeobackError, match="expected an identification of case 'staged-forecast'"):
        geoback.forecast(analysis, paper[1])
    with pytest.raises(GeobackError, match="expected an identification of case 'staged-forecast'"):
        geoback.design(analysis, paper[1])


def test_predict_refuses_a_vector_of_the_wrong_length(paper):
    analysis, _ = paper
    for p in ([1.0e4], [1.0e4, 1.0, 0.3]):
        with pytest.raises(GeobackError, match=r"expected 2 values, one for each of E\[clay\], K0"):
            analysis.predict(p)
    with pytest.raises(GeobackError, match=r"expected E\[clay\] within its allowed range"):
        analysis.predict([-5000.0, 1.0])
    assert analysis.predict([1.0e4, 1.0]).x.shape == (12,)


def test_identify_refuses_initial_values_outside_the_bounds(paper):
    """identify(analysis, p0=[-5000, 0.5]) reported 'E = -5000 ± 53 kPa' (a negative modulus)."""
    analysis, _ = paper
    with pytest.raises(GeobackError, match=r"expected E\[clay\] within its bounds \[100, 1e\+06\] kPa.*found -5000"):
        geoback.identify(analysis, p0=[-5000.0, 0.5])
    with pytest.raises(GeobackError, match="expected 2 values"):
        geoback.identify(analysis, p0=[5000.0])


def _staged_with_beta_bounds(tmp_path, bounds) -> Path:
    data = yaml.safe_load(STAGED.read_text())
    beta = next(p for p in data["parameters"] if p["name"] == "beta[advance]")
    beta["bounds"] = bounds
    for ins in data["instruments"]:
        if ins.get("readings_file"):
            ins["readings_file"] = str(ROOT / "cases" / ins["readings_file"])
    path = tmp_path / "beta-bounds.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_a_release_above_1_is_refused_wherever_it_comes_from(tmp_path):
    """`simulate --set beta[advance]=1.5` and a beta parameter bounded by [0.05, 1.5] were accepted
    although the case's construction section refuses `release: 1.5`; one range (case/limits.py
    RELEASE) is now checked by the command line and the library alike."""
    from measure import run_cli

    run = run_cli(["simulate", STAGED, "--set", "beta[advance]=1.5", "--out", tmp_path / "sim"], tmp_path)
    assert run.returncode == 2 and "beta[advance]: expected a value within 0.001 to 1, found 1.5" in run.stderr, run.stderr
    path = _staged_with_beta_bounds(tmp_path, [0.05, 1.5])
    with pytest.raises(GeobackError, match=r"parameters\[2\]\.bounds: expected bounds of beta\[advance\] within "
                                           r"its allowed range \(0.001 to 1\), found \[0.05, 1.5\]"):
        geoback.prepare(path)
    run = run_cli(["validate", path], tmp_path)
    assert run.returncode == 2 and "parameters[2].bounds: expected bounds of beta[advance]" in run.stderr
    from geoback.inference.parameters import resolve_values

    analysis = geoback.prepare(STAGED, with_readings=False)
    with pytest.raises(GeobackError, match="expected a value within 0.001 to 1"):
        resolve_values(analysis.simulation, {"beta[advance]": "1.5"})
    assert resolve_values(analysis.simulation, {"beta[advance]": "1"}) == {"beta[advance]": 1.0}
