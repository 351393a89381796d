"""The size of a section's mesh known before gmsh runs (issue 19): the size field of
``physics/section_mesh.py`` integrated over the whole section (openings, cut lines and linings' bands
included) estimates gmsh's elements and DOFs within the stated factor, `validate` announces it, and a
section beyond the size limit is refused, located, before gmsh runs."""
from __future__ import annotations

import copy
import sys
from pathlib import Path

import pytest

import geoback.physics.section_mesh as section_mesh
from geoback.case import meshsize
from geoback.case.loading import case_from_data
from geoback.case.meshsize import mesh_inputs, refined_case
from geoback.case.yamlmarks import load_yaml_with_marks
from geoback.errors import CaseError
from geoback.physics.section_mesh import build_section_mesh

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from mesh_estimate import FACTOR  # noqa: E402

NATM, _ = load_yaml_with_marks(ROOT / "cases" / "natm-heading-bench.yaml")
TWIN, _ = load_yaml_with_marks(ROOT / "cases" / "twin-tunnels.yaml")
BOX = {"name": "box", "geometry": {"model": "full", "width": 60.0, "depth": 30.0, "openings": [
    {"name": "station", "shape": "polygon", "boundary": [[-6.0, -16.0], [6.0, -16.0], [6.0, -11.0], {"through": [0.0, -8.0]},
                                                         [-6.0, -11.0]],
     "cuts": [[[-7.0, -12.0], [7.0, -12.0]]], "parts": [{"name": "crown", "contains": [0.0, -10.0]},
                                                        {"name": "base", "contains": [0.0, -14.0]}]}]},
    "ground": {"unit_weight": 20.0, "K0": 0.6, "layers": [{"name": "clay", "top": 0.0, "E": 30000.0, "nu": 0.3}]},
    "mesh": {"size_tunnel": 0.3, "size_far": 3.0},
    "construction": {"linings": [{"name": "roof", "on": "crown", "thickness": 0.4, "E": 10e6, "nu": 0.2}],
                     "stages": [{"name": "crown", "excavate": ["crown"], "release": 0.5},
                                {"name": "roofed", "install": ["roof"]}, {"name": "base", "excavate": ["base"]}]}}


def _without_readings(data: dict, **mesh) -> dict:
    data = copy.deepcopy(data)
    for ins in data.get("instruments", []):
        ins.pop("readings_file", None)
    data.pop("forecasts", None)
    data.pop("design", None)
    data["mesh"] = {**data.get("mesh", {}), **mesh}
    return data


VARIANTS = [("natm", _without_readings(NATM)), ("natm fine", _without_readings(NATM, size_tunnel=0.2, size_far=2.0)),
            ("natm growth 1", _without_readings(NATM, size_tunnel=0.2, growth=1.0)),
            ("natm linear", {**_without_readings(NATM, order=1), "construction": None}),
            ("twin", _without_readings(TWIN)), ("twin fine", _without_readings(TWIN, size_tunnel=0.2, size_far=2.5)),
            ("polygon with an arc, a cut and a lining", _without_readings(BOX))]


@pytest.mark.parametrize("label, data", VARIANTS, ids=[v[0] for v in VARIANTS])
def test_estimate_within_stated_factor(label, data):
    data = {k: v for k, v in data.items() if v is not None}
    case = case_from_data(data, {}, file=label, allow_large=True)
    est = meshsize.estimate(mesh_inputs(case))
    mesh = build_section_mesh(case, use_cache=False)
    for ratio in (est.elements / len(mesh.triangles), est.dofs / (2 * len(mesh.nodes))):
        assert 1 / FACTOR <= ratio <= FACTOR, f"{label}: estimate/gmsh = {ratio:.3f}"


def test_a_huge_section_is_refused_before_gmsh():
    _refused_before_gmsh((1e-5,))  # walls of millions of elements: refused at once


@pytest.mark.slow  # 30 s: the size estimate integrates a section just beyond the limit
def test_a_section_just_beyond_the_limit_is_refused_before_gmsh():
    _refused_before_gmsh((0.004,))


def _refused_before_gmsh(sizes):
    calls = section_mesh.GMSH_CALLS
    for size in sizes:
        with pytest.raises(CaseError) as err:
            case_from_data(_without_readings(NATM, size_tunnel=size), {}, file="natm.yaml")
        assert err.value.field == "mesh.size_tunnel"
        assert "expected mesh sizes giving at most" in err.value.reason and "--allow-large" in err.value.reason
    assert section_mesh.GMSH_CALLS == calls


def test_refined_case_halves_a_sections_sizes():
    case = case_from_data(_without_readings(NATM), {}, file="natm.yaml")
    coarse, fine = mesh_inputs(case), mesh_inputs(refined_case(case, 2.0))
    assert fine["size_tunnel"] == pytest.approx(coarse["size_tunnel"] / 2)
    assert fine["size_far"] == pytest.approx(coarse["size_far"] / 2)
    defaults = case_from_data({**_without_readings(NATM), "mesh": {}}, {}, file="natm.yaml")
    wall, far = section_mesh.default_sizes(defaults)  # the estimate's defaults are the mesher's
    assert (mesh_inputs(defaults)["size_tunnel"], mesh_inputs(defaults)["size_far"]) == pytest.approx((wall, far))
