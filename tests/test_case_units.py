"""Lengths take units as stresses do (issue 18): '0.5m', '50 cm', '500 mm' are metres; an unknown
unit is refused located; a bare number is metres as before."""
from __future__ import annotations

import copy
from pathlib import Path

import pytest
import yaml

from geoback.case.loading import case_from_data
from geoback.errors import CaseError

pytestmark = pytest.mark.quick

BASE = yaml.safe_load((Path(__file__).resolve().parents[1] / "cases" / "tunnel-paper.yaml").read_text())


def _case(mutate):
    data = copy.deepcopy(BASE)
    mutate(data)
    return case_from_data(data, {}, file="case.yaml")


@pytest.mark.parametrize("text, metres", [("0.5m", 0.5), ("50 cm", 0.5), ("500 mm", 0.5), ("0.5 M", 0.5), (0.5, 0.5)])
def test_a_length_with_its_unit(text, metres):
    case = _case(lambda d: d["mesh"].update(size_tunnel=text))
    assert case.mesh.size_tunnel == pytest.approx(metres, rel=1e-15)


def test_every_length_field_takes_units():
    def mutate(d):
        d["geometry"].update(radius="300 cm", axis_depth="10 m", width="40000 mm", depth="0.03 km")
        d["instruments"][1].update(spacing="125 cm", sigma="0.5 mm", start=["0 m", "0 m"], end=["0", "-650 cm"])
        d["ground"]["layers"][0]["top"] = "0 m"

    case = _case(mutate)
    g = case.geometry
    assert (g.radius, g.axis_depth, g.width, g.depth) == (3.0, 10.0, 40.0, 30.0)
    x1 = case.instruments[1]
    assert x1.spacing == pytest.approx(1.25) and x1.sigma == pytest.approx(5e-4) and x1.end == (0.0, -6.5)


@pytest.mark.parametrize("text, words", [("1.25 furlong", "expected a unit m, cm, mm or km after the number, "
                                                          "found 'furlong'"),
                                         ("-1 m", "expected a number greater than 0"),
                                         ("one metre", "expected a number, found 'one metre' (a length in m")])
def test_a_bad_length_is_refused_located(text, words):
    with pytest.raises(CaseError) as info:
        _case(lambda d: d["instruments"][1].update(spacing=text))
    assert str(info.value).startswith("case.yaml: instruments[1].spacing: ") and words in str(info.value)
