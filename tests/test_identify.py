"""Identification of the paper's synthetic example (eqns 27-55) and the reliability measures."""
import json
import subprocess
import sys

import numpy as np
import pytest

from geoback.case.loading import LoadedCase, case_from_data, load_case
from geoback.inference.estimate import fit
from geoback.inference.identification import identify, prepare
from geoback.commands.run import run_case

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)


@pytest.fixture(scope="module")
def paper_problem():
    from conftest import CASES

    return prepare(load_case(CASES / "tunnel-paper.yaml"))


@pytest.mark.parametrize("method", ["gn", "lm", "lm-scaled"])
@pytest.mark.parametrize("weighting", ["identity", "full"])
def test_paper_example_reaches_truth(paper_problem, method, weighting):
    """From E = 5 MPa, K0 = 0.5 to E = 10 MPa, K0 = 1 (readings from a 2x finer mesh, no noise)."""
    before = paper_problem.simulation.counters.factorisations
    res = fit(paper_problem.misfit.with_weighting(weighting), paper_problem.settings, method=method)
    E, K0 = res.p
    assert res.status == "converged", res.reason
    assert abs(E / 10000 - 1) < 0.005
    assert abs(K0 - 1) < 0.005
    assert res.iterations <= 8
    assert res.history[0].p[0] == 5000 and res.history[0].p[1] == 0.5
    # K = E k: the factorisation of k made for the first fit serves every later one (eqns 41-42)
    assert paper_problem.simulation.counters.factorisations == max(before, 1)


def test_run_writes_outputs_with_one_factorisation(paper_case_path, tmp_path):
    res = run_case(load_case(paper_case_path), tmp_path)
    for name in ("parameters.csv", "covariance.csv", "correlation.csv", "eigen.csv", "information_density.csv",
                 "readings.csv", "iterations.csv", "summary.json", "report.md", "field.vtu"):
        assert (tmp_path / name).stat().st_size > 0, name
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["factorisations"] == 1
    assert summary["status"] == "converged"
    # the load is linear in K0 and K = E k: after u for two loads every solve is a combination of them
    assert 1 <= summary["solves"] <= 3 < summary["forward_runs"]
    assert abs(summary["parameters"]["E[clay]"]["estimate"] / 10000 - 1) < 0.005
    rows = (tmp_path / "readings.csv").read_text().splitlines()
    assert len(rows) == 1 + res.data.m


def test_information_density_is_a_projector(paper_problem):
    res = identify(paper_problem)
    Q = res.reliability.information_density
    n = paper_problem.parameters.n
    assert np.allclose(Q, Q.T, atol=1e-12)
    assert np.allclose(Q @ Q, Q, atol=1e-10)
    assert np.trace(Q) == pytest.approx(n, rel=1e-10)
    assert np.all(res.reliability.leverage >= -1e-12) and np.all(res.reliability.leverage <= 1 + 1e-12)


def test_covariance_is_inverse_fisher_and_scales_with_sigma(paper_problem):
    """C_p = (A'^t A')^-1 (eqn 55): check against a direct computation, and C_p ∝ sigma^2."""
    res = identify(paper_problem)
    A = res.fit.A
    C = res.data.covariance
    direct = np.linalg.inv(A.T @ np.linalg.solve(C, A))
    assert np.allclose(res.reliability.covariance, direct, rtol=1e-8)
    from geoback.inference.misfit import Data, Misfit
    from geoback.inference.reliability import assess

    mis = paper_problem.misfit  # the same readings with every sigma doubled: C_x -> 4 C_x
    data4 = Data(mis.data.blocks, mis.data.measured, 4 * mis.data.covariance, mis.data.labels)
    mis4 = Misfit(mis.simulation, data4, mis.parameters, mis.base_values, "full")
    doubled = assess(mis4.evaluate(res.fit.p, jacobian=True), mis4.parameters, mis4.logdet)
    assert np.allclose(doubled.std, 2 * res.reliability.std, rtol=1e-10)


def _paper_dict(paper_case_path):
    import yaml

    return yaml.safe_load(paper_case_path.read_text())


def test_prior_enters_covariance(paper_case_path):
    data = _paper_dict(paper_case_path)
    data["parameters"][1]["prior"] = {"mean": 1.0, "std": 0.01}
    problem = prepare(LoadedCase(case_from_data(data), paper_case_path, {}))
    res = identify(problem)
    A, C = res.fit.A, problem.misfit.data.covariance
    info = A.T @ np.linalg.solve(C, A) + np.diag([0.0, 1 / 0.01 ** 2])
    assert np.allclose(res.reliability.covariance, np.linalg.inv(info), rtol=1e-8)
    assert res.reliability.std[1] < 0.01
    assert res.reliability.dof == problem.misfit.m - 2 + 1


def test_log_transform_reaches_same_optimum(paper_case_path, paper_problem):
    data = _paper_dict(paper_case_path)
    for p in data["parameters"]:
        p["log"] = True
    problem = prepare(LoadedCase(case_from_data(data), paper_case_path, {}))
    a = fit(problem.misfit, problem.settings, method="lm")
    b = fit(paper_problem.misfit, paper_problem.settings, method="lm")
    assert np.allclose(a.p, b.p, rtol=1e-5)


def test_undetermined_combination_is_named(paper_case_path):
    """Unlined tunnel: the stress-release fraction beta only rescales E (x ∝ beta / E)."""
    data = _paper_dict(paper_case_path)
    data["parameters"] = [{"name": "E", "initial": 8000}, {"name": "beta", "initial": 0.8},
                          {"name": "K0", "initial": 0.8}]
    problem = prepare(LoadedCase(case_from_data(data), paper_case_path, {}))
    res = identify(problem)
    rel = res.reliability
    assert rel.undetermined, "E and beta should be reported as not separately determined"
    text = rel.undetermined[0]
    assert "E[clay]" in text and "beta" in text
    assert np.isinf(rel.std[0]) and np.isinf(rel.std[1])
    assert np.isfinite(rel.std[2])


def test_cli_run_prints_report_and_exits_zero(paper_case_path, tmp_path):
    out = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "run", str(paper_case_path), "--out", str(tmp_path)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "E[clay]" in out.stdout and "converged" in out.stdout
    assert "Traceback" not in out.stderr


def test_library_entry_points(paper_case_path):
    """DESIGN.md: `from geoback import load_case, identify, diagnose` is the library's front door."""
    import geoback.diagnosis  # noqa: F401 - importing the modules must not shadow the functions
    import geoback.inference.identification  # noqa: F401
    from geoback import diagnose, identify

    res = identify(load_case(paper_case_path))
    assert abs(res.fit.p[0] / 10000 - 1) < 0.005
    assert callable(diagnose)


def test_chi2_survival_function_matches_scipy():
    """reliability.chi2_sf (written to keep scipy.special out of start-up) against gammaincc."""
    from scipy import special

    from geoback.inference.reliability import chi2_sf

    for dof in (1, 2, 3, 7, 51, 400, 5000):
        for x in np.concatenate([np.linspace(1e-3, 3 * dof + 60, 120), [1e-9, 1e6]]):
            expected = float(special.gammaincc(dof / 2, x / 2))
            got = chi2_sf(x, dof)
            assert abs(got - expected) <= 1e-9 * expected + 1e-300, (dof, x, got, expected)
    assert np.isnan(chi2_sf(3.0, 0)) and chi2_sf(0.0, 4) == 1.0
    from geoback.inference import chi2

    for dof in (0.7, 2, 3.3, 51, 5000):
        for q in (1e-6, 0.025, 0.5, 0.975, 0.999999):
            x = float(2 * special.gammaincinv(dof / 2, q))
            assert chi2.ppf(q, dof) == pytest.approx(x, rel=1e-10)
            assert chi2.cdf(x, dof) == pytest.approx(q, rel=1e-10)


def test_chi2_quantiles_for_very_many_degrees_of_freedom():
    """Up to 1e8 dof the series, beyond it (an error-scale prior worth 1e20 readings ended in a ZeroDivisionError
    traceback): the Wilson-Hilferty transform, within 1e-10 of scipy's quantiles, finite everywhere."""
    from scipy import special

    from geoback.inference import chi2

    for dof in (2e6, 5e7, 2e8, 1e10, 1e12):
        for q in (0.001, 0.025, 0.5, 0.975, 0.999):
            x = float(2 * special.gammaincinv(dof / 2, q))
            assert chi2.ppf(q, dof) == pytest.approx(x, rel=1e-10)
            assert chi2.cdf(x, dof) == pytest.approx(q, abs=1e-6)
    for dof in (1e20, 1e300):
        assert np.isfinite(chi2.ppf(0.975, dof)) and np.isfinite(chi2.cdf(dof, dof))
    assert chi2.cdf(1e5 + 1, 1e5) == pytest.approx(float(special.gammainc(5e4, (1e5 + 1) / 2)), rel=1e-10)
