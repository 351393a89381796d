"""The shipped cases with openings through the command line, as a user runs them: validate announces
the mesh and its cost, run --plots writes every result file and figure (the cross-section figures
name the stage they show, field.vtu the state of every element after every stage), simulate,
covariance, diagnose and design answer, all on the case's own mesh (cases/natm-heading-bench.yaml:
a horseshoe dug as heading and bench in a half-model; cases/twin-tunnels.yaml: two circular tunnels
in a full model)."""
import csv
import json
import subprocess
import sys
from xml.etree import ElementTree

import numpy as np
import meshio
import pytest

from conftest import CASES

NATM = CASES / "natm-heading-bench.yaml"
TWIN = CASES / "twin-tunnels.yaml"
STAGES = {NATM: ["heading", "heading-lined", "bench", "ring-closed"], TWIN: ["west", "west-lined", "east", "east-lined"]}
FIGURES = ("mesh", "field", "instruments", "measured_vs_predicted", "convergence", "objective_contours",
           "information_density", "forecast_trough")
FILES = ("summary.json", "report.md", "parameters.csv", "readings.csv", "covariance.csv", "forecast.csv", "field.vtu")


def cli(*args):
    return subprocess.run([sys.executable, "-m", "geoback.commands.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


def svg_title(path) -> str:
    """The figure's title as the SVG states it (dc:title)."""
    root = ElementTree.parse(path).getroot()
    titles = [e.text for e in root.iter() if e.tag.endswith("}title") and e.text]
    return " ".join(titles)


@pytest.fixture(scope="module", params=[NATM, pytest.param(TWIN, marks=pytest.mark.slow)],
                ids=["natm-heading-bench", "twin-tunnels"])  # twin tunnels: 37 s, in the slow tier
def ran(request, tmp_path_factory):
    case = request.param
    out = tmp_path_factory.mktemp(case.stem)
    done = cli("run", case, "--plots", "--out", out, "-q")
    assert done.returncode == 0, done.stderr
    return case, out, done


def test_validate_announces_the_mesh_and_its_cost():
    for case in (NATM, TWIN):
        done = cli("validate", case)
        assert done.returncode == 0, done.stderr
        assert f"{case}: valid" in done.stdout and "dofs" in done.stdout
        assert "cost of `geoback run`" in done.stdout and "memory at most" in done.stdout


def test_run_writes_every_result_and_figure(ran):
    case, out, done = ran
    for name in FILES:
        assert (out / name).stat().st_size > 0, name
    for name in FIGURES:
        for fmt in ("png", "svg"):
            assert (out / f"{name}.{fmt}").stat().st_size > 1000, f"{name}.{fmt}"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "converged"
    rows = list(csv.DictReader(open(out / "readings.csv")))
    assert {r["stage"] for r in rows} <= set(STAGES[case]) and len({r["stage"] for r in rows}) >= 2
    assert "converged" in done.stderr + done.stdout


def test_the_section_figures_name_the_stage_they_show(ran):
    case, out, _ = ran
    stages = STAGES[case]
    field = svg_title(out / "field.svg")
    assert f"after stage '{stages[-1]}' (the last of {len(stages)}: {', '.join(stages)})" in field
    mesh = svg_title(out / "mesh.svg")
    assert "before construction" in mesh and "degrees of freedom" in mesh


def test_field_vtu_holds_every_stage(ran):
    case, out, _ = ran
    field = meshio.read(out / "field.vtu")
    stages = STAGES[case]
    for stage in stages:
        assert field.point_data[f"displacement[{stage}]"].shape == (len(field.points), 3)
        state = field.cell_data[f"state[{stage}]"][0]
        assert set(np.unique(state)) <= set(range(-1, 1 + len(stages)))
    first, last = (field.cell_data[f"state[{s}]"][0] for s in (stages[0], stages[-1]))
    assert 0 < (first == -1).sum() and (first == 0).sum() > (last == 0).sum()  # dug stage by stage
    assert (last > 0).sum() > 0  # linings stand after the last stage
    stress = field.cell_data["stress_xx"][0]
    assert np.isnan(stress[last == -1]).all() and np.isfinite(stress[last >= 0]).all()


@pytest.mark.slow  # 25 s: simulate, covariance, diagnose and design on openings (run stays in the default tier)
def test_simulate_covariance_diagnose_and_design(tmp_path):
    for case in (NATM, TWIN):
        sim = cli("simulate", case, "--out", tmp_path / f"sim-{case.stem}", "--plots")
        assert sim.returncode == 0, sim.stderr
        assert (tmp_path / f"sim-{case.stem}" / "predicted.png").exists()
        name = "C1" if case == NATM else "I1"
        cov = cli("covariance", case, "--name", name)
        assert cov.returncode == 0 and f"C_x of" in cov.stdout, cov.stderr
    diag = cli("diagnose", NATM, "--out", tmp_path / "diag", "--json")
    assert diag.returncode == 0, diag.stderr
    result = json.loads(diag.stdout)
    assert result["adequate_before"] and result["not_tested"] == []  # yielding too is tested with openings
    design = cli("design", NATM, "--out", tmp_path / "design")
    assert design.returncode == 0, design.stderr
    assert (tmp_path / "design" / "design.csv").exists()
