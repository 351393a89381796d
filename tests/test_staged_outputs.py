"""The staged case through the commands: `geoback run` (readings per stage, lining.csv, lining.vtu,
per-stage fields, figures), `geoback simulate` (predictions per stage, the lining's outputs, study
data per stage read back), `geoback diagnose` (the shipped case is adequate; a wrong release
before the lining and a wrong lining stiffness are each named and identified)."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
import yaml

from conftest import CASES
from geoback.case.loading import LoadedCase, case_from_data, load_case
from geoback.diagnosis import diagnose
from geoback.commands.run import run_case

STAGED = CASES / "staged-tunnel.yaml"
TRUTH = {"E[clay]": 40000.0, "K0": 0.7, "beta[advance]": 0.35}  # cases/generate_staged_tunnel.py


def rows(path: Path) -> list[dict]:
    """The CSV's rows, after any '#' comment lines (how study data were made)."""
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(line for line in fh if not line.startswith("#")))


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("staged-run")
    res = run_case(load_case(STAGED), out, plots=True)
    return res, out


def test_run_identifies_E_K0_and_the_release_before_the_lining(run):
    res, out = run
    assert res.fit.status == "converged"
    for name, truth in TRUTH.items():
        assert abs(res[name].value - truth) < 3 * res[name].std, (name, res[name])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["factorisations"] == 2  # the ground, and the ground with the lining
    assert summary["exploration"]["factorisations"] == 0  # the figures' grid reuses them


def test_readings_csv_has_every_stage(run):
    res, out = run
    table = rows(out / "readings.csv")
    assert len(table) == res.data.m
    assert {r["stage"] for r in table} == {"advance", "lined"}
    assert {(r["instrument"], r["stage"]) for r in table} == {(i, s) for i in ("I1", "X1", "S1")
                                                            for s in ("advance", "lined")}
    labels = (out / "information_density.csv").read_text().splitlines()[0]
    assert "I1:1:ux@advance" in labels and "I1:1:ux@lined" in labels


def test_lining_outputs(run):
    res, out = run
    table = rows(out / "lining.csv")
    assert {r["stage"] for r in table} == {"lined"}  # the lining acts from the stage installing it
    angle = np.array([float(r["angle_from_crown_deg"]) for r in table])
    N = np.array([float(r["N_kN_per_m"]) for r in table])
    M = np.array([float(r["M_kNm_per_m"]) for r in table])
    assert 0 < angle.min() < 5 and 175 < angle.max() < 180 and np.all(np.diff(angle) > 0)
    assert np.all(N > 0)  # in compression all round
    # K0 < 1: the ring is squeezed vertically: intrados in tension at the crown, extrados at the springline
    assert M[0] > 0 and M[np.argmin(np.abs(angle - 90))] < 0
    # thrust of the order of the lining's share of the overburden: (1 - beta) sigma_v R
    sv = 20.0 * 15.0
    assert 0.3 * (1 - 0.35) * sv * 3.0 < N.mean() < 1.5 * sv * 3.0
    vtu = meshio.read(out / "lining.vtu")
    for key in ("N_kN_per_m[lined]", "M_kNm_per_m[lined]", "V_kN_per_m[lined]", "displacement[lined]"):
        assert key in vtu.point_data
    np.testing.assert_allclose(vtu.point_data["N_kN_per_m[lined]"], N)
    assert (out / "lining.png").stat().st_size > 0 and (out / "lining.svg").stat().st_size > 0


def test_field_has_every_stage_and_the_lining(run):
    res, out = run
    field = meshio.read(out / "field.vtu")
    for stage in ("advance", "lined"):
        assert f"displacement[{stage}]" in field.point_data
    region = field.cell_data["region"][0]
    assert set(np.unique(region)) == {0, 1}  # the clay and the lining
    u = field.point_data["displacement"]
    np.testing.assert_allclose(u, field.point_data["displacement[lined]"])
    # the ground moved between the stages; the lining's stresses are hoop compression
    assert np.abs(field.point_data["displacement[advance]"] - u).max() > 1e-4
    lining = region == 1
    assert np.all(field.cell_data["stress_xx"][0][lining] + field.cell_data["stress_yy"][0][lining] < 0)


def test_every_figure_of_a_staged_run(run):
    _, out = run
    for name in ("objective_contours", "convergence", "information_density", "instruments", "field", "lining"):
        assert (out / f"{name}.png").stat().st_size > 0, name


def cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "geoback.commands.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def test_simulate_writes_stages_and_the_lining(tmp_path):
    out = cli("simulate", STAGED, "--out", tmp_path)
    assert out.returncode == 0, out.stderr
    assert "lining.csv" in out.stdout
    table = rows(tmp_path / "predicted.csv")
    assert {r["stage"] for r in table} == {"advance", "lined"}
    assert all(r["measured"] for r in table)
    lining = rows(tmp_path / "lining.csv")
    assert lining and (tmp_path / "lining.vtu").exists() and (tmp_path / "lining.png").exists()


def test_study_data_per_stage_is_read_back(tmp_path):
    """`geoback simulate --noise --readings-out` on a staged case writes a stage column, and a case
    reading that file identifies from it."""
    target = tmp_path / "readings.csv"
    out = cli("simulate", STAGED, "--set", "beta[advance]=0.3", "--refine", "1.5", "--noise", "--seed", "3",
              "--readings-out", target)
    assert out.returncode == 0, out.stderr
    table = rows(target)
    assert {r["stage"] for r in table} == {"advance", "lined"}
    data = yaml.safe_load(STAGED.read_text())
    for ins in data["instruments"]:
        ins["readings_file"] = str(target)
    loaded = LoadedCase(case_from_data(data), tmp_path / "case.yaml", {})
    from geoback.inference.identification import prepare

    a = prepare(loaded)
    assert a.misfit.m == 44


def concealed(tmp_path: Path, truth: dict, parameters: list, seed: int, assumed_release: float = 0.5) -> LoadedCase:
    """The shipped case (assuming `assumed_release` before the lining) with readings simulated (finer
    mesh, noise) at other values than it assumes."""
    from geoback.commands.simulate import write_readings_csv
    from geoback.inference.synthetic import synthetic_readings

    data = yaml.safe_load(STAGED.read_text())
    data["construction"]["stages"][0]["release"] = assumed_release
    for ins in data["instruments"]:
        ins.pop("readings_file")
    plain = LoadedCase(case_from_data(data), tmp_path / "case.yaml", {})
    readings = synthetic_readings(plain, refine=2.0, values=truth, noise_seed=seed, by_stage=True)
    write_readings_csv(plain, readings, tmp_path / "readings.csv")
    for ins in data["instruments"]:
        ins["readings_file"] = "readings.csv"
    data["parameters"] = parameters
    (tmp_path / "case.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    return load_case(tmp_path / "case.yaml")


def test_the_shipped_case_is_adequate():
    d = diagnose(load_case(STAGED))
    assert d.adequate_before and not d.accepted


E_K0 = [{"name": "E", "initial": 20000.0, "bounds": [1000, 1e6]}, {"name": "K0", "initial": 0.5, "bounds": [0.1, 3]}]


def test_less_stress_released_before_the_lining_is_named_and_identified(tmp_path):
    """The case assumes beta = 0.6 before the lining; the lining came early, the ground took 0.2."""
    d = diagnose(concealed(tmp_path, {**TRUTH, "beta[advance]": 0.2}, E_K0, seed=5, assumed_release=0.6))
    assert not d.adequate_before
    assert d.accepted and d.accepted[0].hypothesis.kind == "release-before-lining"
    est = d.final["beta[advance]"]
    assert abs(est.value - 0.2) < 3 * est.std
    assert d.adequate_after


def test_a_stiffer_lining_is_named_and_identified(tmp_path):
    """The case assumes E = 5 GPa for the shotcrete; it is 25 GPa (beta = 0.2: the lining carries most)."""
    truth = {**TRUTH, "beta[advance]": 0.2, "E[shotcrete]": 25e6}
    d = diagnose(concealed(tmp_path, truth, E_K0, seed=2, assumed_release=0.2))
    assert not d.adequate_before
    assert d.accepted and d.accepted[0].hypothesis.kind == "lining-stiffness"
    est = d.final["E[shotcrete]"]
    assert abs(est.value - 25e6) < 3 * est.std
