"""A failed fit prints no interval, a positive quantity no negative one, and the instrument that
drives the misfit is named (issue 18, item 3). Called as a user would: a case file with one
instrument's readings negated, through the library and the command line."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

import geoback

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"


def _paper_with(tmp_path: Path, name: str, change) -> Path:
    data = yaml.safe_load(PAPER.read_text())
    change(data)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _negate(instrument: int):
    def change(data):
        ins = data["instruments"][instrument]
        ins["readings"] = [-v for v in ins["readings"]]
    return change


@pytest.fixture(scope="module")
def negated_x1(tmp_path_factory) -> Path:
    """The paper's case with the extensometer's readings negated (a sign convention slipped)."""
    return _paper_with(tmp_path_factory.mktemp("neg"), "negated-x1", _negate(1))


def test_a_fit_that_did_not_converge_gives_no_interval(negated_x1, tmp_path):
    """Was: E[clay] 95 % [-3.1e+06, 5.1e+06] and K0 [-11.6, 21.6] from a fit stopped by the
    iteration limit. Now no interval, with the reason in words, in summary.json (ci95 null and
    ci95_reason) and in the report's table; `geoback run` still exits 1."""
    result = geoback.identify(negated_x1)
    assert result.fit.status != "converged"
    for e in result:
        assert e.interval is None and e.method == "none" and np.isnan(e.low) and np.isnan(e.high)
        assert "did not converge" in e.reason
        assert "no 95 % interval" in repr(e)
    assert result.to_dict()["estimates"]["E[clay]"]["interval"] is None
    from measure import run_cli

    run = run_cli(["run", negated_x1, "--out", tmp_path / "out", "-q"], tmp_path)
    assert run.returncode == 1, run.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    for p in summary["parameters"].values():
        assert p["ci95"] is None and p["ci95_method"] == "none" and "did not converge" in p["ci95_reason"]
    table = (tmp_path / "out" / "report.md").read_text()
    assert "| none: the fit did not converge" in table and "-3.09" not in table


def test_warnings_give_values_in_the_unit_of_the_table(negated_x1):
    """Was: '988.3 MPa ± 2.084 GPa' in the warning beside a table in kPa."""
    result = geoback.identify(negated_x1)
    text = " ".join(c.message for c in result.caveats if c.parameter == "E[clay]")
    assert "kPa" in text and "MPa" not in text and "GPa" not in text


def test_the_instrument_that_drives_the_misfit_is_named(negated_x1):
    """X1's readings alone ask for 25x its stated sigma, I1's for 4x: X1 is named with its own
    error scale, its share of J, the signs of its residuals and readings running opposite to the
    computed ones (code instrument-misfit, parameter None)."""
    result = geoback.identify(negated_x1)
    found = [c for c in result.caveats if c.code == "instrument-misfit"]
    assert len(found) == 1
    text = found[0].message
    assert text.startswith("X1 drives the misfit") and "its stated σ" in text and "of J" in text
    assert "the other instruments'" in text and "F test p" in text
    assert "all 5 of its residuals" in text and "opposite to the computed" in text
    assert found[0].as_dict()["code"] == "instrument-misfit"


def test_no_instrument_is_blamed_when_the_readings_fit_or_misfit_alike(tmp_path):
    """The paper's readings (fitted within their errors) and the inclinometer negated (both
    instruments 5x their stated sigma, neither stands out): no instrument-misfit caveat."""
    assert not [c for c in geoback.identify(PAPER).caveats if c.code == "instrument-misfit"]
    both = geoback.identify(_paper_with(tmp_path, "negated-i1", _negate(0)))
    assert both.status.startswith("converged; model inadequate")
    assert not [c for c in both.caveats if c.code == "instrument-misfit"]


def test_a_positive_quantity_never_gets_a_negative_interval_end(tmp_path):
    """The paper's case with sigma 200x larger: E's linearised interval p ± 1.96 std would start
    below zero. It is linearised in ln p instead (p exp(± 1.96 std / p), the same std), and its
    ends are positive; the report says how it was found."""
    def noisy(data):
        data["instruments"][0]["sigma"] = 0.2
        data["instruments"][1]["sigma"] = 0.1
        data["instruments"][1]["var_a"] = 1.0e-2
    result = geoback.identify(_paper_with(tmp_path, "noisy", noisy), profile="none")
    E = result["E[clay]"]
    assert E.value - 1.96 * E.std < 0  # the plain linearised interval would cross zero
    assert E.method == "linearised in ln p" and 0 < E.low < E.value < E.high
    assert E.low * E.high == pytest.approx(E.value ** 2, rel=1e-9)
    for e in result:
        assert e.interval is None or e.low > 0
    assert "(linearised in ln p)" in geoback.fit_report(result)
