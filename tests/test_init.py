"""`geoback init`: a commented template case that validates and identifies as it is."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from geoback.case.loading import case_schema
from geoback.errors import GeobackError
from geoback.commands.template import TEMPLATE, write_template

GEOBACK = [sys.executable, "-m", "geoback.commands.cli"]


@pytest.fixture()
def env(tmp_path):
    return dict(os.environ, GEOBACK_CACHE=str(tmp_path / "cache"))


def cli(*args, cwd, env) -> subprocess.CompletedProcess:
    return subprocess.run(GEOBACK + [str(a) for a in args], capture_output=True, text=True, cwd=cwd,
                          env=env, timeout=300)


def test_init_validate_run(tmp_path, env):
    r = cli("init", cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr
    case = tmp_path / "case.yaml"
    assert case.read_text() == TEMPLATE

    r = cli("validate", "case.yaml", cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr
    assert "valid" in r.stdout

    r = cli("run", "case.yaml", "--out", "out", "-q", cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["status"] == "converged"
    est = {name.split("[")[0]: v["estimate"] for name, v in summary["parameters"].items()}
    assert est["E"] == pytest.approx(10000, rel=0.01)
    assert est["K0"] == pytest.approx(1.0, rel=0.02)
    kinds = {row["kind"] for row in _rows(tmp_path / "out" / "readings.csv")}
    assert "points" in kinds  # the settlement points take part in the fit


def _rows(path: Path) -> list[dict]:
    import csv

    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_init_refuses_to_overwrite(tmp_path, env):
    target = tmp_path / "mine.yaml"
    assert cli("init", target, cwd=tmp_path, env=env).returncode == 0
    target.write_text("# my edits\n")

    r = cli("init", target, cwd=tmp_path, env=env)
    assert r.returncode == 2
    assert "already exists" in r.stderr and "--force" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert target.read_text() == "# my edits\n"

    r = cli("init", target, "--force", cwd=tmp_path, env=env)
    assert r.returncode == 0, r.stderr
    assert target.read_text() == TEMPLATE


def test_init_into_a_folder_is_refused(tmp_path):
    with pytest.raises(GeobackError, match="is a folder"):
        write_template(tmp_path)
    assert not list(tmp_path.iterdir())


def test_template_comments_every_setting():
    """Every field the template sets carries a comment (its meaning and unit), and the template
    uses only fields of the schema."""
    uncommented = []
    for line in TEMPLATE.splitlines():
        body = line.split("#", 1)[0]
        stripped = body.strip()
        if not stripped or stripped.startswith("- [") or "#" in line:
            continue
        uncommented.append(line)
    assert not uncommented, "template lines without a comment:\n" + "\n".join(uncommented)
    data = yaml.safe_load(TEMPLATE)
    assert set(data) <= set(case_schema()["properties"])
