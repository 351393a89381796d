"""The commands that produce files: mesh, simulate (forward and study data), schema."""
import csv
import json
import subprocess
import sys

import meshio
import numpy as np

from conftest import CASES

PAPER = CASES / "tunnel-paper.yaml"


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "geoback.commands.cli", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def test_mesh_writes_msh_and_vtu_with_regions(tmp_path):
    out = cli("mesh", PAPER, "--out", tmp_path)
    assert out.returncode == 0, out.stderr
    for name in ("mesh.msh", "mesh.vtu"):
        m = meshio.read(tmp_path / name)
        assert "triangle6" in m.cells_dict and len(m.points) > 100
    vtu = meshio.read(tmp_path / "mesh.vtu")
    assert set(np.unique(vtu.cell_data["region"][0])) == {0}  # one layer in the paper case
    msh = meshio.read(tmp_path / "mesh.msh")
    assert msh.field_data["clay"][0] == 1 and msh.field_data["tunnel"][0] == 100
    wall = msh.points[np.unique(msh.cells_dict["line3"])]
    assert np.allclose(np.hypot(wall[:, 0], wall[:, 1] + 10.0), 3.0)  # the tagged wall is the tunnel


def test_simulate_writes_readings_and_field(tmp_path):
    out = cli("simulate", PAPER, "--out", tmp_path)
    assert out.returncode == 0, out.stderr
    rows = list(csv.DictReader(open(tmp_path / "predicted.csv")))
    assert len(rows) == 12 and {r["instrument"] for r in rows} == {"I1", "X1"}
    data = json.loads((tmp_path / "predicted.json").read_text())
    assert len(data["readings"]) == 12
    field = meshio.read(tmp_path / "field.vtu")
    u = field.point_data["displacement"]
    assert u.shape[1] == 3 and 0.01 < np.abs(u).max() < 0.5  # centimetres, like the paper's Table 1
    for key in ("stress_xx", "stress_yy", "stress_xy"):
        assert key in field.cell_data
    # the computed readings agree with the case's readings (simulated on a finer mesh) to 1 %
    measured = np.array([float(r["measured"]) for r in rows])
    computed = np.array([float(r["computed"]) for r in rows])
    assert np.allclose(computed, measured, rtol=0.01, atol=2e-4)


def test_simulate_study_data_is_seeded_and_switches_physics(tmp_path):
    a, b, c = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    for target, extra in ((a, []), (b, []), (c, ["--set", "Egrad[clay]=500"])):
        out = cli("simulate", PAPER, "--noise", "--seed", "3", "--readings-out", target, *extra)
        assert out.returncode == 0, out.stderr
    read = lambda p: np.array([float(r["reading"]) for r in csv.DictReader(  # noqa: E731
        line for line in open(p) if not line.startswith("#"))])  # the first line says how the data were made
    assert np.array_equal(read(a), read(b))  # same seed, same data
    assert np.abs(read(c) - read(a)).max() > 1e-3  # a stiffer deep ground moves the readings
    bad = cli("simulate", PAPER, "--set", "Egrad[clay]=lots", "--readings-out", tmp_path / "d.csv")
    assert bad.returncode == 2 and "NAME=NUMBER" in bad.stderr


def test_schema_is_json_schema_of_the_case():
    out = cli("schema")
    assert out.returncode == 0
    schema = json.loads(out.stdout)
    assert schema["title"] == "geoback case"
    assert {"geometry", "ground", "instruments", "parameters"} <= set(schema["properties"])
