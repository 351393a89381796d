"""`geoback validate` lists every problem, one located line each; other commands print the first
with the count."""
from __future__ import annotations

import copy
import os
import re
from pathlib import Path

import pytest
import yaml

from geoback.case.loading import case_from_data
from geoback.errors import CaseError
from measure import run_cli

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "cases" / "tunnel-paper.yaml"
LINE = re.compile(r"^error: (?P<file>.+?):(?P<line>\d+):(?P<column>\d+): (?P<field>[^:]+): (?P<reason>.*expected .+)$")


def schema_mistakes(text: str) -> str:
    """Three independent schema mistakes, in file order."""
    text = text.replace("radius: 3.0 ", "radius: -3.0", 1)
    text = text.replace("nu: 0.49}", "nu: 0.7}", 1)
    text = text.replace("fit:\n", "fit:\n  colour: blue\n", 1)
    return text


def physics_mistakes(text: str) -> str:
    """Three physical problems (the schema is fine)."""
    text = text.replace("toe_depth: 24.0", "toe_depth: 45.0", 1)  # below the model's bottom
    text = text.replace("end: [0.0, -6.5]", "end: [0.0, -9.0]", 1)  # inside the tunnel
    text = text.replace("bounds: [0.05, 5.0]", "bounds: [5.0, 0.05]", 1)  # lower above upper
    return text


@pytest.fixture()
def env(tmp_path):
    e = dict(os.environ, GEOBACK_CACHE=str(tmp_path / "cache"))
    e.pop("GEOBACK_DEBUG", None)
    return e


@pytest.mark.parametrize("mistakes, fields", [
    (schema_mistakes, ["geometry.radius", "ground.layers[0].nu", "fit.colour"]),
    (physics_mistakes, ["instruments[0].toe_depth", "instruments[1].end", "parameters[1].bounds"]),
], ids=["schema", "physics"])
def test_validate_lists_every_problem(mistakes, fields, tmp_path, env):
    path = tmp_path / "three.yaml"
    path.write_text(mistakes(PAPER.read_text()))
    proc = run_cli(["validate", path], tmp_path, env=env)
    assert proc.returncode == 2 and proc.stdout == "", proc.stdout + proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 3, proc.stderr
    found = [LINE.match(line) for line in lines]
    assert all(found), lines
    assert [m["field"] for m in found] == fields
    assert all(Path(m["file"]) == path for m in found)
    assert "more problem" not in proc.stderr
    run = run_cli(["run", path], tmp_path, env=env)  # the others: the first, with the count
    assert run.returncode == 2
    (line,) = run.stderr.strip().splitlines()
    assert line == lines[0] + " (and 2 more problems)"


def test_case_error_carries_every_problem():
    data = yaml.safe_load(schema_mistakes(PAPER.read_text()))
    with pytest.raises(CaseError) as info:
        case_from_data(copy.deepcopy(data), {}, file="x.yaml")
    err = info.value
    assert len(err.problems) == 3 and str(err).endswith("(and 2 more problems)")
    assert [p.field for p in err.problems] == ["geometry.radius", "ground.layers[0].nu", "fit.colour"]
    assert all(p.problems == [p] for p in err.problems)
    single = yaml.safe_load(PAPER.read_text())
    single["geometry"]["radius"] = -3
    with pytest.raises(CaseError) as info:
        case_from_data(single, {}, file="x.yaml")
    assert info.value.problems == [info.value] and "more problem" not in str(info.value)
