"""Instruments on the FE model: observation operators, primary readings, the covariance CLI."""
import csv
import io
import subprocess
import sys

import numpy as np
import yaml

from conftest import CASES
from geoback.case import covariance as cov
from geoback.case.loading import LoadedCase, case_from_data
from geoback.inference.identification import prepare
import pytest

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)


def _paper():
    return yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())


def _problem(data):
    return prepare(LoadedCase(case_from_data(data), CASES / "tunnel-paper.yaml", {}))


def _J(problem, p):
    return problem.misfit.J(p)


def test_primary_readings_give_the_same_objective():
    """Eqns 21-26: slopes with sigma^2 I and displacements with C_x = sigma^2 W W^t give one J."""
    data = _paper()
    disp = _problem(data)
    inc = data["instruments"][0]
    lengths = np.full(inc["stations"], inc["spacing"])
    W = cov.integration_matrix("inclinometer", lengths)
    slopes = np.linalg.solve(W, np.array(inc["readings"]))
    prim_data = _paper()
    prim_data["instruments"][0]["readings"] = slopes.tolist()
    prim_data["instruments"][0]["reading_type"] = "primary"
    prim = _problem(prim_data)
    for p in ([5000.0, 0.5], [9000.0, 0.9], [12000.0, 1.3]):
        p = np.array(p)
        J_disp, J_prim = _J(disp, p), _J(prim, p)
        # J from the slopes directly: sum over intervals of (alpha* - alpha(p))^2 / sigma^2 + extensometer part
        x = prim.predict(p).x
        m1 = len(slopes)
        alpha = np.linalg.solve(W, x[:m1])
        r2 = prim.misfit.data.measured[m1:] - x[m1:]
        C2 = prim.misfit.data.covariance[m1:, m1:]
        J_direct = np.sum((slopes - alpha) ** 2) / inc["sigma"] ** 2 + r2 @ np.linalg.solve(C2, r2)
        assert abs(J_prim / J_disp - 1) < 1e-10
        assert abs(J_direct / J_disp - 1) < 1e-10


def test_linewise_and_chord_operators_match_the_field():
    data = _paper()
    data["instruments"] += [
        {"name": "SM", "kind": "sliding_micrometer", "start": [6.0, -20.0], "end": [12.0, -2.0],
         "lengths": [2.0, 3.0, 1.5, 4.0], "sigma": 1e-4},
        {"name": "D1", "kind": "deflectometer", "start": [4.0, -1.0], "end": [16.0, -1.0], "spacing": 2.0,
         "stations": 5, "sigma": 1e-5},
        {"name": "C1", "kind": "convergence", "points": [[3.0, -10.0], [0.0, -7.0]], "sigma": 1e-4},
    ]
    pr = prepare(LoadedCase(case_from_data(data), CASES / "tunnel-paper.yaml", {}), with_readings=False)
    sim = pr.simulation
    u = sim.fe.expand(sim.displacement(pr.values)).reshape(-1, 2)
    x = pr.predict(pr.parameters.initial).x
    labels = sim.survey.labels
    nodes = sim.mesh.nodes

    def at(point):  # displacement at a mesh node coinciding with the point, or interpolated
        Ix, Iy = sim.fe.interpolation(np.array([point]))
        uf = sim.displacement(pr.values)
        return np.array([(Ix @ uf)[0], (Iy @ uf)[0]])

    rows = {(lab.instrument, lab.station): i for i, lab in enumerate(labels)}
    d = np.array([6.0, 18.0]) / np.hypot(6.0, 18.0)
    L = np.cumsum([2.0, 3.0, 1.5, 4.0])
    for k in range(4):
        pt = np.array([6.0, -20.0]) + L[k] * d
        assert np.isclose(x[rows[("SM", k + 1)]], at(pt) @ d, rtol=1e-12, atol=1e-15)
    for k in range(5):  # deflectometer along +x: normal = d rotated clockwise = (0, -1)
        pt = np.array([4.0 + 2.0 * (k + 1), -1.0])
        assert np.isclose(x[rows[("D1", k + 1)]], -at(pt)[1], rtol=1e-12, atol=1e-15)
    a, b = np.array([3.0, -10.0]), np.array([0.0, -7.0])
    chord = (b - a) / np.linalg.norm(b - a)
    assert np.isclose(x[rows[("C1", 1)]], (at(b) - at(a)) @ chord, rtol=1e-12, atol=1e-15)
    # interpolation reproduces nodal values exactly at a mesh node
    n = 17
    Ix, Iy = sim.fe.interpolation(nodes[[n]])
    uf = sim.displacement(pr.values)
    assert np.allclose([(Ix @ uf)[0], (Iy @ uf)[0]], u[n], rtol=1e-12, atol=1e-16)


def test_covariance_cli_exact_values():
    out = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "covariance", "--instrument", "inclinometer",
                          "--stations", "5", "--lengths", "0.5,1,0.5,2,1", "--sigma", "1", "--var-b", "0.3",
                          "--format", "csv"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    M = np.array([[float(v) for v in row] for row in csv.reader(io.StringIO(out.stdout)) if row])
    l2 = np.cumsum(np.array([0.5, 1, 0.5, 2, 1]) ** 2)
    expected = np.array([[l2[min(i, j)] + 0.3 for j in range(5)] for i in range(5)])
    assert M.shape == (5, 5) and np.array_equal(M, expected)


def test_covariance_cli_from_case_and_errors():
    out = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "covariance", str(CASES / "tunnel-paper.yaml"),
                          "--name", "X1", "--format", "json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    import json

    data = json.loads(out.stdout)
    C = np.array(data["matrix"])
    assert np.allclose(C, cov.sliding_micrometer_covariance(5, 0.0005, 1e-6), rtol=1e-14)
    bad = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "covariance", "--instrument", "theodolite",
                          "--stations", "3", "--spacing", "1", "--sigma", "1"], capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and "theodolite" in bad.stderr
