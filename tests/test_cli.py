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


def test_version_and_case_insensitive_choices(tmp_path):
    """issue 18: --version; --method and --format are choices, case-insensitive, listed in --help."""
    from geoback import __version__

    v = cli("--version", cwd=tmp_path)
    assert v.returncode == 0 and v.stdout.strip() == f"geoback {__version__}"
    h = cli("run", "--help", cwd=tmp_path)
    assert "lm|lm-scaled|gn" in h.stdout
    bad = cli("run", str(CASES / "tunnel-paper.yaml"), "--method", "newton", "--out", str(tmp_path / "r"), cwd=tmp_path)
    assert bad.returncode == 2 and "newton" in bad.stderr and "Traceback" not in bad.stderr
    c = cli("covariance", "--instrument", "Inclinometer", "--stations", "2", "--spacing", "1", "--sigma", "1",
            "--format", "JSON", cwd=tmp_path)
    assert c.returncode == 0, c.stderr
    data = json.loads(c.stdout)
    assert data["matrix"] == [[1.0, 1.0], [1.0, 2.0]] and "m²" in data["caption"]


def test_covariance_of_points_and_a_bounded_size(tmp_path):
    """issue 18: points and convergence have a covariance too; issue 23: a dense matrix too large to
    hold is refused before it is allocated (was a MemoryError traceback)."""
    c = cli("covariance", "--instrument", "points", "--stations", "3", "--sigma", "0.002", "--format", "csv",
            cwd=tmp_path)
    assert c.returncode == 0, c.stderr
    rows = [list(map(float, line.split(","))) for line in c.stdout.split()]
    assert rows == [[4e-06, 0.0, 0.0], [0.0, 4e-06, 0.0], [0.0, 0.0, 4e-06]]
    big = cli("covariance", "--instrument", "inclinometer", "--stations", "100000", "--spacing", "1", "--sigma", "1",
              cwd=tmp_path)
    assert big.returncode == 2 and "expected at most" in big.stderr and "Traceback" not in big.stderr


def test_json_on_every_command_with_results(tmp_path):
    """issue 18: --json prints the command's result file on stdout, the final line on stderr."""
    out = tmp_path / "sim"
    s = cli("simulate", str(CASES / "tunnel-paper.yaml"), "--out", str(out), "--no-vtu", "--json", cwd=tmp_path)
    assert s.returncode == 0, s.stderr
    assert json.loads(s.stdout) == json.loads((out / "predicted.json").read_text())
    d = cli("diagnose", str(CASES / "tunnel-paper.yaml"), "--out", str(tmp_path / "d"), "--no-plots", "--json",
            cwd=tmp_path)
    assert d.returncode == 0, d.stderr
    assert json.loads(d.stdout)["case"] == "tunnel-paper"
