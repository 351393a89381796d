"""`diagnose` goes as far as the next step (issue 18, item 4): every parameter before and after,
with 95 % intervals and units, the case amended with what was accepted (`geoback run` reproduces
the final joint fit from it), counts that agree, and p-values and units that explain themselves.
Called as a user would: geoback.diagnose on the shipped concealed layer-boundary case."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

import geoback
from geoback.units import value_text as shown

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "concealed" / "layer-boundary.yaml"


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    """The diagnosis of the layer-boundary case, its progress lines and its files (no figure)."""
    from geoback.reports.diagnosis_report import write_diagnosis

    said: list[str] = []
    d = geoback.diagnose(str(CASE), progress=said.append)
    out = tmp_path_factory.mktemp("diagnosis") / "results"
    write_diagnosis(d, out, plots=False)
    return d, said, out


def test_amended_case_reproduces_the_final_joint_fit(diagnosed, tmp_path):
    """amended.yaml: the boundary as a new layer 'clay_below' at the identified depth with its
    modulus, E[clay_below] a parameter, readings files found from where it is written; `run` on it
    gives the final joint fit's estimates within 1e-6."""
    d, _, out = diagnosed
    path = out / "amended.yaml"
    data = yaml.safe_load(path.read_text())
    layers = {ly["name"]: ly for ly in data["ground"]["layers"]}
    depth = d.depth_profile(d.accepted[0]).z_hat
    assert layers["clay_below"]["top"] == pytest.approx(depth) and layers["clay_below"]["nu"] == layers["clay"]["nu"]
    assert [p["name"] for p in data["parameters"]] == ["E[clay]", "K0", "E[clay_below]"]
    for ins in data["instruments"]:
        assert (out / ins["readings_file"]).is_file()
    assert path.read_text().startswith("# Amended by `geoback diagnose` from layer-boundary.yaml")
    res = geoback.run_case(geoback.load_case(path), tmp_path / "run")
    assert res.status == "converged"
    final = dict(zip(d.final.parameters.names, d.final_fit.p))
    for e in res:
        assert e.value == pytest.approx(final[e.name], rel=1e-6), e.name
    # it is a case to go on with: a forecast at the amended case's own estimate
    assert geoback.prepare(path).check_identification(res) is None


def test_before_after_table_of_every_parameter_with_units(diagnosed):
    d, _, out = diagnosed
    md = (out / "diagnosis.md").read_text()
    table = md[md.index("| parameter | unit | before | after |"):]
    rows = {line.split(" | ")[0][2:]: line for line in table.splitlines()[2:5]}
    assert set(rows) == {"E[clay]", "K0", "E[clay_below]"}
    assert rows["E[clay]"].startswith("| E[clay] | MPa | ")
    assert f"{shown('E[clay]', 'kPa', d.baseline['E[clay]'].value).split(' ')[0]} ± " in rows["E[clay]"]
    assert f"{shown('E[clay]', 'kPa', d.final['E[clay]'].value).split(' ')[0]} ± " in rows["E[clay]"]
    assert "not in the model" in rows["E[clay_below]"] and "95 % [" in rows["E[clay_below]"]
    data = json.loads((out / "diagnosis.json").read_text())
    assert [p["name"] for p in data["parameters"]] == ["E[clay]", "K0", "E[clay_below]"]
    below = data["parameters"][2]
    assert below["before"] is None and below["added"] and below["unit"] == "kPa" and below["shown_in"] == "MPa"
    assert below["after"]["ci95"][0] < below["after"]["estimate"] < below["after"]["ci95"][1]
    assert data["parameters"][0]["before"]["estimate"] == pytest.approx(d.baseline["E[clay]"].value)
    assert data["amended_case"] == "amended.yaml"


def test_counts_agree_and_every_p_of_1_is_explained(diagnosed):
    """'Scoring 37 hypotheses' beside a 13-row table and a Bonferroni 0.05/15: each now says
    what it counts, and the level is alpha over the family the text names. A row with S > 0 and
    p = 1 is a layer boundary's best depth, Bonferroni over its depths, and says so."""
    d, said, out = diagnosed
    md = (out / "diagnosis.md").read_text()
    scoring = [s for s in said if s.startswith("scoring")]
    assert len(scoring) == len(d.rounds)
    for line, rnd in zip(scoring, d.rounds):
        groups = [s for s in rnd.ranking if s.group_size > 1]
        assert line.startswith(f"scoring {rnd.hypotheses} hypotheses in ")
        assert all(f"the {s.group_size} depths of a layer boundary" in line for s in groups)
        assert rnd.threshold == pytest.approx(d.alpha / rnd.family)
        assert rnd.family == rnd.tests + rnd.screened
        assert f"{rnd.hypotheses} hypotheses scored, one row per test" in md
        assert f"(= {rnd.family_words(d.alpha)})" in md
        for s in rnd.ranking:
            if s.collinear_with is None and s.score > 0 and s.p_score == 1.0:
                assert s.group_size > 1 and s.p_single < 1.0
                assert f"1 ({s.p_single:.2g} at this depth × {s.group_size} depths, Bonferroni)" in md
    rnd = d.rounds[-1]
    assert any(s.group_size > 1 and s.p_score == 1.0 for s in rnd.ranking)
    items = json.loads((out / "diagnosis.json").read_text())["rounds"][-1]
    assert items["bonferroni_family"] == rnd.family and items["hypotheses_scored"] == rnd.hypotheses


def test_every_estimate_has_its_unit_and_angles_one_unit(diagnosed):
    """Units were missing or mixed (`±9.8e+06 (shotcrete)`, rad in one line and mm/m in the next)."""
    d, _, out = diagnosed
    md = (out / "diagnosis.md").read_text()
    assert "mm/m" not in md and " rad" not in md
    assert re.search(r"a bias shift of ±[0-9.]+ mrad", md)
    assert re.search(r"Egrad\[clay\] = [0-9.]+ ± [0-9.e+-]+ MPa/m", md)
    assert re.search(r"E\[clay_below\] = [0-9.]+ ± [0-9.e+-]+ MPa", md)
    assert re.search(r"K0grad = -?[0-9.]+ ± [0-9.e+-]+ /m", md)
    assert re.search(r"c\[clay\] = [0-9.]+ ± [0-9.e+-]+ kPa", md)
    assert re.search(r"a modulus gradient of ±[0-9.e+-]+ MPa/m", md)


def test_a_lining_modulus_is_shown_in_mpa():
    """The staged case's detectable lining change was '±9.8e+06 (shotcrete)', no unit."""
    from geoback.reports.diagnosis_report import verdict

    d = geoback.diagnose(ROOT / "cases" / "staged-tunnel.yaml")
    text = verdict(d)
    found = re.search(r"a change of the lining's modulus of ±([0-9.e+]+) MPa \(shotcrete\)", text)
    assert found, text
    assert np.isfinite(float(found.group(1)))
